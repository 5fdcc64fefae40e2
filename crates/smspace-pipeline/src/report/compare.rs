//! Runs side by side (the pupil arm and its spatial sets): one page with
//! every run's dimension estimates, Betti numbers, agreement with the poses, the
//! compensability dimension `d` per base point, and the runs' embeddings next to each
//! other.
//!
//! It reads what the pipeline wrote in each run folder and runs nothing:
//! `analysis.json` (required: Betti numbers, TwoNN and MLE, trustworthiness,
//! `compensability`), and when present `manifest.json` (the experiment's name),
//! `config.resolved.toml` (the set metric, `[kernel] spatial`), `sets.trace.json`
//! (points per set, the motors the sets were extended along) and the embedding figure
//! `figures/embedding-pose.png` (or `.svg`; else `fig5d-embedding-probes`), embedded
//! in the page so that it can be moved. A missing folder or `analysis.json` is an error
//! naming it; a missing optional file leaves its cell as `–`.
//!
//! The page compares what each run measured, with the settings that make numbers
//! comparable (M, the metric, points per set) in its first rows: the dimension of the
//! learned manifold is the paper's section 3.3 question, the compensable dimension
//! `d = dim(T_M ∩ T_E)` per base point that of the conclusion (Philipona et al. 2003,
//! [`smspace::analysis::compensability`]).

use std::path::{Path, PathBuf};

use super::html::{escape, STYLE};
use super::ReportError;
use smspace::analysis::AnalysisReport;
use smspace::kernel::TraceReport;

/// Figures tried, in order, as a run's embedding (file stems under `figures/`).
const EMBEDDING_FIGURES: [&str; 2] = ["embedding-pose", "fig5d-embedding-probes"];

/// What the page shows of one run, read from its folder ([`RunDigest::read`]).
#[derive(Debug, Clone)]
pub struct RunDigest {
    /// The run folder.
    pub folder: PathBuf,
    /// The experiment's name (`manifest.json`), or the folder's name.
    pub name: String,
    /// `[metric] metric` of `config.resolved.toml`, if readable.
    pub metric: Option<String>,
    /// The trace report (`sets.trace.json`), if readable.
    pub trace: Option<TraceReport>,
    /// The analysis (`analysis.json`).
    pub analysis: AnalysisReport,
    /// The embedding figure: its file name and bytes.
    pub embedding: Option<(String, Vec<u8>)>,
}

fn run_error(folder: &Path, reason: String) -> ReportError {
    ReportError::Run {
        folder: folder.to_owned(),
        reason,
    }
}

impl RunDigest {
    /// Reads a run folder (module docs): an error naming the folder when it is missing
    /// or has no readable `analysis.json`.
    pub fn read(folder: &Path) -> Result<Self, ReportError> {
        if !folder.is_dir() {
            return Err(run_error(
                folder,
                "no such folder; give the folder of a run (smspace run writes runs/<name>)".into(),
            ));
        }
        let analysis_file = folder.join("analysis.json");
        if !analysis_file.is_file() {
            return Err(run_error(
                folder,
                format!(
                    "{} is missing: the run has not reached its analyze stage (run smspace run on its experiment)",
                    analysis_file.display()
                ),
            ));
        }
        let analysis =
            AnalysisReport::load(&analysis_file).map_err(|e| run_error(folder, e.to_string()))?;
        let name = crate::manifest::Manifest::previous(folder)
            .map(|m| m.experiment)
            .unwrap_or_else(|| folder_name(folder));
        Ok(Self {
            folder: folder.to_owned(),
            name,
            metric: resolved_metric(folder),
            trace: smspace::io::read_json(&folder.join("sets.trace.json"), "trace report").ok(),
            analysis,
            embedding: embedding_figure(folder),
        })
    }

    /// What the sets are: traced, or spanned along motors (`kernel::spatial`).
    fn sets(&self) -> String {
        match &self.trace {
            None => "–".into(),
            Some(t) if t.extended_along.is_empty() => {
                format!("kernel sets, {} points each", t.points)
            }
            Some(t) => format!(
                "spatial sets: spanned along motor(s) {:?}, {} points each",
                t.extended_along, t.points
            ),
        }
    }
}

