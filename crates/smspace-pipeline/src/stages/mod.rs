//! The stages of a run as types: one file per stage, each behind the one [`Stage`]
//! trait.
//!
//! A stage is a serialisable struct that holds exactly the parameters its
//! [`compute`](Stage::compute) reads. Its cache key is
//!
//! ```text
//! key = BLAKE3(smspace version, stage name, JSON of the stage struct, keys of its inputs)
//! ```
//!
//! so a parameter cannot be read without being keyed: the struct *is* the key. What
//! flows between stages is typed and carries its own key ([`Keyed`]); an input struct
//! lists the keys of the values it borrows ([`StageInput::keys`]). What does not change
//! the results (progress, the memory limit, the run folder, the stages' timings) comes
//! in the [`StageContext`], which is not keyed.
//!
//! | stage | struct | input | output |
//! |---|---|---|---|
//! | `explore` | [`ExploreStage`] | [`World`] | [`Exploration`](smspace::explore::Exploration) |
//! | `trace` | [`TraceStage`] | world, exploration | [`TracedSets`](smspace::kernel::TracedSets) |
//! | `distances` | [`DistancesStage`] | traced sets (exploration: which are babbled) | [`SetDistances`]: the [`DistanceMatrix`](smspace::metric::DistanceMatrix), or landmarks and the kNN graph ([`crate::scale`]) |
//! | `embed` | [`EmbedStage`] | distances | [`EmbedOutputs`] |
//! | `analyze` | [`AnalyzeStage`] | exploration, traced sets, distances | [`AnalysisReport`](smspace::analysis::AnalysisReport) |
//! | `invariance` | [`InvarianceStage`] | world, exploration | [`InvarianceData`](crate::report::InvarianceData) |
//! | `report` | [`ReportStage`] | all of the above | [`ReportSummary`](crate::report::ReportSummary) |

mod analyze;
mod distances;
mod embed;
mod explore;
mod invariance;
mod report;
mod trace;

use std::path::Path;

use serde::Serialize;

use super::manifest::{hash_parts, SMSPACE_VERSION};
use super::StageId;
use crate::report::StageTiming;
use smspace::agent::{Agent, AgentConfig, Environment};
use smspace::explore::Workspace;
use smspace::io::Outputs;
use smspace::progress::Progress;

pub use analyze::{AnalyzeInput, AnalyzeStage};
pub use distances::{
    DistanceBackend, DistancesInput, DistancesStage, LandmarkGraph, LocalDistances, SetDistances,
};
pub use embed::{EmbedInput, EmbedOutputs, EmbedStage, DYDX_PAIRS, QUALITY_NEIGHBOURS};
pub use explore::{ExploreInput, ExploreStage};
pub use invariance::{InvarianceInput, InvarianceStage};
pub use report::{ReportInput, ReportStage};
pub use trace::{TraceInput, TraceStage};

/// One stage of the pipeline (see the module docs).
pub trait Stage: Serialize {
    /// Which stage this is (its name in `manifest.json` and in the observer's events).
    const ID: StageId;
    /// What the stage reads from the stages before it.
    type Input<'a>: StageInput
    where
        Self: 'a;
    /// What it produces, in memory.
    type Output;

