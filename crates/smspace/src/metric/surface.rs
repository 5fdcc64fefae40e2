//! The `surface` metric: the Hausdorff distance between kernel sets of dimension
//! `k ≥ 2` read as sampled surfaces.
//!
//! # Why
//!
//! With `N` motors and a sensor configuration of dimension `r`, a kernel is an
//! `(N − r)`-dimensional manifold; the tracer samples it with `P` points whose covering
//! radius `r_B` (the largest distance from the kernel to its nearest sample) falls only
//! as `P^(−1/k)`. The point metric between two samples then has a floor near that
//! radius: on the 4-link arm (`k = 2`, 150 points, `r_B ≈ 0.8` rad) the nearest and the
//! second nearest set are almost equally far, and the nearest-neighbour ratios that
//! estimate the dimension see noise (TwoNN 31 where the manifold is 3-D). The `curve`
//! metric removes the floor for `k = 1` by measuring the polylines; this metric does the
//! same to first order for any `k`, by giving every sample the piece of tangent plane
//! around it.
//!
//! # Definition
//!
//! Every point `b` of a set `B` carries a **disk** of its tangent plane:
//!
//! ```text
//! D_b = { b + T_b y : y ∈ R^k, |y| ≤ ρ_b },
//! ```
//!
//! with `T_b` (`N × k`, orthonormal columns) the `k` leading eigenvectors of
//! `Σ_q h(x_q − b) h(x_q − b)ᵀ` over the `neighbours` points `x_q` of `B` nearest to
//! `b` (a local principal component analysis through `b`; `h` wraps every coordinate
//! difference into `[−T_n/2, T_n/2]` as the point metric `g` does), and
//! `ρ_b = radius_scale · min_q g(x_q, b)` (the distance to its nearest neighbour: after a
//! farthest-point subsampling every pairwise distance is at least the covering radius,
//! so with `radius_scale ≥ 1` the disks reach over the whole kernel).
//!
//! The distance from a point `a` to a disk, with `w = h(a − b)` and `y = T_bᵀ w`
//! (the foot of `w` on the plane), is exact in closed form:
//!
//! ```text
//! dist(a, D_b)² = |w|² − |y|²                      when |y| ≤ ρ_b,
//!               = |w|² − |y|² + (|y| − ρ_b)²       otherwise (the foot clamped to the rim),
//! ```
//!
//! and the metric is the symmetric Hausdorff distance from the samples of one set to
//! the disks of the other:
//!
//! ```text
//! h_s(A, B) = max_{a∈A} min_{b∈B} dist(a, D_b),      ρ_s(A, B) = max(h_s(A, B), h_s(B, A)).
//! ```
//!
//! `ρ_s(A, A) = 0` (every sample is the centre of its disk) and `ρ_s` is symmetric; the
//! triangle inequality is not guaranteed ([`SetMetric::is_metric`] is `false`, so the
//! nearest-neighbour search does not prune with it).
//!
//! # How close to the kernels
//!
//! If the disks of `B` lie within `ε_B` of the kernel `K_B` (a disk of radius `ρ` on a
//! surface of curvature `κ` leaves it by about `κρ²/2`) and cover it, then
//! `|min_b dist(a, D_b) − d(a, K_B)| ≤ ε_B` for every `a`; the maximum over the
//! samples of `A` is within `r_A` below the maximum over `K_A` (`d(·, K_B)` is
//! 1-Lipschitz). So `ρ_s` is within `max(r_A, r_B) + max(ε_A, ε_B)` of the Hausdorff
//! distance between the kernels, where the point metric is within `r_A + r_B`; and
//! where the point metric's error is a floor of order `r` even between kernels that
//! nearly coincide, this metric's error between such kernels is of order `κρ²`.
//!
//! # Algorithm
//!
//! The disks of every set are computed once ([`SetMetric::prepare`]): `O(P²N)` per set
//! for the neighbours and an `N × N` symmetric eigen-decomposition per point. Each set's
//! points are then put in a greedy nearest-neighbour order (the set is unchanged), so
//! that consecutive points are near each other. A directed pass keeps the running
//! maximum `c` of the exact values found so far; for each `a`, the scan of `B` starts at
//! the point where the previous `a` found its nearest disk and moves outwards; a point
//! `b` with `g(a, b) ≤ c` ends the scan (`dist(a, D_b) ≤ g(a, b)`: `a` cannot raise
//! `c`), a disk whose lower bound `g(a, b) − ρ_b` is above the best found so far is
//! skipped, and every other disk is measured exactly. The result is the maximum of
//! exactly computed values, so it does not depend on the scan order, and the pair is
//! always evaluated as (smaller index, larger index).

