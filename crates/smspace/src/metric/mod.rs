//! The metric on kernel sets (paper section 3.2, step 3): the matrix of distances
//! between every pair of sets `M^i`, and the `k` nearest sets of every set.
//!
//! # Formulas
//!
//! Points are motor configurations `m ∈ ℝ^N`, angles in radians. Their distance wraps
//! every coordinate difference to the nearest periodic image (paper eq. for `g`, `h`):
//!
//! ```text
//! g(m, m') = sqrt( Σ_{n=1..N} h(m_n − m'_n)² ),   h(u) = u − 2π·round(u / 2π),
//! ```
//!
//! so `|h(u)| ≤ π` (the paper writes `h(u) = 2π − u` for `u > π` and `−2π − u` for
//! `u < −π`: the same up to sign, which the square removes). With
//! [`Period::None`] `h(u) = u` and `g` is Euclidean.
//!
//! Between two sets `A = M^i`, `B = M^j` of `P` points each:
//!
//! * [`MetricKind::Hausdorff`], the paper's `ρ` (section 3.2), on the sampled points:
//!   `ρ(A, B) = max( max_a min_b g(a, b), max_b min_a g(a, b) )`;
//! * [`MetricKind::Curve`], the Hausdorff distance between the sets read as closed or
//!   open **polylines** (the continuous curves the `P` points sample), exact to
//!   [`CURVE_TOLERANCE`]; definitions, algorithm and bounds in [`mod@curve`]. With `P`
//!   points per loop the point metric `ρ` sees where the samples fall as much as where
//!   the curves are (on the paper's arm the spacing along a loop is as large as the
//!   distance to the nearest set), which biases the learned manifold's dimension; `ρ_c`
//!   measures the curves;
//! * [`MetricKind::MeanHausdorff`], less sensitive to one stray point (the paper notes
//!   that any metric on the sets could serve):
//!   `ρ̄(A, B) = ½ ( mean_a min_b g(a, b) + mean_b min_a g(a, b) )`.
//!   It is symmetric and zero on equal sets, but not a metric (no triangle
//!   inequality).
//!
//! # Exact and fast
//!
//! Every value equals the brute-force `max`/`min` over the whole `P × P` table of
//! `g` (the functions in [`mod@reference`]): the fast kernels only skip work that cannot
//! change it. They combine an early-break scan (Taha & Hanbury 2015), warm starts from
//! the nearest chunk of the other set (sets are ordered closed curves), bounding boxes
//! around runs of eight consecutive points, and a structure-of-arrays layout processed
//! eight points at a time with runtime SIMD dispatch ([`PreparedSets`]; details in the
//! `kernel` source). The matrix is computed in tiles of 32 rows × 32 columns, so that
//! the sets of a column block stay in the L2 cache while every row of the tile uses
//! them (about 18 % less CPU at M = 2500, where the sets do not fit in cache). Results
//! do not depend on the number of threads or on the tiles.
//!
//! # Entry points
//!
//! * [`distance_matrix`]: the full symmetric matrix as a validated [`DistanceMatrix`],
//!   for users;
//! * [`distance_matrix_with`]: the same for any [`SetMetric`] (a user-defined one
//!   included), through the same tiles, threads, memory check and progress;
//! * [`distance_rows`] / [`fill_rows`]: any block of rows `[i0, i1)` on its own, into a
//!   new array or a caller's buffer;
//! * [`TilePlan`], [`distance_tile`] / [`fill_tile`], [`TileMerge`]: the matrix as
//!   triangular tiles, each pair computed exactly once, each tile from the sets of its
//!   rows and columns only, for spreading over processes ([`mod@tiles`]);
//! * [`knn`] / [`knn_with`]: the `k` nearest sets of every set (or of a block of rows)
//!   without the matrix, in `O(M·k)` memory;
//! * [`SetMetric`]: one distance between two point sets; [`MetricRegistry`]: metrics
//!   by name, as the `[metric]` table of an experiment picks them.
//!
//! ```
//! use smspace::metric::{distance_matrix, DistanceParams, MetricKind, Period};
//! use smspace::progress::Silent;
//! // Three sets of two points on a line (no period): ρ is the largest point shift.
//! let sets = ndarray::array![[[0.0], [1.0]], [[0.5], [1.0]], [[3.0], [4.0]]];
//! let params = DistanceParams::new().metric(MetricKind::Hausdorff).period(Period::None);
//! let d = distance_matrix(sets.view(), &params, &Silent)?;
//! assert_eq!(d[[0, 1]], 0.5);
//! assert_eq!(d[[0, 2]], 3.0);
//! assert_eq!(d[[2, 0]], d[[0, 2]]);
//! # Ok::<(), smspace::metric::MetricError>(())
//! ```

pub mod curve;
mod kernel;
mod knn;
pub mod landmarks;
mod period;
mod prepared;
pub mod reference;
mod registry;
pub mod surface;
pub mod tiles;

use std::ops::Range;

use ndarray::{Array2, Array3, ArrayView2, ArrayView3, ArrayViewMut2, Axis};
use serde::{Deserialize, Serialize};

use crate::params::{CheckParams, InvalidParameter};
use crate::progress::Progress;

pub use crate::matrix::{DistanceMatrix, MatrixError, SYMMETRY_TOLERANCE};
pub use crate::sets::{Closure, KernelShape, SetsView};
pub use curve::CURVE_TOLERANCE;
pub use kernel::{force_simd_level, simd_level, SimdLevel};
pub use knn::{knn, knn_bytes, knn_prepared, knn_with, Knn, KnnParams, KnnValidParams, MAX_PIVOTS};
pub use period::{CoordinatePeriods, PeriodError, Periodicity, Periods};
pub use prepared::PreparedSets;
pub use registry::{BuiltMetric, MetricBuilder, MetricContext, MetricRegistry};
pub use surface::{Surface, SurfaceParams};
pub use tiles::{
    distance_tile, fill_tile, load_tile, save_tile, Tile, TileMerge, TilePlan, TileRecord,
};

