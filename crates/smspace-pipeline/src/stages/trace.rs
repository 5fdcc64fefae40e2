//! `trace`: the kernel sets `M^i` through the explored configurations (paper section
//! 3.2, step 2, appendix A).

use std::path::Path;

use serde::Serialize;

use super::{label, Keyed, Stage, StageContext, StageInput, World};
use crate::data::DataSource;
use crate::manifest::StageId;
use ndarray::ArrayView2;
use smspace::analysis::compensability::{compensability, CompensabilityParams};
use smspace::analysis::AnalysisError;
use smspace::explore::Exploration;
use smspace::io::Outputs;
use smspace::kernel::{
    extend_along, trace_sets, KernelError, Spatial, TraceMethod, TraceParams, TraceValidParams,
    TracedSets, TruthErrors,
};
use smspace::learn::budget::{learn_from_agent, BudgetParams};
use smspace::learn::trace_learned;
use smspace::params::InvalidParameter;

/// The `trace` stage: the `[kernel]` table (and, with `spatial = "compensable"`, the
/// `[analysis.compensability]` table that finds the non-spatial motors).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TraceStage {
    /// Tracing parameters.
    pub kernel: TraceParams,
    /// With `spatial = "compensable"`: the analysis that finds the motors to extend
    /// the sets along (none otherwise, and then not in the key).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compensability: Option<CompensabilityParams>,
    /// With `method = "learned"`: the `[learn]` table (the budget of sensor rows, the
    /// babbling rounds, verification and the law); none otherwise, and then not in the
    /// key.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub learn: Option<BudgetParams>,
}

impl TraceStage {
    /// The stage of the `[kernel]` table; `analysis` is the `[analysis.compensability]`
    /// table (its defaults when absent), read only with `spatial = "compensable"`;
    /// `learn` the `[learn]` table, read only with `method = "learned"`.
    pub fn new(
        kernel: TraceParams,
        analysis: Option<&CompensabilityParams>,
        learn: Option<&BudgetParams>,
    ) -> Self {
        let compensability =
            (kernel.spatial == Spatial::Compensable).then(|| analysis.cloned().unwrap_or_default());
        let learn = (kernel.method == TraceMethod::Learned)
            .then(|| learn.cloned())
            .flatten();
        Self {
            kernel,
            compensability,
            learn,
        }
    }

    /// `method = "learned"`: the law learned from babbling the agent within the
    /// `[learn]` budget, the starts' sets traced on it (the `[kernel]` table's
    /// parameters) and verified against the agent; the rows spent, the rounds and the
    /// verdicts in the report's `budget`.
    fn learned_sets(
        &self,
        world: &World,
        motors: ArrayView2<'_, f64>,
        context: &StageContext<'_>,
    ) -> crate::Result<TracedSets> {
        let Some(learn) = &self.learn else {
            return Err(KernelError::from(InvalidParameter::new(
                "kernel",
                "method",
                "learned",
                "needs a [learn] table with budget = ROWS (the sensor rows the agent may be read in all)",
            ))
            .into());
        };
        if world.data.is_some() {
            return Err(KernelError::from(InvalidParameter::new(
                "kernel",
                "method",
                "learned",
                "babbles the agent itself; a [data] table learns from a log: keep one of the two",
            ))
            .into());
        }
        let budget = learn.check()?;
        let law = learn.law.check()?;
        let environment = world
            .environments
            .first()
            .ok_or(KernelError::MissingEnvironment)?;
        let trace = TraceParams {
            method: TraceMethod::Sensory,
            ..self.kernel.clone()
        };
        let found = learn_from_agent(
            world.agent.as_ref(),
            environment,
            motors,
            world.workspace,
            &budget,
            &law,
            &trace,
            context.memory_limit_bytes,
            context.progress,
        )?;
        Ok(found.into_traced())
    }

