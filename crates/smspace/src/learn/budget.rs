//! Learning from an agent within a budget of sensor rows: a real agent (a robot, a
//! slow simulator) pays for every reading, so the learned route reads it as few times
//! as it can, and checks what it traced against a few more readings.
//!
//! A budget of `B` rows for `M` starts and `V = verify_points` is spent as follows.
//!
//! 1. **Reserve** `M (V + 1)` rows for verification (each start's own reading and `V`
//!    points of its set). The rest, `B − M (V + 1)`, is the babbling; below
//!    [`min_babble_rows`] the budget is refused before any row is read
//!    ([`LearnError::Budget`]).
//! 2. **Babble**: that many motor rows drawn uniformly and independently (one seeded
//!    ChaCha8 stream) over the agent's motor space (`[−T/2, T/2)` for a periodic motor,
//!    `[low, high)` for a bounded one), read with [`Agent::sense_batch`] `batch` rows at
//!    a time, one call after the other. Rows with a reading that is not finite are
//!    counted, the first [`NAMED_NON_FINITE`] named, and left out of the log.
//! 3. **Learn** the law from the log ([`learn_with_progress`]) and trace the starts on it
//!    ([`trace_learned`]); neither reads the agent.
//! 4. **Verify** each traced set without the truth: the agent is read at the start
//!    `m⁰` and at `V` points `p_v` spread along the set (points `⌊(v + ½) P / V⌋` of
//!    its `P`), and the set's error is the largest change of a reading, in units of
//!    the sensors' spread `σ_k` (the standard deviation of sensor `k` over the babbled
//!    readings):
//!
//!    ```text
//!    e = max_{v, k} |s_k(p_v) − s_k(m⁰)| / σ_k,        kept  ⇔  e ≤ τ + c σ̂,
//!    ```
//!
//!    `τ = verify_tolerance`, `σ̂` the largest relative sensor noise the law measured
//!    ([`NoiseEstimate::relative`](super::NoiseEstimate), 0 when it is not measurable)
//!    and `c =` [`NOISE_MULTIPLE`]: on a true kernel set the readings change only by
//!    the noise, whose difference between two readings has the deviation `√2 σ̂`.
//!    Sets whose error exceeds that (or whose readings are not finite) are dropped and
//!    listed with their error.
//!
//! Verification tells whether the points of a set read as its start (the set lies on
//! the kernel), not whether the set is the whole kernel: a loop traced on part of its
//! level set, or missing a piece, passes.
//!
//! Every row read is counted ([`RowsSpent`]); the total never exceeds the budget, and
//! the rows drawn, the law and the verdicts are the same for any thread count.

use std::path::PathBuf;

use ndarray::{Array2, ArrayView2, Axis};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use super::{
    learn_with_progress, trace_learned, LawMethod, LawReport, LawValidParams, LearnError, LogFiles,
    SensorimotorLog,
};
use crate::agent::{check_motor_count, Agent, Environment};
use crate::kernel::{TraceParams, TracedSets};
use crate::params::{CheckParams, InvalidParameter};
use crate::progress::Progress;

/// The progress stage of babbling (units: rows).
pub const BABBLE: &str = "babble";
/// The progress stage of verification (units: rows).
pub const VERIFY: &str = "verify";

/// Fewest babbled rows learning is tried with, whatever the motors: 4096, the probes of
/// the noise estimate, which sets verification's noise floor.
pub const MIN_BABBLE_ROWS: u64 = 4096;

/// Rows with a reading that is not finite named in the report (their motor rows); the
/// rest are only counted.
pub const NAMED_NON_FINITE: usize = 5;

/// The multiple `c` of the measured relative noise `σ̂` added to the tolerance: 6. Two
/// noisy readings differ with the deviation `√2 σ̂`, and `6 σ̂ = 4.2 × √2 σ̂` is exceeded
/// by one of the `V K` changes of a true kernel set (64 for 8 points of 8 sensors) with
/// a probability under 0.2 %.
pub const NOISE_MULTIPLE: f64 = 6.0;

