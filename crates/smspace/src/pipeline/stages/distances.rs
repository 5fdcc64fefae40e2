//! `distances`: the set metric between every pair of kernel sets (paper section 3.2,
//! step 3).

use std::path::Path;
use std::sync::Arc;

use serde::Serialize;

use super::{Keyed, Stage, StageContext, StageInput};
use crate::io::{IoError, Outputs};
use crate::kernel::TracedSets;
use crate::metric::{
    distance_matrix_with, BuiltMetric, DistanceMatrix, DistanceParams, MetricName, Periodicity,
    SetMetric, SetsView,
};
use crate::pipeline::StageId;
use crate::progress::Progress;

/// Where the `distances` stage computes its matrix: in this process
/// ([`LocalDistances`], what [`run`](crate::pipeline::run) uses) or elsewhere, e.g. on a
/// cluster's workers ([`run_with`](crate::pipeline::run_with); the Python package's
/// Dask backend). The stage's key does not depend on it, so every backend must return
/// the matrix [`distance_matrix_with`] returns, bit for bit (tiles do:
/// [`crate::metric::fill_tile`]).
pub trait DistanceBackend: Sync {
    /// The matrix of `stage`'s metric ([`DistancesStage::set_metric`], built from its
    /// `metric`, `period` and `params`) between `sets`, refusing a matrix above
    /// `memory_limit_bytes`, reporting to `progress`.
    fn distances(
        &self,
        stage: &DistancesStage,
        sets: SetsView<'_>,
        memory_limit_bytes: Option<u64>,
        progress: &dyn Progress,
    ) -> crate::Result<DistanceMatrix>;
}

/// The matrix in this process, on its threads ([`distance_matrix_with`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct LocalDistances;

impl DistanceBackend for LocalDistances {
    fn distances(
        &self,
        stage: &DistancesStage,
        sets: SetsView<'_>,
        memory_limit_bytes: Option<u64>,
        progress: &dyn Progress,
    ) -> crate::Result<DistanceMatrix> {
        let limit = DistanceParams::new().memory_limit_bytes(memory_limit_bytes);
        Ok(distance_matrix_with(
            sets,
            stage.set_metric(),
            &limit,
            progress,
        )?)
    }
}

/// The `distances` stage: the `[metric]` table's metric, period and parameters (its
/// memory limit is the run's, in the [`StageContext`]), and the metric they build
/// (built-in or registered, [`crate::metric::MetricRegistry`]).
#[derive(Clone, Serialize)]
pub struct DistancesStage {
    /// The set metric's name.
    pub metric: MetricName,
    /// The period of the motor coordinates (resolved: never `"motors"`).
    pub period: Periodicity,
    /// The metric's own parameters (`[metric.params]`; none for the built-in ones).
    #[serde(skip_serializing_if = "toml::Table::is_empty")]
    pub params: toml::Table,
    /// The metric built from the fields above.
    #[serde(skip)]
    set_metric: Arc<dyn SetMetric>,
}

impl DistancesStage {
    /// The stage of a metric built from its `[metric]` table.
    pub fn new(built: &BuiltMetric) -> Self {
        Self {
            metric: built.params.metric.clone(),
            period: built.params.period.clone(),
            params: built.params.params.clone(),
            set_metric: built.metric.clone(),
        }
    }

    /// The metric built from the stage's fields.
    pub fn set_metric(&self) -> &dyn SetMetric {
        self.set_metric.as_ref()
    }
}

impl std::fmt::Debug for DistancesStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DistancesStage")
            .field("metric", &self.metric)
            .field("period", &self.period)
            .field("params", &self.params)
            .finish()
    }
}

/// What `distances` reads.
#[derive(Debug, Clone, Copy)]
pub struct DistancesInput<'a> {
    /// The kernel sets and which of them are closed loops.
    pub traced: &'a Keyed<TracedSets>,
}

impl StageInput for DistancesInput<'_> {
    fn keys(&self) -> Vec<&str> {
        vec![&self.traced.key]
    }
}

const MATRIX_FILE: &str = "D.npy";

impl Stage for DistancesStage {
    const ID: StageId = StageId::Distances;
    type Input<'a> = DistancesInput<'a>;
    type Output = DistanceMatrix;

