//! `distances`: the set metric between every pair of kernel sets (paper section 3.2,
//! step 3).

use std::path::Path;

use ndarray::Array2;
use serde::Serialize;

use super::{label, Keyed, Stage, StageContext, StageInput};
use crate::io::{self, IoError, Outputs};
use crate::kernel::TracedSets;
use crate::metric::{distance_matrix, DistanceParams, MetricKind, Period, SetsView};
use crate::pipeline::StageId;

/// The `distances` stage: the `[metric]` table's metric and period (its memory limit
/// is the run's, in the [`StageContext`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DistancesStage {
    /// The set metric.
    pub metric: MetricKind,
    /// The period of the motor coordinates.
    pub period: Period,
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
    type Output = Array2<f64>;

    fn compute(
        &self,
        input: &DistancesInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<Array2<f64>> {
        let params = DistanceParams::new()
            .metric(self.metric)
            .period(self.period)
            .memory_limit_bytes(context.memory_limit_bytes)
            .check()?;
        let traced = &input.traced.value;
        let sets = SetsView::new(traced.sets.view()).with_closure(&traced.closure);
        Ok(distance_matrix(sets, &params, context.progress)?)
    }

    fn save(
        &self,
        _: &DistancesInput<'_>,
        d: &Array2<f64>,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        outputs.npy(&dir.join(MATRIX_FILE), d)?;
        Ok(())
    }

    fn load(&self, input: &DistancesInput<'_>, dir: &Path) -> crate::Result<Array2<f64>> {
        let path = dir.join(MATRIX_FILE);
        let m = input.traced.kept.len();
        let d = io::read_matrix(&path, Some(m), "(M, M)")?;
        if d.nrows() != m {
            return Err(IoError::Shape {
                path,
                found: io::shape_string(d.shape()),
                expected: format!("({m}, {m}), one row per set of sets.npy"),
            }
            .into());
        }
        Ok(d)
    }

    fn summary(&self, d: &Array2<f64>) -> String {
        format!(
            "{0} × {0} matrix ({1}, period {2})",
            d.nrows(),
            label(&self.metric),
            label(&self.period)
        )
    }
}
