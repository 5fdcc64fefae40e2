//! The `[data]` table: a run from a sensorimotor log instead of a simulator (the
//! paper's section 3.2, step 2: manifolds "estimated purely on the basis of unlabelled
//! sensorimotor data").
//!
//! With `[data]`, the run learns the law `ŝ(m)` from the log ([`smspace::learn`]) and:
//!
//! - `explore` **picks** `[exploration] n` reference samples of the (first) log, seeded
//!   by `[exploration] seed`, instead of babbling: `motors.npy` holds their motor
//!   commands, in the order drawn;
//! - `trace` traces the kernel sets `ŝ(m) = ŝ(m^i)` through them on the learned law
//!   ([`smspace::learn::trace_learned`]: the sensory method, with the `[kernel]` table's
//!   parameters), and records the law's report (held-out error, rank) under `law` in
//!   `sets.trace.json`; sets that leave the data end with the status `left-data`.
//!
//! The log comes from files, or is simulated from the `[agent]` (so that the result can
//! be measured against the truth):
//!
//! ```toml
//! [data]
//! motors = ["log/motors.npy"]    # (S, N), one file per environment
//! sensors = ["log/sensors.npy"]  # (S, K), row i read at motor command i
//! period = "2pi"                 # the motors: as `smspace learn --period`
//! [data.law]                     # smspace::learn::LawParams
//! method = "invariants"          # or "local-quadratic", "local-linear"
//! # rank = 3                     # the rank of ∂s/∂m when known (1..=N−1): kernels of dimension N − rank
//! ```
//!
//! or `[data.simulate]` (`samples`, `relative_noise`, `seed`: [`SimulateParams`]) with an
//! `[agent]`: the log is babbled in the working space of `[exploration]` and sensed in
//! the main environment. With files there is no agent: `[agent]` may be left out, and
//! the run has no ground truth (no poses: the analysis reports what it can without
//! them). With a simulated log the agent's poses of the picked samples are the ground
//! truth, used for evaluation only.
//!
//! Paths are relative to the experiment file. The files' contents (BLAKE3) key the run,
//! so a changed log is traced again.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use ndarray::{Array2, Axis};
use rand::rngs::ChaCha8Rng;
use rand::seq::index::sample;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use smspace::agent::{Agent, Environment, MotorSpace, Observer};
use smspace::explore::Workspace;
use smspace::learn::{
    declared_space, gib_bytes, learn_with_progress, parse_motor_declarations, simulate, LawParams,
    LawValidParams, LearnError, LearnedLaw, LogFiles, SensorimotorLog, SimulateParams,
    DEFAULT_MEMORY_LIMIT_GIB,
};
use smspace::params::InvalidParameter;

/// The `[data]` table (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataParams {
    /// Motor commands `(S, N)` of each log (one per environment), relative to the
    /// experiment file. Empty with `simulate`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub motors: Vec<PathBuf>,
    /// Sensor values `(S, K)` of each log, in the order of `motors`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<PathBuf>,
    /// The motors: `2pi` (hinges, the default), `none` (bounded by the log's range), a
    /// period, a range `LOW:HIGH`, or one of these per motor, comma-separated. With
    /// `simulate` the agent's own motors are used and this key must stay `2pi`.
    #[serde(default = "default_period")]
    pub period: String,
    /// Simulate the log from `[agent]` instead of reading files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulate: Option<SimulateParams>,
    /// The learned law's parameters.
    #[serde(default)]
    pub law: LawParams,
    /// The most memory learning may need, in GiB: the estimate from the log's shape and
    /// the law's parameters ([`smspace::learn::MemoryEstimate`]) is checked against it
    /// (and the run's own limit, `--max-memory`) before anything is built. Default
    /// [`DEFAULT_MEMORY_LIMIT_GIB`] (16).
    #[serde(default = "default_memory_limit_gib")]
    pub memory_limit_gib: f64,
}

fn default_period() -> String {
    "2pi".to_owned()
}