/// Errors of the metric stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MetricError {
    /// A distance came out NaN or infinite (coordinates so large that their squares
    /// overflow): nothing is returned or written.
    #[error("the distance between sets {i} and {j} is {value}: the sets' coordinates are too large for float64 arithmetic (their squared differences overflow); smspace never gives a non-finite distance: divide the sets by a common factor (the distances scale with it), or use a periodic motor space")]
    NonFiniteDistance {
        /// The row set.
        i: usize,
        /// The column set.
        j: usize,
        /// The value found.
        value: f64,
    },
    /// A distance backend (where the pipeline's matrix is computed, e.g. a cluster)
    /// failed or returned a wrong matrix.
    #[error("the distance backend ({backend}) failed: {reason}")]
    Backend {
        /// The backend: where it computes.
        backend: String,
        /// What went wrong, with the shapes or the backend's own error.
        reason: String,
    },
    /// A metric of one's own (registered) failed to measure a pair.
    #[error("the {metric} metric failed: {reason}")]
    Failed {
        /// The metric's name.
        metric: String,
        /// Its own error.
        reason: String,
    },
    /// Fewer than two sets: there is no pair to measure.
    #[error("need at least 2 kernel sets to compute distances, got {sets}")]
    TooFewSets {
        /// `M`.
        sets: usize,
    },
    /// Sets without points or points without coordinates.
    #[error("kernel sets have shape {shape:?}, expected (M, P, N) with P >= 1 points and N >= 1 coordinates")]
    EmptySets {
        /// `(M, P, N)`.
        shape: (usize, usize, usize),
    },
    /// A coordinate is NaN or infinite.
    #[error("kernel set {set} point {point} coordinate {coord} is {value}; every coordinate must be finite")]
    NonFinite {
        /// Set index.
        set: usize,
        /// Point index within the set.
        point: usize,
        /// Coordinate index.
        coord: usize,
        /// The value found.
        value: f64,
    },
    /// Two sets given to [`SetMetric::distance`] have different coordinate counts.
    #[error("point sets have {a} and {b} coordinates per point; they must match")]
    DimensionMismatch {
        /// Coordinates of the first set.
        a: usize,
        /// Coordinates of the second set.
        b: usize,
    },
    /// A row block outside `[0, M)` or empty.
    #[error("row block {start}:{end} is not a non-empty range within 0:{sets}")]
    BadRows {
        /// First row.
        start: usize,
        /// One past the last row.
        end: usize,
        /// `M`.
        sets: usize,
    },
    /// The output buffer does not match the row block.
    #[error("output buffer has shape {found:?}, expected {expected:?} in standard (C) layout")]
    BadBuffer {
        /// Shape given.
        found: (usize, usize),
        /// Shape expected.
        expected: (usize, usize),
    },
    /// `k` is not within `1..M`.
    #[error("k = {k} nearest sets requested, but it must be between 1 and M - 1 = {max}")]
    BadK {
        /// Requested `k`.
        k: usize,
        /// `M − 1`.
        max: usize,
    },
    /// A [`SetMetric`] failed on one pair of sets.
    #[error("the {metric} metric failed on sets {i} and {j}: {reason}")]
    Pair {
        /// The metric's name.
        metric: String,
        /// First set.
        i: usize,
        /// Second set.
        j: usize,
        /// Its error.
        reason: Box<MetricError>,
    },
    /// The `curve` metric was asked for sets whose closures are unknown.
    #[error("the curve metric needs to know which sets are closed loops and which are open polylines: the trace stage records it in sets.closed.npy next to sets.npy; for a bare .npy say it with --curve closed or --curve open")]
    MissingClosure,
    /// The closures do not match the sets.
    #[error("{found} closed/open records were given for {sets} sets; there must be one per set (sets.closed.npy has shape (M,))")]
    ClosureLength {
        /// Records given.
        found: usize,
        /// `M`.
        sets: usize,
    },
    /// Periods that do not fit the sets.
    #[error(transparent)]
    Period(#[from] PeriodError),
    /// A polyline needs two points.
    #[error("the curve metric joins the points of a set into a polyline, which needs at least 2 points per set, but the sets have P = {points}")]
    TooFewPoints {
        /// `P`.
        points: usize,
    },
    /// The curve kernels are compiled for up to 16 coordinates.
    #[error("the curve metric supports up to 16 coordinates (motors) per point, the sets have {dims}; use --metric hausdorff")]
    TooManyCoordinates {
        /// `N`.
        dims: usize,
    },
    /// A parameter is out of its range.
    #[error(transparent)]
    Invalid(#[from] crate::params::InvalidParameter),
    /// The landmark distances would not fit in the memory available.
    #[error("the distances of {sets} sets to {landmarks} landmarks need {} but only {} is available; lower scale.landmarks", human_bytes(*needed), human_bytes(*available))]
    LandmarksOutOfMemory {
        /// `M`.
        sets: usize,
        /// `L`.
        landmarks: usize,
        /// Bytes the table, the landmark matrix and the prepared sets need.
        needed: u64,
        /// Bytes available.
        available: u64,
    },
    /// The nearest-set search would not fit in the memory available.
    #[error("the {k} nearest sets of {sets} sets need {} but only {} is available; use fewer pivots (--pivots), or compute blocks of rows in turn (--rows)", human_bytes(*needed), human_bytes(*available))]
    KnnOutOfMemory {
        /// `M`.
        sets: usize,
        /// `k`.
        k: usize,
        /// Bytes the lists, the pivot table and the working data need.
        needed: u64,
        /// Bytes available.
        available: u64,
    },
    /// A [`SetMetric`] returned a value that is not a distance.
    #[error("it returned {value}; a distance must be a finite number of at least 0")]
    NotADistance {
        /// The value returned.
        value: f64,
    },
    /// The `[metric]` table names a metric that is not registered.
    #[error("unknown metric '{name}' ([metric] metric); the registered metrics are {known}")]
    UnknownMetric {
        /// The name given.
        name: String,
        /// The registered names, comma-separated.
        known: String,
    },
    /// A metric's parameter table (`[metric.params]`) does not fit the metric.
    #[error("invalid [metric.params] table for the {metric} metric: {reason}")]
    InvalidTable {
        /// The metric.
        metric: String,
        /// The reader's message, naming the key.
        reason: String,
    },
    /// The sets given for one side of a tile do not match its range.
    #[error("{found} sets were given for the tile range {start}:{end}; give exactly the sets of that range")]
    TileSets {
        /// Sets given.
        found: usize,
        /// First index of the range.
        start: usize,
        /// One past its last index.
        end: usize,
    },
    /// A tile holds a value that is not a distance.
    #[error("a tile holds {value} at [{i}, {j}]; every distance must be finite and at least 0")]
    TileValue {
        /// Row.
        i: usize,
        /// Column.
        j: usize,
        /// The value.
        value: f64,
    },
    /// Two tiles hold different values for one pair.
    #[error("two tiles disagree on the pair ({i}, {j}): {before} and {after}; were they computed from the same sets and metric?")]
    TileConflict {
        /// First set.
        i: usize,
        /// Second set.
        j: usize,
        /// The value of the earlier tile.
        before: f64,
        /// The value of the later one.
        after: f64,
    },
    /// The tiles merged leave a pair out.
    #[error("no tile holds the pair ({i}, {j}); merge the tiles of a whole plan (every block of rows against every block of columns at or after it)")]
    TileMissing {
        /// First set.
        i: usize,
        /// Second set.
        j: usize,
    },
    /// An array is not a distance matrix.
    #[error(transparent)]
    Matrix(#[from] MatrixError),
    /// The output would not fit in the memory available.
    #[error("the distance matrix of {sets} sets needs {} but only {} is available; compute the k nearest sets instead (knn, `--knn K` on the command line), or a block of rows", human_bytes(*needed), human_bytes(*available))]
    OutOfMemory {
        /// `M`.
        sets: usize,
        /// Bytes the output and working data need.
        needed: u64,
        /// Bytes available.
        available: u64,
    },
}

impl MetricError {
    /// The parameter out of its domain, located by table and key, if this is one
    /// (also inside a failing pair).
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            MetricError::Invalid(p) => Some(p),
            MetricError::Pair { reason, .. } => reason.invalid_parameter(),
            _ => None,
        }
    }
}

