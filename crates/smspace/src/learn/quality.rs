//! The law's quality without the truth: figures a user can read from the log alone, and
//! warnings when the data cannot support what was found, each saying what would help.
//!
//! - **Samples per dimension** `S_f^{1/d}`: the fitted samples `S_f` of a log spread over
//!   the dimension `d` the method must resolve. For `invariants` the pairs are nearest
//!   neighbours in sensor space, whose manifold has the dimension `r` of the law's rank
//!   (`rank`: the data's, or the invariants' where lower); for the local fits, the fits
//!   live in motor space, `d = N`. Below
//!   [`MIN_SAMPLES_PER_DIMENSION`] the neighbours are too far apart to share their
//!   invariants (or the fits to follow the law): warned, with the samples that would
//!   reach it, `MIN_SAMPLES_PER_DIMENSION^d`.
//! - **Neighbour change** (`invariants`): `√λ_h`, `λ_h` the mean `E[(z_i − z_j)²]` of
//!   the kept invariants (unit variance) between a held-out sample and its nearest fitted
//!   sample in sensor space: the root mean square change of an invariant between
//!   sensory neighbours, relative to its spread (0 for exact invariants, `√2` for a
//!   function unrelated to the sensors). Its **ratio** `λ_h / λ_f` to the same on the
//!   fitted pairs is near 1 when the invariants generalise; above
//!   [`MAX_HELD_OUT_RATIO`] (and `λ_h > 0.01`) they fit the log's own pairs: warned.
//! - **Held-out error** (`invariants`): the error of `ŝ = g(z)` on the held-out samples,
//!   relative to the sensors' spread (in each log's report); above
//!   [`MAX_HELD_OUT_ERROR`] the invariants do not tell apart poses the sensors do:
//!   warned.
//! - **Closure rate** (after tracing, [`LawReport::with_trace`]): the share of the sets
//!   traced as curves that closed (a loop back to its start, or a segment ending on
//!   the bounds of bounded motors): `(closed + open + pieces) / (total − point −
//!   covered − cover-budget)` ([`TraceSummary::curve_closure_rate`]), none when the
//!   kernels are not curves (surfaces have no closure). A law whose level sets wander
//!   does not close them; below [`MIN_CLOSURE_RATE`] it is warned.
//!
//! The held-out error of the sensor values and the noise estimate are in each log's
//! report; their warnings come with the law's own.

use serde::{Deserialize, Serialize};

use super::law::LawReport;
use super::LawMethod;
use crate::kernel::TraceSummary;

/// Fewest fitted samples per dimension of what the method resolves (see the module
/// docs) before a warning: 40 (64 000 samples for a sensory manifold of dimension 3).
pub const MIN_SAMPLES_PER_DIMENSION: f64 = 40.0;

/// Largest ratio of the invariants' change between held-out sensory neighbours to that
/// between fitted ones before a warning: 2.
pub const MAX_HELD_OUT_RATIO: f64 = 2.0;

/// Largest held-out error of the `invariants` law's sensor values `ŝ = g(z)`, relative
/// to the sensors' spread, before a warning: 0.25 (on nine retina laws of the 4-motor
/// arm whose learned sets are within 0.02 rad of the truth it is 0.06 to 0.13; on the
/// laws whose sets are wrong, 0.27 to 0.64).
pub const MAX_HELD_OUT_ERROR: f64 = 0.25;

/// Smallest share of traced curves that close before a warning: 0.5.
pub const MIN_CLOSURE_RATE: f64 = 0.5;

/// The law's quality without the truth (see the module docs).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct LawQuality {
    /// Fitted samples of the first log per dimension it must resolve, `S_f^{1/d}`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples_per_dimension: Option<f64>,
    /// That dimension `d`: the rank in the data for `invariants`, `N` for the local
    /// fits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resolved_dimension: Option<usize>,
    /// `invariants`: the root mean square change of an invariant between a held-out
    /// sample and its nearest fitted sensory neighbour, relative to its spread (`√λ`
    /// held out; 0 exact, `√2` unrelated).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub neighbour_change: Option<f64>,
    /// `invariants`: `λ` held out over `λ` fitted (near 1 when the invariants
    /// generalise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_ratio: Option<f64>,
    /// After tracing: the share of the sets traced as curves that closed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub closure_rate: Option<f64>,
}