use std::sync::Arc;

use ndarray::{ArrayView2, ArrayView3, Axis};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::curve::around;
use super::period::{swrap, wrap};
use super::{
    CoordinatePeriods, KernelShape, MetricBuilder, MetricContext, MetricError, Periodicity,
    PreparedPairs, SetMetric, WorkForecast,
};
use crate::params::InvalidParameter;

/// The `[metric.params]` of the `surface` metric.
///
/// ```
/// use smspace::metric::SurfaceParams;
/// let p: SurfaceParams = toml::from_str("dimension = 2").unwrap();
/// assert_eq!((p.dimension, p.neighbours, p.radius_scale), (2, 8, 1.0));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurfaceParams {
    /// Dimension `k` of the kernels, and so of each point's tangent plane: `N − r` for
    /// `N` motors and a sensor configuration of dimension `r` (2 for the 4-link arm).
    /// Default 2.
    pub dimension: usize,
    /// Points of its own set, nearest first, whose offsets give each point's tangent
    /// plane. Default 8; at least `dimension`, at most `P − 1`.
    pub neighbours: usize,
    /// Radius of each point's disk in units of the distance to its nearest neighbour in
    /// its set. Default 1.0 (the disks then reach over a farthest-point sample's
    /// covering radius); 0 gives the point metric `hausdorff`.
    pub radius_scale: f64,
}

impl Default for SurfaceParams {
    fn default() -> Self {
        Self {
            dimension: 2,
            neighbours: 8,
            radius_scale: 1.0,
        }
    }
}

/// Largest kernel dimension `k` the metric takes.
pub const MAX_DIMENSION: usize = 8;

/// The `surface` metric `ρ_s` (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    params: SurfaceParams,
    period: Periodicity,
}

fn invalid(key: &'static str, value: impl std::fmt::Display, reason: String) -> MetricError {
    MetricError::Invalid(InvalidParameter::new("metric.params", key, value, reason))
}

impl Surface {
    /// The metric with these parameters, checked, under the point metric's `period`.
    pub fn new(params: SurfaceParams, period: Periodicity) -> Result<Self, MetricError> {
        if !(1..=MAX_DIMENSION).contains(&params.dimension) {
            return Err(invalid(
                "dimension",
                params.dimension,
                format!(
                    "the kernels' dimension must be between 1 and {MAX_DIMENSION} (2 for surfaces)"
                ),
            ));
        }
        if params.neighbours < params.dimension {
            return Err(invalid(
                "neighbours",
                params.neighbours,
                format!(
                    "a tangent plane of dimension {} needs at least that many neighbours",
                    params.dimension
                ),
            ));
        }
        if !(params.radius_scale.is_finite() && params.radius_scale >= 0.0) {
            return Err(invalid(
                "radius_scale",
                params.radius_scale,
                "must be a finite number of at least 0 (1.0 by default)".into(),
            ));
        }
        Ok(Self { params, period })
    }

    /// The parameters.
    pub fn params(&self) -> &SurfaceParams {
        &self.params
    }
}

/// The registry's `[metric.params]` table of the surface metric, every default in it.
pub(super) fn default_table() -> toml::Table {
    crate::registry::table_of(&SurfaceParams::default()).unwrap_or_default()
}