pub use crate::io::human_bytes;

/// Period of every motor coordinate in the point metric `g`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Period {
    /// Hinge joints: differences wrap with period `2π` (the paper's `h`). Default.
    #[default]
    #[serde(rename = "2pi")]
    TwoPi,
    /// No wrapping: plain Euclidean distance.
    #[serde(rename = "none")]
    None,
}

impl Period {
    /// The period in radians (`f64::INFINITY` for [`Period::None`]).
    pub fn radians(self) -> f64 {
        match self {
            Period::TwoPi => std::f64::consts::TAU,
            Period::None => f64::INFINITY,
        }
    }
}

/// The set metric of every door when none is named: `smspace distances` and
/// `smspace invariance` without `--metric`, `smspace.distances` and `smspace.knn`
/// without `metric=`, and a `[metric]` table without `metric` ([`DistanceParams`]'s
/// default). `curve`, the Hausdorff distance between the sets read as polylines, which
/// measures the traced curves rather than where their samples fall (see the module
/// docs); the paper's point metric is `hausdorff`.
pub const DEFAULT_METRIC: MetricKind = MetricKind::Curve;

/// Which set metric to compute. Default: [`DEFAULT_METRIC`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MetricKind {
    /// The symmetric Hausdorff distance `ρ` of the paper, between the sampled points.
    Hausdorff,
    /// The average of the two mean directed distances.
    MeanHausdorff,
    /// The Hausdorff distance between the sets read as closed or open polylines
    /// ([`DEFAULT_METRIC`]).
    Curve,
}

impl Default for MetricKind {
    /// [`DEFAULT_METRIC`].
    fn default() -> Self {
        DEFAULT_METRIC
    }
}

impl MetricKind {
    /// Every built-in metric.
    pub const ALL: [MetricKind; 3] = [
        MetricKind::Hausdorff,
        MetricKind::MeanHausdorff,
        MetricKind::Curve,
    ];

    /// The built-in metric called `name`, if there is one.
    pub fn from_name(name: &str) -> Option<MetricKind> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MetricKind::Hausdorff => "hausdorff",
            MetricKind::MeanHausdorff => "mean-hausdorff",
            MetricKind::Curve => "curve",
        }
    }

    /// True when the triangle inequality holds, which nearest-neighbour search uses to
    /// prune.
    pub fn is_metric(self) -> bool {
        matches!(self, MetricKind::Hausdorff | MetricKind::Curve)
    }

    /// Absolute error of the computed values (0 for the point metrics, which are exact
    /// up to rounding; [`CURVE_TOLERANCE`] for `curve`). Nearest-neighbour pruning
    /// widens its bounds by it.
    pub fn tolerance(self) -> f64 {
        match self {
            MetricKind::Curve => CURVE_TOLERANCE,
            _ => 0.0,
        }
    }

    /// True when the metric needs each set's [`Closure`].
    pub fn needs_closure(self) -> bool {
        matches!(self, MetricKind::Curve)
    }

    /// This metric as a [`SetMetric`] object under the point metric `period` (a
    /// uniform [`Period`] or a [`Periodicity`]). The `curve` metric reads both sets as
    /// `closure` polylines.
    pub fn with_period(
        self,
        period: impl Into<Periodicity>,
        closure: Closure,
    ) -> Box<dyn SetMetric> {
        let period = period.into();
        match self {
            MetricKind::Hausdorff => Box::new(Hausdorff { period }),
            MetricKind::MeanHausdorff => Box::new(MeanHausdorff { period }),
            MetricKind::Curve => Box::new(Curve { period, closure }),
        }
    }
}

