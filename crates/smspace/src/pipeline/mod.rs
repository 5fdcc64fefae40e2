//! The whole pipeline from an experiment file: explore → trace → distances → embed →
//! analyze (→ invariance) → report, with a cache (paper section 3.2, steps 1–4, and
//! section 3.3).
//!
//! [`check`] validates every table of the experiment before anything runs, so that an
//! impossible value is reported with its file, line and key instead of after minutes
//! of work. [`run`] then runs the stages in order and writes into one folder:
//!
//! | stage | outputs |
//! |---|---|
//! | `explore` | `motors.npy` (M0, N), `poses.npy` (M0, 3), `probes.npy` (M0, 3) int64, `exploration.json`, `environment.json` (+ `environment-2.json`, … for compared environments) |
//! | `trace` | `sets.npy` (M, P, N), `sets.kept.npy` (M,) int64 (row of `motors.npy` of each set), `sets.closed.npy` (M,) int64 (1: a closed loop, 0: an open polyline), `sets.trace.json` |
//! | `distances` | `D.npy` (M, M) |
//! | `embed` | `Y.npy` (M, d), `Y.embed.json`, `Y.dydx.npy` (pairs, 2) |
//! | `analyze` | `analysis.json` |
//! | `invariance` | `invariance.json`, `invariance-D-<e>.npy`, `invariance-sensors-<e>.npy` (only with several environments) |
//! | `report` | `figures/*.png`, `figures/*.svg`, `report.html`, `report.md`, `report.json` |
//!
//! plus `config.resolved.toml` (every parameter, defaults included) and
//! `manifest.json` ([`manifest::Manifest`]: version, seeds, configuration hash, time per
//! stage, output hashes). A stage whose key (its parameters and the keys of its inputs)
//! is unchanged and whose outputs are intact is not recomputed
//! ([`Recompute::Changed`]); its outputs are read back instead. Every file is written
//! atomically and the manifest after every stage, so a failing or interrupted stage
//! leaves the earlier stages' outputs and records intact.

pub mod manifest;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use ndarray::{Array1, Array2, Array3, Axis};
use serde::{Deserialize, Serialize};

use crate::agent::{Agent, Environment, MotorTopology};
use crate::analysis::{
    analyze_on, invariance_measured, AnalysisReport, AnalysisValidParams, DimensionSets,
};
use crate::config::{ConfigError, LoadedExperiment};
use crate::embed::quality::{assess, shepard_pairs, Quality};
use crate::embed::{DydxSample, EmbedFile, EmbedReport, Embedding};
use crate::explore::{explore_in, Exploration, Workspace, EXPLORATION_FILES};
use crate::io::{self, IoError};
use crate::kernel::{trace_sets, TraceMethod, TraceParams, TraceReport, TraceValidParams};
use crate::metric::{distance_matrix, SetsView, ValidDistanceParams};
use crate::progress::Progress;
use crate::report::{
    write_report, InvarianceData, ReportInputs, ReportParams, SensoryManifold, StageTiming,
};
use manifest::{hash_file, hash_parts, Manifest, RunStatus, Seeds, StageRecord, SMSPACE_VERSION};

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
}

/// The stages, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stage {
    /// Motor babbling and the probe grid.
    Explore,
    /// Kernel sets.
    Trace,
    /// Distance matrix between sets.
    Distances,
    /// Embedding.
    Embed,
    /// Topology, dimension, agreement.
    Analyze,
    /// Environment invariance (only with several environments).
    Invariance,
    /// Figures and report.
    Report,
}

impl Stage {
    /// Every stage, in order.
    pub const ALL: [Stage; 7] = [
        Stage::Explore,
        Stage::Trace,
        Stage::Distances,
        Stage::Embed,
        Stage::Analyze,
        Stage::Invariance,
        Stage::Report,
    ];

    /// The stage's name.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Explore => "explore",
            Stage::Trace => "trace",
            Stage::Distances => "distances",
            Stage::Embed => "embed",
            Stage::Analyze => "analyze",
            Stage::Invariance => "invariance",
            Stage::Report => "report",
        }
    }
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
    /// Refuse a distance matrix larger than this many bytes (the command-line tool
    /// passes the memory available). `None`: no limit.
    pub memory_limit_bytes: Option<u64>,
}

