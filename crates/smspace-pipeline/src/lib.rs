//! The whole pipeline from an experiment file: explore → trace → distances → embed →
//! analyze (→ invariance) → report, with a cache (paper section 3.2, steps 1–4, and
//! section 3.3).
//!
//! [`check`] validates every table of the experiment before anything runs, so that an
//! impossible value is reported with its file, line and key instead of after minutes
//! of work, and makes a [`Plan`]: one typed stage per table ([`stages`], each behind
//! the [`Stage`](stages::Stage) trait). [`run`] then runs the stages in order and
//! writes into one folder:
//!
//! | stage | outputs |
//! |---|---|
//! | `explore` | `motors.npy` (M0, N), `poses.npy` (M0, d) (when the agent has a ground truth), `probes.npy` (M0, 3) int64, `exploration.json`, `environment.json` (+ `environment-2.json`, … for compared environments) |
//! | `trace` | `sets.npy` (M, P, N), `sets.kept.npy` (M,) int64 (row of `motors.npy` of each set), `sets.closed.npy` (M,) int64 (1: a closed loop, 0: an open polyline), `sets.trace.json` |
//! | `distances` | `D.npy` (M, M) |
//! | `embed` | `Y.npy` (M, d), `Y.embed.json`, `Y.dydx.npy` (pairs, 2) |
//! | `analyze` | `analysis.json` |
//! | `invariance` | `invariance.json`, `invariance-D-<e>.npy`, `invariance-sensors-<e>.npy` (only with several environments) |
//! | `report` | `figures/*.png`, `figures/*.svg`, `report.html`, `report.md`, `report.json` |
//!
//! plus `config.resolved.toml` (every parameter, defaults included) and
//! `manifest.json` ([`manifest::Manifest`]: version, seeds, configuration hash, time per
//! stage, output hashes). A stage whose key (the hash of the stage struct, which holds
//! every parameter its computation reads, and the keys of its inputs) is unchanged and whose outputs are intact is not recomputed
//! ([`Recompute::Changed`]); its outputs are read back instead. A computed stage's
//! files, the configuration and the manifest with its record are written together
//! ([`smspace::io::Outputs`], hashed while written), so a failing or interrupted stage
//! leaves the earlier stages' outputs and records intact; a run that reuses every stage
//! of an unchanged configuration writes nothing, and so runs from a read-only folder
//! (the order of the writes is in `runner`'s docs). Each stage's peak memory is
//! estimated before it starts and held to [`RunOptions::memory_limit_bytes`]. One
//! process writes a folder at a time ([`lock`]: a second run refuses, or waits with
//! [`BusyFolder::Wait`]). `docs/RELIABILITY.md` lists these promises and the tests that
//! check them.
//!
//! With a `[data]` table ([`data`]) the run starts from a sensorimotor log: `explore`
//! picks reference samples of it instead of babbling, and `trace` traces the sets on
//! the law learned from it (`sets.trace.json` then has the law's report under `law`).
//!
//! # Example
//!
//! A tiny experiment (the redundant toy of section 2.3) from the library:
//!
//! ```
//! use smspace_pipeline::{BusyFolder, Recompute, RunObserver, RunOptions};
//! use smspace::progress::{Progress, Silent};
//!
//! struct Quiet;
//! impl RunObserver for Quiet {
//!     fn progress(&self) -> &dyn Progress { &Silent }
//! }
//! let dir = tempfile::tempdir()?;
//! let file = dir.path().join("tiny.toml");
//! std::fs::write(&file, r#"
//!     [agent]
//!     kind = "toy-redundant"
//!     [exploration]
//!     n = 60
//!     [kernel]
//!     method = "kinematic"
//!     points = 12
//!     [metric]
//!     period = "none"
//!     [embedding]
//!     method = "mds"
//!     dim = 1
//!     [analysis]
//!     mle_neighbors = 8
//!     [report]
//!     formats = "svg"
//!     sample_configurations = 3
//!     sample_sets = 3
//! "#)?;
//! let experiment = smspace_pipeline::config::load_experiment(&file, &[])?;
//! let plan = smspace_pipeline::check(&experiment)?;
//! let options = RunOptions {
//!     out_dir: dir.path().join("run"),
//!     recompute: Recompute::Changed,
//!     memory_limit_bytes: None,
//!     busy: BusyFolder::Refuse,
//! };
//! let summary = smspace_pipeline::run(&plan, &options, &Quiet)?;
//! // The kernel sets m1 + m2 = x form one segment: one component.
//! assert_eq!(summary.analysis.betti[0], 1);
//! assert!(summary.dir.join("D.npy").is_file() && summary.dir.join("report.html").is_file());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod config;
pub mod data;
mod error;
pub mod front;
pub mod lock;
pub mod manifest;
mod memory;
mod plan;
pub mod report;
mod runner;
pub mod scale;
pub mod stages;

