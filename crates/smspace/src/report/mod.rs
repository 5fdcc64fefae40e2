//! The last stage: figures (PNG and SVG), `report.html` (self-contained, with an
//! interactive 3-D view of the embedding) and `report.md`, from the outputs of the
//! earlier stages.
//!
//! The report mirrors the paper's figures: Fig. 1 (toy-line's sensory manifolds in two
//! environments, section 2.2), Fig. 2 (toy-redundant's kernel lines and learned 1-D
//! manifold, section 2.3), Fig. 5a/5b/5d (the arm's explored configurations, kernel
//! sets in motor space, the CCA embedding with the probe surfaces, section 3.3), plus
//! the embedding coloured by each pose coordinate, the persistence diagram, the CCA
//! `dy–dx` plot and the environment-invariance comparison. A figure whose inputs are
//! absent (e.g. no probe grid) is skipped and listed as such in the summary.
//!
//! This module is the only one that knows every stage: it reads their outputs and
//! never runs them.

mod figures;
mod html;
mod markdown;
mod plot;
mod tables;

use std::path::{Path, PathBuf};

use ndarray::{Array2, ArrayView2, ArrayView3, Axis};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::agent::{Agent, Environment, MotorSpace};
use crate::analysis::AnalysisReport;
use crate::embed::EmbedReport;
use crate::explore::Workspace;
use crate::invariance::InvarianceReport;
use crate::io::Outputs;
use crate::kernel::TraceSummary;

/// Errors of the report stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReportError {
    /// Drawing a figure failed.
    #[error("cannot draw figure {figure}: {reason}")]
    Draw {
        /// The figure's file stem.
        figure: String,
        /// What the plotting backend said.
        reason: String,
    },
    /// An input has a shape that does not fit the others.
    #[error("report input {what}: {reason}")]
    Input {
        /// Which input.
        what: &'static str,
        /// What is wrong, and the expected shape.
        reason: String,
    },
    /// A parameter is out of range.
    #[error("report parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// The parameter's name.
        name: &'static str,
        /// The value given.
        value: String,
        /// Why it is refused.
        reason: String,
    },
    /// Writing a file failed.
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
}

/// The raw sensory manifold of one environment (paper Fig. 1): the sensor values
/// `s = σ_E(m)` along a sweep of the motors.
#[derive(Debug, Clone, PartialEq)]
pub struct SensoryManifold {
    /// A label for the legend, e.g. `"environment 1 (seed 1, 5 lights)"`.
    pub label: String,
    /// The motor sweep `(T, N)`.
    pub motors: Array2<f64>,
    /// The sensor values `(T, K)` at those motors.
    pub sensors: Array2<f64>,
}

/// What the invariance figure compares: for each environment, the distance matrix of
/// the sets traced there (over the rows traced in every environment) and the raw
/// sensor values of the same rows.
#[derive(Debug, Clone)]
pub struct InvarianceData {
    /// The numbers.
    pub report: InvarianceReport,
    /// One `(C, C)` Hausdorff matrix per environment, over the `C` common rows.
    pub set_distances: Vec<Array2<f64>>,
    /// One `(C, K)` array of sensor values per environment, for the same rows.
    pub sensors: Vec<Array2<f64>>,
}

/// Time spent in one stage of the pipeline, for the report's table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageTiming {
    /// The stage's name (`explore`, `trace`, …).
    pub stage: String,
    /// Seconds spent (0 when reused from the cache).
    pub seconds: f64,
    /// Whether its outputs were reused instead of recomputed.
    pub cached: bool,
}

