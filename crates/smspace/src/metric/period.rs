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
//! period `2π`, or none wrapped. A metric carries a [`Periodicity`]: one of those, a
//! list with one period per coordinate (hinges and bounded motors mixed), or
//! `"motors"`, which asks the caller that knows the agent (the pipeline) to put the
//! agent's own periods in its place.

use serde::{Deserialize, Serialize};

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
    /// `"motors"` reached a metric that has no motor space to read it from.
    #[error("period \"motors\" takes one period per coordinate from the agent's motor space, which only a run with an agent knows (smspace run); give \"2pi\", \"none\" or one period per coordinate")]
    FromMotors,
    /// An entry of a per-coordinate list that is neither a period nor a name.
    #[error(
        "period entry {coord} is {value:?}; each entry is \"2pi\", \"none\" or a period in radians"
    )]
    BadEntry {
        /// The coordinate.
        coord: usize,
        /// The entry given.
        value: String,
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

/// How the point metric `g` wraps coordinates: one period for all of them, one per
/// coordinate, or the agent's own (resolved by the pipeline).
///
/// In files it is a string, `"2pi"`, `"none"` or `"motors"`, or a list with one entry
/// per coordinate, `"2pi"`, `"none"` or a period in radians:
///
/// ```
/// use smspace::metric::{Period, Periodicity};
/// #[derive(serde::Deserialize)]
/// struct Table { period: Periodicity }
/// let t: Table = toml::from_str("period = \"2pi\"").unwrap();
/// assert_eq!(t.period, Periodicity::Uniform(Period::TwoPi));
/// let t: Table = toml::from_str("period = [\"2pi\", \"2pi\", \"none\"]").unwrap();
/// assert_eq!(t.period.to_string(), "[2pi, 2pi, none]");
/// let t: Table = toml::from_str("period = \"motors\"").unwrap();
/// assert_eq!(t.period, Periodicity::FromMotors);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub enum Periodicity {
    /// Every coordinate alike: `2π` (hinges, the paper's `h`) or none.
    Uniform(Period),
    /// One period per coordinate.
    PerCoordinate(Periods),
    /// The periods of the agent's motors (hinges `2π`, bounded motors none): the
    /// pipeline replaces it by [`Periodicity::Uniform`] or
    /// [`Periodicity::PerCoordinate`] before any distance is computed.
    FromMotors,
}

impl Default for Periodicity {
    /// `2π` on every coordinate, the paper's hinge joints.
    fn default() -> Self {
        Self::Uniform(Period::TwoPi)
    }
}

impl From<Period> for Periodicity {
    fn from(period: Period) -> Self {
        Self::Uniform(period)
    }
}

impl From<&Periodicity> for Periodicity {
    fn from(period: &Periodicity) -> Self {
        period.clone()
    }
}

impl From<Periods> for Periodicity {
    /// Per-coordinate periods, written as the uniform [`Period`] they equal if any.
    fn from(periods: Periods) -> Self {
        match periods.as_uniform() {
            Some(uniform) => Self::Uniform(uniform),
            None => Self::PerCoordinate(periods),
        }
    }
}

impl Periodicity {
    /// The uniform period, when every coordinate has the same.
    pub fn as_uniform(&self) -> Option<Period> {
        match self {
            Self::Uniform(period) => Some(*period),
            Self::PerCoordinate(periods) => periods.as_uniform(),
            Self::FromMotors => None,
        }
    }

    /// Parses the command line's form: `2pi`, `none`, `motors`, or a comma-separated
    /// list with one entry per coordinate (`2pi`, `none` or a period in radians).
    /// The list may be in brackets (`[2pi, none]`, as [`Display`](std::fmt::Display)
    /// writes it).
    pub fn parse(text: &str) -> Result<Self, PeriodError> {
        let text = text.trim();
        let text = match text.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
            Some(inner) => inner.trim(),
            None => text,
        };
        if !text.contains(',') {
            if let Some(single) = Self::named(text) {
                return Ok(single);
            }
        }
        let entries = text
            .split(',')
            .enumerate()
            .map(|(coord, entry)| entry_period(coord, entry.trim()))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self::PerCoordinate(Periods::new(entries)?))
    }

    fn named(text: &str) -> Option<Self> {
        match text {
            "2pi" => Some(Self::Uniform(Period::TwoPi)),
            "none" => Some(Self::Uniform(Period::None)),
            "motors" => Some(Self::FromMotors),
            _ => None,
        }
    }
}

fn entry_period(coord: usize, entry: &str) -> Result<Option<f64>, PeriodError> {
    match entry {
        "2pi" => Ok(Some(std::f64::consts::TAU)),
        "none" => Ok(None),
        _ => match entry.parse::<f64>() {
            Ok(value) if value.is_finite() && value > 0.0 => Ok(Some(value)),
            Ok(value) => Err(PeriodError::NotPositive { coord, value }),
            Err(_) => Err(PeriodError::BadEntry {
                coord,
                value: entry.to_owned(),
            }),
        },
    }
}

