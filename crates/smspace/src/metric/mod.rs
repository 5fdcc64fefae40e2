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
//! * [`distance_matrix`]: the full symmetric `(M, M)` matrix, for users;
//! * [`distance_rows`] / [`fill_rows`]: any block of rows `[i0, i1)` on its own, into a
//!   new array or a caller's buffer, so that the matrix can be spread over processes;
//! * [`knn`]: the `k` nearest sets of every set (or of a block of rows) without the
//!   matrix, in `O(M·k)` memory;
//! * [`SetMetric`]: one distance between two point sets.

pub mod curve;
mod kernel;
mod knn;
mod period;
mod prepared;
pub mod reference;

use std::ops::Range;

use ndarray::{Array2, Array3, ArrayView2, ArrayView3, ArrayViewMut2, Axis};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::progress::Progress;

pub use curve::{Closure, CURVE_TOLERANCE};
pub use kernel::simd_level;
pub use knn::{knn, knn_prepared, Knn, KnnParams, ValidKnnParams, MAX_PIVOTS};
pub use period::{CoordinatePeriods, PeriodError, Periods};
pub use prepared::PreparedSets;

/// Kernel sets as the metric reads them: the points `(M, P, N)` and, for the `curve`
/// metric, how each set's points are joined ([`Closure`]).
///
/// An `ArrayView3` converts into a view without closures, so every function that takes
/// `impl Into<SetsView>` also takes the plain points.
///
/// ```
/// use smspace::metric::{distance_matrix, Closure, DistanceParams, MetricKind, Period, SetsView};
/// use smspace::progress::Silent;
/// // Two open segments on the line y = 0 and y = 1 (no period): distance 1.
/// let sets = ndarray::array![[[0.0, 0.0], [2.0, 0.0]], [[0.0, 1.0], [2.0, 1.0]]];
/// let closure = [Closure::Open, Closure::Open];
/// let params = DistanceParams::new().metric(MetricKind::Curve).period(Period::None);
/// let d = distance_matrix(SetsView::new(sets.view()).with_closure(&closure), &params, &Silent).unwrap();
/// assert!((d[[0, 1]] - 1.0).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, Copy)]
pub struct SetsView<'a> {
    points: ArrayView3<'a, f64>,
    closure: Option<&'a [Closure]>,
}

impl<'a> SetsView<'a> {
    /// The sets `(M, P, N)` without closures (enough for the point metrics).
    pub fn new(points: ArrayView3<'a, f64>) -> Self {
        Self {
            points,
            closure: None,
        }
    }

    /// The same sets with one [`Closure`] per set (checked when the sets are prepared).
    pub fn with_closure(mut self, closure: &'a [Closure]) -> Self {
        self.closure = Some(closure);
        self
    }

    /// The points `(M, P, N)`.
    pub fn points(&self) -> ArrayView3<'a, f64> {
        self.points
    }

    /// The closures, if given.
    pub fn closure(&self) -> Option<&'a [Closure]> {
        self.closure
    }
}

impl<'a> From<ArrayView3<'a, f64>> for SetsView<'a> {
    fn from(points: ArrayView3<'a, f64>) -> Self {
        Self::new(points)
    }
}

/// Errors of the metric stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MetricError {
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
    Invalid(#[from] crate::error::InvalidParameter),
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

/// Formats a byte count as `12.3 GiB`.
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}

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

/// Which set metric to compute.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MetricKind {
    /// The symmetric Hausdorff distance `ρ` of the paper. Default.
    #[default]
    Hausdorff,
    /// The average of the two mean directed distances.
    MeanHausdorff,
    /// The Hausdorff distance between the sets read as closed or open polylines.
    Curve,
}

impl MetricKind {
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

    /// This metric as a [`SetMetric`] object under the point metric `period`. The
    /// `curve` metric reads both sets as `closure` polylines.
    pub fn with_period(self, period: Period, closure: Closure) -> Box<dyn SetMetric> {
        match self {
            MetricKind::Hausdorff => Box::new(Hausdorff { period }),
            MetricKind::MeanHausdorff => Box::new(MeanHausdorff { period }),
            MetricKind::Curve => Box::new(Curve { period, closure }),
        }
    }
}

/// A distance between two point sets, each a `(P, N)` view (one point per row).
pub trait SetMetric: Sync {
    /// Short name, as on the command line.
    fn name(&self) -> &'static str;

    /// The distance between `a` and `b`. Errors on empty sets, non-finite coordinates
    /// or different coordinate counts.
    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError>;

    /// True when the triangle inequality holds. Defaults to `false`.
    fn is_metric(&self) -> bool {
        false
    }
}

/// The paper's symmetric Hausdorff distance `ρ` under the point metric `g`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Hausdorff {
    /// Period of the coordinates.
    pub period: Period,
}

/// The mean Hausdorff distance `ρ̄` under the point metric `g`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MeanHausdorff {
    /// Period of the coordinates.
    pub period: Period,
}

/// The Hausdorff distance `ρ_c` between two sets read as polylines (see [`mod@curve`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Curve {
    /// Period of the coordinates.
    pub period: Period,
    /// How the points of both sets are joined.
    pub closure: Closure,
}

