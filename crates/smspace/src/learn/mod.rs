//! Kernel sets from recorded sensorimotor data: the law `ŝ(m)` learned from a log of
//! motor commands and sensor values, with no simulator (paper section 3.2, step 2: "a
//! more realistic scenario, in which these manifolds are estimated purely on the basis
//! of unlabelled sensorimotor data", after Laflaquière et al. 2013).
//!
//! ## Input
//!
//! A log is `motors.npy` `(S, N)` and `sensors.npy` `(S, K)`: `S` samples of babbling in
//! one environment, row `i` the sensor values read at motor command `i`
//! ([`SensorimotorLog`]). Several logs (one per environment) give one law whose sensor
//! vector is theirs side by side. Each motor is declared periodic (a hinge: `2pi`, the
//! default) or bounded ([`MotorDeclaration`]); nothing else is known: no pose, no
//! Jacobian, no agent.
//!
//! ## The law: local polynomial regression ([`LawMethod`])
//!
//! At a configuration `m`, the samples `x_i` within the bandwidth `h` (distance on the
//! motor torus: periodic coordinates are queried through the samples' images shifted by
//! whole periods, stored in a k-d tree) get the weights `w_i = (1 − ‖x_i − m‖²/h²)³`,
//! and the sensor values are fitted by weighted least squares with a polynomial in
//! `d_i = (x_i − m)/h`: `s ≈ a + B d` (`local-linear`) or `s ≈ a + B d + Σ_{a≤b} c_ab d_a
//! d_b` (`local-quadratic`), a small ridge `λ Σw` on the non-constant coefficients. Then
//! `ŝ(m) = a`, and its Jacobian is the derivative of `a(m)`: the slope `B / h` plus the
//! terms the moving weights and basis add (with `G⁻¹ e₀ = g₀` and the fit's residuals
//! `r_i`: `Σ_i g₀ᵀ (∂w_i/∂m φ_i + w_i ∂φ_i/∂m) r_i`, zero when the fit is exact), so
//! that the tracer's predictor follows the value's level set. The weights vanish with two derivatives at
//! `‖x − m‖ = h`, so `ŝ` is twice continuously differentiable: the tracer's Newton
//! corrector and finite differences see a smooth function. The bandwidth is
//! `bandwidth_factor` times the median, over 512 seeded samples, of the distance to
//! their `neighbours`-th nearest sample: the data's own spacing.
//!
//! ## Noise and rank, from the data ([`estimate_local`])
//!
//! Before the fit, the log's sensor noise is measured on 4096 seeded fitted samples
//! with no truth: each sample's reading against the affine fit to its `k` nearest
//! other samples in motor space, `k = 2, 3, 4 × (N + 1)`; the squared prediction
//! error, corrected for the fit's own noise, is regressed on the squared mean squared
//! distance of the neighbours, and the intercept is `σ̂²`:
//!
//! ```text
//! E[e_i² / (1 + v_i)] = σ² + c r_i⁴ + …     (v_i = ((XᵀX)⁻¹)₀₀, r_i² the neighbours' mean squared distance)
//! ```
//!
//! (the nearest-neighbour estimator `E[(s_i − s_j)²] = 2σ² + O(‖m_i − m_j‖²)` with the
//! gradient fitted away). `σ̂` is reported per sensor and overall (relative to the
//! sensors' spread), with the resolution: the root mean square error of the nearest
//! fits, noise and curvature together. Unless `σ̂` makes nearly all of it (`σ̂ ≥ 0.95 × resolution`),
//! the noise is not measured (it is below what the data's spacing resolves) and the law
//! assumes none ([`NoiseEstimate`]).
//!
//! The local fits use it: unless `neighbours` is given, a fit holds at least
//! `p (σ̂ / 0.005)²` samples (at most `16 p` and a hundredth of the log), so that the
//! noise left in the law's values is about 0.5 % of the sensors' spread
//! ([`NOISE_TARGET`]).
//!
//! The generic rank of `∂ŝ/∂m` (hence the kernel dimension `k = N − rank`) is read
//! from the data, at the same probes: the singular values of the slope of the affine
//! fit to the `4 (N + 1)` nearest samples (sensors divided by their spread), with the
//! share noise adds to their squares removed (`K σ̂² q`, `q` the slope's variance per
//! unit noise): the median spectrum `sqrt(median(β_r² − K σ̂² q) / median(β_1² − K σ̂²
//! q))` and the floor `sqrt(K σ̂² q)` on the same scale; values under a tenth of the
//! floor do not count, and the rank ends at the last ratio of 4 between consecutive
//! values of the rest, else at their largest ratio (`N` when the smallest exceeds 0.1)
//! ([`LocalRank`], [`spectrum_rank`],
//! `data_rank` in the [`LawReport`]). The rank of the fitted law's Jacobian (the most
//! frequent numerical rank at 512 seeded samples, by the largest gap of its singular
//! values) is reported beside it (`rank_counts`), and used when the log is too short
//! for the data's rank. For `invariants`, at least that many invariants are kept; and
//! when the invariants' Jacobian has one lower rank at [`UNANIMOUS_SHARE`] of the
//! probed samples, the law is traced at that rank ([`RankSource::Invariants`]): the
//! affine slope over a neighbourhood of `4 (N + 1)` samples picks up the sensors'
//! curvature across it, which grows with the neighbourhood's width, so with five or
//! more motors a kernel direction can read as a weak direction of change (the 4-link
//! arm at 10⁶ samples: spectrum 1, 0.37, 0.13, 0.036, 0.005, rank 4, where the nine
//! invariants change along 3 directions at all 512 probes).
//!
//! ## The rank: every piece of evidence ([`RankChoice`])
//!
//! The spectrum can also under-read the rank: a weak direction of change (far lights,
//! long ranges) stands a ratio of 4 below the first and reads as the kernel's leak
//! (a retina of Cauchy cells with far lights at 10⁶ samples: 1, 0.234, 0.083, 0.026,
//! rank 1, kernels of dimension 3, while its nine invariants, `λ ≤ 0.005` and the next
//! 0.544, change along 3 directions). Functions that sensory neighbours share are
//! locally functions of the sensors, so `rank ∂s/∂m ≥ rank ∂z/∂m`: for `invariants`,
//! the invariants' Jacobian rank is used over a lower data rank when it holds at
//! [`UNANIMOUS_SHARE`] of the probes, the kept eigenvalues stand apart from the next
//! (a ratio of at least [`INVARIANT_GAP`]), held-out sensory neighbours share the
//! invariants as the fitted ones do (held-out `λ` at most [`HELD_OUT_SLACK`] times the
//! fitted one, plus 0.01) and the spectrum has a value above its floor at that rank.
//! The choice, the estimate and the reason are the report's `rank_choice`; when the
//! pieces disagree the report's `warnings` say which rank is used and why. When every
//! traced set fails at the chosen rank (a kernel too large to cover, or a Jacobian
//! singular at it), [`trace_learned`] traces again at the next candidate (the other
//! readings, then the spectrum's gaps from the largest), and says so.
//!
//! A user who knows the rank gives it ([`LawParams::rank`], `1..=N−1`: the kernels
//! have dimension `N − rank`); it is used as given, with the estimate beside it and a
//! warning when they differ, and never retried.
//!
//! When the data cannot support the law, the report's `warnings` say so with the
//! measured `σ̂` and what would help: a held-out error far above the noise (the
//! sensors change faster than the samples' spacing), noise that a fit of the samples
//! the log allows cannot average down, directions of change hidden under the noise
//! floor, a log too short to measure its noise.
//!
//! ## The law: invariants ([`LawMethod::Invariants`])
//!
//! The kernels are level sets; the law need not be right everywhere, only its level
//! sets. Every fitted sample `i` is paired with the fitted sample `j(i)` nearest to it
//! in sensor space. In the tensor Fourier basis `φ(m)` of the motors (per hinge
//! `1, cos m_j, sin m_j`; per bounded motor `1, u, 2u² − 1`: `F = 3^N − 1` functions
//! without the constant), the combinations `z = wᵀφ` that change least between the two
//! samples of a pair, relative to their variance, solve the generalised eigenproblem
//!
//! ```text
//! C w = λ Σ w,   C = mean_i (φ_i − φ_j(i))(φ_i − φ_j(i))ᵀ,   Σ = Cov(φ),   λ = E[(z_i − z_j(i))²] / Var z.
//! ```
//!
//! Pairs whose samples read alike from poses far apart (aliased pairs) are set aside:
//! three times, the change of the functions below the threshold (in the last round,
//! of the invariants kept) is measured on every pair
//! and `C` is taken again over the pairs whose change is at most 9 times the median.
//! The invariants `z(m) = Wᵀ(φ(m) − μ)` are the eigenvectors of the smallest `λ` up to
//! the largest gap (a ratio of at least 2 between consecutive `λ`, those under a
//! hundredth of the threshold counting as zero; else all of them) among those below
//! `invariance_threshold` (0.4; an unrelated function has `λ ≈ 2`). When the sensors are a function of the pose of the sensor that tells
//! poses apart, the invariants are functions of the pose, and the kernel through `m^i`
//! is the level set `z(m) = z(m^i)`: that is what is traced, with the exact Jacobian
//! `Wᵀ ∂φ/∂m`. For a chain of hinges the pose is a trigonometric polynomial of degree one
//! in every joint (`x = Σ l_i cos(θ_1 + … + θ_i)`, `cos α`, `sin α`), so the basis holds
//! it exactly. The report gives the eigenvalues, `λ` on the fitted pairs and on the
//! held-out samples (each with its nearest fitted sample in sensor space), and the
//! held-out error of `ŝ = g(z)`, `g` the mean sensor values of the 8 fitted samples
//! nearest in `z`. At most seven motors (2186 functions; past five motors `Σ` and `C`
//! are summed over `max(2^36 / F², 64 F)` seeded pairs). See the `invariants` module.
//!
//! ## Coverage (status `left-data`)
//!
//! The law is known at `m` when at least `coverage_neighbours` samples lie within the
//! bandwidth `h`, i.e. when the distance to the `coverage_neighbours`-th nearest sample
//! is below `h` (default: a quarter of `neighbours`, at least one more than the fit's
//! coefficients). A traced set that leaves this region ends there, with the status
//! `left-data` ([`crate::kernel::SetStatus::LeftData`]).
//!
//! ## Tracing on the law
//!
//! [`trace_learned`] runs the tracer's sensory method on the law, with the law's exact
//! Jacobian ([`crate::agent::Agent::sense_with_jacobian`]: one fit per
//! linearisation instead of the `2N + 1` of central differences) and the sensor
//! tolerance [`LAW_SENSOR_TOLERANCE`] (`10⁻⁸`, which the least-squares solve can honour;
//! the simulator's `10⁻¹²` is at its rounding level). The queries of one traced curve
//! lie a fraction of `h` apart: each worker thread keeps the samples within `1.5 h` of
//! its last refill and answers the next queries from them ([`KdTree::within_near`],
//! the same answer bit for bit).
//!
//! ## Held-out error
//!
//! `holdout` seeded samples of every log are left out of the fit; the law's error on
//! them (root mean square over samples and sensors, relative to the root mean square of
//! the sensors' standard deviations) is in the [`LawReport`].

