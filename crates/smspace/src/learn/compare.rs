//! Learned kernel sets measured against the true ones (simulated logs, where the truth
//! is known): per start, the Hausdorff distance between the two sets on the motor torus,
//! read so that the sampling of a set adds no error of its own to first order: curves
//! (`k = 1`) as polylines (the `curve` metric), surfaces of dimension `k ≥ 2` as their
//! points' tangent disks (the `surface` metric with that `k`). Sets of different
//! dimensions (a law whose rank differs from the truth's) are compared point to point
//! (`hausdorff`).

use serde::{Deserialize, Serialize};

use super::LearnError;
use crate::kernel::{Closure, TracedSets};
use crate::metric::{MetricKind, Periodicity, Periods, SetMetric, Surface, SurfaceParams};

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

/// The point metric's periods under which [`set_errors`] compares sets of motors with
/// these periods (`None`: not wrapped): `2pi` when every motor is a hinge, none when
/// none is, and one period per motor for a mix (hinges wrapped, bounded motors not).
pub fn comparison_period(periods: &[Option<f64>]) -> Result<Periodicity, LearnError> {
    Periods::new(periods.to_vec())
        .map(Periodicity::from)
        .map_err(|e| LearnError::Compare {
            reason: format!("the motors' periods cannot be compared under: {e}"),
        })
}

/// The Hausdorff distance between the learned and the true set of every start traced in
/// both (the same starts, the same point count), under the point metric `period`
/// ([`comparison_period`] of the motors). A curve that is a closed loop in both is read
/// as a loop, otherwise as an open polyline; see the module docs for surfaces.
pub fn set_errors(
    learned: &TracedSets,
    truth: &TracedSets,
    period: impl Into<Periodicity>,
) -> Result<SetErrors, LearnError> {
    let period = period.into();
    if learned.sets.dim().1 != truth.sets.dim().1 || learned.sets.dim().2 != truth.sets.dim().2 {
        return Err(LearnError::Compare {
            reason: format!(
                "the learned sets are {:?} and the true ones {:?}: trace both with the same points and motors",
                learned.sets.dim(),
                truth.sets.dim()
            ),
        });
    }
    let (learned_dims, truth_dims) = (learned.dimensions(), truth.dimensions());
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
        let metric = comparison_metric(
            (learned_dims[i], truth_dims[j]),
            &period,
            closure,
            learned.sets.dim().1,
        )?;
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

/// The metric that compares a learned set of dimension `dims.0` with a true one of
/// dimension `dims.1` (see the module docs), sets of `points` points.
fn comparison_metric(
    dims: (usize, usize),
    period: &Periodicity,
    closure: Closure,
    points: usize,
) -> Result<Box<dyn SetMetric>, LearnError> {
    Ok(match dims {
        (a, b) if a <= 1 && b <= 1 => MetricKind::Curve.with_period(period, closure),
        (a, b) if a == b => {
            let params = SurfaceParams {
                dimension: a,
                neighbours: (2 * a).max(8).min(points.saturating_sub(1)).max(a),
                ..SurfaceParams::default()
            };
            Box::new(
                Surface::new(params, period.clone()).map_err(|e| LearnError::Compare {
                    reason: e.to_string(),
                })?,
            )
        }
        _ => MetricKind::Hausdorff.with_period(period, closure),
    })
}