/// The registry's builder of `metric = "surface"`: `dimension`, when the table leaves
/// it out, is the kernels' when the caller knows them (else 2).
pub(super) fn builder() -> MetricBuilder {
    Arc::new(|table: &toml::Table, context: &MetricContext| {
        let mut table = table.clone();
        if let Some(kernels) = context.kernels.filter(|_| !table.contains_key("dimension")) {
            table.insert("dimension".into(), (kernels.dimension as i64).into());
        }
        let params: SurfaceParams =
            toml::Value::Table(table.clone())
                .try_into()
                .map_err(|e: toml::de::Error| MetricError::InvalidTable {
                    metric: "surface".into(),
                    reason: e.to_string().trim_end().to_owned(),
                })?;
        let metric = Surface::new(params, context.period.clone())?;
        let resolved = crate::registry::table_of(&metric.params).unwrap_or(table);
        Ok((Box::new(metric) as Box<dyn SetMetric>, resolved))
    })
}

impl Surface {
    /// The disks of every set of `sets` `(M, P, N)`, in parallel (identical for any
    /// thread count: each set on its own).
    fn disks(&self, sets: ArrayView3<'_, f64>) -> Result<SurfaceSets, MetricError> {
        let (m, p, n) = sets.dim();
        super::prepared::check_points(sets)?;
        if p <= self.params.neighbours {
            return Err(invalid(
                "neighbours",
                self.params.neighbours,
                format!("the sets have P = {p} points, so at most {} neighbours per point; sample more points per set or lower it", p.saturating_sub(1)),
            ));
        }
        if n <= self.params.dimension {
            return Err(invalid(
                "dimension",
                self.params.dimension,
                format!("the sets have N = {n} coordinates; a kernel's dimension is below N"),
            ));
        }
        let periods = self.period.for_dims(n)?;
        let periods: Vec<f64> = (0..n).map(|k| periods.radians(k)).collect();
        let sets: Vec<Disks> = (0..m)
            .into_par_iter()
            .map(|s| Disks::new(sets.index_axis(Axis(0), s), &self.params, &periods))
            .collect();
        Ok(SurfaceSets { sets, periods })
    }
}

impl SetMetric for Surface {
    fn name(&self) -> &str {
        "surface"
    }

    fn check_kernels(&self, kernels: KernelShape) -> Result<(), InvalidParameter> {
        if kernels.dimension == self.params.dimension {
            return Ok(());
        }
        let k = kernels.dimension;
        Err(InvalidParameter::new(
            "metric.params",
            "dimension",
            self.params.dimension,
            format!("the agent's kernels have dimension {k} (motors minus the dimension of the sensor's configuration); set dimension = {k}"),
        ))
    }

    fn prepared_bytes(&self, sets: usize, points: usize, coordinates: usize) -> u64 {
        prepared_bytes(sets, points, coordinates, self.params.dimension)
    }

    fn forecast(&self, kernels: KernelShape, sets: usize, points: usize) -> Option<WorkForecast> {
        if kernels.dimension < 2 || sets < 2 {
            return None;
        }
        let work = sets as f64 * (sets as f64 - 1.0) * (points as f64).powi(2);
        Some(WorkForecast {
            core_seconds: work / DISK_PAIRS_PER_CORE_SECOND,
            what: format!("the surface metric measures each of their {points} points against the other set's tangent disks, about {work:.1e} point–disk pairs before pruning"),
        })
    }

    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
        if a.ncols() != b.ncols() {
            return Err(MetricError::DimensionMismatch {
                a: a.ncols(),
                b: b.ncols(),
            });
        }
        let one = |x: ArrayView2<'_, f64>| -> Result<SurfaceSets, MetricError> {
            let (p, n) = x.dim();
            self.disks(
                x.into_shape_with_order((1, p, n))
                    .map_err(|_| MetricError::EmptySets { shape: (1, p, n) })?,
            )
        };
        let (a, b) = (one(a)?, one(b)?);
        Ok(pair(&a.sets[0], &b.sets[0], &a.periods))
    }

    fn prepare(
        &self,
        sets: ArrayView3<'_, f64>,
    ) -> Result<Option<Box<dyn PreparedPairs>>, MetricError> {
        Ok(Some(Box::new(self.disks(sets)?)))
    }
}