/// Everything the report shows. Arrays are views of the stages' outputs; optional parts
/// that are `None` (or empty) skip their figures.
#[derive(Debug, Clone, Copy)]
pub struct ReportInputs<'a> {
    /// The experiment's name (the report's title).
    pub name: &'a str,
    /// One or two sentences on what the experiment shows.
    pub description: &'a str,
    /// The resolved experiment file (TOML), shown at the end of the report.
    pub config_toml: &'a str,
    /// The agent.
    pub agent: &'a dyn Agent,
    /// The environments; the first is the one the pipeline explored and traced in.
    pub environments: &'a [Environment],
    /// The working space, when the agent has one.
    pub workspace: Option<Workspace>,
    /// Explored motor configurations `(M0, N)`.
    pub motors: ArrayView2<'a, f64>,
    /// Their poses `(M0, 3)` as `(x, y, alpha)`, when the agent's ground truth is the
    /// planar pose; `None` skips the figures of poses (with a sentence).
    pub poses: Option<ArrayView2<'a, f64>>,
    /// Probe labels `(M0, 3)`: `(orientation, ix, iy)`, `-1` for babbled rows.
    pub probes: ArrayView2<'a, i64>,
    /// The kernel sets `(M, P, N)`, one per kept exploration row.
    pub sets: ArrayView3<'a, f64>,
    /// `kept[i]`: the exploration row of set `i` (length `M`, increasing).
    pub kept: &'a [usize],
    /// How tracing went.
    pub trace: &'a TraceSummary,
    /// The embedding `(M, d)`, row `i` for set `i`.
    pub embedding: ArrayView2<'a, f64>,
    /// The embedding's diagnostics.
    pub embed_report: &'a EmbedReport,
    /// Quality of the embedding against the learned distances (trustworthiness,
    /// continuity, stress …) as written to `Y.embed.json`, if computed.
    pub embed_quality: Option<&'a serde_json::Value>,
    /// Shepard sample `(P, 2)`: columns `dx` (learned distance), `dy` (embedded
    /// distance), for the CCA `dy–dx` plot.
    pub dydx: Option<ArrayView2<'a, f64>>,
    /// Topology, dimension and agreement with the poses.
    pub analysis: Option<&'a AnalysisReport>,
    /// The invariance comparison across environments.
    pub invariance: Option<&'a InvarianceData>,
    /// Raw sensory manifolds, one per environment (paper Fig. 1).
    pub sensory_manifolds: &'a [SensoryManifold],
    /// Time per stage.
    pub stages: &'a [StageTiming],
}

/// Which image files each figure is written as.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FigureFormats {
    /// PNG and SVG (default).
    #[default]
    PngAndSvg,
    /// PNG only.
    Png,
    /// SVG only.
    Svg,
}

/// Parameters of the report: the `[report]` table of an experiment file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReportParams {
    /// Image formats of the figures. Default `png-and-svg`.
    pub formats: FigureFormats,
    /// Explored configurations drawn in Fig. 5a. Default 60.
    pub sample_configurations: usize,
    /// Kernel sets drawn in Fig. 2 / 5b. Default 40.
    pub sample_sets: usize,
    /// Seed of the samples above. Default 1.
    pub seed: u64,
    /// Width of a figure panel in pixels. Default 640.
    pub panel_width: u32,
    /// Height of a figure panel in pixels. Default 480.
    pub panel_height: u32,
}

impl Default for ReportParams {
    fn default() -> Self {
        Self {
            formats: FigureFormats::PngAndSvg,
            sample_configurations: 60,
            sample_sets: 40,
            seed: 1,
            panel_width: 640,
            panel_height: 480,
        }
    }
}

/// One figure the report drew (or skipped).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FigureRecord {
    /// File stem, e.g. `fig5d-embedding-probes`.
    pub name: String,
    /// Caption, with the paper's figure number when it mirrors one.
    pub caption: String,
    /// Files written, relative to the report folder (empty when skipped).
    pub files: Vec<PathBuf>,
    /// Why it was skipped, when it was.
    pub skipped: Option<String>,
}

/// What [`write_report`] wrote.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReportSummary {
    /// The figures, in the report's order.
    pub figures: Vec<FigureRecord>,
    /// `report.html`, relative to the report folder.
    pub html: PathBuf,
    /// `report.md`, relative to the report folder.
    pub markdown: PathBuf,
}

/// Largest panel side accepted, in pixels.
const MAX_PANEL_PIXELS: u32 = 4000;

impl ReportParams {
    /// Checks the parameters.
    pub fn check(&self) -> Result<(), ReportError> {
        for (name, value, least) in [
            ("panel_width", self.panel_width, 320),
            ("panel_height", self.panel_height, 240),
        ] {
            if !(least..=MAX_PANEL_PIXELS).contains(&value) {
                return Err(ReportError::InvalidParameter {
                    name,
                    value: value.to_string(),
                    reason: format!("must be between {least} and {MAX_PANEL_PIXELS} pixels"),
                });
            }
        }
        Ok(())
    }
}

fn input_error(what: &'static str, reason: String) -> ReportError {
    ReportError::Input { what, reason }
}

/// Checks that the inputs fit together, input by input, in the order of
/// [`ReportInputs`]: the first misfit found is the error.
fn check_inputs(inputs: &ReportInputs<'_>) -> Result<(), ReportError> {
    check_exploration(inputs)?;
    check_sets(inputs)?;
    check_embedding(inputs)?;
    check_sensory_manifolds(inputs.sensory_manifolds)?;
    if let Some(inv) = inputs.invariance {
        check_invariance(inv)?;
    }
    Ok(())
}

/// The exploration: motors `(M0, N)` for the agent, then poses and probe labels with
/// one row of three per motor row.
fn check_exploration(inputs: &ReportInputs<'_>) -> Result<(), ReportError> {
    let rows = inputs.motors.nrows();
    let n = inputs.agent.motor_dim();
    if inputs.motors.ncols() != n {
        return Err(input_error(
            "motors",
            format!(
                "has shape ({rows}, {}), expected (M0, {n}) for the agent {}",
                inputs.motors.ncols(),
                inputs.agent.name()
            ),
        ));
    }
    if let Some(poses) = inputs.poses {
        check_per_motor_row("poses", poses.dim(), rows)?;
    }
    check_per_motor_row("probes", inputs.probes.dim(), rows)
}