fn default_memory_limit_gib() -> f64 {
    DEFAULT_MEMORY_LIMIT_GIB
}

/// Where the log comes from, as the run's key records it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum DataSource {
    /// Files, with the BLAKE3 hash of each.
    Files {
        /// `(motors, its hash, sensors, its hash)` per log.
        logs: Vec<(PathBuf, String, PathBuf, String)>,
        /// The motor declarations as written.
        period: String,
    },
    /// Simulated from the run's agent in its main environment.
    Simulate(SimulateParams),
}

/// The checked `[data]` table of a run: the source, the law's parameters, and the
/// log and law once made (each made once per process, when a stage first needs it).
pub struct RunData {
    /// Where the log comes from.
    pub source: DataSource,
    /// The law's parameters, as given.
    pub law_params: LawParams,
    law_valid: LawValidParams,
    /// `memory_limit_gib` in bytes.
    memory_limit_bytes: u64,
    space: MotorSpace,
    sensor_dim: usize,
    logs: Mutex<Option<Arc<Vec<SensorimotorLog>>>>,
    law: Mutex<Option<Arc<LearnedLaw>>>,
}

impl std::fmt::Debug for RunData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunData")
            .field("source", &self.source)
            .field("law_params", &self.law_params)
            .field("space", &self.space)
            .field("sensor_dim", &self.sensor_dim)
            .finish()
    }
}

fn invalid(
    key: &'static str,
    value: impl std::fmt::Display,
    reason: impl Into<String>,
) -> LearnError {
    InvalidParameter::new("data", key, value, reason.into()).into()
}

/// What a simulated log (`[data.simulate]`) is drawn from: the run's agent, its main
/// environment (none: an empty one) and its working space.
#[derive(Clone, Copy)]
pub struct Simulator<'a> {
    /// The agent.
    pub agent: &'a dyn Agent,
    /// The main environment.
    pub environment: Option<&'a Environment>,
    /// The working space.
    pub workspace: Option<Workspace>,
}

impl RunData {
    /// Checks the table: exactly one source; for files, that the logs read, agree and
    /// pass [`SensorimotorLog::new`]'s checks (they are kept for the run); for a
    /// simulated log, that there is an `agent`. `base` is the experiment file's folder.
    pub fn check(
        params: &DataParams,
        base: &Path,
        agent: Option<&dyn Agent>,
    ) -> Result<Self, LearnError> {
        let law_valid = params.law.check()?;
        if !(params.memory_limit_gib.is_finite() && params.memory_limit_gib > 0.0) {
            return Err(invalid(
                "memory_limit_gib",
                params.memory_limit_gib,
                "must be a finite number of GiB greater than zero (default 16)",
            ));
        }
        match (&params.simulate, params.motors.is_empty() && params.sensors.is_empty()) {
            (Some(_), false) => Err(invalid(
                "simulate",
                "a table",
                "give either the log's files (motors, sensors) or [data.simulate], not both",
            )),
            (None, true) => Err(invalid(
                "motors",
                "[]",
                "name the log's files (motors = [\"log/motors.npy\"], sensors = [\"log/sensors.npy\"]) or simulate one with [data.simulate]",
            )),
            (Some(simulate), true) => {
                let Some(agent) = agent else {
                    return Err(invalid(
                        "simulate",
                        "a table",
                        "a simulated log needs the [agent] that records it; add an [agent] table, or name the log's files instead",
                    ));
                };
                if params.period != "2pi" {
                    return Err(invalid(
                        "period",
                        &params.period,
                        "a simulated log has the agent's own motors; leave period out",
                    ));
                }
                law_valid.check_rank(agent.motor_dim())?;
                simulate.check()?;
                if simulate.samples < 2 {
                    return Err(invalid(
                        "simulate",
                        simulate.samples,
                        "samples must be at least 2",
                    ));
                }
                Ok(Self::new(
                    DataSource::Simulate(simulate.clone()),
                    params,
                    law_valid,
                    agent.motor_space(),
                    agent.sensor_dim(),
                    None,
                ))
            }
            (None, false) => Self::check_files(params, base, law_valid),
        }
    }

