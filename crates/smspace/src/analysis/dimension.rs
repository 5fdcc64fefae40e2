//! Intrinsic dimension from nearest-neighbour distances, read off a distance matrix.
//!
//! **TwoNN** (Facco, d'Errico, Rodriguez & Laio, Sci. Rep. 7, 2017). With `r₁ ≤ r₂`
//! the distances of a point to its two nearest neighbours, `μ = r₂ / r₁` follows the
//! Pareto law `F(μ) = 1 − μ^{−d}` on a `d`-manifold of locally uniform density. The
//! `μ_i` are sorted, `F_emp(μ_(i)) = i / N`, the largest `discard` fraction (default
//! 10 %) is dropped, and `d` is the least-squares slope through the origin of
//! `−ln(1 − F_emp)` against `ln μ`.
//!
//! **MLE** (Levina & Bickel, NIPS 2004). With `T_1 ≤ … ≤ T_k` the distances of `x` to
//! its `k` nearest neighbours (default `k = 20`),
//! `m̂_k(x) = [ (k − 1)⁻¹ Σ_{j<k} ln(T_k / T_j) ]⁻¹`, and the estimate is the mean of
//! `m̂_k(x)` over the points (Levina and Bickel's average).
//!
//! Points with a duplicate (a zero distance to another point) carry no scale and are
//! skipped; the number skipped is reported.

use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use super::AnalysisError;
use crate::neighbours::{nearest_neighbours, DenseDistances};

/// A dimension estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DimensionEstimate {
    /// The estimated intrinsic dimension.
    pub dimension: f64,
    /// Points that entered the estimate.
    pub points_used: usize,
    /// Points skipped (a duplicate neighbour, or all `k` neighbours equally far).
    pub points_skipped: usize,
}

/// The `k` smallest distances from each point to the other points, increasing
/// ([`nearest_neighbours`]), `(M, k)`.
fn nearest_distances(
    distances: ArrayView2<'_, f64>,
    k: usize,
) -> Result<Array2<f64>, AnalysisError> {
    Ok(nearest_neighbours(&DenseDistances::new(distances)?, k)?.distances)
}

/// TwoNN estimate; `discard` is the fraction of largest ratios dropped, in `[0, 1)`.
pub fn twonn(
    distances: ArrayView2<'_, f64>,
    discard: f64,
) -> Result<DimensionEstimate, AnalysisError> {
    twonn_sorted(nearest_distances(distances, 2)?.view(), discard)
}

/// The rows of a `(M, k)` array of each point's nearest distances, checked increasing
/// with at least `k_min` columns.
fn neighbour_rows(
    neighbours: ArrayView2<'_, f64>,
    k_min: usize,
) -> Result<ArrayView2<'_, f64>, AnalysisError> {
    if neighbours.ncols() < k_min {
        return Err(AnalysisError::NotNeighbourDistances {
            reason: format!(
                "there are {} per point, the estimate needs at least {k_min}",
                neighbours.ncols()
            ),
        });
    }
    if let Some(i) = neighbours.outer_iter().position(|r| {
        r.iter().any(|x| !x.is_finite()) || r.iter().zip(r.iter().skip(1)).any(|(a, b)| a > b)
    }) {
        return Err(AnalysisError::NotNeighbourDistances {
            reason: format!(
                "row {i}: every row must hold finite distances sorted nearest first (as knn_distances.npy)"
            ),
        });
    }
    Ok(neighbours)
}

/// TwoNN from each point's nearest distances, `(M, k)` with `k ≥ 2`, sorted nearest
/// first (e.g. `knn_distances.npy` of `smspace distances --knn K`): the same estimate
/// as [`twonn`] without the `M × M` matrix.
pub fn twonn_neighbours(
    neighbours: ArrayView2<'_, f64>,
    discard: f64,
) -> Result<DimensionEstimate, AnalysisError> {
    twonn_sorted(neighbour_rows(neighbours, 2)?, discard)
}

/// Levina–Bickel from each point's `k` nearest distances, `(M, k)` sorted nearest
/// first: the same estimate as [`mle`] with that `k`, without the matrix.
pub fn mle_neighbours(neighbours: ArrayView2<'_, f64>) -> Result<DimensionEstimate, AnalysisError> {
    let k = neighbours.ncols();
    mle_sorted(neighbour_rows(neighbours, 2)?, k)
}

/// TwoNN from nearest distances `(M, ≥ 2)`, each row increasing.
fn twonn_sorted(
    near: ArrayView2<'_, f64>,
    discard: f64,
) -> Result<DimensionEstimate, AnalysisError> {
    let n = near.nrows();
    let ratios: Vec<Option<f64>> = near
        .outer_iter()
        .map(|near| (near[0] > 0.0).then(|| near[1] / near[0]))
        .collect();
    let mut mu: Vec<f64> = ratios.iter().flatten().copied().collect();
    let skipped = n - mu.len();
    mu.sort_by(f64::total_cmp);
    let total = mu.len();
    let kept = ((total as f64) * (1.0 - discard)).floor() as usize;
    let kept = kept.min(total.saturating_sub(1));
    let (mut xy, mut xx) = (0.0, 0.0);
    for (i, &m) in mu.iter().take(kept).enumerate() {
        let x = m.ln();
        let y = -(1.0 - (i + 1) as f64 / total as f64).ln();
        xy += x * y;
        xx += x * x;
    }
    if kept < 2 || xx <= 0.0 {
        return Err(AnalysisError::Degenerate {
            what: "TwoNN",
            reason: format!(
                "{total} usable points (of {n}) with distinct neighbour ratios are too few to fit a slope"
            ),
        });
    }
    Ok(DimensionEstimate {
        dimension: xy / xx,
        points_used: kept,
        points_skipped: skipped,
    })
}

/// Levina–Bickel maximum-likelihood estimate with `k ≥ 2` neighbours (`k < M`).
pub fn mle(distances: ArrayView2<'_, f64>, k: usize) -> Result<DimensionEstimate, AnalysisError> {
    let n = distances.nrows();
    if k < 2 || k >= n {
        return Err(crate::error::InvalidParameter::new(
            "analysis",
            "mle_neighbors",
            k,
            format!("must be at least 2 and less than the number of points ({n})"),
        )
        .into());
    }
    mle_sorted(nearest_distances(distances, k)?.view(), k)
}

/// Levina–Bickel from nearest distances `(M, ≥ k)`, each row increasing.
fn mle_sorted(near: ArrayView2<'_, f64>, k: usize) -> Result<DimensionEstimate, AnalysisError> {
    let n = near.nrows();
    let local: Vec<Option<f64>> = near
        .outer_iter()
        .map(|near| {
            if near[0] <= 0.0 {
                return None;
            }
            let tk = near[k - 1];
            let sum: f64 = near.iter().take(k - 1).map(|&t| (tk / t).ln()).sum();
            (sum > 0.0).then(|| (k - 1) as f64 / sum)
        })
        .collect();
    let used: Vec<f64> = local.iter().flatten().copied().collect();
    if used.is_empty() {
        return Err(AnalysisError::Degenerate {
            what: "MLE",
            reason: format!("no point of {n} has {k} neighbours at distinct positive distances"),
        });
    }
    Ok(DimensionEstimate {
        dimension: used.iter().sum::<f64>() / used.len() as f64,
        points_used: used.len(),
        points_skipped: n - used.len(),
    })
}
