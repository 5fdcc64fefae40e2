//! The `k` nearest sets of every set, exact, without the `M × M` matrix.
//!
//! For a metric (the Hausdorff distance `ρ` satisfies the triangle inequality, since
//! `g` does), `ρ(i, j) ≥ |ρ(i, p) − ρ(j, p)|` for every pivot set `p`. Pivots are
//! chosen by farthest-first traversal ([`crate::neighbours`]: set 0, then the set
//! farthest from all pivots so far), and their distances to every set are computed
//! once (`pivots × M` pairs). For each query set `i`:
//!
//! 1. the lower bound `L(j) = max_p |ρ(i, p) − ρ(j, p)|` of every other set;
//! 2. exact distances to the `k` sets of smallest `L`, giving a radius `τ` (the `k`-th
//!    smallest distance so far);
//! 3. the remaining sets with `L(j) ≤ τ`, by increasing `L`, each measured with an
//!    early abort as soon as `ρ(i, j) > τ` is proven; `τ` shrinks as better sets come.
//!
//! Ties are broken by the smaller index, so the lists equal the first `k` entries of
//! the sorted rows of the full matrix (diagonal excluded). Memory: `pivots × M` for the
//! pivot table, `rows × k` for the output and `O(M)` per thread. Without the triangle
//! inequality ([`MetricKind::MeanHausdorff`], or a [`SetMetric`] whose
//! [`is_metric`](SetMetric::is_metric) is false) no pivots are used: every pair of a
//! row is measured, still in `O(M)` memory per thread.
//!
//! [`knn`] runs a built-in metric on its SIMD kernels, with early exits once a pair is
//! proven farther than `τ`; [`knn_with`] runs any [`SetMetric`] through the same rows,
//! threads, memory check, progress and pruning (one call per pair, no early exit).

use std::ops::Range;

use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::kernel::{Driver, Eval, Scratch};
use super::tiles::Measure;
use super::{
    check_rows, closure_for, DistanceParams, MetricError, MetricKind, PreparedSets, SetMetric,
    SetsView,
};
use crate::neighbours::FarthestFirst;
use crate::params::{CheckParams, InvalidParameter};
use crate::progress::Progress;

/// Relative safety margin on the pivot lower bounds (rounding of the distances).
const PIVOT_MARGIN: f64 = 1e-10;

/// Parameters of the nearest-set search. Unchecked; [`KnnParams::check`] validates them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct KnnParams {
    /// Number of nearest sets per set. Default: 15.
    pub k: usize,
    /// Number of pivot sets for the triangle-inequality bounds. Default: 24. Zero
    /// measures every pair.
    pub pivots: usize,
}

impl Default for KnnParams {
    fn default() -> Self {
        Self { k: 15, pivots: 24 }
    }
}

/// Validated [`KnnParams`].
#[derive(Debug, Clone, PartialEq)]
pub struct KnnValidParams(KnnParams);

impl std::ops::Deref for KnnValidParams {
    type Target = KnnParams;
    fn deref(&self) -> &KnnParams {
        &self.0
    }
}

/// Most pivots of the nearest-set search.
pub const MAX_PIVOTS: usize = 4_096;

impl KnnParams {
    /// Default parameters.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets `k` (default 15).
    pub fn k(mut self, k: usize) -> Self {
        self.k = k;
        self
    }

    /// Sets the number of pivots (default 24).
    pub fn pivots(mut self, pivots: usize) -> Self {
        self.pivots = pivots;
        self
    }

    /// Checks that `k ≥ 1` and `pivots ≤` [`MAX_PIVOTS`] (the bound `k < M` is checked
    /// against the data).
    pub fn check(&self) -> Result<KnnValidParams, MetricError> {
        if self.k == 0 {
            return Err(InvalidParameter::new(
                "knn",
                "k",
                0,
                "ask for at least 1 nearest set (--knn K with K ≥ 1)",
            )
            .into());
        }
        if self.pivots > MAX_PIVOTS {
            return Err(InvalidParameter::new(
                "knn",
                "pivots",
                self.pivots,
                format!("at most {MAX_PIVOTS} (the default {} prunes well; every pivot costs M distances and 8·M bytes)", KnnParams::default().pivots),
            )
            .into());
        }
        Ok(KnnValidParams(self.clone()))
    }
}

impl CheckParams for KnnParams {
    type Valid = KnnValidParams;
    type Error = MetricError;
    fn check_params(&self) -> Result<KnnValidParams, MetricError> {
        self.check()
    }
}