    fn compute(
        &self,
        input: &DistancesInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<DistanceMatrix> {
        let traced = &input.traced.value;
        if self.metric.kind() == Some(crate::metric::MetricKind::Curve) {
            // Spatial sets are read slice by slice (`kernel::spatial`): polylines when
            // the traced kernels are curves.
            let k = crate::kernel::spatial::curve_dimension(&traced.report);
            crate::kernel::check_curve_metric(k).map_err(crate::metric::MetricError::Invalid)?;
            crate::kernel::spatial::check_slices(traced)?;
        }
        let sets = SetsView::new(traced.sets.view())
            .with_closure(&traced.closure)
            .with_pieces(traced.pieces.view());
        context
            .distances
            .distances(self, sets, context.memory_limit_bytes, context.progress)
    }

    fn save(
        &self,
        _: &DistancesInput<'_>,
        d: &DistanceMatrix,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        d.write_into(outputs, &dir.join(MATRIX_FILE))?;
        Ok(())
    }

    fn load(&self, input: &DistancesInput<'_>, dir: &Path) -> crate::Result<DistanceMatrix> {
        let path = dir.join(MATRIX_FILE);
        let m = input.traced.kept.len();
        let d = DistanceMatrix::load(&path).map_err(crate::metric::MetricError::from)?;
        if d.len() != m {
            return Err(IoError::Shape {
                path,
                found: crate::io::shape_string(d.shape()),
                expected: format!("({m}, {m}), one row per set of sets.npy"),
            }
            .into());
        }
        Ok(d)
    }

    /// For kernels of dimension `k ≥ 2` (surfaces sampled by `P` points) under a metric
    /// other than `curve` (which reads spatial sets as polylines): the point metric
    /// between two of them compares every point with every point, almost without
    /// the early exits that make loops fast, about `M (M − 1) P²` point distances in
    /// all; said with the time it takes at `SURFACE_POINT_DISTANCES_PER_CORE_SECOND`
    /// when it exceeds about a minute on one core.
    fn forecast(&self, input: &DistancesInput<'_>) -> Option<String> {
        let traced = &input.traced.value;
        if self.metric.kind() == Some(crate::metric::MetricKind::Curve) {
            // The curve metric reads spatial sets slice by slice, as polylines.
            return None;
        }
        let k = traced.dimensions().into_iter().max().unwrap_or(0);
        let (m, p, _) = traced.sets.dim();
        surface_forecast(k, m, p)
    }

    fn summary(&self, d: &DistanceMatrix) -> String {
        format!(
            "{0} × {0} matrix ({1}, period {2})",
            d.len(),
            self.metric,
            self.period
        )
    }
}

/// Point distances per second and core of the point metric between surfaces sampled
/// farthest first (almost no early exits): measured on the 1288 sets of 150 points of
/// `experiments/planar-arm-5.toml` (`smspace distances --metric hausdorff`, release,
/// AVX2 path): 3.7·10¹⁰ point distances in 23.1 s of CPU, 1.6·10⁹ per core-second.
pub const SURFACE_POINT_DISTANCES_PER_CORE_SECOND: f64 = 1.6e9;

/// The forecast of [`DistancesStage::forecast`] for `m` sets of `p` points of kernels
/// of dimension `k`: `None` for points and curves, and below a minute of one core.
fn surface_forecast(k: usize, m: usize, p: usize) -> Option<String> {
    if k < 2 || m < 2 {
        return None;
    }
    let work = m as f64 * (m as f64 - 1.0) * (p as f64) * (p as f64);
    let core_seconds = work / SURFACE_POINT_DISTANCES_PER_CORE_SECOND;
    if core_seconds < 60.0 {
        return None;
    }
    let cores = rayon::current_num_threads().max(1) as f64;
    Some(format!(
        "the kernels are {k}-D surfaces: the point metric compares each of their {p} points with each of the other set's, with few early exits: about {work:.1e} point distances for {m} sets, roughly {:.0} min on {cores} threads (about {:.0} core-minutes); lower exploration.n or kernel.points to shorten it",
        core_seconds / cores / 60.0,
        core_seconds / 60.0
    ))
}

#[cfg(test)]
mod tests {
    use super::surface_forecast;

    #[test]
    fn surfaces_are_forecast_and_curves_are_not() {
        assert_eq!(surface_forecast(1, 100_000, 100), None);
        assert_eq!(surface_forecast(2, 10, 20), None);
        let note = surface_forecast(2, 3500, 200).unwrap();
        assert!(
            note.contains("2-D surfaces") && note.contains("3500 sets"),
            "{note}"
        );
        assert!(note.contains("kernel.points"), "{note}");
    }
}