/// The quality figures of `report` (before tracing) and the warnings they raise.
pub(super) fn assess(report: &LawReport, n: usize) -> (LawQuality, Vec<String>) {
    let mut quality = LawQuality::default();
    let mut warnings = Vec::new();
    let dimension = match report.method {
        LawMethod::Invariants => report.rank,
        LawMethod::LocalLinear | LawMethod::LocalQuadratic => n,
    };
    if let Some(first) = report.logs.first().filter(|_| dimension > 0) {
        let per = (first.fitted as f64).powf(1.0 / dimension as f64);
        quality.samples_per_dimension = Some(per);
        quality.resolved_dimension = Some(dimension);
        if per < MIN_SAMPLES_PER_DIMENSION {
            let wanted = MIN_SAMPLES_PER_DIMENSION.powi(dimension as i32);
            let what = match report.method {
                LawMethod::Invariants => {
                    format!("a sensory manifold of dimension {dimension} (the law's rank)")
                }
                _ => format!("the {dimension} motors the local fits span"),
            };
            warnings.push(format!(
                "{}: {} fitted samples are {per:.0} per dimension of {what}, fewer than {MIN_SAMPLES_PER_DIMENSION:.0}: neighbouring samples are too far apart for the law to resolve it, and the kernel sets are unreliable; record about {:.0} samples ({:.0}× more)",
                first.motors,
                first.fitted,
                wanted.ceil(),
                (wanted / first.fitted as f64).ceil()
            ));
        }
    }
    if let Some(found) = &report.invariants {
        for log in report
            .logs
            .iter()
            .filter(|log| log.held_out_relative_rms > MAX_HELD_OUT_ERROR)
        {
            warnings.push(format!(
                "{}: the invariants predict held-out readings with an error of {:.0} % of the sensors' spread (at most {:.0} % where the learned sets follow the true ones): samples whose readings are nearest are often far apart in pose ({:.0} % of the held-out pairs set aside as aliased), so the invariants miss part of the pose and the kernel sets are likely wrong; record more samples, or add sensors that tell those poses apart",
                log.motors,
                100.0 * log.held_out_relative_rms,
                100.0 * MAX_HELD_OUT_ERROR,
                100.0 * found.held_out_aliased.unwrap_or(0.0)
            ));
        }
        if let Some(held) = found.held_out_lambda {
            quality.neighbour_change = Some(held.max(0.0).sqrt());
            let ratio = held / found.fitted_lambda.max(f64::MIN_POSITIVE);
            quality.held_out_ratio = Some(ratio);
            if ratio > MAX_HELD_OUT_RATIO && held > 0.01 {
                warnings.push(format!(
                    "the invariants change {ratio:.1}× more between held-out sensory neighbours than between the fitted ones (λ {held:.3} against {:.3}): the {} basis functions fit the log's own pairs rather than the sensors' law; record more samples, or keep fewer invariants (invariants = …)",
                    found.fitted_lambda, found.features
                ));
            }
        }
    }
    (quality, warnings)
}