/// Parameters of learning from an agent within a budget of sensor rows (a value out
/// of its domain is named as the `budget` table's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BudgetParams {
    /// Sensor rows in all: babbling and verification together. Required, at least the
    /// verification's `M (V + 1)` plus [`min_babble_rows`].
    pub budget: u64,
    /// Rows read along each traced set to verify it, `V`. Default 8.
    #[serde(default = "default_verify_points")]
    pub verify_points: usize,
    /// Rows per [`Agent::sense_batch`] call. Default 4096.
    #[serde(default = "default_batch")]
    pub batch: usize,
    /// Seed of the babbling. Default 1.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// The largest change `τ` of a reading along a kept set, relative to the sensor's
    /// spread over the babbling, before the noise allowance `c σ̂`. Default 0.1: on
    /// the paper's arm babbled over its whole motor space (200 000 rows, 10 starts),
    /// the sets within 0.37 rad of the true ones read changes of 0 to 0.45, those
    /// 1.9 rad or more off 0.42 to 1.9; a law that holds the sensors exactly (two
    /// hinges reading a function of `sin m1 + sin(m2)/2`, 20 000 rows) reads 10⁻⁵.
    #[serde(default = "default_verify_tolerance")]
    pub verify_tolerance: f64,
}

fn default_verify_points() -> usize {
    8
}
fn default_batch() -> usize {
    4096
}
fn default_seed() -> u64 {
    1
}
fn default_verify_tolerance() -> f64 {
    0.1
}

impl BudgetParams {
    /// A budget of `budget` rows, the other parameters at their defaults.
    pub fn new(budget: u64) -> Self {
        Self {
            budget,
            verify_points: default_verify_points(),
            batch: default_batch(),
            seed: default_seed(),
            verify_tolerance: default_verify_tolerance(),
        }
    }

    /// Validates the parameters ([`CheckParams::check_params`]).
    pub fn check(&self) -> Result<ValidBudgetParams, LearnError> {
        self.check_params()
    }
}

/// Checked [`BudgetParams`].
#[derive(Debug, Clone, PartialEq)]
pub struct ValidBudgetParams {
    budget: u64,
    verify_points: usize,
    batch: usize,
    seed: u64,
    verify_tolerance: f64,
}

impl ValidBudgetParams {
    /// Sensor rows in all.
    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// Rows read along each traced set.
    pub fn verify_points(&self) -> usize {
        self.verify_points
    }

    /// Rows reserved for verifying the sets of `starts` starts: `starts (V + 1)`.
    pub fn reserved(&self, starts: usize) -> u64 {
        (starts as u64).saturating_mul(self.verify_points as u64 + 1)
    }
}

fn invalid(key: &'static str, value: impl std::fmt::Display, reason: &str) -> LearnError {
    InvalidParameter::new("budget", key, value, reason).into()
}

impl CheckParams for BudgetParams {
    type Valid = ValidBudgetParams;
    type Error = LearnError;

    fn check_params(&self) -> Result<ValidBudgetParams, LearnError> {
        if self.budget == 0 {
            return Err(invalid(
                "budget",
                0,
                "give the sensor rows the agent may be read in all (at least a few thousand)",
            ));
        }
        if self.verify_points == 0 {
            return Err(invalid(
                "verify_points",
                0,
                "read at least one point of each set to verify it (8 by default)",
            ));
        }
        if self.batch == 0 {
            return Err(invalid(
                "batch",
                0,
                "read at least one row per call (4096 by default)",
            ));
        }
        if !(self.verify_tolerance.is_finite() && self.verify_tolerance >= 0.0) {
            return Err(invalid(
                "verify_tolerance",
                self.verify_tolerance,
                "must be a finite fraction ≥ 0 of the sensors' spread (0.1 by default)",
            ));
        }
        Ok(ValidBudgetParams {
            budget: self.budget,
            verify_points: self.verify_points,
            batch: self.batch,
            seed: self.seed,
            verify_tolerance: self.verify_tolerance,
        })
    }
}

