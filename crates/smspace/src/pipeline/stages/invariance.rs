//! `invariance`: the first babbled starts traced with the sensory method in every
//! environment and compared (paper sections 2.2, 2.3, 3.3; [`crate::invariance`]).

use std::path::Path;

use ndarray::Axis;
use serde::Serialize;

use super::{Keyed, Stage, StageContext, StageInput, World};
use crate::explore::Exploration;
use crate::invariance::invariance_measured;
use crate::io::{self, Outputs};
use crate::kernel::TraceParams;
use crate::metric::MetricKind;
use crate::pipeline::StageId;
use crate::report::InvarianceData;

/// The `invariance` stage: the `[kernel]` table traced with the sensory method, the
/// number of starts (`[analysis] invariance_starts`) and the metric.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InvarianceStage {
    /// Tracing parameters (the method is `sensory`).
    pub kernel: TraceParams,
    /// The first this many babbled rows are the starts.
    pub starts: usize,
    /// The set metric.
    pub metric: MetricKind,
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

fn matrix_file(environment: usize) -> String {
    format!("invariance-D-{}.npy", environment + 1)
}

fn sensors_file(environment: usize) -> String {
    format!("invariance-sensors-{}.npy", environment + 1)
}

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
            self.metric,
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
        outputs.json(&dir.join(REPORT_FILE), &data.report)?;
        for (i, (d, s)) in data.set_distances.iter().zip(&data.sensors).enumerate() {
            outputs.npy(&dir.join(matrix_file(i)), d)?;
            outputs.npy(&dir.join(sensors_file(i)), s)?;
        }
        Ok(())
    }

    fn load(&self, input: &InvarianceInput<'_>, dir: &Path) -> crate::Result<InvarianceData> {
        let world = &input.world.value;
        let report = io::read_json(&dir.join(REPORT_FILE), "invariance report")?;
        let k = world.agent.sensor_dim();
        let mut set_distances = Vec::new();
        let mut sensors = Vec::new();
        for i in 0..world.environments.len() {
            set_distances.push(io::read_matrix(&dir.join(matrix_file(i)), None, "(C, C)")?);
            sensors.push(io::read_matrix(
                &dir.join(sensors_file(i)),
                Some(k),
                "(C, K)",
            )?);
        }
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
