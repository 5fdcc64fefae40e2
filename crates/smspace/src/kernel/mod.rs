//! Kernel sets `M^i`: the motor configurations that give the same sensory input as an
//! explored configuration `m^i` (paper section 2.3 and appendix A).
//!
//! `M^i = { m | σ_E(m) = σ_E(m^i) }` is the kernel of `σ_E − s^i`, a set of dimension
//! `k = N − rank(J)` (`J` the Jacobian of the level set's function, see
//! [`tangent_space`]). For the paper's arm (`N = 4` hinges, a 3-D pose) it is a closed
//! curve on the motor torus; for the redundant toy a segment `m1 + m2 = x` of the
//! motor box; for the one-motor toy a single point; for a 4-link arm a surface. The
//! tracer samples points and curves, and covers kernels of dimension `k ≥ 2` densely
//! and samples them farthest first, with a covering radius per set (see `cover.rs`:
//! the module docs of the covering, the farthest-point sampling and the multi-start
//! search for the pieces of a level set, `[kernel] components`).
//!
//! ## Tracing (appendix A)
//!
//! From `m[1] = m^i`, the paper steps along the null vector `v[j]` of the Jacobian,
//! `m[j+1] = m[j] + μ ρ v[j]` with `μ = 10⁻³` and `ρ = ±1` keeping the direction
//! continuous (`v[j]·v[j−1] ≥ 0`), until `‖m[j] − m[1]‖ ≤ 10⁻²` with `j ≥ 50`. Plain
//! Euler steps drift off the set (by about `2·10⁻³` over a loop); here every step is a
//! predictor–corrector step: after the predictor, a Newton (kinematic) or chord
//! Gauss–Newton (sensory) corrector projects the point back onto the level set with
//! minimum-norm updates `m ← m − Jᵀ(JJᵀ)⁻¹ r`, so every traced point keeps the start's
//! pose to about `10⁻¹¹`.
//!
//! Two level sets can be followed ([`TraceMethod`]):
//! - `kinematic`, the paper's: `F(m)` is the observer's pose (the tangent coordinates
//!   the motors change), `J` the pose Jacobian; it needs the agent's ground truth;
//! - `sensory`: `F(m) = σ_E(m)`, `J` from finite differences of sensor readings, i.e.
//!   only what the agent can measure. In a rich environment it gives the same sets,
//!   and it is the only method for an agent without a ground truth.
//!
//! ## Sensor rows (sensory method)
//!
//! Every motor row at which the agent's sensors are read is counted per set
//! ([`SetReport::sensor_rows`], summed in [`TraceSummary::sensor_rows`]): for a
//! simulator or a robot they are the cost of tracing. With `jacobian =
//! "finite-differences"` every linearisation takes central differences, `2N + 1` rows.
//! With `jacobian = "secant"` (the default, [`JacobianMethod`]):
//! - every reading after the first is a secant pair with the one before it
//!   (`Δm`, `Δr`), and the Jacobian takes Broyden's rank-1 update
//!   `J ← J + (Δr − J Δm) Δmᵀ / |Δm|²`, so the chord corrector converges in fewer
//!   readings;
//! - a traced node, whose null vector is the tangent of the Hermite curve, is
//!   linearised exactly, by one-sided differences from the corrector's last reading
//!   there (`N` rows; error `O(h)` with `h = finite_difference_step`, a tangent off by
//!   about `10⁻⁶` rad);
//! - the projections of the multi-start seeds start from a secant update (one row)
//!   instead of differences, refreshed by one-sided differences when the residual
//!   grows or the rank is lost;
//! - the exact linearisation of every node is kept with the curve, and a resampled
//!   point's projection starts from those of its segment's two nodes interpolated
//!   linearly to it (error `O(h²)` for nodes `h` apart, where a secant update carried
//!   from the last resampled point is off by `O(h)`), then corrects with secant
//!   updates; its landing place moves along the set by its distance to the set times
//!   the Jacobian's error, far below the tolerances, and a point whose corrector fails
//!   is projected again from a secant, then an exact, linearisation;
//! - the steps are long ([`EXACT_SENSORY_MAX_STEP`] when `max_step = 0`, the default),
//!   the predictor extrapolates the cubic Hermite segment of the last two nodes and
//!   their tangents (error `O(h⁴)`, where a second-order predictor's is `O(h³)`), and
//!   the step grows by up to 4 at a time while the corrector has almost nothing to do
//!   (from the initial `step` to `max_step` in four steps);
//! - the linearisation of a node is kept and restored when a rejected adaptive step
//!   returns to it, and a reading at the point just read is reused;
//! - a traced node is accepted at `10³` times the sensor tolerance (`10⁻⁹` of the
//!   sensor scale): it only carries the Hermite curve, whose resampled points are
//!   projected to the tolerance itself.
//!
//! With either method, a seed of the search for pieces stops once it settles next to
//! a piece already found (within half `piece_tolerance` of the piece's Hermite curve,
//! its segments cut into chords of at most `0.05` rad: the chords of long steps stray
//! from the set by a few thousandths), and gives up after 8 iterations that do not
//! halve its smallest residual (see `cover.rs`). The rows of every set are reported by phase
//! ([`SetReport::sensor_row_phases`]: the start, following the pieces, the seeds of
//! the search, the resampling; single readings apart from Jacobians).
//!
//! On the paper's arm the sets agree with those of `finite-differences` within
//! `2·10⁻⁷` rad (the `curve` metric between the two sets through a start: median
//! `2·10⁻¹⁰`, largest `1.4·10⁻⁷` over 100 starts, with the short steps of
//! `max_step = 0.05`, in 3 500 sensor rows per start instead of 7 600). With the long
//! steps, the Hermite predictor and the nodes' linearisations above, a start costs
//! 1 923 sensor rows (median; mean 1 970, 90th percentile 2 456) instead of 3 551
//! (mean 3 543, 90th percentile 4 471) at `max_step = 0.05` with a second-order
//! predictor and secant-carried resampling, over 200 starts (`cargo bench -p smspace
//! --bench trace_rows`, 2 threads of an Intel Xeon with AVX-512, shared): following
//! the loop 1 311 (585 readings, 726 Jacobian rows) instead of 2 673, the
//! search 386 as before, the resampling 272 instead of 483 (readings only:
//! about 2.7 a point, no refresh). The sets stay within `7.1·10⁻⁷` rad of those of the
//! earlier steps (the `curve` metric between the two sets through each start: median
//! `1.1·10⁻⁸`, 90th percentile `5.7·10⁻⁸`; the largest distance between corresponding
//! points `2.5·10⁻⁶`, the points moving along the set with the arc length of the Hermite
//! curve), measured with `SMSPACE_BENCH_SAVE` on the earlier build and
//! `SMSPACE_BENCH_COMPARE` on this one. `max_step = 0.2` alone (second-order predictor)
//! took 2 253 rows (sets within `4.1·10⁻⁷`); growing the step up to half the
//! largest turn instead of a quarter, 1 730 rows but sets `2.2·10⁻⁶` away. On the
//! MuJoCo arm of `examples/python/mujoco_arm.py --sets 100` (12 rangefinders), 1 948
//! rows per start (median; mean 1 996, 90th percentile 2 520) instead of 3 536 (mean
//! 3 517, 90th percentile 4 405), its sets within `4.3·10⁻⁷` rad of the earlier ones.
//!
//! With [`StepControl::Adaptive`] the step grows up to `max_step` while the tangent
//! turns less than `max_turn` per step and the corrector has little to do, and shrinks
//! otherwise. Closure is detected on segments (the travelled segment passes within
//! `closure_tolerance` of an image of the start, periodic coordinates shifted by whole
//! periods), after `min_steps` steps for fixed steps and in any case only once the
//! trace has gone farther than twice the tolerance from the start. A trace that
//! reaches a bound of a bounded motor ends there; the set is then traced the other way
//! from the start too, and is an open segment (status `open`).
//!
//! ## Noisy sensors
//!
//! Readings that change between two calls at the same motors (a robot, a simulator
//! with noise, [`crate::agent::NoisyAgent`]) cannot meet a tolerance of `10⁻¹²`, nor
//! give a Jacobian by differences `10⁻⁶` rad apart. With `[kernel] sensor_sigma = "auto"`
//! (the default) every start is read twice in one batch: readings equal to within the
//! exact corrector's own tolerance are exact and the set is traced as above (one sensor
//! row more per set). Otherwise the set is the level set of the sensors' mean law,
//! `{ m | a(m) = a₀ }`, `a(m)` the intercept of a local regression of repeated readings
//! around `m` and its slope the Jacobian, with the noise's `σ` measured at the start
//! (or given) and every step, tolerance and stopping rule scaled to the uncertainty
//! `σ_pos` of a point's position (the `noisy` module's docs give the equations).
//! `σ`, `σ_pos`, `ρ`, `r` and the doubled fraction are reported per set
//! ([`SetReport::noise`]) and summarised ([`TraceSummary::noise`]); beyond a median
//! `σ_pos` of [`MAX_POSITION_UNCERTAINTY`] rad, or with most sets failed, the summary
//! warns ([`TraceSummary::warnings`]); a trace that runs back over its own path is
//! [`SetStatus::Retraced`] ([`MAX_DOUBLED`]).
//!
//! Noisy readings cost far more rows than exact ones, so the cost is said before it
//! is paid: before any set is traced, the first [`FORECAST_STARTS`] starts are probed
//! as their traces probe them (the two readings, and with noise the first
//! regression and the target; these rows count in those sets' start phase, and a
//! start found exact is not read again), timed,
//! and [`NoiseForecast`] forecasts the rows per set from the measured `σ`: one
//! regression of `r (3N + 1)` rows per point visited, `1.5 L / max_step` points
//! following a curve (`L` forecast as the diagonal of the motor space), `1.5 P`
//! resampling it and 10 per seed of the piece search, plus the start's rows; the total
//! at the agent's measured rate; and above [`LEARNED_ROUTE_ROWS`] rows per set the
//! learned route (`method = "learned"` with a `budget`). It goes to the progress
//! observer ([`Note::NoiseForecast`]) and into
//! the report ([`TraceSummary::noise_forecast`], and its warnings).
//!
//! ## Resampling
//!
//! The traced nodes with their tangents define a piecewise cubic Hermite curve. Its
//! arc length is measured on a fine subdivision (spacing `≈ 10⁻³`); `points` targets
//! equally spaced in arc length (starting at `m^i` for closed loops) are interpolated and
//! projected back onto the set with the corrector. Periodic coordinates are finally
//! wrapped into their ranges (`[-π, π)` for hinges); bounded ones are left as they are.