/// Receives the run's events; the command-line tool prints them. All methods but
/// [`progress`](RunObserver::progress) default to doing nothing.
pub trait RunObserver: Sync {
    /// The observer of long loops inside stages.
    fn progress(&self) -> &dyn Progress;
    /// A stage starts.
    fn stage_started(&self, _stage: Stage) {}
    /// A stage ended (computed or reused); `summary` is one line on what it produced.
    fn stage_finished(&self, _stage: Stage, _record: &StageRecord, _summary: &str) {}
    /// A stage is skipped because the experiment does not need it.
    fn stage_skipped(&self, _stage: Stage, _why: &str) {}
}

/// What [`run`] produced.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    /// The run folder.
    pub dir: PathBuf,
    /// The manifest written.
    pub manifest: Manifest,
    /// The analysis report.
    pub analysis: AnalysisReport,
}

/// The experiment with every table checked: what [`run`] executes.
#[derive(Debug)]
pub struct Plan {
    experiment: LoadedExperiment,
    agent: Box<dyn Agent>,
    environments: Vec<Environment>,
    workspace: Option<Workspace>,
    trace: TraceValidParams,
    invariance_trace: Option<TraceValidParams>,
    distances: ValidDistanceParams,
    embedding: Box<dyn Embedding>,
    analysis: AnalysisValidParams,
    report: ReportParams,
}

impl Plan {
    /// The experiment.
    pub fn experiment(&self) -> &LoadedExperiment {
        &self.experiment
    }

    /// The agent.
    pub fn agent(&self) -> &dyn Agent {
        self.agent.as_ref()
    }
}

/// Pairs of `(dx, dy)` sampled for the CCA `dy–dx` plot.
const DYDX_PAIRS: usize = 20_000;
/// Neighbours of the embedding's trustworthiness and continuity against `D`.
const QUALITY_NEIGHBOURS: usize = 10;
/// Motor samples of each raw sensory manifold (paper Fig. 1).
const SENSORY_SAMPLES: usize = 400;

/// Validates every table of the experiment (agent, environments, working space, and
/// each stage's parameters) without running anything. Errors name the file, the line
/// of the key (or the `--set` that gave it) and the key.
pub fn check(experiment: &LoadedExperiment) -> Result<Plan, ConfigError> {
    let e = &experiment.experiment;
    let agent = e
        .agent
        .build()
        .map_err(|err| experiment.invalid("agent", err))?;
    let environments = e
        .environment
        .configs()
        .iter()
        .map(|c| c.build(agent.as_ref()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|err| experiment.invalid("environment", err))?;
    let workspace = e
        .exploration
        .check(agent.as_ref())
        .map_err(|err| experiment.invalid("exploration", err))?;
    let trace = e
        .kernel
        .check()
        .map_err(|err| experiment.invalid("kernel", err))?;
    let wants_invariance = environments.len() > 1 && e.analysis.invariance_starts > 0;
    let invariance_trace = if wants_invariance {
        let sensory = TraceParams {
            method: TraceMethod::Sensory,
            ..e.kernel.clone()
        };
        Some(
            sensory
                .check()
                .map_err(|err| experiment.invalid("kernel", err))?,
        )
    } else {
        None
    };
    let distances = e
        .metric
        .check()
        .map_err(|err| experiment.invalid("metric", err))?;
    let embedding = e
        .embedding
        .clone()
        .build()
        .map_err(|err| experiment.invalid("embedding", err))?;
    let analysis = e
        .analysis
        .check()
        .map_err(|err| experiment.invalid("analysis", err))?;
    e.report
        .check()
        .map_err(|err| experiment.invalid("report", err))?;
    Ok(Plan {
        experiment: experiment.clone(),
        agent,
        environments,
        workspace,
        trace,
        invariance_trace,
        distances,
        embedding,
        analysis,
        report: e.report.clone(),
    })
}

/// The name a configuration file uses for an enum value (`"2pi"`, `"kinematic"`).
fn label<T: Serialize + std::fmt::Debug>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(s)) => s,
        _ => format!("{value:?}"),
    }
}