    fn check_files(
        params: &DataParams,
        base: &Path,
        law_valid: LawValidParams,
    ) -> Result<Self, LearnError> {
        if params.motors.len() != params.sensors.len() {
            return Err(invalid(
                "sensors",
                format!("{} files", params.sensors.len()),
                format!(
                    "{} motors files were given: one sensors file per motors file (one pair per environment)",
                    params.motors.len()
                ),
            ));
        }
        let declarations = parse_motor_declarations(&params.period)
            .map_err(|reason| invalid("period", &params.period, reason))?;
        let mut logs = Vec::with_capacity(params.motors.len());
        let mut hashed = Vec::with_capacity(params.motors.len());
        let mut space = None;
        for (motors, sensors) in params.motors.iter().zip(&params.sensors) {
            let files = LogFiles {
                motors: base.join(motors),
                sensors: base.join(sensors),
            };
            let motor_values = smspace::io::read_matrix(&files.motors, None, "(S, N)")?;
            let space = match &space {
                Some(space) => space,
                None => space.insert(declared_space(
                    &declarations,
                    motor_values.view(),
                    &files.motors,
                )?),
            };
            let sensor_values = smspace::io::read_matrix(&files.sensors, None, "(S, K)")?;
            hashed.push((
                files.motors.clone(),
                super::manifest::hash_file(&files.motors)?,
                files.sensors.clone(),
                super::manifest::hash_file(&files.sensors)?,
            ));
            logs.push(SensorimotorLog::new(
                motor_values,
                sensor_values,
                files,
                space,
            )?);
        }
        let space = space.ok_or(LearnError::NoLog)?;
        law_valid.check_rank(space.dim())?;
        let sensor_dim = logs.iter().map(|l| l.sensors.ncols()).sum();
        Ok(Self::new(
            DataSource::Files {
                logs: hashed,
                period: params.period.clone(),
            },
            params,
            law_valid,
            space,
            sensor_dim,
            Some(logs),
        ))
    }

    fn new(
        source: DataSource,
        params: &DataParams,
        law_valid: LawValidParams,
        space: MotorSpace,
        sensor_dim: usize,
        logs: Option<Vec<SensorimotorLog>>,
    ) -> Self {
        Self {
            source,
            law_params: params.law.clone(),
            law_valid,
            memory_limit_bytes: gib_bytes(params.memory_limit_gib),
            space,
            sensor_dim,
            logs: Mutex::new(logs.map(Arc::new)),
            law: Mutex::new(None),
        }
    }

    /// The motors of the log.
    pub fn motor_space(&self) -> &MotorSpace {
        &self.space
    }

    /// Samples of every log: `(samples, sensors)` per log.
    fn shapes(&self) -> Vec<(usize, usize)> {
        match &self.source {
            DataSource::Simulate(params) => vec![(params.samples, self.sensor_dim)],
            DataSource::Files { .. } => self
                .logs
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .as_ref()
                .map(|logs| {
                    logs.iter()
                        .map(|l| (l.samples(), l.sensors.ncols()))
                        .collect()
                })
                .unwrap_or_default(),
        }
    }

    /// Total samples of the logs.
    pub fn samples(&self) -> usize {
        self.shapes().iter().map(|s| s.0).sum()
    }

    /// Bytes the logs and the law take while the sets are traced (the logs, the law's
    /// trees and arrays: [`LawValidParams::bytes`], with a simulated log's own arrays
    /// while it is made).
    pub fn bytes(&self) -> u64 {
        let n = self.space.dim();
        let periodic = self
            .space
            .motors()
            .iter()
            .filter(|m| m.is_periodic())
            .count();
        let mut total = self
            .shapes()
            .iter()
            .map(|&(s, k)| self.law_valid.bytes(s, n, k, periodic))
            .fold(0u64, u64::saturating_add);
        if let DataSource::Simulate(params) = &self.source {
            total = total.saturating_add(smspace::learn::SimulatedLog::bytes(
                params.samples,
                n,
                self.sensor_dim,
                0,
            ));
        }
        total
    }

