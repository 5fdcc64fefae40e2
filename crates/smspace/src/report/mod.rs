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

use std::path::{Path, PathBuf};

use ndarray::{Array2, ArrayView2, ArrayView3};
use serde::{Deserialize, Serialize};

use crate::agent::{Agent, Environment};
use crate::analysis::{AnalysisReport, InvarianceReport};
use crate::embed::EmbedReport;
use crate::explore::Workspace;
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
    /// Their poses `(M0, 3)` as `(x, y, alpha)`.
    pub poses: ArrayView2<'a, f64>,
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

/// Draws every figure into `dir/figures/` and writes `dir/report.html` and
/// `dir/report.md`, atomically.
pub fn write_report(
    inputs: &ReportInputs<'_>,
    params: &ReportParams,
    dir: &Path,
) -> Result<ReportSummary, ReportError> {
    let _ = (inputs, params, dir);
    todo!("the report helper implements this")
}