pub mod budget;
mod compare;
mod invariants;
mod law;
mod log;
mod memory;
mod noise;
pub mod observe;
mod quality;
mod simulate;
mod tree;

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::io::IoError;
use crate::params::{CheckParams, InvalidParameter};
pub use compare::{comparison_period, set_errors, SetErrors};
use invariants::InvariantModel;
pub use invariants::{InvariantsReport, MAX_INVARIANTS};
pub use law::{
    AgentRank, FitSupport, LawReport, LearnedLaw, LogReport, RankChoice, RankSource, TriedRank,
    AGENT_FLOOR_MULTIPLE, HELD_OUT_SLACK, INVARIANT_GAP, UNANIMOUS_SHARE,
};
pub use log::{
    declared_space, parse_motor_declarations, LogFiles, MotorDeclaration, SensorimotorLog,
    REPEAT_TOLERANCE,
};
pub use memory::{gib_bytes, MemoryEstimate, DEFAULT_MEMORY_LIMIT_GIB};
pub use noise::{
    estimate_local, held_out_rank, spectrum_rank, LocalRank, NoiseEstimate, CLEAR_GAP,
    FULL_RANK_RATIO, HELD_OUT_TIE, MAX_CORRELATION, MEASURABLE_SHARE,
};
pub use quality::{LawQuality, MAX_HELD_OUT_RATIO, MIN_CLOSURE_RATE, MIN_SAMPLES_PER_DIMENSION};
pub use simulate::{simulate, LogRecord, SimulateParams, SimulatedLog, SIMULATED_LOG_FILES};
pub use tree::{Candidates, KdTree};

