//! The toy agents of paper section 2: a T-shaped body moved along a line, with two light
//! sensors on its top.
//!
//! The body's position along the line is `x = m1` (agent 1, section 2.2) or
//! `x = m1 + m2` (agent 2, section 2.3, two redundant motors). The sensors sit at
//! `(x ∓ d/2, h)` (`d` the sensor spacing, `h` the sensor height) and read
//!
//! ```text
//! s_i = Σ_l 1 / d_il² ,
//! ```
//!
//! `d_il` the distance from sensor `i` to light `l`. Motors are linear actuators on a
//! bounded range, so agent 2's kernel sets are the segments `m1 + m2 = x` inside the
//! motor box.

use std::f64::consts::PI;

use serde::{Deserialize, Serialize};

use super::{
    check_positive, Agent, AgentError, Environment, LightRegion, MotorSpace, Observer, Pose,
    PoseSpace,
};
use crate::params::{CheckParams, InvalidParameter};

/// Parameters of the toy agents (`kind = "toy-line"` or `kind = "toy-redundant"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ToyParams {
    /// Distance between the two sensors. Default 0.5.
    pub sensor_spacing: f64,
    /// Height of the sensors above the line the body moves on. Default 1.0.
    pub sensor_height: f64,
    /// `[low, high]` range of every motor command. Default `[-π, π]`.
    pub motor_range: [f64; 2],
}

impl Default for ToyParams {
    fn default() -> Self {
        Self {
            sensor_spacing: 0.5,
            sensor_height: 1.0,
            motor_range: [-PI, PI],
        }
    }
}

/// Which toy agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ToyKind {
    /// One motor: `x = m1` (paper section 2.2).
    Line,
    /// Two redundant motors: `x = m1 + m2` (paper section 2.3).
    Redundant,
}

/// A toy agent of paper section 2. See the module docs for the equations.
#[derive(Debug, Clone)]
pub struct ToyAgent {
    kind: ToyKind,
    sensor_spacing: f64,
    sensor_height: f64,
    motor_range: [f64; 2],
}

/// Checked [`ToyParams`], the only form a toy is built from ([`ToyAgent::from_valid`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ToyValidParams {
    sensor_spacing: f64,
    sensor_height: f64,
    motor_range: [f64; 2],
}

impl CheckParams for ToyParams {
    type Valid = ToyValidParams;
    type Error = AgentError;

    /// Positive spacing and height, a finite motor range with `low < high`.
    fn check_params(&self) -> Result<ToyValidParams, AgentError> {
        check_positive("sensor_spacing", self.sensor_spacing)?;
        check_positive("sensor_height", self.sensor_height)?;
        let [low, high] = self.motor_range;
        if !(low.is_finite() && high.is_finite() && low < high) {
            return Err(InvalidParameter::new(
                "agent",
                "motor_range",
                format!("[{low}, {high}]"),
                "must be two finite numbers [low, high] with low < high",
            )
            .into());
        }
        Ok(ToyValidParams {
            sensor_spacing: self.sensor_spacing,
            sensor_height: self.sensor_height,
            motor_range: self.motor_range,
        })
    }
}

impl ToyAgent {
    /// Validates `params` and builds the agent.
    pub fn new(kind: ToyKind, params: &ToyParams) -> Result<Self, AgentError> {
        Ok(Self::from_valid(kind, params.check_params()?))
    }

    /// The agent of checked parameters.
    pub fn from_valid(kind: ToyKind, params: ToyValidParams) -> Self {
        Self {
            kind,
            sensor_spacing: params.sensor_spacing,
            sensor_height: params.sensor_height,
            motor_range: params.motor_range,
        }
    }

    /// The body's pose `(x, 0, 0)`: its position on the line.
    pub fn planar_pose(&self, motors: &[f64]) -> Pose {
        Pose {
            x: motors.iter().sum(),
            y: 0.0,
            alpha: 0.0,
        }
    }

    /// Positions of the two sensors for motors `m`.
    pub fn sensor_positions(&self, motors: &[f64]) -> [[f64; 2]; 2] {
        let x = self.planar_pose(motors).x;
        let half = self.sensor_spacing / 2.0;
        [
            [x - half, self.sensor_height],
            [x + half, self.sensor_height],
        ]
    }
}

impl Agent for ToyAgent {
    fn motor_dim(&self) -> usize {
        match self.kind {
            ToyKind::Line => 1,
            ToyKind::Redundant => 2,
        }
    }