/// An array `what` of shape `dim` that must have one row of three per motor row.
fn check_per_motor_row(
    what: &'static str,
    dim: (usize, usize),
    rows: usize,
) -> Result<(), ReportError> {
    if dim != (rows, 3) {
        return Err(input_error(
            what,
            format!(
                "has shape ({}, {}), expected ({rows}, 3) to match the motors",
                dim.0, dim.1
            ),
        ));
    }
    Ok(())
}

/// The kernel sets `(M, P, N)` and `kept`, their increasing exploration rows.
fn check_sets(inputs: &ReportInputs<'_>) -> Result<(), ReportError> {
    let rows = inputs.motors.nrows();
    let n = inputs.agent.motor_dim();
    let (m, p, sn) = inputs.sets.dim();
    if m > 0 && (sn != n || p == 0) {
        return Err(input_error(
            "sets",
            format!("has shape ({m}, {p}, {sn}), expected (M, P, {n}) with P > 0"),
        ));
    }
    if inputs.kept.len() != m {
        return Err(input_error(
            "kept",
            format!(
                "has {} rows for {m} sets; give the exploration row of every set",
                inputs.kept.len()
            ),
        ));
    }
    if let Some(w) = inputs.kept.windows(2).find(|w| w[0] >= w[1]) {
        return Err(input_error(
            "kept",
            format!("is not increasing ({} then {})", w[0], w[1]),
        ));
    }
    if let Some(&row) = inputs.kept.iter().find(|&&r| r >= rows) {
        return Err(input_error(
            "kept",
            format!("names exploration row {row} but there are {rows} rows"),
        ));
    }
    Ok(())
}

/// The embedding: one finite row per set; and the `dy–dx` sample, `(P, 2)`.
fn check_embedding(inputs: &ReportInputs<'_>) -> Result<(), ReportError> {
    let m = inputs.sets.len_of(Axis(0));
    if inputs.embedding.nrows() != m {
        return Err(input_error(
            "embedding",
            format!(
                "has {} rows, expected one per set ({m})",
                inputs.embedding.nrows()
            ),
        ));
    }
    if let Some(((i, j), v)) = inputs
        .embedding
        .indexed_iter()
        .find(|(_, v)| !v.is_finite())
    {
        return Err(input_error(
            "embedding",
            format!("holds {v} at ({i}, {j}); every coordinate must be finite"),
        ));
    }
    if let Some(dydx) = inputs.dydx {
        if dydx.ncols() != 2 {
            return Err(input_error(
                "dydx",
                format!("has {} columns, expected (P, 2): dx, dy", dydx.ncols()),
            ));
        }
    }
    Ok(())
}

/// Each sensory manifold: motors `(T, N)` and sensors `(T, K)`, `N, K > 0`.
fn check_sensory_manifolds(manifolds: &[SensoryManifold]) -> Result<(), ReportError> {
    for s in manifolds {
        if s.motors.nrows() != s.sensors.nrows() || s.sensors.ncols() == 0 || s.motors.ncols() == 0
        {
            return Err(input_error(
                "sensory_manifolds",
                format!(
                    "'{}' has motors {:?} and sensors {:?}, expected (T, N) and (T, K) with the same T",
                    s.label,
                    s.motors.dim(),
                    s.sensors.dim()
                ),
            ));
        }
    }
    Ok(())
}

/// The invariance data: per environment, a `(C, C)` distance matrix and `(C, K)`
/// sensor values.
fn check_invariance(inv: &InvarianceData) -> Result<(), ReportError> {
    if inv.set_distances.len() != inv.sensors.len() {
        return Err(input_error(
            "invariance",
            format!(
                "has {} distance matrices but {} sensor arrays; give one of each per environment",
                inv.set_distances.len(),
                inv.sensors.len()
            ),
        ));
    }
    for (k, (d, s)) in inv.set_distances.iter().zip(&inv.sensors).enumerate() {
        let c = d.nrows();
        if d.ncols() != c || s.nrows() != c {
            return Err(input_error(
                "invariance",
                format!(
                    "environment {}: distances {:?} and sensors {:?}, expected (C, C) and (C, K)",
                    k + 1,
                    d.dim(),
                    s.dim()
                ),
            ));
        }
    }
    Ok(())
}

/// What every figure needs besides the inputs.
struct Derived {
    /// `(M, 3)`: the planar pose of every set's exploration row, when there are poses.
    set_poses: Option<Array2<f64>>,
    /// Unit of motor coordinates and of set distances.
    motor_unit: &'static str,
    space: MotorSpace,
}

