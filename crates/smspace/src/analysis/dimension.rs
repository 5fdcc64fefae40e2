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
//!
//! **Reliability.** Both estimators assume points drawn from a density that is locally
//! uniform, so that neighbour distances vary continuously from point to point. Regular
//! data break that assumption: on a lattice, or on equally spaced points of concentric
//! circles, the two nearest neighbours of most points are equally far (`μ = 1`, so
//! `ln μ = 0` and the TwoNN slope explodes: 2.5e14 for 30 concentric circles), and on a
//! smoothly warped grid (the paper's probe grid) `μ` is concentrated near one value
//! (TwoNN 11.4 on the arm's grid alone). Every estimate therefore carries a
//! [`Reliability`], read off the same nearest distances ([`NeighbourDiagnostics`]):
//!
//! - **ties**: the share of points whose two nearest neighbours are equally far
//!   (`μ − 1 ≤ 1e-9`), and, for the MLE, the share of equal consecutive distances among
//!   the `k` nearest; at most [`TIE_SHARE_LIMIT`] (5 %) is accepted (a continuous
//!   density gives none);
//! - **lattice**: the largest share of points whose ratios `μ` are equal (to `1e-9`
//!   relative); at most [`TIE_SHARE_LIMIT`] is accepted;
//! - **the law of `ln μ`**: under the Pareto law `ln μ` is exponential with rate `d`,
//!   whatever the density (as long as it is locally uniform). The Kolmogorov–Smirnov
//!   distance between the distribution of `ln μ` and the exponential law of the same
//!   mean must be at most [`PARETO_KS_LIMIT`] (0.1; or `2.5/√N` on few points). The
//!   arm's babbled sets give about 0.05; its probe grid, whose ratios sit at a few
//!   values (the two neighbours along the grid's finest direction, nearly equally far),
//!   about 0.17;
//! - **duplicates**: more than [`TIE_SHARE_LIMIT`] of the points skipped.
//!
//! An unreliable estimate is still computed and reported, with its reasons.

use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use super::AnalysisError;
use crate::neighbours::{nearest_neighbours, DenseDistances};

/// A dimension estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DimensionEstimate {
    /// The estimated intrinsic dimension.
    pub dimension: f64,
    /// Points that entered the estimate.
    pub points_used: usize,
    /// Points skipped (a duplicate neighbour, or all `k` neighbours equally far).
    pub points_skipped: usize,
    /// Whether the data fit the estimator's assumptions (`not-checked` in reports
    /// written before the check existed).
    #[serde(default)]
    pub reliability: Reliability,
}

/// Largest share of points with tied neighbour distances, or with one and the same
/// ratio `μ`, that an estimate accepts: 5 %.
pub const TIE_SHARE_LIMIT: f64 = 0.05;

/// Two distances are tied when they differ by at most this fraction of the larger.
pub const TIE_TOLERANCE: f64 = 1e-9;

/// The largest Kolmogorov–Smirnov distance accepted between the distribution of
/// `ln μ` and its exponential law: 0.1, or `2.5 / √N` on `N` points when larger (about
/// twice the 5 % critical value of the test with an estimated rate, 1.09 / √N).
pub const PARETO_KS_LIMIT: f64 = 0.1;

/// The sampling-noise part of the limit above: `PARETO_KS_NOISE / √N`.
pub const PARETO_KS_NOISE: f64 = 2.5;

/// Whether an estimate can be trusted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReliabilityStatus {
    /// The nearest distances look like a sample of a continuous density.
    Reliable,
    /// The data break the estimator's assumptions; the reasons say how.
    Unreliable,
    /// Not checked (a report written before the check existed).
    #[default]
    NotChecked,
}

/// The verdict on an estimate, with its reasons and the numbers behind them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Reliability {
    /// The verdict.
    pub status: ReliabilityStatus,
    /// Why it is unreliable, one sentence each with the numbers (empty when reliable).
    pub reasons: Vec<String>,
    /// The measurements.
    pub diagnostics: Option<NeighbourDiagnostics>,
}

impl Reliability {
    /// Whether the estimate was checked and found unreliable.
    pub fn is_unreliable(&self) -> bool {
        self.status == ReliabilityStatus::Unreliable
    }
}

