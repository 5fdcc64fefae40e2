//! Learning from an agent within a budget of sensor rows: a real agent (a robot, a
//! slow simulator) pays for every reading, so the learned route reads it as few times
//! as it can, and checks what it traced against a few more readings.
//!
//! A budget of `B` rows for `M` starts and `V = verify_points` is spent as follows.
//!
//! 1. **Reserve** `M (V + 2)` rows for verification (each start read twice and `V`
//!    points of its set) and `P (2N + 2)` for the agent's own slope (step 3,
//!    `P = min(M,` [`AGENT_RANK_STARTS`]`)`). The rest is the babbling; below
//!    [`min_babble_rows`] the budget is refused before any row is read
//!    ([`LearnError::Budget`]).
//! 2. **Babble in rounds** (`rounds = R`, default 2). The first round reads
//!    `max(minimum, first_round · b)` rows (`b` the babbling's rows) (`first_round` 0.5 by
//!    default): drawn in the working space when one is given (by the agent's pose, as
//!    exploration draws, reading no sensor), else uniformly and independently over the
//!    agent's motor space (`[−T/2, T/2)` for a periodic motor, `[low, high)` for a
//!    bounded one), one seeded ChaCha8 stream. The law of the rows read so far is
//!    learned ([`learn_with_progress`]) and the starts traced on it
//!    ([`trace_learned`]); neither reads the agent. Each later round reads an equal
//!    share of the rest: [`SPREAD_SHARE`] of it drawn as the first round's (so that the
//!    law's coverage keeps growing where no set was traced yet), the others where that
//!    law is least resolved along the sets: at
//!    [`SPACING_POINTS`] points `q` of every traced set (the start itself when no set
//!    was traced), the spacing `d(q)` is the distance to the
//!    [`SPACING_NEIGHBOURS`]-th nearest babbled row (a periodic motor of period `T`
//!    read as the point `(T/2π)(cos θ, sin θ)`, whose chord equals the distance on the
//!    circle to second order), and every row is a point `q` drawn with probability
//!    `∝ d(q)^N` (the motor volume per babbled row there: the sparsest parts fill
//!    first) displaced by `d(q) ξ` (`2 d(q) ξ` around a start whose set failed),
//!    `ξ ~ N(0, I_N)` (periodic motors wrapped, bounded
//!    ones clipped). The kernel sets through the starts lie where the starts' sensor
//!    readings are met again, so the rows go where the sets are traced, not over the
//!    whole motor space. Rows are read [`Agent::sense_batch`] `batch` at a time, one
//!    call after the other. Rows with a reading that is not finite are counted, the
//!    first [`NAMED_NON_FINITE`] named, and left out of the log. The spacing's median
//!    and 90th percentile after each round are reported ([`RoundReport`]).
//! 3. **Read the agent's own slope** after the first round, at `P` of the starts
//!    spread over them: twice at the start and at `± δ` along each motor
//!    ([`AGENT_RANK_STEP`]), so its rank is read without the babbling's spacing
//!    ([`AgentRank`]). Every law learned is weighed against it
//!    ([`LearnedLaw::weigh_agent_rank`]): a higher rank, clear of the stencil's noise,
//!    is traced at.
//! 4. **Learn** the law from every row read and trace the starts on it, as above.
//! 5. **Verify** each traced set without the truth: the agent is read twice at the
//!    start `m⁰` (readings `a`, `b`) and once at each of `V` points `p_v` spread along
//!    the set (points `⌊(v + ½) P / V⌋` of its `P`). Readings are measured in units of
//!    the sensors' spread `σ_k` (the standard deviation of sensor `k` over the babbled
//!    readings). The two readings of every start measure the agent's own noise, the
//!    law aside: over the `S` sets traced,
//!
//!    ```text
//!    σ̂_k = 1.4826 · median_i |a_ik − b_ik| / (√2 σ_k),        σ̂ = max_k σ̂_k,
//!    ```
//!
//!    (the median absolute difference of two readings, scaled to a Gaussian's deviation
//!    and robust to the few starts whose readings jump). The set's error is the largest
//!    change of a reading from the start's mean reading `s̄ = (a + b)/2`:
//!
//!    ```text
//!    e = max_{v, k} |s_k(p_v) − s̄_k| / σ_k,        kept  ⇔  e ≤ τ + c σ̂,
//!    ```
//!
//!    `τ = verify_tolerance` and `c =` [`NOISE_MULTIPLE`]: on a true kernel set the
//!    readings change only by the noise, and `s_k(p_v) − s̄_k` has the deviation
//!    `√1.5 σ̂_k`. Sets whose error exceeds that (or whose readings are not finite) are
//!    dropped and listed with their error. A sensor that reads the same everywhere
//!    (`σ_k = 0`) fails a set only where its reading changes.
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

use rayon::prelude::*;

use super::tree::KdTree;
use super::{
    learn_with_progress, noise, trace_learned, AgentRank, LawMethod, LawParams, LawReport,
    LawValidParams, LearnError, LearnedLaw, LogFiles, SensorimotorLog,
};
use crate::agent::{check_motor_count, Agent, Environment, MotorSpace, Workspace};
use crate::explore::{explore_in, ExploreParams};
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