/// A distance between two point sets, each a `(P, N)` view (one point per row, any
/// strides).
///
/// Every function that measures many pairs takes one ([`distance_matrix_with`],
/// [`knn_with`], [`fill_tile`]): a metric defined outside the crate runs through the
/// same tiles, threads, memory checks and progress as the built-in ones, and a
/// [`MetricRegistry`] gives it a name for the `[metric]` table of an experiment.
///
/// ```
/// use ndarray::ArrayView2;
/// use smspace::metric::{knn_with, DistanceParams, KnnParams, MetricError, SetMetric};
/// /// The distance between the sets' first points (a metric: the triangle inequality holds).
/// struct FirstPoints;
/// impl SetMetric for FirstPoints {
///     fn name(&self) -> &'static str { "first-points" }
///     fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
///         Ok((a[[0, 0]] - b[[0, 0]]).abs())
///     }
///     fn is_metric(&self) -> bool { true }
/// }
/// let sets = ndarray::Array3::from_shape_fn((6, 2, 1), |(i, p, _)| (i * i + p) as f64);
/// let near = knn_with(sets.view(), &FirstPoints, &DistanceParams::new(), &KnnParams::new().k(2), 0..6, &smspace::progress::Silent)?;
/// assert_eq!(near.indices.row(3).to_vec(), vec![2, 4]); // 9 is nearest to 4, then 16
/// # Ok::<(), MetricError>(())
/// ```
pub trait SetMetric: Send + Sync {
    /// Short name, as on the command line.
    fn name(&self) -> &str;

    /// The distance between `a` and `b`: finite and at least 0. Errors on empty sets,
    /// non-finite coordinates or different coordinate counts.
    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError>;

    /// True when the triangle inequality holds, which nearest-neighbour search uses to
    /// prune. Defaults to `false`.
    fn is_metric(&self) -> bool {
        false
    }

    /// Absolute error of the values (nearest-neighbour pruning widens its bounds by
    /// it). Defaults to 0.
    fn tolerance(&self) -> f64 {
        0.0
    }

    /// The built-in SIMD kernel that computes exactly this metric, if there is one: the
    /// built-in metrics return theirs, so that the functions measuring many pairs run
    /// them on the kernels. Defaults to `None`: one [`distance`](SetMetric::distance)
    /// call per pair.
    fn kernel(&self) -> Option<KernelMetric> {
        None
    }

    /// Work done once for every set before the pairs of a matrix, a block of rows or a
    /// nearest-neighbour search (per-set data such as the tangent planes of
    /// [`Surface`]): the evaluator of the pairs of `sets` `(M, P, N)` by index, or
    /// `None` (the default) for one [`distance`](SetMetric::distance) call per pair.
    /// Its values must equal `distance`'s on the same two sets.
    fn prepare(
        &self,
        sets: ArrayView3<'_, f64>,
    ) -> Result<Option<Box<dyn PreparedPairs>>, MetricError> {
        let _ = sets;
        Ok(None)
    }

    /// What the metric reads of the sets besides their points (closures, pieces), so
    /// that a caller reads those records and hands them over ([`SetsView`]). Defaults
    /// to the points alone.
    fn records(&self) -> SetRecords {
        SetRecords::default()
    }

    /// Whether the metric measures kernels of this shape: `Err` names the `[metric]`
    /// key and what to use instead. Asked before a run starts (with the dimension the
    /// agent's kernels will have) and before the matrix. Defaults to any shape.
    fn check_kernels(&self, kernels: KernelShape) -> Result<(), InvalidParameter> {
        let _ = kernels;
        Ok(())
    }

    /// Checks the sets themselves before the matrix (e.g. that sets extended along
    /// motors are recorded slice by slice), `extended_along` the motors they were
    /// extended along. Defaults to `Ok`.
    fn check_sets(&self, sets: &SetsView<'_>, extended_along: &[usize]) -> Result<(), MetricError> {
        let _ = (sets, extended_along);
        Ok(())
    }

    /// Bytes [`prepare`](SetMetric::prepare) holds for `sets` sets of `points` points of
    /// `coordinates` coordinates, for the run's memory estimate. Defaults to 0.
    fn prepared_bytes(&self, sets: usize, points: usize, coordinates: usize) -> u64 {
        let _ = (sets, points, coordinates);
        0
    }

    /// The work of the matrix of `sets` sets of `points` points of kernels of this
    /// shape, when the metric can forecast it (a run says it before a long matrix).
    /// Defaults to `None`.
    fn forecast(&self, kernels: KernelShape, sets: usize, points: usize) -> Option<WorkForecast> {
        let _ = (kernels, sets, points);
        None
    }
}

/// What a [`SetMetric`] reads of the kernel sets besides their points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SetRecords {
    /// How each set's points are joined ([`Closure`], `sets.closed.npy`).
    pub closure: bool,
    /// The piece of every point (`sets.components.npy`).
    pub pieces: bool,
}

