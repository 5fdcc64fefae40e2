//! `analyze`: topology, dimension and agreement with the poses of the learned metric
//! (paper section 3.3). On the landmark path ([`crate::scale`]): persistent
//! homology of the first `min(L, max_points)` landmarks in the order chosen (their
//! covering radius over every set reported), TwoNN and MLE from the kNN lists of the
//! babbled sets (the lists the dense path sorts out of `D`: the same estimates), and
//! the agreement with the poses on the `L` landmarks (`analysis.json` `scale`).

use std::path::Path;

use serde::Serialize;

use ndarray::{Axis, Slice};

use super::{Keyed, LandmarkGraph, SetDistances, Stage, StageContext, StageInput, World};
use crate::manifest::StageId;
use smspace::agent::GroundTruth;
use smspace::analysis::compensability::compensability;
use smspace::analysis::dimension::{mle_neighbours, twonn_neighbours};
use smspace::analysis::{
    agreement, analyze_on, circle_of, rips_persistence, AnalysisError, AnalysisParams,
    AnalysisReport, AnalysisValidParams, DimensionSets, HomologySummary, IntrinsicDimension,
    ScaleSummary, Subsampling,
};
use smspace::explore::{is_babbled, Exploration};
use smspace::io::Outputs;
use smspace::kernel::TracedSets;
use smspace::progress::Progress;

/// The `analyze` stage: the `[analysis]` table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AnalyzeStage {
    /// Analysis parameters.
    pub analysis: AnalysisParams,
}

/// What `analyze` reads.
#[derive(Debug, Clone, Copy)]
pub struct AnalyzeInput<'a> {
    /// The poses and probe labels of the explored rows.
    pub exploration: &'a Keyed<Exploration>,
    /// Which rows were traced.
    pub traced: &'a Keyed<TracedSets>,
    /// The distances between the traced sets (either path).
    pub distances: &'a Keyed<SetDistances>,
    /// The agent and its environment, read only by the compensability analysis
    /// (`[analysis.compensability]`; none otherwise, and then not in the key).
    pub world: Option<&'a Keyed<World>>,
}

impl StageInput for AnalyzeInput<'_> {
    fn keys(&self) -> Vec<&str> {
        let mut keys = vec![
            self.exploration.key.as_str(),
            self.traced.key.as_str(),
            self.distances.key.as_str(),
        ];
        keys.extend(self.world.map(|w| w.key.as_str()));
        keys
    }
}

const REPORT_FILE: &str = "analysis.json";

impl Stage for AnalyzeStage {
    const ID: StageId = StageId::Analyze;
    type Input<'a> = AnalyzeInput<'a>;
    type Output = AnalysisReport;