    fn sensor_dim(&self) -> usize {
        2
    }

    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        for (s, p) in sensors.iter_mut().zip(self.sensor_positions(motors)) {
            *s = environment
                .lights
                .iter()
                .enumerate()
                .map(|(i, l)| {
                    environment.intensity(i) / ((l[0] - p[0]).powi(2) + (l[1] - p[1]).powi(2))
                })
                .sum();
        }
    }

    fn name(&self) -> &str {
        match self.kind {
            ToyKind::Line => "toy-line",
            ToyKind::Redundant => "toy-redundant",
        }
    }

    /// Every motor is a linear actuator on `motor_range`.
    fn motor_space(&self) -> MotorSpace {
        let [low, high] = self.motor_range;
        MotorSpace::bounded(self.motor_dim(), low, high)
            .expect("the range was checked when the agent was built")
    }

    fn ground_truth(&self) -> Option<&dyn Observer> {
        Some(self)
    }

    /// A band of lights above the sensors: `x` across the reachable line widened by 1,
    /// `y` from 1 to 3 units above the sensors.
    fn default_light_region(&self) -> LightRegion {
        let n = self.motor_dim() as f64;
        let [low, high] = self.motor_range;
        LightRegion {
            center: [n * (low + high) / 2.0, self.sensor_height + 2.0],
            half_size: [n * (high - low) / 2.0 + 1.0, 1.0],
            exclusion_half_size: [0.0, 0.0],
        }
    }

    fn default_light_count(&self) -> usize {
        5
    }
}

/// The observer sees the body's position on the line as the planar pose `(x, 0, 0)`:
/// only `x` changes with the motors.
impl Observer for ToyAgent {
    fn pose_space(&self) -> PoseSpace {
        PoseSpace::planar()
    }

    fn pose(&self, motors: &[f64], pose: &mut [f64]) {
        pose[..3].copy_from_slice(&self.planar_pose(motors).to_array());
    }

    fn configuration_dim(&self) -> usize {
        1
    }

    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        let n = self.motor_dim();
        jacobian[..n].fill(1.0);
        jacobian[n..3 * n].fill(0.0);
        self.pose(motors, pose);
    }

    fn inverse_kinematics(&self, pose: &[f64]) -> Option<Vec<f64>> {
        let n = self.motor_dim() as f64;
        let m = pose[0] / n;
        let [low, high] = self.motor_range;
        (low..=high).contains(&m).then(|| vec![m; self.motor_dim()])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn huge_motors_give_finite_sensors() {
        let env = Environment::from_lights(vec![[-0.25, 3.0], [1.0, 2.0]]);
        for (kind, motors) in [
            (ToyKind::Line, &[1e308][..]),
            (ToyKind::Redundant, &[1e308, 1e308][..]),
            (ToyKind::Redundant, &[-f64::MAX, 1e300][..]),
        ] {
            let agent = ToyAgent::new(kind, &ToyParams::default()).unwrap();
            let mut s = [f64::NAN; 2];
            agent.sense(&env, motors, &mut s);
            // Lights infinitely far away in effect: no light reaches the sensors.
            assert_eq!(s, [0.0, 0.0], "{motors:?}");
        }
    }

    #[test]
    fn inverse_square_law() {
        let agent = ToyAgent::new(ToyKind::Line, &ToyParams::default()).unwrap();
        let env = Environment::from_lights(vec![[-0.25, 3.0]]);
        let mut s = [0.0; 2];
        agent.sense(&env, &[0.0], &mut s);
        assert_abs_diff_eq!(s[0], 0.25, epsilon = 1e-15); // distance 2 above sensor 1
        assert_abs_diff_eq!(s[1], 1.0 / (0.25 + 4.0), epsilon = 1e-15);
    }

    #[test]
    fn redundant_motors_add() {
        let agent = ToyAgent::new(ToyKind::Redundant, &ToyParams::default()).unwrap();
        let env = Environment::from_lights(vec![[1.0, 2.0], [-2.0, 3.5]]);
        let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
        agent.sense(&env, &[0.3, 0.4], &mut a);
        agent.sense(&env, &[0.9, -0.2], &mut b);
        assert_abs_diff_eq!(a[0], b[0], epsilon = 1e-14);
        assert_abs_diff_eq!(a[1], b[1], epsilon = 1e-14);
    }

    #[test]
    fn bad_range_is_rejected() {
        let p = ToyParams {
            motor_range: [1.0, -1.0],
            ..ToyParams::default()
        };
        let err = ToyAgent::new(ToyKind::Line, &p).unwrap_err();
        assert!(err.to_string().contains("motor_range"));
    }
}
