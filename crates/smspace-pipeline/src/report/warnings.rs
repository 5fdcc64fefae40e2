//! The report's "Warnings" section: everything the run flagged, gathered from the
//! stages' outputs so that nobody has to find it in a log — sets the tracer could not
//! trace or kept as single points (`sets.trace.json`), intrinsic-dimension estimates
//! the data make unreliable (`analysis.json`, [`smspace::analysis::dimension`]),
//! analyses that did not run, the warnings of a law learned from a log (too few samples,
//! invariants that do not predict held-out readings: `law` of `sets.trace.json`), and
//! whatever the pipeline passes on
//! ([`ReportInputs::warnings`](super::ReportInputs::warnings)).

use serde::{Deserialize, Serialize};

use super::ReportInputs;
use smspace::analysis::dimension::DimensionEstimate;

/// One thing the run flagged.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Warning {
    /// The stage whose output it comes from (`trace`, `analyze`, …).
    pub stage: String,
    /// What is wrong and what it means, in a sentence or two.
    pub message: String,
}

impl Warning {
    /// A warning of `stage`.
    pub fn new(stage: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            stage: stage.into(),
            message: message.into(),
        }
    }
}

/// Every warning of the run, in the order of the stages.
pub(super) fn warnings(inputs: &ReportInputs<'_>) -> Vec<Warning> {
    let mut out = law_warnings(inputs);
    out.extend(trace_warnings(inputs));
    out.extend(analysis_warnings(inputs));
    out.extend(invariance_warnings(inputs));
    out.extend(inputs.warnings.iter().cloned());
    out
}

/// `n of total sets`, with the right plural.
fn of_sets(n: usize, total: usize) -> String {
    format!("{n} of {total} set{}", if total == 1 { "" } else { "s" })
}

/// The warnings of the law the sets were traced on, when it was learned from a log:
/// the data cannot support it, and the learned sets may be far from the true ones.
fn law_warnings(inputs: &ReportInputs<'_>) -> Vec<Warning> {
    inputs
        .law
        .and_then(|law| law["warnings"].as_array())
        .into_iter()
        .flatten()
        .filter_map(|message| message.as_str())
        .map(|message| Warning::new("learn", message))
        .collect()
}

/// The sets whose status is neither `closed` nor `open`.
fn trace_warnings(inputs: &ReportInputs<'_>) -> Vec<Warning> {
    let trace = inputs.trace;
    let mut out = Vec::new();
    if trace.total > 0 && trace.traced == 0 {
        out.push(Warning::new(
            "trace",
            format!("none of the {} sets asked for was traced", trace.total),
        ));
    }
    for (status, &count) in &trace.by_status {
        let traced_shapes = ["closed", "open", "pieces", "covered"];
        // A body whose every set is a point: said once, by the summary's warning below.
        let all_points = status == "point" && count == trace.traced;
        if count == 0 || traced_shapes.contains(&status.as_str()) || all_points {
            continue;
        }
        let sets = of_sets(count, trace.total);
        let message = match status.as_str() {
            "point" => format!(
                "{sets} are single points: at those configurations the sensation fixes every motor (no redundancy), so the sets carry no shape and their distances are those of their configurations (expected for an agent with as many motors as sensed pose coordinates, such as toy-line)"
            ),
            "not-closed" => format!(
                "{sets} did not close into a loop within the tracer's step budget and were left out"
            ),
            "singular" => format!(
                "{sets} were left out because the Jacobian lost rank there (sensory method: too few lights in view; kinematic: a singular posture)"
            ),
            "corrector-failed" => format!(
                "{sets} were left out because the corrector could not bring a traced point back onto the set"
            ),
            "outside-workspace" => format!(
                "{sets} start outside the working space and were left out"
            ),
            "cover-budget" => format!(
                "{sets} were left out because the dense covering of their k-dimensional kernel needed more than max_cover_points nodes (raise cover_step or max_cover_points)"
            ),
            "row-budget" => format!(
                "{sets} were left out because they read [kernel] max_rows sensor rows before their trace ended (raise max_rows)"
            ),
            "retraced" => format!(
                "{sets} were left out because their noisy traces ran back over their own path"
            ),
            other => format!("{sets} have status {other} (see sets.trace.json)"),
        };
        out.push(Warning::new("trace", message));
    }
    out.extend(
        trace
            .warnings()
            .into_iter()
            .map(|message| Warning::new("trace", message)),
    );
    out
}

/// Unreliable dimension estimates, and a missing analysis or agreement.
fn analysis_warnings(inputs: &ReportInputs<'_>) -> Vec<Warning> {
    let Some(analysis) = inputs.analysis else {
        return vec![Warning::new(
            "analyze",
            "the analysis did not run: no Betti numbers, intrinsic dimension or agreement with the poses",
        )];
    };
    let mut out: Vec<Warning> = analysis
        .betti_ambiguities
        .iter()
        .map(|why| Warning::new("analyze", format!("the topology is uncertain: {why}")))
        .collect();
    let d = &analysis.intrinsic_dimension;
    let mut dimension = |name: &str, value: f64, estimate: &DimensionEstimate| {
        if estimate.reliability.is_unreliable() {
            out.push(Warning::new(
                "analyze",
                format!(
                    "the {name} intrinsic dimension ({value:.3}) is unreliable: {}",
                    estimate
                        .reliability
                        .reasons
                        .iter()
                        .map(|r| r.split_once(": ").map_or(r.as_str(), |(_, why)| why))
                        .collect::<Vec<_>>()
                        .join("; ")
                ),
            ));
        }
    };
    dimension("TwoNN", d.twonn, &d.twonn_detail);
    dimension("Levina-Bickel", d.mle, &d.mle_detail);
    if analysis.agreement.is_none() {
        out.push(Warning::new(
            "analyze",
            "no poses were given: the agreement with the observer's poses was not computed",
        ));
    }
    out
}

/// An invariance comparison that did not run although there are environments to
/// compare, or that kept no row.
fn invariance_warnings(inputs: &ReportInputs<'_>) -> Vec<Warning> {
    let environments = inputs.environments.len();
    match inputs.invariance {
        None if environments >= 2 => vec![Warning::new(
            "invariance",
            format!(
                "the experiment has {environments} environments but the invariance comparison did not run (analysis.invariance_starts = 0?)"
            ),
        )],
        Some(inv) if inv.report.common_sets == 0 => vec![Warning::new(
            "invariance",
            format!(
                "none of the {} starts was traced in every environment: nothing was compared",
                inv.report.starts
            ),
        )],
        _ => Vec::new(),
    }
}
