//! `analyze`: topology, dimension and agreement with the poses of the learned metric
//! (paper section 3.3).

use std::path::Path;

use serde::Serialize;

use super::{Keyed, Stage, StageContext, StageInput, World};
use crate::analysis::compensability::compensability;
use crate::analysis::AnalysisError;
use crate::analysis::{analyze_on, AnalysisParams, AnalysisReport, DimensionSets};
use crate::explore::Exploration;
use crate::io::Outputs;
use crate::kernel::TracedSets;
use crate::metric::DistanceMatrix;
use crate::pipeline::StageId;

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
    /// The distances between the traced sets.
    pub distances: &'a Keyed<DistanceMatrix>,
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
            .filter(|&(_, &row)| exploration.probes[[row, 0]] < 0)
            .map(|(i, _)| i)
            .collect();
        // Without a ground truth there is no agreement to measure (the summary says so).
        let truth = exploration.ground_truth.as_ref().map(|t| t.select(kept));
        let mut report = analyze_on(
            &input.distances.value,
            truth.as_ref().map(|t| t.view()),
            Some(DimensionSets {
                rows: &babbled,
                name: "babbled",
            }),
            &self.analysis.check()?,
            context.progress,
        )?;
        if let (Some(params), Some(world)) = (&self.analysis.compensability, input.world) {
            let environment = world
                .value
                .environments
                .first()
                .ok_or(crate::kernel::KernelError::MissingEnvironment)?;
            let starts: Vec<usize> = (0..exploration.motors.nrows())
                .filter(|&row| exploration.probes[[row, 0]] < 0)
                .collect();
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
        format!(
            "betti {:?}, TwoNN {:.2}, MLE {:.2}{agreement}{compensable}",
            a.betti, a.intrinsic_dimension.twonn, a.intrinsic_dimension.mle
        )
    }
}