mod cover;
mod curve;
mod gather;
pub use gather::HOST_STACK_BYTES;
mod level_set;
mod noise;
mod noisy;
mod params;
mod pieces;
pub use params::{
    Components, JacobianMethod, StepControl, TraceMethod, TraceParams, TraceValidParams,
    DEFAULT_MAX_STEP, DEFAULT_SPATIAL_SAMPLES, EXACT_SENSORY_MAX_STEP, MAX_PIECE_STARTS,
    MAX_POINTS,
};
pub use pieces::{PieceSearch, MAX_PIECE_MISS};
pub mod spatial;
mod tracer;

use std::path::{Path, PathBuf};

use ndarray::{Array3, ArrayView2};
use serde::{Deserialize, Serialize};

use crate::agent::Workspace;
use crate::agent::{Agent, Environment};
use crate::params::InvalidParameter;
use crate::progress::{Note, Progress};
pub use crate::sets::Closure;
use curve::Scratch;
pub use noise::{
    NoiseForecast, NoiseSummary, SensorNoise, SetNoise, FORECAST_STARTS, LEARNED_ROUTE_ROWS,
    MAX_DOUBLED, MAX_POSITION_UNCERTAINTY,
};
pub use spatial::{extend_along, Spatial};
use tracer::Tracer;
pub use tracer::{tangent_space, SensoryRank, TangentSpace};