/// The rate of the surface metric (blocks of eight tangent disks pruned by their
/// bounding balls), in units of `M (M − 1) P²` per core-second: measured on the 1288
/// sets of 600 points of `experiments/planar-arm-5.toml` (`smspace run`, release, AVX2
/// path): 6.0·10¹¹ in about 190 s of CPU, 3.1·10⁹ per core-second.
pub const DISK_PAIRS_PER_CORE_SECOND: f64 = 3.1e9;

/// Bytes the surface metric holds for `sets` sets of `points` points of `dims`
/// coordinates with tangent planes of `dimension` (what [`SetMetric::prepare`] makes:
/// the points twice, in two layouts, the tangent directions, the radii, the blocks).
pub fn prepared_bytes(sets: usize, points: usize, dims: usize, dimension: usize) -> u64 {
    let lanes = points.div_ceil(LANES) * LANES;
    let per_set = points * dims + lanes * dims * (1 + dimension) + lanes + 2 * lanes / LANES;
    (sets as u64).saturating_mul(per_set as u64 * 8)
}

/// The disks of every set.
struct SurfaceSets {
    sets: Vec<Disks>,
    periods: Vec<f64>,
}

impl PreparedPairs for SurfaceSets {
    fn distance(&self, i: usize, j: usize) -> Result<f64, MetricError> {
        let (i, j) = (i.min(j), i.max(j));
        Ok(pair(&self.sets[i], &self.sets[j], &self.periods))
    }
}

/// Points of a set measured together (one block of lanes).
const LANES: usize = 8;

/// One set's points (wrapped, in a nearest-neighbour order) and their disks, in blocks
/// of [`LANES`] consecutive points laid out lane by lane (the last block padded with
/// copies of the last point, which change no minimum).
struct Disks {
    points: usize,
    dims: usize,
    k: usize,
    /// `[point][n]`.
    coords: Vec<f64>,
    /// `[block][n][lane]`.
    lanes: Vec<[f64; LANES]>,
    /// `[block][j][n][lane]`: the orthonormal tangent directions `T_b`.
    tangents: Vec<[f64; LANES]>,
    /// `[block]`: `ρ_b` of every lane.
    radius: Vec<[f64; LANES]>,
    /// `[block]`: the middle point of the block.
    centres: Vec<usize>,
    /// `[block]`: `max_b (g(centre, b) + ρ_b)` over the block: no point of its disks is
    /// farther from the centre.
    reach: Vec<f64>,
}

