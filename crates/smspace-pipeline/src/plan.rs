//! The checked experiment and the run's own types: the [`Plan`] that
//! [`check`](crate::check) makes and [`run`](crate::run) executes, the run's options
//! ([`RunOptions`], [`Recompute`]), its observer ([`RunObserver`]), what it produces
//! ([`RunSummary`]) and how it fails ([`PipelineError`]). The crate root re-exports
//! them.

use std::path::{Path, PathBuf};

use smspace::agent::Agent;
use smspace::analysis::AnalysisReport;
use smspace::io::IoError;
use smspace::progress::Progress;

use crate::config::{ConfigError, LoadedExperiment};
use crate::lock::{BusyFolder, LockError};
use crate::manifest::{Manifest, StageId, StageRecord};
use crate::stages::{
    self, AnalyzeStage, DistancesStage, EmbedStage, ExploreStage, InvarianceStage, Keyed,
    ReportStage, TraceStage, World,
};

/// Errors of a run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// The experiment is invalid; nothing ran.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The output folder cannot be made.
    #[error("cannot create the output folder {path}: {reason}")]
    CreateDir {
        /// The folder.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// A stage failed; the earlier stages' outputs are intact.
    #[error("stage `{stage}` failed: {reason}\n(the outputs of the stages before it are intact in {dir}; see manifest.json)")]
    Stage {
        /// The stage.
        stage: &'static str,
        /// The run folder.
        dir: PathBuf,
        /// Why it failed.
        reason: Box<crate::Error>,
    },
    /// Writing the manifest or the resolved configuration failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// Another process is writing the run folder (and [`BusyFolder::Refuse`]), or its
    /// lock file cannot be opened or locked.
    #[error(transparent)]
    Folder(#[from] LockError),
    /// A stage's estimated peak memory (or, before anything runs, the explored
    /// configurations or their kernel sets) exceeds the run's limit; the stage did
    /// not start.
    #[error("{what}: about {} needed, but the limit is {} (the memory available, or --max-memory); {fix}", smspace::metric::human_bytes(*needed), smspace::metric::human_bytes(*available))]
    OutOfMemory {
        /// What would not fit, with its size (e.g. `kernel sets (3500 × 100 × 4)`).
        what: String,
        /// Bytes needed.
        needed: u64,
        /// Bytes available.
        available: u64,
        /// Which keys to lower.
        fix: &'static str,
    },
    /// The run folder cannot be written (a read-only folder or file system) and the run
    /// would have to write it; nothing was written.
    #[error("{dir} cannot be written, and {what}: a read-only run folder can only be reused as it is (the same experiment and settings, every stage finished); run it into a writable folder with --out{}", reason.as_ref().map(|r| format!(" ({r})")).unwrap_or_default())]
    ReadOnly {
        /// The run folder.
        dir: PathBuf,
        /// Why the run must write (e.g. "stage `embed` must be computed").
        what: String,
        /// The operating system's reason, when a write was tried.
        reason: Option<std::io::Error>,
    },
}

/// Which stages run again.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Recompute {
    /// Only stages whose parameters or inputs changed, or whose outputs are missing or
    /// were modified (default).
    #[default]
    Changed,
    /// Every stage (`--force`).
    All,
}

/// Options of a run that are not part of the experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOptions {
    /// The run folder.
    pub out_dir: PathBuf,
    /// Which stages run again.
    pub recompute: Recompute,
    /// The run's memory limit in bytes (the command-line tool passes `--max-memory`,
    /// by default the memory available): every stage's estimated peak is checked
    /// against it before the stage starts, and the distance matrix against the
    /// smaller of it and the experiment's `[metric] memory_limit_bytes`. `None`: no
    /// limit but the experiment's.
    pub memory_limit_bytes: Option<u64>,
    /// What to do when another process is writing the run folder ([`crate::lock`]).
    pub busy: BusyFolder,
}