    /// Computes the output from the inputs and the stage's own parameters.
    fn compute(
        &self,
        input: &Self::Input<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<Self::Output>;

    /// Stages the output's files for the run folder `dir` into `outputs` (every path
    /// inside `dir`). The run renames them into place together with the manifest,
    /// which records each file with the hash of the bytes staged ([`Outputs::staged`]).
    fn save(
        &self,
        input: &Self::Input<'_>,
        output: &Self::Output,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()>;

    /// Reads back what [`save`](Stage::save) wrote.
    fn load(&self, input: &Self::Input<'_>, dir: &Path) -> crate::Result<Self::Output>;

    /// One line on what the stage produced.
    fn summary(&self, output: &Self::Output) -> String;

    /// What a user should know before the stage is computed (not when it is reused):
    /// e.g. that it will take long, and why. `None` (the default) when nothing stands
    /// out. The run hands it to [`RunObserver::stage_note`](crate::RunObserver::stage_note).
    fn forecast(&self, _input: &Self::Input<'_>) -> Option<String> {
        None
    }

    /// The cache key: the stage's name and parameters and the keys of its inputs.
    fn key(&self, input: &Self::Input<'_>) -> String {
        let params = json(self);
        let mut parts: Vec<&[u8]> = vec![
            SMSPACE_VERSION.as_bytes(),
            Self::ID.name().as_bytes(),
            params.as_bytes(),
        ];
        parts.extend(input.keys().into_iter().map(str::as_bytes));
        hash_parts(&parts)
    }

    /// The part of the key the stage's own parameters make: the hash of its name and
    /// its struct, without the inputs' keys. Two stages with the same parameter key
    /// and the same inputs have the same [`key`](Stage::key).
    fn parameter_key(&self) -> String {
        let params = json(self);
        hash_parts(&[
            SMSPACE_VERSION.as_bytes(),
            Self::ID.name().as_bytes(),
            params.as_bytes(),
        ])
    }
}

/// The inputs of a stage: borrowed [`Keyed`] values.
pub trait StageInput {
    /// The keys of every value the stage reads, in a fixed order.
    fn keys(&self) -> Vec<&str>;
}

/// A stage's output (or the [`World`]) with the key it was made under.
#[derive(Debug, Clone, PartialEq)]
pub struct Keyed<T> {
    /// The value.
    pub value: T,
    /// Its key: a BLAKE3 hex digest.
    pub key: String,
}

impl<T> std::ops::Deref for Keyed<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.value
    }
}

/// What a stage may use that does not change its results, and so is not keyed.
pub struct StageContext<'a> {
    /// Observer of long loops.
    pub progress: &'a dyn Progress,
    /// Refuse a distance matrix larger than this many bytes; `None`: no limit.
    pub memory_limit_bytes: Option<u64>,
    /// The run folder (the report renders its figures straight into it).
    pub dir: &'a Path,
    /// The stages run so far, with their times (for the report's table).
    pub stage_times: &'a [StageTiming],
    /// Where the distance matrix is computed ([`LocalDistances`] unless
    /// [`run_with`](crate::run_with) names another backend).
    pub distances: &'a dyn DistanceBackend,
}

/// The agent, its environments and its working space: built from the `[agent]`,
/// `[environment]` and `[exploration]` tables when the experiment is checked, before
/// any stage runs.
#[derive(Debug)]
pub struct World {
    /// The agent's description (written into `exploration.json`).
    pub agent_config: AgentConfig,
    /// The agent.
    pub agent: Box<dyn Agent>,
    /// The environments, the main one first.
    pub environments: Vec<Environment>,
    /// The working space the agent explores, if it has one.
    pub workspace: Option<Workspace>,
    /// With a `[data]` table: the log the run learns the law from (explore picks its
    /// reference samples, trace traces on the learned law).
    pub data: Option<std::sync::Arc<crate::data::RunData>>,
}

impl World {
    /// What a simulated log is drawn from: the agent, the main environment, the
    /// working space.
    pub fn simulator(&self) -> crate::data::Simulator<'_> {
        crate::data::Simulator {
            agent: self.agent.as_ref(),
            environment: self.environments.first(),
            workspace: self.workspace,
        }
    }

    /// The world with its key: the agent's description, the environments' lights and
    /// the working space, and with `[data]` the log's source (files by content) and the
    /// law's parameters.
    pub fn keyed(self) -> Keyed<World> {
        let data = self.data.as_ref().map(|d| (&d.source, &d.law_params));
        let description = json(&(
            &self.agent_config,
            &self.environments,
            &self.workspace,
            data,
        ));
        let key = hash_parts(&[b"world", description.as_bytes()]);
        Keyed { value: self, key }
    }
}

/// JSON text of a serialisable value, for keys.
pub(crate) fn json<T: Serialize + ?Sized>(value: &T) -> String {
    serde_json::to_string(value).unwrap_or_else(|e| format!("unserialisable: {e}"))
}

/// The name a configuration file uses for an enum value (`"2pi"`, `"kinematic"`).
pub(crate) fn label<T: Serialize + std::fmt::Debug>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(s)) => s,
        _ => format!("{value:?}"),
    }
}