/// Errors of learning from data.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LearnError {
    /// A parameter is out of its domain.
    #[error(transparent)]
    Parameter(#[from] InvalidParameter),
    /// A file could not be read (missing, not float64, NaN: the reader names it).
    #[error(transparent)]
    Io(#[from] IoError),
    /// The motors and sensors of a log have different row counts.
    #[error("{motors} has {motor_rows} rows but {sensors} has {sensor_rows}: a log needs one row of sensor values per row of motor commands; cut both files to the same samples")]
    RowCount {
        /// The motors file.
        motors: PathBuf,
        /// Its rows.
        motor_rows: usize,
        /// The sensors file.
        sensors: PathBuf,
        /// Its rows.
        sensor_rows: usize,
    },
    /// A sensor never changes.
    #[error("sensor column {column} of {path} is constant ({value}) over all {samples} samples: it carries no information on the motors; drop the column (or check the sensor)")]
    ConstantSensor {
        /// The sensors file.
        path: PathBuf,
        /// The column (0-based).
        column: usize,
        /// Its value.
        value: f64,
        /// Samples.
        samples: usize,
    },
    /// A bounded motor's value lies outside its declared range.
    #[error("{path}, row {row}: motor m{motor} is {value}, outside its declared range [{low}, {high}]; fix the declared range (--period / [data] period) or remove the row")]
    OutOfRange {
        /// The motors file.
        path: PathBuf,
        /// The row (0-based).
        row: usize,
        /// The motor (1-based).
        motor: usize,
        /// The value.
        value: f64,
        /// Declared low.
        low: f64,
        /// Declared high.
        high: f64,
    },
    /// Too few samples for the method.
    #[error("{path} has too few samples ({samples}) for the law: {reason}; {fix}")]
    TooFewSamples {
        /// The motors file.
        path: PathBuf,
        /// Samples available.
        samples: usize,
        /// What does not fit.
        reason: String,
        /// What to do.
        fix: &'static str,
    },
    /// The logs do not describe the same motors.
    #[error("{path} has {found} motor columns but {expected} motors are declared (or the first log has {expected}); every log of one law records the same motors")]
    MotorColumns {
        /// The motors file.
        path: PathBuf,
        /// Columns found.
        found: usize,
        /// Motors expected.
        expected: usize,
    },
    /// Learning would need more memory than allowed.
    #[error("learning from {samples} samples needs about {} ({parts}) but the limit is {}; {fix}", crate::metric::human_bytes(*needed), crate::metric::human_bytes(*available))]
    OutOfMemory {
        /// Samples.
        samples: usize,
        /// Bytes needed.
        needed: u64,
        /// Bytes allowed.
        available: u64,
        /// The parts of the estimate ([`MemoryEstimate::parts`]).
        parts: String,
        /// What to lower.
        fix: &'static str,
    },
    /// No log was given.
    #[error("no log to learn from: give at least one pair of motors and sensors files")]
    NoLog,
    /// The simulation's agent or environment failed.
    #[error(transparent)]
    Explore(#[from] crate::explore::ExploreError),
    /// Tracing on the learned law failed.
    #[error(transparent)]
    Kernel(#[from] crate::kernel::KernelError),
    /// A sensor-row budget too small to learn from ([`budget::learn_from_agent`]).
    #[error("a budget of {budget} sensor rows leaves {babble} for babbling after the {reserved} kept to verify the sets of {starts} starts, and learning the law of {motors} motors needs at least {minimum}: raise budget to at least {needed} (or lower verify_points, or trace fewer starts)")]
    Budget {
        /// The budget.
        budget: u64,
        /// Rows it leaves for babbling.
        babble: u64,
        /// Rows kept for verification.
        reserved: u64,
        /// Starts.
        starts: usize,
        /// Motors.
        motors: usize,
        /// Fewest babbled rows ([`budget::min_babble_rows`]).
        minimum: u64,
        /// Fewest rows in all: `minimum + reserved`.
        needed: u64,
    },
    /// Comparing with the truth needs the same starts.
    #[error("cannot compare the sets: {reason}")]
    Compare {
        /// Why.
        reason: String,
    },
}

impl LearnError {
    /// The parameter this error is about, when it is one.
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            LearnError::Parameter(p) => Some(p),
            _ => None,
        }
    }
}

/// The regression of the law.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LawMethod {
    /// A local affine fit `a + B d` (cheaper, more bias).
    LocalLinear,
    /// A local quadratic fit (lower error than `local-linear` at the same data).
    LocalQuadratic,
    /// The functions of the motors (a tensor Fourier basis) that sensory neighbours
    /// share, learned once for all the logs; the kernels are their level sets (see the
    /// [module docs](self#the-law-invariants-lawmethodinvariants)). The default: the
    /// local laws average the sensors over their bandwidth, and the curves traced on
    /// them drift into wrong loops.
    #[default]
    Invariants,
}

