//! The report's numbers as tables, built once and written both as HTML and Markdown.

use serde_json::Value;

use super::ReportInputs;
use smspace::analysis::AnalysisReport;
use smspace::embed::EmbedReport;
use smspace::kernel::TraceSummary;

/// A table: a title, a header row and body rows of plain text.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Table {
    /// Section title.
    pub(super) title: String,
    /// Column names.
    pub(super) header: Vec<String>,
    /// Rows, each as long as the header.
    pub(super) rows: Vec<Vec<String>>,
    /// A sentence under the table.
    pub(super) note: Option<String>,
}

impl Table {
    fn key_value(title: &str) -> Self {
        Self {
            title: title.to_owned(),
            header: vec!["quantity".to_owned(), "value".to_owned()],
            rows: Vec::new(),
            note: None,
        }
    }

    fn push(&mut self, key: impl Into<String>, value: impl Into<String>) {
        self.rows.push(vec![key.into(), value.into()]);
    }
}

/// A number with 4 significant digits (integers as they are, `inf`, `NaN`).
pub(super) fn num(v: f64) -> String {
    if v.is_nan() {
        return "NaN".to_owned();
    }
    if v.is_infinite() {
        return if v > 0.0 { "inf" } else { "-inf" }.to_owned();
    }
    if v == v.trunc() && v.abs() < 1e9 {
        return format!("{v:.0}");
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        return format!("{v:.3e}");
    }
    let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
    format!("{v:.digits$}")
}

fn list(values: impl IntoIterator<Item = String>) -> String {
    format!("[{}]", values.into_iter().collect::<Vec<_>>().join(", "))
}

/// All tables of the report, in order.
pub(super) fn tables(inputs: &ReportInputs<'_>) -> Vec<Table> {
    let mut out = Vec::new();
    if !inputs.stages.is_empty() {
        out.push(stage_table(inputs));
    }
    out.push(trace_table(inputs.trace, inputs.law));
    out.push(embed_table(inputs.embed_report));
    if let Some(quality) = inputs.embed_quality {
        out.extend(quality_table(quality));
    }
    if let Some(analysis) = inputs.analysis {
        out.extend(analysis_tables(analysis));
    }
    out.extend(affine_table(inputs));
    if let Some(inv) = inputs.invariance {
        out.extend(invariance_tables(&inv.report));
    }
    out
}