/// The work of a distance matrix as its metric forecasts it ([`SetMetric::forecast`]).
#[derive(Debug, Clone, PartialEq)]
pub struct WorkForecast {
    /// The work in core-seconds, roughly.
    pub core_seconds: f64,
    /// What the work is, in words (e.g. "about 3.1e11 point distances").
    pub what: String,
}

/// Point distances per second and core of the point metric between surfaces sampled
/// farthest first (almost no early exits): measured on the 1288 sets of 150 points of
/// `experiments/planar-arm-5.toml` (`smspace distances --metric hausdorff`, release,
/// AVX2 path): 3.7·10¹⁰ point distances in 23.1 s of CPU, 1.6·10⁹ per core-second.
pub const SURFACE_POINT_DISTANCES_PER_CORE_SECOND: f64 = 1.6e9;

/// The forecast of a point metric between kernels of dimension `k ≥ 2` (surfaces
/// sampled by `P` points): every point against every point, almost without the early
/// exits that make loops fast, about `M (M − 1) P²` point distances. `None` for curves.
fn point_forecast(kernels: KernelShape, sets: usize, points: usize) -> Option<WorkForecast> {
    if kernels.dimension < 2 || sets < 2 {
        return None;
    }
    let work = sets as f64 * (sets as f64 - 1.0) * (points as f64).powi(2);
    Some(WorkForecast {
        core_seconds: work / SURFACE_POINT_DISTANCES_PER_CORE_SECOND,
        what: format!("the point metric compares each of their {points} points with each of the other set's, with few early exits: about {work:.1e} point distances"),
    })
}

/// The pairs of sets a [`SetMetric`] prepared ([`SetMetric::prepare`]), by set index.
pub trait PreparedPairs: Send + Sync {
    /// The distance between sets `i` and `j` of the prepared sets (called with
    /// `i < j`): finite and at least 0.
    fn distance(&self, i: usize, j: usize) -> Result<f64, MetricError>;
}

/// A built-in metric as its SIMD kernels run it ([`SetMetric::kernel`]).
#[derive(Debug, Clone, PartialEq)]
pub struct KernelMetric {
    /// The metric.
    pub kind: MetricKind,
    /// The point metric's period.
    pub period: Periodicity,
    /// For the `curve` metric, how sets given without their closures are joined (sets
    /// given with them, [`SetsView::with_closure`], keep their own).
    pub closure: Closure,
}

/// The paper's symmetric Hausdorff distance `ρ` under the point metric `g`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Hausdorff {
    /// Period of the coordinates.
    pub period: Periodicity,
}

/// The mean Hausdorff distance `ρ̄` under the point metric `g`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MeanHausdorff {
    /// Period of the coordinates.
    pub period: Periodicity,
}

/// The Hausdorff distance `ρ_c` between two sets read as polylines (see [`mod@curve`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// Period of the coordinates.
    pub period: Periodicity,
    /// How the points of both sets are joined.
    pub closure: Closure,
}

fn pair_distance(
    kind: MetricKind,
    period: &Periodicity,
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
) -> Result<f64, MetricError> {
    pair_distance_closed(kind, period, a, b, Closure::Open)
}

fn pair_distance_closed(
    kind: MetricKind,
    period: &Periodicity,
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
    closure: Closure,
) -> Result<f64, MetricError> {
    if a.ncols() != b.ncols() {
        return Err(MetricError::DimensionMismatch {
            a: a.ncols(),
            b: b.ncols(),
        });
    }
    if kind == MetricKind::Curve && a.nrows() != b.nrows() {
        // Repeating the last point adds segments of length 0, which leave the polyline
        // (as a set of points) unchanged, closed or open: pad the shorter set.
        let p = a.nrows().max(b.nrows());
        let pad = |x: ArrayView2<'_, f64>| {
            let mut out = Array2::zeros((p, x.ncols()));
            for (i, mut row) in out.outer_iter_mut().enumerate() {
                row.assign(&x.row(i.min(x.nrows().saturating_sub(1))));
            }
            out
        };
        if a.nrows() == 0 || b.nrows() == 0 {
            return Err(MetricError::EmptySets {
                shape: (2, a.nrows().min(b.nrows()), a.ncols()),
            });
        }
        return pair_distance_closed(kind, period, pad(a).view(), pad(b).view(), closure);
    }
    if a.nrows() != b.nrows() {
        // Different point counts: no shared layout, use the reference (after the checks).
        PreparedSets::new(a.insert_axis(Axis(0)), period)?;
        PreparedSets::new(b.insert_axis(Axis(0)), period)?;
        return Ok(match kind {
            MetricKind::Hausdorff => reference::hausdorff(a, b, period),
            MetricKind::MeanHausdorff => reference::mean_hausdorff(a, b, period),
            MetricKind::Curve => unreachable!("curve sets of different sizes are padded above"),
        });
    }
    let mut both = Array3::zeros((2, a.nrows(), a.ncols()));
    both.index_axis_mut(Axis(0), 0).assign(&a);
    both.index_axis_mut(Axis(0), 1).assign(&b);
    let closures = [closure; 2];
    let view = SetsView::new(both.view());
    let view = if kind.needs_closure() {
        view.with_closure(&closures)
    } else {
        view
    };
    let prepared = PreparedSets::new(view, period)?;
    check_metric(&prepared, kind)?;
    let mut scratch = kernel::Scratch::default();
    Ok(kernel::dispatch(&prepared, kind, &mut scratch, PairDriver))
}

struct PairDriver;

impl kernel::Driver for PairDriver {
    type Output = f64;
    #[inline(always)]
    fn drive<E: kernel::Eval>(self, eval: &mut E) -> f64 {
        eval.distance(0, 1, f64::INFINITY).unwrap_or(f64::INFINITY)
    }
}

