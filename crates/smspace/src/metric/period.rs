//! A period per motor coordinate for the point metric `g` (paper section 3.2).
//!
//! Each coordinate `n` of a motor configuration is either periodic with its own period
//! `T_n` (a hinge joint: `T_n = 2π`; any finite positive value is allowed) or not
//! wrapped (a bounded or linear motor). The point metric wraps every coordinate
//! difference with its own period:
//!
//! ```text
//! g(m, m')² = Σ_n h_n(m_n − m'_n)²,   h_n(u) = u − T_n·round(u / T_n)   (periodic n),
//!                                      h_n(u) = u                         (unwrapped n),
//! ```
//!
//! so `|h_n(u)| ≤ T_n / 2`. The uniform [`Period::TwoPi`] and [`Period::None`] are the
//! shorthands of the command line and the experiment files: every coordinate with
//! period `2π`, or none wrapped.

use super::Period;

/// Errors of per-coordinate periods.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PeriodError {
    /// No coordinate.
    #[error("no period given: give one period (or none) per motor coordinate")]
    Empty,
    /// A period that is not finite and positive.
    #[error("the period of coordinate {coord} is {value}; a period must be finite and positive (leave the coordinate unwrapped for none)")]
    NotPositive {
        /// The coordinate.
        coord: usize,
        /// The value given.
        value: f64,
    },
    /// Periods given for another number of coordinates.
    #[error("{periods} periods given for points with {dims} coordinates; give one per coordinate")]
    Count {
        /// Periods given.
        periods: usize,
        /// Coordinates of the points.
        dims: usize,
    },
}

/// The period of every coordinate: `Some(T_n)` (finite, positive) or `None` (not
/// wrapped). Built from a uniform [`Period`] and the coordinate count, or checked from
/// a list.
///
/// ```
/// use smspace::metric::{Period, Periods};
/// // Two hinge joints and a linear slide.
/// let periods = Periods::new(vec![Some(std::f64::consts::TAU), Some(std::f64::consts::TAU), None])?;
/// assert_eq!(periods.dims(), 3);
/// assert_eq!(periods.radians(2), f64::INFINITY);
/// assert_eq!(Periods::uniform(Period::TwoPi, 3).radians(0), std::f64::consts::TAU);
/// # Ok::<(), smspace::metric::PeriodError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Periods {
    periods: Vec<Option<f64>>,
}

impl Periods {
    /// Every one of `dims` coordinates with the same [`Period`].
    pub fn uniform(period: Period, dims: usize) -> Self {
        let value = match period {
            Period::TwoPi => Some(std::f64::consts::TAU),
            Period::None => None,
        };
        Self {
            periods: vec![value; dims],
        }
    }

    /// One period per coordinate (`None`: not wrapped). Errors when a period is not
    /// finite or not positive (naming the coordinate), or when the list is empty.
    pub fn new(periods: Vec<Option<f64>>) -> Result<Self, PeriodError> {
        if periods.is_empty() {
            return Err(PeriodError::Empty);
        }
        for (coord, period) in periods.iter().enumerate() {
            if let Some(value) = *period {
                if !(value.is_finite() && value > 0.0) {
                    return Err(PeriodError::NotPositive { coord, value });
                }
            }
        }
        Ok(Self { periods })
    }

    /// Number of coordinates `N`.
    pub fn dims(&self) -> usize {
        self.periods.len()
    }

    /// The period of coordinate `n` (`None`: not wrapped).
    pub fn get(&self, n: usize) -> Option<f64> {
        self.periods[n]
    }

    /// The period of coordinate `n` in its units (`f64::INFINITY` when not wrapped).
    pub fn radians(&self, n: usize) -> f64 {
        self.periods[n].unwrap_or(f64::INFINITY)
    }

    /// The uniform [`Period`] these periods equal, if any.
    pub fn as_uniform(&self) -> Option<Period> {
        [Period::TwoPi, Period::None]
            .into_iter()
            .find(|&p| *self == Self::uniform(p, self.dims()))
    }
}