/// Why the figures of poses are skipped when there are none.
const NO_PLANAR_POSES: &str = "the agent has no planar ground truth (x, y, alpha) to colour or place the sets by, so the figures of poses are skipped";

fn derive(inputs: &ReportInputs<'_>) -> Derived {
    let m = inputs.kept.len();
    let set_poses = inputs.poses.map(|poses| {
        let mut set_poses = Array2::zeros((m, 3));
        for (i, &row) in inputs.kept.iter().enumerate() {
            set_poses.row_mut(i).assign(&poses.row(row));
        }
        set_poses
    });
    let space = inputs.agent.motor_space();
    let motor_unit = if space.is_hinges() {
        "rad"
    } else if space.is_bounded() {
        "m"
    } else {
        "rad or m"
    };
    Derived {
        set_poses,
        motor_unit,
        space,
    }
}

/// A seeded sample of `k` of `0..n` (all when `k ≥ n`), sorted; `stream` separates the
/// samples of different figures.
fn sample(n: usize, k: usize, seed: u64, stream: u64) -> Vec<usize> {
    if k >= n {
        return (0..n).collect();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    let mut picked = rand::seq::index::sample(&mut rng, n, k).into_vec();
    picked.sort_unstable();
    picked
}

/// A figure ready to draw, or why it is skipped.
enum Planned<'a> {
    Skip(String),
    SensoryManifolds(figures::SensoryManifolds<'a>),
    KernelLines(figures::KernelLines<'a>),
    LearnedManifold(figures::LearnedManifold<'a>),
    Configurations(figures::Configurations),
    KernelSets3d(figures::KernelSets3d<'a>),
    EmbeddingProbes(figures::EmbeddingProbes<'a>),
    EmbeddingPose(figures::EmbeddingPose<'a>),
    Persistence(figures::PersistenceDiagram<'a>),
    DyDx(figures::DyDx<'a>),
    Invariance(figures::Invariance),
    Stress(figures::StressTrace<'a>),
}

impl Planned<'_> {
    fn render(&self, name: &str, formats: FigureFormats) -> Result<plot::Rendered, ReportError> {
        use plot::render;
        match self {
            Planned::Skip(_) => Ok(plot::Rendered::default()),
            Planned::SensoryManifolds(f) => render(f, name, formats),
            Planned::KernelLines(f) => render(f, name, formats),
            Planned::LearnedManifold(f) => render(f, name, formats),
            Planned::Configurations(f) => render(f, name, formats),
            Planned::KernelSets3d(f) => render(f, name, formats),
            Planned::EmbeddingProbes(f) => render(f, name, formats),
            Planned::EmbeddingPose(f) => render(f, name, formats),
            Planned::Persistence(f) => render(f, name, formats),
            Planned::DyDx(f) => render(f, name, formats),
            Planned::Invariance(f) => render(f, name, formats),
            Planned::Stress(f) => render(f, name, formats),
        }
    }
}

/// Removes the files of the report's figures that this report did not write: a format
/// no longer asked for, a figure now skipped. `figures/` then holds only what the
/// report shows (files of other names are left alone).
fn remove_stale_figures<'r>(dir: &Path, records: impl Iterator<Item = &'r FigureRecord>) {
    for record in records {
        for extension in ["png", "svg"] {
            let relative = PathBuf::from("figures").join(format!("{}.{extension}", record.name));
            if !record.files.contains(&relative) {
                // Absent is the usual case; a file that cannot be removed stays stale
                // but is not listed by the report.
                let _ = std::fs::remove_file(dir.join(&relative));
            }
        }
    }
}

/// One entry of the figure plan: `(name, caption, plan)`.
type PlannedFigure<'b> = (&'static str, String, Planned<'b>);

/// The figures of the report in order: `(name, caption, plan)`.
fn plan<'a: 'b, 'b>(
    inputs: &ReportInputs<'a>,
    params: &ReportParams,
    derived: &'b Derived,
    surfaces: &'b [figures::ProbeSurface],
) -> Vec<PlannedFigure<'b>> {
    let planner = Planner {
        inputs: *inputs,
        derived,
        panel: (params.panel_width, params.panel_height),
    };
    let sets_sample = sample(inputs.kept.len(), params.sample_sets, params.seed, 2);
    vec![
        planner.sensory_manifolds(),
        planner.kernel_lines(&sets_sample),
        planner.learned_manifold(),
        planner.configurations(params),
        planner.kernel_sets_3d(sets_sample),
        planner.embedding_probes(surfaces),
        planner.embedding_pose(),
        planner.persistence(),
        planner.dydx(),
        planner.invariance(),
        planner.stress(),
    ]
}

/// What the plan of every figure reads: one method per figure, each deciding
/// whether its figure is drawn and with what.
struct Planner<'a, 'b> {
    inputs: ReportInputs<'a>,
    derived: &'b Derived,
    /// Size of one panel in pixels, `(width, height)`.
    panel: (u32, u32),
}

impl<'a: 'b, 'b> Planner<'a, 'b> {
    /// The observer's `x` for every set.
    fn set_x(&self) -> Option<Vec<f64>> {
        let poses = self.derived.set_poses.as_ref()?;
        Some(poses.column(0).to_vec())
    }

    /// Fig. 1: the sensory manifolds.
    fn sensory_manifolds(&self) -> PlannedFigure<'b> {
        let caption = "Paper Fig. 1 (section 2.2): the sensory manifold S traced by the sensors as the motors sweep their range, in each environment; it depends on the environment.".to_owned();
        let planned = if self.inputs.sensory_manifolds.is_empty() {
            Planned::Skip(
                "no sensory manifolds were given (they are computed for the toy agents)".to_owned(),
            )
        } else {
            Planned::SensoryManifolds(figures::SensoryManifolds {
                manifolds: self.inputs.sensory_manifolds,
                agent: self.inputs.agent.name(),
                motor_unit: self.derived.motor_unit,
                size: self.panel,
            })
        };
        ("fig1-sensory-manifolds", caption, planned)
    }

    /// Fig. 2, right: the sampled kernel sets in the motor plane.
    fn kernel_lines(&self, sets_sample: &[usize]) -> PlannedFigure<'b> {
        let inputs = &self.inputs;
        let n = inputs.agent.motor_dim();
        let caption = format!(
            "Paper Fig. 2 right (section 2.3): {} kernel sets M^i in the motor plane, each the motor configurations that give the same sensation as its start (black dot); coloured by the observer's x.",
            sets_sample.len()
        );
        let planned = if n != 2 {
            Planned::Skip(format!(
                "the agent has N = {n} motors; kernel lines in the motor plane are drawn for N = 2 (see fig5b-kernel-sets-3d for N >= 3)"
            ))
        } else if sets_sample.is_empty() {
            Planned::Skip("no kernel sets to draw (no sets traced, or sample_sets = 0)".to_owned())
        } else if self.set_x().is_none() {
            Planned::Skip(NO_PLANAR_POSES.to_owned())
        } else {
            Planned::KernelLines(figures::KernelLines {
                sets: inputs.sets.reborrow(),
                starts: sets_sample
                    .iter()
                    .map(|&i| {
                        let row = inputs.motors.row(inputs.kept[i]);
                        (row[0], row[1])
                    })
                    .collect(),
                sample: sets_sample.to_vec(),
                set_x: self.set_x().unwrap_or_default(),
                space: self.derived.space.clone(),
                motor_unit: self.derived.motor_unit,
                total: inputs.kept.len(),
                size: self.panel,
            })
        };
        ("fig2-kernel-lines", caption, planned)
    }

    /// Fig. 2, left: the learned manifold against `x`.
    fn learned_manifold(&self) -> PlannedFigure<'b> {
        let n = self.inputs.agent.motor_dim();
        let m = self.inputs.kept.len();
        let d = self.inputs.embedding.ncols();
        let caption = if d == 1 {
            "Paper Fig. 2 left (section 2.3): the learned 1-D manifold, the embedding coordinate q1 of every set against the observer's x: a monotonic curve means the agent has captured x.".to_owned()
        } else {
            "Paper Fig. 2 (section 2.3): the learned manifold, the first two embedding coordinates of every set, coloured by the observer's x.".to_owned()
        };
        let planned = if m == 0 {
            Planned::Skip("no kernel sets were embedded".to_owned())
        } else if self.set_x().is_none() {
            Planned::Skip(NO_PLANAR_POSES.to_owned())
        } else if d == 1 || (d >= 2 && n == 2) {
            Planned::LearnedManifold(figures::LearnedManifold {
                embedding: self.inputs.embedding.reborrow(),
                set_x: self.set_x().unwrap_or_default(),
                size: self.panel,
            })
        } else {
            Planned::Skip(format!(
                "the embedding has d = {d} and the agent N = {n} motors; see embedding-pose and fig5d-embedding-probes"
            ))
        };
        ("fig2-learned-manifold", caption, planned)
    }

    /// Fig. 5a: a seeded sample of the babbled configurations of the arm.
    fn configurations(&self, params: &ReportParams) -> PlannedFigure<'b> {
        let inputs = &self.inputs;
        let agent = inputs.agent;
        let babbled: Vec<usize> = (0..inputs.motors.nrows())
            .filter(|&r| inputs.probes[[r, 0]] < 0)
            .collect();
        let picked = sample(babbled.len(), params.sample_configurations, params.seed, 1);
        let skeletons: Vec<Vec<[f64; 2]>> = picked
            .iter()
            .map(|&k| agent.skeleton(&inputs.motors.row(babbled[k]).to_vec()))
            .collect();
        let caption = format!(
            "Paper Fig. 5a (section 3.3): {} of the {} explored (babbled) configurations of the arm, the sensor's orientation alpha as a red tick, the working space and the lights of environment 1.",
            picked.len(),
            babbled.len()
        );
        let planned = if picked.is_empty() {
            Planned::Skip(
                "no babbled configurations to draw (or sample_configurations = 0)".to_owned(),
            )
        } else if skeletons.iter().all(Vec::is_empty) {
            Planned::Skip(format!(
                "the agent {} has no body to draw (Agent::skeleton is empty)",
                agent.name()
            ))
        } else if let Some(poses) = inputs.poses {
            Planned::Configurations(figures::Configurations {
                alphas: picked.iter().map(|&k| poses[[babbled[k], 2]]).collect(),
                skeletons,
                workspace: inputs.workspace,
                environment: inputs.environments.first().cloned(),
                agent: agent.name().to_owned(),
                explored: babbled.len(),
                size: self.panel,
            })
        } else {
            Planned::Skip(NO_PLANAR_POSES.to_owned())
        };
        ("fig5a-configurations", caption, planned)
    }

    /// Fig. 5b: the sampled kernel sets in 3-D motor space.
    fn kernel_sets_3d(&self, sets_sample: Vec<usize>) -> PlannedFigure<'b> {
        let n = self.inputs.agent.motor_dim();
        let caption = format!(
            "Paper Fig. 5b (section 3.3): {} kernel sets M^i in motor space, two 3-D projections; each closed curve is one set, coordinates wrapped into [-pi, pi).",
            sets_sample.len()
        );
        let planned = if n < 3 {
            Planned::Skip(format!(
                "the agent has N = {n} motors; the 3-D view of kernel sets needs N >= 3"
            ))
        } else if sets_sample.is_empty() {
            Planned::Skip("no kernel sets to draw (no sets traced, or sample_sets = 0)".to_owned())
        } else {
            Planned::KernelSets3d(figures::KernelSets3d {
                sets: self.inputs.sets.reborrow(),
                sample: sets_sample,
                space: self.derived.space.clone(),
                motor_unit: self.derived.motor_unit,
                panel: self.panel,
            })
        };
        ("fig5b-kernel-sets-3d", caption, planned)
    }

    /// Fig. 5d: the embedding with one probe surface per orientation.
    fn embedding_probes(&self, surfaces: &'b [figures::ProbeSurface]) -> PlannedFigure<'b> {
        let m = self.inputs.kept.len();
        let d = self.inputs.embedding.ncols();
        let caption = format!(
            "Paper Fig. 5d (section 3.3): the embedding of the {m} kernel sets (grey) and, for each probe orientation ({}), the surface of the probe sets connected to their grid neighbours, coloured by the probe's x: translations of the sensor at a fixed orientation form a sheet, one per orientation.",
            surfaces
                .iter()
                .map(|s| format!("{:.0} deg", s.alpha.to_degrees()))
                .collect::<Vec<_>>()
                .join(", ")
        );
        let planned = if d < 2 {
            Planned::Skip(format!(
                "the embedding has d = {d}; probe surfaces need d >= 2"
            ))
        } else if surfaces.is_empty() {
            Planned::Skip(
                "no probe rows among the kept sets (explore with probes = \"grid\")".to_owned(),
            )
        } else if let Some(set_poses) = &self.derived.set_poses {
            Planned::EmbeddingProbes(figures::EmbeddingProbes {
                embedding: self.inputs.embedding.reborrow(),
                set_poses,
                surfaces,
                size: self.panel,
            })
        } else {
            Planned::Skip(NO_PLANAR_POSES.to_owned())
        };
        ("fig5d-embedding-probes", caption, planned)
    }

    /// The embedding coloured by each pose coordinate that varies over the sets.
    fn embedding_pose(&self) -> PlannedFigure<'b> {
        let m = self.inputs.kept.len();
        let d = self.inputs.embedding.ncols();
        let Some(set_poses) = &self.derived.set_poses else {
            let caption =
                format!("The embedding of the {m} kernel sets coloured by the observer's pose.");
            return (
                "embedding-pose",
                caption,
                Planned::Skip(NO_PLANAR_POSES.to_owned()),
            );
        };
        let varying: Vec<usize> = (0..3)
            .filter(|&c| {
                figures_extent(set_poses.column(c).iter().copied())
                    .is_some_and(|(lo, hi)| hi - lo > 1e-9)
            })
            .collect();
        let caption = format!(
            "The embedding of the {m} kernel sets coloured by each varying coordinate of the observer's pose ({}); alpha uses a circular colour map. Smooth colour gradients mean the learned manifold is organised like the sensor's configuration.",
            varying
                .iter()
                .map(|&c| ["x", "y", "alpha"][c])
                .collect::<Vec<_>>()
                .join(", ")
        );
        let planned = if m == 0 || d == 0 {
            Planned::Skip("no kernel sets were embedded".to_owned())
        } else if varying.is_empty() {
            Planned::Skip("every pose coordinate is constant over the sets".to_owned())
        } else {
            Planned::EmbeddingPose(figures::EmbeddingPose {
                embedding: self.inputs.embedding.reborrow(),
                set_poses,
                coordinates: varying,
                panel: self.panel,
            })
        };
        ("embedding-pose", caption, planned)
    }

    /// The persistence diagram of the analysis.
    fn persistence(&self) -> PlannedFigure<'b> {
        let caption = "Vietoris-Rips persistence diagram of the set metric rho (Hausdorff distances between kernel sets): points far above the diagonal are robust features; the Betti numbers read off by the gap rule are in the title (the arm's manifold, a circle of orientations times a disc of positions, gives b = [1, 1]).".to_owned();
        let planned = match self.inputs.analysis {
            None => Planned::Skip("no analysis was run".to_owned()),
            Some(a) if a.persistence.iter().all(Vec::is_empty) => {
                Planned::Skip("the analysis has no persistence bars".to_owned())
            }
            Some(a) => Planned::Persistence(figures::PersistenceDiagram {
                analysis: a,
                distance_unit: self.derived.motor_unit,
                size: self.panel,
            }),
        };
        ("persistence-diagram", caption, planned)
    }

    /// CCA's `dy–dx` plot.
    fn dydx(&self) -> PlannedFigure<'b> {
        let caption = "CCA's dy-dx plot: the distance of two sets in the embedding (dy) against their learned distance (dx); points on the diagonal are preserved, CCA favours the small distances (lower left).".to_owned();
        let planned = match self.inputs.dydx {
            Some(p) if p.nrows() > 0 => Planned::DyDx(figures::DyDx {
                pairs: p.reborrow(),
                distance_unit: self.derived.motor_unit,
                size: self.panel,
            }),
            _ => Planned::Skip(
                "no dy-dx sample was given (the embedding method is not CCA, or it was not computed)"
                    .to_owned(),
            ),
        };
        ("dydx", caption, planned)
    }

    /// Set and sensor distances in the first two environments.
    fn invariance(&self) -> PlannedFigure<'b> {
        let caption = "Environment invariance (section 2.3): for the rows traced in two environments, the learned distances between their kernel sets (left) agree across environments, while the distances between their raw sensor values (right) do not.".to_owned();
        let planned = match self.inputs.invariance {
            None => Planned::Skip("no invariance comparison was run".to_owned()),
            Some(inv) if inv.set_distances.len() < 2 => Planned::Skip(
                "the invariance comparison has fewer than two environments".to_owned(),
            ),
            Some(inv) => {
                Planned::Invariance(invariance_figure(inv, self.derived.motor_unit, self.panel))
            }
        };
        ("invariance", caption, planned)
    }

    /// CCA's stress per epoch.
    fn stress(&self) -> PlannedFigure<'b> {
        let report = self.inputs.embed_report;
        let caption =
            "CCA's stress, accumulated over each epoch, as the neighbourhood width lambda shrinks."
                .to_owned();
        let planned = if report.stress_trace.is_empty() {
            Planned::Skip(format!(
                "the embedding method {} records no stress per epoch",
                report.method
            ))
        } else {
            Planned::Stress(figures::StressTrace {
                stress: &report.stress_trace,
                size: self.panel,
            })
        };
        ("cca-stress", caption, planned)
    }
}