impl SetMetric for Hausdorff {
    fn name(&self) -> &str {
        MetricKind::Hausdorff.name()
    }
    fn forecast(&self, kernels: KernelShape, sets: usize, points: usize) -> Option<WorkForecast> {
        point_forecast(kernels, sets, points)
    }
    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
        pair_distance(MetricKind::Hausdorff, &self.period, a, b)
    }
    fn is_metric(&self) -> bool {
        true
    }
    fn kernel(&self) -> Option<KernelMetric> {
        Some(KernelMetric {
            kind: MetricKind::Hausdorff,
            period: self.period.clone(),
            closure: Closure::Open,
        })
    }
}

impl SetMetric for Curve {
    fn name(&self) -> &str {
        MetricKind::Curve.name()
    }
    fn records(&self) -> SetRecords {
        SetRecords {
            closure: true,
            pieces: true,
        }
    }
    fn check_kernels(&self, kernels: KernelShape) -> Result<(), InvalidParameter> {
        check_polylines(kernels.dimension.saturating_sub(kernels.extended))
    }
    fn check_sets(&self, sets: &SetsView<'_>, extended_along: &[usize]) -> Result<(), MetricError> {
        check_slices(sets, extended_along).map_err(MetricError::Invalid)
    }
    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
        pair_distance_closed(MetricKind::Curve, &self.period, a, b, self.closure)
    }
    fn is_metric(&self) -> bool {
        true
    }
    fn tolerance(&self) -> f64 {
        MetricKind::Curve.tolerance()
    }
    fn kernel(&self) -> Option<KernelMetric> {
        Some(KernelMetric {
            kind: MetricKind::Curve,
            period: self.period.clone(),
            closure: self.closure,
        })
    }
}

impl SetMetric for MeanHausdorff {
    fn name(&self) -> &str {
        MetricKind::MeanHausdorff.name()
    }
    fn forecast(&self, kernels: KernelShape, sets: usize, points: usize) -> Option<WorkForecast> {
        point_forecast(kernels, sets, points)
    }
    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
        pair_distance(MetricKind::MeanHausdorff, &self.period, a, b)
    }
    fn kernel(&self) -> Option<KernelMetric> {
        Some(KernelMetric {
            kind: MetricKind::MeanHausdorff,
            period: self.period.clone(),
            closure: Closure::Open,
        })
    }
}

/// The `curve` metric reads a set as polylines (its pieces' loops and segments): it
/// does not apply to kernels of dimension `k ≥ 2`, sampled as point clouds. An error
/// on the `[metric] metric` key naming the `hausdorff` metric (the point metric, whose
/// value between two sampled kernels is within their covering radii of the value
/// between the kernels themselves) when `dimension ≥ 2`.
fn check_polylines(dimension: usize) -> Result<(), InvalidParameter> {
    if dimension < 2 {
        return Ok(());
    }
    Err(InvalidParameter::new(
        "metric",
        "metric",
        "curve",
        format!(
            "the kernel sets have dimension k = {dimension}: they are point samples of surfaces, not polylines, so the curve metric does not apply; use metric = \"hausdorff\" (between the sampled points, within the covering radii of the distance between the kernels, see sets.trace.json)"
        ),
    ))
}