/// Errors of tracing kernel sets (failures of single sets are statuses, not errors).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum KernelError {
    /// A parameter is out of its domain (located by table and key).
    #[error(transparent)]
    Parameter(#[from] InvalidParameter),
    /// The motor array does not fit the agent.
    #[error(transparent)]
    Agent(#[from] crate::agent::AgentError),
    /// Nothing to trace.
    #[error("no motor configurations to trace (the motor array has 0 rows)")]
    NoMotors,
    /// The sensors change at a scale the tracer's linear algebra cannot hold.
    #[error("the sensors change by at most {slope:e} per unit of motor at the {starts} starts, outside 1e-150 to 1e150: the tracer squares these changes, which then overflow or vanish; scale the sensor values towards 1 (divide the agent's readings by a constant), which changes no kernel set")]
    SensorScale {
        /// The largest absolute entry of the sensory Jacobian over the starts.
        slope: f64,
        /// The starts it was read at.
        starts: usize,
    },
    /// The sensory method needs an environment.
    #[error("the sensory method needs an environment (give --env FILE or --env-seed S)")]
    MissingEnvironment,
    /// The stack of a coroutine for gathered tracing could not be reserved.
    #[error("could not reserve the {bytes}-byte stack of a set traced in lockstep ({source}); trace fewer sets at once (a Python agent's concurrent_sets)")]
    CoroutineStack {
        /// The stack's size.
        bytes: usize,
        /// Why.
        source: std::io::Error,
    },
    /// Too few sets were traced for the later stages (a distance matrix needs two).
    #[error("only {traced} of {total} sets could be traced (statuses: {by_status}); check the working space, the environment (sensory method) and the tolerances")]
    NothingTraced {
        /// Sets traced.
        traced: usize,
        /// Sets attempted.
        total: usize,
        /// Count per status.
        by_status: String,
    },
    /// Fewer sets were kept than the caller needs (the later stages need two), while
    /// others failed: the count of each status of the failed sets and what it suggests
    /// ([`TraceSummary::require`]).
    #[error("only {kept} of {total} sets were traced and kept ({needed} needed: the later stages compare pairs of sets); the {failed} that failed: {statuses}")]
    TooFewKept {
        /// Sets kept.
        kept: usize,
        /// Sets attempted.
        total: usize,
        /// Sets failed.
        failed: usize,
        /// Sets needed.
        needed: usize,
        /// Each failure status with its count and advice ([`TraceSummary::failures`]).
        statuses: String,
    },
    /// The agent has fewer motors than the pose coordinates the kinematic level set
    /// holds fixed.
    #[error("the {agent} agent has {motors} motors for {configuration} pose coordinates that the motors change: its pose Jacobian cannot have full rank {configuration}; check its ground truth's configuration_dim")]
    TooFewMotors {
        /// The agent's name.
        agent: String,
        /// Motors `N`.
        motors: usize,
        /// Pose coordinates `C` held fixed.
        configuration: usize,
    },
    /// Something needs the observer's pose and the agent has no ground truth.
    #[error("{needs} needs the observer's pose, and the {agent} agent has no ground truth; {fix}")]
    NoGroundTruth {
        /// The agent's name.
        agent: String,
        /// What needs it.
        needs: &'static str,
        /// What to do instead.
        fix: &'static str,
    },
    /// The Jacobian at a configuration is not finite.
    #[error("the Jacobian of the {method:?} level set at {motors:?} is not finite (NaN or infinite sensor or pose values)")]
    NonFiniteJacobian {
        /// The level set.
        method: TraceMethod,
        /// Where.
        motors: Vec<f64>,
    },
}

impl KernelError {
    /// The parameter this error is about, when it is one of the `[kernel]` table (or
    /// of the agent).
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            KernelError::Parameter(p) => Some(p),
            KernelError::Agent(e) => e.invalid_parameter(),
            _ => None,
        }
    }
}

/// What became of one set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SetStatus {
    /// A closed loop, traced and resampled.
    Closed,
    /// A segment ending on bounds of bounded motors at both ends, traced and resampled.
    Open,
    /// The set is a single point (kernel dimension 0: `rank(J) = N`).
    Point,
    /// Several pieces (`components = "all"`), each a closed loop or an open segment.
    Pieces,
    /// A kernel of dimension k ≥ 2, covered densely and sampled farthest first.
    Covered,
    /// The dense covering of a k-D kernel needed more than `max_cover_points` nodes,
    /// or was forecast to need many more before it started (see `cover.rs`).
    CoverBudget,
    /// The loop did not close within `max_steps`.
    NotClosed,
    /// The set read `max_rows` sensor rows before it was traced, and stopped there.
    RowBudget,
    /// The level set is not a manifold of the kernel dimension `k` where the tracer
    /// stands, so it cannot be followed there: the Jacobian `J` lost rank (its
    /// `(N − k)`-th singular value is below `rank_tolerance` times the largest: a
    /// sensor that cannot tell some pose change apart, e.g. too few lights in view or
    /// a cell that sees nothing, for the sensory method; a singular posture of the body,
    /// for the kinematic one), or the null direction of `J` turned by more than
    /// `max_turn` however short the step (two directions nearly null; or noisy
    /// readings, whose finite differences point anywhere).
    Singular,
    /// The corrector did not bring a point back onto the set within
    /// `max_corrector_iterations` (readings that do not repeat exactly, i.e. noise,
    /// never meet a tight `sensor_tolerance`).
    CorrectorFailed,
    /// The start's pose lies outside the working space (the starts and the working
    /// space disagree).
    OutsideWorkspace,
    /// The set left the region a law learned from data covers
    /// ([`Agent::covers`]); it ends there and is not kept.
    LeftData,
    /// Noisy readings: the traced curve runs back over its own path (more than
    /// [`MAX_DOUBLED`] of it pairs up with a part farther along, or it came back to
    /// the start heading the other way; see the module docs, "Noisy sensors"): the
    /// tangent's noise turned the trace round, so the set is a part of the loop gone
    /// over twice, not the loop. Not kept.
    Retraced,
}

impl SetStatus {
    /// The status's name in files and messages (`not-closed`, `singular`, …).
    pub fn name(self) -> String {
        serde_json::to_value(self)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default()
    }