pub use error::{Error, Result};

/// The architecture page (`docs/ARCHITECTURE.md`): its Rust listings are compiled with
/// the doc tests, so they follow the code.
#[cfg(doctest)]
#[doc = include_str!("../../../docs/ARCHITECTURE.md")]
pub struct ArchitecturePage;

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use crate::config::{ConfigError, LoadedExperiment};
pub use lock::BusyFolder;
use lock::FolderLock;
pub use manifest::StageId;
use manifest::{hash_parts, Manifest, RunStatus, Seeds, SMSPACE_VERSION};
pub use plan::{PipelineError, Plan, Recompute, RunObserver, RunOptions, RunSummary};
use runner::Runner;
use smspace::agent::{Agent, AgentRegistry};
use smspace::embed::EmbeddingRegistry;
use smspace::kernel::{TraceMethod, TraceParams};
use smspace::metric::{DistanceParams, KernelShape, MetricError, MetricRegistry};
use smspace::params::InvalidParameter;
use stages::{
    AnalyzeInput, AnalyzeStage, DistancesInput, DistancesStage, EmbedInput, EmbedStage,
    ExploreInput, ExploreStage, InvarianceInput, InvarianceStage, ReportInput, ReportStage,
    TraceInput, TraceStage, World, DYDX_PAIRS, QUALITY_NEIGHBOURS,
};
pub use stages::{DistanceBackend, LocalDistances};

/// The kinds a run can build by name: agents (`[agent] kind`) and set metrics
/// (`[metric] metric`) and embedding methods (`[embedding] method`). An embedder adds
/// its own to the built-in ones and hands them to [`check_with`]; an
/// [`AgentRegistry`], a [`MetricRegistry`] or an [`EmbeddingRegistry`] alone stands for
/// itself with the others' built-ins.
#[derive(Debug, Clone)]
pub struct Registries {
    /// Agent kinds.
    pub agents: AgentRegistry,
    /// Set metrics.
    pub metrics: MetricRegistry,
    /// Embedding methods.
    pub embeddings: EmbeddingRegistry,
}

impl Registries {
    /// The built-in agents, metrics and embedding methods.
    pub fn builtin() -> Self {
        Self {
            agents: AgentRegistry::builtin(),
            metrics: MetricRegistry::builtin(),
            embeddings: EmbeddingRegistry::builtin(),
        }
    }
}

impl From<&EmbeddingRegistry> for Registries {
    fn from(embeddings: &EmbeddingRegistry) -> Self {
        Self {
            embeddings: embeddings.clone(),
            ..Self::builtin()
        }
    }
}

impl From<&Registries> for Registries {
    fn from(registries: &Registries) -> Self {
        registries.clone()
    }
}

impl From<&AgentRegistry> for Registries {
    fn from(agents: &AgentRegistry) -> Self {
        Self {
            agents: agents.clone(),
            ..Self::builtin()
        }
    }
}

impl From<&MetricRegistry> for Registries {
    fn from(metrics: &MetricRegistry) -> Self {
        Self {
            metrics: metrics.clone(),
            ..Self::builtin()
        }
    }
}

/// Validates every table of the experiment (agent, environments, working space, and
/// each stage's parameters) without running anything. Errors name the file, the line
/// of the key (or the `--set` that gave it) and the key.
pub fn check(experiment: &LoadedExperiment) -> Result<Plan, ConfigError> {
    check_with(experiment, Registries::builtin())
}

/// Builds the `[embedding]` method from `embeddings` and records its table resolved
/// (every default) in `experiment`, as the run records it.
fn resolve_embedding(
    experiment: &mut LoadedExperiment,
    embeddings: &EmbeddingRegistry,
) -> Result<Box<dyn smspace::embed::Embedding>, ConfigError> {
    let table = &experiment.experiment.embedding;
    let (embedding, method) = table.resolve(embeddings).map_err(|err| {
        experiment.invalid_table_error(
            "embedding",
            "embedding",
            &["method"],
            smspace::Error::from(err),
            |document| embeddings.read_error(&table.method, document),
        )
    })?;
    experiment.experiment.embedding = embedding;
    Ok(method)
}