/// Nearest sets of a block of rows: the crate's one kNN type,
/// [`crate::neighbours::Knn`].
pub use crate::neighbours::Knn;

/// The `k` nearest sets of each set in rows `rows` of `(M, P, N)` kernel sets (any
/// strides) under a built-in metric: equal to the first `k` entries of the rows of
/// [`distance_matrix`](super::distance_matrix) sorted by `(distance, index)`, the set
/// itself left out.
///
/// ```
/// use smspace::metric::{knn, DistanceParams, KnnParams, MetricKind, Period};
/// use smspace::progress::Silent;
/// // Sets of one point at 0, 1, 3, 7 on a line (points: the hausdorff metric).
/// let sets = ndarray::Array3::from_shape_fn((4, 1, 1), |(i, _, _)| [0.0, 1.0, 3.0, 7.0][i]);
/// let params = DistanceParams::new().metric(MetricKind::Hausdorff).period(Period::None);
/// let near = knn(sets.view(), &params, &KnnParams::new().k(2), 0..4, &Silent)?;
/// assert_eq!(near.indices.row(2).to_vec(), vec![1, 0]);
/// assert_eq!(near.distances.row(2).to_vec(), vec![2.0, 3.0]);
/// # Ok::<(), smspace::metric::MetricError>(())
/// ```
pub fn knn<'a>(
    sets: impl Into<SetsView<'a>>,
    distance: &DistanceParams,
    params: &KnnParams,
    rows: Range<usize>,
    progress: &dyn Progress,
) -> Result<Knn, MetricError> {
    let distance = distance.check()?;
    let params = params.check()?;
    let sets = closure_for(sets.into(), distance.kind())?;
    let (m, p, n) = sets.points().dim();
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    check_rows(&rows, m)?;
    check_knn_memory(
        distance.memory_limit_bytes(),
        m,
        &params,
        knn_bytes(m, p, n, rows.len(), &params),
    )?;
    let measure = Measure::kernel(sets, distance.kind(), distance.period())?;
    knn_measured(measure, &params, rows, progress)
}

/// [`knn`] for any [`SetMetric`] (a user-defined one included): on its kernel when it
/// has one ([`SetMetric::kernel`]), else one call per pair; pivots prune only when
/// [`SetMetric::is_metric`]. Of `distance` only the memory limit is read.
pub fn knn_with<'a>(
    sets: impl Into<SetsView<'a>>,
    metric: &dyn SetMetric,
    distance: &DistanceParams,
    params: &KnnParams,
    rows: Range<usize>,
    progress: &dyn Progress,
) -> Result<Knn, MetricError> {
    let params = params.check()?;
    let sets: SetsView<'a> = sets.into();
    let sets = sets.reborrow();
    let (m, p, n) = sets.points().dim();
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    check_rows(&rows, m)?;
    let needed = match metric.kernel() {
        Some(_) => knn_bytes(m, p, n, rows.len(), &params),
        None => search_bytes(m, rows.len(), &params),
    };
    check_knn_memory(distance.memory_limit_bytes, m, &params, needed)?;
    knn_measured(Measure::new(sets, metric)?, &params, rows, progress)
}

fn check_knn_memory(
    limit: Option<u64>,
    sets: usize,
    params: &KnnParams,
    needed: u64,
) -> Result<(), MetricError> {
    match limit {
        Some(available) if needed > available => Err(MetricError::KnnOutOfMemory {
            sets,
            k: params.k,
            needed,
            available,
        }),
        _ => Ok(()),
    }
}

/// Bytes [`knn`] needs: layout, pivot table, output and per-thread buffers.
pub fn knn_bytes(sets: usize, points: usize, dims: usize, rows: usize, params: &KnnParams) -> u64 {
    PreparedSets::estimate_bytes_with_curves(sets, points, dims) + search_bytes(sets, rows, params)
}

/// Bytes of the search without the sets' layout: pivot table, output, per-thread
/// buffers.
fn search_bytes(sets: usize, rows: usize, params: &KnnParams) -> u64 {
    let threads = rayon::current_num_threads() as u64;
    (params.pivots as u64) * (sets as u64) * 8
        + (rows as u64) * (params.k as u64) * 16
        + threads * (sets as u64) * 24
}