    /// What a set that failed with this status suggests, and what to change; `None`
    /// for the statuses of kept sets.
    pub fn advice(self) -> Option<&'static str> {
        Some(match self {
            SetStatus::Closed
            | SetStatus::Open
            | SetStatus::Point
            | SetStatus::Pieces
            | SetStatus::Covered => return None,
            SetStatus::CoverBudget => {
                "the covering of a k-D kernel needed, or was forecast from the motor ranges and cover_step to need, more nodes than [kernel] max_cover_points: raise cover_step (or max_cover_points, at the cost of sensor calls in proportion)"
            }
            SetStatus::RowBudget => {
                "the set read [kernel] max_rows sensor rows before its trace ended: raise max_rows, or lower its cost per set (a looser closure_tolerance, a longer max_step); with noisy readings, learn the law instead (method = \"learned\" with a budget)"
            }
            SetStatus::NotClosed => {
                "the loop did not close within [kernel] max_steps: raise max_steps or closure_tolerance; with the sensory method, noisy readings make the trace wander"
            }
            SetStatus::Singular => {
                "the Jacobian lost rank or its null direction jumped: a sensor that cannot tell pose changes apart (too few lights in view, a cell that sees nothing; kernel::tangent_space gives the Jacobian's singular values at a start), a singular posture, or noisy readings (raise [kernel] finite_difference_step above the noise, or lower rank_tolerance)"
            }
            SetStatus::CorrectorFailed => {
                "points could not be brought back onto the set: noisy readings never meet a tight tolerance (loosen [kernel] sensor_tolerance or pose_tolerance, raise max_corrector_iterations)"
            }
            SetStatus::OutsideWorkspace => {
                "the starts lie outside the working space: explore in the same working space ([exploration] workspace_center and workspace_size, or --workspace) or trace without one"
            }
            SetStatus::LeftData => {
                "the sets left the region the law's data covers: record logs that cover the starts' kernels, or take starts inside the log"
            }
            SetStatus::Retraced => {
                "the noisy readings turned the trace back over its own path (where the sensors' slope is weak their null direction is poorly determined): average more readings per point (a less noisy sensor or simulator), or record a log and learn the law from it (smspace learn)"
            }
        })
    }

    /// Whether the set was traced and kept.
    pub fn is_traced(self) -> bool {
        matches!(
            self,
            SetStatus::Closed
                | SetStatus::Open
                | SetStatus::Point
                | SetStatus::Pieces
                | SetStatus::Covered
        )
    }
}

impl SetStatus {
    /// How a traced set's points are joined: loops are closed; segments between faces
    /// of the motor box and single points (their `P` equal points) are open. `None`
    /// for the statuses of sets that were not traced.
    pub fn closure(self) -> Option<Closure> {
        match self {
            SetStatus::Closed => Some(Closure::Closed),
            SetStatus::Open | SetStatus::Point | SetStatus::Pieces | SetStatus::Covered => {
                Some(Closure::Open)
            }
            _ => None,
        }
    }
}

/// Writes the closures of kernel sets as `(M,)` int64 codes (1 closed, 0 open): the
/// file `sets.closed.npy` next to `sets.npy`.
pub fn write_closure(
    path: &std::path::Path,
    closure: &[Closure],
) -> Result<(), crate::io::IoError> {
    crate::io::write_npy(path, &closure_codes(closure))
}

/// The codes of `sets.closed.npy`: 1 for a closed loop, 0 for an open polyline.
fn closure_codes(closure: &[Closure]) -> ndarray::Array1<i64> {
    closure.iter().map(|c| c.code()).collect()
}

/// Reads `sets.closed.npy` (see [`write_closure`]), checking that it holds one code,
/// 0 or 1, for each of `sets` sets.
pub fn read_closure(
    path: &std::path::Path,
    sets: usize,
) -> Result<Vec<Closure>, crate::io::IoError> {
    let codes = crate::io::read_i64(path)?;
    if codes.ndim() != 1 || codes.len() != sets {
        return Err(crate::io::IoError::Shape {
            path: path.to_path_buf(),
            found: crate::io::shape_string(codes.shape()),
            expected: format!("({sets},), one code per set of the sets file"),
        });
    }
    codes
        .iter()
        .enumerate()
        .map(|(i, &code)| {
            Closure::from_code(code).ok_or_else(|| crate::io::IoError::Invalid {
                path: path.to_path_buf(),
                what: "closed/open record",
                reason: format!(
                    "entry {i} is {code}; use 1 for a closed loop and 0 for an open polyline"
                ),
            })
        })
        .collect()
}

/// Per-set line of the trace report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetReport {
    /// Row of the motor array this set starts from.
    pub index: usize,
    /// What became of it.
    pub status: SetStatus,
    /// Predictor–corrector steps taken.
    pub steps: usize,
    /// Arc length of the set in motor space (radians; the sum over its pieces), 0
    /// when not traced and for kernels of dimension k ≥ 2 (see `covering_radius`).
    pub length: f64,
    /// Largest corrector residual over traced and resampled points (pose units for
    /// kinematic, relative sensor units for sensory).
    pub max_residual: f64,
    /// Observer's check: largest deviation of a resampled point's pose from the start's
    /// pose (largest of the tangent coordinates held fixed, |Δx|, |Δy|, |Δalpha| for the
    /// arm); `null` when the agent has no ground truth.
    pub max_pose_deviation: Option<f64>,
    /// The dimension `k = N − rank(J)` of the kernel set (0: a point, 1: a curve).
    pub dimension: usize,
    /// Pieces of the level set found (the piece through the start and those the
    /// multi-start search found; 0 when the set failed).
    #[serde(default)]
    pub pieces: usize,
    /// Pieces of the level set that are not in the sampled set: with `components =
    /// "connected"` every piece but the start's; with either, pieces found that could
    /// not be traced. More than 0 means `M^i` misses configurations with the same
    /// sensation.
    #[serde(default)]
    pub unvisited_pieces: usize,
    /// Curves and points: the seeds of the multi-start search that landed on each
    /// further piece found (not the start's), in the order found ([`PieceSearch`]).
    /// Empty when the search found none, and for kernels of dimension k ≥ 2.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub piece_landings: Vec<u32>,
    /// Kernels of dimension k ≥ 2: the covering radius of the sample, the largest
    /// distance from a node of the dense covering to its nearest sampled point
    /// (radians, torus distance; the kernel is within this plus about `cover_step`
    /// of the sample). `null` for points and curves.
    #[serde(default)]
    pub covering_radius: Option<f64>,
    /// Motor rows at which the agent's sensors were read for this set, traced or
    /// failed (the sensory method; 0 for the kinematic one, which reads poses): the
    /// rows a simulator or a robot answers for it, counted where the agent is called,
    /// whether directly or in gathered rounds. Without a ground truth it includes the
    /// rows of the rank estimate at this start.
    #[serde(default)]
    pub sensor_rows: u64,
    /// The sensor rows of [`sensor_rows`](Self::sensor_rows) by the phase of tracing
    /// that read them; `None` for the kinematic method.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_row_phases: Option<SensorRowPhases>,
    /// The sensory method on readings with noise: the noise measured at the start and
    /// what it leaves of a point's position; `None` for exact readings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<SetNoise>,
}