/// JSON text of a parameter struct, for stage keys.
fn json<T: Serialize>(value: &T) -> String {
    serde_json::to_string(value).unwrap_or_default()
}

/// The state of a run: folder, manifests, and the records so far.
struct Runner<'a> {
    dir: PathBuf,
    options: &'a RunOptions,
    observer: &'a dyn RunObserver,
    previous: Option<Manifest>,
    manifest: Manifest,
    started: Instant,
}

/// Files written by a stage, relative to the run folder.
type Outputs = Vec<String>;

impl Runner<'_> {
    fn write_manifest(&mut self) -> Result<(), IoError> {
        self.manifest.total_seconds = self.started.elapsed().as_secs_f64();
        io::write_json(&self.dir.join("manifest.json"), &self.manifest)
    }

    /// Runs one stage: reuses it when the previous manifest has its key and intact
    /// outputs (`load`), computes it otherwise (`compute`); records it either way.
    /// Returns the stage's value and its key (for the keys of the stages after it).
    fn stage<T>(
        &mut self,
        stage: Stage,
        key_parts: &[&[u8]],
        load: impl FnOnce(&Path) -> crate::Result<T>,
        compute: impl FnOnce(&Path, &dyn Progress) -> crate::Result<(T, Outputs)>,
        summary: impl FnOnce(&T) -> String,
    ) -> Result<(T, String), PipelineError> {
        let name = stage.name();
        let mut parts: Vec<&[u8]> = vec![SMSPACE_VERSION.as_bytes(), name.as_bytes()];
        parts.extend_from_slice(key_parts);
        let key = hash_parts(&parts);
        self.observer.stage_started(stage);
        let start = Instant::now();
        let reusable = match (self.options.recompute, &self.previous) {
            (Recompute::Changed, Some(previous)) => {
                previous.reusable(&self.dir, name, &key).cloned()
            }
            _ => None,
        };
        // Outputs that no longer read (an older format, say) are recomputed like
        // changed ones.
        let loaded = reusable.and_then(|old| load(&self.dir).ok().map(|value| (value, old)));
        let result = match loaded {
            Some((value, old)) => Ok((
                value,
                StageRecord {
                    seconds: start.elapsed().as_secs_f64(),
                    cached: true,
                    ..old
                },
            )),
            None => compute(&self.dir, self.observer.progress()).and_then(|(value, files)| {
                let seconds = start.elapsed().as_secs_f64();
                let mut outputs = BTreeMap::new();
                for file in files {
                    let hash = hash_file(&self.dir.join(&file))?;
                    outputs.insert(file, hash);
                }
                Ok((
                    value,
                    StageRecord {
                        stage: name.to_owned(),
                        key: key.clone(),
                        cached: false,
                        seconds,
                        compute_seconds: seconds,
                        outputs,
                    },
                ))
            }),
        };
        match result {
            Ok((value, record)) => {
                self.observer
                    .stage_finished(stage, &record, &summary(&value));
                self.manifest.stages.retain(|r| r.stage != name);
                self.manifest.stages.push(record);
                self.write_manifest()?;
                Ok((value, key))
            }
            Err(reason) => {
                self.manifest.status = RunStatus::Failed {
                    stage: name.to_owned(),
                    reason: reason.to_string(),
                };
                // The failure itself is what the caller must see; a manifest that
                // cannot be written does not hide it.
                let _ = self.write_manifest();
                Err(PipelineError::Stage {
                    stage: name,
                    dir: self.dir.clone(),
                    reason: Box::new(reason),
                })
            }
        }
    }
}

/// What the trace stage keeps in memory.
struct Traced {
    sets: Array3<f64>,
    kept: Vec<usize>,
    closure: Vec<crate::metric::Closure>,
    report: TraceReport,
}

/// What the embed stage keeps in memory.
struct EmbedOutputs {
    coordinates: Array2<f64>,
    report: EmbedReport,
    quality: Option<Quality>,
    dydx: Array2<f64>,
}

fn read_kept(path: &Path) -> crate::Result<Vec<usize>> {
    let kept = io::read_i64(path)?;
    kept.iter()
        .map(|&k| usize::try_from(k))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|_| {
            IoError::Shape {
                path: path.to_owned(),
                found: "negative row index".into(),
                expected: "(M,) int64 rows of motors.npy".into(),
            }
            .into()
        })
}

