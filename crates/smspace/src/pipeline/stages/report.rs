//! `report`: the paper's figures, `report.html` with a 3-D view (and the plotly.js it
//! loads, in `assets/`), `report.md` and `report.json`.

use std::path::Path;

use ndarray::Array2;
use serde::Serialize;

use super::{EmbedOutputs, Keyed, Stage, StageContext, StageInput, World};
use crate::agent::{Agent, Environment, MotorTopology};
use crate::analysis::AnalysisReport;
use crate::explore::Exploration;
use crate::io;
use crate::kernel::TracedSets;
use crate::pipeline::StageId;
use crate::report::{
    write_report, InvarianceData, ReportInputs, ReportParams, ReportSummary, SensoryManifold,
};

/// Motor samples of each raw sensory manifold (paper Fig. 1).
const SENSORY_SAMPLES: usize = 400;

/// The `report` stage: the `[report]` table, and the experiment's name, description and
/// resolved configuration (all printed in the report).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReportStage {
    /// The experiment's name.
    pub name: String,
    /// What it shows.
    pub description: String,
    /// Every parameter of the experiment, as TOML.
    pub config_toml: String,
    /// Figure parameters.
    pub report: ReportParams,
}

/// What `report` reads: everything.
#[derive(Debug, Clone, Copy)]
pub struct ReportInput<'a> {
    /// The agent, environments, working space.
    pub world: &'a Keyed<World>,
    /// Motors, poses, probe labels.
    pub exploration: &'a Keyed<Exploration>,
    /// The kernel sets.
    pub traced: &'a Keyed<TracedSets>,
    /// The embedding.
    pub embedded: &'a Keyed<EmbedOutputs>,
    /// The analysis.
    pub analysis: &'a Keyed<AnalysisReport>,
    /// The invariance experiment, when it ran.
    pub invariance: Option<&'a Keyed<InvarianceData>>,
}

impl StageInput for ReportInput<'_> {
    fn keys(&self) -> Vec<&str> {
        let mut keys = vec![
            self.world.key.as_str(),
            &self.exploration.key,
            &self.traced.key,
            &self.embedded.key,
            &self.analysis.key,
        ];
        keys.extend(self.invariance.map(|i| i.key.as_str()));
        keys
    }
}

const SUMMARY_FILE: &str = "report.json";

impl Stage for ReportStage {
    const ID: StageId = StageId::Report;
    type Input<'a> = ReportInput<'a>;
    type Output = ReportSummary;

    /// Renders the figures, `report.html` and `report.md` straight into the run folder
    /// (figures are files); [`save`](Stage::save) adds `report.json`.
    fn compute(
        &self,
        input: &ReportInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<ReportSummary> {
        let world = &input.world.value;
        let exploration = &input.exploration.value;
        let traced = &input.traced.value;
        let embedded = &input.embedded.value;
        let manifolds = sensory_manifolds(world.agent.as_ref(), &world.environments);
        let quality = embedded
            .quality
            .map(|q| serde_json::to_value(q).unwrap_or_default());
        let inputs = ReportInputs {
            name: &self.name,
            description: &self.description,
            config_toml: &self.config_toml,
            agent: world.agent.as_ref(),
            environments: &world.environments,
            workspace: world.workspace,
            motors: exploration.motors.view(),
            poses: exploration.poses.view(),
            probes: exploration.probes.view(),
            sets: traced.sets.view(),
            kept: &traced.kept,
            trace: &traced.report.summary,
            embedding: embedded.coordinates.view(),
            embed_report: &embedded.report,
            embed_quality: quality.as_ref(),
            dydx: Some(embedded.dydx.view()),
            analysis: Some(&input.analysis.value),
            invariance: input.invariance.map(|i| &i.value),
            sensory_manifolds: &manifolds,
            stages: context.stage_times,
            warnings: &[],
        };
        Ok(write_report(&inputs, &self.report, context.dir)?)
    }

    fn save(
        &self,
        _: &ReportInput<'_>,
        summary: &ReportSummary,
        dir: &Path,
    ) -> crate::Result<Vec<String>> {
        io::write_json(&dir.join(SUMMARY_FILE), summary)?;
        let mut files: Vec<String> = summary
            .figures
            .iter()
            .flat_map(|f| f.files.iter().map(|p| p.to_string_lossy().into_owned()))
            .collect();
        files.extend(
            summary
                .assets
                .iter()
                .map(|p| p.to_string_lossy().into_owned()),
        );
        files.push(summary.html.to_string_lossy().into_owned());
        files.push(summary.markdown.to_string_lossy().into_owned());
        files.push(SUMMARY_FILE.to_owned());
        Ok(files)
    }

    fn load(&self, _: &ReportInput<'_>, dir: &Path) -> crate::Result<ReportSummary> {
        Ok(io::read_json(&dir.join(SUMMARY_FILE), "report summary")?)
    }

    fn summary(&self, summary: &ReportSummary) -> String {
        match summary.warnings.len() {
            0 => "report.html, report.md and figures/".to_owned(),
            n => format!(
                "report.html, report.md and figures/; {n} warning{} at the top of the report",
                if n == 1 { "" } else { "s" }
            ),
        }
    }
}

/// The raw sensory manifold of each environment along the single motor of a 1-motor
/// agent (paper Fig. 1); empty for other agents.
fn sensory_manifolds(agent: &dyn Agent, environments: &[Environment]) -> Vec<SensoryManifold> {
    if agent.motor_dim() != 1 {
        return Vec::new();
    }
    let (low, high) = match agent.motor_topology() {
        MotorTopology::Bounded { low, high } => (low, high),
        MotorTopology::Periodic => (-std::f64::consts::PI, std::f64::consts::PI),
    };
    let motors = Array2::from_shape_fn((SENSORY_SAMPLES, 1), |(t, _)| {
        low + (high - low) * t as f64 / (SENSORY_SAMPLES - 1) as f64
    });
    environments
        .iter()
        .enumerate()
        .map(|(e, env)| {
            let mut sensors = Array2::zeros((SENSORY_SAMPLES, agent.sensor_dim()));
            agent.sense_batch(env, motors.view(), sensors.view_mut());
            let seed = env.seed.map(|s| format!("seed {s}, ")).unwrap_or_default();
            SensoryManifold {
                label: format!("environment {} ({seed}{} lights)", e + 1, env.lights.len()),
                motors: motors.clone(),
                sensors,
            }
        })
        .collect()
}