/// The rows of a law learned from a log: its method and rank, each log's held-out
/// error, and for the `invariants` law what its eigenproblem found.
fn law_rows(t: &mut Table, law: &serde_json::Value) {
    let text = |v: &serde_json::Value| v.as_str().map_or_else(|| v.to_string(), str::to_owned);
    t.push(
        "learned law (method, rank of its Jacobian)",
        format!("{}, rank {}", text(&law["method"]), law["rank"]),
    );
    for log in law["logs"].as_array().into_iter().flatten() {
        if let Some(error) = log["held_out_relative_rms"].as_f64() {
            t.push(
                format!("held-out error of the law, {}", text(&log["motors"])),
                format!(
                    "{} of the sensors' spread ({} samples of {})",
                    num(error),
                    log["held_out"],
                    log["samples"]
                ),
            );
        }
        if let Some(sigma) = log["noise"]["relative_overall"].as_f64() {
            t.push(
                format!("sensor noise measured, {}", text(&log["motors"])),
                format!(
                    "{} of the sensors' spread (the data resolve {})",
                    num(sigma),
                    num(log["noise"]["resolution"].as_f64().unwrap_or(f64::NAN))
                ),
            );
        }
    }
    if let Some(rank) = law["data_rank"]["rank"].as_u64() {
        let spectrum: Vec<String> = law["data_rank"]["spectrum"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(serde_json::Value::as_f64)
            .map(num)
            .collect();
        t.push(
            "rank in the data (slope spectrum; noise floor)",
            format!(
                "{rank} ({}; {})",
                spectrum.join(", "),
                num(law["data_rank"]["floor"].as_f64().unwrap_or(f64::NAN))
            ),
        );
    }
    if law["rank_source"].as_str() == Some("invariants") {
        t.push(
            "rank traced",
            format!(
                "{} (the invariants' Jacobian at nearly every probed sample, below the data's)",
                law["rank"].as_u64().unwrap_or(0)
            ),
        );
    }
    quality_rows(t, &law["quality"]);
    for warning in law["warnings"].as_array().into_iter().flatten() {
        t.push("warning", text(warning));
    }
    let invariants = &law["invariants"];
    if let (Some(kept), Some(features)) = (
        invariants["invariants"].as_u64(),
        invariants["features"].as_u64(),
    ) {
        t.push(
            "invariants kept (of the basis functions)",
            format!("{kept} of {features}"),
        );
        let lambdas: Vec<String> = invariants["eigenvalues"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(serde_json::Value::as_f64)
            .take(kept as usize + 2)
            .map(num)
            .collect();
        t.push("smallest eigenvalues λ", lambdas.join(", "));
        if let (Some(fitted), Some(held)) = (
            invariants["fitted_lambda"].as_f64(),
            invariants["held_out_lambda"].as_f64(),
        ) {
            t.push(
                "λ of the invariants kept: fitted pairs / held-out samples",
                format!("{} / {}", num(fitted), num(held)),
            );
        }
    }
}

/// The rows of a learned law's quality without the truth (`LawQuality`): samples per
/// dimension, the invariants' change between held-out sensory neighbours, the closure
/// rate of the traced curves.
fn quality_rows(t: &mut Table, quality: &serde_json::Value) {
    if let (Some(per), Some(dimension)) = (
        quality["samples_per_dimension"].as_f64(),
        quality["resolved_dimension"].as_u64(),
    ) {
        t.push(
            "fitted samples per dimension (of the dimension resolved)",
            format!("{} ({dimension})", num(per)),
        );
    }
    if let (Some(change), Some(ratio)) = (
        quality["neighbour_change"].as_f64(),
        quality["held_out_ratio"].as_f64(),
    ) {
        t.push(
            "change of the invariants between held-out sensory neighbours (of their spread; held-out / fitted λ)",
            format!("{}; {}", num(change), num(ratio)),
        );
    }
    if let Some(rate) = quality["closure_rate"].as_f64() {
        t.push(
            "traced curves that closed",
            format!("{:.1} %", 100.0 * rate),
        );
    }
}

fn stage_table(inputs: &ReportInputs<'_>) -> Table {
    let mut t = Table {
        title: "Stage times".to_owned(),
        header: vec![
            "stage".to_owned(),
            "seconds".to_owned(),
            "outputs".to_owned(),
        ],
        rows: Vec::new(),
        note: None,
    };
    for s in inputs.stages {
        t.rows.push(vec![
            s.stage.clone(),
            format!("{:.3}", s.seconds),
            if s.cached { "reused" } else { "computed" }.to_owned(),
        ]);
    }
    let total: f64 = inputs.stages.iter().map(|s| s.seconds).sum();
    t.rows.push(vec![
        "total".to_owned(),
        format!("{total:.3}"),
        String::new(),
    ]);
    t
}

fn trace_table(trace: &TraceSummary, law: Option<&serde_json::Value>) -> Table {
    let mut t = Table::key_value("Tracing of the kernel sets");
    if let Some(law) = law {
        law_rows(&mut t, law);
    }
    t.push("sets asked for", trace.total.to_string());
    t.push("sets traced and kept", trace.traced.to_string());
    t.push("sets failed", trace.failed.to_string());
    for (status, count) in &trace.by_status {
        t.push(format!("status {status}"), count.to_string());
    }
    if let Some(truth) = &trace.truth {
        t.push(
            "distance to the agent's true sets (median / 90th percentile)",
            format!(
                "{} / {} rad over {} sets traced in both (curve metric)",
                num(truth.median),
                num(truth.p90),
                truth.compared
            ),
        );
    }
    if let Some(noise) = &trace.noise {
        t.push(
            "sensor noise σ (median) and a traced point's position uncertainty (median / most)",
            format!(
                "{} sensor units over {} starts; {} / {} rad",
                num(noise.sigma),
                noise.sets,
                num(noise.position),
                num(noise.max_position)
            ),
        );
    }
    if let Some(rows) = &trace.sensor_rows {
        t.push(
            "sensor rows per start (median / 90th percentile / most; all)",
            format!(
                "{} / {} / {}; {}",
                rows.median, rows.p90, rows.max, rows.total
            ),
        );
    }
    if let Some([low, median, high]) = trace.covering_radius {
        t.push(
            "covering radius (min / median / max)",
            format!("{} / {} / {}", num(low), num(median), num(high)),
        );
        t.note = Some(
            "The kernels are surfaces (dimension k >= 2), each sampled by P points; the covering radius r of a sample is the largest distance from its kernel to its nearest point. The point metric (hausdorff) between two samples is within r_A + r_B of the Hausdorff distance between the kernels, and has a floor of about r even between kernels that nearly coincide, which hides the dimension; the surface metric (each point's tangent disk, see the surface module) is within max(r_A, r_B) plus the disks' deviation from the kernels (about curvature x r^2 / 2), and has no such floor.".to_owned(),
        );
    }
    t
}

fn embed_table(e: &EmbedReport) -> Table {
    let mut t = Table::key_value("Embedding");
    t.push("method", e.method.clone());
    t.push("points M", e.points.to_string());
    t.push("dimension d", e.dim.to_string());
    if !e.stress_trace.is_empty() {
        t.push("epochs", e.stress_trace.len().to_string());
        t.push("stress, first epoch", num(e.stress_trace[0]));
        t.push(
            "stress, last epoch",
            num(*e.stress_trace.last().unwrap_or(&f64::NAN)),
        );
    }
    if let Some(l) = e.lambda_end {
        t.push("final neighbourhood width lambda", num(l));
    }
    if !e.eigenvalues.is_empty() {
        t.push(
            "largest eigenvalues of B",
            list(e.eigenvalues.iter().take(5).map(|&v| num(v))),
        );
        if let Some(trace) = e.eigenvalue_trace {
            if trace.abs() > 0.0 {
                let kept: f64 = e.eigenvalues.iter().take(e.dim).sum();
                t.push("share of trace(B) kept by d eigenvalues", num(kept / trace));
            }
        }
    }
    if let Some(k) = e.k {
        t.push("graph neighbours k", k.to_string());
    }
    if !e.landmarks.is_empty() {
        t.push("landmarks", e.landmarks.len().to_string());
    }
    t
}

/// The note under the embedding's quality: what its trustworthiness and continuity
/// compare, told apart from those against the poses.
pub(super) const EMBEDDING_QUALITY_NOTE: &str = "Trustworthiness and continuity of the embedding (Venna & Kaski) compare the embedding with the learned distances between the sets: trustworthiness is 1 when every set's k nearest sets in the embedding are also among its k nearest by the learned distance (no false neighbours drawn), continuity is 1 when the learned nearest sets stay near in the embedding (no neighbours torn apart). They say how faithfully the embedding draws the learned metric, not whether that metric is spatial: the trustworthiness against the poses (agreement with the observer's poses, below) says that.";

/// The note under the agreement with the poses: what its trustworthiness compares.
pub(super) const POSE_AGREEMENT_NOTE: &str = "Trustworthiness and continuity against the poses compare the learned distances with the distances between the observer's poses (x, y and alpha, each scaled by its spread): trustworthiness is 1 when every set's k nearest sets by the learned distance are also among its k nearest by pose, continuity when sets of nearby poses are also near by the learned distance. They say whether the learned metric is spatial; the embedding's own trustworthiness (embedding quality, above) compares the embedding with the learned distances instead.";

/// The embedding's quality (`Y.embed.json`): its trustworthiness and continuity named
/// as the embedding's against the learned distances, with a note on each, and any
/// other number it holds as it is.
fn quality_table(quality: &Value) -> Option<Table> {
    let mut t = Table::key_value("Embedding quality (the embedding against the learned distances)");
    let k = quality["k"].as_u64();
    let with_k = |name: &str| match k {
        Some(k) => format!("{name} (k = {k})"),
        None => name.to_owned(),
    };
    let mut rest = serde_json::Map::new();
    for (key, value) in quality.as_object().into_iter().flatten() {
        match key.as_str() {
            "trustworthiness" => t.push(
                with_k("trustworthiness of the embedding vs the learned distances"),
                scalar(value),
            ),
            "continuity" => t.push(
                with_k("continuity of the embedding vs the learned distances"),
                scalar(value),
            ),
            "k" => {}
            _ => {
                rest.insert(key.clone(), value.clone());
            }
        }
    }
    let named = !t.rows.is_empty();
    flatten(&Value::Object(rest), "", &mut t);
    if named {
        t.note = Some(EMBEDDING_QUALITY_NOTE.to_owned());
    }
    (!t.rows.is_empty()).then_some(t)
}

/// Flattens a JSON document into `key.path → value` rows.
fn flatten(value: &Value, prefix: &str, t: &mut Table) {
    match value {
        Value::Object(map) => {
            for (k, v) in map {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(v, &key, t);
            }
        }
        Value::Array(items) if items.iter().all(|v| !v.is_object() && !v.is_array()) => {
            t.push(prefix, list(items.iter().map(scalar)));
        }
        Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                flatten(v, &format!("{prefix}[{i}]"), t);
            }
        }
        other => t.push(prefix, scalar(other)),
    }
}