/// Fewest babbled rows learning the law of `n` motors is tried with: the smallest log
/// whose fitted rows (those left after the held-out ones, [`LawValidParams::holdout`])
/// hold what learning needs — `100 (N + 1)` for the noise and rank estimate, a typical
/// fit's neighbours plus one, and for `invariants` ten per basis function, `10 · 3^N` —
/// and at least [`MIN_BABBLE_ROWS`].
pub fn min_babble_rows(law: &LawValidParams, n: usize) -> u64 {
    let mut least =
        (super::noise::MIN_SAMPLES_PER_COEFFICIENT * (n + 1)).max(law.neighbours(n) + 1);
    if law.method() == LawMethod::Invariants {
        least = least.max(10 * 3usize.saturating_pow(n as u32));
    }
    let mut rows = least;
    while rows - law.holdout(rows) < least {
        rows += least - (rows - law.holdout(rows));
    }
    (rows as u64).max(MIN_BABBLE_ROWS)
}

/// The sensor rows read, by what they were read for.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RowsSpent {
    /// Rows read babbling, those not finite included.
    pub babble: u64,
    /// Of those, rows with a reading that is not finite (left out of the log).
    pub non_finite: u64,
    /// Rows read verifying the traced sets (their starts and points).
    pub verify: u64,
    /// `babble + verify`: every row read, at most the budget.
    pub total: u64,
}

/// The verification of one traced set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetVerification {
    /// The start's row (as in [`TracedSets::kept`]).
    pub index: usize,
    /// The largest change of a reading along the set, relative to the sensor's spread;
    /// infinite (written `null`) when a reading was not finite.
    pub error: f64,
    /// Whether the set was kept (`error` at most the threshold).
    pub passed: bool,
}

/// What [`learn_from_agent`] found: the verified sets and how the budget was spent.
/// Everything but `traced` serialises as the report.
#[derive(Debug, Clone, Serialize)]
pub struct BudgetedSets {
    /// The traced sets that passed verification (the tracer's report unchanged: it
    /// lists every start; `verification` says which were dropped).
    #[serde(skip)]
    pub traced: TracedSets,
    /// The law's report, completed with the trace ([`LawReport::with_trace`]).
    pub law: LawReport,
    /// The rows read.
    pub rows: RowsSpent,
    /// The motor rows of the first [`NAMED_NON_FINITE`] babbled rows whose reading was
    /// not finite.
    pub non_finite_motors: Vec<Vec<f64>>,
    /// The sensors' spread `σ_k` over the babbled readings (standard deviations).
    pub spread: Vec<f64>,
    /// The error above which a set is dropped, `τ + c σ̂`.
    pub threshold: f64,
    /// Every traced set's verification, in the order of the starts.
    pub verification: Vec<SetVerification>,
}

impl BudgetedSets {
    /// The sets that failed verification.
    pub fn failed(&self) -> impl Iterator<Item = &SetVerification> {
        self.verification.iter().filter(|v| !v.passed)
    }

    /// What a user must know, one sentence each: rows left out for readings that are
    /// not finite, and sets dropped by verification.
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.rows.non_finite > 0 {
            out.push(format!(
                "{} of {} babbled rows had a sensor reading that is not finite (NaN or infinite) and were left out of the law (first motor rows: {:?}); the law does not cover where the agent cannot read: check the sensors there",
                self.rows.non_finite, self.rows.babble, self.non_finite_motors
            ));
        }
        let failed: Vec<String> = self
            .failed()
            .map(|v| format!("start {} (error {:.3})", v.index, v.error))
            .collect();
        if !failed.is_empty() {
            out.push(format!(
                "{} of {} traced sets failed verification (the agent's readings along them changed by more than {:.3} of the sensors' spread) and were dropped: {}; the law is wrong there: raise the budget for a finer law, or check that the agent's readings repeat",
                failed.len(),
                self.verification.len(),
                self.threshold,
                failed.join(", ")
            ));
        }
        out
    }
}

