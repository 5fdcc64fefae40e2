//! The `[kernel]` table: the tracing parameters ([`TraceParams`]), their defaults and
//! their check into the form that runs ([`TraceValidParams`]).

use serde::{Deserialize, Serialize};

use super::{spatial::Spatial, tracer, KernelError, SensorNoise};
use crate::agent::Agent;
use crate::params::{CheckParams, InvalidParameter, Renamed};

/// Which level set to follow.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TraceMethod {
    /// The observer's pose and its analytic Jacobian (the paper's simulation).
    #[default]
    Kinematic,
    /// The agent's sensor values and their finite-difference Jacobian.
    Sensory,
    /// The law learned from babbling the agent within a budget of sensor rows, the
    /// sets traced on it (by the sensory method) and verified against the agent
    /// (`smspace::learn::budget`). It runs through the pipeline's `trace` stage (with a
    /// `[learn]` table), `smspace trace --method learned` and Python's `trace`; the
    /// tracer itself refuses it.
    Learned,
}

impl std::str::FromStr for TraceMethod {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "kinematic" => Ok(TraceMethod::Kinematic),
            "sensory" => Ok(TraceMethod::Sensory),
            "learned" => Ok(TraceMethod::Learned),
            other => Err(format!(
                "unknown tracing method '{other}'; use kinematic, sensory or learned"
            )),
        }
    }
}

/// How the step length is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StepControl {
    /// `fixed` for the kinematic method (the paper's), `adaptive` for the sensory one.
    #[default]
    Auto,
    /// Every step has length `step`.
    Fixed,
    /// Steps from `step` up to `max_step`, shrunk where the curve bends.
    Adaptive,
}

/// How the sensory method gets the Jacobian of the sensors between full evaluations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum JacobianMethod {
    /// Central differences (`2N` sensor rows) at every point where the level set is
    /// linearised.
    FiniteDifferences,
    /// Secant (Broyden) updates from the readings the tracer makes anyway, with
    /// central differences only where an update would not do (see the module docs).
    #[default]
    Secant,
}

impl JacobianMethod {
    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            JacobianMethod::FiniteDifferences => "finite-differences",
            JacobianMethod::Secant => "secant",
        }
    }
}

impl std::str::FromStr for JacobianMethod {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "finite-differences" => Ok(JacobianMethod::FiniteDifferences),
            "secant" => Ok(JacobianMethod::Secant),
            other => Err(format!(
                "unknown jacobian '{other}'; use secant (few sensor rows) or finite-differences (central differences at every point)"
            )),
        }
    }
}

