//! The motor space: per motor, a periodic coordinate (a hinge, with its period) or a
//! bounded one (a linear actuator, or a joint with limits, with its range).
//!
//! A configuration is `m ∈ ℝ^N`. Coordinate `j` is either **periodic** with period
//! `T_j` (values are read modulo `T_j` and kept in `[−T_j/2, T_j/2)`; a hinge has
//! `T_j = 2π`) or **bounded** in `[low_j, high_j]` (no wrapping). The motor distance
//! is the paper's `g` (section 3.2) with each difference taken on its own coordinate:
//!
//! ```text
//! g(m, m') = sqrt( Σ_j δ_j(m_j − m'_j)² ),   δ_j(x) = wrap_{T_j}(x) (periodic), x (bounded),
//! wrap_T(x) = x − T ⌊(x + T/2) / T⌋  ∈ [−T/2, T/2).
//! ```
//!
//! Babbling draws every coordinate uniformly from its own range (`[−T/2, T/2)` or
//! `[low, high)`); the tracer wraps only periodic coordinates and ends an open set
//! where it reaches a bound of a bounded coordinate.

use std::f64::consts::TAU;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::params::InvalidParameter;

/// One motor coordinate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Motor {
    /// A periodic coordinate: values are read modulo `period` and kept in
    /// `[−period/2, period/2)`. A hinge has period `2π` ([`Motor::HINGE`]).
    Periodic {
        /// The period (radians for a hinge).
        period: f64,
    },
    /// A coordinate bounded to `[low, high]`, never wrapped.
    Bounded {
        /// Lower bound.
        low: f64,
        /// Upper bound.
        high: f64,
    },
}

impl Motor {
    /// A hinge: periodic with period `2π`, values in `[−π, π)`.
    pub const HINGE: Motor = Motor::Periodic { period: TAU };

    /// The period of a periodic coordinate, `None` for a bounded one.
    pub fn period(self) -> Option<f64> {
        match self {
            Motor::Periodic { period } => Some(period),
            Motor::Bounded { .. } => None,
        }
    }

    /// Whether the coordinate is periodic.
    pub fn is_periodic(self) -> bool {
        matches!(self, Motor::Periodic { .. })
    }

    /// The interval babbling draws this coordinate from: `[−T/2, T/2)` when periodic,
    /// `[low, high)` when bounded.
    pub fn range(self) -> (f64, f64) {
        match self {
            Motor::Periodic { period } => (-period / 2.0, period / 2.0),
            Motor::Bounded { low, high } => (low, high),
        }
    }

    /// `x` wrapped into `[−T/2, T/2)` when periodic; `x` itself when bounded.
    #[inline]
    pub fn wrap(self, x: f64) -> f64 {
        match self {
            Motor::Periodic { period } => wrap_period(x, period),
            Motor::Bounded { .. } => x,
        }
    }

    /// The difference `a − b` on this coordinate: wrapped when periodic.
    #[inline]
    pub fn difference(self, a: f64, b: f64) -> f64 {
        self.wrap(a - b)
    }

    /// Checks that a period is finite and positive, or a range finite with
    /// `low < high`; `index` is the motor's position (0-based) for the message.
    pub fn check(self, index: usize) -> Result<(), InvalidParameter> {
        let ok = match self {
            Motor::Periodic { period } => period.is_finite() && period > 0.0,
            Motor::Bounded { low, high } => low.is_finite() && high.is_finite() && low < high,
        };
        if ok {
            return Ok(());
        }
        Err(InvalidParameter::new(
            "agent",
            "motor_space",
            format!("{self} (motor m{})", index + 1),
            "a period must be a finite number greater than zero, a range two finite numbers [low, high] with low < high",
        ))
    }
}

impl fmt::Display for Motor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Motor::Periodic { period } if period == TAU => write!(f, "hinge (period 2π)"),
            Motor::Periodic { period } => write!(f, "periodic (period {period})"),
            Motor::Bounded { low, high } => write!(f, "bounded in [{low}, {high}]"),
        }
    }
}