/// The raw sensory manifold of each environment along the single motor of a 1-motor
/// agent (paper Fig. 1); empty for other agents.
fn sensory_manifolds(agent: &dyn Agent, environments: &[Environment]) -> Vec<SensoryManifold> {
    if agent.motor_dim() != 1 {
        return Vec::new();
    }
    let (low, high) = match agent.motor_topology() {
        MotorTopology::Bounded { low, high } => (low, high),
        MotorTopology::Periodic => (-std::f64::consts::PI, std::f64::consts::PI),
    };
    let motors = Array2::from_shape_fn((SENSORY_SAMPLES, 1), |(t, _)| {
        low + (high - low) * t as f64 / (SENSORY_SAMPLES - 1) as f64
    });
    environments
        .iter()
        .enumerate()
        .map(|(e, env)| {
            let mut sensors = Array2::zeros((SENSORY_SAMPLES, agent.sensor_dim()));
            for (m, mut s) in motors.outer_iter().zip(sensors.outer_iter_mut()) {
                agent.sense(
                    env,
                    m.as_slice().expect("standard layout"),
                    s.as_slice_mut().expect("standard layout"),
                );
            }
            let seed = env.seed.map(|s| format!("seed {s}, ")).unwrap_or_default();
            SensoryManifold {
                label: format!("environment {} ({seed}{} lights)", e + 1, env.lights.len()),
                motors: motors.clone(),
                sensors,
            }
        })
        .collect()
}