/// [`knn`] on prepared sets (the point metric is the one they were prepared with).
pub fn knn_prepared(
    prepared: &PreparedSets,
    metric: MetricKind,
    params: &KnnValidParams,
    rows: Range<usize>,
    progress: &dyn Progress,
) -> Result<Knn, MetricError> {
    let m = prepared.len();
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    check_rows(&rows, m)?;
    knn_measured(Measure::prepared(prepared, metric)?, params, rows, progress)
}

/// The search itself (module docs), on the sets and metric of `measure`.
fn knn_measured(
    measure: Measure<'_>,
    params: &KnnValidParams,
    rows: Range<usize>,
    progress: &dyn Progress,
) -> Result<Knn, MetricError> {
    let m = measure.len();
    let k = params.k;
    if k == 0 || k >= m {
        return Err(MetricError::BadK { k, max: m - 1 });
    }
    let (is_metric, tolerance) = measure.bounds();
    let pivots = if is_metric { params.pivots.min(m) } else { 0 };
    let table = pivot_table(&measure, pivots, progress);

    progress.start("neighbours", rows.len() as u64);
    let mut indices = Array2::zeros((rows.len(), k));
    let mut distances = Array2::zeros((rows.len(), k));
    let index_rows = indices
        .as_slice_mut()
        .expect("a new array is in standard layout");
    let distance_rows = distances
        .as_slice_mut()
        .expect("a new array is in standard layout");
    index_rows
        .par_chunks_mut(k)
        .zip(distance_rows.par_chunks_mut(k))
        .enumerate()
        .for_each_init(
            || (Scratch::default(), Vec::new(), Vec::new()),
            |(scratch, bounds, candidates), (r, (out_index, out_distance))| {
                let driver = QueryDriver {
                    margin: 3.0 * tolerance,
                    query: rows.start + r,
                    sets: m,
                    k,
                    pivots,
                    table: &table,
                    bounds,
                    candidates,
                    out_index,
                    out_distance,
                };
                measure.drive(scratch, driver);
                progress.advance(1);
            },
        );
    progress.finish();
    measure.failure(|s| s)?;
    if let Some(((r, c), &value)) = distances.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(MetricError::NonFiniteDistance {
            i: rows.start + r,
            j: indices[[r, c]],
            value,
        });
    }
    Ok(Knn {
        rows,
        indices,
        distances,
    })
}

/// `[t][j]`: distance from pivot `t` to set `j`, pivots by farthest-first traversal.
fn pivot_table(measure: &Measure<'_>, pivots: usize, progress: &dyn Progress) -> Vec<f64> {
    let m = measure.len();
    let mut table = vec![0.0; pivots * m];
    if pivots == 0 {
        return table;
    }
    progress.start("pivots", pivots as u64);
    let mut traversal = FarthestFirst::new(m, 0).expect("there are at least 2 sets");
    for row in table.chunks_mut(m) {
        const COLUMNS: usize = 64;
        let pivot = traversal.next_landmark();
        row.par_chunks_mut(COLUMNS).enumerate().for_each_init(
            Scratch::default,
            |scratch, (c, out)| {
                let driver = ColumnDriver {
                    row: pivot,
                    first: c * COLUMNS,
                    out,
                };
                measure.drive(scratch, driver);
            },
        );
        traversal.add(&*row);
        progress.advance(1);
    }
    progress.finish();
    table
}

struct ColumnDriver<'a> {
    row: usize,
    first: usize,
    out: &'a mut [f64],
}

impl Driver for ColumnDriver<'_> {
    type Output = ();
    #[inline(always)]
    fn drive<E: Eval>(self, eval: &mut E) {
        for (c, slot) in self.out.iter_mut().enumerate() {
            let j = self.first + c;
            *slot = if j == self.row {
                0.0
            } else {
                eval.distance(self.row, j, f64::INFINITY)
                    .unwrap_or(f64::INFINITY)
            };
        }
    }
}

struct QueryDriver<'a> {
    /// Absolute widening of the pivot bounds: the computed distances may lie this much
    /// below the exact ones (three times the metric's tolerance covers the three
    /// distances of a triangle).
    margin: f64,
    query: usize,
    sets: usize,
    k: usize,
    pivots: usize,
    table: &'a [f64],
    bounds: &'a mut Vec<f64>,
    candidates: &'a mut Vec<(f64, u32)>,
    out_index: &'a mut [usize],
    out_distance: &'a mut [f64],
}

/// The best `k` so far, sorted by `(distance, index)`: the running answer of the
/// nearest-set searches (here and through the landmarks, [`super::landmarks`]).
pub(super) struct Best {
    pub(super) entries: Vec<(f64, usize)>,
    k: usize,
}