/// `x` wrapped into `[−period/2, period/2)` (see the module docs). Exact: the
/// remainder is computed with `rem_euclid`; for `period = 2π` this is
/// [`wrap_angle`](super::wrap_angle).
#[inline]
pub fn wrap_period(x: f64, period: f64) -> f64 {
    let half = period / 2.0;
    if (-half..half).contains(&x) {
        return x;
    }
    let wrapped = (x + half).rem_euclid(period) - half;
    // rem_euclid can round up to exactly `period` for tiny negative inputs.
    if wrapped >= half {
        wrapped - period
    } else {
        wrapped
    }
}

/// The motor space of an agent: one [`Motor`] per motor coordinate, checked.
///
/// ```
/// use smspace::agent::{Motor, MotorSpace};
/// // A hinge arm whose last motor is a pupil opening from 0.2 to 1.
/// let space = MotorSpace::new(vec![Motor::HINGE, Motor::HINGE, Motor::Bounded { low: 0.2, high: 1.0 }])?;
/// let tau = std::f64::consts::TAU;
/// assert_eq!(space.periods(), vec![Some(tau), Some(tau), None]);
/// // The hinge difference wraps, the pupil's does not.
/// let d = space.distance(&[3.0, 0.0, 0.9], &[-3.0, 0.0, 0.3]);
/// assert!((d - ((tau - 6.0).powi(2) + 0.36).sqrt()).abs() < 1e-12);
/// # Ok::<(), smspace::params::InvalidParameter>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Vec<Motor>", into = "Vec<Motor>")]
pub struct MotorSpace {
    motors: Vec<Motor>,
}

impl TryFrom<Vec<Motor>> for MotorSpace {
    type Error = InvalidParameter;
    fn try_from(motors: Vec<Motor>) -> Result<Self, InvalidParameter> {
        Self::new(motors)
    }
}

impl From<MotorSpace> for Vec<Motor> {
    fn from(space: MotorSpace) -> Self {
        space.motors
    }
}

impl MotorSpace {
    /// The space of these motors, each checked ([`Motor::check`]).
    pub fn new(motors: Vec<Motor>) -> Result<Self, InvalidParameter> {
        for (j, motor) in motors.iter().enumerate() {
            motor.check(j)?;
        }
        Ok(Self { motors })
    }

    /// `n` hinges: the torus `[−π, π)^n` (the paper's arm).
    pub fn hinges(n: usize) -> Self {
        Self {
            motors: vec![Motor::HINGE; n],
        }
    }

    /// `n` motors bounded in `[low, high]` (the paper's toys).
    pub fn bounded(n: usize, low: f64, high: f64) -> Result<Self, InvalidParameter> {
        Self::new(vec![Motor::Bounded { low, high }; n])
    }

    /// The number of motors `N`.
    pub fn dim(&self) -> usize {
        self.motors.len()
    }

    /// Every motor, in order.
    pub fn motors(&self) -> &[Motor] {
        &self.motors
    }

    /// Motor `j` (0-based).
    pub fn motor(&self, j: usize) -> Motor {
        self.motors[j]
    }

    /// The period of every coordinate (`None` for bounded ones): what a set metric
    /// needs to compare configurations of this space.
    pub fn periods(&self) -> Vec<Option<f64>> {
        self.motors.iter().map(|m| m.period()).collect()
    }

    /// The home configuration: every periodic motor at 0, every bounded one at the
    /// middle of its range.
    pub fn home(&self) -> Vec<f64> {
        self.motors
            .iter()
            .map(|m| match *m {
                Motor::Bounded { low, high } => 0.5 * (low + high),
                Motor::Periodic { .. } => 0.0,
            })
            .collect()
    }

    /// Whether every motor is a hinge (periodic with period `2π`).
    pub fn is_hinges(&self) -> bool {
        self.motors.iter().all(|&m| m == Motor::HINGE)
    }

    /// Whether every motor is bounded.
    pub fn is_bounded(&self) -> bool {
        self.motors.iter().all(|m| !m.is_periodic())
    }

