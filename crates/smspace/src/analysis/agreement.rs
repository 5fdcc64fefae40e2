//! Agreement of the learned metric with the observer's ground truth, the poses
//! `(x, y, alpha)` of the sensor (paper section 3.3: "each parameter of the retina's
//! external configuration `[x, y, α]` has been successfully captured").
//!
//! The pose distance weighs every coordinate by its spread:
//!
//! ```text
//! d_pose(i, j) = sqrt( Σ_c (Δ_c(i, j) / s_c)² ),   s_c = sqrt( mean_{i<j} Δ_c(i, j)² ),
//! ```
//!
//! with `Δ_alpha` wrapped into `[-π, π)` (alpha is circular) and coordinates of zero
//! spread (the toys' `y` and `alpha`) left out. Figures:
//! - **Spearman** `ρ_s` between the learned and pose distances over all pairs `i < j`
//!   (average ranks for ties);
//! - **trustworthiness** and **continuity** (Venna & Kaski 2001) of the `k` nearest
//!   neighbours (default 10):
//!   `T(k) = 1 − 2 / (N k (2N − 3k − 1)) Σ_i Σ_{j ∈ U_k(i)} (r(i, j) − k)`, with `U_k(i)`
//!   the learned neighbours of `i` that are not among its `k` nearest in pose and
//!   `r(i, j)` the rank of `j` among `i`'s pose neighbours; continuity swaps the roles.
//!   Both are 1 when the neighbourhoods agree; ties in distance are broken by index;
//! - per coordinate, Spearman between the learned distance and `|Δ_c|`.

use std::collections::BTreeMap;

use ndarray::ArrayView2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::AnalysisError;
use crate::agent::wrap_angle;

/// Names of the pose columns.
pub const POSE_COORDINATES: [&str; 3] = ["x", "y", "alpha"];

/// Agreement figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Agreement {
    /// Spearman correlation of learned and pose distances over all pairs.
    pub spearman: f64,
    /// Trustworthiness of the learned `k`-neighbourhoods.
    pub trustworthiness: f64,
    /// Continuity of the pose `k`-neighbourhoods in the learned metric.
    pub continuity: f64,
    /// `k` of trustworthiness and continuity.
    pub neighbors: usize,
    /// Per pose coordinate, Spearman of the learned distance with `|Δ_c|`; `null` for a
    /// constant coordinate.
    pub coordinates: BTreeMap<String, Option<f64>>,
    /// The spread `s_c` of every coordinate (length units, radians for alpha).
    pub pose_scales: BTreeMap<String, f64>,
}

/// Ranks `1..=n` of `values`, ties sharing their average rank.
pub fn average_ranks(values: &[f64]) -> Vec<f64> {
    let mut order: Vec<(f64, usize)> = values.iter().copied().zip(0..).collect();
    order.par_sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut ranks = vec![0.0; values.len()];
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && order[end].0 == order[start].0 {
            end += 1;
        }
        let rank = 0.5 * ((start + 1) + end) as f64;
        for &(_, i) in &order[start..end] {
            ranks[i] = rank;
        }
        start = end;
    }
    ranks
}

/// Pearson correlation; `None` when either side is constant.
pub fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (dx, dy) = (x - ma, y - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    (saa > 0.0 && sbb > 0.0).then(|| (sab / (saa * sbb).sqrt()).clamp(-1.0, 1.0))
}

/// Spearman rank correlation; `None` when either side is constant.
pub fn spearman(a: &[f64], b: &[f64]) -> Option<f64> {
    pearson(&average_ranks(a), &average_ranks(b))
}

/// The upper triangle `i < j` of a square matrix, row by row.
pub fn upper_triangle(matrix: ArrayView2<'_, f64>) -> Vec<f64> {
    let n = matrix.nrows();
    let mut out = Vec::with_capacity(n * n.saturating_sub(1) / 2);
    for i in 0..n {
        for j in i + 1..n {
            out.push(matrix[[i, j]]);
        }
    }
    out
}