/// What the nearest distances say about the data (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NeighbourDiagnostics {
    /// Points measured.
    pub points: usize,
    /// Share of points with a duplicate (nearest distance 0).
    pub duplicate_share: f64,
    /// Share of the other points whose two nearest neighbours are equally far (`μ = 1`).
    pub tied_share: f64,
    /// Largest share of points with one and the same ratio `μ`.
    pub same_ratio_share: f64,
    /// That ratio.
    pub same_ratio: f64,
    /// Kolmogorov–Smirnov distance between the distribution of `ln μ` and the
    /// exponential law of the same mean, which `ln μ` follows under TwoNN's Pareto law
    /// (`null` when every `μ` is 1).
    pub pareto_ks: Option<f64>,
    /// Share of equal consecutive distances among the nearest distances of every point
    /// (all `k` of them for the MLE; the first two, as `tied_share`, for TwoNN).
    pub tied_distance_share: f64,
}

impl NeighbourDiagnostics {
    /// Measures the nearest distances `(M, k ≥ 2)`, each row increasing.
    pub fn measure(near: ArrayView2<'_, f64>) -> Self {
        let n = near.nrows();
        let mu: Vec<f64> = near
            .outer_iter()
            .filter(|r| r[0] > 0.0)
            .map(|r| r[1] / r[0])
            .collect();
        let used = mu.len().max(1) as f64;
        let tied = mu.iter().filter(|&&m| m - 1.0 <= TIE_TOLERANCE).count();
        let (same_ratio, same_count) = largest_equal_run(&mu);
        let mut logs: Vec<f64> = mu.iter().map(|m| m.ln()).collect();
        logs.sort_by(f64::total_cmp);
        let mean = logs.iter().sum::<f64>() / used;
        let pairs = near.nrows() * (near.ncols() - 1);
        let tied_distances = near
            .outer_iter()
            .map(|r| {
                r.iter()
                    .zip(r.iter().skip(1))
                    .filter(|&(&a, &b)| b - a <= TIE_TOLERANCE * b)
                    .count()
            })
            .sum::<usize>();
        Self {
            points: n,
            duplicate_share: (n - mu.len()) as f64 / n.max(1) as f64,
            tied_share: tied as f64 / used,
            same_ratio_share: same_count as f64 / used,
            same_ratio,
            pareto_ks: (mean > 0.0).then(|| exponential_ks(&logs, mean)),
            tied_distance_share: tied_distances as f64 / pairs.max(1) as f64,
        }
    }

    /// The verdict: every limit of the module documentation that is exceeded, in words.
    pub fn verdict(self, estimator: &str) -> Reliability {
        let percent = |share: f64| format!("{:.1} %", 100.0 * share);
        let mut reasons = Vec::new();
        if self.duplicate_share > TIE_SHARE_LIMIT {
            reasons.push(format!(
                "{} of the points have a duplicate (a neighbour at distance 0)",
                percent(self.duplicate_share)
            ));
        }
        if self.tied_share > TIE_SHARE_LIMIT {
            reasons.push(format!(
                "{} of the points have their two nearest neighbours equally far (r2/r1 = 1): the points are regularly spaced (a lattice, equally spaced points on curves), not a sample of a density",
                percent(self.tied_share)
            ));
        } else if self.same_ratio_share > TIE_SHARE_LIMIT {
            reasons.push(format!(
                "{} of the points share one neighbour-distance ratio r2/r1 = {:.6}: the data are lattice-like",
                percent(self.same_ratio_share),
                self.same_ratio
            ));
        }
        if self.tied_distance_share > TIE_SHARE_LIMIT && self.tied_distance_share > self.tied_share
        {
            reasons.push(format!(
                "{} of the consecutive nearest distances are equal: the data are lattice-like",
                percent(self.tied_distance_share)
            ));
        }
        let limit = PARETO_KS_LIMIT.max(PARETO_KS_NOISE / (self.points.max(1) as f64).sqrt());
        match self.pareto_ks {
            Some(ks) if ks > limit => reasons.push(format!(
                "the ratios r2/r1 do not follow the Pareto law TwoNN assumes (Kolmogorov-Smirnov distance of ln(r2/r1) to its exponential law {ks:.3}, more than {limit:.3}): they are concentrated at a few values, as on a regular grid"
            )),
            Some(_) => {}
            None => reasons.push("every point has its two nearest neighbours equally far".to_owned()),
        }
        let status = if reasons.is_empty() {
            ReliabilityStatus::Reliable
        } else {
            ReliabilityStatus::Unreliable
        };
        let reasons = reasons
            .into_iter()
            .map(|r| format!("{estimator}: {r}"))
            .collect();
        Reliability {
            status,
            reasons,
            diagnostics: Some(self),
        }
    }
}