fn entry_label(period: Option<f64>) -> String {
    match period {
        Some(t) if t == std::f64::consts::TAU => "2pi".to_owned(),
        Some(t) => format!("{t}"),
        None => "none".to_owned(),
    }
}

impl std::fmt::Display for Periodicity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Uniform(Period::TwoPi) => f.write_str("2pi"),
            Self::Uniform(Period::None) => f.write_str("none"),
            Self::FromMotors => f.write_str("motors"),
            Self::PerCoordinate(periods) => {
                let entries: Vec<String> =
                    periods.periods.iter().map(|&p| entry_label(p)).collect();
                write!(f, "[{}]", entries.join(", "))
            }
        }
    }
}

/// One entry of a per-coordinate list in a file.
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum EntryRepr {
    Name(String),
    Radians(f64),
}

/// A [`Periodicity`] in a file.
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum PeriodicityRepr {
    Name(String),
    List(Vec<EntryRepr>),
}

impl Serialize for Periodicity {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let repr = match self {
            Self::PerCoordinate(periods) => PeriodicityRepr::List(
                periods
                    .periods
                    .iter()
                    .map(|&p| match p {
                        Some(t) if t == std::f64::consts::TAU => EntryRepr::Name("2pi".into()),
                        Some(t) => EntryRepr::Radians(t),
                        None => EntryRepr::Name("none".into()),
                    })
                    .collect(),
            ),
            other => PeriodicityRepr::Name(other.to_string()),
        };
        repr.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for Periodicity {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        match PeriodicityRepr::deserialize(deserializer)? {
            PeriodicityRepr::Name(name) => Self::named(&name).ok_or_else(|| {
                D::Error::custom(format!(
                    "unknown period {name:?}: give \"2pi\", \"none\", \"motors\" or a list with one entry per motor"
                ))
            }),
            PeriodicityRepr::List(entries) => {
                let periods = entries
                    .into_iter()
                    .enumerate()
                    .map(|(coord, entry)| match entry {
                        EntryRepr::Name(name) => entry_period(coord, &name),
                        EntryRepr::Radians(value) => entry_period(coord, &value.to_string()),
                    })
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(D::Error::custom)?;
                Ok(Self::PerCoordinate(
                    Periods::new(periods).map_err(D::Error::custom)?,
                ))
            }
        }
    }
}

impl CoordinatePeriods for Periodicity {
    fn for_dims(&self, dims: usize) -> Result<Periods, PeriodError> {
        match self {
            Self::Uniform(period) => period.for_dims(dims),
            Self::PerCoordinate(periods) => periods.for_dims(dims),
            Self::FromMotors => Err(PeriodError::FromMotors),
        }
    }
}

impl CoordinatePeriods for &Periodicity {
    fn for_dims(&self, dims: usize) -> Result<Periods, PeriodError> {
        (*self).for_dims(dims)
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
    fn periodicity_parses_prints_and_round_trips() {
        let mixed = Periodicity::parse("2pi, none,3").unwrap();
        assert_eq!(mixed.to_string(), "[2pi, none, 3]");
        assert_eq!(Periodicity::parse(&mixed.to_string()).unwrap(), mixed);
        assert_eq!(
            mixed.for_dims(3).unwrap(),
            Periods::new(vec![Some(TAU), None, Some(3.0)]).unwrap()
        );
        assert!(mixed.for_dims(2).is_err());
        // A list keeps its length (checked against the points), even when its entries
        // are equal; per-coordinate periods that are all alike are the uniform period.
        let equal = Periodicity::parse("2pi,2pi").unwrap();
        assert_eq!(equal.as_uniform(), Some(Period::TwoPi));
        assert!(equal.for_dims(3).is_err());
        assert_eq!(
            Periodicity::from(Periods::uniform(Period::TwoPi, 3)),
            Periodicity::Uniform(Period::TwoPi)
        );
        assert_eq!(Periodicity::parse("none").unwrap(), Period::None.into());
        assert!(matches!(
            Periodicity::FromMotors.for_dims(2),
            Err(PeriodError::FromMotors)
        ));
        for bad in ["2pi,abc", "1,-2", "tau"] {
            assert!(Periodicity::parse(bad).is_err(), "{bad}");
        }
        for value in [mixed, Periodicity::default(), Periodicity::FromMotors] {
            let json = serde_json::to_string(&value).unwrap();
            let back: Periodicity = serde_json::from_str(&json).unwrap();
            assert_eq!(back, value, "{json}");
        }
        // The uniform periods keep the file form of `Period`.
        assert_eq!(
            serde_json::to_string(&Periodicity::default()).unwrap(),
            serde_json::to_string(&Period::TwoPi).unwrap()
        );
        assert!(serde_json::from_str::<Periodicity>("\"tau\"").is_err());
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