/// The share of starts without a verified set above which the budget is said to have
/// been spent before the law was resolved: 5 %.
pub const UNRESOLVED_SHARE: f64 = 0.05;

/// The deviation of a Gaussian per median absolute value: `1 / Φ⁻¹(3/4) ≈ 1.4826`.
const MAD_TO_DEVIATION: f64 = 1.482_602_218_505_602;

/// Readings of each start when verifying: 2, whose difference measures the noise.
pub const VERIFY_START_READS: u64 = 2;

/// Starts at which the agent's own slope is read for its rank ([`AgentRank`]): 16.
pub const AGENT_RANK_STARTS: usize = 16;

/// The step `δ` of the central differences of the agent's own slope: 0.01 (radians
/// for hinges). Their error from the sensors' curvature is `O(δ²)`, ten thousand times
/// smaller than the slope, so that a direction a thousandth as strong as the first
/// stands out of it, where the babbling's spacing (0.1 to 0.3 rad) blurs it.
pub const AGENT_RANK_STEP: f64 = 0.01;

/// Most babbling rounds.
pub const MAX_ROUNDS: usize = 16;

/// The multiple `c` of the measured relative noise `σ̂` added to the tolerance: 6. A
/// reading differs from the mean of two others with the deviation `√1.5 σ̂`, and
/// `6 σ̂ = 4.9 × √1.5 σ̂` is exceeded by one of the `V K` changes of a true kernel set
/// (96 for 8 points of 12 sensors) with a probability under 0.01 % when the noise is
/// Gaussian.
pub const NOISE_MULTIPLE: f64 = 6.0;

/// Parameters of learning from an agent within a budget of sensor rows: an
/// experiment's `[learn]` table (a value out of its domain is named as that table's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BudgetParams {
    /// Sensor rows in all: babbling and verification together. Required, at least the
    /// verification's `M (V + 2)` plus [`min_babble_rows`].
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
    /// Babbling rounds `R`: the first draws its rows over the working space (or the
    /// motor space), each later one around the sets traced on the law of the rows read
    /// so far, where they are farthest from a babbled row. Default 2; 1 babbles once.
    #[serde(default = "default_rounds")]
    pub rounds: usize,
    /// Share of the babbled rows the first round reads (the later rounds share the rest
    /// equally). Default 0.5.
    #[serde(default = "default_first_round")]
    pub first_round: f64,
    /// The law's parameters (the `[learn.law]` table of an experiment; Python's
    /// `trace(..., method="learned")` takes them as keywords). Default: the defaults
    /// of [`LawParams`].
    #[serde(default)]
    pub law: LawParams,
}

fn default_rounds() -> usize {
    2
}
fn default_first_round() -> f64 {
    0.5
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
            rounds: default_rounds(),
            first_round: default_first_round(),
            law: LawParams::default(),
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
    rounds: usize,
    first_round: f64,
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

    /// Rows reserved for verifying the sets of `starts` starts of `motors` motors:
    /// `starts (V + 2)` (each start read twice, and `V` points of its set), and `P (2N
    /// + 2)` for the agent's own slope at `P = min(starts,` [`AGENT_RANK_STARTS`]`)`
    /// of them ([`AgentRank`]).
    pub fn reserved(&self, starts: usize, motors: usize) -> u64 {
        let per_set = self.verify_points as u64 + VERIFY_START_READS;
        let stencil = starts.min(AGENT_RANK_STARTS) as u64 * (2 * motors as u64 + 2);
        (starts as u64)
            .saturating_mul(per_set)
            .saturating_add(stencil)
    }
}

