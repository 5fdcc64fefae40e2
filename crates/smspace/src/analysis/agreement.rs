//! Agreement of the learned metric with the observer's ground truth, the poses of the
//! sensor (paper section 3.3: "each parameter of the retina's external configuration
//! `[x, y, α]` has been successfully captured").
//!
//! The pose distance weighs every component `c` of the pose by its spread:
//!
//! ```text
//! d_pose(i, j) = sqrt( Σ_c (Δ_c(i, j) / s_c)² ),   s_c = sqrt( mean_{i<j} Δ_c(i, j)² ),
//! ```
//!
//! with `Δ_c` taken by the component's kind ([`PoseComponent::distance`]): `|Δ|` for a
//! linear coordinate, the difference wrapped into `[-π, π)` for an angle (the planar
//! `alpha`), the rotation angle `2 acos |q·q'|` for a quaternion block; components of
//! zero spread (the toys' `y` and `alpha`) are left out. Figures:
//! - **Spearman** `ρ_s` between the learned and pose distances over all pairs `i < j`
//!   (average ranks for ties);
//! - **trustworthiness** and **continuity** (Venna & Kaski 2001) of the `k` nearest
//!   neighbours (default 10, at most `N/2`), [`crate::neighbours`] with the pose distance
//!   as the input and the learned one as the output:
//!   `T(k) = 1 − 2 / (N k (2N − 3k − 1)) Σ_i Σ_{j ∈ U_k(i)} (r(i, j) − k)`, with `U_k(i)`
//!   the learned neighbours of `i` that are not among its `k` nearest in pose and
//!   `r(i, j)` the rank of `j` among `i`'s pose neighbours; continuity swaps the roles.
//!   Both are 1 when the neighbourhoods agree; ties in distance are broken by index;
//! - per component, Spearman between the learned distance and `Δ_c`.

use std::collections::BTreeMap;

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use super::AnalysisError;
use crate::agent::{GroundTruthView, PoseComponent, PoseSpace};
use crate::neighbours::{self, DenseDistances, NeighboursError};

/// Names of the planar pose's columns ([`PoseSpace::planar`]).
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
    /// Per pose component (a coordinate, or a quaternion block named `qw/qx/qy/qz`),
    /// Spearman of the learned distance with `Δ_c`; `null` for a constant component.
    pub coordinates: BTreeMap<String, Option<f64>>,
    /// The spread `s_c` of every component (length units, radians for angles and
    /// rotations).
    pub pose_scales: BTreeMap<String, f64>,
}