fn scalar(v: &Value) -> String {
    match v {
        Value::Number(n) => n.as_f64().map_or_else(|| n.to_string(), num),
        Value::String(s) => s.clone(),
        Value::Null => "null".to_owned(),
        other => other.to_string(),
    }
}

fn analysis_tables(a: &AnalysisReport) -> Vec<Table> {
    let mut topo = Table::key_value("Topology (Vietoris-Rips persistence of the set metric)");
    topo.push("points M", a.points.to_string());
    topo.push("Betti numbers", list(a.betti.iter().map(|b| b.to_string())));
    let h = &a.homology;
    topo.push(
        "Rips threshold",
        format!("{} ({})", num(h.threshold), h.threshold_rule),
    );
    topo.push(
        "points used",
        format!(
            "{} ({}, covering radius {})",
            h.subsampling.points,
            h.subsampling.method,
            num(h.subsampling.covering_radius)
        ),
    );
    topo.push(
        "Betti rule",
        format!(
            "gap ratio {}, noise fraction {}",
            num(h.rule.gap_ratio),
            num(h.rule.noise_fraction)
        ),
    );
    for (dim, bars) in a.persistence.iter().enumerate() {
        let infinite = bars.iter().filter(|b| b.1.is_none()).count();
        topo.push(
            format!("H{dim} bars"),
            format!("{} ({infinite} infinite)", bars.len()),
        );
    }
    for (dim, longest) in h.longest_bars.iter().enumerate() {
        topo.push(
            format!("H{dim} longest bars"),
            list(longest.iter().map(|&v| num(v))),
        );
    }
    let d = &a.intrinsic_dimension;
    let mut dim = Table::key_value("Intrinsic dimension");
    if d.sets != "all" {
        dim.push(
            "computed on",
            format!(
                "the {} {} sets only (the probe grid's regular spacing biases nearest-neighbour ratios)",
                d.sets_used, d.sets
            ),
        );
    }
    dim.push(
        "TwoNN",
        format!(
            "{} ({} points, {} discarded as the largest ratios)",
            num(d.twonn),
            d.twonn_detail.points_used,
            num(d.twonn_discard)
        ),
    );
    dim.push(
        "Levina-Bickel MLE",
        format!(
            "{} (k = {}, {} points)",
            num(d.mle),
            d.mle_neighbors,
            d.mle_detail.points_used
        ),
    );
    for (name, estimate) in [
        ("TwoNN", &d.twonn_detail),
        ("Levina-Bickel MLE", &d.mle_detail),
    ] {
        dim.push(
            format!("{name} reliability"),
            reliability(&estimate.reliability),
        );
    }
    let mut out = vec![topo, dim];
    if let Some(g) = &a.agreement {
        let mut t = Table::key_value("Agreement with the observer's poses");
        t.push("Spearman (learned vs pose distances)", num(g.spearman));
        t.push(
            format!(
                "trustworthiness of the learned distances vs the poses (k = {})",
                g.neighbors
            ),
            num(g.trustworthiness),
        );
        t.push(
            format!(
                "continuity of the learned distances vs the poses (k = {})",
                g.neighbors
            ),
            num(g.continuity),
        );
        for (c, v) in &g.coordinates {
            t.push(
                format!("Spearman with |delta {c}|"),
                v.map_or_else(|| "constant coordinate".to_owned(), num),
            );
        }
        for (c, v) in &g.pose_scales {
            t.push(format!("spread of {c}"), num(*v));
        }
        t.note = Some(POSE_AGREEMENT_NOTE.to_owned());
        out.push(t);
    }
    out.extend(a.circle.as_ref().map(circle_table));
    if let Some(why) = &a.circle_missing {
        let mut t = Table::key_value("Circular coordinate");
        t.push("not computed", why.clone());
        out.push(t);
    }
    out.extend(a.compensability.as_ref().map(compensability_table));
    out
}