fn folder_name(folder: &Path) -> String {
    folder.file_name().map_or_else(
        || folder.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

/// `[metric] metric` of the run's resolved configuration.
fn resolved_metric(folder: &Path) -> Option<String> {
    let text = std::fs::read_to_string(folder.join("config.resolved.toml")).ok()?;
    let table: toml::Table = toml::from_str(&text).ok()?;
    Some(table.get("metric")?.get("metric")?.as_str()?.to_owned())
}

/// The first embedding figure of [`EMBEDDING_FIGURES`] the run drew, PNG before SVG.
fn embedding_figure(folder: &Path) -> Option<(String, Vec<u8>)> {
    EMBEDDING_FIGURES.iter().find_map(|stem| {
        ["png", "svg"].iter().find_map(|ext| {
            let name = format!("{stem}.{ext}");
            let bytes = std::fs::read(folder.join("figures").join(&name)).ok()?;
            Some((name, bytes))
        })
    })
}

/// One row of the table: a quantity and its value in every run.
type Row = (String, Vec<String>);

fn fixed(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "–".into()
    }
}

/// The rows of the comparison table, in order (module docs).
pub fn comparison_rows(runs: &[RunDigest]) -> Vec<(String, Vec<String>)> {
    let each = |f: &dyn Fn(&RunDigest) -> String| runs.iter().map(f).collect::<Vec<_>>();
    let mut rows: Vec<Row> = vec![
        ("experiment".into(), each(&|r| r.name.clone())),
        ("sets".into(), each(&|r| r.sets())),
        (
            "set metric".into(),
            each(&|r| r.metric.clone().unwrap_or_else(|| "–".into())),
        ),
        ("M (sets)".into(), each(&|r| r.analysis.points.to_string())),
        (
            "Betti numbers".into(),
            each(&|r| format!("{:?}", r.analysis.betti)),
        ),
        (
            "TwoNN dimension".into(),
            each(&|r| fixed(r.analysis.intrinsic_dimension.twonn, 2)),
        ),
        (
            "MLE dimension".into(),
            each(&|r| fixed(r.analysis.intrinsic_dimension.mle, 2)),
        ),
    ];
    let agreement = |f: fn(&smspace::analysis::Agreement) -> f64| {
        move |r: &RunDigest| {
            r.analysis
                .agreement
                .as_ref()
                .map_or("–".into(), |a| fixed(f(a), 3))
        }
    };
    rows.push((
        "trustworthiness vs poses".into(),
        each(&agreement(|a| a.trustworthiness)),
    ));
    rows.push((
        "continuity vs poses".into(),
        each(&agreement(|a| a.continuity)),
    ));
    rows.push((
        "Spearman vs pose distances".into(),
        each(&agreement(|a| a.spearman)),
    ));
    rows.extend(compensability_rows(runs));
    rows
}

/// The compensability rows: the most frequent `d`, the base points of every `d` seen
/// in any run (the histogram, side by side), the spatial dimension, the ambiguous
/// points and the non-spatial motors.
fn compensability_rows(runs: &[RunDigest]) -> Vec<Row> {
    let reports: Vec<_> = runs
        .iter()
        .map(|r| r.analysis.compensability.as_ref())
        .collect();
    if reports.iter().all(Option::is_none) {
        return Vec::new();
    }
    let each = |f: &dyn Fn(&smspace::analysis::compensability::CompensabilityReport) -> String| {
        reports
            .iter()
            .map(|c| c.map_or_else(|| "not analysed".into(), f))
            .collect::<Vec<_>>()
    };
    let show = |d: Option<usize>| d.map_or_else(|| "none".into(), |d| d.to_string());
    let mut rows: Vec<Row> = vec![(
        "compensable dimension d (most frequent)".into(),
        each(&|c| show(c.dimension)),
    )];
    let longest = reports
        .iter()
        .flatten()
        .map(|c| c.histogram.len())
        .max()
        .unwrap_or(0);
    for d in 0..longest {
        let seen = reports
            .iter()
            .flatten()
            .any(|c| c.histogram.get(d).is_some_and(|&n| n > 0));
        if seen {
            rows.push((
                format!("base points with d = {d}"),
                each(&|c| c.histogram.get(d).copied().unwrap_or(0).to_string()),
            ));
        }
    }
    rows.push((
        "ambiguous base points (not counted above)".into(),
        each(&|c| format!("{} of {}", c.ambiguous, c.base_points)),
    ));
    rows.push((
        "spatial dimension (d minus commuting directions)".into(),
        each(&|c| show(c.spatial_dimension)),
    ));
    rows.push((
        "non-spatial motors".into(),
        each(&|c| format!("{:?}", c.non_spatial_motors)),
    ));
    rows
}

/// The page (module docs).
pub fn comparison_html(runs: &[RunDigest]) -> String {
    let names: Vec<String> = runs.iter().map(|r| r.name.clone()).collect();
    let mut out = String::new();
    out.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    out.push_str(&format!(
        "<title>smspace: {}</title>\n",
        escape(&names.join(" vs "))
    ));
    out.push_str(STYLE);
    out.push_str("\n<style>.side { display: flex; gap: 1em; } .side figure { flex: 1; }</style>\n</head>\n<body>\n");
    out.push_str(&format!("<h1>{}</h1>\n", escape(&names.join(" vs "))));
    out.push_str("<p>The runs side by side: what each measured (paper section 3.3: the learned manifold's topology, dimension and agreement with the poses; the conclusion: the dimension d of the compensable sensory changes per base point). Read the first rows before comparing numbers: M, the metric and the points per set change the dimension estimates.</p>\n");
    out.push_str("<h2>Numbers</h2>\n<table>\n<tr><th>quantity</th>");
    for r in runs {
        out.push_str(&format!(
            "<th>{}<br><small>{}</small></th>",
            escape(&r.name),
            escape(&r.folder.display().to_string())
        ));
    }
    out.push_str("</tr>\n");
    for (quantity, values) in comparison_rows(runs) {
        out.push_str(&format!("<tr><td>{}</td>", escape(&quantity)));
        for v in values {
            out.push_str(&format!("<td>{}</td>", escape(&v)));
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</table>\n<h2>Embeddings</h2>\n<div class=\"side\">\n");
    for r in runs {
        out.push_str(&embedding_html(r));
    }
    out.push_str("</div>\n</body>\n</html>\n");
    out
}

fn embedding_html(run: &RunDigest) -> String {
    use base64::Engine;
    let name = escape(&run.name);
    match &run.embedding {
        None => format!(
            "<figure><p class=\"skipped\">{name}: no embedding figure in {}/figures</p></figure>\n",
            escape(&run.folder.display().to_string())
        ),
        Some((file, bytes)) => {
            let mime = if file.ends_with(".svg") {
                "image/svg+xml"
            } else {
                "image/png"
            };
            format!(
                "<figure><img alt=\"{name}: {file}\" src=\"data:{mime};base64,{}\"><figcaption>{name}: {file}</figcaption></figure>\n",
                base64::engine::general_purpose::STANDARD.encode(bytes),
                file = escape(file)
            )
        }
    }
}

/// Reads every run folder and writes the page to `out` (atomically): an error naming
/// the first folder that cannot be read, or when fewer than two runs are given.
pub fn write_comparison(folders: &[PathBuf], out: &Path) -> Result<(), ReportError> {
    if folders.len() < 2 {
        return Err(smspace::params::InvalidParameter::new(
            "compare",
            "runs",
            folders.len(),
            "give at least two run folders to compare",
        )
        .into());
    }
    let runs = folders
        .iter()
        .map(|f| RunDigest::read(f))
        .collect::<Result<Vec<_>, _>>()?;
    let mut outputs = smspace::io::Outputs::new();
    outputs.bytes(out, comparison_html(&runs).as_bytes())?;
    outputs.commit()?;
    Ok(())
}