/// Where the sensor rows of one set went: each phase of tracing, its single readings
/// (the corrector's and the secant's, one row each) apart from its Jacobians (the
/// rows of finite differences, or of an agent's own Jacobian). The fields sum to
/// [`SetReport::sensor_rows`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SensorRowPhases {
    /// The start's own reading, and the rank estimate's rows when the rank is estimated.
    pub start: u64,
    /// Following (or covering) the pieces: corrector and secant readings.
    pub trace_readings: u64,
    /// Following (or covering) the pieces: Jacobians.
    pub trace_jacobians: u64,
    /// Projecting the seeds of the multi-start search for pieces: readings.
    pub search_readings: u64,
    /// Projecting the seeds of the multi-start search for pieces: Jacobians.
    pub search_jacobians: u64,
    /// Projecting the resampled points onto the set: readings.
    pub resample_readings: u64,
    /// Projecting the resampled points onto the set: Jacobians.
    pub resample_jacobians: u64,
}

impl SensorRowPhases {
    /// All the rows counted.
    pub fn total(&self) -> u64 {
        self.start
            + self.trace_readings
            + self.trace_jacobians
            + self.search_readings
            + self.search_jacobians
            + self.resample_readings
            + self.resample_jacobians
    }

    /// The rows of `phase`, `jacobian` ones or single readings.
    pub(crate) fn add(&mut self, phase: RowPhase, jacobian: bool, rows: u64) {
        let field = match (phase, jacobian) {
            (RowPhase::Start, _) => &mut self.start,
            (RowPhase::Trace, false) => &mut self.trace_readings,
            (RowPhase::Trace, true) => &mut self.trace_jacobians,
            (RowPhase::Search, false) => &mut self.search_readings,
            (RowPhase::Search, true) => &mut self.search_jacobians,
            (RowPhase::Resample, false) => &mut self.resample_readings,
            (RowPhase::Resample, true) => &mut self.resample_jacobians,
        };
        *field += rows;
    }
}

/// The phase of tracing a level set is in, for [`SensorRowPhases`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum RowPhase {
    /// The start's reading and the rank estimate.
    Start,
    /// Following or covering pieces.
    Trace,
    /// Projecting the multi-start seeds.
    Search,
    /// Projecting resampled points.
    Resample,
}

/// Counts of sets by status.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TraceSummary {
    /// Sets asked for.
    pub total: usize,
    /// Sets traced and kept.
    pub traced: usize,
    /// Sets that failed.
    pub failed: usize,
    /// Count for every status that occurred, by its name.
    pub by_status: std::collections::BTreeMap<String, usize>,
    /// Sets whose level set has pieces that the sampled set misses
    /// ([`SetReport::unvisited_pieces`] > 0): their `M^i` is incomplete.
    #[serde(default)]
    pub with_unvisited_pieces: usize,
    /// Traced sets of more than one piece found.
    #[serde(default)]
    pub with_several_pieces: usize,
    /// With `components = "all"`: how many seeds landed on the further pieces found,
    /// and the estimated share of such pieces the search misses ([`PieceSearch`]);
    /// `None` when it found none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub piece_search: Option<PieceSearch>,
    /// Kernels of dimension k ≥ 2: the covering radii of the traced sets (smallest,
    /// median, largest), radians.
    #[serde(default)]
    pub covering_radius: Option<[f64; 3]>,
    /// Sets traced on a law learned from a simulated log: their distance to the agent's
    /// true sets through the same starts. `None` otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth: Option<TruthErrors>,
    /// The agent's sensor rows per start ([`SetReport::sensor_rows`]), all starts
    /// counted, traced or failed; `None` when no sensor was read (the kinematic
    /// method).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_rows: Option<SensorRows>,
    /// The sensory method on readings with noise ([`SetReport::noise`]): the noise
    /// over the starts; `None` for exact readings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<NoiseSummary>,
    /// The sensory method on readings with noise: what tracing was forecast to cost
    /// before it started ([`NoiseForecast`]); `None` for exact readings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_forecast: Option<NoiseForecast>,
    /// The share of the sets traced as curves that closed
    /// ([`TraceSummary::curve_closure_rate`]); `None` when no set was a curve (kernels
    /// of dimension 0 or at least 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub closure_rate: Option<f64>,
    /// Without a ground truth: the sensory rank the starts show, and those of another.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensory_rank: Option<SensoryRank>,
}

/// Sensor rows per start: what tracing costs an agent that is slow to sense.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SensorRows {
    /// All starts together.
    pub total: u64,
    /// The median per start.
    pub median: u64,
    /// Its 90th percentile.
    pub p90: u64,
    /// The most for one start.
    pub max: u64,
}

impl SensorRows {
    /// The counts of `rows` (one per start), `None` when they are all 0.
    pub fn of(rows: &[u64]) -> Option<Self> {
        let total: u64 = rows.iter().sum();
        if total == 0 {
            return None;
        }
        let mut sorted = rows.to_vec();
        sorted.sort_unstable();
        let at = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
        Some(Self {
            total,
            median: at(0.5),
            p90: at(0.9),
            max: sorted[sorted.len() - 1],
        })
    }
}

/// The traced sets against the true sets through the same starts, by the `curve` metric
/// (each pair read as polylines; radians): what a run from a simulated log measures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthErrors {
    /// Starts traced in both.
    pub compared: usize,
    /// The median distance.
    pub median: f64,
    /// Its 90th percentile.
    pub p90: f64,
}

impl TraceSummary {
    /// The share of the sets traced as curves that closed: a loop back to its start, a
    /// segment ending on the bounds of bounded motors, or pieces,
    /// `(closed + open + pieces) / (total − point − covered − cover-budget)`; `None`
    /// when no set was traced as a curve. On a law learned from data, whose level sets
    /// wander where the data are poor, a quality figure without the truth.
    pub fn curve_closure_rate(&self) -> Option<f64> {
        let count = |status: SetStatus| self.by_status.get(&status.name()).copied().unwrap_or(0);
        let closed = count(SetStatus::Closed) + count(SetStatus::Open) + count(SetStatus::Pieces);
        let curves = self.total.saturating_sub(
            count(SetStatus::Point) + count(SetStatus::Covered) + count(SetStatus::CoverBudget),
        );
        (curves > 0).then(|| closed as f64 / curves as f64)
    }