    /// Whether some motor is bounded (so a set may end on a bound: an open set).
    pub fn has_bounds(&self) -> bool {
        self.motors.iter().any(|m| !m.is_periodic())
    }

    /// The distance `g` between two configurations (see the module docs).
    pub fn distance(&self, a: &[f64], b: &[f64]) -> f64 {
        self.motors
            .iter()
            .zip(a.iter().zip(b))
            .map(|(m, (&x, &y))| {
                let d = m.difference(x, y);
                d * d
            })
            .sum::<f64>()
            .sqrt()
    }

    /// Wraps the periodic coordinates of every point of `points` (rows of `N`
    /// values) into their ranges; bounded coordinates are left as they are.
    pub fn wrap_points(&self, points: &mut [f64]) {
        if self.is_bounded() || self.motors.is_empty() {
            return;
        }
        for point in points.chunks_exact_mut(self.motors.len()) {
            for (x, m) in point.iter_mut().zip(&self.motors) {
                *x = m.wrap(*x);
            }
        }
    }

    /// The image of `start` nearest to `m` (unwrapped coordinates): periodic
    /// coordinates shifted by whole periods, bounded ones equal to `start`'s.
    pub fn nearest_image(&self, start: &[f64], m: &[f64], image: &mut [f64]) {
        for (((out, s), x), motor) in image.iter_mut().zip(start).zip(m).zip(&self.motors) {
            *out = match *motor {
                Motor::Periodic { period } => s + period * ((x - s) / period).round(),
                Motor::Bounded { .. } => *s,
            };
        }
    }

    /// For a step from `previous` to `m` that leaves the range of a bounded
    /// coordinate: the fraction `τ ∈ [0, 1)` of the step where it first reaches a
    /// bound. `None` when the step stays within every bound.
    pub fn exit_fraction(&self, previous: &[f64], m: &[f64]) -> Option<f64> {
        let mut tau: f64 = 1.0;
        for ((motor, &p), &x) in self.motors.iter().zip(previous).zip(m) {
            if let Motor::Bounded { low, high } = *motor {
                let step = x - p;
                if x > high {
                    tau = tau.min((high - p) / step);
                } else if x < low {
                    tau = tau.min((low - p) / step);
                }
            }
        }
        (tau < 1.0).then_some(tau)
    }

    /// `previous + τ (m − previous)`, bounded coordinates clamped into their ranges:
    /// where a step leaving the box crosses its boundary.
    pub fn point_on_exit(&self, previous: &[f64], m: &[f64], tau: f64, out: &mut [f64]) {
        for (((o, motor), &p), &x) in out.iter_mut().zip(&self.motors).zip(previous).zip(m) {
            let v = p + tau * (x - p);
            *o = match *motor {
                Motor::Bounded { low, high } => v.clamp(low, high),
                Motor::Periodic { .. } => v,
            };
        }
    }
}