impl LawReport {
    /// This report completed with what tracing on the law showed: the closure rate of
    /// `summary` ([`LawQuality::closure_rate`]) and, when it is low, a warning with
    /// what would help.
    pub fn with_trace(&self, summary: &TraceSummary) -> LawReport {
        let mut report = self.clone();
        report.quality.closure_rate = summary.closure_rate;
        if let Some(rate) = report.quality.closure_rate {
            if rate < MIN_CLOSURE_RATE {
                let other = match report.method {
                    LawMethod::Invariants => "",
                    _ => ", or try method = invariants",
                };
                report.warnings.push(format!(
                    "only {:.0} % of the traced curves closed (statuses {:?}): the law's level sets wander instead of returning to their start, where the data are too sparse or too noisy; record more samples{other} (a looser closure_tolerance only hides it)",
                    100.0 * rate,
                    summary.by_status
                ));
            }
        }
        report
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_closure_rate_counts_curves_that_end_well() {
        let mut summary = TraceSummary {
            total: 10,
            ..TraceSummary::default()
        };
        for (status, count) in [("closed", 6), ("open", 1), ("not-closed", 2), ("point", 1)] {
            summary.by_status.insert(status.to_owned(), count);
        }
        assert_eq!(summary.curve_closure_rate(), Some(7.0 / 9.0));
        let points = TraceSummary {
            total: 3,
            by_status: [("point".to_owned(), 3)].into_iter().collect(),
            ..TraceSummary::default()
        };
        assert_eq!(points.curve_closure_rate(), None);
    }

    /// An `invariants` report of a log of `fitted` samples, rank 3, with the `λ` of the
    /// fitted pairs and of the held-out samples.
    fn report(fitted: usize, fitted_lambda: f64, held_out_lambda: f64) -> LawReport {
        serde_json::from_value(serde_json::json!({
            "method": "invariants",
            "logs": [{
                "motors": "m.npy", "sensors": "s.npy", "samples": fitted + 100,
                "fitted": fitted, "held_out": 100, "bandwidth": 0.2,
                "images_per_sample": 2.0, "held_out_relative_rms": 0.01,
                "held_out_max_abs": 0.05, "held_out_uncovered": 0
            }],
            "rank": 3,
            "rank_counts": [0, 0, 0, 512, 0],
            "invariants": {
                "features": 80, "invariants": 9, "threshold": 0.4,
                "eigenvalues": [0.01, 0.02], "pairs": fitted, "kept_pairs": fitted,
                "fitted_lambda": fitted_lambda, "held_out_lambda": held_out_lambda
            }
        }))
        .unwrap()
    }

    #[test]
    fn invariants_that_do_not_predict_the_readings_are_warned() {
        let mut poor = report(1_000_000, 0.04, 0.05);
        let (_, warnings) = assess(&poor, 4);
        assert!(warnings.is_empty(), "{warnings:?}");
        poor.logs[0].held_out_relative_rms = 0.6;
        let (_, warnings) = assess(&poor, 4);
        assert!(
            warnings.len() == 1
                && warnings[0].contains("60 %")
                && warnings[0].contains("add sensors"),
            "{warnings:?}"
        );
    }

    #[test]
    fn invariants_that_do_not_generalise_are_warned() {
        let (quality, warnings) = assess(&report(1_000_000, 0.04, 0.05), 4);
        assert!(warnings.is_empty(), "{warnings:?}");
        let per = quality.samples_per_dimension.unwrap();
        approx::assert_relative_eq!(per, 100.0, max_relative = 1e-12);
        assert_eq!(quality.resolved_dimension, Some(3));
        approx::assert_relative_eq!(quality.neighbour_change.unwrap(), 0.05f64.sqrt());
        approx::assert_relative_eq!(quality.held_out_ratio.unwrap(), 1.25);
        // Held-out neighbours change 5× more than fitted ones.
        let (_, warnings) = assess(&report(1_000_000, 0.04, 0.2), 4);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(warnings[0].contains("5.0× more"), "{warnings:?}");
        assert!(warnings[0].contains("record more samples"), "{warnings:?}");
        // Too few samples for a 3-D sensory manifold: 20 per dimension.
        let (quality, warnings) = assess(&report(8000, 0.04, 0.05), 4);
        approx::assert_relative_eq!(
            quality.samples_per_dimension.unwrap(),
            20.0,
            max_relative = 1e-12
        );
        assert!(
            warnings[0].contains("record about 64000 samples (8× more)"),
            "{warnings:?}"
        );
    }
}