/// Learns the law of `agent` in `environment` within the sensor-row budget, traces the
/// kernel sets through `starts` (`(M, N)`) on it and verifies them against the agent
/// (see the module docs). `law`, `trace` and `memory_limit` are those of
/// [`learn_with_progress`] and [`trace_learned`] ([`super::law_trace_params`] suits
/// them). The budget is refused before any row is read when it leaves fewer than
/// [`min_babble_rows`] for babbling.
#[allow(clippy::too_many_arguments)] // The stages' own parameters, each checked by its stage.
pub fn learn_from_agent(
    agent: &dyn Agent,
    environment: &Environment,
    starts: ArrayView2<'_, f64>,
    budget: &ValidBudgetParams,
    law: &LawValidParams,
    trace: &TraceParams,
    memory_limit: Option<u64>,
    progress: &dyn Progress,
) -> Result<BudgetedSets, LearnError> {
    check_motor_count(agent, starts.ncols()).map_err(|e| LearnError::Explore(e.into()))?;
    let n = agent.motor_dim();
    let reserved = budget.reserved(starts.nrows());
    let minimum = min_babble_rows(law, n);
    let babble = budget.budget.saturating_sub(reserved);
    if babble < minimum {
        return Err(LearnError::Budget {
            budget: budget.budget,
            babble,
            reserved,
            starts: starts.nrows(),
            motors: n,
            minimum,
            needed: minimum + reserved,
        });
    }
    let log = babble_log(agent, environment, budget, babble as usize, progress)?;
    let space = agent.motor_space();
    let learned = learn_with_progress(
        std::slice::from_ref(&log.log),
        &space,
        law,
        memory_limit,
        progress,
    )?;
    let traced = trace_learned(&learned, starts, trace, progress)?;
    let report = learned.report().with_trace(&traced.report.summary);
    let threshold = budget.verify_tolerance + NOISE_MULTIPLE * largest_relative_noise(&report);
    let (verification, verify_rows) = verify(
        agent,
        environment,
        starts,
        &traced,
        (budget, &log.spread, threshold),
        progress,
    );
    let rows = RowsSpent {
        babble,
        non_finite: log.non_finite,
        verify: verify_rows,
        total: babble + verify_rows,
    };
    debug_assert!(rows.total <= budget.budget);
    Ok(BudgetedSets {
        traced: keep_passed(traced, &verification),
        law: report,
        rows,
        non_finite_motors: log.named,
        spread: log.spread,
        threshold,
        verification,
    })
}

/// The largest relative noise per sensor the law measured, 0 when not measurable.
fn largest_relative_noise(report: &LawReport) -> f64 {
    report
        .logs
        .iter()
        .filter_map(|log| log.noise.as_ref())
        .filter(|noise| noise.measurable())
        .flat_map(|noise| noise.relative.iter().copied())
        .fold(0.0, f64::max)
}

/// The babbled log with its bookkeeping.
struct Babbled {
    log: SensorimotorLog,
    non_finite: u64,
    named: Vec<Vec<f64>>,
    spread: Vec<f64>,
}

/// Reads `agent` at `rows` seeded uniform motor rows, `batch` at a time, and keeps
/// the rows whose readings are all finite.
fn babble_log(
    agent: &dyn Agent,
    environment: &Environment,
    budget: &ValidBudgetParams,
    rows: usize,
    progress: &dyn Progress,
) -> Result<Babbled, LearnError> {
    let space = agent.motor_space();
    let (n, k) = (agent.motor_dim(), agent.sensor_dim());
    let mut rng = ChaCha8Rng::seed_from_u64(budget.seed ^ 0x6261_6262_6c65);
    let ranges: Vec<(f64, f64)> = space.motors().iter().map(|m| m.range()).collect();
    let motors = Array2::from_shape_fn((rows, n), |(_, j)| {
        let (low, high) = ranges[j];
        rng.random_range(low..high)
    });
    let sensors = read_rows(
        agent,
        environment,
        motors.view(),
        budget.batch,
        BABBLE,
        progress,
    );
    let finite: Vec<usize> = (0..rows)
        .filter(|&i| sensors.row(i).iter().all(|v| v.is_finite()))
        .collect();
    let non_finite = (rows - finite.len()) as u64;
    let named = (0..rows)
        .filter(|&i| !sensors.row(i).iter().all(|v| v.is_finite()))
        .take(NAMED_NON_FINITE)
        .map(|i| motors.row(i).to_vec())
        .collect();
    let (motors, sensors) = if non_finite > 0 {
        (
            motors.select(Axis(0), &finite),
            sensors.select(Axis(0), &finite),
        )
    } else {
        (motors, sensors)
    };
    let spread = (0..k)
        .map(|c| sensors.column(c).std(0.0))
        .collect::<Vec<f64>>();
    let name = agent.name();
    let files = LogFiles {
        motors: PathBuf::from(format!("the motor rows babbled by {name}")),
        sensors: PathBuf::from(format!("the sensor rows read from {name}")),
    };
    let log = SensorimotorLog::new(motors, sensors, files, &space)?;
    Ok(Babbled {
        log,
        non_finite,
        named,
        spread,
    })
}