fn pair_distance(
    kind: MetricKind,
    period: Period,
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
) -> Result<f64, MetricError> {
    pair_distance_closed(kind, period, a, b, Closure::Open)
}

fn pair_distance_closed(
    kind: MetricKind,
    period: Period,
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
    fn name(&self) -> &'static str {
        MetricKind::Hausdorff.name()
    }
    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
        pair_distance(MetricKind::Hausdorff, self.period, a, b)
    }
    fn is_metric(&self) -> bool {
        true
    }
}

impl SetMetric for Curve {
    fn name(&self) -> &'static str {
        MetricKind::Curve.name()
    }
    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
        pair_distance_closed(MetricKind::Curve, self.period, a, b, self.closure)
    }
    fn is_metric(&self) -> bool {
        true
    }
}

impl SetMetric for MeanHausdorff {
    fn name(&self) -> &'static str {
        MetricKind::MeanHausdorff.name()
    }
    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
        pair_distance(MetricKind::MeanHausdorff, self.period, a, b)
    }
}

/// Parameters of the distance matrix. Unchecked; [`DistanceParams::check`] validates them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DistanceParams {
    /// Set metric. Default: [`MetricKind::Hausdorff`].
    pub metric: MetricKind,
    /// Period of the motor coordinates. Default: [`Period::TwoPi`].
    pub period: Period,
    /// Refuse to start when the output needs more bytes than this. Default: `None`
    /// (no limit; the command-line tool passes the memory available).
    pub memory_limit_bytes: Option<u64>,
}

/// Validated [`DistanceParams`].
#[derive(Debug, Clone, PartialEq)]
pub struct ValidDistanceParams(DistanceParams);

impl DistanceParams {
    /// Default parameters.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets the set metric (default Hausdorff).
    pub fn metric(mut self, metric: MetricKind) -> Self {
        self.metric = metric;
        self
    }

    /// Sets the period of the coordinates (default `2π`).
    pub fn period(mut self, period: Period) -> Self {
        self.period = period;
        self
    }

    /// Sets the memory limit in bytes (default none).
    pub fn memory_limit_bytes(mut self, limit: Option<u64>) -> Self {
        self.memory_limit_bytes = limit;
        self
    }

    /// Validates the parameters. Every combination is valid today; the call keeps the
    /// unchecked/checked pattern of the other stages.
    pub fn check(&self) -> Result<ValidDistanceParams, MetricError> {
        Ok(ValidDistanceParams(self.clone()))
    }
}

impl std::ops::Deref for ValidDistanceParams {
    type Target = DistanceParams;
    fn deref(&self) -> &DistanceParams {
        &self.0
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

/// The full symmetric distance matrix `(M, M)` of kernel sets `(M, P, N)`: zero
/// diagonal, `D[i, j] = D[j, i] = ρ(M^i, M^j)`.
///
/// Errors before any work when `M < 2`, `P` or `N` is zero, a coordinate is not
/// finite, or the matrix needs more than `params.memory_limit_bytes`.
///
/// The `curve` metric needs the sets' closures ([`SetsView::with_closure`]).
pub fn distance_matrix<'a>(
    sets: impl Into<SetsView<'a>>,
    params: &DistanceParams,
    progress: &dyn Progress,
) -> Result<Array2<f64>, MetricError> {
    let sets = sets.into();
    let m = sets.points().dim().0;
    distance_rows(sets, params, 0..m, progress)
}

/// Rows `[i0, i1)` of the distance matrix, as a `(i1 − i0, M)` array. Any split of
/// `0..M` into blocks gives, stacked, exactly [`distance_matrix`].
pub fn distance_rows<'a>(
    sets: impl Into<SetsView<'a>>,
    params: &DistanceParams,
    rows: Range<usize>,
    progress: &dyn Progress,
) -> Result<Array2<f64>, MetricError> {
    let params = params.check()?;
    let sets = closure_for(sets.into(), params.metric)?;
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
    let prepared = PreparedSets::new(sets, params.period)?;
    check_metric(&prepared, params.metric)?;
    let mut out = Array2::zeros((rows.len(), m));
    fill_rows(&prepared, params.metric, rows, out.view_mut(), progress)?;
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

/// Rows of a tile share a pass over each block of this many columns, so that the
/// block's sets stay in the core's L2 cache while every row of the tile uses them.
const TILE_COLUMNS: usize = 32;
/// Rows computed together (one parallel task).
const TILE_ROWS: usize = 32;

/// Computes a tile of rows `[row0, row0 + out.len() / m)` of the matrix, column block by
/// column block (cache blocking: each column set is read from memory once per tile
/// instead of once per row). Every entry is the same `distance(i, j)` call as without
/// tiling, so the result does not depend on the tile sizes.
struct TileDriver<'a> {
    row0: usize,
    m: usize,
    /// Columns `skip_from..=row` of a row are left alone (mirrored afterwards, or the
    /// diagonal).
    skip_from: usize,
    out: &'a mut [f64],
}