/// Trustworthiness and continuity of `learned` against `truth` with `k` neighbours
/// (`1 ≤ k`, `3k < 2N − 1`).
pub fn trustworthiness_continuity(
    learned: ArrayView2<'_, f64>,
    truth: ArrayView2<'_, f64>,
    k: usize,
) -> Result<(f64, f64), AnalysisError> {
    let n = learned.nrows();
    if k == 0 || 3 * k + 1 >= 2 * n {
        return Err(AnalysisError::InvalidParameter {
            name: "neighbors",
            value: k.to_string(),
            reason: format!(
                "must be at least 1 and satisfy 3k + 1 < 2N with N = {n} points (k < {})",
                (2 * n).saturating_sub(1).div_ceil(3)
            ),
        });
    }
    let sums: Vec<(f64, f64)> = (0..n)
        .into_par_iter()
        .map(|i| {
            let order = |m: ArrayView2<'_, f64>| {
                let mut idx: Vec<(f64, usize)> = m
                    .row(i)
                    .iter()
                    .copied()
                    .zip(0..)
                    .filter(|&(_, j)| j != i)
                    .collect();
                idx.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                let mut rank = vec![0usize; n];
                for (r, &(_, j)) in idx.iter().enumerate() {
                    rank[j] = r + 1;
                }
                let idx: Vec<usize> = idx.into_iter().map(|(_, j)| j).collect();
                (idx, rank)
            };
            let (learned_order, learned_rank) = order(learned);
            let (truth_order, truth_rank) = order(truth);
            let trust: usize = learned_order[..k]
                .iter()
                .filter(|&&j| truth_rank[j] > k)
                .map(|&j| truth_rank[j] - k)
                .sum();
            let cont: usize = truth_order[..k]
                .iter()
                .filter(|&&j| learned_rank[j] > k)
                .map(|&j| learned_rank[j] - k)
                .sum();
            (trust as f64, cont as f64)
        })
        .collect();
    let (nf, kf) = (n as f64, k as f64);
    let norm = 2.0 / (nf * kf * (2.0 * nf - 3.0 * kf - 1.0));
    let trust: f64 = sums.iter().map(|s| s.0).sum();
    let cont: f64 = sums.iter().map(|s| s.1).sum();
    Ok((1.0 - norm * trust, 1.0 - norm * cont))
}

/// All agreement figures of `learned` (M × M) against `poses` (M × 3).
pub fn agreement(
    learned: ArrayView2<'_, f64>,
    poses: ArrayView2<'_, f64>,
    k: usize,
) -> Result<Agreement, AnalysisError> {
    let n = learned.nrows();
    let pairs = n * (n - 1) / 2;
    let mut deltas: Vec<Vec<f64>> = (0..3).map(|_| Vec::with_capacity(pairs)).collect();
    for i in 0..n {
        for j in i + 1..n {
            for (c, delta) in deltas.iter_mut().enumerate() {
                let d = poses[[i, c]] - poses[[j, c]];
                delta.push(if c == 2 { wrap_angle(d) } else { d }.abs());
            }
        }
    }
    let scales: Vec<f64> = deltas
        .iter()
        .map(|d| (d.iter().map(|x| x * x).sum::<f64>() / pairs as f64).sqrt())
        .collect();
    if scales.iter().all(|&s| s <= 0.0) {
        return Err(AnalysisError::Degenerate {
            what: "agreement",
            reason: "every pose is the same, so pose distances are all zero".into(),
        });
    }
    let mut pose_pairs = vec![0.0; pairs];
    for (delta, &s) in deltas.iter().zip(&scales) {
        if s > 0.0 {
            for (p, &d) in pose_pairs.iter_mut().zip(delta) {
                *p += (d / s) * (d / s);
            }
        }
    }
    pose_pairs.iter_mut().for_each(|p| *p = p.sqrt());
    let learned_pairs = upper_triangle(learned);
    let learned_ranks = average_ranks(&learned_pairs);
    let spearman_all = pearson(&learned_ranks, &average_ranks(&pose_pairs)).ok_or_else(|| {
        AnalysisError::Degenerate {
            what: "agreement",
            reason: "the learned distances are all equal".into(),
        }
    })?;
    let mut coordinates = BTreeMap::new();
    let mut pose_scales = BTreeMap::new();
    for (c, name) in POSE_COORDINATES.iter().enumerate() {
        let rho = if scales[c] > 0.0 {
            pearson(&learned_ranks, &average_ranks(&deltas[c]))
        } else {
            None
        };
        coordinates.insert((*name).to_owned(), rho);
        pose_scales.insert((*name).to_owned(), scales[c]);
    }
    let mut truth = ndarray::Array2::<f64>::zeros((n, n));
    let mut p = 0;
    for i in 0..n {
        for j in i + 1..n {
            truth[[i, j]] = pose_pairs[p];
            truth[[j, i]] = pose_pairs[p];
            p += 1;
        }
    }
    let (trustworthiness, continuity) = trustworthiness_continuity(learned, truth.view(), k)?;
    Ok(Agreement {
        spearman: spearman_all,
        trustworthiness,
        continuity,
        neighbors: k,
        coordinates,
        pose_scales,
    })
}