/// Receives the run's events; the command-line tool prints them. All methods but
/// [`progress`](RunObserver::progress) default to doing nothing.
pub trait RunObserver: Sync {
    /// The observer of long loops inside stages.
    fn progress(&self) -> &dyn Progress;
    /// A stage starts.
    fn stage_started(&self, _stage: StageId) {}
    /// A stage ended (computed or reused); `summary` is one line on what it produced.
    fn stage_finished(&self, _stage: StageId, _record: &StageRecord, _summary: &str) {}
    /// What a stage says before it is computed ([`Stage::forecast`](stages::Stage::forecast)):
    /// e.g. that it will take long.
    fn stage_note(&self, _stage: StageId, _note: &str) {}
    /// A stage is skipped because the experiment does not need it.
    fn stage_skipped(&self, _stage: StageId, _why: &str) {}
    /// Another process holds the run folder and [`BusyFolder::Wait`] waits for it.
    fn waiting_for_folder(&self, _lock: &Path) {}
}

/// What [`run`](crate::run) produced.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    /// The run folder.
    pub dir: PathBuf,
    /// The manifest written.
    pub manifest: Manifest,
    /// The analysis report.
    pub analysis: AnalysisReport,
}

/// The experiment with every table checked, as one typed stage per table: what [`run`](crate::run)
/// executes.
#[derive(Debug)]
pub struct Plan {
    pub(crate) experiment: LoadedExperiment,
    pub(crate) world: Keyed<World>,
    pub(crate) explore: ExploreStage,
    pub(crate) trace: TraceStage,
    pub(crate) distances: DistancesStage,
    pub(crate) embed: EmbedStage,
    pub(crate) analyze: AnalyzeStage,
    /// `None`: one environment, or no starts to compare.
    pub(crate) invariance: Option<InvarianceStage>,
    pub(crate) report: ReportStage,
}

impl Plan {
    /// The experiment.
    pub fn experiment(&self) -> &LoadedExperiment {
        &self.experiment
    }

    /// The files the run reads: the experiment file and, with a `[data]` table of
    /// files, every log's motors and sensors; no output of the run may replace them
    /// ([`smspace::io::check_folder_spares_inputs`]).
    pub fn input_files(&self) -> Vec<(&'static str, PathBuf)> {
        let mut files = vec![("experiment file", self.experiment.path.clone())];
        if let Some(data) = &self.world.data {
            if let crate::data::DataSource::Files { logs, .. } = &data.source {
                for (motors, _, sensors, _) in logs {
                    files.push(("[data] motors", motors.clone()));
                    files.push(("[data] sensors", sensors.clone()));
                }
            }
        }
        files
    }

    /// The agent.
    pub fn agent(&self) -> &dyn Agent {
        self.world.agent.as_ref()
    }

    /// What the cache compares besides the keys of the inputs: every stage's struct as
    /// JSON (the parameters its computation reads) and its parameter key (the hash of
    /// its name and that JSON, [`Stage::parameter_key`](stages::Stage::parameter_key)),
    /// in order; the invariance stage only when it runs. The world's key is
    /// [`Plan::world_key`].
    pub fn parameter_keys(&self) -> Vec<(StageId, String, serde_json::Value)> {
        use stages::Stage;
        fn entry<S: Stage>(stage: &S) -> (StageId, String, serde_json::Value) {
            let json = serde_json::to_value(stage).unwrap_or_default();
            (S::ID, stage.parameter_key(), json)
        }
        let mut keys = vec![
            entry(&self.explore),
            entry(&self.trace),
            entry(&self.distances),
            entry(&self.embed),
            entry(&self.analyze),
        ];
        keys.extend(self.invariance.as_ref().map(entry));
        keys.push(entry(&self.report));
        keys
    }

    /// The key of the agent, its environments and its working space.
    pub fn world_key(&self) -> &str {
        &self.world.key
    }
}