/// Runs the checked experiment into `options.out_dir` (see the module docs).
pub fn run(
    plan: &Plan,
    options: &RunOptions,
    observer: &dyn RunObserver,
) -> Result<RunSummary, PipelineError> {
    let started = Instant::now();
    let dir = options.out_dir.clone();
    std::fs::create_dir_all(&dir).map_err(|reason| PipelineError::CreateDir {
        path: dir.clone(),
        reason,
    })?;
    let loaded = &plan.experiment;
    let e = &loaded.experiment;
    let resolved = loaded.resolved_toml();
    io::write_atomic(&dir.join("config.resolved.toml"), |w| {
        std::io::Write::write_all(w, resolved.as_bytes())
    })?;
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
    let mut runner = Runner {
        dir: dir.clone(),
        options,
        observer,
        previous,
        manifest,
        started,
    };
    let agent = plan.agent.as_ref();
    let environments = &plan.environments;

    // 1. Exploration (and the environments it runs in).
    let explore_key = json(&(&e.agent, &e.environment, &e.exploration));
    let (exploration, explore_record) = runner.stage(
        Stage::Explore,
        &[explore_key.as_bytes()],
        |dir| Ok(Exploration::load(dir, agent.motor_dim(), plan.workspace)?),
        |dir, _| {
            let exploration = explore_in(agent, &e.exploration, plan.workspace)?;
            exploration.save(dir, &e.agent, &e.exploration)?;
            let mut files: Outputs = EXPLORATION_FILES.map(String::from).to_vec();
            for (i, env) in environments.iter().enumerate() {
                let file = if i == 0 {
                    "environment.json".to_owned()
                } else {
                    format!("environment-{}.json", i + 1)
                };
                env.save(&dir.join(&file))?;
                files.push(file);
            }
            Ok((exploration, files))
        },
        |x| {
            let probes = x.probe_count();
            format!(
                "{} configurations ({} babbled, {probes} probes), {} environment(s)",
                x.motors.nrows(),
                x.motors.nrows() - probes,
                environments.len()
            )
        },
    )?;

    // 2. Kernel sets.
    let trace_key = json(&e.kernel);
    let (traced, trace_record) = runner.stage(
        Stage::Trace,
        &[explore_record.as_bytes(), trace_key.as_bytes()],
        |dir| {
            let sets = io::read_cube(&dir.join("sets.npy"), "(M, P, N)")?;
            Ok(Traced {
                closure: crate::kernel::read_closure(&dir.join("sets.closed.npy"), sets.dim().0)?,
                sets,
                kept: read_kept(&dir.join("sets.kept.npy"))?,
                report: io::read_json(&dir.join("sets.trace.json"), "trace report")?,
            })
        },
        |dir, progress| {
            let traced = trace_sets(
                agent,
                environments.first(),
                exploration.motors.view(),
                plan.workspace.as_ref(),
                &plan.trace,
                progress,
            )?;
            if traced.kept.len() < 2 {
                return Err(crate::kernel::KernelError::NothingTraced {
                    traced: traced.kept.len(),
                    total: exploration.motors.nrows(),
                    by_status: format!("{:?}", traced.report.summary.by_status),
                }
                .into());
            }
            io::write_npy(&dir.join("sets.npy"), &traced.sets)?;
            let kept: Array1<i64> = traced.kept.iter().map(|&k| k as i64).collect();
            io::write_npy(&dir.join("sets.kept.npy"), &kept)?;
            io::write_json(&dir.join("sets.trace.json"), &traced.report)?;
            crate::kernel::write_closure(&dir.join("sets.closed.npy"), &traced.closure)?;
            Ok((
                Traced {
                    sets: traced.sets,
                    kept: traced.kept,
                    closure: traced.closure,
                    report: traced.report,
                },
                [
                    "sets.npy",
                    "sets.kept.npy",
                    "sets.trace.json",
                    "sets.closed.npy",
                ]
                .map(String::from)
                .to_vec(),
            ))
        },
        |t| {
            let s = &t.report.summary;
            format!(
                "{} of {} sets traced ({}), {} points each",
                s.traced,
                s.total,
                label(&plan.trace.method()),
                t.sets.dim().1
            )
        },
    )?;
    let kept_poses = exploration.poses.select(Axis(0), &traced.kept);

    // 3. Distances between sets.
    let metric_key = json(&(e.metric.metric, e.metric.period));
    let (distances, distance_record) = runner.stage(
        Stage::Distances,
        &[trace_record.as_bytes(), metric_key.as_bytes()],
        |dir| Ok(io::read_matrix(&dir.join("D.npy"), None, "(M, M)")?),
        |dir, progress| {
            let params = (*plan.distances)
                .clone()
                .memory_limit_bytes(options.memory_limit_bytes);
            let sets = SetsView::new(traced.sets.view()).with_closure(&traced.closure);
            let d = distance_matrix(sets, &params, progress)?;
            io::write_npy(&dir.join("D.npy"), &d)?;
            Ok((d, vec!["D.npy".to_owned()]))
        },
        |d| {
            format!(
                "{0} × {0} matrix ({1}, period {2})",
                d.nrows(),
                label(&e.metric.metric),
                label(&e.metric.period)
            )
        },
    )?;
    if distances.nrows() != traced.kept.len() {
        return Err(PipelineError::Stage {
            stage: Stage::Distances.name(),
            dir: runner.dir.clone(),
            reason: Box::new(
                IoError::Shape {
                    path: runner.dir.join("D.npy"),
                    found: format!("{} rows", distances.nrows()),
                    expected: format!("{} rows, one per set of sets.npy", traced.kept.len()),
                }
                .into(),
            ),
        });
    }

    // 4. Embedding.
    let embed_key = json(&(&e.embedding, DYDX_PAIRS, QUALITY_NEIGHBOURS));
    let (embedded, embed_record) = runner.stage(
        Stage::Embed,
        &[distance_record.as_bytes(), embed_key.as_bytes()],
        |dir| {
            let file: EmbedFile = io::read_json(&dir.join("Y.embed.json"), "embedding report")?;
            Ok(EmbedOutputs {
                coordinates: io::read_matrix(&dir.join("Y.npy"), None, "(M, d)")?,
                report: file.report,
                quality: file.quality,
                dydx: io::read_matrix(&dir.join("Y.dydx.npy"), Some(2), "(pairs, 2)")?,
            })
        },
        |dir, progress| {
            let fitted = plan.embedding.fit(distances.view(), progress)?;
            let m = distances.nrows();
            let k = QUALITY_NEIGHBOURS.min(m.saturating_sub(1) / 2);
            let quality = if k >= 1 {
                Some(assess(distances.view(), fitted.coordinates.view(), k)?)
            } else {
                None
            };
            let seed = e.report.seed;
            let dydx = shepard_pairs(
                distances.view(),
                fitted.coordinates.view(),
                DYDX_PAIRS,
                seed,
            )?;
            io::write_npy(&dir.join("Y.npy"), &fitted.coordinates)?;
            io::write_npy(&dir.join("Y.dydx.npy"), &dydx)?;
            io::write_json(
                &dir.join("Y.embed.json"),
                &EmbedFile {
                    report: fitted.report.clone(),
                    params: plan.embedding.params_json(),
                    input: serde_json::json!({ "distances": "D.npy" }),
                    quality,
                    dydx: Some(DydxSample::new("Y.dydx.npy", dydx.nrows(), m)),
                    extended: None,
                    seconds: None,
                },
            )?;
            Ok((
                EmbedOutputs {
                    coordinates: fitted.coordinates,
                    report: fitted.report,
                    quality,
                    dydx,
                },
                ["Y.npy", "Y.dydx.npy", "Y.embed.json"]
                    .map(String::from)
                    .to_vec(),
            ))
        },
        |y| {
            let quality = y
                .quality
                .map(|q| {
                    format!(
                        "; trustworthiness {:.4}, continuity {:.4}",
                        q.trustworthiness, q.continuity
                    )
                })
                .unwrap_or_default();
            format!(
                "{} points in {} dimensions with {}{quality}",
                y.report.points, y.report.dim, y.report.method
            )
        },
    )?;

    // 5. Analysis.
    let analysis_key = json(&e.analysis);
    let (analysis, analysis_record) = runner.stage(
        Stage::Analyze,
        &[
            distance_record.as_bytes(),
            trace_record.as_bytes(),
            analysis_key.as_bytes(),
        ],
        |dir| {
            Ok(io::read_json(
                &dir.join("analysis.json"),
                "analysis report",
            )?)
        },
        |dir, progress| {
            // The dimension on the babbled sets: the probe grid's regular spacing biases
            // nearest-neighbour ratios.
            let babbled: Vec<usize> = traced
                .kept
                .iter()
                .enumerate()
                .filter(|&(_, &row)| exploration.probes[[row, 0]] < 0)
                .map(|(i, _)| i)
                .collect();
            let report = analyze_on(
                distances.view(),
                Some(kept_poses.view()),
                Some(DimensionSets {
                    rows: &babbled,
                    name: "babbled",
                }),
                &plan.analysis,
                progress,
            )?;
            io::write_json(&dir.join("analysis.json"), &report)?;
            Ok((report, vec!["analysis.json".to_owned()]))
        },
        |a: &AnalysisReport| {
            let agreement = a
                .agreement
                .as_ref()
                .map(|g| format!(", Spearman {:.3}", g.spearman))
                .unwrap_or_default();
            format!(
                "betti {:?}, TwoNN {:.2}, MLE {:.2}{agreement}",
                a.betti, a.intrinsic_dimension.twonn, a.intrinsic_dimension.mle
            )
        },
    )?;

    // 6. Invariance across environments.
    let (invariance, invariance_record) = match &plan.invariance_trace {
        None => {
            observer.stage_skipped(
                Stage::Invariance,
                if environments.len() < 2 {
                    "one environment; add [[environment.compare]] tables to compare"
                } else {
                    "analysis.invariance_starts = 0"
                },
            );
            (None, String::new())
        }
        Some(params) => {
            let babbled: Vec<usize> = exploration
                .probes
                .column(0)
                .iter()
                .enumerate()
                .filter(|(_, &o)| o < 0)
                .map(|(row, _)| row)
                .take(e.analysis.invariance_starts)
                .collect();
            let starts = exploration.motors.select(Axis(0), &babbled);
            let invariance_params =
                json(&(&e.kernel, e.analysis.invariance_starts, e.metric.metric));
            let count = environments.len();
            let (data, key) = runner.stage(
                Stage::Invariance,
                &[explore_record.as_bytes(), invariance_params.as_bytes()],
                |dir| {
                    let report = io::read_json(&dir.join("invariance.json"), "invariance report")?;
                    let mut set_distances = Vec::new();
                    let mut sensors = Vec::new();
                    for i in 1..=count {
                        set_distances.push(io::read_matrix(&dir.join(format!("invariance-D-{i}.npy")), None, "(C, C)")?);
                        sensors.push(io::read_matrix(&dir.join(format!("invariance-sensors-{i}.npy")), Some(agent.sensor_dim()), "(C, K)")?);
                    }
                    Ok(InvarianceData {
                        report,
                        set_distances,
                        sensors,
                    })
                },
                |dir, progress| {
                    let measured = invariance_measured(
                        agent,
                        starts.view(),
                        environments,
                        plan.workspace.as_ref(),
                        params,
                        e.metric.metric,
                        progress,
                    )?;
                    io::write_json(&dir.join("invariance.json"), &measured.report)?;
                    let mut files = vec!["invariance.json".to_owned()];
                    for (i, (d, s)) in measured.set_distances.iter().zip(&measured.sensors).enumerate() {
                        let d_file = format!("invariance-D-{}.npy", i + 1);
                        let s_file = format!("invariance-sensors-{}.npy", i + 1);
                        io::write_npy(&dir.join(&d_file), d)?;
                        io::write_npy(&dir.join(&s_file), s)?;
                        files.extend([d_file, s_file]);
                    }
                    Ok((
                        InvarianceData {
                            report: measured.report,
                            set_distances: measured.set_distances,
                            sensors: measured.sensors,
                        },
                        files,
                    ))
                },
                |inv| {
                    let r = &inv.report;
                    format!(
                        "{} sets in {} environments: largest set difference {:.1e}, Mantel of the set metric ≥ {:.4}, of the raw sensors ≤ {:.3}",
                        r.common_sets,
                        r.environments.len(),
                        r.max_set_distance,
                        r.min_mantel,
                        r.max_sensor_mantel
                    )
                },
            )?;
            (Some(data), key)
        }
    };

    // 7. Figures and report.
    let report_key = json(&(&loaded.name, &e.description, &e.report));
    let keys = [
        explore_record.as_bytes(),
        trace_record.as_bytes(),
        distance_record.as_bytes(),
        embed_record.as_bytes(),
        analysis_record.as_bytes(),
        invariance_record.as_bytes(),
        report_key.as_bytes(),
    ];
    let manifolds = sensory_manifolds(agent, environments);
    let stage_times: Vec<StageTiming> = runner
        .manifest
        .stages
        .iter()
        .map(|r| StageTiming {
            stage: r.stage.clone(),
            seconds: r.compute_seconds,
            cached: r.cached,
        })
        .collect();
    let quality_json = embedded
        .quality
        .map(|q| serde_json::to_value(q).unwrap_or_default());
    runner.stage(
        Stage::Report,
        &keys,
        |_| Ok(()),
        |dir, _| {
            let inputs = ReportInputs {
                name: &loaded.name,
                description: &e.description,
                config_toml: &resolved,
                agent,
                environments,
                workspace: plan.workspace,
                motors: exploration.motors.view(),
                poses: exploration.poses.view(),
                probes: exploration.probes.view(),
                sets: traced.sets.view(),
                kept: &traced.kept,
                trace: &traced.report.summary,
                embedding: embedded.coordinates.view(),
                embed_report: &embedded.report,
                embed_quality: quality_json.as_ref(),
                dydx: Some(embedded.dydx.view()),
                analysis: Some(&analysis),
                invariance: invariance.as_ref(),
                sensory_manifolds: &manifolds,
                stages: &stage_times,
            };
            let summary = write_report(&inputs, &plan.report, dir)?;
            io::write_json(&dir.join("report.json"), &summary)?;
            let mut files: Outputs = summary
                .figures
                .iter()
                .flat_map(|f| f.files.iter().map(|p| p.to_string_lossy().into_owned()))
                .collect();
            files.push(summary.html.to_string_lossy().into_owned());
            files.push(summary.markdown.to_string_lossy().into_owned());
            files.push("report.json".to_owned());
            Ok(((), files))
        },
        |_| "report.html, report.md and figures/".to_owned(),
    )?;

    runner.manifest.status = RunStatus::Complete;
    runner.write_manifest()?;
    Ok(RunSummary {
        dir,
        manifest: runner.manifest,
        analysis,
    })
}