impl std::str::FromStr for LawMethod {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "local-linear" => Ok(LawMethod::LocalLinear),
            "local-quadratic" => Ok(LawMethod::LocalQuadratic),
            "invariants" => Ok(LawMethod::Invariants),
            other => Err(format!(
                "unknown law method '{other}'; use local-linear, local-quadratic or invariants"
            )),
        }
    }
}

/// Parameters of the learned law (keys of the `[data]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LawParams {
    /// The law. Default `invariants`.
    pub method: LawMethod,
    /// Samples a typical fit holds: the bandwidth is the median distance to the
    /// `neighbours`-th nearest sample. Default `4p + 20` with `p` the fit's
    /// coefficients (40 for local-linear, 80 for local-quadratic with 4 motors); 40 for
    /// `invariants` (whose bandwidth only decides coverage).
    pub neighbours: Option<usize>,
    /// Factor on that bandwidth. Default 1.
    pub bandwidth_factor: f64,
    /// Samples within the bandwidth for the law to cover a configuration. Default
    /// `max(p + 1, neighbours / 4)`.
    pub coverage_neighbours: Option<usize>,
    /// Samples of each log held out to measure the error. Default `min(S/10, 2000)`.
    pub holdout: Option<usize>,
    /// Ridge on the non-constant coefficients, relative to the total weight. Default
    /// `1e-6`.
    pub ridge: f64,
    /// Seed of the held-out samples and of the probes. Default 1.
    pub seed: u64,
    /// `invariants` only: how many invariants to keep (the smallest generalised
    /// eigenvalues, at most 32). Default: those up to the largest ratio (at least 2)
    /// between consecutive eigenvalues below `invariance_threshold`, else all of those.
    pub invariants: Option<usize>,
    /// `invariants` only: the largest `λ = E[(z_i − z_j)²] / Var z` over pairs of
    /// sensory neighbours of a kept invariant (2 for a function independent between the
    /// two samples of a pair); the count ends at the largest gap below it. Default 0.4.
    pub invariance_threshold: f64,
    /// The rank of `∂s/∂m` (the kernels have dimension `N − rank`), when the user knows
    /// it: `1..=N−1` (`N` motors; rank 3 on the paper's 4-hinge arm, whose kernels are
    /// curves). Used in place of the rank the evidence reads, which is reported beside
    /// it, with a warning when they differ ([`RankChoice`]). Default: read from the
    /// data and the law.
    pub rank: Option<usize>,
}

impl Default for LawParams {
    fn default() -> Self {
        Self {
            method: LawMethod::Invariants,
            neighbours: None,
            bandwidth_factor: 1.0,
            coverage_neighbours: None,
            holdout: None,
            ridge: 1e-6,
            seed: 1,
            invariants: None,
            invariance_threshold: 0.4,
            rank: None,
        }
    }
}

/// Checked [`LawParams`].
#[derive(Debug, Clone, PartialEq)]
pub struct LawValidParams {
    pub(crate) method: LawMethod,
    neighbours: Option<usize>,
    pub(crate) bandwidth_factor: f64,
    coverage_neighbours: Option<usize>,
    holdout: Option<usize>,
    pub(crate) ridge: f64,
    pub(crate) seed: u64,
    pub(crate) invariants: Option<usize>,
    pub(crate) invariance_threshold: f64,
    pub(crate) rank: Option<usize>,
}

fn invalid(key: &'static str, value: impl std::fmt::Display, reason: &str) -> LearnError {
    InvalidParameter::new("data", key, value, reason).into()
}

impl CheckParams for LawParams {
    type Valid = LawValidParams;
    type Error = LearnError;

    fn check_params(&self) -> Result<LawValidParams, LearnError> {
        if !(self.bandwidth_factor.is_finite() && self.bandwidth_factor > 0.0) {
            return Err(invalid(
                "bandwidth_factor",
                self.bandwidth_factor,
                "must be a finite number greater than zero",
            ));
        }
        if !(self.ridge.is_finite() && (0.0..1.0).contains(&self.ridge)) {
            return Err(invalid("ridge", self.ridge, "must be in [0, 1)"));
        }
        for (key, value) in [
            ("neighbours", self.neighbours),
            ("coverage_neighbours", self.coverage_neighbours),
        ] {
            if value == Some(0) {
                return Err(invalid(key, 0, "must be at least 1"));
            }
        }
        if !(self.invariance_threshold.is_finite() && self.invariance_threshold > 0.0) {
            return Err(invalid(
                "invariance_threshold",
                self.invariance_threshold,
                "must be a finite number greater than zero (0.4: an invariant changes between sensory neighbours by at most a fifth of what an unrelated function does)",
            ));
        }
        if let Some(count) = self.invariants {
            if count == 0 || count > invariants::MAX_INVARIANTS {
                return Err(invalid(
                    "invariants",
                    count,
                    "must be in 1..=32 (or left out: those below invariance_threshold)",
                ));
            }
        }
        if self.rank == Some(0) {
            return Err(invalid(
                "rank",
                0,
                "must be at least 1 (and at most N − 1 for N motors: the kernels have dimension N − rank), or left out to read it from the data",
            ));
        }
        if let (Some(n), Some(c)) = (self.neighbours, self.coverage_neighbours) {
            if c > n {
                return Err(invalid(
                    "coverage_neighbours",
                    c,
                    "must be at most neighbours (a typical fit must cover its own sample)",
                ));
            }
        }
        Ok(LawValidParams {
            method: self.method,
            neighbours: self.neighbours,
            bandwidth_factor: self.bandwidth_factor,
            coverage_neighbours: self.coverage_neighbours,
            holdout: self.holdout,
            ridge: self.ridge,
            seed: self.seed,
            invariants: self.invariants,
            invariance_threshold: self.invariance_threshold,
            rank: self.rank,
        })
    }
}