/// Ranks `1..=n` of `values`, ties sharing their average rank.
pub fn average_ranks(values: &[f64]) -> Vec<f64> {
    let order = sorted_order(values);
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

/// `(key, index)` of `values` in increasing order of value, ties by index: a stable
/// least-significant-digit radix sort over the bytes of an order-preserving `u64` key
/// of each `f64` (`-0.0` and `0.0` get different keys, so they are not tied). Bytes
/// that every key shares are skipped. Linear in `n`; the Spearman correlation of
/// 3500 sets sorts 6.1 M pair distances several times.
fn sorted_order(values: &[f64]) -> Vec<(u64, usize)> {
    let key = |v: f64| {
        let bits = v.to_bits();
        if bits >> 63 == 1 {
            !bits
        } else {
            bits | (1 << 63)
        }
    };
    let n = values.len();
    let mut order: Vec<(u64, usize)> = values.iter().map(|&v| key(v)).zip(0..).collect();
    let mut spare = vec![(0_u64, 0_usize); n];
    for shift in (0..64).step_by(8) {
        let mut counts = [0_usize; 256];
        for &(k, _) in &order {
            counts[((k >> shift) & 0xff) as usize] += 1;
        }
        if counts.contains(&n) {
            continue;
        }
        let mut next = 0;
        for c in counts.iter_mut() {
            let here = *c;
            *c = next;
            next += here;
        }
        for &(k, i) in &order {
            let digit = ((k >> shift) & 0xff) as usize;
            spare[counts[digit]] = (k, i);
            counts[digit] += 1;
        }
        std::mem::swap(&mut order, &mut spare);
    }
    order
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

/// Trustworthiness and continuity of `learned` against `truth` with `k` neighbours,
/// both `(N, N)`: [`neighbours::trustworthiness_continuity`] with `truth` the input and
/// `learned` the output (`N ≥ 3`, `1 ≤ k ≤ N/2`).
pub fn trustworthiness_continuity(
    learned: ArrayView2<'_, f64>,
    truth: ArrayView2<'_, f64>,
    k: usize,
) -> Result<(f64, f64), AnalysisError> {
    let (learned, truth) = (DenseDistances::new(learned)?, DenseDistances::new(truth)?);
    neighbours::trustworthiness_continuity(&truth, &learned, k).map_err(|e| match e {
        NeighboursError::TrustworthinessK { points, max, .. } => {
            crate::params::InvalidParameter::new(
                "analysis",
                "neighbors",
                k,
                format!("must be at least 1 and at most N/2 = {max} with N = {points} points"),
            )
            .into()
        }
        e => e.into(),
    })
}

/// All agreement figures of `learned` (M × M) against planar poses `poses` (M × 3,
/// `(x, y, alpha)`): [`agreement_of`] with [`PoseSpace::planar`].
pub fn agreement(
    learned: ArrayView2<'_, f64>,
    poses: ArrayView2<'_, f64>,
    k: usize,
) -> Result<Agreement, AnalysisError> {
    let planar = PoseSpace::planar();
    let truth =
        GroundTruthView::new(&planar, poses.reborrow()).map_err(|_| AnalysisError::PosesShape {
            rows: poses.nrows(),
            columns: poses.ncols(),
            expected: learned.nrows(),
            coordinates: 3,
        })?;
    agreement_of(learned, truth, k)
}

/// The distance `Δ_c(i, j)` of every pair `i < j`, row by row, for every component.
fn component_distances(poses: ArrayView2<'_, f64>, components: &[PoseComponent]) -> Vec<Vec<f64>> {
    let n = poses.nrows();
    let pairs = n * n.saturating_sub(1) / 2;
    let poses = poses.as_standard_layout();
    let row = |i: usize| poses.row(i).to_slice().expect("standard layout");
    let mut deltas: Vec<Vec<f64>> = components
        .iter()
        .map(|_| Vec::with_capacity(pairs))
        .collect();
    for i in 0..n {
        for j in i + 1..n {
            for (component, delta) in components.iter().zip(deltas.iter_mut()) {
                delta.push(component.distance(row(i), row(j)));
            }
        }
    }
    deltas
}

/// All agreement figures of `learned` (M × M) against the observer's poses `truth`
/// (M × d, each component compared by its kind; see the module docs).
pub fn agreement_of(
    learned: ArrayView2<'_, f64>,
    truth: GroundTruthView<'_>,
    k: usize,
) -> Result<Agreement, AnalysisError> {
    let n = learned.nrows();
    let pairs = n * (n - 1) / 2;
    let components = truth.space().components();
    let deltas = component_distances(truth.poses(), &components);
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
    // One ranking at a time, each list dropped once ranked: a ranking of the
    // M(M − 1)/2 pairs needs 2.5 times the memory of D while it runs (its radix sort's
    // two buffers and the ranks), so rankings side by side made this the run's peak
    // (`pipeline::memory`).
    let learned_ranks = average_ranks(&upper_triangle(learned));
    let spearman_all = pearson(&learned_ranks, &average_ranks(&pose_pairs)).ok_or_else(|| {
        AnalysisError::Degenerate {
            what: "agreement",
            reason: "the learned distances are all equal".into(),
        }
    })?;
    let per_component: Vec<Option<f64>> = (0..components.len())
        .map(|c| {
            (scales[c] > 0.0)
                .then(|| pearson(&learned_ranks, &average_ranks(&deltas[c])))
                .flatten()
        })
        .collect();
    drop((learned_ranks, deltas));
    let mut coordinates = BTreeMap::new();
    let mut pose_scales = BTreeMap::new();
    for (c, component) in components.iter().enumerate() {
        coordinates.insert(component.name.clone(), per_component[c]);
        pose_scales.insert(component.name.clone(), scales[c]);
    }
    let mut pose_matrix = ndarray::Array2::<f64>::zeros((n, n));
    let mut p = 0;
    for i in 0..n {
        for j in i + 1..n {
            pose_matrix[[i, j]] = pose_pairs[p];
            pose_matrix[[j, i]] = pose_pairs[p];
            p += 1;
        }
    }
    let (trustworthiness, continuity) = trustworthiness_continuity(learned, pose_matrix.view(), k)?;
    Ok(Agreement {
        spearman: spearman_all,
        trustworthiness,
        continuity,
        neighbors: k,
        coordinates,
        pose_scales,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn radix_order_equals_a_comparison_sort() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(5);
        let mut values: Vec<f64> = (0..5000)
            .map(|_| match rng.random_range(0..4) {
                0 => rng.random_range(-1e3..1e3),
                1 => rng.random_range(0.0..1e-300),
                2 => f64::from(rng.random_range(-3_i32..3)),
                _ => rng.random_range(0.0..10.0),
            })
            .collect();
        values.extend([f64::MAX, f64::MIN, 0.0, 1.0, 1.0]);
        let mut expected: Vec<(f64, usize)> = values.iter().copied().zip(0..).collect();
        expected.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let found: Vec<usize> = sorted_order(&values).into_iter().map(|(_, i)| i).collect();
        let expected: Vec<usize> = expected.into_iter().map(|(_, i)| i).collect();
        assert_eq!(found, expected);
        assert_eq!(
            average_ranks(&[3.0, 1.0, 3.0, 2.0]),
            vec![3.5, 1.0, 3.5, 2.0]
        );
        assert!(average_ranks(&[]).is_empty());
    }

    /// Poses with a position on a line and an orientation in 3-D (a quaternion block),
    /// and a learned distance that is the true one: every figure is perfect, and each
    /// component is compared by its kind.
    #[test]
    fn poses_of_any_layout_are_compared_by_coordinate_kind() {
        use crate::agent::{CoordinateKind, PoseCoordinate};
        let names = ["x", "qw", "qx", "qy", "qz"];
        let kinds = [CoordinateKind::Linear]
            .into_iter()
            .chain([CoordinateKind::Quaternion; 4]);
        let space = PoseSpace::new(
            names
                .iter()
                .zip(kinds)
                .map(|(n, k)| PoseCoordinate::new(n, k))
                .collect(),
        )
        .unwrap();
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(9);
        let n = 60;
        let mut poses = ndarray::Array2::<f64>::zeros((n, 5));
        for mut row in poses.outer_iter_mut() {
            // A turn about z by angle a: q = (cos a/2, 0, 0, sin a/2), and the sign of
            // q flipped at random (the same orientation).
            let a: f64 = rng.random_range(-3.0..3.0);
            let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            row[0] = rng.random_range(0.0..1.0);
            row[1] = sign * (a / 2.0).cos();
            row[4] = sign * (a / 2.0).sin();
        }
        let components = space.components();
        let distance = |c: usize, i: usize, j: usize| {
            components[c].distance(&poses.row(i).to_vec(), &poses.row(j).to_vec())
        };
        let pairs = (n * (n - 1) / 2) as f64;
        let scales: Vec<f64> = (0..2)
            .map(|c| {
                let sum: f64 = (0..n)
                    .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
                    .map(|(i, j)| distance(c, i, j).powi(2))
                    .sum();
                (sum / pairs).sqrt()
            })
            .collect();
        // The learned distance is the pose distance itself.
        let learned = ndarray::Array2::from_shape_fn((n, n), |(i, j)| {
            (0..2)
                .map(|c| (distance(c, i, j) / scales[c]).powi(2))
                .sum::<f64>()
                .sqrt()
        });
        let truth = GroundTruthView::new(&space, poses.view()).unwrap();
        let a = agreement_of(learned.view(), truth, 5).unwrap();
        assert!(a.spearman > 0.999_999, "{a:?}");
        assert!(
            a.trustworthiness > 0.999_999 && a.continuity > 0.999_999,
            "{a:?}"
        );
        approx::assert_abs_diff_eq!(a.pose_scales["qw/qx/qy/qz"], scales[1], epsilon = 1e-12);
        assert!(a.coordinates["qw/qx/qy/qz"].unwrap() > 0.5, "{a:?}");
        // Flipping the sign of every quaternion changes nothing.
        let flipped = {
            let mut p = poses.clone();
            for mut row in p.outer_iter_mut() {
                row.iter_mut().skip(1).for_each(|v| *v = -*v);
            }
            p
        };
        let truth = GroundTruthView::new(&space, flipped.view()).unwrap();
        assert_eq!(agreement_of(learned.view(), truth, 5).unwrap(), a);
        // The planar case is the planar layout.
        let planar = poses.select(ndarray::Axis(1), &[0, 1, 2]);
        let space = PoseSpace::planar();
        let truth = GroundTruthView::new(&space, planar.view()).unwrap();
        assert_eq!(
            agreement(learned.view(), planar.view(), 5).unwrap(),
            agreement_of(learned.view(), truth, 5).unwrap()
        );
    }
}