    /// Fails with [`KernelError::TooFewKept`] when fewer than `needed` sets were kept
    /// and some failed (fewer asked for than needed, all traced, is the caller's to
    /// judge): the pipeline needs 2, `smspace trace` of `M` rows `min(2, M)`.
    pub fn require(&self, needed: usize) -> Result<(), KernelError> {
        if self.traced >= needed || self.failed == 0 {
            return Ok(());
        }
        Err(KernelError::TooFewKept {
            kept: self.traced,
            total: self.total,
            failed: self.failed,
            needed,
            statuses: self.failures(),
        })
    }

    /// The statuses of the failed sets, most frequent first, each with its count and
    /// what it suggests ([`SetStatus::advice`]): `"2431 singular (…); 69 not-closed
    /// (…)"`. Empty when no set failed.
    pub fn failures(&self) -> String {
        let mut failed: Vec<(usize, SetStatus)> = self
            .by_status
            .iter()
            .filter_map(|(name, &count)| {
                let status: SetStatus =
                    serde_json::from_value(serde_json::Value::String(name.clone())).ok()?;
                (!status.is_traced()).then_some((count, status))
            })
            .collect();
        failed.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.name().cmp(&b.1.name())));
        failed
            .iter()
            .map(|&(count, status)| {
                format!(
                    "{count} {} ({})",
                    status.name(),
                    status.advice().unwrap_or_default()
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    }

    /// What the summary says that a user must know, one sentence each: noisy readings
    /// forecast above [`LEARNED_ROUTE_ROWS`] sensor rows per set (with the forecast
    /// and the learned route recommended, [`NoiseForecast`]), sets whose level set has
    /// pieces the sampled sets miss, and sets that are single points (no redundancy).
    /// Empty when every traced set is a complete curve or covering.
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        out.extend(
            self.noise_forecast
                .as_ref()
                .and_then(NoiseForecast::warning),
        );
        if self.with_unvisited_pieces > 0 {
            out.push(format!(
                "{} of {} sets miss pieces of their level set: other motor configurations give the same sensation and are not in M^i (the multi-start search found them); the sets are incomplete, and the learned manifold can have the wrong topology. Trace with components = \"all\" (smspace trace --components all)",
                self.with_unvisited_pieces, self.total
            ));
        }
        out.extend(self.piece_search.as_ref().and_then(PieceSearch::warning));
        if let Some(noise) = &self.noise {
            let blurred = noise.position > MAX_POSITION_UNCERTAINTY;
            if blurred || (noise.sets > 0 && 2 * self.failed > self.total) {
                out.push(format!(
                    "the sensors are noisy (σ = {:.3e} sensor units, median over {} starts) and the sets traced from them are {}: a traced point's position is uncertain by {:.4} rad (median; {:.4} at most, the tracer tolerates up to {MAX_POSITION_UNCERTAINTY} rad), and {} of {} sets failed. Average more readings per point (a less noisy simulator or sensor), or record a log and learn the law from it (smspace learn, the [data] table), which averages the noise over many samples",
                    noise.sigma,
                    noise.sets,
                    if blurred { "too blurred to trust" } else { "mostly lost" },
                    noise.position,
                    noise.max_position,
                    self.failed,
                    self.total
                ));
            }
            let retraced = self.by_status.get("retraced").copied().unwrap_or(0);
            if retraced > 0 {
                out.push(format!(
                    "{retraced} of {} sets traced from noisy readings (σ = {:.3e} sensor units, position uncertainty {:.4} rad, medians) ran back over their own path: more than {:.0} % of each curve lies alongside another part of it, where the noise of the sensors' slope turned the trace round, so they are pieces of their loops gone over twice and were left out ({} sets kept). Average more readings per point (a less noisy simulator or sensor), or record a log and learn the law from it (smspace learn, the [data] table)",
                    self.total,
                    noise.sigma,
                    noise.position,
                    100.0 * MAX_DOUBLED,
                    self.traced
                ));
            }
        }
        let points = self.by_status.get("point").copied().unwrap_or(0);
        let rank = &self.sensory_rank;
        out.extend(rank.iter().filter_map(SensoryRank::disagreement_warning));
        if let (true, Some(rank)) = (points > 0 && points == self.traced, rank) {
            out.push(rank.points_warning(points, self.total));
        } else if points > 0 && points == self.traced {
            out.push(format!(
                "every traced set ({points} of {}) is a single point: the kernel dimension is k = 0 (as many pose coordinates as motors, no redundancy), so the sets carry no shape and the method learns nothing beyond the configurations themselves",
                self.total
            ));
        }
        out
    }
}

/// The trace report, written as `sets.trace.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TraceReport {
    /// Name of the agent.
    pub agent: String,
    /// Level set followed.
    pub method: TraceMethod,
    /// Step control in force.
    pub step_control: StepControl,
    /// Points per set.
    pub points: usize,
    /// Counts.
    pub summary: TraceSummary,
    /// One line per motor row, in order.
    pub sets: Vec<SetReport>,
    /// With `spatial = "compensable"`: the motors the sets were extended along
    /// ([`spatial`]), from 0. Empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extended_along: Vec<usize>,
    /// Sets traced on a law learned from a log: the law's report (held-out error,
    /// rank; [`crate::learn::LawReport`] as JSON). `None` otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub law: Option<serde_json::Value>,
    /// Sets traced on a law learned from the agent within a budget: the rows read by
    /// phase, the babbling rounds and every set's verification
    /// (`smspace::learn::budget::BudgetedSets` as JSON). `None` otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget: Option<serde_json::Value>,
}

/// The traced sets.
#[derive(Debug, Clone)]
pub struct TracedSets {
    /// `(M_kept, P, N)`: the kept sets in order of their motor rows.
    pub sets: Array3<f64>,
    /// Motor rows of the kept sets, increasing.
    pub kept: Vec<usize>,
    /// How the points of every kept set are joined (closed loops, open polylines).
    pub closure: Vec<Closure>,
    /// `(M_kept, P)`: the piece of every point (0 for sets of one piece). Each piece is
    /// a run of consecutive points; with several pieces, a closed piece ends with a
    /// copy of its first point (so that the `curve` metric reads it as a loop).
    pub pieces: ndarray::Array2<i64>,
    /// Per-set statuses, dimensions and the summary.
    pub report: TraceReport,
}

impl TracedSets {
    /// The dimension `k` of every kept set, in the order of [`sets`](Self::sets).
    pub fn dimensions(&self) -> Vec<usize> {
        let sets = &self.report.sets;
        self.kept
            .iter()
            .map(|&row| {
                sets.get(row)
                    .filter(|s| s.index == row)
                    .or_else(|| sets.iter().find(|s| s.index == row))
                    .map_or(0, |s| s.dimension)
            })
            .collect()
    }