/// The invariance figure of environments 1 and 2 (at least two): an evenly spaced
/// sample of the pairs of common rows, their set distances and sensor distances in
/// each environment, and the Mantel correlations of the pair `(0, 1)` (or the first).
fn invariance_figure(
    inv: &InvarianceData,
    distance_unit: &'static str,
    panel: (u32, u32),
) -> figures::Invariance {
    let pair = inv
        .report
        .pairs
        .iter()
        .find(|p| p.a == 0 && p.b == 1)
        .or(inv.report.pairs.first());
    let c = inv.set_distances[0].nrows();
    let all: Vec<(usize, usize)> = (0..c)
        .flat_map(|i| (i + 1..c).map(move |j| (i, j)))
        .collect();
    let drawn: Vec<(usize, usize)> = plot::stride_sample(all.len(), figures::MAX_SCATTER_POINTS)
        .into_iter()
        .map(|k| all[k])
        .collect();
    let sensor_distance = |s: &Array2<f64>, i: usize, j: usize| {
        s.row(i)
            .iter()
            .zip(s.row(j))
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt()
    };
    let (d0, d1) = (&inv.set_distances[0], &inv.set_distances[1]);
    let (s0, s1) = (&inv.sensors[0], &inv.sensors[1]);
    figures::Invariance {
        set_pairs: drawn
            .iter()
            .map(|&(i, j)| (d0[[i, j]], d1[[i, j]]))
            .collect(),
        sensor_pairs: drawn
            .iter()
            .map(|&(i, j)| (sensor_distance(s0, i, j), sensor_distance(s1, i, j)))
            .collect(),
        mantel: pair.map_or(f64::NAN, |p| p.mantel),
        sensor_mantel: pair.map_or(f64::NAN, |p| p.sensor_mantel),
        environments: (0, 1),
        distance_unit,
        panel,
    }
}