    fn compute(
        &self,
        input: &AnalyzeInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<AnalysisReport> {
        let exploration = &input.exploration.value;
        let kept = &input.traced.kept;
        // The dimension on the babbled sets: the probe grid's regular spacing biases
        // nearest-neighbour ratios.
        let babbled: Vec<usize> = kept
            .iter()
            .enumerate()
            .filter(|&(_, &row)| is_babbled(exploration.probes.row(row)))
            .map(|(i, _)| i)
            .collect();
        // Without a ground truth there is no agreement to measure (the summary says so).
        let params = self.analysis.check()?;
        let mut report = match &input.distances.value {
            SetDistances::Dense(distances) => {
                let truth = exploration.ground_truth.as_ref().map(|t| t.select(kept));
                analyze_on(
                    distances,
                    truth.as_ref().map(|t| t.view()),
                    Some(DimensionSets {
                        rows: &babbled,
                        name: "babbled",
                    }),
                    &params,
                    context.progress,
                )?
            }
            SetDistances::Landmarks(graph) => {
                // The landmarks' poses by increasing set index (the agreement's order).
                let truth = exploration.ground_truth.as_ref().map(|t| {
                    let mut rows: Vec<usize> = graph.landmarks.rows.clone();
                    rows.sort_unstable();
                    let rows: Vec<usize> = rows.iter().map(|&r| kept[r]).collect();
                    t.select(&rows)
                });
                analyze_landmarks(graph, truth.as_ref(), &params, context.progress)?
            }
        };
        if let (Some(params), Some(world)) = (&self.analysis.compensability, input.world) {
            let environment = world
                .value
                .environments
                .first()
                .ok_or(smspace::kernel::KernelError::MissingEnvironment)?;
            let starts = exploration.babbled_rows();
            let motors = exploration.motors.select(ndarray::Axis(0), &starts);
            let mut found = compensability(
                world.value.agent.as_ref(),
                environment,
                motors.view(),
                &params.check().map_err(AnalysisError::from)?,
            )
            .map_err(AnalysisError::from)?;
            // Rows of the exploration, not of the babbled selection.
            found.points.iter_mut().for_each(|b| b.row = starts[b.row]);
            report.compensability = Some(found);
        }
        Ok(report)
    }

    fn save(
        &self,
        _: &AnalyzeInput<'_>,
        report: &AnalysisReport,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        report.write_into(outputs, &dir.join(REPORT_FILE))?;
        Ok(())
    }

    fn load(&self, _: &AnalyzeInput<'_>, dir: &Path) -> crate::Result<AnalysisReport> {
        Ok(AnalysisReport::load(&dir.join(REPORT_FILE))?)
    }

    fn summary(&self, a: &AnalysisReport) -> String {
        let on = a.scale.as_ref().map_or_else(String::new, |s| {
            format!(
                " (landmark path: homology of {} landmarks, dimension from the {}-NN of {} sets, agreement on {} landmarks)",
                s.homology_points, s.knn, s.dimension_sets, s.agreement_sets
            )
        });
        let agreement = a.agreement.as_ref().map_or_else(
            || ", no agreement (the agent has no ground truth)".to_owned(),
            |g| format!(", Spearman {:.3}", g.spearman),
        );
        let compensable = a.compensability.as_ref().map_or_else(String::new, |c| {
            format!(
                ", compensable d = {} (spatial {}; histogram {:?}, {} of {} base points ambiguous)",
                c.dimension.map_or("none".into(), |d| d.to_string()),
                c.spatial_dimension.map_or("none".into(), |d| d.to_string()),
                c.histogram,
                c.ambiguous,
                c.base_points
            )
        });
        let circle = a.circle.as_ref().map_or_else(String::new, |c| {
            let scores: Vec<String> = c
                .agreement
                .iter()
                .map(|(name, g)| format!("{:.3} with {name}", g.circular_correlation))
                .collect();
            if scores.is_empty() {
                ", a circular coordinate".to_owned()
            } else {
                format!(", circle coordinate {}", scores.join(", "))
            }
        });
        format!(
            "betti {:?}, TwoNN {:.2}, MLE {:.2}{agreement}{circle}{compensable}{on}",
            a.betti, a.intrinsic_dimension.twonn, a.intrinsic_dimension.mle
        )
    }
}

/// The analysis on the landmark path (module docs); `truth` holds the landmarks' poses
/// by increasing set index.
fn analyze_landmarks(
    graph: &LandmarkGraph,
    truth: Option<&GroundTruth>,
    params: &AnalysisValidParams,
    progress: &dyn Progress,
) -> Result<AnalysisReport, AnalysisError> {
    let p = params.params();
    let l = &graph.landmarks;
    let count = l.len().min(p.max_points);
    let first = l.landmarks.view();
    let first = first
        .slice_axis_move(Axis(0), Slice::from(..count))
        .slice_axis_move(Axis(1), Slice::from(..count));
    let persistence = rips_persistence(first, p.max_homology_dim, p.threshold, progress)?;
    // The covering radius of those landmarks over every set.
    let covering_radius = l.covering_radius_of_first(count);
    let near = graph.knn.distances.view();
    progress.start("dimension", 2);
    let columns = |k: usize| near.slice_axis(Axis(1), Slice::from(..k.min(near.ncols())));
    let twonn = twonn_neighbours(columns(2), p.twonn_discard)?;
    progress.advance(1);
    let mle = mle_neighbours(columns(p.mle_neighbors))?;
    progress.advance(1);
    progress.finish();
    // On the landmarks by increasing set index: with every set a landmark, the dense
    // path's pairs in its order (ties in ranks go to the smaller index alike).
    let mut order: Vec<usize> = (0..l.len()).collect();
    order.sort_unstable_by_key(|&a| l.rows[a]);
    let sorted = l
        .landmarks
        .view()
        .select(Axis(0), &order)
        .select(Axis(1), &order);
    let agreement = match truth {
        Some(t) => Some(agreement::agreement_of(
            sorted.view(),
            t.view(),
            p.neighbors,
        )?),
        None => None,
    };
    // The circle on the landmarks, in the same order as their poses.
    let (circle, circle_missing) = circle_of(sorted.view(), truth.map(|t| t.view()), p, progress)?;
    let rule = params.betti_rule();
    let all = graph.knn_sets.len() == l.sets();
    Ok(AnalysisReport {
        points: l.sets(),
        betti: rule.betti(&persistence),
        betti_ambiguities: rule.ambiguities(&persistence),
        persistence: smspace::analysis::bars(&persistence),
        homology: HomologySummary::of(
            &persistence,
            p,
            Subsampling {
                method: if count < l.len() {
                    format!(
                        "landmarks ({}, the first {count} of {}; covering radius: an upper bound through each set's nearest landmarks)",
                        l.selection,
                        l.len()
                    )
                } else {
                    format!("landmarks ({}, all {count})", l.selection)
                },
                points: count,
                covering_radius,
            },
            rule,
        ),
        intrinsic_dimension: IntrinsicDimension {
            twonn: twonn.dimension,
            mle: mle.dimension,
            twonn_detail: twonn,
            mle_detail: mle,
            twonn_discard: p.twonn_discard,
            mle_neighbors: p.mle_neighbors,
            sets: if all {
                smspace::analysis::all_sets()
            } else {
                "babbled".to_owned()
            },
            sets_used: graph.knn_sets.len(),
        },
        agreement,
        circle,
        circle_missing,
        affine: None,
        compensability: None,
        scale: Some(ScaleSummary {
            sets: l.sets(),
            landmarks: l.len(),
            selection: l.selection.to_string(),
            covering_radius: l.covering_radius,
            homology_points: count,
            dimension_sets: graph.knn_sets.len(),
            knn: graph.knn.k(),
            agreement_sets: l.len(),
        }),
    })
}