impl LawParams {
    /// Validates the parameters ([`CheckParams::check_params`]).
    pub fn check(&self) -> Result<LawValidParams, LearnError> {
        self.check_params()
    }
}

impl LawValidParams {
    /// The fit's coefficients for `n` motors.
    pub fn coefficients(&self, n: usize) -> usize {
        law::parameter_count(self.method, n)
    }

    /// Samples a typical fit holds (see [`LawParams::neighbours`]).
    pub fn neighbours(&self, n: usize) -> usize {
        match self.method {
            LawMethod::Invariants => self.neighbours.unwrap_or(40),
            _ => self.neighbours.unwrap_or(4 * self.coefficients(n) + 20),
        }
    }

    /// Samples a typical fit holds on a log whose noise is `noise`, of `fitted` rows:
    /// the default of [`LawValidParams::neighbours`], raised so that the fit averages
    /// the noise down to [`NOISE_TARGET`] of the sensors' spread (`p (σ̂ / target)²`
    /// for `p` coefficients), at most `16 p` and `fitted / 100`. A given `neighbours`
    /// is kept.
    pub fn neighbours_for_noise(&self, n: usize, noise: &NoiseEstimate, fitted: usize) -> usize {
        let default = self.neighbours(n);
        if self.neighbours.is_some() || self.method == LawMethod::Invariants {
            return default;
        }
        let p = self.coefficients(n);
        let ratio = noise.assumed_relative() / NOISE_TARGET;
        let wanted = (p as f64 * ratio * ratio).ceil() as usize;
        default.max(wanted.min(16 * p).min(fitted / 100))
    }

    /// Samples a fit on a log of noise `noise` would need to average it down to
    /// [`NOISE_TARGET`] (see [`LawValidParams::neighbours_for_noise`]), uncapped.
    fn neighbours_wanted(&self, n: usize, noise: &NoiseEstimate) -> usize {
        let ratio = noise.assumed_relative() / NOISE_TARGET;
        ((self.coefficients(n) as f64 * ratio * ratio).ceil() as usize).max(self.neighbours(n))
    }

    /// Samples within the bandwidth that make a configuration covered.
    pub fn coverage_neighbours(&self, n: usize) -> usize {
        self.coverage_neighbours
            .unwrap_or_else(|| match self.method {
                LawMethod::Invariants => (self.neighbours(n) / 4).max(1),
                _ => (self.coefficients(n) + 1).max(self.neighbours(n) / 4),
            })
    }

    /// Samples held out of a log of `samples`.
    pub fn holdout(&self, samples: usize) -> usize {
        self.holdout
            .unwrap_or((samples / 10).min(2000))
            .min(samples)
    }

    /// Bytes learning from a log of `samples` rows of `n` motors and `k` sensors needs
    /// at most, the log included: the arrays, the sensors' copy, the plain k-d tree and
    /// the tree of periodic images (at most `1.5^P` images per sample for `P` periodic
    /// motors, as the bandwidth is below a quarter period).
    /// For `invariants`, the tree of the sensors and that of the invariants (at most
    /// 32 coordinates) come in their stead of the plain tree, with the pairs.
    /// The basis sums and matrices of `invariants` and the worker threads' buffers (on
    /// rayon's current pool) count too: [`LawValidParams::memory`] in all.
    pub fn bytes(&self, samples: usize, n: usize, k: usize, periodic: usize) -> u64 {
        self.memory(&[(samples, k)], n, periodic, rayon::current_num_threads())
            .total_bytes()
    }

    /// The method.
    pub fn method(&self) -> LawMethod {
        self.method
    }

    /// The rank given (see [`LawParams::rank`]).
    pub fn rank(&self) -> Option<usize> {
        self.rank
    }

    /// Refuses a given rank outside `1..=N−1` for `n` motors ([`LawParams::rank`]).
    pub fn check_rank(&self, n: usize) -> Result<(), LearnError> {
        match self.rank {
            Some(rank) if rank == 0 || rank >= n => Err(InvalidParameter::new(
                "data",
                "rank",
                rank,
                format!(
                    "must be in 1..={} for {n} motors (the kernels have dimension {n} − rank: rank {} gives curves, rank 1 sets of dimension {}), or left out to read it from the data",
                    n.saturating_sub(1),
                    n.saturating_sub(1),
                    n.saturating_sub(1)
                ),
            )
            .into()),
            _ => Ok(()),
        }
    }
}

/// The noise a local fit should leave in the law's values, relative to the sensors'
/// spread: `0.005`.
pub const NOISE_TARGET: f64 = 0.005;

/// Learns the law from `logs` (at least one; every log's motors in `space`), holding
/// out samples of each to measure its error. `memory_limit` (bytes), when given, is
/// checked before anything is built. [`learn_with_progress`] reports its stages.
pub fn learn(
    logs: &[SensorimotorLog],
    space: &crate::agent::MotorSpace,
    params: &LawValidParams,
    memory_limit: Option<u64>,
) -> Result<LearnedLaw, LearnError> {
    learn_with_progress(logs, space, params, memory_limit, &crate::progress::Silent)
}

impl MemoryEstimate {
    /// Refuses an estimate above `limit` bytes, with its parts and what to lower
    /// ([`LearnError::OutOfMemory`]); `samples` are those of the logs.
    pub fn check(&self, samples: usize, limit: u64) -> Result<(), LearnError> {
        let needed = self.total_bytes();
        if needed > limit {
            return Err(LearnError::OutOfMemory {
                samples,
                needed,
                available: limit,
                parts: self.parts(),
                fix: self.fix(),
            });
        }
        Ok(())
    }
}

