//! `analyze`: topology, dimension and agreement with the poses of the learned metric
//! (paper section 3.3).

use std::path::Path;

use ndarray::{Array2, Axis};
use serde::Serialize;

use super::{Keyed, Stage, StageContext, StageInput};
use crate::analysis::{analyze_on, AnalysisParams, AnalysisReport, DimensionSets};
use crate::explore::Exploration;
use crate::io::{self, Outputs};
use crate::kernel::TracedSets;
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
    pub distances: &'a Keyed<Array2<f64>>,
}

impl StageInput for AnalyzeInput<'_> {
    fn keys(&self) -> Vec<&str> {
        vec![&self.exploration.key, &self.traced.key, &self.distances.key]
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
        let poses = exploration.poses.select(Axis(0), kept);
        Ok(analyze_on(
            input.distances.view(),
            Some(poses.view()),
            Some(DimensionSets {
                rows: &babbled,
                name: "babbled",
            }),
            &self.analysis.check()?,
            context.progress,
        )?)
    }

    fn save(
        &self,
        _: &AnalyzeInput<'_>,
        report: &AnalysisReport,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        outputs.json(&dir.join(REPORT_FILE), report)?;
        Ok(())
    }

    fn load(&self, _: &AnalyzeInput<'_>, dir: &Path) -> crate::Result<AnalysisReport> {
        Ok(io::read_json(&dir.join(REPORT_FILE), "analysis report")?)
    }

    fn summary(&self, a: &AnalysisReport) -> String {
        let agreement = a
            .agreement
            .as_ref()
            .map(|g| format!(", Spearman {:.3}", g.spearman))
            .unwrap_or_default();
        format!(
            "betti {:?}, TwoNN {:.2}, MLE {:.2}{agreement}",
            a.betti, a.intrinsic_dimension.twonn, a.intrinsic_dimension.mle
        )
    }
}