/// The periods of a set of coordinates as the metric functions accept them: a uniform
/// [`Period`] (every coordinate alike) or [`Periods`] (one per coordinate).
pub trait CoordinatePeriods {
    /// The periods of `dims` coordinates; errors when they were given for another
    /// coordinate count.
    fn for_dims(&self, dims: usize) -> Result<Periods, PeriodError>;
}

impl CoordinatePeriods for Period {
    fn for_dims(&self, dims: usize) -> Result<Periods, PeriodError> {
        Ok(Periods::uniform(*self, dims))
    }
}

impl CoordinatePeriods for Periods {
    fn for_dims(&self, dims: usize) -> Result<Periods, PeriodError> {
        if self.dims() != dims {
            return Err(PeriodError::Count {
                periods: self.dims(),
                dims,
            });
        }
        Ok(self.clone())
    }
}

impl CoordinatePeriods for &Periods {
    fn for_dims(&self, dims: usize) -> Result<Periods, PeriodError> {
        (*self).for_dims(dims)
    }
}

/// Wraps `x` into `[−T/2, T/2)` (`T = period`, `f64::INFINITY` for none), leaving values
/// already there untouched.
pub(crate) fn wrap(x: f64, period: f64) -> f64 {
    if !period.is_finite() {
        return x;
    }
    let half = 0.5 * period;
    if (-half..half).contains(&x) {
        return x;
    }
    // The remainder is exact (fmod), so even a coordinate near 1e300 lands in range;
    // `rem_euclid` can round up to exactly `T` for a tiny negative `x`.
    let w = x.rem_euclid(period);
    if w >= half {
        w - period
    } else {
        w
    }
}

/// `|h(u)|`: the periodic difference folded to its magnitude, for `|u| < T` (inputs
/// wrapped); `|u|` without a period.
#[inline(always)]
pub(crate) fn fold(u: f64, period: f64) -> f64 {
    let u = u.abs();
    let v = period - u;
    if v < u {
        v
    } else {
        u
    }
}

/// `h(u)` signed, for `|u| < 3T/2`: `u` brought into `[−T/2, T/2]`; unchanged without a
/// period.
#[inline(always)]
pub(crate) fn swrap(u: f64, period: f64) -> f64 {
    let half = 0.5 * period;
    let u = if u > half { u - period } else { u };
    if u < -half {
        u + period
    } else {
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{PI, TAU};

    #[test]
    fn periods_are_checked_and_uniform_ones_recognised() {
        assert!(Periods::new(vec![Some(TAU), None, Some(1.5)]).is_ok());
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let err = Periods::new(vec![None, Some(bad)]).unwrap_err();
            assert!(err.to_string().contains("coordinate 1"), "{err}");
        }
        assert!(Periods::new(vec![]).is_err());
        assert_eq!(
            Periods::uniform(Period::TwoPi, 4).as_uniform(),
            Some(Period::TwoPi)
        );
        assert_eq!(
            Periods::new(vec![None, None]).unwrap().as_uniform(),
            Some(Period::None)
        );
        assert_eq!(
            Periods::new(vec![Some(TAU), None]).unwrap().as_uniform(),
            None
        );
        assert!(Periods::uniform(Period::None, 3).for_dims(4).is_err());
    }

    #[test]
    fn wrap_keeps_values_in_range_bit_for_bit() {
        let t = 2.0 * PI;
        for x in [-PI, -1.0, 0.0, 1.0, PI - 1e-12] {
            assert_eq!(wrap(x, t).to_bits(), x.to_bits());
        }
        for x in [PI, 3.0 * PI + 0.5, -7.0, 100.0] {
            let w = wrap(x, t);
            assert!((-PI..PI).contains(&w), "{x} -> {w}");
            let back = (x - w) / t;
            assert!((back - back.round()).abs() < 1e-9);
        }
        assert_eq!(wrap(123.0, f64::INFINITY), 123.0);
        // Another period.
        let w = wrap(2.6, 1.0);
        assert!((w - (-0.4)).abs() < 1e-12 && (-0.5..0.5).contains(&w));
    }
}