    /// With `spatial = "compensable"`: the non-spatial motors the compensability
    /// analysis finds at the babbled starts, and the sets extended along them.
    fn spatial_sets(
        &self,
        traced: TracedSets,
        world: &World,
        exploration: &Exploration,
    ) -> crate::Result<TracedSets> {
        let Some(params) = &self.compensability else {
            return Ok(traced);
        };
        let environment = world
            .environments
            .first()
            .ok_or(KernelError::MissingEnvironment)?;
        let babbled = exploration.babbled_rows();
        let starts = exploration.motors.select(ndarray::Axis(0), &babbled);
        let report = compensability(
            world.agent.as_ref(),
            environment,
            starts.view(),
            &params.check().map_err(AnalysisError::from)?,
        )
        .map_err(AnalysisError::from)?;
        let removed = report.dimension.zip(report.spatial_dimension);
        if report.non_spatial_motors.is_empty() && removed.is_some_and(|(d, s)| s < d) {
            return Err(KernelError::from(InvalidParameter::new(
                "kernel",
                "spatial",
                "compensable",
                "the compensability analysis found non-spatial directions that are not the axis of one motor; only motors whose axis is non-spatial (a pupil's aperture) can be spanned",
            ))
            .into());
        }
        let space = world.agent.motor_space();
        Ok(extend_along(
            traced,
            &space,
            &report.non_spatial_motors,
            self.kernel.spatial_samples,
        )?)
    }
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

/// The learned sets of a run from a simulated log (or the sets of an agent with
/// simulated noise) against the true sets of `agent` (the exact agent) through
/// the same starts (traced with the same `[kernel]` parameters on the agent in the main
/// environment, where the log was simulated), by [`smspace::learn::set_errors`] under
/// the motors' periods; `None` when no start was traced in both.
fn truth_errors(
    world: &World,
    agent: &dyn smspace::agent::Agent,
    motors: ArrayView2<'_, f64>,
    params: &TraceValidParams,
    learned: &TracedSets,
    progress: &dyn smspace::progress::Progress,
) -> crate::Result<Option<TruthErrors>> {
    let Ok(period) = smspace::learn::comparison_period(&agent.motor_space().periods()) else {
        return Ok(None);
    };
    let truth = trace_sets(
        agent,
        world.environments.first(),
        motors,
        world.workspace.as_ref(),
        params,
        progress,
    )?;
    Ok(smspace::learn::set_errors(learned, &truth, &period)
        .ok()
        .map(|e| TruthErrors {
            compared: e.compared,
            median: e.median,
            p90: e.p90,
        }))
}

/// The sets file in the run folder; its companions follow [`TracedSets::save`].
const SETS_FILE: &str = "sets.npy";

impl TraceStage {
    /// The sets of the stage (see [`Stage::compute`]).
    fn compute_sets(
        &self,
        input: &TraceInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<TracedSets> {
        let world = &input.world.value;
        let motors = input.exploration.motors.view();
        if self.kernel.method == TraceMethod::Learned {
            let mut traced = self.learned_sets(world, motors, context)?;
            // Against the agent's true sets (its kinematic sets, when it has a ground
            // truth: no sensor is read for them).
            let exact = world.agent.noiseless().unwrap_or(world.agent.as_ref());
            if !traced.kept.is_empty() && exact.sensed_configuration().is_some() {
                let truth = TraceParams {
                    method: TraceMethod::Kinematic,
                    points: self.kernel.points,
                    ..TraceParams::default()
                }
                .check()?;
                traced.report.summary.truth =
                    truth_errors(world, exact, motors, &truth, &traced, context.progress)?;
            }
            return self.checked(traced, motors, world, &input.exploration.value);
        }
        let params = self.kernel.check()?;
        let traced = match &world.data {
            Some(data) => {
                let law = data.law(
                    world.simulator(),
                    context.memory_limit_bytes,
                    context.progress,
                )?;
                // Its report's `law`: the law's, with the closure rate and warnings.
                let mut traced = trace_learned(&law, motors, &self.kernel, context.progress)?;
                if matches!(data.source, DataSource::Simulate(_)) && !traced.kept.is_empty() {
                    traced.report.summary.truth = truth_errors(
                        world,
                        world.agent.as_ref(),
                        motors,
                        &params,
                        &traced,
                        context.progress,
                    )?;
                }
                traced
            }
            None => {
                let mut traced = trace_sets(
                    world.agent.as_ref(),
                    world.environments.first(),
                    motors,
                    world.workspace.as_ref(),
                    &params,
                    context.progress,
                )?;
                // An agent with simulated noise: the sets against the exact agent's.
                if let Some(exact) = world.agent.noiseless() {
                    if !traced.kept.is_empty() {
                        traced.report.summary.truth =
                            truth_errors(world, exact, motors, &params, &traced, context.progress)?;
                    }
                }
                traced
            }
        };
        self.checked(traced, motors, world, &input.exploration.value)
    }
}

impl TraceStage {
    /// Fails when fewer than two sets were kept (naming the statuses), else extends
    /// the sets along the non-spatial motors when asked.
    fn checked(
        &self,
        traced: TracedSets,
        motors: ArrayView2<'_, f64>,
        world: &World,
        exploration: &Exploration,
    ) -> crate::Result<TracedSets> {
        if traced.kept.len() < 2 {
            // Sets failed: the statuses and what each suggests.
            traced.report.summary.require(2)?;
            return Err(KernelError::NothingTraced {
                traced: traced.kept.len(),
                total: motors.nrows(),
                by_status: format!("{:?}", traced.report.summary.by_status),
            }
            .into());
        }
        self.spatial_sets(traced, world, exploration)
    }
}

impl Stage for TraceStage {
    const ID: StageId = StageId::Trace;
    type Input<'a> = TraceInput<'a>;
    type Output = TracedSets;