impl Disks {
    fn new(set: ArrayView2<'_, f64>, params: &SurfaceParams, periods: &[f64]) -> Self {
        let (p, n) = set.dim();
        let k = params.dimension;
        let raw: Vec<f64> = set
            .outer_iter()
            .flat_map(|x| {
                x.iter()
                    .zip(periods)
                    .map(|(&v, &t)| wrap(v, t))
                    .collect::<Vec<_>>()
            })
            .collect();
        let order = tour(&raw, p, n, periods);
        let mut coords = Vec::with_capacity(p * n);
        for &i in &order {
            coords.extend_from_slice(&raw[i * n..(i + 1) * n]);
        }
        let mut tangents = vec![0.0; p * k * n];
        let mut radius = vec![0.0; p];
        let mut near: Vec<(f64, usize)> = Vec::with_capacity(p);
        let mut offset = vec![0.0; n];
        for b in 0..p {
            near.clear();
            for q in (0..p).filter(|&q| q != b) {
                near.push((dist2(&coords, b, q, n, periods), q));
            }
            let count = params.neighbours;
            near.select_nth_unstable_by(count - 1, |x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            let nearest = near[..count]
                .iter()
                .fold(f64::INFINITY, |m, &(d, _)| m.min(d));
            radius[b] = params.radius_scale * nearest.sqrt();
            let mut moment = faer::Mat::<f64>::zeros(n, n);
            for &(_, q) in &near[..count] {
                for c in 0..n {
                    offset[c] = swrap(coords[q * n + c] - coords[b * n + c], periods[c]);
                }
                for r in 0..n {
                    for c in 0..n {
                        moment[(r, c)] += offset[r] * offset[c];
                    }
                }
            }
            // An overflowing moment (coordinates near f64::MAX) does not converge: the
            // coordinate axes then, and the distances report the overflow.
            let (values, vectors) = crate::linalg::self_adjoint_eigen(moment.as_ref())
                .unwrap_or_else(|_| (vec![0.0; n], faer::Mat::identity(n, n)));
            let mut rank: Vec<usize> = (0..n).collect();
            rank.sort_by(|&x, &y| values[y].total_cmp(&values[x]).then(x.cmp(&y)));
            for (j, &e) in rank[..k].iter().enumerate() {
                for c in 0..n {
                    tangents[(b * k + j) * n + c] = vectors[(c, e)];
                }
            }
        }
        let blocks = p.div_ceil(LANES);
        let lane = |q: usize, l: usize| (q * LANES + l).min(p - 1);
        let mut lanes = vec![[0.0; LANES]; blocks * n];
        let mut tangent_lanes = vec![[0.0; LANES]; blocks * k * n];
        let mut radius_lanes = vec![[0.0; LANES]; blocks];
        for q in 0..blocks {
            for l in 0..LANES {
                let b = lane(q, l);
                for c in 0..n {
                    lanes[q * n + c][l] = coords[b * n + c];
                    for j in 0..k {
                        tangent_lanes[(q * k + j) * n + c][l] = tangents[(b * k + j) * n + c];
                    }
                }
                radius_lanes[q][l] = radius[b];
            }
        }
        let (centres, reach) = (0..blocks)
            .map(|q| {
                let members = q * LANES..((q + 1) * LANES).min(p);
                let centre = (members.start + members.end) / 2;
                let reach = members
                    .map(|b| dist2(&coords, centre, b, n, periods).sqrt() + radius[b])
                    .fold(0.0, f64::max);
                // A hair more than the rounded sums keeps the bound safe.
                (centre, reach * (1.0 + 1e-12) + 1e-300)
            })
            .unzip();
        Self {
            points: p,
            dims: n,
            k,
            coords,
            lanes,
            tangents: tangent_lanes,
            radius: radius_lanes,
            centres,
            reach,
        }
    }
}

/// `g(x_i, x_j)²` within one `[point][n]` array of wrapped points.
#[inline]
fn dist2(coords: &[f64], i: usize, j: usize, n: usize, periods: &[f64]) -> f64 {
    let mut d2 = 0.0;
    for c in 0..n {
        let u = swrap(coords[i * n + c] - coords[j * n + c], periods[c]);
        d2 += u * u;
    }
    d2
}

/// A greedy nearest-neighbour order of the `p` points: from point 0, always the nearest
/// point not yet taken (ties to the lower index).
fn tour(coords: &[f64], p: usize, n: usize, periods: &[f64]) -> Vec<usize> {
    let mut taken = vec![false; p];
    let mut order = Vec::with_capacity(p);
    let mut at = 0;
    for _ in 0..p {
        taken[at] = true;
        order.push(at);
        let mut best = (f64::INFINITY, usize::MAX);
        for q in (0..p).filter(|&q| !taken[q]) {
            let d = dist2(coords, at, q, n, periods);
            if d < best.0 {
                best = (d, q);
            }
        }
        at = best.1;
        if at == usize::MAX {
            break;
        }
    }
    order
}

/// `ρ_s(A, B)`, with the pass compiled for this CPU's best instruction set (chosen at
/// run time; the same arithmetic, so the same values, on every path).
fn pair(a: &Disks, b: &Disks, periods: &[f64]) -> f64 {
    let call = PairCall { a, b, periods };
    match super::kernel::simd() {
        #[cfg(target_arch = "x86_64")]
        super::kernel::Simd::Avx512(v4) => v4.vectorize(call),
        #[cfg(target_arch = "x86_64")]
        super::kernel::Simd::Avx2(v3) => v3.vectorize(call),
        super::kernel::Simd::Portable => pulp::NullaryFnOnce::call(call),
    }
}

/// One pair, as work for `pulp`'s target-feature context.
struct PairCall<'a> {
    a: &'a Disks,
    b: &'a Disks,
    periods: &'a [f64],
}

