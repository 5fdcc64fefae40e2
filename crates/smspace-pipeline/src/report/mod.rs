//! The last stage: figures (PNG and SVG), `report.html` (with an interactive 3-D view
//! of the embedding) and `report.md`, from the outputs of the earlier stages.
//!
//! The report mirrors the paper's figures: Fig. 1 (toy-line's sensory manifolds in two
//! environments, section 2.2), Fig. 2 (toy-redundant's kernel lines and learned 1-D
//! manifold, section 2.3), Fig. 5a/5b/5d (the arm's explored configurations, kernel
//! sets in motor space, the CCA embedding with the probe sheets, section 3.3), plus
//! the embedding coloured by each pose coordinate, the persistence diagram, the CCA
//! `dy–dx` plot and the environment-invariance comparison. A figure whose inputs are
//! absent (e.g. no probe grid) is skipped, with its reason in `report.json`.
//!
//! **Warnings first.** Everything the run flagged (sets the tracer could not trace
//! or kept as single points, dimension estimates the data make unreliable, analyses
//! that did not run, and any figure of this run whose texts overlap) opens the report,
//! in a "Warnings" section ([`warnings`]).
//!
//! **Print sizes.** A panel prints `panel_width_in × panel_height_in` inches (3.5 ×
//! 2.8, one journal column; two-panel figures are a page wide), the PNG has `dpi`
//! (300) pixels per inch and says so, the SVG gives its size in inches, and every text
//! is at least 9 pt at that size. [`figure_texts`] returns the box of every text of
//! every figure, to check that none overlaps another.
//!
//! **One plotting library per run folder.** `report.html` loads plotly.js from
//! `assets/` next to it (written with the report, atomically) and shows the figures
//! from `figures/`; `self_contained = true` embeds both in the page instead.
//!
//! This module is the only one that knows every stage: it reads their outputs and
//! never runs them.

pub mod compare;
mod figures;
mod html;
mod layout;
mod markdown;
mod plan;
mod plot;
mod tables;
mod view3d;
pub mod warnings;

use std::path::{Path, PathBuf};

use ndarray::{Array2, ArrayView2, ArrayView3, Axis};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use layout::{FigureText, TextBox};
pub use warnings::Warning;