/// Checks that sets extended along motors are recorded as slices, as the `curve`
/// metric reads them: every piece lies in one slice (its coordinate along every
/// extended motor is constant); sets traced before slices were pieces fail.
fn check_slices(sets: &SetsView<'_>, extended_along: &[usize]) -> Result<(), InvalidParameter> {
    let (Some(pieces), points) = (sets.pieces(), sets.points()) else {
        return Ok(());
    };
    let (m, p, n) = points.dim();
    for &j in extended_along.iter().filter(|&&j| j < n) {
        for s in 0..m {
            let mixed = (1..p).any(|q| {
                pieces[[s, q]] == pieces[[s, q - 1]] && points[[s, q, j]] != points[[s, q - 1, j]]
            });
            if mixed {
                return Err(InvalidParameter::new(
                    "metric",
                    "metric",
                    "curve",
                    format!(
                        "set {s} was extended along motor {j} but a piece of it spans several values of that motor (sets written before each slice was its own piece): trace again (smspace run --force trace) or use metric = \"hausdorff\""
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The name of a set metric in a `[metric]` table: a built-in one ([`MetricKind`]) or
/// one registered in a [`MetricRegistry`]. Written as the bare name.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct MetricName(String);

impl MetricName {
    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The built-in metric of this name, if it is one.
    pub(crate) fn kind(&self) -> Option<MetricKind> {
        MetricKind::from_name(&self.0)
    }
}

impl Default for MetricName {
    /// [`DEFAULT_METRIC`].
    fn default() -> Self {
        DEFAULT_METRIC.into()
    }
}

impl From<MetricKind> for MetricName {
    fn from(kind: MetricKind) -> Self {
        Self(kind.name().to_owned())
    }
}

impl From<&str> for MetricName {
    fn from(name: &str) -> Self {
        Self(name.to_owned())
    }
}

impl std::fmt::Display for MetricName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// Parameters of the distance matrix: the `[metric]` table of an experiment.
/// Unchecked; [`DistanceParams::check`] validates them for the built-in metrics,
/// [`MetricRegistry::build`] for any registered one.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DistanceParams {
    /// Set metric, by name: `hausdorff`, `mean-hausdorff`, `curve` ([`MetricKind`]),
    /// or a registered one. Default: `curve` ([`DEFAULT_METRIC`]).
    pub metric: MetricName,
    /// Period of the motor coordinates: `"2pi"`, `"none"`, one entry per motor, or
    /// `"motors"` (the agent's own, resolved by the pipeline). Default: `"2pi"`
    /// ([`Period::TwoPi`]).
    pub period: Periodicity,
    /// Refuse to start when the output needs more bytes than this. Default: `None`
    /// (no limit; the command-line tool passes the memory available).
    pub memory_limit_bytes: Option<u64>,
    /// The metric's own parameters (`[metric.params]`), for registered metrics that
    /// have some; the built-in ones have none. Default: empty.
    #[serde(skip_serializing_if = "toml::Table::is_empty")]
    pub params: toml::Table,
}

/// Checked [`DistanceParams`] of a built-in metric: the only form the built-in
/// matrix and kNN functions run.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceValidParams {
    kind: MetricKind,
    period: Periodicity,
    memory_limit_bytes: Option<u64>,
}

impl DistanceParams {
    /// Default parameters.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets the set metric (default [`DEFAULT_METRIC`], `curve`): a [`MetricKind`] or a
    /// registered name.
    pub fn metric(mut self, metric: impl Into<MetricName>) -> Self {
        self.metric = metric.into();
        self
    }

    /// Sets the period of the coordinates (default `2π`): a uniform [`Period`] or a
    /// [`Periodicity`].
    pub fn period(mut self, period: impl Into<Periodicity>) -> Self {
        self.period = period.into();
        self
    }

    /// Sets the memory limit in bytes (default none).
    pub fn memory_limit_bytes(mut self, limit: Option<u64>) -> Self {
        self.memory_limit_bytes = limit;
        self
    }

    /// Validates the parameters of a built-in metric: the name must be one of
    /// [`MetricKind`]'s (a registered metric is built by [`MetricRegistry::build`] and
    /// run with [`distance_matrix_with`]) and `params` empty.
    pub fn check(&self) -> Result<DistanceValidParams, MetricError> {
        let Some(kind) = self.metric.kind() else {
            return Err(MetricError::UnknownMetric {
                name: self.metric.to_string(),
                known: MetricKind::ALL.map(MetricKind::name).join(", ")
                    + " (register others in a MetricRegistry and run them with distance_matrix_with)",
            });
        };
        if let Some(key) = self.params.keys().next() {
            return Err(InvalidParameter::new(
                "metric",
                "params",
                format!("{{ {key} = … }}"),
                format!("the {} metric has no parameters", kind.name()),
            )
            .into());
        }
        Ok(DistanceValidParams {
            kind,
            period: self.period.clone(),
            memory_limit_bytes: self.memory_limit_bytes,
        })
    }
}

impl CheckParams for DistanceParams {
    type Valid = DistanceValidParams;
    type Error = MetricError;
    fn check_params(&self) -> Result<DistanceValidParams, MetricError> {
        self.check()
    }
}

impl DistanceValidParams {
    /// The metric.
    pub fn kind(&self) -> MetricKind {
        self.kind
    }

    /// The point metric's period.
    pub fn period(&self) -> &Periodicity {
        &self.period
    }

    /// The memory limit in bytes, if any.
    pub fn memory_limit_bytes(&self) -> Option<u64> {
        self.memory_limit_bytes
    }

    /// The metric as a [`SetMetric`] (for [`fill_tile`], [`distance_matrix_with`],
    /// [`knn_with`]); `curve` sets given without their closures are read as closed
    /// loops.
    pub fn set_metric(&self) -> Box<dyn SetMetric> {
        self.kind.with_period(&self.period, Closure::Closed)
    }
}

/// Bytes needed to compute rows `rows` of the matrix of `sets` sets of `points` points
/// with `dims` coordinates: the `(rows, M)` output plus the prepared layout (with the
/// segments of the `curve` metric).
pub fn matrix_bytes(sets: usize, points: usize, dims: usize, rows: usize) -> u64 {
    (rows as u64) * (sets as u64) * 8 + PreparedSets::estimate_bytes_with_curves(sets, points, dims)
}

fn check_rows(rows: &Range<usize>, sets: usize) -> Result<(), MetricError> {
    if rows.start >= rows.end || rows.end > sets {
        return Err(MetricError::BadRows {
            start: rows.start,
            end: rows.end,
            sets,
        });
    }
    Ok(())
}

/// Checks that `prepared` can be measured with `metric`: the `curve` metric needs the
/// closures and at most 16 coordinates.
pub(crate) fn check_metric(prepared: &PreparedSets, metric: MetricKind) -> Result<(), MetricError> {
    if metric.needs_closure() {
        if !prepared.has_closure() {
            return Err(MetricError::MissingClosure);
        }
        if prepared.dims() > 16 {
            return Err(MetricError::TooManyCoordinates {
                dims: prepared.dims(),
            });
        }
    }
    Ok(())
}

fn check_memory(limit: Option<u64>, sets: usize, needed: u64) -> Result<(), MetricError> {
    match limit {
        Some(available) if needed > available => Err(MetricError::OutOfMemory {
            sets,
            needed,
            available,
        }),
        _ => Ok(()),
    }
}

/// The full symmetric distance matrix `(M, M)` of kernel sets `(M, P, N)` (any
/// strides) under a built-in metric: zero diagonal, `D[i, j] = D[j, i] = ρ(M^i, M^j)`.
///
/// Errors before any work when `M < 2`, `P` or `N` is zero, a coordinate is not
/// finite, the metric is not built in, or the matrix needs more than
/// `params.memory_limit_bytes`.
///
/// The `curve` metric needs the sets' closures ([`SetsView::with_closure`]).
pub fn distance_matrix<'a>(
    sets: impl Into<SetsView<'a>>,
    params: &DistanceParams,
    progress: &dyn Progress,
) -> Result<DistanceMatrix, MetricError> {
    let sets = sets.into();
    let m = sets.points().dim().0;
    let values = distance_rows(sets, params, 0..m, progress)?;
    Ok(DistanceMatrix::from_symmetric(values))
}

/// Rows `[i0, i1)` of the distance matrix, as a `(i1 − i0, M)` array: the tile
/// `(i0..i1, 0..M)` ([`mod@tiles`]). Any split of `0..M` into blocks gives, stacked,
/// exactly [`distance_matrix`] (the pairs across blocks are computed in both; a
/// [`TilePlan`] computes each pair once).
pub fn distance_rows<'a>(
    sets: impl Into<SetsView<'a>>,
    params: &DistanceParams,
    rows: Range<usize>,
    progress: &dyn Progress,
) -> Result<Array2<f64>, MetricError> {
    let params = params.check()?;
    let sets = closure_for(sets.into(), params.kind)?;
    let (m, p, n) = sets.points().dim();
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    check_rows(&rows, m)?;
    check_memory(
        params.memory_limit_bytes,
        m,
        matrix_bytes(m, p, n, rows.len()),
    )?;
    let measure = tiles::Measure::kernel(sets, params.kind, &params.period)?;
    let mut out = Array2::zeros((rows.len(), m));
    let row0 = rows.start;
    let layout = tiles::Layout::within(Tile::new(rows, 0..m));
    tiles::fill(measure, &layout, out.view_mut(), progress)?;
    check_finite_distances(out.view(), row0, 0)?;
    Ok(out)
}

/// The view to prepare for `metric`: closures dropped when the metric does not read
/// them (no segment layout to build), required when it does.
pub(crate) fn closure_for(
    sets: SetsView<'_>,
    metric: MetricKind,
) -> Result<SetsView<'_>, MetricError> {
    if metric.needs_closure() {
        if sets.closure().is_none() {
            return Err(MetricError::MissingClosure);
        }
        Ok(sets)
    } else {
        Ok(SetsView::new(sets.points()))
    }
}

/// Fills `out` (shape `(i1 − i0, M)`, standard layout) with rows `rows = [i0, i1)` of the
/// distance matrix of `prepared` under `metric`, in parallel on rayon's current pool.
///
/// Pairs with both sets inside the block are computed once and mirrored. `progress`
/// sees one stage, "distances", counted in pairs.
pub fn fill_rows(
    prepared: &PreparedSets,
    metric: MetricKind,
    rows: Range<usize>,
    out: ArrayViewMut2<'_, f64>,
    progress: &dyn Progress,
) -> Result<(), MetricError> {
    let m = prepared.len();
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    check_rows(&rows, m)?;
    let measure = tiles::Measure::prepared(prepared, metric)?;
    let tile = Tile::new(rows, 0..m);
    tiles::check_buffer(&out, &tile)?;
    tiles::fill(measure, &tiles::Layout::within(tile), out, progress)
}

/// The full matrix of any [`SetMetric`] (a user-defined one included), through the
/// same tiles, threads, memory check and progress as the built-in metrics: a metric
/// with a [`kernel`](SetMetric::kernel) (the built-in ones) runs on it, any other one
/// [`SetMetric::distance`] call per pair, without early exits. Identical for any
/// thread count. Of `params` only the memory limit is read.
///
/// A failing pair is reported (the first in row-major order, whatever the threads),
/// and so is a value that is not a distance (negative or not finite).
///
/// ```
/// use ndarray::{Array3, ArrayView2};
/// use smspace::metric::{distance_matrix_with, DistanceParams, MetricError, SetMetric};
///
/// /// The distance between the sets' first points.
/// struct FirstPoints;
/// impl SetMetric for FirstPoints {
///     fn name(&self) -> &'static str { "first-points" }
///     fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
///         Ok((a[[0, 0]] - b[[0, 0]]).abs())
///     }
/// }
/// let sets = Array3::from_shape_fn((3, 2, 1), |(i, p, _)| (i * 10 + p) as f64);
/// let d = distance_matrix_with(sets.view(), &FirstPoints, &DistanceParams::new(), &smspace::progress::Silent)?;
/// assert_eq!(d[[0, 2]], 20.0);
/// # Ok::<(), MetricError>(())
/// ```
pub fn distance_matrix_with<'a>(
    sets: impl Into<SetsView<'a>>,
    metric: &dyn SetMetric,
    params: &DistanceParams,
    progress: &dyn Progress,
) -> Result<DistanceMatrix, MetricError> {
    let sets: SetsView<'a> = sets.into();
    let sets = sets.reborrow();
    let (m, p, n) = sets.points().dim();
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    let needed = match metric.kernel() {
        Some(_) => matrix_bytes(m, p, n, m),
        None => (m as u64) * (m as u64) * 8,
    };
    check_memory(params.memory_limit_bytes, m, needed)?;
    let measure = tiles::Measure::new(sets, metric)?;
    let mut out = Array2::zeros((m, m));
    let layout = tiles::Layout::within(Tile::new(0..m, 0..m));
    tiles::fill(measure, &layout, out.view_mut(), progress)?;
    check_finite_distances(out.view(), 0, 0)?;
    Ok(DistanceMatrix::from_symmetric(out))
}

/// Refuses a block of distances (rows from `row0`, columns from `column0`) holding NaN
/// or an infinity ([`MetricError::NonFiniteDistance`], naming the first).
pub(crate) fn check_finite_distances(
    block: ndarray::ArrayView2<'_, f64>,
    row0: usize,
    column0: usize,
) -> Result<(), MetricError> {
    match block.indexed_iter().find(|(_, v)| !v.is_finite()) {
        Some(((i, j), &value)) => Err(MetricError::NonFiniteDistance {
            i: row0 + i,
            j: column0 + j,
            value,
        }),
        None => Ok(()),
    }
}