/// The most sets the affine-fit measures take from the babbled ones (evenly spaced):
/// their cost grows like the square.
const AFFINE_SETS: usize = 4000;

/// The positions `(x, y)` read off the embedding by one affine map
/// ([`smspace::analysis::affine`]), on the probe grid's sets when there is one (the
/// measures' source evaluates them on a regular grid), else on at most
/// [`AFFINE_SETS`] sets; none without poses. The analysis does not depend on the
/// embedding (a drawing), so the report computes these from the two.
fn affine_table(inputs: &ReportInputs<'_>) -> Option<Table> {
    let poses = inputs.poses?;
    let kept = inputs.kept;
    let y = inputs.embedding;
    if y.nrows() != kept.len() || kept.iter().any(|&r| r >= poses.nrows()) {
        return None;
    }
    let grid: Vec<usize> = (0..kept.len())
        .filter(|&i| inputs.probes.get([kept[i], 0]).is_some_and(|&p| p >= 0))
        .collect();
    let (rows, on) = if grid.len() >= 3 {
        (grid, "the probe grid's sets")
    } else {
        let step = kept.len().div_ceil(AFFINE_SETS).max(1);
        ((0..kept.len()).step_by(step).collect(), "the sets")
    };
    if rows.len() < 3 {
        return None;
    }
    let explored: Vec<usize> = rows.iter().map(|&i| kept[i]).collect();
    let positions = poses
        .select(ndarray::Axis(0), &explored)
        .select(ndarray::Axis(1), &[0, 1]);
    let representation = y.select(ndarray::Axis(0), &rows);
    let mut t = Table::key_value("Positions (x, y) read off the embedding by one affine map");
    match smspace::analysis::affine::affine_errors(representation.view(), positions.view()) {
        Ok(f) => {
            t.push("states", format!("{} ({on})", f.states));
            t.push("R² of the fit", num(f.r_squared));
            t.push("metric error", num(f.metric_error));
            t.push(
                "topology error in the positions",
                num(f.topology_error_positions),
            );
            t.push(
                "topology error in the embedding",
                num(f.topology_error_representation),
            );
        }
        Err(e) => t.push("not computed", e.to_string()),
    }
    t.note = Some(AFFINE_NOTE.to_owned());
    Some(t)
}