impl pulp::NullaryFnOnce for PairCall<'_> {
    type Output = f64;

    #[inline(always)]
    fn call(self) -> f64 {
        let c2 = directed(self.a, self.b, 0.0, self.periods);
        directed(self.b, self.a, c2, self.periods).sqrt()
    }
}

/// `max(c2, h_s(A, B)²)`.
#[inline(always)]
fn directed(a: &Disks, b: &Disks, mut c2: f64, periods: &[f64]) -> f64 {
    let n = a.dims;
    let blocks = b.centres.len();
    let mut hint = 0;
    for i in 0..a.points {
        let x = &a.coords[i * n..(i + 1) * n];
        let mut best = f64::INFINITY;
        let mut best_at = hint;
        for t in 0..blocks {
            let q = around(hint, t, blocks);
            // No disk of the block is nearer than g(a, centre) − reach.
            let gap = point2(x, b, b.centres[q], periods).sqrt() - b.reach[q];
            if gap > 0.0 && gap * gap >= best {
                continue;
            }
            let d2 = block2(x, b, q, periods)
                .into_iter()
                .fold(f64::INFINITY, f64::min);
            if d2 < best {
                best = d2;
                best_at = q;
                if best <= c2 {
                    // dist(a, B) ≤ c: a cannot raise c.
                    break;
                }
            }
        }
        hint = best_at;
        if best > c2 {
            c2 = best;
        }
    }
    c2
}

/// `g(x, b_j)²`.
#[inline(always)]
fn point2(x: &[f64], b: &Disks, j: usize, periods: &[f64]) -> f64 {
    let y = &b.coords[j * b.dims..(j + 1) * b.dims];
    let mut d2 = 0.0;
    for c in 0..b.dims {
        let u = swrap(x[c] - y[c], periods[c]);
        d2 += u * u;
    }
    d2
}