/// Parameters of kernel-set tracing (the `[kernel]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TraceParams {
    /// Level set to follow. Default `kinematic`.
    pub method: TraceMethod,
    /// Step length `μ` (radians of motor space); the initial step when adaptive.
    /// Default `1e-3` (the paper's).
    pub step: f64,
    /// Fixed or adaptive steps. Default `auto` (fixed for kinematic, adaptive for sensory).
    pub step_control: StepControl,
    /// Largest adaptive step (radians); `0` (the default) lets the level set choose:
    /// [`EXACT_SENSORY_MAX_STEP`] for the sensory method on exact readings with
    /// `jacobian = "secant"` (its nodes carry exact tangents and the resampled points
    /// are projected onto the set, so long steps cost fewer sensor rows for the same
    /// sets; see the module docs), [`DEFAULT_MAX_STEP`] otherwise (noisy readings, a
    /// law learned from data, finite differences, the kinematic method).
    pub max_step: f64,
    /// Largest turn of the tangent per adaptive step, radians. Default `0.1`.
    pub max_turn: f64,
    /// A loop is closed when it comes back within this distance of its start (torus
    /// distance). Default `1e-2` (the paper's).
    pub closure_tolerance: f64,
    /// Fewest steps before a fixed-step loop may close. Default 50 (the paper's).
    pub min_steps: usize,
    /// Step budget of one set; a loop not closed by then fails. Default 200 000.
    pub max_steps: usize,
    /// Most sensor rows one set may read, what a set may cost its user (a simulator's
    /// or a robot's readings): the tracer checks the set's rows before every step of
    /// the trace and every node of a k-D covering, and a set that has read this many
    /// stops there and fails as `row-budget` (so a set reads at most this plus one
    /// step's rows). The kinematic method reads no sensor rows. 0: no cap. Default 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub max_rows: u64,
    /// Points per resampled set `P`. Default 100 (the paper's).
    pub points: usize,
    /// Kinematic corrector: largest pose residual accepted (length units and radians),
    /// or `1e-12` times the largest linear coordinate of the start's pose when that is
    /// larger (poses far from the origin). Default `1e-11`.
    pub pose_tolerance: f64,
    /// Sensory corrector: largest sensor residual accepted, relative to the largest
    /// sensor value at the start. Default `1e-12`.
    pub sensor_tolerance: f64,
    /// Corrector iterations allowed per point. Default 12.
    pub max_corrector_iterations: usize,
    /// Sensory method: finite-difference step of the Jacobian, radians. Default `1e-6`.
    pub finite_difference_step: f64,
    /// Sensory method: how the Jacobian of the sensors is obtained between full
    /// finite-difference evaluations ([`JacobianMethod`]). Default `secant`.
    pub jacobian: JacobianMethod,
    /// Sensory method: a set is singular where `σ_{N−1}/σ_max` of the sensory Jacobian
    /// falls below this (too few lights in view). Default `1e-4`.
    pub rank_tolerance: f64,
    /// Sensory method, the key `sensor_sigma`: the standard deviation the tracer takes
    /// for one reading, in sensor units ([`SensorNoise`]): `"auto"` (measured at every
    /// start from repeated readings), or a number (`0`: exact readings). Default
    /// `"auto"`. (Noise *added* to an agent is its `[agent.noise]` table; to a
    /// simulated log, `[data.simulate] relative_noise`.)
    #[serde(rename = "sensor_sigma", skip_serializing_if = "SensorNoise::is_auto")]
    pub noise: SensorNoise,
    /// The old name of `sensor_sigma`, refused by the check with the new one.
    #[serde(rename = "noise", skip_serializing)]
    pub old_noise: Renamed,
    /// Which pieces of a level set make the set `M^i`: `connected` (the paper's: the
    /// piece through `m^i`) or `all` (every configuration with the sensation of
    /// `m^i`). Default `connected`.
    pub components: Components,
    /// Seeds of the multi-start search for pieces, per set (see the module docs);
    /// with `connected`, pieces found and not sampled are reported. 0 turns the
    /// search off. Default 16.
    pub piece_starts: usize,
    /// Seed of the random shift of the multi-start design. Default 0.
    pub piece_seed: u64,
    /// A projected seed within this distance of a piece found (radians, torus
    /// distance; plus `cover_step` for k-D kernels) lies on it. Default `1e-2`.
    pub piece_tolerance: f64,
    /// Kernels of dimension k ≥ 2: the tangent step of the dense covering (radians).
    /// Default `0.05`.
    pub cover_step: f64,
    /// Kernels of dimension k ≥ 2: most nodes of the dense covering of one set, all
    /// pieces together (a set needing more fails as `cover-budget`). Default 100 000.
    pub max_cover_points: usize,
    /// Which sets the pipeline compares: `kernel` (the traced sets, the paper's) or
    /// `compensable` (each extended along the motors the compensability analysis finds
    /// non-spatial, [`spatial`](super::spatial)). Default `kernel`.
    #[serde(skip_serializing_if = "Spatial::is_kernel")]
    pub spatial: Spatial,
    /// With `spatial = "compensable"`: values of each non-spatial motor every traced
    /// point is repeated at ([`spatial`](super::spatial)). Default 8.
    #[serde(skip_serializing_if = "is_default_spatial_samples")]
    pub spatial_samples: usize,
}

/// Default of [`TraceParams::spatial_samples`].
pub const DEFAULT_SPATIAL_SAMPLES: usize = 8;

/// The largest adaptive step when `max_step = 0` (automatic) for every level set but
/// the sensory one on exact readings with secant Jacobians, radians.
pub const DEFAULT_MAX_STEP: f64 = 0.05;

/// The largest adaptive step when `max_step = 0` (automatic) for the sensory method on
/// exact readings with `jacobian = "secant"`, radians (measured on the paper's arm,
/// see the module docs: the sets agree with those of `0.05` within `5·10⁻⁷` rad).
pub const EXACT_SENSORY_MAX_STEP: f64 = 0.2;

