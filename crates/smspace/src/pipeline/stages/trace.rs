//! `trace`: the kernel sets `M^i` through the explored configurations (paper section
//! 3.2, step 2, appendix A).

use std::path::Path;

use serde::Serialize;

use super::{label, Keyed, Stage, StageContext, StageInput, World};
use crate::explore::Exploration;
use crate::io::Outputs;
use crate::kernel::{trace_sets, KernelError, TraceParams, TracedSets};
use crate::pipeline::StageId;

/// The `trace` stage: the `[kernel]` table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TraceStage {
    /// Tracing parameters.
    pub kernel: TraceParams,
}

/// What `trace` reads.
#[derive(Debug, Clone, Copy)]
pub struct TraceInput<'a> {
    /// The agent, and the environment its sensory method sees (the first).
    pub world: &'a Keyed<World>,
    /// The starts: every explored configuration.
    pub exploration: &'a Keyed<Exploration>,
}

impl StageInput for TraceInput<'_> {
    fn keys(&self) -> Vec<&str> {
        vec![&self.world.key, &self.exploration.key]
    }
}

/// The sets file in the run folder; its companions follow [`TracedSets::save`].
const SETS_FILE: &str = "sets.npy";

impl Stage for TraceStage {
    const ID: StageId = StageId::Trace;
    type Input<'a> = TraceInput<'a>;
    type Output = TracedSets;

    fn compute(
        &self,
        input: &TraceInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<TracedSets> {
        let world = &input.world.value;
        let params = self.kernel.check()?;
        let motors = input.exploration.motors.view();
        let traced = trace_sets(
            world.agent.as_ref(),
            world.environments.first(),
            motors,
            world.workspace.as_ref(),
            &params,
            context.progress,
        )?;
        if traced.kept.len() < 2 {
            return Err(KernelError::NothingTraced {
                traced: traced.kept.len(),
                total: motors.nrows(),
                by_status: format!("{:?}", traced.report.summary.by_status),
            }
            .into());
        }
        Ok(traced)
    }

    fn save(
        &self,
        _: &TraceInput<'_>,
        traced: &TracedSets,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        traced.write_into(outputs, &dir.join(SETS_FILE))?;
        Ok(())
    }

    fn load(&self, _: &TraceInput<'_>, dir: &Path) -> crate::Result<TracedSets> {
        Ok(TracedSets::load(&dir.join(SETS_FILE))?)
    }

    /// `N of M sets traced (method), P points each`, with the pieces found, the
    /// covering radii of k-D kernels, and every warning of
    /// [`TraceSummary::warnings`](crate::kernel::TraceSummary::warnings) (sets missing
    /// pieces, bodies without redundancy), so that the log never reads as if all were
    /// fine when it is not.
    fn summary(&self, t: &TracedSets) -> String {
        let s = &t.report.summary;
        let mut line = format!(
            "{} of {} sets traced ({}), {} points each",
            s.traced,
            s.total,
            label(&self.kernel.method),
            t.sets.dim().1
        );
        if s.with_several_pieces > 0 {
            line.push_str(&format!(
                "; {} with several pieces ({})",
                s.with_several_pieces,
                label(&self.kernel.components)
            ));
        }
        if let Some([low, median, high]) = s.covering_radius {
            line.push_str(&format!(
                "; covering radius {low:.3} / {median:.3} / {high:.3} rad (min / median / max)"
            ));
        }
        for warning in s.warnings() {
            line.push_str(&format!("; warning: {warning}"));
        }
        line
    }
}
