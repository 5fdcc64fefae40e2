//! Quality of an embedding `Y` against its input distances `X`.
//!
//! * Trustworthiness and continuity at `k` (Venna & Kaski 2001, 2006; computed by
//!   [`crate::neighbours`], valid for `1 ≤ k ≤ M/2`). With `r(i, j)` the
//!   rank of `j` among the neighbours of `i` by input distance and `r̂(i, j)` by output
//!   distance, `U_k(i)` the points among the `k` nearest of `i` in the output but not in
//!   the input, and `V_k(i)` the converse,
//!   `T(k) = 1 − 2/(M k (2M − 3k − 1)) Σ_i Σ_{j∈U_k(i)} (r(i, j) − k)` and
//!   `C(k) = 1 − 2/(M k (2M − 3k − 1)) Σ_i Σ_{j∈V_k(i)} (r̂(i, j) − k)`.
//!   Both are 1 when the `k`-neighbourhoods agree; `T` penalises false neighbours
//!   (tears hidden by folds), `C` missing ones (tears). Ties are broken by index.
//! * Kruskal's stress-1 `√(Σ_{i<j} (X_ij − Y_ij)² / Σ_{i<j} X_ij²)`, and the raw stress
//!   `½ Σ_{i≠j} (X_ij − Y_ij)²`.
//! * A Shepard (`dy–dx`) sample: pairs `(X_ij, Y_ij)` for a seeded random subset of the
//!   pairs `i < j`, the data of the CCA diagnostic plot (Demartines & Hérault 1997, fig. 3):
//!   a CCA embedding keeps `dy ≈ dx` for small `dy` and lets large distances stretch.

use ndarray::{Array2, ArrayView2};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::EmbedError;
use crate::neighbours::{self, Coordinates, DenseDistances};

/// Quality measures of an embedding.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quality {
    /// Neighbourhood size of trustworthiness and continuity.
    pub k: usize,
    /// Trustworthiness `T(k)`, in `[0, 1]`.
    pub trustworthiness: f64,
    /// Continuity `C(k)`, in `[0, 1]`.
    pub continuity: f64,
    /// Kruskal's stress-1 (0 for a perfect embedding).
    pub kruskal_stress: f64,
    /// Raw stress `½ Σ_{i≠j} (X_ij − Y_ij)²`.
    pub raw_stress: f64,
}

/// Euclidean distance between rows `i` and `j` of `y`.
fn out_distance(y: ArrayView2<'_, f64>, i: usize, j: usize) -> f64 {
    Coordinates(y).distance(i, j)
}