/// Candidates `(lower bound, index)` by increasing bound, ties by index.
fn by_bound(x: &(f64, u32), y: &(f64, u32)) -> std::cmp::Ordering {
    x.0.total_cmp(&y.0).then(x.1.cmp(&y.1))
}

impl Best {
    pub(super) fn new(k: usize) -> Self {
        Self {
            entries: Vec::with_capacity(k + 1),
            k,
        }
    }

    /// The `k`-th distance (infinite until there are `k` entries).
    pub(super) fn radius(&self) -> f64 {
        if self.entries.len() < self.k {
            f64::INFINITY
        } else {
            self.entries[self.k - 1].0
        }
    }

    pub(super) fn offer(&mut self, d: f64, j: usize) {
        let before = |e: &(f64, usize)| e.0 < d || (e.0 == d && e.1 < j);
        if self.entries.len() == self.k {
            let last = self.entries[self.k - 1];
            if !(d < last.0 || (d == last.0 && j < last.1)) {
                return;
            }
            self.entries.pop();
        }
        let at = self.entries.partition_point(before);
        self.entries.insert(at, (d, j));
    }

    /// Writes the entries, nearest first.
    pub(super) fn write(&self, index: &mut [usize], distance: &mut [f64]) {
        for (e, &(d, j)) in self.entries.iter().enumerate() {
            index[e] = j;
            distance[e] = d;
        }
    }

    /// Measures the `k` candidates `(lower bound, index)` of smallest bound in full
    /// (`measure(j, limit)`, here without a limit) and returns the others.
    pub(super) fn measure_smallest<'c>(
        &mut self,
        candidates: &'c mut [(f64, u32)],
        mut measure: impl FnMut(usize, f64) -> Option<f64>,
    ) -> &'c mut [(f64, u32)] {
        let first = self.k.min(candidates.len());
        if first > 0 && first < candidates.len() {
            candidates.select_nth_unstable_by(first - 1, by_bound);
        }
        let (smallest, rest) = candidates.split_at_mut(first);
        for &(_, j) in smallest.iter() {
            let d = measure(j as usize, f64::INFINITY).unwrap_or(f64::INFINITY);
            self.offer(d, j as usize);
        }
        rest
    }

    /// Measures the candidates whose bound is within the `k`-th distance, by
    /// increasing bound while it stays within it (the distance shrinks as better ones
    /// come), each with an early exit at it.
    pub(super) fn measure_within(
        &mut self,
        rest: &mut [(f64, u32)],
        mut measure: impl FnMut(usize, f64) -> Option<f64>,
    ) {
        let radius = self.radius();
        let mut kept = 0;
        for e in 0..rest.len() {
            if rest[e].0 <= radius {
                rest.swap(kept, e);
                kept += 1;
            }
        }
        let rest = &mut rest[..kept];
        rest.sort_unstable_by(by_bound);
        for &(bound, j) in rest.iter() {
            let radius = self.radius();
            if bound > radius {
                break;
            }
            if let Some(d) = measure(j as usize, radius) {
                self.offer(d, j as usize);
            }
        }
    }
}

impl Driver for QueryDriver<'_> {
    type Output = ();
    #[inline(always)]
    fn drive<E: Eval>(self, eval: &mut E) {
        let QueryDriver {
            margin,
            query,
            sets,
            k,
            pivots,
            table,
            bounds,
            candidates,
            out_index,
            out_distance,
        } = self;
        let mut best = Best::new(k);
        if pivots == 0 {
            for j in (0..sets).filter(|&j| j != query) {
                let limit = best.radius();
                if let Some(d) = eval.distance(query, j, limit) {
                    best.offer(d, j);
                }
            }
        } else {
            bounds.clear();
            bounds.resize(sets, 0.0);
            for t in 0..pivots {
                let column = &table[t * sets..(t + 1) * sets];
                let x = column[query];
                for (bound, &y) in bounds.iter_mut().zip(column.iter()) {
                    let gap = (x - y).abs() - PIVOT_MARGIN * (x + y) - margin;
                    if gap > *bound {
                        *bound = gap;
                    }
                }
            }
            candidates.clear();
            candidates.extend(
                bounds
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != query)
                    .map(|(j, &b)| (b, j as u32)),
            );
            let mut measure = |j: usize, limit: f64| eval.distance(query, j, limit);
            let rest = best.measure_smallest(candidates, &mut measure);
            best.measure_within(rest, &mut measure);
        }
        best.write(out_index, out_distance);
    }
}