/// The note under the affine-fit measures.
pub(super) const AFFINE_NOTE: &str = "The measures of Laflaquière & Garcia Ortiz (NeurIPS 2019), for comparison with that work: the mean error of the pairwise distances between the fitted and the true positions over the largest distance (metric error), the same weighted toward small distances by exp(-10 d/d_max) (topology error in the positions), and the spread of the embedding among states close in space, weighted by exp(-50 d/d_max) (topology error in the embedding); all 0 for an affine image of the positions. They ask whether position is linearly readable from the drawing; a circle x plane drawn in 3-D is not, so a low R² here does not contradict the topology above.";

/// The note under the circular coordinate: what it is and what its agreement compares.
pub(super) const CIRCLE_NOTE: &str = "The circular coordinate gives every set a number on the circle from the manifold's longest loop: an integer cocycle of the landmarks' Rips complex at a scale inside the loop's bar, smoothed to its harmonic representative (persistent cohomology, as in DREiMac). Its agreement with an angle of the pose is the Fisher-Lee circular correlation |rho| (1 for the same angle up to a rotation or a reflection of the circle) and the mean resultant length of their difference. The class is fixed by the manifold but the coordinate only up to a function of the plane: the learned metric is a distance between motor configurations, in which turning the arm about its base is cheap, so the coordinate follows the orientation measured from the bearing of the sensor seen from the base (alpha - atan2(y, x)) more closely than the world's alpha.";

