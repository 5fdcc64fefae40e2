//! The noise of the sensors the `sensory` method reads: the `[kernel] sensor_sigma` parameter
//! and what is reported of the noise, per set and over the starts (the level set of
//! noisy readings is in `noisy.rs`; the maths in the module docs of [`super`],
//! "Noisy sensors").

use serde::{Deserialize, Serialize};

use super::SetReport;

/// The noise of the sensors the `sensory` method reads (`[kernel] sensor_sigma`):
/// `"auto"` or a standard deviation in sensor units. Noisy readings are traced on the
/// level set of their mean (see the module docs, "Noisy sensors").
///
/// ```
/// use smspace::kernel::{SensorNoise, TraceParams};
/// let p: TraceParams = toml::from_str("sensor_sigma = 0.02").unwrap();
/// assert_eq!(p.noise, SensorNoise::Sigma(0.02));
/// let p: TraceParams = toml::from_str("sensor_sigma = \"auto\"").unwrap();
/// assert_eq!(p.noise, SensorNoise::Auto);
/// assert!(toml::from_str::<TraceParams>("sensor_sigma = \"foo\"").unwrap_err().to_string().contains("auto"));
/// // The key's old name is refused with the new one.
/// let old: TraceParams = toml::from_str("noise = 0.02").unwrap();
/// assert!(old.check().unwrap_err().to_string().contains("sensor_sigma = 0.02"));
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
                format!("invalid sensor_sigma '{other}'; use \"auto\" or a standard deviation ≥ 0 in sensor units (0: exact readings)")
            }),
        }
    }
}

/// The noise of the readings of one set, as the `sensory` method measured (or was
/// given) it at the start (see the module docs, "Noisy sensors").
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetNoise {
    /// The standard deviation `σ` of a reading, pooled over the sensors (sensor
    /// units): measured from repeated readings at the start with `sensor_sigma = "auto"`, or
    /// the `sensor_sigma` given.
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

/// Above this forecast of sensor rows per set, the sensory trace of noisy readings
/// recommends the learned route instead ([`NoiseForecast::recommendation`]): a law
/// learned from babbling the agent within a budget of rows (`method = "learned"` with
/// a `budget`), whose sets cost no further row.
pub const LEARNED_ROUTE_ROWS: u64 = 20_000;

/// Starts probed for the forecast of noisy readings ([`NoiseForecast`]): the first
/// ones, or all when there are fewer.
pub const FORECAST_STARTS: usize = 3;

/// Regressions of one predictor–corrector step of a noisy trace, forecast: one where
/// the predicted point lands, and a second when its residual is above the tolerance
/// (about every other step; rejected and halved steps come on top, rarely). Measured:
/// 1.36 on the redundant toy at 1 % noise (4 sets).
const STEP_REGRESSIONS: f64 = 1.5;
/// Regressions of one resampled point (the same corrector, from the Hermite curve;
/// measured 1.33 on the toy).
const POINT_REGRESSIONS: f64 = 1.5;
/// Regressions of one seed of the piece search, forecast: a seed settles next to the
/// piece found in about this many damped Gauss–Newton iterations, each a regression
/// (measured 10.6 on the toy).
const SEED_REGRESSIONS: f64 = 10.0;

/// What tracing noisy readings by the sensory method will cost, forecast before the
/// sets are traced from the noise measured at the first [`FORECAST_STARTS`] starts
/// (see the module docs of [`super`], "Noisy sensors", and `noisy.rs`).
///
/// Every point a noisy trace visits is one regression of `r (3N + 1)` rows (the centre
/// read `N + 1` times and the `2N` rows `m ± ρ e_j`, all repeated `r` times, `r` from
/// the noise `σ` and the slope `g` at the start). A set of dimension `k = 1` visits
/// about `1.5 L / max_step` points following the curve (one or two regressions a step;
/// `L` the curve's length, forecast as the diagonal of the motor space
/// `√(Σ_j range_j²)`, the steps at `max_step`), `1.5 P` resampling it and 10 per seed
/// of the piece search;
/// its start reads the first regression of `16 (3N + 1)` rows (twice with sensors
/// that jump) and the target of `4 r (3N + 1)`. Sets of dimension 0 have no curve nor
/// resampling; a k-D covering visits `2k` points per node of its forecast covering.
/// On the redundant toy at 1 % noise (the test of this forecast) the forecast was 1.28
/// times the rows spent (12 450 against a mean of 9 763 over 4 sets) with the
/// constants at 2, 2 and 8.
///
/// Two forecasts are equal when everything but the measured rate and the time at it
/// is (the rate is the agent's speed on this run, which no setting decides).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NoiseForecast {
    /// Starts whose readings were probed for the forecast.
    pub starts_probed: usize,
    /// Of those, the starts whose readings had noise.
    pub noisy_starts: usize,
    /// The median measured (or given) `σ` over the noisy starts (sensor units).
    pub sigma: f64,
    /// The median repeats `r` of a regression over the noisy starts.
    pub repeats: usize,
    /// Rows of one regression, `r (3N + 1)`.
    pub rows_per_regression: u64,
    /// Regressions (points visited) forecast per set.
    pub regressions_per_set: u64,
    /// Sensor rows forecast per set (the start's included).
    pub rows_per_set: u64,
    /// Sensor rows forecast for all the sets.
    pub rows_total: u64,
    /// The agent's rate measured while the starts were probed (rows per second of wall
    /// time); `None` when too fast to time.
    pub rows_per_second: Option<f64>,
    /// `rows_total` at that rate, seconds.
    pub seconds_at_measured_rate: Option<f64>,
    /// What to do instead, when `rows_per_set` exceeds [`LEARNED_ROUTE_ROWS`].
    pub recommendation: Option<String>,
}

