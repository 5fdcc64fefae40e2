//! Straightforward brute-force distances, the reference the fast kernels are tested and
//! benchmarked against: every `g(a, b)` of the `P × P` table, no pruning, no layout.

use ndarray::{Array2, ArrayView1, ArrayView2, ArrayView3};

use super::{MetricKind, Period};

/// `h(u)` of paper section 3.2 in magnitude: the coordinate difference `u` brought to
/// the nearest of its periodic images, `|h(u)| ≤ T/2`.
pub fn wrapped_difference(u: f64, period: Period) -> f64 {
    let t = period.radians();
    if !t.is_finite() {
        return u.abs();
    }
    let r = u.abs() % t;
    r.min(t - r)
}

/// The point metric `g(a, b) = sqrt(Σ_n h(a_n − b_n)²)` of paper section 3.2.
pub fn point_distance(a: ArrayView1<'_, f64>, b: ArrayView1<'_, f64>, period: Period) -> f64 {
    point_distance2(a, b, period).sqrt()
}

fn point_distance2(a: ArrayView1<'_, f64>, b: ArrayView1<'_, f64>, period: Period) -> f64 {
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b.iter()) {
        let w = wrapped_difference(x - y, period);
        s += w * w;
    }
    s
}

/// Every `min_b g²(a, b)` (one per row `a`) and every `min_a g²(a, b)` (one per `b`).
fn nearest2(
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
    period: Period,
) -> (Vec<f64>, Vec<f64>) {
    let mut rows = vec![f64::INFINITY; a.nrows()];
    let mut cols = vec![f64::INFINITY; b.nrows()];
    for (i, x) in a.outer_iter().enumerate() {
        for (j, y) in b.outer_iter().enumerate() {
            let d2 = point_distance2(x, y, period);
            rows[i] = rows[i].min(d2);
            cols[j] = cols[j].min(d2);
        }
    }
    (rows, cols)
}

/// Brute-force Hausdorff distance `ρ(A, B) = max(max_a min_b g, max_b min_a g)` between
/// two sets of points (rows).
pub fn hausdorff(a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>, period: Period) -> f64 {
    let (rows, cols) = nearest2(a, b, period);
    let m = rows
        .iter()
        .chain(cols.iter())
        .fold(0.0_f64, |m, &x| m.max(x));
    m.sqrt()
}

/// Brute-force mean Hausdorff distance
/// `(mean_a min_b g(a, b) + mean_b min_a g(a, b)) / 2`.
pub fn mean_hausdorff(a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>, period: Period) -> f64 {
    let (rows, cols) = nearest2(a, b, period);
    let mean = |v: &[f64]| v.iter().fold(0.0, |s, x| s + x.sqrt()) / v.len() as f64;
    0.5 * (mean(&rows) + mean(&cols))
}

/// Brute-force distance matrix `(M, M)` between all sets of `(M, P, N)`, single-threaded.
pub fn distance_matrix(sets: ArrayView3<'_, f64>, kind: MetricKind, period: Period) -> Array2<f64> {
    let m = sets.dim().0;
    let mut out = Array2::zeros((m, m));
    for i in 0..m {
        for j in i + 1..m {
            let a = sets.index_axis(ndarray::Axis(0), i);
            let b = sets.index_axis(ndarray::Axis(0), j);
            let d = match kind {
                MetricKind::Hausdorff => hausdorff(a, b, period),
                MetricKind::MeanHausdorff => mean_hausdorff(a, b, period),
            };
            out[[i, j]] = d;
            out[[j, i]] = d;
        }
    }
    out
}