/// Whether a set that has read `rows` sensor rows has spent a cap of `max_rows`
/// ([`TraceParams::max_rows`]: 0 is no cap).
pub(crate) fn rows_spent(max_rows: u64, rows: u64) -> bool {
    max_rows > 0 && rows >= max_rows
}

fn is_zero(value: &u64) -> bool {
    *value == 0
}

fn is_default_spatial_samples(samples: &usize) -> bool {
    *samples == DEFAULT_SPATIAL_SAMPLES
}

/// Which pieces of a level set are sampled (`[kernel] components`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Components {
    /// The piece through the start (the paper's method, appendix A).
    #[default]
    Connected,
    /// Every piece the multi-start search finds.
    All,
}

impl std::str::FromStr for Components {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "connected" => Ok(Components::Connected),
            "all" => Ok(Components::All),
            other => Err(format!(
                "unknown components '{other}'; use connected (the piece through the start) or all (every piece)"
            )),
        }
    }
}

impl Default for TraceParams {
    fn default() -> Self {
        Self {
            method: TraceMethod::Kinematic,
            step: 1e-3,
            step_control: StepControl::Auto,
            max_step: 0.0,
            max_turn: 0.1,
            closure_tolerance: 1e-2,
            min_steps: 50,
            max_steps: 200_000,
            max_rows: 0,
            points: 100,
            pose_tolerance: 1e-11,
            sensor_tolerance: 1e-12,
            max_corrector_iterations: 12,
            finite_difference_step: 1e-6,
            jacobian: JacobianMethod::Secant,
            rank_tolerance: 1e-4,
            noise: SensorNoise::Auto,
            old_noise: Renamed::default(),
            components: Components::Connected,
            piece_starts: 16,
            piece_seed: 0,
            piece_tolerance: 1e-2,
            cover_step: 0.05,
            max_cover_points: 100_000,
            spatial: Spatial::Kernel,
            spatial_samples: DEFAULT_SPATIAL_SAMPLES,
        }
    }
}

/// Checked tracing parameters, the only form that runs. Built by [`TraceParams::check`].
#[derive(Debug, Clone, PartialEq)]
pub struct TraceValidParams {
    pub(crate) method: TraceMethod,
    pub(crate) step: f64,
    pub(crate) step_control: StepControl,
    pub(crate) max_step: f64,
    pub(crate) max_turn: f64,
    pub(crate) closure_tolerance: f64,
    pub(crate) min_steps: usize,
    pub(crate) max_steps: usize,
    pub(crate) max_rows: u64,
    pub(crate) points: usize,
    pub(crate) pose_tolerance: f64,
    pub(crate) sensor_tolerance: f64,
    pub(crate) max_corrector_iterations: usize,
    pub(crate) finite_difference_step: f64,
    pub(crate) jacobian: JacobianMethod,
    pub(crate) rank_tolerance: f64,
    pub(crate) noise: SensorNoise,
    pub(crate) components: Components,
    pub(crate) piece_starts: usize,
    pub(crate) piece_seed: u64,
    pub(crate) piece_tolerance: f64,
    pub(crate) cover_step: f64,
    pub(crate) max_cover_points: usize,
}

impl TraceValidParams {
    /// The level set followed.
    pub fn method(&self) -> TraceMethod {
        self.method
    }
    /// The step control in force (`auto` resolved).
    pub fn step_control(&self) -> StepControl {
        self.step_control
    }
    /// The largest adaptive step on a level set whose own choice is `automatic`
    /// (`max_step` when given, see [`TraceParams::max_step`]).
    pub(crate) fn max_step_or(&self, automatic: f64) -> f64 {
        if self.max_step > 0.0 {
            self.max_step
        } else {
            automatic
        }
    }
    /// Whether a set that has read `rows` sensor rows has spent its
    /// [`max_rows`](TraceParams::max_rows).
    pub(crate) fn rows_spent(&self, rows: u64) -> bool {
        rows_spent(self.max_rows, rows)
    }
    /// Points per resampled set.
    pub fn points(&self) -> usize {
        self.points
    }
    /// Which pieces are sampled.
    pub fn components(&self) -> Components {
        self.components
    }
}

fn invalid(key: &'static str, value: impl std::fmt::Display, reason: &str) -> KernelError {
    InvalidParameter::new("kernel", key, value, reason).into()
}

fn positive(key: &'static str, value: f64) -> Result<(), KernelError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            key,
            value,
            "must be a finite number greater than zero",
        ))
    }
}