fn figures_extent(values: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    plot::finite_extent(values)
}

/// Draws every figure into `dir/figures/` and writes `dir/report.html` and
/// `dir/report.md`: all of them together or none ([`crate::io::Outputs`]).
///
/// Figures whose inputs are absent are skipped, with the reason in their
/// [`FigureRecord`]. Figures are drawn in parallel; the output is the same for any
/// number of threads.
pub fn write_report(
    inputs: &ReportInputs<'_>,
    params: &ReportParams,
    dir: &Path,
) -> Result<ReportSummary, ReportError> {
    let rendered = render_report(inputs, params)?;
    let mut outputs = Outputs::new();
    rendered.write_into(&mut outputs, dir)?;
    outputs.commit()?;
    Ok(rendered.summary)
}

/// A report drawn in memory: what [`write_report`] writes.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedReport {
    /// What the report holds (the pipeline writes it as `report.json`).
    pub summary: ReportSummary,
    /// Every file of the report (figures, `report.html`, `report.md`), relative to the
    /// report folder, with its bytes.
    pub files: Vec<(PathBuf, Vec<u8>)>,
}

impl RenderedReport {
    /// Stages every file under `dir` into `outputs` (making `dir/figures`), and removes
    /// the figure files of an earlier report that this one does not write (a format no
    /// longer asked for, a figure now skipped).
    pub fn write_into(&self, outputs: &mut Outputs, dir: &Path) -> Result<(), ReportError> {
        let figures_dir = dir.join("figures");
        std::fs::create_dir_all(&figures_dir).map_err(|reason| {
            ReportError::Io(crate::io::IoError::Write {
                path: figures_dir.clone(),
                reason,
            })
        })?;
        remove_stale_figures(dir, self.summary.figures.iter());
        for (relative, bytes) in &self.files {
            outputs.bytes(&dir.join(relative), bytes)?;
        }
        Ok(())
    }
}