impl kernel::Driver for TileDriver<'_> {
    type Output = ();
    #[inline(always)]
    fn drive<E: kernel::Eval>(self, eval: &mut E) {
        let m = self.m;
        let rows = self.out.len() / m;
        for block in (0..m).step_by(TILE_COLUMNS) {
            let columns = block..(block + TILE_COLUMNS).min(m);
            for r in 0..rows {
                let i = self.row0 + r;
                let out = &mut self.out[r * m..(r + 1) * m];
                for j in columns.clone() {
                    if j >= self.skip_from && j <= i {
                        continue;
                    }
                    // The first row of the tile brings the block's sets from memory:
                    // start loading the one after next while this pair is computed.
                    if r == 0 && j + 2 < columns.end {
                        eval.touch(j + 2);
                    }
                    out[j] = eval.distance(i, j, f64::INFINITY).unwrap_or(f64::INFINITY);
                }
            }
        }
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
    check_metric(prepared, metric)?;
    let expected = (rows.len(), m);
    if out.dim() != expected || !out.is_standard_layout() {
        return Err(MetricError::BadBuffer {
            found: out.dim(),
            expected,
        });
    }
    fill_tiles(m, rows, out, progress, |scratch, driver| {
        kernel::dispatch(prepared, metric, scratch, driver)
    });
    Ok(())
}

/// The tiles of rows `rows` of `out` (checked: `(rows.len(), m)`, standard layout), in
/// parallel: `tile` computes one [`TileDriver`]; pairs inside the block are then
/// mirrored and the diagonal is zero.
fn fill_tiles(
    m: usize,
    rows: Range<usize>,
    mut out: ArrayViewMut2<'_, f64>,
    progress: &dyn Progress,
    tile: impl Fn(&mut kernel::Scratch, TileDriver<'_>) + Sync,
) {
    let i0 = rows.start;
    let total: u64 = rows.clone().map(|i| (m - 1 - (i - i0)) as u64).sum();
    progress.start("distances", total);
    let buffer = out
        .as_slice_mut()
        .expect("standard layout was checked by the caller");
    buffer
        .par_chunks_mut(m * TILE_ROWS)
        .enumerate()
        .for_each_init(kernel::Scratch::default, |scratch, (t, block)| {
            let row0 = i0 + t * TILE_ROWS;
            let tile_rows = block.len() / m;
            for r in 0..tile_rows {
                block[r * m + row0 + r] = 0.0;
            }
            let driver = TileDriver {
                row0,
                m,
                skip_from: i0,
                out: block,
            };
            tile(scratch, driver);
            let done: usize = (0..tile_rows).map(|r| m - 1 - (row0 + r - i0)).sum();
            progress.advance(done as u64);
        });
    for i in rows.clone() {
        for j in i0..i {
            out[[i - i0, j]] = out[[j - i0, i]];
        }
    }
    progress.finish();
}

/// The full matrix of any [`SetMetric`] (a user-defined one included), through the
/// same row tiles, threads, memory check and progress as the built-in metrics (the
/// generic path next to the SIMD kernels: each pair is one
/// [`SetMetric::distance`] call, without early exits). Identical for any thread count.
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
pub fn distance_matrix_with(
    sets: ArrayView3<'_, f64>,
    metric: &dyn SetMetric,
    params: &DistanceParams,
    progress: &dyn Progress,
) -> Result<Array2<f64>, MetricError> {
    let m = sets.dim().0;
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    prepared::check_points(sets)?;
    check_memory(params.memory_limit_bytes, m, (m as u64) * (m as u64) * 8)?;
    let mut out = Array2::zeros((m, m));
    // The error of the first failing pair in row-major order, whatever the threads.
    let failure: std::sync::Mutex<Option<((usize, usize), MetricError)>> = Default::default();
    fill_tiles(m, 0..m, out.view_mut(), progress, |_, driver| {
        let mut eval = GenericEval {
            sets: sets.view(),
            metric,
            failure: &failure,
        };
        kernel::Driver::drive(driver, &mut eval)
    });
    match failure.into_inner().unwrap_or_else(|e| e.into_inner()) {
        Some(((i, j), reason)) => Err(MetricError::Pair {
            metric: metric.name().to_owned(),
            i,
            j,
            reason: Box::new(reason),
        }),
        None => Ok(out),
    }
}

/// Evaluates a [`SetMetric`] on a pair of sets for the tile driver.
struct GenericEval<'a> {
    sets: ArrayView3<'a, f64>,
    metric: &'a dyn SetMetric,
    failure: &'a std::sync::Mutex<Option<((usize, usize), MetricError)>>,
}

impl kernel::Eval for GenericEval<'_> {
    fn distance(&mut self, i: usize, j: usize, _limit: f64) -> Option<f64> {
        let (a, b) = (
            self.sets.index_axis(Axis(0), i),
            self.sets.index_axis(Axis(0), j),
        );
        match self.metric.distance(a, b) {
            Ok(d) => Some(d),
            Err(reason) => {
                let mut failure = self.failure.lock().unwrap_or_else(|e| e.into_inner());
                if failure.as_ref().is_none_or(|(at, _)| (i, j) < *at) {
                    *failure = Some(((i, j), reason));
                }
                Some(f64::NAN)
            }
        }
    }
}