    /// Writes the sets to `sets_path` (`(M, P, N)` float64) and, next to it (see
    /// [`crate::io::sibling`]), `<stem>.kept.npy` (`(M,)` int64 motor rows),
    /// `<stem>.closed.npy` ([`write_closure`]), `<stem>.components.npy` (`(M, P)` int64,
    /// the piece of every point) and `<stem>.trace.json` (the report). Returns the five
    /// paths. `smspace trace` and the pipeline's trace stage both write through here.
    pub fn save(&self, sets_path: &Path) -> Result<[PathBuf; 5], crate::io::IoError> {
        // All five or none (see `io::Outputs`).
        let mut outputs = crate::io::Outputs::new();
        let files = self.write_into(&mut outputs, sets_path)?;
        outputs.commit()?;
        Ok(files)
    }

    /// Stages the files of [`save`](Self::save) into `outputs`, to be renamed into place
    /// with the other files of a command or stage; returns their paths.
    pub fn write_into(
        &self,
        outputs: &mut crate::io::Outputs,
        sets_path: &Path,
    ) -> Result<[PathBuf; 5], crate::io::IoError> {
        let files = Self::files(sets_path);
        let [sets, kept, closed, components, report] = &files;
        outputs.npy(sets, &self.sets)?;
        let rows: ndarray::Array1<i64> = self.kept.iter().map(|&k| k as i64).collect();
        outputs.npy(kept, &rows)?;
        outputs.npy(closed, &closure_codes(&self.closure))?;
        outputs.npy(components, &self.pieces)?;
        outputs.json(report, &self.report)?;
        Ok(files)
    }

    /// Reads what [`TracedSets::save`] wrote, checking that the records match the sets.
    /// A missing `<stem>.components.npy` (files written before pieces) reads as one
    /// piece per set.
    pub fn load(sets_path: &Path) -> Result<Self, crate::io::IoError> {
        let [sets_file, kept_file, closed_file, components_file, report_file] =
            Self::files(sets_path);
        let sets = crate::io::read_cube(&sets_file, "(M, P, N)")?;
        let (m, p, _) = sets.dim();
        let codes = crate::io::read_i64(&kept_file)?;
        let kept = codes
            .iter()
            .map(|&k| usize::try_from(k).ok())
            .collect::<Option<Vec<usize>>>()
            .filter(|k| codes.ndim() == 1 && k.len() == m)
            .ok_or_else(|| crate::io::IoError::Shape {
                path: kept_file.clone(),
                found: crate::io::shape_string(codes.shape()),
                expected: format!("({m},) int64 motor rows ≥ 0, one per set"),
            })?;
        let pieces = read_pieces(&components_file, m, p)?;
        Ok(Self {
            closure: read_closure(&closed_file, m)?,
            sets,
            kept,
            pieces,
            report: crate::io::read_json(&report_file, "trace report")?,
        })
    }

    /// The sets file and its four companions.
    fn files(sets_path: &Path) -> [PathBuf; 5] {
        let sibling = |suffix| crate::io::sibling(sets_path, suffix);
        [
            sets_path.to_owned(),
            sibling("kept.npy"),
            sibling("closed.npy"),
            sibling("components.npy"),
            sibling("trace.json"),
        ]
    }
}

/// Reads `<stem>.components.npy`: `(M, P)` int64 piece indices `≥ 0`, each piece a run
/// of consecutive points. A missing file is one piece per set (zeros).
pub fn read_pieces(
    path: &Path,
    sets: usize,
    points: usize,
) -> Result<ndarray::Array2<i64>, crate::io::IoError> {
    if !path.exists() {
        return Ok(ndarray::Array2::zeros((sets, points)));
    }
    let codes = crate::io::read_i64(path)?;
    let shape_error = || crate::io::IoError::Shape {
        path: path.to_path_buf(),
        found: crate::io::shape_string(codes.shape()),
        expected: format!("({sets}, {points}), the piece of every point of the sets file"),
    };
    let pieces = codes
        .clone()
        .into_dimensionality::<ndarray::Ix2>()
        .map_err(|_| shape_error())?;
    if pieces.dim() != (sets, points) {
        return Err(shape_error());
    }
    for (i, row) in pieces.outer_iter().enumerate() {
        let ordered = row.iter().all(|&c| c >= 0)
            && row
                .iter()
                .zip(row.iter().skip(1))
                .all(|(a, b)| b == a || *b == a + 1)
            && row.first().is_none_or(|&c| c == 0);
        if !ordered {
            return Err(crate::io::IoError::Invalid {
                path: path.to_path_buf(),
                what: "piece record",
                reason: format!(
                    "row {i} is not 0, 0, …, 1, 1, … (pieces numbered from 0 in runs of consecutive points)"
                ),
            });
        }
    }
    Ok(pieces)
}

/// Traces and resamples the kernel set through one start `m⁰`. Returns the points
/// `(P × N, row-major)` when the set was traced, and its report line (`index` 0).
pub fn trace_one(
    agent: &dyn Agent,
    environment: Option<&Environment>,
    start: &[f64],
    workspace: Option<&Workspace>,
    params: &TraceValidParams,
) -> Result<(Option<Vec<f64>>, SetReport), KernelError> {
    crate::agent::check_motor_count(agent, start.len())?;
    let starts =
        ndarray::ArrayView2::from_shape((1, start.len()), start).expect("one row of N values");
    let tracer = Tracer::new(agent, environment, starts, workspace, params)?;
    let mut result = tracer.trace(start, None, &mut Scratch::default());
    tracer.add_rank_rows(&mut result.report, 0);
    Ok((result.points, result.report))
}

/// The closure rate of a trace ([`TraceSummary::curve_closure_rate`]) when its kernels
/// are curves; `None` for a trace of points or surfaces, whose failures are no curves.
fn closure_rate(summary: &TraceSummary, reports: &[SetReport]) -> Option<f64> {
    if reports.iter().any(|r| r.dimension == 1) {
        summary.curve_closure_rate()
    } else {
        None
    }
}

