//! Straightforward brute-force distances, the reference the fast kernels are tested and
//! benchmarked against: every `g(a, b)` of the `P × P` table, no pruning, no layout.

use ndarray::{Array2, ArrayView1, ArrayView2, ArrayView3};

use super::period::{CoordinatePeriods, Periods};
use super::{MetricKind, Period};

/// The periods of `dims` coordinates (a uniform [`Period`] or [`Periods`]); panics when
/// they were given for another coordinate count (a bug in the caller).
fn periods_of(periods: &impl CoordinatePeriods, dims: usize) -> Periods {
    periods
        .for_dims(dims)
        .expect("the reference needs one period per coordinate")
}

/// `|h(u)|` with period `t` (`+∞`: none).
fn folded(u: f64, t: f64) -> f64 {
    if !t.is_finite() {
        return u.abs();
    }
    let r = u.abs() % t;
    r.min(t - r)
}

/// `h(u)` of paper section 3.2 in magnitude: the coordinate difference `u` brought to
/// the nearest of its periodic images, `|h(u)| ≤ T/2`.
pub fn wrapped_difference(u: f64, period: Period) -> f64 {
    folded(u, period.radians())
}

/// The point metric `g(a, b) = sqrt(Σ_n h_n(a_n − b_n)²)` of paper section 3.2, every
/// coordinate with its own period (a uniform [`Period`] or [`Periods`]).
pub fn point_distance(
    a: ArrayView1<'_, f64>,
    b: ArrayView1<'_, f64>,
    periods: impl CoordinatePeriods,
) -> f64 {
    point_distance2(a, b, &periods_of(&periods, a.len())).sqrt()
}

fn point_distance2(a: ArrayView1<'_, f64>, b: ArrayView1<'_, f64>, periods: &Periods) -> f64 {
    let mut s = 0.0;
    for (k, (x, y)) in a.iter().zip(b.iter()).enumerate() {
        let w = folded(x - y, periods.radians(k));
        s += w * w;
    }
    s
}

/// Every `min_b g²(a, b)` (one per row `a`) and every `min_a g²(a, b)` (one per `b`).
fn nearest2(
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
    periods: &Periods,
) -> (Vec<f64>, Vec<f64>) {
    let mut rows = vec![f64::INFINITY; a.nrows()];
    let mut cols = vec![f64::INFINITY; b.nrows()];
    for (i, x) in a.outer_iter().enumerate() {
        for (j, y) in b.outer_iter().enumerate() {
            let d2 = point_distance2(x, y, periods);
            rows[i] = rows[i].min(d2);
            cols[j] = cols[j].min(d2);
        }
    }
    (rows, cols)
}

/// Brute-force Hausdorff distance `ρ(A, B) = max(max_a min_b g, max_b min_a g)` between
/// two sets of points (rows), under a uniform [`Period`] or [`Periods`].
pub fn hausdorff(
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
    periods: impl CoordinatePeriods,
) -> f64 {
    let (rows, cols) = nearest2(a, b, &periods_of(&periods, a.ncols()));
    let m = rows
        .iter()
        .chain(cols.iter())
        .fold(0.0_f64, |m, &x| m.max(x));
    m.sqrt()
}

/// Brute-force mean Hausdorff distance
/// `(mean_a min_b g(a, b) + mean_b min_a g(a, b)) / 2`.
pub fn mean_hausdorff(
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
    periods: impl CoordinatePeriods,
) -> f64 {
    let (rows, cols) = nearest2(a, b, &periods_of(&periods, a.ncols()));
    let mean = |v: &[f64]| v.iter().fold(0.0, |s, x| s + x.sqrt()) / v.len() as f64;
    0.5 * (mean(&rows) + mean(&cols))
}

/// Brute-force distance matrix `(M, M)` between all sets of `(M, P, N)`, single-threaded,
/// for the point metrics. The curve metric has no finite brute force: its reference is
/// [`curve_bounds`], and asking this function for it is a bug (it panics).
pub fn distance_matrix(
    sets: ArrayView3<'_, f64>,
    kind: MetricKind,
    periods: impl CoordinatePeriods,
) -> Array2<f64> {
    let m = sets.dim().0;
    let periods = periods_of(&periods, sets.dim().2);
    let mut out = Array2::zeros((m, m));
    for i in 0..m {
        for j in i + 1..m {
            let a = sets.index_axis(ndarray::Axis(0), i);
            let b = sets.index_axis(ndarray::Axis(0), j);
            let d = match kind {
                MetricKind::Hausdorff => hausdorff(a, b, &periods),
                MetricKind::MeanHausdorff => mean_hausdorff(a, b, &periods),
                MetricKind::Curve => {
                    panic!("reference::distance_matrix is for the point metrics; use curve_bounds")
                }
            };
            out[[i, j]] = d;
            out[[j, i]] = d;
        }
    }
    out
}