use smspace::agent::{Agent, Environment};
use smspace::analysis::AnalysisReport;
use smspace::embed::EmbedReport;
use smspace::explore::Workspace;
use smspace::invariance::InvarianceReport;
use smspace::io::Outputs;
use smspace::kernel::TraceSummary;

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
    /// A parameter is out of range, named by its table and key (located at its line
    /// in an experiment file).
    #[error(transparent)]
    InvalidParameter(#[from] smspace::params::InvalidParameter),
    /// A run folder to compare cannot be read ([`compare`]).
    #[error("run folder {}: {reason}", folder.display())]
    Run {
        /// The folder given.
        folder: PathBuf,
        /// What is missing or wrong, and the fix.
        reason: String,
    },
    /// Writing a file failed.
    #[error(transparent)]
    Io(#[from] smspace::io::IoError),
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
    /// Their poses `(M0, 3)` as `(x, y, alpha)`: the agent's planar pose, or a 3-D pose
    /// seen from above ([`GroundTruth::planar_view`](smspace::agent::GroundTruth::planar_view));
    /// `None` skips the figures of poses (with a sentence).
    pub poses: Option<ArrayView2<'a, f64>>,
    /// How `poses` were obtained; the captions of the pose figures say so for a 3-D
    /// agent.
    pub pose_view: smspace::agent::PlanarView,
    /// Probe labels `(M0, 3)`: `(orientation, ix, iy)`, `-1` for babbled rows.
    pub probes: ArrayView2<'a, i64>,
    /// The kernel sets `(M, P, N)`, one per kept exploration row.
    pub sets: ArrayView3<'a, f64>,
    /// `kept[i]`: the exploration row of set `i` (length `M`, increasing).
    pub kept: &'a [usize],
    /// How tracing went.
    pub trace: &'a TraceSummary,
    /// The law the sets were traced on, when it was learned from a log (`law` of
    /// `sets.trace.json`: [`smspace::learn::LawReport`] as JSON); `None` for an agent.
    pub law: Option<&'a serde_json::Value>,
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
    /// Warnings of the earlier stages that the report does not derive itself from the
    /// inputs above (it derives those of the trace summary and the analysis).
    pub warnings: &'a [Warning],
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
    /// Kernel sets drawn in Fig. 2 (Fig. 5b draws the first 12 of them, one colour
    /// each). Default 40.
    pub sample_sets: usize,
    /// Seed of the samples above. Default 1.
    pub seed: u64,
    /// Print width of one figure panel, inches. Default 3.5 (one journal column; a
    /// figure of two panels side by side is 7 in, a page).
    pub panel_width_in: f64,
    /// Print height of one figure panel, inches. Default 2.8.
    pub panel_height_in: f64,
    /// Pixels per inch of the PNG figures at their print size. Default 300.
    pub dpi: u32,
    /// `true`: `report.html` embeds plotly.js and the figures, one file that works
    /// anywhere; `false`: it loads them from `assets/` and `figures/` next to it, one
    /// copy of the plotting library per run folder. Default `false`.
    pub self_contained: bool,
    /// Most sets the figures and the 3-D view of a pipeline run draw: above it they
    /// are drawn from a sample (every probe-grid set and babbled sets drawn at random
    /// with `seed`), named at the top of the report. Default 5000.
    pub max_sets: usize,
}

impl Default for ReportParams {
    fn default() -> Self {
        Self {
            formats: FigureFormats::PngAndSvg,
            sample_configurations: 60,
            sample_sets: 40,
            seed: 1,
            panel_width_in: 3.5,
            panel_height_in: 2.8,
            dpi: 300,
            self_contained: false,
            max_sets: 5000,
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
    /// What the run flagged, as listed at the top of the report.
    #[serde(default)]
    pub warnings: Vec<Warning>,
    /// The figures, in the report's order.
    pub figures: Vec<FigureRecord>,
    /// Files `report.html` loads, relative to the report folder (`assets/…`; empty
    /// when self-contained).
    #[serde(default)]
    pub assets: Vec<PathBuf>,
    /// `report.html`, relative to the report folder.
    pub html: PathBuf,
    /// `report.md`, relative to the report folder.
    pub markdown: PathBuf,
}

/// Largest side of a panel accepted, in pixels (`inches × dpi`).
const MAX_PANEL_PIXELS: f64 = 3000.0;

impl ReportParams {
    /// The size of one panel in pixels, `(width, height)`: its print size times `dpi`
    /// (a figure is one to four panels).
    pub fn panel_pixels(&self) -> (u64, u64) {
        let dpi = f64::from(self.dpi);
        let pixels = |inches: f64| (inches * dpi).round().max(0.0) as u64;
        (pixels(self.panel_width_in), pixels(self.panel_height_in))
    }

    /// Checks the parameters.
    pub fn check(&self) -> Result<(), ReportError> {
        if self.max_sets < 100 {
            return Err(smspace::params::InvalidParameter::new(
                "report",
                "max_sets",
                self.max_sets.to_string(),
                "must be at least 100 sets (the figures need that many to show a manifold)"
                    .to_owned(),
            )
            .into());
        }
        if !(72..=1200).contains(&self.dpi) {
            return Err(smspace::params::InvalidParameter::new(
                "report",
                "dpi",
                self.dpi.to_string(),
                "must be between 72 and 1200 pixels per inch".to_owned(),
            )
            .into());
        }
        for (name, value, least) in [
            ("panel_width_in", self.panel_width_in, 2.0),
            ("panel_height_in", self.panel_height_in, 1.5),
        ] {
            let most = MAX_PANEL_PIXELS / f64::from(self.dpi);
            if !(value.is_finite() && value >= least && value <= most) {
                return Err(smspace::params::InvalidParameter::new(
                    "report",
                    name,
                    value.to_string(),
                    format!(
                        "must be between {least} and {most:.2} inches (at most {MAX_PANEL_PIXELS} pixels at dpi = {}); figures with smaller panels cannot hold their 9-point text",
                        self.dpi
                    ),
                )
                .into());
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

/// Draws every figure into `dir/figures/` and writes `dir/report.html` and
/// `dir/report.md` (and, unless `self_contained`, `dir/assets/` with plotly.js): all
/// of them together or none ([`smspace::io::Outputs`]).
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
    /// Every file of the report (plotly.js under `assets/` unless self-contained,
    /// `report.html`, the figures, `report.md`), relative to the report folder, with
    /// its bytes.
    pub files: Vec<(PathBuf, Vec<u8>)>,
}

impl RenderedReport {
    /// Stages every file under `dir` into `outputs` (making `dir/figures` and
    /// `dir/assets`), and removes the figure files of an earlier report that this one
    /// does not write (a format no longer asked for, a figure now skipped).
    pub fn write_into(&self, outputs: &mut Outputs, dir: &Path) -> Result<(), ReportError> {
        let folders: std::collections::BTreeSet<PathBuf> = std::iter::once(dir.join("figures"))
            .chain(
                self.files
                    .iter()
                    .filter_map(|(relative, _)| dir.join(relative).parent().map(Path::to_owned)),
            )
            .collect();
        for folder in folders {
            std::fs::create_dir_all(&folder).map_err(|reason| {
                ReportError::Io(smspace::io::IoError::Write {
                    path: folder.clone(),
                    reason,
                })
            })?;
        }
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
    let derived = plan::derive(inputs);
    let planned = plan::plan(inputs, params, &derived);
    let print = plot::Print {
        dpi: f64::from(params.dpi),
    };
    let (rendered, layout) = draw_all(&planned, params.formats, print);
    let mut warnings = warnings::warnings(inputs);
    for text in layout {
        for problem in text?.iter().flat_map(FigureText::problems) {
            warnings.push(Warning::new("report", format!("figure layout: {problem}")));
        }
    }
    let mut figures = Vec::with_capacity(planned.len());
    for ((name, caption, p), r) in planned.into_iter().zip(rendered) {
        let r = r?;
        let skipped = match p {
            plan::Planned::Skip(reason) => Some(reason),
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
    let mut files = Vec::new();
    let mut assets = Vec::new();
    if !params.self_contained {
        let (path, bytes) = html::plotly_file();
        assets.push(path.clone());
        files.push((path, bytes));
    }
    let tables = tables::tables(inputs);
    let page = html::Page {
        inputs,
        tables: &tables,
        figures: &figures,
        warnings: &warnings,
        self_contained: params.self_contained,
        ring_axes: derived.ring_frame.map(|frame| frame.axes()),
    };
    let html_path = PathBuf::from("report.html");
    files.push((html_path.clone(), page.html().into_bytes()));
    let mut records = Vec::with_capacity(figures.len());
    for (record, r) in figures {
        // A figure's files are its PNG then its SVG (see `plot::render`).
        let bytes = r.png.into_iter().chain(r.svg.map(String::into_bytes));
        files.extend(record.files.iter().cloned().zip(bytes));
        records.push(record);
    }
    let md_text = markdown::markdown(inputs, &tables, &records, &warnings);
    let md_path = PathBuf::from("report.md");
    files.push((md_path.clone(), md_text.into_bytes()));
    Ok(RenderedReport {
        summary: ReportSummary {
            warnings,
            figures: records,
            assets,
            html: html_path,
            markdown: md_path,
        },
        files,
    })
}

/// A figure's images, and its text as drawn (`None` when skipped).
type Drawings = (
    Vec<Result<plot::Rendered, ReportError>>,
    Vec<Result<Option<FigureText>, ReportError>>,
);

/// Draws every image of every planned figure and records its text (the layout
/// check), one task each, so that the largest figures keep both threads busy; each
/// figure's images come back in the order of `formats` (PNG first).
fn draw_all(
    planned: &[plan::PlannedFigure<'_>],
    formats: FigureFormats,
    print: plot::Print,
) -> Drawings {
    /// One image of figure `.0`, or its text when `.1` is `None`.
    type Task = (usize, Option<plot::ImageFormat>);
    enum Done {
        Image(Result<plot::Rendered, ReportError>),
        Text(Result<Option<FigureText>, ReportError>),
    }
    let tasks: Vec<Task> = (0..planned.len())
        .flat_map(|f| {
            formats
                .images()
                .iter()
                .map(move |&format| (f, Some(format)))
                .chain(std::iter::once((f, None)))
        })
        .collect();
    let done: Vec<Done> = tasks
        .par_iter()
        .map(|&(f, format)| {
            let (name, _, p) = &planned[f];
            match format {
                Some(format) => Done::Image(p.render(name, format, print)),
                None => Done::Text(p.record(name, print)),
            }
        })
        .collect();
    let mut rendered: Vec<Result<plot::Rendered, ReportError>> = Vec::with_capacity(planned.len());
    let mut texts = Vec::with_capacity(planned.len());
    let mut images = Ok(plot::Rendered::default());
    for done in done {
        match done {
            Done::Image(image) => {
                images = images.and_then(|so_far| Ok(so_far.merge(image?)));
            }
            Done::Text(text) => {
                // A figure's text is its last task: its images are all in.
                rendered.push(std::mem::replace(
                    &mut images,
                    Ok(plot::Rendered::default()),
                ));
                texts.push(text);
            }
        }
    }
    (rendered, texts)
}

/// The text of every figure [`write_report`] would draw with these inputs and
/// parameters, as drawn in the PNG (skipped figures are left out): for checking that
/// no two texts overlap, that none leaves its figure and that none is smaller than
/// 9 pt ([`FigureText::problems`]). Nothing is written.
pub fn figure_texts(
    inputs: &ReportInputs<'_>,
    params: &ReportParams,
) -> Result<Vec<FigureText>, ReportError> {
    params.check()?;
    check_inputs(inputs)?;
    let derived = plan::derive(inputs);
    let print = plot::Print {
        dpi: f64::from(params.dpi),
    };
    let recorded: Vec<Result<Option<FigureText>, ReportError>> =
        plan::plan(inputs, params, &derived)
            .par_iter()
            .map(|(name, _, p)| p.record(name, print))
            .collect();
    let mut out = Vec::new();
    for r in recorded {
        out.extend(r?);
    }
    Ok(out)
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