/// Traces the kernel set of every motor row, in parallel. Sets are independent and
/// deterministic, so the output is identical for any number of threads.
///
/// Rows whose set fails (see [`SetStatus`]) are left out of [`TracedSets::sets`] and
/// listed in the report; [`TracedSets::kept`] maps kept sets back to motor rows.
///
/// ```
/// use smspace::agent::AgentConfig;
/// use smspace::kernel::{trace_sets, TraceParams};
/// use smspace::progress::Silent;
/// let agent = AgentConfig::preset("toy-redundant").unwrap().build().unwrap();
/// let motors = ndarray::array![[0.5, 0.25], [-1.0, 0.5]];
/// let params = TraceParams { points: 5, ..TraceParams::default() }.check().unwrap();
/// let traced = trace_sets(agent.as_ref(), None, motors.view(), None, &params, &Silent).unwrap();
/// // Every point of the first set keeps m1 + m2 = 0.75.
/// for p in traced.sets.outer_iter().next().unwrap().outer_iter() {
///     assert!((p[0] + p[1] - 0.75).abs() < 1e-9);
/// }
/// ```
pub fn trace_sets(
    agent: &dyn Agent,
    environment: Option<&Environment>,
    motors: ArrayView2<'_, f64>,
    workspace: Option<&Workspace>,
    params: &TraceValidParams,
    progress: &dyn Progress,
) -> Result<TracedSets, KernelError> {
    let n = agent.motor_dim();
    crate::agent::check_motor_count(agent, motors.ncols())?;
    if motors.nrows() == 0 {
        return Err(KernelError::NoMotors);
    }
    let mut tracer = Tracer::new(agent, environment, motors, workspace, params)?;
    let noise_forecast = tracer.forecast_noise(motors);
    progress.note(&Note::KernelDimension {
        sets: motors.nrows() as u64,
        motors: n,
        dimension: tracer.dimension(),
        covering: (tracer.dimension() >= 2).then_some((params.cover_step, params.max_cover_points)),
    });
    if let Some(forecast) = &noise_forecast {
        progress.note(&Note::NoiseForecast(forecast.to_string()));
    }
    progress.start("trace", motors.nrows() as u64);
    let rows: Vec<Vec<f64>> = motors.outer_iter().map(|r| r.to_vec()).collect();
    let done = || progress.advance(1);
    // A first batch of one set per worker, timed, gives the estimate of the rest (the
    // sets are independent, so the split changes no result).
    let batch = rayon::current_num_threads().max(1);
    let mut results: Vec<tracer::SetResult> = Vec::with_capacity(rows.len());
    if rows.len() > 2 * batch {
        let clock = std::time::Instant::now();
        results = tracer.map_starts(
            &rows[..batch],
            |caller, scratch, start| tracer.trace(start, caller, scratch),
            &done,
        )?;
        let elapsed = clock.elapsed().as_secs_f64();
        progress.note(&Note::Estimate {
            stage: "trace".to_owned(),
            unit: "sets".to_owned(),
            done: batch as u64,
            total: rows.len() as u64,
            elapsed_seconds: elapsed,
            remaining_seconds: elapsed * (rows.len() - batch) as f64 / batch as f64,
        });
    }
    let first = results.len();
    results.extend(tracer.map_starts(
        &rows[first..],
        |caller, scratch, start| tracer.trace(start, caller, scratch),
        &done,
    )?);
    progress.finish();
    Ok(assemble(agent, params, &tracer, results, noise_forecast))
}

/// The traced sets and their report from every start's result, in the starts' order:
/// the kept sets' points, pieces and closures, and the summary over all of them.
fn assemble(
    agent: &dyn Agent,
    params: &TraceValidParams,
    tracer: &Tracer<'_>,
    results: Vec<tracer::SetResult>,
    noise_forecast: Option<NoiseForecast>,
) -> TracedSets {
    let n = agent.motor_dim();
    // The kept sets' exact sizes, so that the arrays hold no growth slack (up to as much
    // again as the sets, which the memory estimates of the later stages do not count).
    let (values, labels) = results
        .iter()
        .filter_map(|r| r.points.as_ref().map(|v| (v.len(), r.pieces.len())))
        .fold((0, 0), |(a, b), (v, q)| (a + v, b + q));
    let results = results.into_iter().enumerate().map(|(index, mut result)| {
        result.report.index = index;
        tracer.add_rank_rows(&mut result.report, index);
        result
    });
    let p = params.points;
    let mut data = Vec::with_capacity(values);
    let mut pieces = Vec::with_capacity(labels);
    let mut kept = Vec::new();
    let mut closure = Vec::new();
    let mut reports = Vec::with_capacity(results.len());
    let mut summary = TraceSummary {
        total: results.len(),
        ..TraceSummary::default()
    };
    let mut radii = Vec::new();
    let mut landings = Vec::new();
    for result in results {
        let report = result.report;
        if let Some(points) = result.points {
            data.extend_from_slice(&points);
            pieces.extend_from_slice(&result.pieces);
            kept.push(report.index);
            closure.push(report.status.closure().expect("a kept set was traced"));
            summary.with_several_pieces += usize::from(report.pieces > 1);
            radii.extend(report.covering_radius);
            landings.extend_from_slice(&report.piece_landings);
        }
        summary.with_unvisited_pieces += usize::from(report.unvisited_pieces > 0);
        let name = report.status.name();
        *summary.by_status.entry(name).or_default() += 1;
        reports.push(report);
    }
    let rows: Vec<u64> = reports.iter().map(|r| r.sensor_rows).collect();
    summary.sensor_rows = SensorRows::of(&rows);
    summary.noise = NoiseSummary::of(&reports);
    summary.noise_forecast = noise_forecast;
    radii.sort_by(f64::total_cmp);
    summary.covering_radius =
        (!radii.is_empty()).then(|| [radii[0], radii[radii.len() / 2], radii[radii.len() - 1]]);
    summary.traced = kept.len();
    if params.components() == Components::All {
        summary.piece_search = PieceSearch::of(&landings, params.piece_starts);
    }
    summary.closure_rate = closure_rate(&summary, &reports);
    summary.failed = summary.total - summary.traced;
    summary.sensory_rank = tracer.sensory_rank();
    let pieces = ndarray::Array2::from_shape_vec((kept.len(), p), pieces)
        .expect("every kept set has a piece for each of its P points");
    let sets =
        Array3::from_shape_vec((kept.len(), p, n), data).expect("every kept set has P × N values");
    TracedSets {
        sets,
        kept,
        closure,
        pieces,
        report: TraceReport {
            agent: agent.name().to_owned(),
            method: params.method,
            step_control: params.step_control,
            points: p,
            summary,
            sets: reports,
            extended_along: Vec::new(),
            law: None,
            budget: None,
        },
    }
}