/// The Kolmogorov–Smirnov distance between the empirical distribution of `sorted`
/// (increasing, non-negative) and the exponential law of mean `mean`.
fn exponential_ks(sorted: &[f64], mean: f64) -> f64 {
    let n = sorted.len() as f64;
    sorted
        .iter()
        .enumerate()
        .map(|(i, &x)| {
            let f = 1.0 - (-x / mean).exp();
            (f - i as f64 / n).abs().max(((i + 1) as f64 / n - f).abs())
        })
        .fold(0.0, f64::max)
}

/// The value shared by the longest run of equal values (to [`TIE_TOLERANCE`]) of
/// `values` once sorted, and the run's length (`(NaN, 0)` without values).
fn largest_equal_run(values: &[f64]) -> (f64, usize) {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let mut best = (f64::NAN, 0);
    let mut start = 0;
    for i in 1..=sorted.len() {
        let ends = i == sorted.len() || sorted[i] - sorted[i - 1] > TIE_TOLERANCE * sorted[i];
        if ends {
            if i - start > best.1 {
                best = (sorted[start], i - start);
            }
            start = i;
        }
    }
    best
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
        reliability: NeighbourDiagnostics::measure(
            near.slice_axis(ndarray::Axis(1), (0..2).into()),
        )
        .verdict("TwoNN"),
    })
}

