//! The noise of the sensors the `sensory` method reads: the `[kernel] noise` parameter
//! and what is reported of the noise, per set and over the starts (the level set of
//! noisy readings is in `noisy.rs`; the maths in the module docs of [`super`],
//! "Noisy sensors").

use serde::{Deserialize, Serialize};

use super::SetReport;

/// The noise of the sensors the `sensory` method reads (`[kernel] noise`): `"auto"` or
/// a standard deviation in sensor units. Noisy readings are traced on the level set of
/// their mean (see the module docs, "Noisy sensors").
///
/// ```
/// use smspace::kernel::{SensorNoise, TraceParams};
/// let p: TraceParams = toml::from_str("noise = 0.02").unwrap();
/// assert_eq!(p.noise, SensorNoise::Sigma(0.02));
/// let p: TraceParams = toml::from_str("noise = \"auto\"").unwrap();
/// assert_eq!(p.noise, SensorNoise::Auto);
/// assert!(toml::from_str::<TraceParams>("noise = \"foo\"").unwrap_err().to_string().contains("noise"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum SensorNoise {
    /// Read every start twice in one batch: readings equal to within
    /// `sensor_tolerance` of the largest one are exact (traced as
    /// exact, one sensor row more per set); otherwise the noise is measured from
    /// repeated readings.
    #[default]
    Auto,
    /// This standard deviation, in sensor units; `0` is exact readings.
    Sigma(f64),
}

impl SensorNoise {
    /// Whether it is `auto` (the default).
    pub fn is_auto(&self) -> bool {
        *self == SensorNoise::Auto
    }
}

impl Serialize for SensorNoise {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            SensorNoise::Auto => serializer.serialize_str("auto"),
            SensorNoise::Sigma(sigma) => serializer.serialize_f64(*sigma),
        }
    }
}

impl<'de> Deserialize<'de> for SensorNoise {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = SensorNoise;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("\"auto\" or a standard deviation ≥ 0 in sensor units")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<SensorNoise, E> {
                v.parse().map_err(E::custom)
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<SensorNoise, E> {
                Ok(SensorNoise::Sigma(v))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<SensorNoise, E> {
                Ok(SensorNoise::Sigma(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<SensorNoise, E> {
                Ok(SensorNoise::Sigma(v as f64))
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

impl std::str::FromStr for SensorNoise {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "auto" => Ok(SensorNoise::Auto),
            other => other.parse::<f64>().map(SensorNoise::Sigma).map_err(|_| {
                format!("invalid noise '{other}'; use \"auto\" or a standard deviation ≥ 0 in sensor units (0: exact readings)")
            }),
        }
    }
}

/// The noise of the readings of one set, as the `sensory` method measured (or was
/// given) it at the start (see the module docs, "Noisy sensors").
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetNoise {
    /// The standard deviation `σ` of a reading, pooled over the sensors (sensor
    /// units): measured from repeated readings at the start with `noise = "auto"`, or
    /// the `noise` given.
    pub sigma: f64,
    /// The position uncertainty `σ_pos` of a traced point (radians): `σ` over the
    /// smallest singular value `g` of the sensory Jacobian's `N − k` at the start and
    /// over the square root of the readings of one regression.
    pub position: f64,
    /// The offset `ρ` of the regressions (radians).
    pub stencil: f64,
    /// The repeats of every row of a regression.
    pub repeats: usize,
    /// The fraction of the traced curve that runs back over its own path (0 for a
    /// simple loop or segment; beyond [`MAX_DOUBLED`] the set is
    /// [`SetStatus::Retraced`](super::SetStatus::Retraced)); 0 when not traced.
    #[serde(default)]
    pub doubled: f64,
    /// Whether the first regression found a sensor that jumps between neighbouring
    /// postures (a rangefinder's ray past an obstacle's edge): such sensors are left
    /// out of the slope wherever they jump (see the module docs, "Noisy sensors").
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub discontinuous: bool,
}

/// The noise of the readings over the starts ([`SetNoise`] of every start read with
/// noise).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseSummary {
    /// Starts whose readings had noise.
    pub sets: usize,
    /// The median of their measured standard deviation `σ` (sensor units).
    pub sigma: f64,
    /// The median position uncertainty `σ_pos` of a traced point (radians).
    pub position: f64,
    /// Its largest value.
    pub max_position: f64,
}

/// Beyond this fraction of a curve traced from noisy readings running back over its
/// own path, the set is [`SetStatus::Retraced`](super::SetStatus::Retraced) and not
/// kept (the fraction of a simple loop is 0; of a trace turned round by noise,
/// 0.15–1).
pub const MAX_DOUBLED: f64 = 0.1;

/// Beyond this median position uncertainty (radians) the sets traced from noisy
/// readings are too blurred to trust, and the run says so.
pub const MAX_POSITION_UNCERTAINTY: f64 = 0.05;

impl NoiseSummary {
    /// The summary of the noise of `sets` (`None` when none had noise).
    pub fn of(sets: &[SetReport]) -> Option<Self> {
        let mut sigmas: Vec<f64> = sets
            .iter()
            .filter_map(|s| s.noise)
            .map(|n| n.sigma)
            .collect();
        let mut positions: Vec<f64> = sets
            .iter()
            .filter_map(|s| s.noise)
            .map(|n| n.position)
            .collect();
        if sigmas.is_empty() {
            return None;
        }
        sigmas.sort_by(f64::total_cmp);
        positions.sort_by(f64::total_cmp);
        Some(Self {
            sets: sigmas.len(),
            sigma: sigmas[sigmas.len() / 2],
            position: positions[positions.len() / 2],
            max_position: positions[positions.len() - 1],
        })
    }
}