/// A run compares kernel sets: it needs at least 2 (babbled rows and probes together).
fn check_set_count(
    exploration: &smspace::explore::ExploreParams,
) -> Result<(), smspace::explore::ExploreError> {
    if exploration.rows() >= 2 {
        return Ok(());
    }
    Err(smspace::params::InvalidParameter::new(
        "exploration",
        "n",
        exploration.n,
        "a run compares kernel sets, so it needs at least 2 sets (the paper uses 2500); raise exploration.n to 2 or more",
    )
    .into())
}

/// Like [`check`], building the agent and the set metric from `registries`: the
/// built-in kinds and any an embedder registered ([`AgentRegistry::register`],
/// [`MetricRegistry::register`]), so that a plug-in agent or metric runs through the
/// whole pipeline. `registries` is a [`Registries`], or an [`AgentRegistry`] or
/// [`MetricRegistry`] alone.
pub fn check_with(
    experiment: &LoadedExperiment,
    registries: impl Into<Registries>,
) -> Result<Plan, ConfigError> {
    let registries: Registries = registries.into();
    let (agent, agent_config, data) = world_parts(experiment, &registries)?;
    if data.is_some() {
        check_data_tables(experiment)?;
    }
    let metric_table = resolve_metric_period(agent.as_ref(), &experiment.experiment.metric)
        .map_err(|err| {
            experiment.invalid_error("metric", smspace::Error::from(MetricError::Invalid(err)))
        })?;
    let metric = registries.metrics.build(&metric_table).map_err(|err| {
        experiment.invalid_table_error(
            "metric",
            "metric.params",
            &[],
            crate::Error::from(err),
            |document| {
                registries
                    .metrics
                    .read_error(metric_table.metric.as_str(), document)
            },
        )
    })?;
    // The resolved agent and metric tables (their defaults included) are what the run
    // records.
    let mut experiment = experiment.clone();
    if experiment.experiment.agent.is_some() {
        experiment.experiment.agent = Some(agent_config.clone());
    }
    experiment.experiment.metric = metric.params.clone();
    let embedding_method = resolve_embedding(&mut experiment, &registries.embeddings)?;
    let experiment = &experiment;
    let e = &experiment.experiment;
    let invalid = |table| move |err: crate::Error| experiment.invalid_error(table, err);
    let environments = e
        .environment
        .configs()
        .iter()
        .map(|c| c.build(agent.as_ref()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|err| invalid("environment")(err.into()))?;
    let workspace = e
        .exploration
        .check(agent.as_ref())
        .map_err(|err| invalid("exploration")(err.into()))?;
    check_set_count(&e.exploration).map_err(|err| invalid("exploration")(err.into()))?;
    check_learn_table(experiment, data.is_some())?;
    let invariance = check_kernel_table(experiment, agent.as_ref(), environments.len(), &metric)?;
    e.analysis
        .check()
        .map_err(|err| invalid("analysis")(err.into()))?;
    e.report
        .check()
        .map_err(|err| invalid("report")(err.into()))?;
    e.scale
        .check(e.analysis.mle_neighbors)
        .map_err(|err| invalid("scale")(err.into()))?;
    let world = World {
        agent_config,
        agent,
        environments,
        workspace,
        data,
    };
    Ok(Plan {
        experiment: experiment.clone(),
        world: world.keyed(),
        explore: ExploreStage {
            exploration: e.exploration.clone(),
        },
        trace: TraceStage::new(
            e.kernel.clone(),
            e.analysis.compensability.as_ref(),
            e.learn.as_ref(),
        ),
        distances: DistancesStage::new(&metric)
            .with_scale(e.scale.clone(), e.analysis.mle_neighbors),
        embed: EmbedStage::new(e.embedding.clone(), Arc::from(embedding_method)).with_figures(
            QUALITY_NEIGHBOURS,
            DYDX_PAIRS,
            e.report.seed,
        ),
        analyze: AnalyzeStage {
            analysis: e.analysis.clone(),
        },
        invariance,
        report: ReportStage {
            name: experiment.name.clone(),
            description: e.description.clone(),
            config_toml: experiment.resolved_toml(),
            report: e.report.clone(),
        },
    })
}

/// Checks the `[kernel]` table against the agent (the learned route's as the sensory
/// method's, which traces on its law) and against the metric (the kernels' dimension
/// it reads), and makes the invariance stage when there are `environments` > 1 to
/// compare.
fn check_kernel_table(
    experiment: &LoadedExperiment,
    agent: &dyn Agent,
    environments: usize,
    metric: &smspace::metric::BuiltMetric,
) -> Result<Option<InvarianceStage>, ConfigError> {
    let e = &experiment.experiment;
    let invalid = |table| move |err: crate::Error| experiment.invalid_error(table, err);
    // The learned route traces on its law by the sensory method: its [kernel] table is
    // checked as that method's.
    let trace_kernel = match e.kernel.method {
        TraceMethod::Learned => TraceParams {
            method: TraceMethod::Sensory,
            ..e.kernel.clone()
        },
        _ => e.kernel.clone(),
    };
    trace_kernel
        .check()
        .and_then(|kernel| kernel.check_for(agent))
        .map_err(|err| invalid("kernel")(err.into()))?;
    let invariance = if environments > 1 && e.analysis.invariance_starts > 0 {
        let kernel = TraceParams {
            method: TraceMethod::Sensory,
            ..e.kernel.clone()
        };
        kernel
            .check()
            .map_err(|err| invalid("kernel")(err.into()))?;
        Some(InvarianceStage::new(
            kernel,
            e.analysis.invariance_starts,
            metric,
        ))
    } else {
        None
    };
    if let Ok(Some(k)) = trace_kernel.check().and_then(|p| p.dimension_for(agent)) {
        metric
            .metric
            .check_kernels(KernelShape::of_dimension(k))
            .map_err(|err| invalid("metric")(MetricError::Invalid(err).into()))?;
    }
    Ok(invariance)
}

/// The `[learn]` table and `[kernel] method = "learned"` go together, and the learned
/// route babbles the agent itself (no `[data]` log); the table's values are checked
/// before anything runs.
fn check_learn_table(experiment: &LoadedExperiment, has_data: bool) -> Result<(), ConfigError> {
    let e = &experiment.experiment;
    let learned = e.kernel.method == TraceMethod::Learned;
    let refusal = match (&e.learn, learned) {
        (Some(_), false) => Some(
            "the [learn] table (a budget of sensor rows for babbling the agent) is read only with method = \"learned\": set it, or remove the [learn] table"
                .to_owned(),
        ),
        (None, true) => Some(
            "needs a [learn] table with budget = ROWS (the sensor rows the agent may be read in all)"
                .to_owned(),
        ),
        (Some(_), true) if has_data => Some(
            "babbles the agent itself, and a [data] table learns from a log: keep one of the two"
                .to_owned(),
        ),
        (Some(learn), true) => {
            learn
                .check()
                .map(|_| ())
                .and_then(|()| learn.law.check().map(|_| ()))
                .map_err(|err| experiment.invalid_error("learn", smspace::Error::from(err)))?;
            None
        }
        (None, false) => None,
    };
    match refusal {
        Some(reason) => Err(experiment.invalid_parameter(&InvalidParameter::new(
            "kernel",
            "method",
            match e.kernel.method {
                TraceMethod::Kinematic => "\"kinematic\"",
                TraceMethod::Sensory => "\"sensory\"",
                TraceMethod::Learned => "\"learned\"",
            },
            reason,
        ))),
        None => Ok(()),
    }
}

/// The agent, its resolved table and the run's data: the `[agent]` table's agent, or,
/// for a run from logged files without one, the [`data::LoggedBody`] of the log.
#[allow(clippy::type_complexity)]
fn world_parts(
    experiment: &LoadedExperiment,
    registries: &Registries,
) -> Result<
    (
        Box<dyn Agent>,
        smspace::agent::AgentConfig,
        Option<Arc<data::RunData>>,
    ),
    ConfigError,
> {
    let e = &experiment.experiment;
    let built = match &e.agent {
        Some(table) => Some(
            registries
                .agents
                .build(table)
                .map_err(|err| experiment.invalid_error("agent", smspace::Error::from(err)))?,
        ),
        None => None,
    };
    let data = match &e.data {
        Some(params) => {
            let base = experiment.path.parent().unwrap_or(Path::new("."));
            let checked =
                data::RunData::check(params, base, built.as_ref().map(|b| b.agent.as_ref()))
                    .map_err(|err| experiment.invalid_error("data", crate::Error::from(err)))?;
            Some(Arc::new(checked))
        }
        None => None,
    };
    match (built, data) {
        (Some(built), data) => {
            if let Some(data) = &data {
                let (log, agent) = (data.motor_space().dim(), built.agent.motor_dim());
                if log != agent {
                    return Err(experiment.invalid_parameter(&InvalidParameter::new(
                        "data",
                        "motors",
                        format!("{log} motor columns"),
                        format!(
                            "the [agent] has {agent} motors: a log of that agent has one column per motor (or leave [agent] out to learn from the log alone)"
                        ),
                    )));
                }
            }
            Ok((built.agent, built.config, data))
        }
        (None, Some(data)) => {
            let mut params = toml::Table::new();
            params.insert(
                "source".to_owned(),
                toml::Value::String("the [data] table's log".to_owned()),
            );
            let config = smspace::agent::AgentConfig {
                kind: "learned".to_owned(),
                params,
            };
            Ok((
                Box::new(data::LoggedBody::new(data.clone())),
                config,
                Some(data),
            ))
        }
        (None, None) => Err(ConfigError::MissingTable {
            path: experiment.path.clone(),
            table: "agent",
        }),
    }
}

/// The tables a run from a log constrains: the references are samples of the log (no
/// probe grid), and the sets are traced by the sensory method (the log has no poses).
fn check_data_tables(experiment: &LoadedExperiment) -> Result<(), ConfigError> {
    let e = &experiment.experiment;
    if e.exploration.probes != smspace::explore::Probes::None {
        return Err(experiment.invalid_parameter(&InvalidParameter::new(
            "exploration",
            "probes",
            "grid",
            "with [data] the references are samples of the log, which has no probe grid: set probes = \"none\"",
        )));
    }
    if e.kernel.method != TraceMethod::Sensory {
        return Err(experiment.invalid_parameter(&InvalidParameter::new(
            "kernel",
            "method",
            "kinematic",
            "with [data] the sets are traced on the learned law, by what the agent senses: set method = \"sensory\"",
        )));
    }
    Ok(())
}

/// The `[metric]` table with its period resolved for `agent` ([`front::resolve_period`]).
fn resolve_metric_period(
    agent: &dyn Agent,
    table: &DistanceParams,
) -> Result<DistanceParams, InvalidParameter> {
    Ok(DistanceParams {
        period: front::resolve_period(agent, &table.period)?,
        ..table.clone()
    })
}

/// Runs the checked experiment into `options.out_dir` (see the module docs).
pub fn run(
    plan: &Plan,
    options: &RunOptions,
    observer: &dyn RunObserver,
) -> Result<RunSummary, PipelineError> {
    run_with(plan, options, observer, &LocalDistances)
}

/// Like [`run`], with the distance stage's matrix computed by `distances` (e.g. on a
/// cluster) instead of in this process; the outputs and keys are the same.
pub fn run_with(
    plan: &Plan,
    options: &RunOptions,
    observer: &dyn RunObserver,
    distances: &dyn DistanceBackend,
) -> Result<RunSummary, PipelineError> {
    check_memory(plan, options.memory_limit_bytes)?;
    let mut runner = start(plan, options, observer, distances)?;
    let world = &plan.world;
    let motors = plan.agent().motor_dim() as u64;
    let exploration = runner.run(&plan.explore, &ExploreInput { world }, plan.explore_peak())?;
    let exploration = &exploration;
    let rows = exploration.motors.nrows() as u64;
    let held = memory::Held::default().plus(memory::exploration_bytes(rows, motors));
    let traced = runner.run(
        &plan.trace,
        &TraceInput { world, exploration },
        plan.trace_peak(held, rows),
    )?;
    let traced = &traced;
    let (m, points) = (traced.sets.dim().0 as u64, traced.sets.dim().1 as u64);
    let held = held.plus(memory::sets_bytes(m, points, motors));
    let distances = runner.run(
        &plan.distances,
        &DistancesInput {
            traced,
            exploration,
        },
        plan.distances_peak(held, m),
    )?;
    let distances = &distances;
    let held = held.plus(plan.distances_held(m));
    let embedded = runner.run(
        &plan.embed,
        &EmbedInput { distances },
        plan.embed_peak(held, m),
    )?;
    let analysis = runner.run(
        &plan.analyze,
        &AnalyzeInput {
            exploration,
            traced,
            distances,
            world: plan
                .analyze
                .analysis
                .compensability
                .is_some()
                .then_some(world),
        },
        plan.analyze_peak(held, m),
    )?;
    let invariance = match (&plan.invariance, plan.invariance_peak(held)) {
        (Some(stage), Some(peak)) => {
            Some(runner.run(stage, &InvarianceInput { world, exploration }, peak)?)
        }
        _ => {
            observer.stage_skipped(
                StageId::Invariance,
                if world.environments.len() < 2 {
                    "one environment; add [[environment.compare]] tables to compare"
                } else {
                    "analysis.invariance_starts = 0"
                },
            );
            None
        }
    };
    runner.run(
        &plan.report,
        &ReportInput {
            world,
            exploration,
            traced,
            embedded: &embedded,
            analysis: &analysis,
            invariance: invariance.as_ref(),
        },
        plan.report_peak(held, m),
    )?;
    runner.finish()?;
    Ok(RunSummary {
        dir: runner.dir,
        manifest: runner.manifest,
        analysis: analysis.value,
    })
}

/// Refuses, before anything runs, an experiment whose explored configurations or kernel
/// sets alone exceed `limit` bytes (the distance matrix is checked by its stage, which
/// knows how many sets were traced).
fn check_memory(plan: &Plan, limit: Option<u64>) -> Result<(), PipelineError> {
    let Some(available) = limit else {
        return Ok(());
    };
    let e = &plan.explore.exploration;
    let rows = e.rows();
    let motors = plan.agent().motor_dim();
    let pose_dim = plan
        .agent()
        .ground_truth()
        .map_or(0, |o| o.pose_space().dim());
    let points = plan.trace.kernel.stored_points();
    let explored = e.bytes(motors, pose_dim);
    let sets = plan.trace.kernel.sets_bytes(rows, motors);
    for (what, needed, fix) in [
        (
            format!("explored configurations ({rows} × {motors} motors, with poses)"),
            explored,
            "lower exploration.n or the probe grid",
        ),
        (
            format!("kernel sets ({rows} × {points} points × {motors} motors)"),
            explored.saturating_add(sets),
            "lower exploration.n, the probe grid or kernel.points",
        ),
    ] {
        if needed > available {
            return Err(PipelineError::OutOfMemory {
                what,
                needed,
                available,
                fix,
            });
        }
    }
    Ok(())
}

/// Makes the run folder, takes its lock and reads the previous manifest (the cache).
/// Nothing is written yet (see [`runner`]'s docs for when and how it is).
fn start<'a>(
    plan: &'a Plan,
    options: &'a RunOptions,
    observer: &'a dyn RunObserver,
    distances: &'a dyn DistanceBackend,
) -> Result<Runner<'a>, PipelineError> {
    let started = Instant::now();
    let dir = options.out_dir.clone();
    // The run folder is the run's to fill and replace: no input may lie in it.
    let inputs = plan.input_files();
    let inputs: Vec<smspace::io::Input<'_>> = inputs
        .iter()
        .map(|(what, path)| smspace::io::Input::new(what, path))
        .collect();
    smspace::io::check_folder_spares_inputs(&dir, &inputs)?;
    std::fs::create_dir_all(&dir).map_err(|reason| PipelineError::CreateDir {
        path: dir.clone(),
        reason,
    })?;
    // One writer at a time, from before the first file is touched.
    let lock = FolderLock::acquire(&dir, options.busy, |path| observer.waiting_for_folder(path))?;
    if lock.access() == lock::Access::Write {
        lock::remove_stale_parts(&dir);
    }
    let loaded = &plan.experiment;
    let e = &loaded.experiment;
    let resolved = &plan.report.config_toml;
    let previous = Manifest::previous(&dir);
    let manifest = Manifest {
        smspace_version: SMSPACE_VERSION.to_owned(),
        experiment: loaded.name.clone(),
        config_file: loaded.path.clone(),
        config_hash: hash_parts(&[resolved.as_bytes()]),
        overrides: loaded.overrides.clone(),
        seeds: Seeds {
            exploration: e.exploration.seed,
            environments: plan
                .world
                .environments
                .iter()
                .map(|env| env.seed.unwrap_or_default())
                .collect(),
            report: e.report.seed,
        },
        threads: rayon::current_num_threads(),
        stages: Vec::new(),
        total_seconds: 0.0,
        status: RunStatus::Running,
    };
    let matrix_limit_bytes = match (options.memory_limit_bytes, e.metric.memory_limit_bytes) {
        (Some(run), Some(metric)) => Some(run.min(metric)),
        (run, metric) => run.or(metric),
    };
    Ok(Runner {
        dir,
        options,
        observer,
        previous,
        manifest,
        started,
        config_toml: resolved,
        matrix_limit_bytes,
        writing: false,
        config_written: false,
        lock,
        distances,
    })
}