/// `δ(a, s)`: the periodic distance from point `a` to the segment from `start` along
/// `v` (`s(t) = start + t·v`, `t ∈ [0, 1]`), by brute force over periodic images: the
/// Euclidean distance from `a` to every translate `s + Σ_n T_n·k_n·e_n` of the segment
/// with `k_n ∈ {−1, 0, 1}` for every periodic coordinate `n` (enough when `a` and
/// `start` are wrapped and `|v_n| ≤ T_n/2`), the smallest one kept. Every coordinate
/// has its own period (a uniform [`Period`] or [`Periods`]). Independent of the fast
/// kernel's pieces; `3^N` images, meant for `N ≤ 8`.
pub fn segment_distance(
    a: ArrayView1<'_, f64>,
    start: ArrayView1<'_, f64>,
    v: ArrayView1<'_, f64>,
    periods: impl CoordinatePeriods,
) -> f64 {
    let n = a.len();
    let periods = periods_of(&periods, n);
    let t: Vec<f64> = (0..n).map(|k| periods.radians(k)).collect();
    let images: usize = t.iter().filter(|t| t.is_finite()).map(|_| 3).product();
    let len2: f64 = v.iter().map(|x| x * x).sum();
    // Bring a and start to their representatives first.
    let wrap = |x: f64, t: f64| {
        if t.is_finite() {
            x - t * (x / t).round()
        } else {
            x
        }
    };
    let mut best = f64::INFINITY;
    for code in 0..images {
        let mut rest = code;
        let mut u = vec![0.0; n];
        for k in 0..n {
            let shift = if t[k].is_finite() {
                let digit = rest % 3;
                rest /= 3;
                (digit as f64 - 1.0) * t[k]
            } else {
                0.0
            };
            u[k] = wrap(a[k], t[k]) - (wrap(start[k], t[k]) + shift);
        }
        let dot: f64 = u.iter().zip(v.iter()).map(|(x, y)| x * y).sum();
        let s = if len2 > 0.0 {
            (dot / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d2: f64 = u
            .iter()
            .zip(v.iter())
            .map(|(x, y)| (x - s * y).powi(2))
            .sum();
        best = best.min(d2);
    }
    best.sqrt()
}

/// The segments `(start, v)` of a polyline through the rows of `x`: `P` of them when
/// `closed`, `P − 1` otherwise, with `v_n = h_n(x_{i+1,n} − x_{i,n})`.
pub fn polyline_segments(
    x: ArrayView2<'_, f64>,
    closed: bool,
    periods: impl CoordinatePeriods,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let periods = periods_of(&periods, x.ncols());
    let signed = |u: f64, k: usize| {
        let t = periods.radians(k);
        if t.is_finite() {
            u - t * (u / t).round()
        } else {
            u
        }
    };
    let p = x.nrows();
    let count = if closed { p } else { p.saturating_sub(1) };
    (0..count)
        .map(|i| {
            let next = x.row((i + 1) % p);
            let start: Vec<f64> = x
                .row(i)
                .iter()
                .enumerate()
                .map(|(k, &z)| signed(z, k))
                .collect();
            let v: Vec<f64> = x
                .row(i)
                .iter()
                .zip(next.iter())
                .enumerate()
                .map(|(k, (a, b))| signed(b - a, k))
                .collect();
            (start, v)
        })
        .collect()
}

/// `d_B(a) = min_j δ(a, s_j)` over the segments of polyline `B`, by brute force.
pub fn polyline_distance(
    a: ArrayView1<'_, f64>,
    segments: &[(Vec<f64>, Vec<f64>)],
    periods: impl CoordinatePeriods,
) -> f64 {
    let periods = periods_of(&periods, a.len());
    segments
        .iter()
        .map(|(s, v)| {
            segment_distance(
                a,
                ArrayView1::from(s.as_slice()),
                ArrayView1::from(v.as_slice()),
                &periods,
            )
        })
        .fold(f64::INFINITY, f64::min)
}

/// Bounds of the curve distance `ρ_c(A, B)` between the polylines through the rows of
/// `a` and `b` by dense sampling: every segment of each polyline is cut into `pieces`
/// equal parts, the distance from every cut point to the other polyline is computed
/// exactly ([`polyline_distance`]), and the largest of them is a lower bound. Since
/// `d_B` is 1-Lipschitz along a segment, the exact value is at most that plus half the
/// longest piece: the pair `(lower, upper)` brackets `ρ_c`.
pub fn curve_bounds(
    a: ArrayView2<'_, f64>,
    a_closed: bool,
    b: ArrayView2<'_, f64>,
    b_closed: bool,
    periods: impl CoordinatePeriods,
    pieces: usize,
) -> (f64, f64) {
    let periods = periods_of(&periods, a.ncols());
    let sa = polyline_segments(a, a_closed, &periods);
    let sb = polyline_segments(b, b_closed, &periods);
    let directed = |from: &[(Vec<f64>, Vec<f64>)], to: &[(Vec<f64>, Vec<f64>)]| {
        let mut lower: f64 = 0.0;
        let mut longest: f64 = 0.0;
        for (s, v) in from {
            let length = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            longest = longest.max(length / pieces as f64);
            for step in 0..=pieces {
                let t = step as f64 / pieces as f64;
                let x: Vec<f64> = s.iter().zip(v).map(|(p, w)| p + t * w).collect();
                lower = lower.max(polyline_distance(
                    ArrayView1::from(x.as_slice()),
                    to,
                    &periods,
                ));
            }
        }
        (lower, lower + 0.5 * longest)
    };
    let (l1, u1) = directed(&sa, &sb);
    let (l2, u2) = directed(&sb, &sa);
    (l1.max(l2), u1.max(u2))
}