/// Bytes of `(rows, points, motor_dim)` float64 kernel sets with the piece of every
/// point (`(rows, points)` int64) (saturating).
fn sets_bytes(rows: u64, points: usize, motor_dim: usize) -> u64 {
    rows.saturating_mul(points as u64)
        .saturating_mul(motor_dim as u64 + 1)
        .saturating_mul(8)
}

impl TraceValidParams {
    /// The checks of these parameters against an agent that need no start: the
    /// `kinematic` method needs a ground truth, and the kernel dimension
    /// `k = N − rank(J)` the ground truth implies must be 0 or 1 (without a ground truth
    /// it is estimated when tracing). The pipeline runs this before anything runs.
    pub fn check_for(&self, agent: &dyn Agent) -> Result<(), KernelError> {
        tracer::check_agent_for(agent, self).map(drop)
    }

    /// The kernel dimension `k = N − C` the agent's ground truth implies (after the
    /// checks of [`check_for`](Self::check_for)); `None` when it is estimated while
    /// tracing (no ground truth).
    pub fn dimension_for(&self, agent: &dyn Agent) -> Result<Option<usize>, KernelError> {
        tracer::check_agent_for(agent, self)
    }

    /// Bytes of the kernel sets traced from `rows` motor rows of an agent with
    /// `motor_dim` motors (see [`TraceParams::sets_bytes`]).
    pub fn sets_bytes(&self, rows: u64, motor_dim: usize) -> u64 {
        sets_bytes(rows, self.points, motor_dim)
    }

    /// Bytes of the seeds of the multi-start search ([`TraceParams::seeds_bytes`]).
    pub fn seeds_bytes(&self, motor_dim: usize) -> u64 {
        seeds_bytes(self.piece_starts, motor_dim)
    }
}

/// Bytes of `piece_starts` seeds of `motor_dim` float64 each (saturating).
fn seeds_bytes(piece_starts: usize, motor_dim: usize) -> u64 {
    (piece_starts as u64)
        .saturating_mul(motor_dim as u64)
        .saturating_mul(8)
}

/// Most points per kernel set.
pub const MAX_POINTS: usize = 100_000;

/// Most seeds of the multi-start search for pieces (`kernel.piece_starts`), per set.
/// Every set projects every seed onto its level set, so the search costs
/// `piece_starts` corrector runs per set; the seeds themselves take
/// `piece_starts × N` float64.
pub const MAX_PIECE_STARTS: usize = 10_000;

impl TraceParams {
    /// Bytes of the kernel sets `(rows, points, N)` float64 traced from `rows` motor
    /// rows of an agent with `motor_dim` motors, and the piece of every point
    /// `(rows, points)` int64, with the points of spatial sets
    /// ([`TraceParams::stored_points`]) (saturating).
    pub fn sets_bytes(&self, rows: u64, motor_dim: usize) -> u64 {
        sets_bytes(rows, self.stored_points(), motor_dim)
    }

    /// Bytes of the seeds of the multi-start search for pieces, `piece_starts × N`
    /// float64, which every tracer holds (saturating).
    pub fn seeds_bytes(&self, motor_dim: usize) -> u64 {
        seeds_bytes(self.piece_starts, motor_dim)
    }

    /// Validates the parameters and resolves `auto` step control
    /// ([`CheckParams::check_params`]).
    pub fn check(&self) -> Result<TraceValidParams, KernelError> {
        self.check_params()
    }
}

impl TraceParams {
    /// The checks of the counts: at least 1 point, step, corrector iteration and
    /// covering node, and at most [`MAX_POINTS`] points and [`MAX_PIECE_STARTS`] seeds.
    fn check_counts(&self) -> Result<(), KernelError> {
        for (key, value) in [
            ("points", self.points),
            ("max_steps", self.max_steps),
            ("max_corrector_iterations", self.max_corrector_iterations),
            ("max_cover_points", self.max_cover_points),
        ] {
            if value == 0 {
                return Err(invalid(key, 0, "must be at least 1"));
            }
        }
        if self.points > MAX_POINTS {
            return Err(invalid(
                "points",
                self.points,
                "must be at most 100000 points per set (the paper uses 100)",
            ));
        }
        if self.piece_starts > MAX_PIECE_STARTS {
            return Err(invalid(
                "piece_starts",
                self.piece_starts,
                &format!("must be at most {MAX_PIECE_STARTS} seeds per set (each costs a projection onto every set's level set; the default is 16, 0 turns the search off)"),
            ));
        }
        Ok(())
    }
}