fn check_shapes(x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> Result<(), EmbedError> {
    if x.nrows() != x.ncols() || x.nrows() != y.nrows() {
        return Err(crate::params::InvalidParameter::new(
            "embedding",
            "coordinates",
            format!("{} points for a {:?} distance matrix", y.nrows(), x.dim()),
            "one row per row of the distance matrix",
        )
        .into());
    }
    Ok(())
}

/// Trustworthiness and continuity at `k` of `y` `(M, d)` for distances `x` `(M, M)`:
/// `(T, C)`, by [`neighbours::trustworthiness_continuity`] with `x` the input and `y`
/// the output. Requires `M ≥ 3` and `1 ≤ k ≤ M/2` (the normalisation assumes it).
pub fn trustworthiness_continuity(
    x: ArrayView2<'_, f64>,
    y: ArrayView2<'_, f64>,
    k: usize,
) -> Result<(f64, f64), EmbedError> {
    check_shapes(x, y)?;
    Ok(neighbours::trustworthiness_continuity(
        &DenseDistances::new(x)?,
        &Coordinates(y),
        k,
    )?)
}

/// Kruskal's stress-1 and the raw stress `½ Σ_{i≠j} (X_ij − Y_ij)²`: `(stress-1, raw)`.
pub fn stress(x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> Result<(f64, f64), EmbedError> {
    check_shapes(x, y)?;
    let m = x.nrows();
    let rows: Vec<(f64, f64)> = (0..m)
        .into_par_iter()
        .map(|i| {
            let (mut num, mut den) = (0.0, 0.0);
            for j in 0..i {
                let d = x[[i, j]] - out_distance(y, i, j);
                num += d * d;
                den += x[[i, j]] * x[[i, j]];
            }
            (num, den)
        })
        .collect();
    let (num, den) = rows
        .iter()
        .fold((0.0, 0.0), |(a, b), &(n, d)| (a + n, b + d));
    let kruskal = if den > 0.0 { (num / den).sqrt() } else { 0.0 };
    Ok((kruskal, num))
}

/// Every measure at once.
pub fn assess(
    x: ArrayView2<'_, f64>,
    y: ArrayView2<'_, f64>,
    k: usize,
) -> Result<Quality, EmbedError> {
    let (trustworthiness, continuity) = trustworthiness_continuity(x, y, k)?;
    let (kruskal_stress, raw_stress) = stress(x, y)?;
    Ok(Quality {
        k,
        trustworthiness,
        continuity,
        kruskal_stress,
        raw_stress,
    })
}

/// A Shepard (`dy–dx`) sample `(P, 2)`: columns `[X_ij, Y_ij]` for `P = min(max_pairs,
/// M(M−1)/2)` pairs `i < j`: all of them in order when they fit, else drawn uniformly
/// with replacement from a generator seeded by `seed`.
pub fn shepard_pairs(
    x: ArrayView2<'_, f64>,
    y: ArrayView2<'_, f64>,
    max_pairs: usize,
    seed: u64,
) -> Result<Array2<f64>, EmbedError> {
    check_shapes(x, y)?;
    let m = x.nrows();
    let total = m * m.saturating_sub(1) / 2;
    let pairs: Vec<(usize, usize)> = if total <= max_pairs {
        (0..m).flat_map(|i| (0..i).map(move |j| (i, j))).collect()
    } else {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..max_pairs)
            .map(|_| loop {
                let (i, j) = (rng.random_range(0..m), rng.random_range(0..m));
                if i != j {
                    break (i.max(j), i.min(j));
                }
            })
            .collect()
    };
    let mut out = Array2::zeros((pairs.len(), 2));
    out.as_slice_mut()
        .expect("standard layout")
        .par_chunks_mut(2)
        .zip(pairs.par_iter())
        .for_each(|(row, &(i, j))| {
            row[0] = x[[i, j]];
            row[1] = out_distance(y, i, j);
        });
    Ok(out)
}

/// The figures measured with an embedding of `distances`: trustworthiness, continuity
/// and stress with `neighbours` neighbours (capped below `M/2`; `None` when fewer than
/// one fits), and a Shepard sample of at most `dydx_pairs` pairs drawn with `seed`
/// (`None` for 0 pairs). `smspace embed` and the pipeline's embed stage both measure
/// through here. The figures are the same at any finite scale of the distances and
/// coordinates (both multiplied by one factor), and the sample is finite.
pub fn measure(
    distances: ArrayView2<'_, f64>,
    coordinates: ArrayView2<'_, f64>,
    neighbours: usize,
    dydx_pairs: usize,
    seed: u64,
) -> Result<(Option<Quality>, Option<Array2<f64>>), EmbedError> {
    // Distances far from 1 (beyond 2^±64) are measured divided by a power of two near
    // their largest (exact), so that squares neither underflow to 0 nor overflow to
    // infinity; lengths are multiplied back, the raw stress by the scale squared
    // (saturated at f64::MAX). Trustworthiness, continuity and stress-1 do not depend
    // on the scale.
    if let Some(scale) = super::eigen::distance_scale(distances.iter()) {
        let x = distances.mapv(|v| v / scale);
        let y = coordinates.mapv(|v| v / scale);
        let (quality, dydx) = measure(x.view(), y.view(), neighbours, dydx_pairs, seed)?;
        let times = super::eigen::times;
        let quality = quality.map(|q| Quality {
            raw_stress: times(times(q.raw_stress, scale), scale),
            ..q
        });
        return Ok((quality, dydx.map(|d| d.mapv(|v| times(v, scale)))));
    }
    let m = distances.nrows();
    let k = neighbours.min(m.saturating_sub(1) / 2);
    let quality = if k >= 1 {
        Some(assess(distances, coordinates, k)?)
    } else {
        None
    };
    let dydx = if dydx_pairs > 0 {
        Some(shepard_pairs(distances, coordinates, dydx_pairs, seed)?)
    } else {
        None
    };
    Ok((quality, dydx))
}