/// The circular coordinate: how it was found and its agreement with the pose's angles.
fn circle_table(c: &smspace::analysis::circular::CircleCoordinate) -> Table {
    let mut t = Table::key_value("Circular coordinate of the loop");
    t.push(
        "landmarks (covering radius)",
        format!("{} ({})", c.landmarks, num(c.covering_radius)),
    );
    t.push(
        "longest loop, [birth, death)",
        format!("[{}, {})", num(c.bar[0]), num(c.bar[1])),
    );
    t.push(
        "complex at scale",
        format!(
            "{} ({} edges, {} triangles)",
            num(c.scale),
            c.edges,
            c.triangles
        ),
    );
    t.push("classes of H1 at that scale", c.classes.to_string());
    for (name, g) in &c.agreement {
        t.push(
            format!("circular correlation with {name}"),
            format!(
                "{}{} (resultant {})",
                num(g.circular_correlation),
                if g.reversed { ", reversed" } else { "" },
                num(g.resultant)
            ),
        );
    }
    if let Some(plane) = &c.plane {
        t.push(
            "positions from the plane at fixed circle coordinate, R² (median, least)",
            format!(
                "{}, {} ({} slices of about {} sets)",
                num(plane.r_squared),
                num(plane.r_squared_min),
                plane.slices,
                plane.sets_per_slice
            ),
        );
    }
    t.note = Some(CIRCLE_NOTE.to_owned());
    t
}

/// The compensability analysis: `d` and its spread over the base points.
fn compensability_table(c: &smspace::analysis::compensability::CompensabilityReport) -> Table {
    let mut t = Table::key_value(
        "Compensability: sensory changes of the agent's movements that changes of the environment also make",
    );
    let counts = |h: &[usize]| {
        let parts: Vec<String> = h
            .iter()
            .enumerate()
            .filter(|&(_, &n)| n > 0)
            .map(|(d, n)| format!("d = {d}: {n}"))
            .collect();
        if parts.is_empty() {
            "none".to_owned()
        } else {
            parts.join(", ")
        }
    };
    let changes: Vec<String> = c
        .changes
        .iter()
        .map(|k| serde_json::to_value(k).map_or_else(|_| format!("{k:?}"), |v| scalar(&v)))
        .collect();
    t.push(
        "environment changes",
        format!(
            "{} ({} parameters)",
            changes.join(" + "),
            c.environment_parameters
        ),
    );
    let show = |d: Option<usize>| {
        d.map_or_else(|| "none (every point ambiguous)".into(), |d| d.to_string())
    };
    t.push(
        "dimension d of T_M ∩ T_E (most frequent)",
        show(c.dimension),
    );
    t.push("d per base point", counts(&c.histogram));
    t.push(
        "spatial dimension (d minus commuting directions)",
        show(c.spatial_dimension),
    );
    t.push(
        "spatial dimension per base point",
        counts(&c.spatial_histogram),
    );
    t.push(
        "ambiguous base points (no clear gap; not counted above)",
        format!("{} of {}", c.ambiguous, c.base_points),
    );
    t.push(
        "non-spatial motors",
        if c.non_spatial_motors.is_empty() {
            "none".to_owned()
        } else {
            list(c.non_spatial_motors.iter().map(|j| format!("motor {j}")))
        },
    );
    if let Some(reason) = c.points.iter().find_map(|b| b.ambiguous.first()) {
        t.note = Some(format!("First ambiguity: {reason}."));
    }
    t
}