/// Draws the report in memory (see [`write_report`]).
pub fn render_report(
    inputs: &ReportInputs<'_>,
    params: &ReportParams,
) -> Result<RenderedReport, ReportError> {
    params.check()?;
    check_inputs(inputs)?;
    let derived = derive(inputs);
    let surfaces = derived
        .set_poses
        .as_ref()
        .map(|poses| figures::probe_surfaces(inputs.probes, inputs.kept, poses))
        .unwrap_or_default();
    let planned = plan(inputs, params, &derived, &surfaces);
    let rendered: Vec<Result<plot::Rendered, ReportError>> = planned
        .par_iter()
        .map(|(name, _, p)| p.render(name, params.formats))
        .collect();
    let mut figures = Vec::with_capacity(planned.len());
    for ((name, caption, p), r) in planned.into_iter().zip(rendered) {
        let r = r?;
        let skipped = match p {
            Planned::Skip(reason) => Some(reason),
            _ => None,
        };
        figures.push((
            FigureRecord {
                name: name.to_owned(),
                caption,
                files: r.files.clone(),
                skipped,
            },
            r,
        ));
    }
    let tables = tables::tables(inputs);
    let html_text = html::html(inputs, &tables, &figures);
    let html_path = PathBuf::from("report.html");
    let mut files = Vec::new();
    let mut records = Vec::with_capacity(figures.len());
    for (record, r) in figures {
        // A figure's files are its PNG then its SVG (see `plot::render`).
        let bytes = r.png.into_iter().chain(r.svg.map(String::into_bytes));
        files.extend(record.files.iter().cloned().zip(bytes));
        records.push(record);
    }
    let md_text = markdown::markdown(inputs, &tables, &records);
    let md_path = PathBuf::from("report.md");
    files.push((html_path.clone(), html_text.into_bytes()));
    files.push((md_path.clone(), md_text.into_bytes()));
    Ok(RenderedReport {
        summary: ReportSummary {
            figures: records,
            html: html_path,
            markdown: md_path,
        },
        files,
    })
}