/// The readings of `motors`, `batch` rows per [`Agent::sense_batch`] call, one call
/// after the other, as the progress stage `stage`.
fn read_rows(
    agent: &dyn Agent,
    environment: &Environment,
    motors: ArrayView2<'_, f64>,
    batch: usize,
    stage: &str,
    progress: &dyn Progress,
) -> Array2<f64> {
    let mut sensors = Array2::<f64>::zeros((motors.nrows(), agent.sensor_dim()));
    progress.start(stage, motors.nrows() as u64);
    for (m, s) in motors
        .axis_chunks_iter(Axis(0), batch)
        .zip(sensors.axis_chunks_iter_mut(Axis(0), batch))
    {
        agent.sense_batch(environment, m, s);
        progress.advance(m.nrows() as u64);
    }
    progress.finish();
    sensors
}

/// Reads every kept set of `traced` at its start and at `V` points along it, and
/// measures its error (see the module docs); returns the verdicts and the rows read.
fn verify(
    agent: &dyn Agent,
    environment: &Environment,
    starts: ArrayView2<'_, f64>,
    traced: &TracedSets,
    (budget, spread, threshold): (&ValidBudgetParams, &[f64], f64),
    progress: &dyn Progress,
) -> (Vec<SetVerification>, u64) {
    let v = budget.verify_points;
    let (sets, p, n) = traced.sets.dim();
    let mut motors = Array2::<f64>::zeros((sets * (v + 1), n));
    for (i, &row) in traced.kept.iter().enumerate() {
        motors.row_mut(i * (v + 1)).assign(&starts.row(row));
        for j in 0..v {
            let at = (((2 * j + 1) * p) / (2 * v)).min(p.saturating_sub(1));
            motors
                .row_mut(i * (v + 1) + 1 + j)
                .assign(&traced.sets.index_axis(Axis(0), i).row(at));
        }
    }
    let sensors = read_rows(
        agent,
        environment,
        motors.view(),
        budget.batch,
        VERIFY,
        progress,
    );
    let verification = traced
        .kept
        .iter()
        .enumerate()
        .map(|(i, &index)| {
            let start = sensors.row(i * (v + 1));
            let mut error: f64 = 0.0;
            for j in 0..v {
                let point = sensors.row(i * (v + 1) + 1 + j);
                for ((a, b), sd) in point.iter().zip(start.iter()).zip(spread) {
                    let change = (a - b).abs() / sd;
                    // A reading that is not finite fails the set.
                    error = if change.is_nan() {
                        f64::INFINITY
                    } else {
                        error.max(change)
                    };
                }
            }
            SetVerification {
                index,
                error,
                passed: error <= threshold,
            }
        })
        .collect();
    (verification, motors.nrows() as u64)
}

/// `traced` with only the sets that passed.
fn keep_passed(traced: TracedSets, verification: &[SetVerification]) -> TracedSets {
    let positions: Vec<usize> = verification
        .iter()
        .enumerate()
        .filter(|(_, v)| v.passed)
        .map(|(i, _)| i)
        .collect();
    TracedSets {
        sets: traced.sets.select(Axis(0), &positions),
        kept: positions.iter().map(|&i| traced.kept[i]).collect(),
        closure: positions.iter().map(|&i| traced.closure[i]).collect(),
        pieces: traced.pieces.select(Axis(0), &positions),
        report: traced.report,
    }
}