/// `dist(x, D_b)²` for the disks of the [`LANES`] points of block `q` of `b`.
#[inline(always)]
fn block2(x: &[f64], b: &Disks, q: usize, periods: &[f64]) -> [f64; LANES] {
    let (n, k) = (b.dims, b.k);
    let mut w2 = [0.0; LANES];
    let mut y2 = [0.0; LANES];
    let mut dots = [[0.0; LANES]; MAX_DIMENSION];
    for c in 0..n {
        let (xc, half, period) = (x[c], 0.5 * periods[c], periods[c]);
        let ys = &b.lanes[q * n + c];
        let mut u = [0.0; LANES];
        for l in 0..LANES {
            // swrap, as selects.
            let d = xc - ys[l];
            let d = if d > half { d - period } else { d };
            u[l] = if d < -half { d + period } else { d };
            w2[l] += u[l] * u[l];
        }
        for (j, dot) in dots.iter_mut().enumerate().take(k) {
            let t = &b.tangents[(q * k + j) * n + c];
            for l in 0..LANES {
                dot[l] += u[l] * t[l];
            }
        }
    }
    for dot in dots.iter().take(k) {
        for l in 0..LANES {
            y2[l] += dot[l] * dot[l];
        }
    }
    let rho = &b.radius[q];
    let mut d2 = [0.0; LANES];
    for l in 0..LANES {
        // The foot y, clamped to the rim when |y| > ρ.
        let y = y2[l].sqrt();
        let over = (y - rho[l]).max(0.0);
        d2[l] = (w2[l] - y2[l] + over * over).max(0.0);
    }
    d2
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metric::Period;
    use approx::assert_abs_diff_eq;
    use ndarray::Array3;
    use std::f64::consts::PI;

    /// A `side × side` grid on the plane `z = height` of R³ (no period), spacing `step`.
    fn plane(side: usize, step: f64, height: f64, shift: f64) -> Vec<[f64; 3]> {
        let mut points = Vec::new();
        for i in 0..side {
            for j in 0..side {
                points.push([i as f64 * step + shift, j as f64 * step + shift, height]);
            }
        }
        points
    }

    fn stack(sets: &[Vec<[f64; 3]>]) -> Array3<f64> {
        let p = sets[0].len();
        Array3::from_shape_fn((sets.len(), p, 3), |(s, i, c)| sets[s][i][c])
    }

    fn metric(period: Period) -> Surface {
        Surface::new(SurfaceParams::default(), period.into()).unwrap()
    }

    #[test]
    fn parallel_planes_are_as_far_as_their_gap_whatever_the_sampling() {
        // Two samples of parallel planes 0.1 apart, the second shifted by half a step:
        // the point metric sees the sampling (√(0.1² + 2·0.25²) ≈ 0.37), the disks
        // see the planes, apart from the rim of the grid.
        let a = plane(10, 0.5, 0.0, 0.0);
        let b = plane(10, 0.5, 0.1, 0.25);
        let sets = stack(&[a, b]);
        let m = metric(Period::None);
        let d = m
            .distance(sets.index_axis(Axis(0), 0), sets.index_axis(Axis(0), 1))
            .unwrap();
        // The corner (0, 0) of A lies 0.25√2 from B's corner disk centre, outside the
        // disk (radius 0.5) by 0: its foot is inside; so every point of A is 0.1 from B.
        // B's far corner (4.75, 4.75) is 0.25√2 ≈ 0.354 from A's (4.5, 4.5), within its
        // disk of radius 0.5: 0.1 again.
        assert_abs_diff_eq!(d, 0.1, epsilon = 1e-12);
    }

    #[test]
    fn a_set_is_at_zero_from_itself_and_the_metric_is_symmetric() {
        let a = plane(6, 0.4, 0.0, 0.0);
        let mut b = plane(6, 0.4, 0.0, 0.0);
        for (i, p) in b.iter_mut().enumerate() {
            p[2] = 0.3 * (p[0] + 0.5 * p[1]).sin() + 0.01 * i as f64;
        }
        let sets = stack(&[a.clone(), a, b]);
        let m = metric(Period::None);
        let pairs = m.prepare(sets.view()).unwrap().unwrap();
        assert_eq!(pairs.distance(0, 1).unwrap(), 0.0);
        let (x, y) = (pairs.distance(0, 2).unwrap(), pairs.distance(2, 0).unwrap());
        assert_eq!(x, y);
        assert!(x > 0.0);
        // The prepared pairs equal the one-pair call.
        let one = m
            .distance(sets.index_axis(Axis(0), 2), sets.index_axis(Axis(0), 0))
            .unwrap();
        assert_eq!(one, x);
    }

    #[test]
    fn the_disk_distance_equals_a_dense_brute_force() {
        // One point of B with its disk, against the minimum over a dense polar grid of
        // the disk, for points in every position (inside the cylinder, beyond the rim).
        let b = plane(5, 1.0, 0.0, 0.0);
        let sets = stack(&[b]);
        let m = metric(Period::None);
        let disks = m.disks(sets.view()).unwrap();
        let set = &disks.sets[0];
        let mut rng = 12345u64;
        let mut next = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((rng >> 11) as f64 / (1u64 << 53) as f64) * 6.0 - 1.0
        };
        let inf = [f64::INFINITY; 3];
        let centre = &set.coords[..3];
        let r = set.radius[0][0];
        let tangent = |j: usize, c: usize| set.tangents[j * 3 + c][0];
        for _ in 0..50 {
            let a = [next(), next(), next() * 0.5];
            let exact = block2(&a, set, 0, &inf)[0].sqrt();
            let mut dense = f64::INFINITY;
            for ri in 0..=200 {
                for ti in 0..400 {
                    let (rho, th) = (r * ri as f64 / 200.0, 2.0 * PI * ti as f64 / 400.0);
                    let d = (0..3)
                        .map(|c| {
                            let q = centre[c]
                                + rho * th.cos() * tangent(0, c)
                                + rho * th.sin() * tangent(1, c);
                            (a[c] - q).powi(2)
                        })
                        .sum::<f64>()
                        .sqrt();
                    dense = dense.min(d);
                }
            }
            assert!(exact <= dense + 1e-12, "{exact} > {dense}");
            assert!(dense - exact < 0.02 * r, "{exact} vs dense {dense}");
        }
    }

    #[test]
    fn a_plane_across_the_seam_is_one_surface() {
        // The plane z = 0 sampled across x = ±π: with the period, the points on either
        // side are neighbours, and a copy lifted by 0.2 is 0.2 away.
        let mut a = Vec::new();
        for i in 0..12 {
            for j in 0..8 {
                let x = wrap(PI - 1.1 + 0.2 * i as f64, 2.0 * PI);
                a.push([x, 0.2 * j as f64, 0.0]);
            }
        }
        let b: Vec<[f64; 3]> = a.iter().map(|p| [p[0], p[1], 0.2]).collect();
        let sets = stack(&[a, b]);
        let d = metric(Period::TwoPi)
            .distance(sets.index_axis(Axis(0), 0), sets.index_axis(Axis(0), 1))
            .unwrap();
        assert_abs_diff_eq!(d, 0.2, epsilon = 1e-12);
    }

    #[test]
    fn radius_scale_zero_is_the_point_metric() {
        let a = plane(5, 0.5, 0.0, 0.0);
        let b = plane(5, 0.5, 0.1, 0.2);
        let sets = stack(&[a, b]);
        let m = Surface::new(
            SurfaceParams {
                radius_scale: 0.0,
                ..SurfaceParams::default()
            },
            Period::None.into(),
        )
        .unwrap();
        let d = m
            .distance(sets.index_axis(Axis(0), 0), sets.index_axis(Axis(0), 1))
            .unwrap();
        let point = crate::metric::reference::hausdorff(
            sets.index_axis(Axis(0), 0),
            sets.index_axis(Axis(0), 1),
            Period::None,
        );
        assert_abs_diff_eq!(d, point, epsilon = 1e-12);
    }

    #[test]
    fn the_memory_estimate_is_what_prepare_holds() {
        for (side, n) in [(5, 3), (7, 3)] {
            let sets = Array3::from_shape_fn((3, side * side, n), |(s, p, c)| {
                (s * 100 + p * n + c) as f64 * 0.01
            });
            let disks = metric(Period::None).disks(sets.view()).unwrap();
            let held: usize = disks
                .sets
                .iter()
                .map(|d| {
                    d.coords.len()
                        + LANES * (d.lanes.len() + d.tangents.len() + d.radius.len())
                        + d.centres.len()
                        + d.reach.len()
                })
                .sum();
            assert_eq!(
                prepared_bytes(3, side * side, n, 2),
                held as u64 * 8,
                "P = {}",
                side * side
            );
        }
    }

    #[test]
    fn bad_parameters_and_sets_name_the_key() {
        let bad = |p: SurfaceParams| {
            Surface::new(p, Period::None.into())
                .unwrap_err()
                .to_string()
        };
        let e = bad(SurfaceParams {
            dimension: 0,
            ..Default::default()
        });
        assert!(e.contains("dimension"), "{e}");
        let e = bad(SurfaceParams {
            neighbours: 1,
            ..Default::default()
        });
        assert!(e.contains("neighbours"), "{e}");
        let e = bad(SurfaceParams {
            radius_scale: f64::NAN,
            ..Default::default()
        });
        assert!(e.contains("radius_scale"), "{e}");
        let few = Array3::<f64>::zeros((2, 5, 3));
        let e = metric(Period::None)
            .prepare(few.view())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("neighbours") && e.contains("P = 5"), "{e}");
        let mut nan = Array3::<f64>::zeros((2, 20, 3));
        nan[[1, 3, 2]] = f64::NAN;
        let e = metric(Period::None)
            .prepare(nan.view())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("finite"), "{e}");
    }
}