/// [`learn`], reporting its stages to `progress` ([`observe`] lists them): the same
/// law whatever observer and thread count.
pub fn learn_with_progress(
    logs: &[SensorimotorLog],
    space: &crate::agent::MotorSpace,
    params: &LawValidParams,
    memory_limit: Option<u64>,
    progress: &dyn crate::progress::Progress,
) -> Result<LearnedLaw, LearnError> {
    if logs.is_empty() {
        return Err(LearnError::NoLog);
    }
    let n = space.dim();
    params.check_rank(n)?;
    let periodic = space.motors().iter().filter(|m| m.is_periodic()).count();
    let shapes: Vec<(usize, usize)> = logs
        .iter()
        .map(|l| (l.samples(), l.sensors.ncols()))
        .collect();
    let memory = params.memory(&shapes, n, periodic, rayon::current_num_threads());
    if let Some(limit) = memory_limit {
        memory.check(logs.iter().map(SensorimotorLog::samples).sum(), limit)?;
    }
    for log in logs {
        if log.motors.ncols() != n {
            return Err(LearnError::MotorColumns {
                path: log.files.motors.clone(),
                found: log.motors.ncols(),
                expected: n,
            });
        }
    }
    // One sample per motor command: repeats are counted, then left out.
    let repeats: Vec<(Vec<bool>, usize)> = logs
        .iter()
        .map(|log| log::repeated_rows(log, space))
        .collect();
    let unique: Option<Vec<SensorimotorLog>> = repeats.iter().any(|r| r.1 > 0).then(|| {
        logs.iter()
            .zip(&repeats)
            .map(|(log, (flags, _))| log::without_repeats(log, flags))
            .collect()
    });
    let original = logs;
    let logs = unique.as_deref().unwrap_or(logs);
    let (models, mut reports, data_rank) = match params.method {
        LawMethod::LocalLinear | LawMethod::LocalQuadratic => {
            let mut models = Vec::with_capacity(logs.len());
            let mut reports = Vec::with_capacity(logs.len());
            let mut data_rank = None;
            for log in logs {
                let (model, report, rank) = log::fit_log(log, space, params, progress)?;
                models.push(model);
                reports.push(report);
                if data_rank.is_none() {
                    data_rank = rank;
                }
            }
            (law::Models::Local(models), reports, data_rank)
        }
        LawMethod::Invariants => {
            let (model, reports, data_rank) = learn_invariants(logs, space, params, progress)?;
            (law::Models::Invariants(Box::new(model)), reports, data_rank)
        }
    };
    for ((report, (_, repeated)), log) in reports.iter_mut().zip(&repeats).zip(original) {
        report.repeated = *repeated;
        report.samples = log.samples();
    }
    let mut law = LearnedLaw::new(
        space.clone(),
        models,
        params.method,
        (reports, data_rank),
        (params.seed, params.rank, progress),
    );
    let mut warnings = law_warnings(law.report(), params, n);
    warnings.extend(repeat_warnings(law.report()));
    law.warn(warnings);
    let (quality, warnings) = quality::assess(law.report(), n);
    law.warn(warnings);
    // The report is the same for any thread count: one thread's buffers.
    law.describe(
        quality,
        Some(MemoryEstimate {
            threads: None,
            ..memory
        }),
    );
    Ok(law)
}

/// The `invariants` law of `logs`: the noise and local rank of every log measured on
/// its fitted rows (the first log's rank is the least count of invariants kept).
fn learn_invariants(
    logs: &[SensorimotorLog],
    space: &crate::agent::MotorSpace,
    params: &LawValidParams,
    progress: &dyn crate::progress::Progress,
) -> Result<(InvariantModel, Vec<LogReport>, Option<LocalRank>), LearnError> {
    let n = space.dim();
    let features = InvariantModel::check_motors(n).map_err(|reason| LearnError::TooFewSamples {
        path: logs[0].files.motors.clone(),
        samples: logs[0].samples(),
        reason,
        fix: "use method = local-quadratic",
    })?;
    let mut fits = Vec::with_capacity(logs.len());
    let mut held = Vec::with_capacity(logs.len());
    let mut locals = Vec::with_capacity(logs.len());
    for log in logs {
        let samples = log.samples();
        let holdout = params.holdout(samples);
        let least = (params.neighbours(n) + 1).max(10 * (features + 1));
        if samples - holdout < least {
            return Err(LearnError::TooFewSamples {
                path: log.files.motors.clone(),
                samples,
                reason: format!(
                    "the invariants of {n} motors need at least {least} fitted samples (ten per basis function), and {} remain after {holdout} held out",
                    samples - holdout
                ),
                fix: "record a longer log, or lower holdout",
            });
        }
        let (fit, held_rows) = log::split_rows(samples, holdout, params.seed);
        fits.push(fit);
        held.push(held_rows);
    }
    progress.start(observe::NOISE, logs.len() as u64);
    for (log, fit) in logs.iter().zip(&fits) {
        locals.push(estimate_local(log, fit, params.seed));
        progress.advance(1);
    }
    progress.finish();
    let data_rank = locals
        .first()
        .and_then(|l| l.as_ref())
        .map(|(_, rank)| rank.clone());
    let least = data_rank.as_ref().map_or(1, |r| r.rank.max(1));
    let (model, mut reports) =
        InvariantModel::fit(logs, (&fits, &held), space, params, (least, progress))?;
    for (report, local) in reports.iter_mut().zip(locals) {
        report.noise = local.map(|(noise, _)| noise);
    }
    Ok((model, reports, data_rank))
}

/// Logs of which at least this share of samples repeat an earlier motor command are
/// warned about ([`LogReport::repeated`]).
pub const REPEAT_WARNING_SHARE: f64 = 0.05;

