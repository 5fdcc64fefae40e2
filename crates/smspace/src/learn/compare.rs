//! Learned kernel sets measured against the true ones (simulated logs, where the truth
//! is known): per start, the Hausdorff distance between the two sets read as polylines
//! on the motor torus (the `curve` metric, so that the sampling of 100 points along a
//! set adds no error of its own).

use serde::{Deserialize, Serialize};

use super::LearnError;
use crate::kernel::{Closure, TracedSets};
use crate::metric::{MetricKind, Period};

/// The set errors of one comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetErrors {
    /// Starts traced in both.
    pub compared: usize,
    /// Per compared start (in order of the motor rows): the Hausdorff distance
    /// (radians).
    pub per_set: Vec<f64>,
    /// Their median.
    pub median: f64,
    /// Their 90th percentile.
    pub p90: f64,
}

/// The one period under which [`set_errors`] compares sets of motors with these periods
/// (`None`: not wrapped): `2pi` when every motor is a hinge, none when none is; `None`
/// for a mix of both.
pub fn comparison_period(periods: &[Option<f64>]) -> Option<Period> {
    if periods
        .iter()
        .all(|p| p.is_some_and(|p| (p - std::f64::consts::TAU).abs() < 1e-12))
    {
        Some(Period::TwoPi)
    } else if periods.iter().all(Option::is_none) {
        Some(Period::None)
    } else {
        None
    }
}

/// The Hausdorff distance between the learned and the true set of every start traced in
/// both (the same starts, the same point count), under the point metric `period`. A
/// set that is a closed loop in both is read as a loop, otherwise as an open polyline.
pub fn set_errors(
    learned: &TracedSets,
    truth: &TracedSets,
    period: Period,
) -> Result<SetErrors, LearnError> {
    if learned.sets.dim().1 != truth.sets.dim().1 || learned.sets.dim().2 != truth.sets.dim().2 {
        return Err(LearnError::Compare {
            reason: format!(
                "the learned sets are {:?} and the true ones {:?}: trace both with the same points and motors",
                learned.sets.dim(),
                truth.sets.dim()
            ),
        });
    }
    let mut per_set = Vec::new();
    let mut j = 0;
    for (i, &row) in learned.kept.iter().enumerate() {
        while j < truth.kept.len() && truth.kept[j] < row {
            j += 1;
        }
        if j >= truth.kept.len() || truth.kept[j] != row {
            continue;
        }
        let closure =
            if learned.closure[i] == Closure::Closed && truth.closure[j] == Closure::Closed {
                Closure::Closed
            } else {
                Closure::Open
            };
        let metric = MetricKind::Curve.with_period(period, closure);
        let distance = metric
            .distance(
                learned.sets.index_axis(ndarray::Axis(0), i),
                truth.sets.index_axis(ndarray::Axis(0), j),
            )
            .map_err(|e| LearnError::Compare {
                reason: e.to_string(),
            })?;
        per_set.push(distance);
    }
    if per_set.is_empty() {
        return Err(LearnError::Compare {
            reason: "no start was traced in both".to_owned(),
        });
    }
    let mut sorted = per_set.clone();
    sorted.sort_by(f64::total_cmp);
    let quantile = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
    Ok(SetErrors {
        compared: per_set.len(),
        median: quantile(0.5),
        p90: quantile(0.9),
        per_set,
    })
}