/// What a forecast knows of the tracing call: the motors, sensors, kernel dimension
/// and the parameters that set the points visited.
pub(crate) struct ForecastShape {
    /// Motors `N`.
    pub motors: usize,
    /// The kernel dimension `k`.
    pub dimension: usize,
    /// The diagonal of the motor space, `√(Σ_j range_j²)` (radians).
    pub diagonal: f64,
    /// `[kernel] max_step`.
    pub max_step: f64,
    /// `[kernel] points`.
    pub points: usize,
    /// `[kernel] piece_starts`.
    pub piece_starts: usize,
    /// Nodes of a k-D covering, forecast (`cover.rs`); 0 for curves and points.
    pub covering_nodes: f64,
    /// Sets to trace.
    pub sets: usize,
}

/// One probed start: its noise (`None` for exact readings) and the rows its start
/// read.
pub(crate) struct ProbedStart {
    pub noise: Option<SetNoise>,
    pub start_rows: u64,
    /// The start's reading when its readings are exact.
    pub exact_reading: Option<Vec<f64>>,
}

impl PartialEq for NoiseForecast {
    fn eq(&self, other: &Self) -> bool {
        let timeless = |f: &Self| {
            (
                f.starts_probed,
                f.noisy_starts,
                f.sigma,
                f.repeats,
                f.rows_per_regression,
                f.regressions_per_set,
                f.rows_per_set,
                f.rows_total,
                f.recommendation.clone(),
            )
        };
        timeless(self) == timeless(other)
    }
}

impl NoiseForecast {
    /// The forecast from the probed starts, `None` when no start had noise.
    /// `seconds` is the wall time the probes took.
    pub(crate) fn of(probed: &[ProbedStart], shape: &ForecastShape, seconds: f64) -> Option<Self> {
        let noisy: Vec<(&SetNoise, u64)> = probed
            .iter()
            .filter_map(|p| p.noise.as_ref().map(|n| (n, p.start_rows)))
            .collect();
        if noisy.is_empty() {
            return None;
        }
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let sigma = median(noisy.iter().map(|(n, _)| n.sigma).collect());
        let repeats = median(noisy.iter().map(|(n, _)| n.repeats as f64).collect()) as usize;
        let start_rows = median(noisy.iter().map(|(_, rows)| *rows as f64).collect());
        let rows_per_regression = (repeats * (3 * shape.motors + 1)) as u64;
        let regressions = shape.regressions();
        let rows_per_set = (start_rows + regressions * rows_per_regression as f64).round() as u64;
        let rows_total = rows_per_set.saturating_mul(shape.sets as u64);
        let read: u64 = probed.iter().map(|p| p.start_rows).sum();
        let rows_per_second = (seconds > 0.0 && read > 0).then(|| read as f64 / seconds);
        let seconds_at_measured_rate = rows_per_second.map(|rate| rows_total as f64 / rate);
        let recommendation = (rows_per_set > LEARNED_ROUTE_ROWS).then(|| {
            format!(
                "learn the law instead: method = \"learned\" with a budget of sensor rows (in Python smspace.trace(agent, starts, method=\"learned\", budget=ROWS)), e.g. a budget of {rows_per_set} rows, one set's forecast here, for the law of all the sets"
            )
        });
        Some(Self {
            starts_probed: probed.len(),
            noisy_starts: noisy.len(),
            sigma,
            repeats,
            rows_per_regression,
            regressions_per_set: regressions.round() as u64,
            rows_per_set,
            rows_total,
            rows_per_second,
            seconds_at_measured_rate,
            recommendation,
        })
    }

    /// The warning of the trace summary when the forecast is above
    /// [`LEARNED_ROUTE_ROWS`] rows per set.
    pub fn warning(&self) -> Option<String> {
        self.recommendation.as_ref().map(|_| self.to_string())
    }
}