    fn compute(
        &self,
        input: &TraceInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<TracedSets> {
        self.compute_sets(input, context)
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
    /// [`TraceSummary::warnings`](smspace::kernel::TraceSummary::warnings) (sets missing
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
        if !t.report.extended_along.is_empty() {
            line.push_str(&format!(
                "; extended along the non-spatial motors {:?} (spatial = \"compensable\")",
                t.report.extended_along
            ));
        }
        if let Some(t) = &s.truth {
            line.push_str(&format!(
                "; against the agent's true sets ({} in both): median {:.4} rad, 90th percentile {:.4} rad",
                t.compared, t.median, t.p90
            ));
        }
        if let Some(noise) = &s.noise {
            line.push_str(&format!(
                "; noisy sensors: σ = {:.3e} (median over {} starts), position uncertainty {:.4} rad (median)",
                noise.sigma, noise.sets, noise.position
            ));
        }
        if let Some(rows) = s.sensor_rows {
            line.push_str(&format!(
                "; {} sensor rows per start (median; 90th percentile {}, most {}), {} in all",
                rows.median, rows.p90, rows.max, rows.total
            ));
        }
        if let Some([low, median, high]) = s.covering_radius {
            line.push_str(&format!(
                "; covering radius {low:.3} / {median:.3} / {high:.3} rad (min / median / max)"
            ));
        }
        if let Some(rate) = s.closure_rate {
            line.push_str(&format!("; {:.0} % of the curves closed", 100.0 * rate));
        }
        // The learned route's budget: the rows read and the sets verification dropped.
        if let Some(budget) = &t.report.budget {
            let rows = &budget["rows"];
            line.push_str(&format!(
                "; {} sensor rows read in all ({} babbling in {} rounds, {} for the agent's own slope, {} verifying)",
                rows["total"],
                rows["babble"],
                budget["rounds"].as_array().map_or(0, Vec::len),
                rows["agent_rank"],
                rows["verify"]
            ));
            for warning in budget["warnings"].as_array().into_iter().flatten() {
                if let Some(warning) = warning.as_str() {
                    line.push_str(&format!("; warning: {warning}"));
                }
            }
        }
        for warning in s.warnings() {
            line.push_str(&format!("; warning: {warning}"));
        }
        // A learned law's warnings (too few samples, noise, low closure).
        if let Some(law) = &t.report.law {
            for warning in law["warnings"].as_array().into_iter().flatten() {
                if let Some(warning) = warning.as_str() {
                    line.push_str(&format!("; warning: {warning}"));
                }
            }
        }
        line
    }
}