impl CheckParams for TraceParams {
    type Valid = TraceValidParams;
    type Error = KernelError;

    fn check_params(&self) -> Result<TraceValidParams, KernelError> {
        self.old_noise.refuse("kernel", "noise", "sensor_sigma")?;
        if self.method == TraceMethod::Learned {
            return Err(invalid(
                "method",
                "learned",
                "traces on a law learned from the agent within a budget of sensor rows: in an experiment give a [learn] table with budget = ROWS, on the command line smspace trace --method learned --budget ROWS, in Python trace(agent, starts, method=\"learned\", budget=ROWS)",
            ));
        }
        if !(self.max_step.is_finite() && self.max_step >= 0.0) {
            return Err(invalid(
                "max_step",
                self.max_step,
                "must be a finite number greater than zero, or 0 to let the level set choose",
            ));
        }
        for (key, value) in [
            ("step", self.step),
            ("max_turn", self.max_turn),
            ("closure_tolerance", self.closure_tolerance),
            ("pose_tolerance", self.pose_tolerance),
            ("sensor_tolerance", self.sensor_tolerance),
            ("finite_difference_step", self.finite_difference_step),
            ("piece_tolerance", self.piece_tolerance),
            ("cover_step", self.cover_step),
        ] {
            positive(key, value)?;
        }
        if !(self.rank_tolerance.is_finite() && (0.0..1.0).contains(&self.rank_tolerance)) {
            return Err(invalid(
                "rank_tolerance",
                self.rank_tolerance,
                "must be in [0, 1)",
            ));
        }
        if let SensorNoise::Sigma(sigma) = self.noise {
            // A σ whose square overflows leaves every regression's weights infinite.
            if !(sigma.is_finite() && sigma >= 0.0 && (sigma * sigma).is_finite()) {
                return Err(invalid(
                    "sensor_sigma",
                    sigma,
                    "must be \"auto\" or a finite standard deviation ≥ 0 of one reading in sensor units (0: exact readings); one whose square overflows (above about 1e154) is no sensor's noise",
                ));
            }
        }
        self.check_counts()?;
        let step_control = match (self.step_control, self.method) {
            (StepControl::Auto, TraceMethod::Kinematic) => StepControl::Fixed,
            (StepControl::Auto, TraceMethod::Sensory | TraceMethod::Learned) => {
                StepControl::Adaptive
            }
            (other, _) => other,
        };
        // (With `max_step = 0` the smallest step a level set may choose bounds `step`.)
        let smallest_max_step = if self.max_step > 0.0 {
            self.max_step
        } else {
            DEFAULT_MAX_STEP.min(EXACT_SENSORY_MAX_STEP)
        };
        if step_control == StepControl::Adaptive && smallest_max_step < self.step {
            return Err(invalid(
                "max_step",
                self.max_step,
                &format!("must be at least step when the step is adaptive (0, automatic, stands for {smallest_max_step} or more)"),
            ));
        }
        if step_control == StepControl::Fixed && self.step >= self.closure_tolerance {
            return Err(invalid(
                "step",
                self.step,
                "fixed steps must be shorter than closure_tolerance, or loops may step over their start",
            ));
        }
        Ok(TraceValidParams {
            method: self.method,
            step: self.step,
            step_control,
            max_step: self.max_step,
            max_turn: self.max_turn,
            closure_tolerance: self.closure_tolerance,
            min_steps: self.min_steps,
            max_steps: self.max_steps,
            max_rows: self.max_rows,
            points: self.points,
            pose_tolerance: self.pose_tolerance,
            sensor_tolerance: self.sensor_tolerance,
            max_corrector_iterations: self.max_corrector_iterations,
            finite_difference_step: self.finite_difference_step,
            jacobian: self.jacobian,
            rank_tolerance: self.rank_tolerance,
            noise: self.noise,
            components: self.components,
            piece_starts: self.piece_starts,
            piece_seed: self.piece_seed,
            piece_tolerance: self.piece_tolerance,
            cover_step: self.cover_step,
            max_cover_points: self.max_cover_points,
        })
    }
}