impl ForecastShape {
    /// Regressions (points visited) forecast per set, the start's aside (see
    /// [`NoiseForecast`]).
    fn regressions(&self) -> f64 {
        let seeds = SEED_REGRESSIONS * self.piece_starts as f64;
        match self.dimension {
            0 => seeds,
            1 => {
                let steps = self.diagonal / self.max_step;
                STEP_REGRESSIONS * steps + POINT_REGRESSIONS * self.points as f64 + seeds
            }
            k => 2.0 * k as f64 * self.covering_nodes + seeds,
        }
    }
}

impl std::fmt::Display for NoiseForecast {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the sensors are noisy (σ = {:.3e} sensor units at {} of {} starts probed): every point a set visits is a regression of {} sensor rows ({} repeats), so tracing is forecast at {} sensor rows per set, {} in all",
            self.sigma,
            self.noisy_starts,
            self.starts_probed,
            self.rows_per_regression,
            self.repeats,
            self.rows_per_set,
            self.rows_total
        )?;
        if let (Some(rate), Some(seconds)) = (self.rows_per_second, self.seconds_at_measured_rate) {
            write!(
                f,
                " ({} at the agent's measured {rate:.0} rows/s)",
                crate::progress::human_duration(seconds)
            )?;
        }
        if let Some(recommendation) = &self.recommendation {
            write!(
                f,
                "; above {LEARNED_ROUTE_ROWS} rows per set, {recommendation}"
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::{Agent, AgentConfig, EnvironmentConfig, NoiseParams, NoisyAgent};
    use crate::kernel::{trace_sets, TraceMethod, TraceParams};
    use crate::progress::Silent;

    #[test]
    fn the_noise_forecast_is_within_a_factor_two_of_the_rows_spent() {
        let toy = AgentConfig::preset("toy-redundant")
            .unwrap()
            .build()
            .unwrap();
        let noise = NoiseParams {
            relative: 0.01,
            sigma: 0.0,
            seed: 3,
        };
        let agent = NoisyAgent::new(toy, noise).unwrap();
        let environment = EnvironmentConfig::default().build(&agent).unwrap();
        let motors = ndarray::array![[0.5, 0.25], [-1.0, 0.5], [1.0, -1.5], [0.2, 0.9]];
        let params = TraceParams {
            method: TraceMethod::Sensory,
            points: 50,
            ..TraceParams::default()
        }
        .check()
        .unwrap();
        let traced = trace_sets(
            &agent,
            Some(&environment),
            motors.view(),
            None,
            &params,
            &Silent,
        )
        .unwrap();
        let summary = &traced.report.summary;
        let forecast = summary
            .noise_forecast
            .clone()
            .expect("noisy readings are forecast");
        assert_eq!((forecast.starts_probed, forecast.noisy_starts), (3, 3));
        assert_eq!(forecast.rows_total, 4 * forecast.rows_per_set);
        let spent: Vec<u64> = traced.report.sets.iter().map(|s| s.sensor_rows).collect();
        let mean = spent.iter().sum::<u64>() as f64 / spent.len() as f64;
        let ratio = forecast.rows_per_set as f64 / mean;
        assert!(
            (0.5..=2.0).contains(&ratio),
            "forecast {} rows per set, spent {spent:?}",
            forecast.rows_per_set
        );
        // The recommendation and the summary's warning follow the threshold.
        let above = forecast.rows_per_set > LEARNED_ROUTE_ROWS;
        assert_eq!(forecast.recommendation.is_some(), above);
        let warned = summary
            .warnings()
            .iter()
            .any(|w| w.contains("method = \"learned\""));
        assert_eq!(warned, above);
        let shape = ForecastShape {
            motors: agent.motor_dim(),
            dimension: 1,
            diagonal: 1.0,
            max_step: 1.0,
            points: 0,
            piece_starts: 0,
            covering_nodes: 0.0,
            sets: 1,
        };
        let probed = [ProbedStart {
            noise: Some(SetNoise {
                sigma: 0.1,
                repeats: 64,
                ..SetNoise::default()
            }),
            start_rows: 10 * LEARNED_ROUTE_ROWS,
            exact_reading: None,
        }];
        let costly = NoiseForecast::of(&probed, &shape, 2.0).unwrap();
        assert!(costly.recommendation.is_some());
        assert_eq!(
            costly.seconds_at_measured_rate,
            Some(2.0 * costly.rows_total as f64 / (10 * LEARNED_ROUTE_ROWS) as f64)
        );
        assert!(costly.warning().unwrap().contains("budget"));
        // Exact readings are not forecast.
        let exact = AgentConfig::preset("toy-redundant")
            .unwrap()
            .build()
            .unwrap();
        let traced = trace_sets(
            exact.as_ref(),
            Some(&environment),
            motors.view(),
            None,
            &params,
            &Silent,
        )
        .unwrap();
        assert!(traced.report.summary.noise_forecast.is_none());
    }
}