/// Levina–Bickel maximum-likelihood estimate with `k ≥ 2` neighbours (`k < M`).
pub fn mle(distances: ArrayView2<'_, f64>, k: usize) -> Result<DimensionEstimate, AnalysisError> {
    let n = distances.nrows();
    if k < 2 || k >= n {
        return Err(crate::params::InvalidParameter::new(
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
        reliability: NeighbourDiagnostics::measure(
            near.slice_axis(ndarray::Axis(1), (0..k).into()),
        )
        .verdict("MLE"),
    })
}

#[cfg(test)]
mod tests {
    use std::f64::consts::TAU;

    use ndarray::{Array2, Axis};
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};

    use super::*;

    /// Euclidean distances between the rows of `points`.
    fn euclidean(points: &Array2<f64>) -> Array2<f64> {
        let n = points.nrows();
        Array2::from_shape_fn((n, n), |(i, j)| {
            points
                .row(i)
                .iter()
                .zip(points.row(j))
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt()
        })
    }

    fn both(d: &Array2<f64>) -> (DimensionEstimate, DimensionEstimate) {
        (twonn(d.view(), 0.1).unwrap(), mle(d.view(), 20).unwrap())
    }

    #[test]
    fn concentric_circles_of_equally_spaced_points_are_unreliable() {
        // 30 circles of radius 1..30, each of 60 equally spaced points: the two
        // neighbours of a point on its circle are equally far (to rounding).
        let points = Array2::from_shape_fn((30 * 60, 2), |(i, c)| {
            let (ring, k) = (i / 60, i % 60);
            let angle = TAU * k as f64 / 60.0;
            let r = 1.0 + ring as f64;
            if c == 0 {
                r * angle.cos()
            } else {
                r * angle.sin()
            }
        });
        let (t, m) = both(&euclidean(&points));
        assert!(t.dimension > 10.0, "TwoNN explodes here: {}", t.dimension);
        for e in [&t, &m] {
            assert!(e.reliability.is_unreliable(), "{e:?}");
        }
        assert!(
            t.reliability.reasons[0].contains("equally far"),
            "{:?}",
            t.reliability.reasons
        );
        let tied = t.reliability.diagnostics.unwrap().tied_share;
        assert!(tied > 0.9, "{tied}");
    }

    /// A 10 × 10 × 10 grid with spacings 1, 1.4 and 1.9, smoothly warped so that no
    /// two distances are exactly equal (as the arm's probe grid seen through the set
    /// metric).
    fn warped_grid() -> Array2<f64> {
        Array2::from_shape_fn((1000, 3), |(i, c)| {
            let g = [(i / 100) as f64, (i / 10 % 10) as f64, (i % 10) as f64];
            let spacing = [1.0, 1.4, 1.9][c];
            let u = g[c] / 9.0;
            spacing * g[c] + 0.8 * (2.0 * u + g[(c + 1) % 3] / 9.0).sin() + 0.6 * u * u
        })
    }

    #[test]
    fn a_warped_grid_is_lattice_like() {
        let (t, m) = both(&euclidean(&warped_grid()));
        for e in [&t, &m] {
            assert!(e.reliability.is_unreliable(), "{e:?}");
            let d = e.reliability.diagnostics.unwrap();
            assert!(d.tied_share < TIE_SHARE_LIMIT, "no exact ties: {d:?}");
        }
        assert!(
            t.reliability
                .reasons
                .iter()
                .any(|r| r.contains("concentrated")),
            "{:?}",
            t.reliability.reasons
        );
    }

    #[test]
    fn a_noisy_cloud_is_reliable_and_three_dimensional() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let points = Array2::from_shape_fn((1500, 5), |(_, c)| {
            if c < 3 {
                rng.random_range(0.0..1.0)
            } else {
                0.01 * rng.random_range(-1.0..1.0)
            }
        });
        let (t, m) = both(&euclidean(&points));
        for e in [&t, &m] {
            assert_eq!(e.reliability.status, ReliabilityStatus::Reliable, "{e:?}");
            assert!(e.reliability.reasons.is_empty());
            assert!((2.6..3.4).contains(&e.dimension), "{e:?}");
        }
        let ks = t.reliability.diagnostics.unwrap().pareto_ks.unwrap();
        assert!(ks < 0.05, "Pareto law: KS = {ks}");
    }

    #[test]
    fn duplicates_are_flagged() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let base = Array2::from_shape_fn((300, 3), |_| rng.random_range(0.0..1.0));
        let points = ndarray::concatenate(Axis(0), &[base.view(), base.view()]).unwrap();
        let d = euclidean(&points);
        let near = nearest_distances(d.view(), 20).unwrap();
        let r = NeighbourDiagnostics::measure(near.view()).verdict("MLE");
        assert!(r.is_unreliable());
        assert!(r.reasons.iter().any(|x| x.contains("duplicate")), "{r:?}");
    }

    /// The kernel sets of the paper's arm (babbled, in its working space) under the
    /// point Hausdorff metric: the data the analysis estimates on.
    fn arm_distances(probes: bool) -> Array2<f64> {
        use crate::agent::AgentConfig;
        use crate::explore::{explore, ExploreParams, Probes};
        use crate::kernel::{trace_sets, TraceParams};
        use crate::metric::{distance_matrix, DistanceParams, Period};
        use crate::progress::Silent;
        let agent = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
        let params = ExploreParams {
            n: if probes { 1 } else { 400 },
            probes: if probes { Probes::Grid } else { Probes::None },
            probe_positions: 7,
            probe_orientations: 7,
            ..ExploreParams::default()
        };
        let found = explore(agent.as_ref(), &params).unwrap();
        let trace = TraceParams {
            points: 50,
            ..TraceParams::default()
        };
        let traced = trace_sets(
            agent.as_ref(),
            None,
            found.motors.view(),
            found.workspace.as_ref(),
            &trace.check().unwrap(),
            &Silent,
        )
        .unwrap();
        let rows: Vec<usize> = if probes {
            (0..traced.kept.len())
                .filter(|&i| !crate::explore::is_babbled(found.probes.row(traced.kept[i])))
                .collect()
        } else {
            (0..traced.kept.len()).collect()
        };
        let sets = traced.sets.select(Axis(0), &rows);
        let metric = DistanceParams::new()
            .metric(crate::metric::MetricKind::Hausdorff)
            .period(Period::TwoPi);
        distance_matrix(sets.view(), &metric, &Silent)
            .unwrap()
            .into_array()
    }

    #[test]
    fn the_arms_sets_are_reliable_and_its_probe_grid_is_not() {
        let (t, m) = both(&arm_distances(false));
        for e in [&t, &m] {
            assert_eq!(e.reliability.status, ReliabilityStatus::Reliable, "{e:?}");
            assert!((2.3..4.0).contains(&e.dimension), "{e:?}");
        }
        let (t, m) = both(&arm_distances(true));
        assert!(t.reliability.is_unreliable(), "{t:?}");
        assert!(m.reliability.is_unreliable() || m.dimension > 4.0, "{m:?}");
    }
}