fn invalid(key: &'static str, value: impl std::fmt::Display, reason: &str) -> LearnError {
    InvalidParameter::new("learn", key, value, reason).into()
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
        if self.rounds == 0 || self.rounds > MAX_ROUNDS {
            return Err(invalid(
                "rounds",
                self.rounds,
                "must be in 1..=16 (2 by default: one over the working space, one around the sets)",
            ));
        }
        if !(self.first_round.is_finite() && self.first_round > 0.0 && self.first_round <= 1.0) {
            return Err(invalid(
                "first_round",
                self.first_round,
                "must be a share in (0, 1] of the babbled rows (0.5 by default)",
            ));
        }
        Ok(ValidBudgetParams {
            budget: self.budget,
            verify_points: self.verify_points,
            batch: self.batch,
            seed: self.seed,
            verify_tolerance: self.verify_tolerance,
            rounds: self.rounds,
            first_round: self.first_round,
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
    /// Rows read verifying the traced sets (each start twice, and its set's points).
    pub verify: u64,
    /// Rows read for the agent's own slope ([`AgentRank`]).
    #[serde(default)]
    pub agent_rank: u64,
    /// `babble + agent_rank + verify`: every row read, at most the budget.
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
    /// The sensors' noise `σ̂_k` measured from the two readings of every verified
    /// start, relative to their spread (0 for exact sensors, and when no set was traced).
    pub noise: Vec<f64>,
    /// The error above which a set is dropped, `τ + c σ̂`.
    pub threshold: f64,
    /// The rank of the agent's own slope at a few starts (absent when no reading there
    /// was finite).
    pub agent_rank: Option<AgentRank>,
    /// Every traced set's verification, in the order of the starts.
    pub verification: Vec<SetVerification>,
    /// The babbling rounds, in order.
    pub rounds: Vec<RoundReport>,
    /// The starts traced.
    pub starts: usize,
}

impl BudgetedSets {
    /// The sets that failed verification.
    pub fn failed(&self) -> impl Iterator<Item = &SetVerification> {
        self.verification.iter().filter(|v| !v.passed)
    }

    /// The verified sets as a trace of the learned route: `method = learned`, and the
    /// report's `budget` this value as JSON (the law's report left to its own `law`)
    /// with its [`warnings`](Self::warnings).
    pub fn into_traced(self) -> TracedSets {
        let spent = self.spent_report();
        let mut traced = self.traced;
        traced.report.method = crate::kernel::TraceMethod::Learned;
        traced.report.budget = spent;
        traced
    }

    /// The report of how the budget was spent (the trace report's `budget`, Python's
    /// `report["budget"]`): this value as JSON without the law's report, which has its
    /// own place, and with its [`warnings`](Self::warnings).
    pub fn spent_report(&self) -> Option<serde_json::Value> {
        let mut spent = serde_json::to_value(self).ok()?;
        let fields = spent.as_object_mut()?;
        fields.remove("law");
        fields.insert("warnings".to_owned(), self.warnings().into());
        Some(spent)
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
        let verified = self.verification.iter().filter(|v| v.passed).count();
        let missing = self.starts - verified;
        if self.starts > 0 && missing as f64 > UNRESOLVED_SHARE * self.starts as f64 {
            let spacing = match (self.rounds.first(), self.rounds.last()) {
                (Some(first), Some(last)) if self.rounds.len() > 1 => format!(
                    "the babbled rows lie a median {:.3} rad (90th percentile {:.3}) from the points of the sets, {:.3} after the first round",
                    last.spacing_median, last.spacing_p90, first.spacing_median
                ),
                (_, Some(last)) => format!(
                    "the babbled rows lie a median {:.3} rad (90th percentile {:.3}) from the points of the sets",
                    last.spacing_median, last.spacing_p90
                ),
                _ => String::new(),
            };
            out.push(format!(
                "the budget of {} rows was spent before the law was resolved: {} of {} starts have no verified set ({} traced on the last law); {spacing}; what was learned is kept: raise the budget (or trace fewer starts) for the rest",
                self.rows.total,
                missing,
                self.starts,
                self.rounds.last().map_or(0, |r| r.traced),
            ));
        }
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
    workspace: Option<Workspace>,
    budget: &ValidBudgetParams,
    law: &LawValidParams,
    trace: &TraceParams,
    memory_limit: Option<u64>,
    progress: &dyn Progress,
) -> Result<BudgetedSets, LearnError> {
    check_motor_count(agent, starts.ncols()).map_err(|e| LearnError::Explore(e.into()))?;
    let n = agent.motor_dim();
    let reserved = budget.reserved(starts.nrows(), n);
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
    let space = agent.motor_space();
    let plan = round_rows(budget, babble, minimum);
    let mut read = Readings::empty(n, agent.sensor_dim());
    let first = spread_motors(agent, workspace, budget, 0, plan[0] as usize)?;
    read.append(
        read_rows(
            agent,
            environment,
            first.view(),
            budget.batch,
            BABBLE,
            progress,
        ),
        first,
    );
    let (agent_rank, agent_rows) = read_agent_rank(
        (agent, environment),
        starts,
        &space,
        &read.spread(),
        budget.batch,
        progress,
    );
    let learn_and_trace = |read: &Readings| -> Result<(LearnedLaw, TracedSets), LearnError> {
        let log = read.log(agent, &space)?;
        let mut learned = learn_with_progress(
            std::slice::from_ref(&log),
            &space,
            law,
            memory_limit,
            progress,
        )?;
        if let Some(agent_rank) = &agent_rank {
            learned.weigh_agent_rank(agent_rank);
        }
        let traced = trace_learned(&learned, starts, trace, progress)?;
        Ok((learned, traced))
    };
    let (mut learned, mut traced) = learn_and_trace(&read)?;
    let mut rounds = vec![read.round(plan[0], &traced, starts, &space)];
    for (round, &rows) in plan.iter().enumerate().skip(1) {
        let motors = later_round_motors(
            (agent, workspace, budget),
            (&read, &traced, starts),
            round,
            rows,
        )?;
        read.append(
            read_rows(
                agent,
                environment,
                motors.view(),
                budget.batch,
                BABBLE,
                progress,
            ),
            motors,
        );
        (learned, traced) = learn_and_trace(&read)?;
        rounds.push(read.round(rows, &traced, starts, &space));
    }
    let report = learned.report().with_trace(&traced.report.summary);
    let verified = verify(
        agent,
        environment,
        starts,
        &traced,
        (budget, &read.spread()),
        progress,
    );
    let (verification, verify_rows) = (verified.sets, verified.rows);
    let rows = RowsSpent {
        babble,
        non_finite: read.non_finite(),
        verify: verify_rows,
        agent_rank: agent_rows,
        total: babble + agent_rows + verify_rows,
    };
    debug_assert!(rows.total <= budget.budget);
    Ok(BudgetedSets {
        traced: keep_passed(traced, &verification),
        law: report,
        rows,
        non_finite_motors: read.named(),
        spread: read.spread(),
        noise: verified.noise,
        threshold: verified.threshold,
        agent_rank,
        verification,
        rounds,
        starts: starts.nrows(),
    })
}

/// The motor rows of later babbling round `round` (`rows` of them): a share
/// ([`SPREAD_SHARE`]) drawn as the first round's, so that the law's coverage keeps
/// growing where no set was traced yet, the rest around the sets `traced` on the law of
/// the rows `read` so far (see the module docs).
fn later_round_motors(
    (agent, workspace, budget): (&dyn Agent, Option<Workspace>, &ValidBudgetParams),
    (read, traced, starts): (&Readings, &TracedSets, ArrayView2<'_, f64>),
    round: usize,
    rows: u64,
) -> Result<Array2<f64>, LearnError> {
    let spread = (SPREAD_SHARE * rows as f64).round() as usize;
    let mut motors = spread_motors(agent, workspace, budget, round, spread)?;
    let around = around_sets(
        read,
        traced,
        starts,
        &agent.motor_space(),
        budget,
        round,
        rows as usize - spread,
    );
    motors
        .append(Axis(0), around.view())
        .expect("rows of the same motors");
    Ok(motors)
}

/// The rows each babbling round reads: the first `max(minimum, first_round · babble)`
/// (at most `babble`; all of it when there is one round), the later ones the rest in equal parts (the last one the
/// remainder); rounds left with no row are dropped.
fn round_rows(budget: &ValidBudgetParams, babble: u64, minimum: u64) -> Vec<u64> {
    let share = if budget.rounds == 1 {
        1.0
    } else {
        budget.first_round
    };
    let first = ((share * babble as f64).round() as u64)
        .max(minimum)
        .min(babble);
    let rest = babble - first;
    let later = (budget.rounds - 1) as u64;
    let mut plan = vec![first];
    if later > 0 && rest > 0 {
        let each = rest / later;
        for round in 0..later {
            let rows = if round + 1 == later {
                rest - each * (later - 1)
            } else {
                each
            };
            if rows > 0 {
                plan.push(rows);
            }
        }
    }
    plan
}

/// The share of every round after the first drawn as the first round draws: 0.25.
pub const SPREAD_SHARE: f64 = 0.25;

/// Motor rows drawn as the first round's are: `rows` draws in the working space (by
/// the agent's ground truth, as exploration draws them: no sensor is read) or,
/// without one, uniform over the motor space (`[−T/2, T/2)` per periodic motor,
/// `[low, high)` per bounded one), from one stream seeded by the budget's seed and the
/// round.
fn spread_motors(
    agent: &dyn Agent,
    workspace: Option<Workspace>,
    budget: &ValidBudgetParams,
    round: usize,
    rows: usize,
) -> Result<Array2<f64>, LearnError> {
    if rows == 0 {
        return Ok(Array2::zeros((0, agent.motor_dim())));
    }
    let seed = budget.seed ^ 0x6261_6262_6c65 ^ ((round as u64) << 48);
    if workspace.is_some() {
        let params = ExploreParams {
            n: rows,
            seed,
            ..ExploreParams::default()
        };
        return Ok(explore_in(agent, &params, workspace)?.motors);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let ranges: Vec<(f64, f64)> = agent
        .motor_space()
        .motors()
        .iter()
        .map(|m| m.range())
        .collect();
    Ok(Array2::from_shape_fn(
        (rows, agent.motor_dim()),
        |(_, j)| {
            let (low, high) = ranges[j];
            rng.random_range(low..high)
        },
    ))
}

/// Points of a set at which the spacing of the babbled rows is measured (later rounds):
/// this many, evenly spread over its points.
pub const SPACING_POINTS: usize = 16;

/// The babbled row that counts for the spacing: the 8th nearest.
pub const SPACING_NEIGHBOURS: usize = 8;

/// Every row read babbling so far, and the bookkeeping of those that were not finite.
struct Readings {
    motors: Array2<f64>,
    sensors: Array2<f64>,
    non_finite: u64,
    named: Vec<Vec<f64>>,
}

impl Readings {
    fn empty(n: usize, k: usize) -> Self {
        Self {
            motors: Array2::zeros((0, n)),
            sensors: Array2::zeros((0, k)),
            non_finite: 0,
            named: Vec::new(),
        }
    }

    /// Keeps the rows of `motors` whose `sensors` are all finite; counts (and names the
    /// first [`NAMED_NON_FINITE`] of) the others.
    fn append(&mut self, sensors: Array2<f64>, motors: Array2<f64>) {
        let finite: Vec<usize> = (0..motors.nrows())
            .filter(|&i| sensors.row(i).iter().all(|v| v.is_finite()))
            .collect();
        for i in (0..motors.nrows()).filter(|&i| !sensors.row(i).iter().all(|v| v.is_finite())) {
            self.non_finite += 1;
            if self.named.len() < NAMED_NON_FINITE {
                self.named.push(motors.row(i).to_vec());
            }
        }
        let motors = motors.select(Axis(0), &finite);
        let sensors = sensors.select(Axis(0), &finite);
        self.motors
            .append(Axis(0), motors.view())
            .expect("rows of the same motors");
        self.sensors
            .append(Axis(0), sensors.view())
            .expect("rows of the same sensors");
    }

    fn non_finite(&self) -> u64 {
        self.non_finite
    }

    fn named(&self) -> Vec<Vec<f64>> {
        self.named.clone()
    }

    /// The sensors' spread `σ_k` over the finite readings (standard deviations).
    fn spread(&self) -> Vec<f64> {
        self.sensors
            .columns()
            .into_iter()
            .map(|c| c.std(0.0))
            .collect()
    }

    /// The log of every finite reading so far.
    fn log(&self, agent: &dyn Agent, space: &MotorSpace) -> Result<SensorimotorLog, LearnError> {
        let name = agent.name();
        let files = LogFiles {
            motors: PathBuf::from(format!("the motor rows babbled by {name}")),
            sensors: PathBuf::from(format!("the sensor rows read from {name}")),
        };
        SensorimotorLog::new(self.motors.clone(), self.sensors.clone(), files, space)
    }

    /// The k-d tree of the babbled motor rows, each periodic motor of period `T` as
    /// the point `(T/2π)(cos θ, sin θ)` of its circle (a chord, equal to the distance
    /// on the torus to second order), each bounded one as it is.
    fn tree(&self, space: &MotorSpace) -> KdTree {
        let dim = embedded_dim(space);
        let mut points = Vec::with_capacity(self.motors.nrows() * dim);
        for row in self.motors.outer_iter() {
            embed_motors(space, row.as_slice().expect("C order"), &mut points);
        }
        KdTree::new(dim, points, (0..self.motors.nrows() as u32).collect())
    }

    /// What a round that read `rows` left: the spacing of the babbled rows along the
    /// sets traced on its law.
    fn round(
        &self,
        rows: u64,
        traced: &TracedSets,
        starts: ArrayView2<'_, f64>,
        space: &MotorSpace,
    ) -> RoundReport {
        let spacing = candidate_spacing(&self.tree(space), traced, starts, space);
        let mut sorted: Vec<f64> = spacing.iter().map(|c| c.1).collect();
        sorted.sort_by(f64::total_cmp);
        let quantile = |q: f64| {
            sorted
                .get(((sorted.len() as f64 - 1.0) * q).round() as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        RoundReport {
            rows,
            traced: traced.kept.len(),
            spacing_median: quantile(0.5),
            spacing_p90: quantile(0.9),
        }
    }
}

/// Coordinates of the tree of babbled rows: two per periodic motor, one per bounded.
fn embedded_dim(space: &MotorSpace) -> usize {
    space
        .motors()
        .iter()
        .map(|m| if m.period().is_some() { 2 } else { 1 })
        .sum()
}

/// Appends the tree coordinates of the motor row `m` to `out` (see [`Readings::tree`]).
fn embed_motors(space: &MotorSpace, m: &[f64], out: &mut Vec<f64>) {
    for (motor, &value) in space.motors().iter().zip(m) {
        match motor.period() {
            Some(period) => {
                let radius = period / std::f64::consts::TAU;
                let angle = value / radius;
                out.push(radius * angle.cos());
                out.push(radius * angle.sin());
            }
            None => out.push(value),
        }
    }
}

/// Every start's candidate points (its set's [`SPACING_POINTS`] points, or the start
/// itself when no set was kept) with the distance from each to its
/// [`SPACING_NEIGHBOURS`]-th nearest babbled row, and whether it is a start whose set
/// failed.
fn candidate_spacing(
    tree: &KdTree,
    traced: &TracedSets,
    starts: ArrayView2<'_, f64>,
    space: &MotorSpace,
) -> Vec<(Vec<f64>, f64, bool)> {
    let points = traced.sets.dim().1;
    let mut candidates: Vec<Vec<f64>> = Vec::new();
    let mut kept = traced.kept.iter().enumerate().peekable();
    for row in 0..starts.nrows() {
        match kept.peek() {
            Some(&(set, &index)) if index == row => {
                kept.next();
                let take = SPACING_POINTS.min(points).max(1);
                for j in 0..take {
                    let at = (j * points) / take;
                    candidates.push(traced.sets.index_axis(Axis(0), set).row(at).to_vec());
                }
            }
            _ => candidates.push(starts.row(row).to_vec()),
        }
    }
    let mut failed = vec![false; candidates.len()];
    let mut at = 0;
    let mut kept = traced.kept.iter().peekable();
    for row in 0..starts.nrows() {
        if kept.peek() == Some(&&row) {
            kept.next();
            at += SPACING_POINTS.min(points).max(1);
        } else {
            failed[at] = true;
            at += 1;
        }
    }
    candidates
        .into_par_iter()
        .zip(failed)
        .map(|(m, failed)| {
            let mut query = Vec::with_capacity(tree.dim());
            embed_motors(space, &m, &mut query);
            let distance = tree.kth_distance(&query, SPACING_NEIGHBOURS);
            (m, distance, failed)
        })
        .collect()
}

/// The motor rows of a later round: `rows` draws around the candidate points of the
/// sets traced on the last law (see [`candidate_spacing`]), each point drawn with a
/// probability proportional to `d^N` (`d` its spacing, `N` the motors: the volume of
/// motor space per babbled row there, so that the rows fill the sparsest parts first)
/// and displaced by a normal draw of deviation `d` in every motor (periodic motors
/// wrapped, bounded ones clipped to their range). Seeded by the budget's seed and
/// the round.
fn around_sets(
    read: &Readings,
    traced: &TracedSets,
    starts: ArrayView2<'_, f64>,
    space: &MotorSpace,
    budget: &ValidBudgetParams,
    round: usize,
    rows: usize,
) -> Array2<f64> {
    let n = space.dim();
    let spacing = candidate_spacing(&read.tree(space), traced, starts, space);
    let weights: Vec<f64> = spacing
        .iter()
        .map(|(_, d, _)| if d.is_finite() { d.powi(n as i32) } else { 0.0 })
        .collect();
    let total: f64 = weights.iter().sum();
    let mut cumulative = Vec::with_capacity(weights.len());
    let mut sum = 0.0;
    for w in &weights {
        sum += w;
        cumulative.push(sum);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(budget.seed ^ 0x0072_6f75_6e64 ^ round as u64);
    let mut motors = Array2::<f64>::zeros((rows, n));
    for mut row in motors.outer_iter_mut() {
        let at = if total > 0.0 {
            let u = rng.random::<f64>() * total;
            cumulative
                .partition_point(|&c| c <= u)
                .min(spacing.len() - 1)
        } else {
            rng.random_range(0..spacing.len())
        };
        let (point, d, failed) = &spacing[at];
        let d = if d.is_finite() { *d } else { 0.0 } * if *failed { 2.0 } else { 1.0 };
        for (j, motor) in space.motors().iter().enumerate() {
            let u1: f64 = 1.0 - rng.random::<f64>();
            let u2: f64 = rng.random();
            let normal = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            let (low, high) = motor.range();
            let value = point[j] + d * normal;
            row[j] = match motor.period() {
                Some(period) => low + (value - low).rem_euclid(period),
                None => value.clamp(low, high),
            };
        }
    }
    motors
}

/// One babbling round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoundReport {
    /// Rows the round read.
    pub rows: u64,
    /// Sets traced on the law of every row read up to this round.
    pub traced: usize,
    /// The median, over the points of those sets (16 per set; a start whose set failed
    /// counts as a point), of the distance to the 8th nearest babbled row (radians of
    /// motor space; chords for periodic motors): how finely the law is sampled where
    /// it is traced.
    pub spacing_median: f64,
    /// The 90th percentile of that distance.
    pub spacing_p90: f64,
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

/// The agent's own slope at the first `P = min(M,` [`AGENT_RANK_STARTS`]`)` starts
/// spread over them, and its rank ([`AgentRank`]), with the rows read (`P (2N + 2)`);
/// `None` when no start's readings were all finite.
fn read_agent_rank(
    (agent, environment): (&dyn Agent, &Environment),
    starts: ArrayView2<'_, f64>,
    space: &MotorSpace,
    spread: &[f64],
    batch: usize,
    progress: &dyn Progress,
) -> (Option<AgentRank>, u64) {
    let (m, n) = starts.dim();
    let k = spread.len();
    let count = m.min(AGENT_RANK_STARTS);
    if count == 0 || n == 0 {
        return (None, 0);
    }
    let per_start = 2 * n + 2;
    let mut motors = Array2::<f64>::zeros((count * per_start, n));
    // The step actually taken along every motor of every start (cut at a bound).
    let mut steps = vec![0.0; count * n];
    for i in 0..count {
        let start = starts.row(i * m / count);
        let base = i * per_start;
        motors.row_mut(base).assign(&start);
        motors.row_mut(base + 1).assign(&start);
        for j in 0..n {
            let motor = space.motor(j);
            let (low, high) = motor.range();
            let (mut minus, mut plus) = (start[j] - AGENT_RANK_STEP, start[j] + AGENT_RANK_STEP);
            if !motor.is_periodic() {
                minus = minus.max(low);
                plus = plus.min(high);
            }
            steps[i * n + j] = plus - minus;
            motors.row_mut(base + 2 + 2 * j).assign(&start);
            motors[[base + 2 + 2 * j, j]] = plus;
            motors.row_mut(base + 3 + 2 * j).assign(&start);
            motors[[base + 3 + 2 * j, j]] = minus;
        }
    }
    let sensors = read_rows(agent, environment, motors.view(), batch, VERIFY, progress);
    let rows = motors.nrows() as u64;
    let scale = |c: usize| spread[c].max(f64::MIN_POSITIVE);
    // Each start's scaled slope, and the noise of its entries from the two centre reads.
    let mut found: Vec<(Vec<f64>, f64)> = Vec::new();
    for i in 0..count {
        let base = i * per_start;
        let block = sensors.slice_axis(Axis(0), ndarray::Slice::from(base..base + per_start));
        if block.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let mut slope = faer::Mat::<f64>::zeros(k, n);
        for j in 0..n {
            let step = steps[i * n + j];
            for c in 0..k {
                if step > 0.0 {
                    slope[(c, j)] =
                        (block[[2 + 2 * j, c]] - block[[3 + 2 * j, c]]) / (step * scale(c));
                }
            }
        }
        let Ok(mut sigma) = crate::linalg::singular_values(slope.as_ref()) else {
            continue;
        };
        sigma.sort_by(|a, b| b.total_cmp(a));
        sigma.resize(n, 0.0);
        // The noise variance of one entry: the two centre reads differ by √2 σ̂.
        let noise: f64 = (0..k)
            .map(|c| ((block[[0, c]] - block[[1, c]]) / scale(c)).powi(2) / 2.0)
            .sum::<f64>()
            / k as f64;
        let smallest_step = steps[i * n..(i + 1) * n]
            .iter()
            .copied()
            .filter(|&s| s > 0.0)
            .fold(f64::INFINITY, f64::min);
        // Σ over the K entries of a column: K σ̂² / (2 δ²) per squared singular value.
        let entry = k as f64 * noise * 2.0 / (smallest_step * smallest_step);
        found.push((sigma, entry));
    }
    if found.is_empty() {
        return (None, rows);
    }
    let (spectrum, floor) = noise::debiased_spectrum(&found, n);
    let rank = noise::spectrum_rank(&spectrum, floor);
    (
        Some(AgentRank {
            rank,
            spectrum,
            floor,
            starts: found.len(),
            step: AGENT_RANK_STEP,
        }),
        rows,
    )
}

/// What verification found: every set's verdict, the noise measured at the starts,
/// the threshold it set and the rows read.
struct Verified {
    sets: Vec<SetVerification>,
    noise: Vec<f64>,
    threshold: f64,
    rows: u64,
}

/// The change of a reading `a` from `b` in units of the sensor's spread `sd`: infinite
/// when a reading is not finite, or when a sensor that reads the same everywhere
/// (`sd = 0`) changed.
fn relative_change(a: f64, b: f64, sd: f64) -> f64 {
    let change = (a - b).abs();
    if change.is_nan() {
        f64::INFINITY
    } else if sd > 0.0 {
        change / sd
    } else if change == 0.0 {
        0.0
    } else {
        f64::INFINITY
    }
}

/// Reads every kept set of `traced` at its start (twice) and at `V` points along it,
/// measures the noise from the starts' two readings and each set's error (see the
/// module docs).
fn verify(
    agent: &dyn Agent,
    environment: &Environment,
    starts: ArrayView2<'_, f64>,
    traced: &TracedSets,
    (budget, spread): (&ValidBudgetParams, &[f64]),
    progress: &dyn Progress,
) -> Verified {
    let v = budget.verify_points;
    let r = VERIFY_START_READS as usize;
    let per_set = v + r;
    let (sets, p, n) = traced.sets.dim();
    let mut motors = Array2::<f64>::zeros((sets * per_set, n));
    for (i, &row) in traced.kept.iter().enumerate() {
        for read in 0..r {
            motors.row_mut(i * per_set + read).assign(&starts.row(row));
        }
        for j in 0..v {
            let at = (((2 * j + 1) * p) / (2 * v)).min(p.saturating_sub(1));
            motors
                .row_mut(i * per_set + r + j)
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
    // The noise of each sensor from the pairs of readings at the starts, those that
    // are finite.
    let noise: Vec<f64> = spread
        .iter()
        .enumerate()
        .map(|(k, &sd)| {
            let mut pairs: Vec<f64> = (0..sets)
                .map(|i| {
                    relative_change(sensors[[i * per_set, k]], sensors[[i * per_set + 1, k]], sd)
                })
                .filter(|d| d.is_finite())
                .collect();
            if pairs.is_empty() {
                return 0.0;
            }
            let mid = pairs.len() / 2;
            let (_, median, _) = pairs.select_nth_unstable_by(mid, f64::total_cmp);
            MAD_TO_DEVIATION * *median / std::f64::consts::SQRT_2
        })
        .collect();
    let threshold =
        budget.verify_tolerance + NOISE_MULTIPLE * noise.iter().copied().fold(0.0, f64::max);
    let verification = traced
        .kept
        .iter()
        .enumerate()
        .map(|(i, &index)| {
            let a = sensors.row(i * per_set);
            let b = sensors.row(i * per_set + 1);
            let mut error: f64 = 0.0;
            for j in 0..v {
                let point = sensors.row(i * per_set + r + j);
                for k in 0..spread.len() {
                    let mean = 0.5 * (a[k] + b[k]);
                    error = error.max(relative_change(point[k], mean, spread[k]));
                }
            }
            SetVerification {
                index,
                error,
                passed: error <= threshold,
            }
        })
        .collect();
    Verified {
        sets: verification,
        noise,
        threshold,
        rows: motors.nrows() as u64,
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::{learn, RankSource};
    use crate::progress::Silent;

    /// Three hinges whose sensors read the tip of a planar 3-link chain (rank 2: the
    /// kernels are curves).
    #[derive(Debug)]
    struct ChainTip;

    impl ChainTip {
        fn tip(m: &[f64]) -> [f64; 2] {
            let (a, b) = (m[0], m[0] + m[1]);
            let t = b + m[2];
            [
                a.cos() + 0.6 * b.cos() + 0.3 * t.cos(),
                a.sin() + 0.6 * b.sin() + 0.3 * t.sin(),
            ]
        }
    }

    impl Agent for ChainTip {
        fn motor_dim(&self) -> usize {
            3
        }
        fn sensor_dim(&self) -> usize {
            2
        }
        fn sense(&self, _: &Environment, m: &[f64], s: &mut [f64]) {
            s.copy_from_slice(&Self::tip(m));
        }
        fn name(&self) -> &str {
            "chain-tip"
        }
    }

    /// Four hinges: the tip of the chain of the first three, and a third sensor that
    /// sees the fourth hinge `ε` as strongly: rank 3 of 4.
    #[derive(Debug)]
    struct WeakThird(f64);

    impl Agent for WeakThird {
        fn motor_dim(&self) -> usize {
            4
        }
        fn sensor_dim(&self) -> usize {
            3
        }
        fn sense(&self, _: &Environment, m: &[f64], s: &mut [f64]) {
            let tip = ChainTip::tip(m);
            s[0] = tip[0];
            s[1] = tip[1];
            s[2] = tip[0] + self.0 * m[3].sin();
        }
        fn name(&self) -> &str {
            "weak-third"
        }
    }

    fn starts(count: usize, motors: usize) -> Array2<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        Array2::from_shape_fn((count, motors), |_| {
            rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)
        })
    }

    #[test]
    fn the_agents_own_slope_reads_its_rank_with_2n_plus_2_rows_a_start() {
        let environment = Environment::from_lights(Vec::new());
        let space = MotorSpace::hinges(3);
        let spread = [0.7, 0.7];
        let (found, rows) = read_agent_rank(
            (&ChainTip, &environment),
            starts(40, 3).view(),
            &space,
            &spread,
            4096,
            &Silent,
        );
        let found = found.unwrap();
        assert_eq!(rows, (AGENT_RANK_STARTS * 8) as u64);
        assert_eq!(found.starts, AGENT_RANK_STARTS);
        assert_eq!(found.rank, 2, "{found:?}");
        assert!(found.spectrum[2] < 1e-3, "{found:?}");
        assert_eq!(found.floor, 0.0);
        // A direction a thousandth as strong as the tip's stands out of the stencil.
        let (found, _) = read_agent_rank(
            (&WeakThird(1e-3), &environment),
            starts(5, 4).view(),
            &MotorSpace::hinges(4),
            &[0.7, 0.7, 0.7],
            4096,
            &Silent,
        );
        let found = found.unwrap();
        assert_eq!(found.starts, 5);
        assert_eq!(found.rank, 3, "{found:?}");
    }

    #[test]
    fn a_higher_rank_that_the_agents_own_slope_shows_is_used_and_a_lower_one_is_reported() {
        let agent = ChainTip;
        let environment = Environment::from_lights(Vec::new());
        let space = agent.motor_space();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let motors = Array2::from_shape_fn((20_000, 3), |_| {
            rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)
        });
        let sensors = read_rows(&agent, &environment, motors.view(), 4096, BABBLE, &Silent);
        let mut read = Readings::empty(3, 2);
        read.append(sensors, motors);
        let log = read.log(&agent, &space).unwrap();
        let params = LawParams::default().check().unwrap();
        let law = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        assert_eq!(law.rank(), 2);
        let (reading, _) = read_agent_rank(
            (&agent, &environment),
            starts(16, 3).view(),
            &space,
            &read.spread(),
            4096,
            &Silent,
        );
        let reading = reading.unwrap();
        // The evidence of the data read rank 1 (surfaces): the agent's reading wins.
        let mut low = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        low.set_candidates(vec![1, 2]);
        low.weigh_agent_rank(&reading);
        assert_eq!(
            (low.rank(), low.report().rank_source),
            (2, RankSource::Agent)
        );
        let choice = low.report().rank_choice.as_ref().unwrap();
        assert_eq!(
            (choice.rank, choice.agent, choice.candidates[0]),
            (2, Some(2), 2)
        );
        assert!(
            choice.reason.contains("agent's own slope"),
            "{}",
            choice.reason
        );
        assert!(low
            .report()
            .warnings
            .iter()
            .any(|w| w.contains("agent's own readings show rank 2")));
        // The same reading as the data's: nothing moves.
        let mut same = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        same.weigh_agent_rank(&reading);
        assert_eq!(same.rank(), 2);
        assert_ne!(same.report().rank_source, RankSource::Agent);
        // A lower reading, or one under its noise floor, is reported and not used.
        let mut high = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        high.set_candidates(vec![2, 1]);
        let lower = AgentRank {
            rank: 1,
            ..reading.clone()
        };
        high.weigh_agent_rank(&lower);
        assert_eq!(high.rank(), 2);
        let reason = &high.report().rank_choice.as_ref().unwrap().reason;
        assert!(reason.contains("not used"), "{reason}");
        let mut low = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        low.set_candidates(vec![1, 2]);
        let noisy = AgentRank {
            floor: 1.0,
            ..reading
        };
        low.weigh_agent_rank(&noisy);
        assert_eq!(low.rank(), 1);
    }
}
