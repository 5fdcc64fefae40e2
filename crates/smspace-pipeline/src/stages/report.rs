//! `report`: the paper's figures, `report.html` with a 3-D view (and the plotly.js it
//! loads, in `assets/`), `report.md` and `report.json`.

use std::path::Path;

use ndarray::{Array2, Axis};
use serde::Serialize;

use super::{EmbedOutputs, Keyed, Stage, StageContext, StageInput, World};
use crate::manifest::StageId;
use crate::report::{
    render_report, InvarianceData, RenderedReport, ReportInputs, ReportParams, SensoryManifold,
};
use smspace::agent::{Agent, Environment};
use smspace::analysis::AnalysisReport;
use smspace::explore::Exploration;
use smspace::io::{self, Outputs};
use smspace::kernel::TracedSets;

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
    type Output = RenderedReport;

    /// Draws the figures, `report.html` and `report.md` in memory;
    /// [`save`](Stage::save) stages them with `report.json`.
    fn compute(
        &self,
        input: &ReportInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<RenderedReport> {
        let world = &input.world.value;
        let exploration = &input.exploration.value;
        let traced = &input.traced.value;
        let embedded = &input.embedded.value;
        let manifolds = sensory_manifolds(world.agent.as_ref(), &world.environments);
        let quality = embedded
            .quality
            .map(|q| serde_json::to_value(q).unwrap_or_default());
        let planar = exploration
            .ground_truth
            .as_ref()
            .and_then(smspace::agent::GroundTruth::planar_view);
        let m = traced.kept.len();
        // Above `max_sets`, the figures and the 3-D view are drawn from a named sample.
        let sample = (m > self.report.max_sets).then(|| {
            sample_rows(
                &traced.kept,
                exploration.probes.view(),
                self.report.max_sets,
                self.report.seed,
            )
        });
        let (motor_rows, set_rows): (Vec<usize>, Vec<usize>) = match &sample {
            Some(rows) => rows.iter().map(|&r| (traced.kept[r], r)).unzip(),
            None => (Vec::new(), Vec::new()),
        };
        let pick = |a: ndarray::ArrayView2<'_, f64>, rows: &[usize]| a.select(Axis(0), rows);
        let sampled = sample.as_ref().map(|rows| {
            let probes = exploration.probes.select(Axis(0), &motor_rows);
            let babbled = smspace::explore::babbled_rows(probes.view()).len();
            (
                pick(exploration.motors.view(), &motor_rows),
                planar
                    .as_ref()
                    .map(|(poses, _)| pick(poses.view(), &motor_rows)),
                probes,
                traced.sets.select(Axis(0), &set_rows),
                (0..rows.len()).collect::<Vec<usize>>(),
                pick(embedded.coordinates.view(), &set_rows),
                vec![crate::report::Warning::new(
                    "report",
                    format!(
                        "the figures and the 3-D view are drawn from a sample of {} of the {m} sets: every probe-grid set ({}) and {babbled} babbled sets drawn at random (report.seed = {}); the tables and the analysis are of all sets. report.max_sets = {} sets the sample's size",
                        rows.len(),
                        rows.len() - babbled,
                        self.report.seed,
                        self.report.max_sets
                    ),
                )],
            )
        });
        let (motors, poses, probes, sets, kept, embedding, notes) = match &sampled {
            Some((motors, poses, probes, sets, kept, embedding, notes)) => (
                motors.view(),
                poses.as_ref().map(|p| p.view()),
                probes.view(),
                sets.view(),
                kept.as_slice(),
                embedding.view(),
                notes.as_slice(),
            ),
            None => (
                exploration.motors.view(),
                planar.as_ref().map(|(poses, _)| poses.view()),
                exploration.probes.view(),
                traced.sets.view(),
                traced.kept.as_slice(),
                embedded.coordinates.view(),
                &[][..],
            ),
        };
        let inputs = ReportInputs {
            name: &self.name,
            description: &self.description,
            config_toml: &self.config_toml,
            agent: world.agent.as_ref(),
            environments: &world.environments,
            workspace: world.workspace,
            motors,
            poses,
            pose_view: planar.as_ref().map(|(_, view)| *view).unwrap_or_default(),
            probes,
            sets,
            kept,
            trace: &traced.report.summary,
            law: traced.report.law.as_ref(),
            embedding,
            embed_report: &embedded.report,
            embed_quality: quality.as_ref(),
            dydx: Some(embedded.dydx.view()),
            analysis: Some(&input.analysis.value),
            invariance: input.invariance.map(|i| &i.value),
            sensory_manifolds: &manifolds,
            stages: context.stage_times,
            warnings: notes,
        };
        Ok(render_report(&inputs, &self.report)?)
    }

    /// The figures, `report.html`, `report.md` and `report.json`, all together.
    fn save(
        &self,
        _: &ReportInput<'_>,
        report: &RenderedReport,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        report.write_into(outputs, dir)?;
        outputs.json(&dir.join(SUMMARY_FILE), &report.summary)?;
        Ok(())
    }

    /// `report.json` (the files themselves are checked by their hashes, not read).
    fn load(&self, _: &ReportInput<'_>, dir: &Path) -> crate::Result<RenderedReport> {
        Ok(RenderedReport {
            summary: io::read_json(&dir.join(SUMMARY_FILE), "report summary")?,
            files: Vec::new(),
        })
    }

    fn summary(&self, report: &RenderedReport) -> String {
        match report.summary.warnings.len() {
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
    let (low, high) = agent.motor_space().motor(0).range();
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

/// The traced rows a report draws when there are more than `most` sets: every
/// probe-grid set, then babbled sets drawn uniformly (seeded) up to `most`, increasing.
fn sample_rows(
    kept: &[usize],
    probes: ndarray::ArrayView2<'_, i64>,
    most: usize,
    seed: u64,
) -> Vec<usize> {
    use rand::SeedableRng;
    let (grid, babbled): (Vec<usize>, Vec<usize>) =
        (0..kept.len()).partition(|&r| !smspace::explore::is_babbled(probes.row(kept[r])));
    let room = most.saturating_sub(grid.len()).min(babbled.len());
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
    let mut rows = grid;
    rows.extend(
        rand::seq::index::sample(&mut rng, babbled.len(), room)
            .into_iter()
            .map(|b| babbled[b]),
    );
    rows.sort_unstable();
    rows
}