/// A warning for every log where at least [`REPEAT_WARNING_SHARE`] of the samples
/// repeat an earlier motor command.
fn repeat_warnings(report: &LawReport) -> Vec<String> {
    report
        .logs
        .iter()
        .filter(|log| log.repeated as f64 >= REPEAT_WARNING_SHARE * log.samples as f64)
        .map(|log| {
            format!(
                "{}: {} of {} samples repeat an earlier sample's motor command (the robot held still, or rows were recorded twice); each command was learned from once, as a repeat's nearest sensory neighbour is its own twin, which tells nothing about the kernels. The law rests on the {} distinct commands: record more distinct configurations for a finer law",
                log.motors,
                log.repeated,
                log.samples,
                log.samples - log.repeated
            )
        })
        .collect()
}

/// What the data cannot support, with the measured noise and what would help: a local
/// law whose held-out error is far above the noise (too few samples for the law's
/// changes), noise the fit cannot average down, a rank the noise floor hides, or a log
/// too short to measure the noise.
fn law_warnings(report: &LawReport, params: &LawValidParams, n: usize) -> Vec<String> {
    let mut warnings = Vec::new();
    let Some(rank) = &report.data_rank else {
        warnings.push(
            "the log has too few samples to measure its noise and the rank of its sensors: record a longer log".to_owned(),
        );
        return warnings;
    };
    let hidden = noise::spectrum_rank(&rank.spectrum, 0.0);
    if hidden > rank.rank && rank.floor > 0.0 {
        warnings.push(format!(
            "the noise floor ({:.3} of the largest slope) hides {} of the {hidden} directions the sensors change along: rank {} is used; a longer log (or less noisy sensors) would show whether they are real",
            rank.floor,
            hidden - rank.rank,
            rank.rank
        ));
    }
    for log in &report.logs {
        let Some(noise) = &log.noise else { continue };
        let sigma = noise.relative_overall;
        let measured = if noise.measurable() {
            format!(
                "measured noise σ̂ = {:.2} % of the sensors' spread",
                100.0 * sigma
            )
        } else {
            format!(
                "noise below what the data's spacing resolves (σ̂ ≤ {:.2} % of the sensors' spread)",
                100.0 * noise.resolution.max(sigma)
            )
        };
        let floor = noise.assumed_relative().max(0.005);
        // The local laws' values are what is traced (the invariants law traces z).
        let local = report.method != LawMethod::Invariants;
        if local && log.held_out_relative_rms > 3.0 * floor && log.held_out_relative_rms > 0.02 {
            warnings.push(format!(
                "{}: the law's held-out error ({:.1} % of the sensors' spread) is far above the noise ({measured}): the sensors change faster than the samples' spacing (bandwidth {:.3}) can follow; record more samples (the error falls with the spacing), or try another method",
                log.motors,
                100.0 * log.held_out_relative_rms,
                log.bandwidth
            ));
        }
        if let Some(chosen) = log.neighbours {
            let wanted = params.neighbours_wanted(n, noise);
            if wanted > chosen {
                warnings.push(format!(
                    "{}: {measured}; averaging it down to {:.1} % needs fits of {wanted} samples, and the log allows {chosen}: record about {:.0}× more samples",
                    log.motors,
                    100.0 * NOISE_TARGET,
                    (wanted as f64 / chosen as f64).ceil()
                ));
            }
        }
    }
    warnings
}

/// The sensor tolerance a learned law can honour (relative to the largest sensor value
/// at the start, as [`crate::kernel::TraceParams::sensor_tolerance`]): the fit's value
/// is a weighted least-squares solve whose rounding error is about `10⁻¹³` of the
/// sensors' size, so the simulator's `10⁻¹²` cannot be met reliably and a corrector
/// asked for it fails and halves the step again and again. `10⁻⁸` moves a point by
/// about `10⁻⁸` of the sensors' scale over the Jacobian's size (below `10⁻⁷` rad on the
/// arm), far below the law's own error.
pub const LAW_SENSOR_TOLERANCE: f64 = 1e-8;

/// Tracing parameters suited to a learned law: the sensory method, the sensor
/// tolerance [`LAW_SENSOR_TOLERANCE`], a loop-closure tolerance of `0.03` (the law's
/// error makes a loop return to its start less exactly than a simulator's), a budget
/// of 3000 steps (a set on a poor law may wander: it fails as `not-closed`), and no
/// multi-start search for other pieces (`piece_starts = 0`: seeds drawn on the whole
/// motor torus lie mostly where the log has no data).
pub fn law_trace_params() -> crate::kernel::TraceParams {
    crate::kernel::TraceParams {
        method: crate::kernel::TraceMethod::Sensory,
        sensor_tolerance: LAW_SENSOR_TOLERANCE,
        closure_tolerance: 0.03,
        max_steps: 3000,
        piece_starts: 0,
        ..crate::kernel::TraceParams::default()
    }
}

