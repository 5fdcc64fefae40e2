//! `invariance`: the first babbled starts traced with the sensory method in every
//! environment and compared (paper sections 2.2, 2.3, 3.3; [`smspace::invariance`]).

use std::path::Path;
use std::sync::Arc;

use ndarray::Axis;
use serde::Serialize;

use super::{Keyed, Stage, StageContext, StageInput, World};
use crate::manifest::StageId;
use crate::report::InvarianceData;
use smspace::explore::Exploration;
use smspace::invariance::{invariance_measured, read_invariance, stage_invariance};
use smspace::io::Outputs;
use smspace::kernel::TraceParams;
use smspace::metric::{BuiltMetric, MetricName, Periodicity, SetMetric};

/// The `invariance` stage: the `[kernel]` table traced with the sensory method, the
/// number of starts (`[analysis] invariance_starts`) and the metric the `[metric]`
/// table builds (built-in or registered, under its resolved period), the same as the
/// distances stage's.
#[derive(Clone, Serialize)]
pub struct InvarianceStage {
    /// Tracing parameters (the method is `sensory`).
    pub kernel: TraceParams,
    /// The first this many babbled rows are the starts.
    pub starts: usize,
    /// The set metric's name.
    pub metric: MetricName,
    /// The period of the motor coordinates it measures under.
    pub period: Periodicity,
    /// The metric's own parameters (`[metric.params]`, resolved).
    pub params: toml::Table,
    /// The metric.
    #[serde(skip)]
    set_metric: Arc<dyn SetMetric>,
}

impl InvarianceStage {
    /// The stage comparing `starts` starts traced with `kernel` under the metric
    /// `built`.
    pub fn new(kernel: TraceParams, starts: usize, built: &BuiltMetric) -> Self {
        Self {
            kernel,
            starts,
            metric: built.params.metric.clone(),
            period: built.params.period.clone(),
            params: built.params.params.clone(),
            set_metric: built.metric.clone(),
        }
    }
}

impl std::fmt::Debug for InvarianceStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InvarianceStage")
            .field("kernel", &self.kernel)
            .field("starts", &self.starts)
            .field("metric", &self.metric)
            .field("period", &self.period)
            .field("params", &self.params)
            .finish()
    }
}

/// What `invariance` reads.
#[derive(Debug, Clone, Copy)]
pub struct InvarianceInput<'a> {
    /// The agent and its environments.
    pub world: &'a Keyed<World>,
    /// The explored rows (the starts are the first babbled ones).
    pub exploration: &'a Keyed<Exploration>,
}

impl StageInput for InvarianceInput<'_> {
    fn keys(&self) -> Vec<&str> {
        vec![&self.world.key, &self.exploration.key]
    }
}

const REPORT_FILE: &str = "invariance.json";

impl Stage for InvarianceStage {
    const ID: StageId = StageId::Invariance;
    type Input<'a> = InvarianceInput<'a>;
    type Output = InvarianceData;

    fn compute(
        &self,
        input: &InvarianceInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<InvarianceData> {
        let world = &input.world.value;
        let exploration = &input.exploration.value;
        let babbled: Vec<usize> = exploration
            .probes
            .column(0)
            .iter()
            .enumerate()
            .filter(|(_, &o)| o < 0)
            .map(|(row, _)| row)
            .take(self.starts)
            .collect();
        let starts = exploration.motors.select(Axis(0), &babbled);
        let measured = invariance_measured(
            world.agent.as_ref(),
            starts.view(),
            &world.environments,
            world.workspace.as_ref(),
            &self.kernel.check()?,
            self.set_metric.as_ref(),
            context.progress,
        )?;
        Ok(InvarianceData {
            report: measured.report,
            set_distances: measured.set_distances,
            sensors: measured.sensors,
        })
    }

    /// `invariance.json` and the two arrays of every environment, all together.
    fn save(
        &self,
        _: &InvarianceInput<'_>,
        data: &InvarianceData,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        stage_invariance(
            outputs,
            &dir.join(REPORT_FILE),
            &data.report,
            &data.set_distances,
            &data.sensors,
        )?;
        Ok(())
    }

    fn load(&self, input: &InvarianceInput<'_>, dir: &Path) -> crate::Result<InvarianceData> {
        let world = &input.world.value;
        let (report, set_distances, sensors) = read_invariance(
            &dir.join(REPORT_FILE),
            world.environments.len(),
            world.agent.sensor_dim(),
        )?;
        Ok(InvarianceData {
            report,
            set_distances,
            sensors,
        })
    }

    fn summary(&self, data: &InvarianceData) -> String {
        let r = &data.report;
        format!(
            "{} sets in {} environments: largest set difference {:.1e}, Mantel of the set metric ≥ {:.4}, of the raw sensors ≤ {:.3}",
            r.common_sets,
            r.environments.len(),
            r.max_set_distance,
            r.min_mantel,
            r.max_sensor_mantel
        )
    }
}
