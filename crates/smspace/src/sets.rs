//! Kernel sets as the stages after tracing read them: how each set's points are joined
//! ([`Closure`]) and a view of the sets with their closures and pieces ([`SetsView`]).
//! A leaf module: the tracer writes these records, the metrics read them, and neither
//! imports the other for them.
//!
//! A set `M^i` is sampled by `P` points `x_0, …, x_{P−1} ∈ ℝ^N` (an array `(M, P, N)`
//! for `M` sets). A closed set is the polyline `x_0 x_1 … x_{P−1} x_0` (`P` segments),
//! an open one `x_0 … x_{P−1}` (`P − 1` segments); a set traced in several pieces is
//! the union of its pieces' polylines, no segment joining two pieces.

use ndarray::ArrayView3;

/// How the points of a traced set are joined into a curve: a closed loop (status
/// `closed`) or an open polyline (status `open`, and the single points of `point`). The
/// `curve` metric reads the sets as these polylines; `sets.closed.npy` records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Closure {
    /// A closed loop: `P` segments, the last one from `x_{P−1}` back to `x_0`.
    Closed,
    /// An open polyline: `P − 1` segments.
    Open,
}

impl Closure {
    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Closure::Closed => "closed",
            Closure::Open => "open",
        }
    }

    /// The code stored in `sets.closed.npy`: 1 for closed, 0 for open.
    pub fn code(self) -> i64 {
        match self {
            Closure::Closed => 1,
            Closure::Open => 0,
        }
    }

    /// The closure of a code of `sets.closed.npy` (1 closed, 0 open), `None` otherwise.
    pub fn from_code(code: i64) -> Option<Self> {
        match code {
            1 => Some(Closure::Closed),
            0 => Some(Closure::Open),
            _ => None,
        }
    }
}

/// Kernel sets as the metric reads them: the points `(M, P, N)` and, for the `curve`
/// metric, how each set's points are joined ([`Closure`]).
///
/// An `ArrayView3` converts into a view without closures, so every function that takes
/// `impl Into<SetsView>` also takes the plain points.
///
/// ```
/// use smspace::metric::{distance_matrix, DistanceParams, MetricKind, Period};
/// use smspace::sets::{Closure, SetsView};
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
    pieces: Option<ndarray::ArrayView2<'a, i64>>,
}

impl<'a> SetsView<'a> {
    /// The sets `(M, P, N)` without closures (enough for the point metrics).
    pub fn new(points: ArrayView3<'a, f64>) -> Self {
        Self {
            points,
            closure: None,
            pieces: None,
        }
    }

    /// The same sets with one [`Closure`] per set (checked when the sets are prepared).
    pub fn with_closure(mut self, closure: &'a [Closure]) -> Self {
        self.closure = Some(closure);
        self
    }

    /// The same sets with the piece of every point, `(M, P)` (`sets.components.npy`):
    /// for the `curve` metric, a set is the union of its pieces, each a run of
    /// consecutive points joined as the set's closure says (no segment joins two
    /// pieces; a closed piece of a set of several ends with a copy of its first point).
    pub fn with_pieces(mut self, pieces: ndarray::ArrayView2<'a, i64>) -> Self {
        self.pieces = Some(pieces);
        self
    }

    /// The points `(M, P, N)`.
    pub fn points(&self) -> ArrayView3<'a, f64> {
        self.points
    }

    /// The pieces of the points, if given.
    pub fn pieces(&self) -> Option<ndarray::ArrayView2<'a, i64>> {
        self.pieces
    }

    /// The closures, if given.
    pub fn closure(&self) -> Option<&'a [Closure]> {
        self.closure
    }

    /// The same view with a shorter lifetime (array views are invariant in theirs).
    pub fn reborrow<'b>(self) -> SetsView<'b>
    where
        'a: 'b,
    {
        SetsView {
            points: self.points.reborrow(),
            closure: self.closure,
            pieces: self.pieces.map(|p| p.reborrow()),
        }
    }
}

impl<'a> From<ArrayView3<'a, f64>> for SetsView<'a> {
    fn from(points: ArrayView3<'a, f64>) -> Self {
        Self::new(points)
    }
}

/// The kernels a metric is asked to measure, as far as a run knows them: the largest
/// dimension `k` of a set, and how many motors the sets were extended along (each set
/// is then its traced kernel repeated at values of those motors, slices of dimension
/// `k − extended`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct KernelShape {
    /// The largest kernel dimension `k`, the extended motors included.
    pub dimension: usize,
    /// The number of motors the sets were extended along.
    pub extended: usize,
}

impl KernelShape {
    /// Kernels of dimension `k`, not extended.
    pub fn of_dimension(dimension: usize) -> Self {
        Self {
            dimension,
            extended: 0,
        }
    }
}