/// Traces the kernel sets `ŝ(m) = ŝ(m^i)` of the learned law through `starts` with the
/// tracer's sensory method, unchanged (`params.method` is set to `sensory`, and the
/// sensor tolerance to at least [`LAW_SENSOR_TOLERANCE`]; the law ignores the
/// environment, so an empty one is passed). Sets that leave the covered region have the
/// status `left-data`. [`law_trace_params`] gives parameters suited to a learned law.
/// The report's `law` is the law's report completed with the closure rate of the sets
/// and its warnings ([`LawReport::with_trace`]). When every set fails at the rank the
/// evidence read, the sets are traced again at the next of [`RankChoice::candidates`]
/// (not when the rank was given), until one keeps a set; the report's `rank`,
/// `rank_source` ([`RankSource::Retried`]) and `rank_choice.tried` say so.
pub fn trace_learned(
    law: &LearnedLaw,
    starts: ndarray::ArrayView2<'_, f64>,
    params: &crate::kernel::TraceParams,
    progress: &dyn crate::progress::Progress,
) -> Result<crate::kernel::TracedSets, LearnError> {
    let mut report = law.report().clone();
    let params = crate::kernel::TraceParams {
        method: crate::kernel::TraceMethod::Sensory,
        sensor_tolerance: params.sensor_tolerance.max(LAW_SENSOR_TOLERANCE),
        ..params.clone()
    }
    .check()?;
    let unused = crate::agent::Environment::from_lights(Vec::new());
    let trace_at = |rank: usize| {
        crate::kernel::trace_sets(
            &law::AtRank { law, rank },
            Some(&unused),
            starts,
            None,
            &params,
            progress,
        )
    };
    let mut traced = trace_at(report.rank)?;
    // Every set failed at the estimated rank: the next candidates, in order.
    let candidates = report
        .rank_choice
        .as_ref()
        .map(|c| c.candidates.clone())
        .unwrap_or_default();
    let mut at = candidates.iter().position(|&r| r == report.rank);
    let given = report.rank_source == RankSource::Given;
    while !given && everything_failed(&traced.report.summary) {
        let Some(next) = at.and_then(|i| candidates.get(i + 1)).copied() else {
            break;
        };
        at = at.map(|i| i + 1);
        let failed = &traced.report.summary;
        let tried = TriedRank {
            rank: report.rank,
            total: failed.total,
            by_status: failed.by_status.clone(),
        };
        report.warnings.push(format!(
            "every one of the {} sets failed at rank {} ({:?}): traced again at the next candidate rank {next} (kernels of dimension {})",
            failed.total,
            report.rank,
            failed.by_status,
            crate::agent::Agent::motor_dim(law) - next
        ));
        traced = trace_at(next)?;
        report.retried(tried, next);
    }
    // A report of numbers and names always serialises.
    traced.report.law = serde_json::to_value(report.with_trace(&traced.report.summary)).ok();
    Ok(traced)
}

/// Whether every one of at least one set failed.
fn everything_failed(summary: &crate::kernel::TraceSummary) -> bool {
    summary.total > 0 && summary.traced == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};

    /// A log of three hinges whose sensors read the tip of a planar 3-link chain
    /// (rank 2: the kernels are curves), and its motor space.
    fn chain_log(samples: usize) -> (SensorimotorLog, crate::agent::MotorSpace) {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let motors = Array2::from_shape_fn((samples, 3), |_| {
            rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)
        });
        let sensors = Array2::from_shape_fn((samples, 2), |(i, c)| {
            let m = motors.row(i);
            let (a, b) = (m[0], m[0] + m[1]);
            let t = b + m[2];
            match c {
                0 => a.cos() + 0.6 * b.cos() + 0.3 * t.cos(),
                _ => a.sin() + 0.6 * b.sin() + 0.3 * t.sin(),
            }
        });
        let files = LogFiles {
            motors: "m.npy".into(),
            sensors: "s.npy".into(),
        };
        let space = declared_space(
            &parse_motor_declarations("2pi").unwrap(),
            motors.view(),
            &files.motors,
        )
        .unwrap();
        (
            SensorimotorLog::new(motors, sensors, files, &space).unwrap(),
            space,
        )
    }

    #[test]
    fn a_rank_at_which_every_set_fails_is_retried_at_the_next_candidate() {
        let (log, space) = chain_log(20_000);
        let params = LawParams::default().check().unwrap();
        let mut law = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        assert_eq!(law.rank(), 2, "{:?}", law.report().rank_choice);
        let starts = log.motors.select(ndarray::Axis(0), &[0, 1, 2, 3]);
        // Surfaces (rank 1) cannot be covered within 10 nodes: every set fails there.
        let trace = crate::kernel::TraceParams {
            max_cover_points: 10,
            points: 20,
            ..law_trace_params()
        };
        law.set_candidates(vec![1, 2]);
        let traced = trace_learned(&law, starts.view(), &trace, &crate::progress::Silent).unwrap();
        assert!(
            traced.report.summary.traced >= 3,
            "{:?}",
            traced.report.summary
        );
        let report: LawReport = serde_json::from_value(traced.report.law.clone().unwrap()).unwrap();
        assert_eq!((report.rank, report.rank_source), (2, RankSource::Retried));
        let choice = report.rank_choice.unwrap();
        assert_eq!(choice.tried.len(), 1);
        assert_eq!(choice.tried[0].rank, 1);
        assert!(
            report
                .warnings
                .iter()
                .any(|w| w.contains("traced again at the next candidate rank 2")),
            "{:?}",
            report.warnings
        );
        // A given rank is never retried.
        let given = LawParams {
            rank: Some(1),
            ..LawParams::default()
        }
        .check()
        .unwrap();
        let law = learn(std::slice::from_ref(&log), &space, &given, None).unwrap();
        assert_eq!(law.report().rank_source, RankSource::Given);
        let traced = trace_learned(&law, starts.view(), &trace, &crate::progress::Silent).unwrap();
        assert_eq!(
            traced.report.summary.traced, 0,
            "{:?}",
            traced.report.summary
        );
        // Out of 1..=N−1: named with the motors and the kernel dimension.
        for rank in [3, 9] {
            let bad = LawParams {
                rank: Some(rank),
                ..LawParams::default()
            }
            .check()
            .unwrap();
            let e = learn(std::slice::from_ref(&log), &space, &bad, None)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("rank") && e.contains("1..=2 for 3 motors"),
                "{e}"
            );
        }
        let e = LawParams {
            rank: Some(0),
            ..LawParams::default()
        }
        .check()
        .unwrap_err()
        .to_string();
        assert!(e.contains("rank = 0"), "{e}");
    }
}