    /// The logs: read at [`check`](Self::check), or simulated from the world's agent
    /// in its main environment and working space on first use.
    pub fn logs(&self, world: Simulator<'_>) -> Result<Arc<Vec<SensorimotorLog>>, LearnError> {
        let mut logs = self.logs.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(logs) = logs.as_ref() {
            return Ok(logs.clone());
        }
        let DataSource::Simulate(params) = &self.source else {
            return Err(LearnError::NoLog);
        };
        let unused = Environment::from_lights(Vec::new());
        let environment = world.environment.unwrap_or(&unused);
        let log = simulate(world.agent, environment, world.workspace, params)?;
        let files = LogFiles {
            motors: PathBuf::from("(simulated motors)"),
            sensors: PathBuf::from("(simulated sensors)"),
        };
        let made = Arc::new(vec![SensorimotorLog::new(
            log.motors,
            log.sensors,
            files,
            &self.space,
        )?]);
        *logs = Some(made.clone());
        Ok(made)
    }

    /// The law learned from [`logs`](Self::logs), learned once, its stages reported to
    /// `progress`; the smaller of `memory_limit` (bytes) and `[data]
    /// memory_limit_gib` is checked before it is built.
    pub fn law(
        &self,
        world: Simulator<'_>,
        memory_limit: Option<u64>,
        progress: &dyn smspace::progress::Progress,
    ) -> Result<Arc<LearnedLaw>, LearnError> {
        let mut law = self.law.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(law) = law.as_ref() {
            return Ok(law.clone());
        }
        let logs = self.logs(world)?;
        let limit =
            memory_limit.map_or(self.memory_limit_bytes, |l| l.min(self.memory_limit_bytes));
        let learned = Arc::new(learn_with_progress(
            &logs,
            &self.space,
            &self.law_valid,
            Some(limit),
            progress,
        )?);
        *law = Some(learned.clone());
        Ok(learned)
    }

    /// `n` distinct reference rows of the first log, drawn with `seed`, in the order
    /// drawn: their motor commands `(n, N)`.
    pub fn pick(
        &self,
        world: Simulator<'_>,
        n: usize,
        seed: u64,
    ) -> Result<Array2<f64>, LearnError> {
        let logs = self.logs(world)?;
        let first = logs.first().ok_or(LearnError::NoLog)?;
        let samples = first.samples();
        if n == 0 || n > samples {
            return Err(InvalidParameter::new(
                "exploration",
                "n",
                n,
                format!(
                    "with [data] the run picks n reference samples of the log, which has {samples}: choose 1 to {samples}"
                ),
            )
            .into());
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let rows = sample(&mut rng, samples, n).into_vec();
        Ok(first.motors.select(Axis(0), &rows))
    }
}

/// The body of a run from logged files: what the log says of the agent (its motors and
/// sensor count) and, once learned, its law. It has no ground truth. The trace stage
/// learns the law before anything senses (and reports its errors); a reading asked
/// before that, or after learning failed, is `NaN`.
#[derive(Debug)]
pub struct LoggedBody {
    data: Arc<RunData>,
}

impl LoggedBody {
    /// The body of `data`.
    pub fn new(data: Arc<RunData>) -> Self {
        Self { data }
    }

    fn learned(&self) -> Option<Arc<LearnedLaw>> {
        self.data
            .law
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
}

impl Agent for LoggedBody {
    fn motor_dim(&self) -> usize {
        self.data.space.dim()
    }

    fn sensor_dim(&self) -> usize {
        self.data.sensor_dim
    }

    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        match self.learned() {
            Some(law) => law.sense(environment, motors, sensors),
            None => sensors.fill(f64::NAN),
        }
    }

    fn name(&self) -> &str {
        "learned"
    }

    fn motor_space(&self) -> MotorSpace {
        self.data.space.clone()
    }

    fn ground_truth(&self) -> Option<&dyn Observer> {
        None
    }
}
