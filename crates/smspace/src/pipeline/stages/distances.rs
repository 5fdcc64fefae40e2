//! `distances`: the set metric between every pair of kernel sets (paper section 3.2,
//! step 3).

use std::path::Path;
use std::sync::Arc;

use serde::Serialize;

use super::{label, Keyed, Stage, StageContext, StageInput};
use crate::io::{IoError, Outputs};
use crate::kernel::TracedSets;
use crate::metric::{
    distance_matrix_with, BuiltMetric, DistanceMatrix, DistanceParams, MetricName, Period,
    SetMetric, SetsView,
};
use crate::pipeline::StageId;

/// The `distances` stage: the `[metric]` table's metric, period and parameters (its
/// memory limit is the run's, in the [`StageContext`]), and the metric they build
/// (built-in or registered, [`crate::metric::MetricRegistry`]).
#[derive(Clone, Serialize)]
pub struct DistancesStage {
    /// The set metric's name.
    pub metric: MetricName,
    /// The period of the motor coordinates.
    pub period: Period,
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
            period: built.params.period,
            params: built.params.params.clone(),
            set_metric: built.metric.clone(),
        }
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
        let limit = DistanceParams::new().memory_limit_bytes(context.memory_limit_bytes);
        let traced = &input.traced.value;
        if self.metric.kind() == Some(crate::metric::MetricKind::Curve) {
            let k = traced.dimensions().into_iter().max().unwrap_or(0);
            crate::kernel::check_curve_metric(k).map_err(crate::metric::MetricError::Invalid)?;
        }
        let sets = SetsView::new(traced.sets.view())
            .with_closure(&traced.closure)
            .with_pieces(traced.pieces.view());
        Ok(distance_matrix_with(
            sets,
            self.set_metric.as_ref(),
            &limit,
            context.progress,
        )?)
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

    fn summary(&self, d: &DistanceMatrix) -> String {
        format!(
            "{0} × {0} matrix ({1}, period {2})",
            d.len(),
            self.metric,
            label(&self.period)
        )
    }
}