impl fmt::Display for MotorSpace {
    /// `4 hinges (period 2π)`, `2 motors bounded in [-1, 1]`, or one entry per motor
    /// when they differ.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.motors.len();
        let plural = if n == 1 { "" } else { "s" };
        match self.motors.first() {
            None => write!(f, "no motors"),
            Some(&first) if self.motors.iter().all(|&m| m == first) => match first {
                m if m == Motor::HINGE => write!(f, "{n} hinge{plural} (period 2π)"),
                Motor::Periodic { period } => {
                    write!(f, "{n} periodic motor{plural} (period {period})")
                }
                Motor::Bounded { low, high } => {
                    write!(f, "{n} motor{plural} bounded in [{low}, {high}]")
                }
            },
            Some(_) => {
                let each: Vec<String> = self
                    .motors
                    .iter()
                    .enumerate()
                    .map(|(j, m)| format!("m{} {m}", j + 1))
                    .collect();
                write!(f, "mixed motors: {}", each.join(", "))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use std::f64::consts::PI;

    #[test]
    fn wrap_period_equals_wrap_angle_for_hinges_bit_for_bit() {
        for x in [
            -1e300,
            -7.5,
            -PI,
            -PI + 1e-15,
            -1e-300,
            0.0,
            1e-300,
            3.0,
            PI,
            2.0 * PI,
            9.4,
            1e17,
        ] {
            assert_eq!(
                wrap_period(x, TAU).to_bits(),
                super::super::wrap_angle(x).to_bits(),
                "{x}"
            );
        }
        assert_abs_diff_eq!(wrap_period(2.6, 1.0), -0.4, epsilon = 1e-12);
        assert_abs_diff_eq!(wrap_period(-0.5, 1.0), -0.5);
        assert_abs_diff_eq!(wrap_period(0.5, 1.0), -0.5);
        assert!(wrap_period(-1e-300, 1.0) < 0.5);
    }

    #[test]
    fn mixed_spaces_wrap_only_their_periodic_coordinates() {
        let space = MotorSpace::new(vec![
            Motor::HINGE,
            Motor::Bounded {
                low: -1.0,
                high: 1.0,
            },
            Motor::Periodic { period: 2.0 },
        ])
        .unwrap();
        let mut points = [4.0, 4.0, 1.5, -4.0, -4.0, -1.5];
        space.wrap_points(&mut points);
        assert_abs_diff_eq!(points[0], 4.0 - TAU, epsilon = 1e-12);
        assert_eq!(points[1], 4.0);
        assert_abs_diff_eq!(points[2], -0.5, epsilon = 1e-12);
        assert_abs_diff_eq!(points[3], TAU - 4.0, epsilon = 1e-12);
        assert_eq!(points[4], -4.0);
        assert_abs_diff_eq!(points[5], 0.5, epsilon = 1e-12);
        let mut image = [0.0; 3];
        space.nearest_image(&[0.1, 0.2, 0.3], &[6.0, 0.9, -1.9], &mut image);
        assert_abs_diff_eq!(image[0], 0.1 + TAU, epsilon = 1e-12);
        assert_eq!(image[1], 0.2);
        assert_abs_diff_eq!(image[2], -1.7, epsilon = 1e-12);
        // A step that leaves the bounded coordinate's range stops on its bound.
        let tau = space
            .exit_fraction(&[0.0, 0.5, 0.0], &[0.3, 1.5, 0.3])
            .unwrap();
        assert_abs_diff_eq!(tau, 0.5, epsilon = 1e-12);
        let mut exit = [0.0; 3];
        space.point_on_exit(&[0.0, 0.5, 0.0], &[0.3, 1.5, 0.3], tau, &mut exit);
        assert_abs_diff_eq!(exit[0], 0.15, epsilon = 1e-12);
        assert_eq!(exit[1], 1.0);
        assert!(space.exit_fraction(&[0.0; 3], &[9.0, 0.9, 9.0]).is_none());
        assert_eq!(space.periods(), vec![Some(TAU), None, Some(2.0)]);
        assert!(
            space.to_string().contains("m2 bounded in [-1, 1]"),
            "{space}"
        );
        assert_eq!(MotorSpace::hinges(4).to_string(), "4 hinges (period 2π)");
    }

    #[test]
    fn impossible_motors_are_refused() {
        for bad in [
            Motor::Periodic { period: 0.0 },
            Motor::Periodic { period: f64::NAN },
            Motor::Bounded {
                low: 1.0,
                high: 1.0,
            },
            Motor::Bounded {
                low: f64::NEG_INFINITY,
                high: 0.0,
            },
        ] {
            let err = MotorSpace::new(vec![Motor::HINGE, bad]).unwrap_err();
            assert_eq!((err.table, err.key), ("agent", "motor_space"));
            assert!(err.value.contains("motor m2"), "{err}");
        }
        let space: MotorSpace =
            serde_json::from_str(r#"[{"kind": "periodic", "period": 6.283185307179586}, {"kind": "bounded", "low": 0, "high": 1}]"#)
                .unwrap();
        assert_eq!(space.motor(0), Motor::HINGE);
        assert!(
            serde_json::from_str::<MotorSpace>(r#"[{"kind": "periodic", "period": -1}]"#).is_err()
        );
    }
}