/// `reliable`, `not checked`, or `unreliable:` and the reasons.
fn reliability(r: &smspace::analysis::dimension::Reliability) -> String {
    use smspace::analysis::dimension::ReliabilityStatus;
    match r.status {
        ReliabilityStatus::Reliable => "reliable".to_owned(),
        ReliabilityStatus::NotChecked => "not checked".to_owned(),
        ReliabilityStatus::Unreliable => format!(
            "unreliable: {}",
            r.reasons
                .iter()
                .map(|x| x.split_once(": ").map_or(x.as_str(), |(_, why)| why))
                .collect::<Vec<_>>()
                .join("; ")
        ),
    }
}

fn invariance_tables(r: &smspace::invariance::InvarianceReport) -> Vec<Table> {
    let mut summary = Table::key_value("Invariance across environments");
    summary.push("agent", r.agent.clone());
    for (i, e) in r.environments.iter().enumerate() {
        summary.push(
            format!("environment {}", i + 1),
            format!(
                "{} lights{}, {} sets traced",
                e.lights,
                e.seed.map_or_else(String::new, |s| format!(" (seed {s})")),
                e.traced
            ),
        );
    }
    summary.push("rows asked for", r.starts.to_string());
    summary.push(
        "rows traced in every environment",
        r.common_sets.to_string(),
    );
    summary.push("worst Mantel r of the set metric", num(r.min_mantel));
    summary.push(
        "best Mantel r of the sensor metric",
        num(r.max_sensor_mantel),
    );
    summary.push("largest set distance", num(r.max_set_distance));
    summary.push(
        "largest relative set distance",
        num(r.max_set_distance_relative),
    );
    summary.push(
        "largest distance-matrix difference",
        num(r.max_distance_difference),
    );
    summary.push(
        "smallest relative sensor difference",
        num(r.min_sensor_difference_relative),
    );
    let mut pairs = Table {
        title: "Invariance per pair of environments".to_owned(),
        header: [
            "pair",
            "Mantel r (sets)",
            "Mantel r (sensors)",
            "max set distance",
            "mean set distance",
            "max |D_a - D_b|",
            "max relative sensor difference",
        ]
        .map(str::to_owned)
        .to_vec(),
        rows: Vec::new(),
        note: Some(
            "The learned metric is the same in every environment (Mantel r near 1) while the raw sensor values differ."
                .to_owned(),
        ),
    };
    for p in &r.pairs {
        pairs.rows.push(vec![
            format!("{} - {}", p.a + 1, p.b + 1),
            num(p.mantel),
            num(p.sensor_mantel),
            num(p.max_set_distance),
            num(p.mean_set_distance),
            num(p.max_distance_difference),
            num(p.max_sensor_difference_relative),
        ]);
    }
    vec![summary, pairs]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_have_four_significant_digits() {
        assert_eq!(num(3.0), "3");
        assert_eq!(num(0.987654), "0.9877");
        assert_eq!(num(123.456), "123.5");
        assert_eq!(num(1.0e-5), "1.000e-5");
        assert_eq!(num(f64::INFINITY), "inf");
    }

    #[test]
    fn json_flattens_to_dotted_keys() {
        let v: Value = serde_json::json!({"a": {"b": 1.5, "c": [1, 2]}, "d": "x"});
        let mut t = Table::key_value("t");
        flatten(&v, "", &mut t);
        assert_eq!(
            t.rows,
            vec![
                vec!["a.b".to_owned(), "1.500".to_owned()],
                vec!["a.c".to_owned(), "[1, 2]".to_owned()],
                vec!["d".to_owned(), "x".to_owned()],
            ]
        );
    }
}
