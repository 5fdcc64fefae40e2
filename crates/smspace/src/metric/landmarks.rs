//! Distances to landmark sets: the landmarks' own `L × L` matrix and every set's `q`
//! nearest landmarks, without the `M × M` matrix (the scale path).
//!
//! # Landmarks
//!
//! `L ≤ M` landmark sets are chosen by one of two rules ([`LandmarkSelection`]):
//!
//! - **random** (the default): `L` distinct sets drawn uniformly (seeded; in the order
//!   drawn), an unbiased sample of the sets. Costs nothing to choose.
//! - **max–min** (farthest first, Gonzalez 1985; [`crate::neighbours`]): a seeded
//!   start `l_1` drawn uniformly from `0..M`, then
//!   `l_{t+1} = argmax_j min_{u ≤ t} ρ(l_u, j)` (smallest `j` on ties). The landmarks
//!   spread evenly over the manifold of sets and the covering radius is at most twice the
//!   best any `L` sets achieve, but choosing them measures every set against every
//!   landmark: `L·M` distances (hours at `M = 10⁵`).
//!
//! Either way the covering radius `r = max_j min_u ρ(l_u, j)` is reported (exact): a
//! feature of the manifold shorter than about `2r` is not resolved by the landmarks.
//!
//! # What is measured
//!
//! - `Δ = (ρ(l_a, l_b))`, the `L × L` matrix of the landmarks;
//! - for every set `j`, its `q` nearest landmarks ([`LandmarkParams::nearest`]) with
//!   their distances, nearest first, ties by the landmark's position: the first `q`
//!   entries of the row `(ρ(j, l_1), …, ρ(j, l_L))` sorted by `(distance, position)`,
//!   exactly.
//!
//! With random landmarks the lists are found like [`super::knn`]'s, with the landmarks
//! as the only candidates: `T` = [`LANDMARK_PIVOTS`] pivots among the landmarks (farthest
//! first in `Δ` from the first one) are measured against every set (`T·M` distances);
//! then for set `j`, `ρ(j, l_a) ≥ max_t |ρ(j, p_t) − Δ(p_t, l_a)|` bounds every landmark,
//! the `q` of smallest bound are measured, and the others only while their bound is
//! below the `q`-th distance so far (each with an early exit). With max–min landmarks
//! the selection's columns give the lists directly.
//!
//! Every distance is the same call `ρ(M^min(l,j), M^max(l,j))` that
//! [`distance_matrix`](super::distance_matrix) makes, so every entry equals the full
//! matrix's bit for bit, for any number of threads.
//!
//! # Distances to the other landmarks
//!
//! An out-of-sample map reads a whole row `δ_a = ρ(j, l_a)`.
//! [`LandmarkDistances::distances_from`] gives it exactly on the `q` nearest landmarks
//! and, for the others, the triangle-inequality bound through them,
//!
//! ```text
//! δ_a ≤ δ̂_a = min_{u ∈ near(j)} (ρ(j, l_u) + Δ(u, a)),
//! ```
//!
//! which is within `2 ρ(j, l_near)` of the truth (`ρ(j, l_near)`, the distance to the
//! nearest landmark, at most the covering radius), small against the distance of a far
//! landmark. With `q ≥ L` every entry is exact.
//!
//! # The `k` nearest sets through the landmarks
//!
//! [`landmarks_and_knn_with`] also finds the exact `k` nearest of every member set
//! among the members (the kNN graph of the scale path) without the `O(M²)` pivot
//! bounds of [`super::knn`]. The members are grouped into clusters by their nearest
//! landmark; `r_j = ρ(j, l_{c(j)})`. For a query `i`, lower bounds of its distance to
//! every landmark,
//!
//! ```text
//! lb(i, a) = max( δ_q(i),  max_t |ρ(i, p_t) − Δ(p_t, a)|,  max_{u ∈ near(i)} Δ(u, a) − ρ(i, l_u) ),
//! ```
//!
//! exact on `near(i)` (`δ_q(i)`, its `q`-th nearest landmark distance, bounds every
//! landmark not in its list), give for every member `j`
//!
//! ```text
//! ρ(i, j) ≥ max( max_t |ρ(i, p_t) − ρ(j, p_t)|,  max_{a ∈ near(j)} lb(i, a) − ρ(j, l_a) )
//! ```
//!
//! (`|ρ(i, l_a) − ρ(j, l_a)|` where both are known). The members of the clusters of
//! `near(i)` are the first candidates: the `k` of smallest bound are measured, then the
//! others while their bound is within the `k`-th distance `τ`. Every other cluster `a`
//! is skipped when `lb(i, a) − max_{j ∈ a} r_j > τ`, and within a cluster (members by
//! decreasing `r_j`) the scan stops at the first `lb(i, a) − r_j > τ`; the rest pass
//! the member bound before they are measured (with an early exit at `τ`). Every skip is
//! proven by the triangle inequality (with margins for rounding), so the lists equal
//! [`super::knn_with`]'s on the members: nearest first, ties by the smaller index.
//!
//! # Cost
//!
//! Random: `L(L − 1)/2 + T·M` distances, plus about `q` to `3q` per set (the
//! `q` landmarks of smallest pivot bound first; the nearest few found then tighten the
//! others' bounds through `Δ`); memory `8 L² + 8 T M + 16 q M` bytes and the prepared
//! sets. Max–min: `L·M − L(L+1)/2` distances and `8 M L` more bytes for the columns
//! ([`landmark_bytes`]). The nearest sets: `O(L (T + q))` per query for the bounds, and
//! the distances the bounds do not rule out.

use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::seq::index::sample;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::kernel::{Driver, Eval, Scratch};
use super::knn::Best;
use super::tiles::Measure;
use super::{DistanceMatrix, Knn, MetricError, PreparedSets, SetMetric, SetsView};
use crate::neighbours::FarthestFirst;
use crate::params::{CheckParams, InvalidParameter};
use crate::progress::Progress;

mod through;

/// Sets per parallel task of a landmark's column.
const COLUMN_CHUNK: usize = 64;

/// Sets per parallel task of the nearest-landmark search.
const SEARCH_CHUNK: usize = 16;

/// Pivots of the nearest-landmark search among random landmarks (fewer when there are
/// fewer landmarks).
pub const LANDMARK_PIVOTS: usize = 24;

/// Nearest landmarks found first that tighten the bounds of the others in the
/// nearest-landmark search.
const NEAR_PIVOTS: usize = 4;

/// Relative safety margin on the pivot lower bounds (rounding of the distances).
const PIVOT_MARGIN: f64 = 1e-10;

/// How landmarks are chosen (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum LandmarkSelection {
    /// Farthest first from a seeded start (`L·M` distances to choose).
    MaxMin,
    /// Uniformly at random, seeded.
    #[default]
    Random,
}

impl std::fmt::Display for LandmarkSelection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::MaxMin => "max-min",
            Self::Random => "random",
        })
    }
}

/// Parameters of the landmarks (unchecked; [`LandmarkParams::check`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LandmarkParams {
    /// Number of landmarks `L` (at most `M`: all sets when `M ≤ L`). Default 2000.
    pub count: usize,
    /// How they are chosen. Default random.
    pub selection: LandmarkSelection,
    /// Seed of the start (max–min) or of the draw (random). Default 0.
    pub seed: u64,
    /// Nearest landmarks `q` measured exactly for every set (module docs). Default 16.
    pub nearest: usize,
}

impl Default for LandmarkParams {
    fn default() -> Self {
        Self {
            count: 2000,
            selection: LandmarkSelection::Random,
            seed: 0,
            nearest: 16,
        }
    }
}

/// Most landmarks: the `L × L` matrix of 20 000 landmarks is 3.2 GB.
pub const MAX_LANDMARKS: usize = 20_000;

/// Validated [`LandmarkParams`].
#[derive(Debug, Clone, PartialEq)]
pub struct LandmarkValidParams(LandmarkParams);

impl std::ops::Deref for LandmarkValidParams {
    type Target = LandmarkParams;
    fn deref(&self) -> &LandmarkParams {
        &self.0
    }
}

impl LandmarkParams {
    /// `count` landmarks chosen by `selection` from `seed`, each set's 16 nearest
    /// measured.
    pub fn new(count: usize, selection: LandmarkSelection, seed: u64) -> Self {
        Self {
            count,
            selection,
            seed,
            ..Self::default()
        }
    }

    /// Sets the number of nearest landmarks measured per set (default 16).
    pub fn nearest(mut self, nearest: usize) -> Self {
        self.nearest = nearest;
        self
    }

    /// Checks `3 ≤ count ≤` [`MAX_LANDMARKS`] and `nearest ≥ 1` (errors name the
    /// `[scale]` keys).
    pub fn check(&self) -> Result<LandmarkValidParams, MetricError> {
        if !(3..=MAX_LANDMARKS).contains(&self.count) {
            return Err(InvalidParameter::new(
                "scale",
                "landmarks",
                self.count,
                format!("between 3 and {MAX_LANDMARKS} landmark sets (2000 to 4000 cover the paper's arm; each costs L distances and 8·L bytes)"),
            )
            .into());
        }
        if !(1..=MAX_LANDMARKS).contains(&self.nearest) {
            return Err(InvalidParameter::new(
                "scale",
                "nearest",
                self.nearest,
                "at least 1 nearest landmark per set (16 places sets well; every one costs a distance per set)",
            )
            .into());
        }
        Ok(LandmarkValidParams(self.clone()))
    }
}

impl CheckParams for LandmarkParams {
    type Valid = LandmarkValidParams;
    type Error = MetricError;
    fn check_params(&self) -> Result<LandmarkValidParams, MetricError> {
        self.check()
    }
}

/// The landmarks, their matrix and every set's nearest landmarks.
#[derive(Debug, Clone, PartialEq)]
pub struct LandmarkDistances {
    /// The landmark sets (rows of the sets), in the order chosen.
    pub rows: Vec<usize>,
    /// How they were chosen.
    pub selection: LandmarkSelection,
    /// `max_j min_u ρ(l_u, j)`: the largest distance of a set to its nearest landmark.
    pub covering_radius: f64,
    /// `(L, L)`: the landmarks' distance matrix, `landmarks[a, b] = ρ(l_a, l_b)`.
    pub landmarks: DistanceMatrix,
    /// `(M, q)`: the positions (in [`LandmarkDistances::rows`]) of every set's `q`
    /// nearest landmarks, nearest first (a landmark's first is itself).
    pub nearest: Array2<usize>,
    /// `(M, q)`: their distances, `nearest_distances[j, c] = ρ(j, l_nearest[j, c])`.
    pub nearest_distances: Array2<f64>,
}

impl LandmarkDistances {
    /// Number of landmarks `L`.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Always false: there are at least 3 landmarks.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Number of sets `M`.
    pub fn sets(&self) -> usize {
        self.nearest.nrows()
    }

    /// Nearest landmarks measured per set, `min(q, L)`.
    pub fn measured(&self) -> usize {
        self.nearest.ncols()
    }

    /// The distances of set `j` to every landmark, `out[a]` for landmark `a` (in the
    /// order of [`LandmarkDistances::rows`]): exact for its nearest landmarks, the
    /// triangle bound through them for the others (module docs).
    pub fn distances_from(&self, j: usize, out: &mut [f64]) {
        out.fill(f64::INFINITY);
        for (&u, &d) in self
            .nearest
            .row(j)
            .iter()
            .zip(self.nearest_distances.row(j))
        {
            for (slot, &far) in out.iter_mut().zip(self.landmarks.row(u)) {
                *slot = slot.min(d + far);
            }
        }
        for (&u, &d) in self
            .nearest
            .row(j)
            .iter()
            .zip(self.nearest_distances.row(j))
        {
            out[u] = d;
        }
    }

    /// The covering radius of the first `count` landmarks over every set: exact when
    /// `count = L`, else the triangle bound through each set's nearest landmarks, an
    /// upper bound.
    pub fn covering_radius_of_first(&self, count: usize) -> f64 {
        if count >= self.len() {
            return self.covering_radius;
        }
        // Each landmark's distance to the first `count` landmarks.
        let to_first: Vec<f64> = (0..self.len())
            .map(|u| {
                self.landmarks
                    .row(u)
                    .iter()
                    .take(count)
                    .copied()
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        (0..self.sets())
            .into_par_iter()
            .map(|j| {
                self.nearest
                    .row(j)
                    .iter()
                    .zip(self.nearest_distances.row(j))
                    .map(|(&u, &d)| if u < count { d } else { d + to_first[u] })
                    .fold(f64::INFINITY, f64::min)
            })
            .reduce(|| 0.0, f64::max)
    }
}

/// Bytes [`landmark_distances_with`] needs for `sets` sets of `points` points of `dims`
/// coordinates and `params`: the `(L, L)` matrix, the nearest lists, the pivot table
/// (random) or the `(M, L)` columns (max–min), and the prepared sets.
pub fn landmark_bytes(sets: usize, points: usize, dims: usize, params: &LandmarkParams) -> u64 {
    let (m, l) = (sets as u64, params.count.min(sets) as u64);
    let q = (params.nearest as u64).min(l);
    let search = match params.selection {
        LandmarkSelection::Random => (LANDMARK_PIVOTS as u64).min(l).saturating_mul(m),
        LandmarkSelection::MaxMin => m.saturating_mul(l),
    };
    l.saturating_mul(l)
        .saturating_add(search)
        .saturating_add(m.saturating_mul(2 * q))
        .saturating_add(2 * m)
        .saturating_mul(8)
        .saturating_add(PreparedSets::estimate_bytes_with_curves(sets, points, dims))
}

/// The landmarks of `sets` `(M, P, N)` under `metric`, their matrix and every set's
/// nearest landmarks (module docs); `min(L, M)` landmarks. Refused before any work when
/// [`landmark_bytes`] exceeds `memory_limit_bytes`. `progress` sees the stages
/// "landmarks" (counted in landmarks) and, for random landmarks, "nearest landmarks"
/// (counted in sets).
///
/// ```
/// use smspace::metric::landmarks::{landmark_distances_with, LandmarkParams, LandmarkSelection};
/// use smspace::metric::{distance_matrix, DistanceParams, MetricKind, Period};
/// use smspace::progress::Silent;
/// // Sets of one point at 0, 1, 3, 7, 8 on a line (points: the hausdorff metric).
/// let sets = ndarray::Array3::from_shape_fn((5, 1, 1), |(i, _, _)| [0.0, 1.0, 3.0, 7.0, 8.0][i]);
/// let params = DistanceParams::new().metric(MetricKind::Hausdorff).period(Period::None);
/// let metric = params.check()?.set_metric();
/// let chosen = LandmarkParams::new(3, LandmarkSelection::Random, 0).nearest(2).check()?;
/// let l = landmark_distances_with(sets.view(), metric.as_ref(), &chosen, None, &Silent)?;
/// assert_eq!(l.nearest.dim(), (5, 2));
/// let d = distance_matrix(sets.view(), &params, &Silent)?;
/// for j in 0..5 {
///     // The nearest landmark of every set, and its distance, as the full matrix says.
///     let a = l.nearest[[j, 0]];
///     let best = l.rows.iter().map(|&r| d[[j, r]]).fold(f64::INFINITY, f64::min);
///     assert_eq!(l.nearest_distances[[j, 0]], best);
///     assert_eq!(d[[j, l.rows[a]]], best);
/// }
/// # Ok::<(), smspace::metric::MetricError>(())
/// ```
pub fn landmark_distances_with<'a>(
    sets: impl Into<SetsView<'a>>,
    metric: &dyn SetMetric,
    params: &LandmarkValidParams,
    memory_limit_bytes: Option<u64>,
    progress: &dyn Progress,
) -> Result<LandmarkDistances, MetricError> {
    let sets: SetsView<'a> = sets.into();
    let sets = sets.reborrow();
    let (m, p, n) = sets.points().dim();
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    check_memory(
        m,
        params,
        landmark_bytes(m, p, n, params),
        memory_limit_bytes,
    )?;
    let measure = Measure::new(sets, metric)?;
    let (found, _) = select(&measure, params, progress);
    measure.failure(|s| s)?;
    Ok(found)
}

/// The landmarks of `sets` as [`landmark_distances_with`] finds them, and the `k`
/// nearest of each of `members` (set rows, increasing) among `members`, found through
/// the landmarks (module docs, "The `k` nearest sets through the landmarks"): equal to
/// [`knn_with`](super::knn_with) on the sets `members` (indices into `members`,
/// nearest first, ties by the smaller index). Without the triangle inequality
/// ([`SetMetric::is_metric`] false) the search measures every pair instead.
/// `progress` also sees "neighbours", counted in members.
pub fn landmarks_and_knn_with<'a>(
    sets: impl Into<SetsView<'a>>,
    metric: &dyn SetMetric,
    params: &LandmarkValidParams,
    members: &[usize],
    k: usize,
    memory_limit_bytes: Option<u64>,
    progress: &dyn Progress,
) -> Result<(LandmarkDistances, Knn), MetricError> {
    let sets: SetsView<'a> = sets.into();
    let sets = sets.reborrow();
    let (m, p, n) = sets.points().dim();
    if m < 2 {
        return Err(MetricError::TooFewSets { sets: m });
    }
    if let Some(&bad) = members.iter().find(|&&j| j >= m) {
        return Err(InvalidParameter::new(
            "knn",
            "members",
            bad,
            format!("set rows below {m}, the number of sets"),
        )
        .into());
    }
    if let Some(w) = members.windows(2).find(|w| w[0] >= w[1]) {
        return Err(InvalidParameter::new(
            "knn",
            "members",
            format!("{} then {}", w[0], w[1]),
            "increasing set rows",
        )
        .into());
    }
    if k == 0 || k >= members.len() {
        return Err(MetricError::BadK {
            k,
            max: members.len().saturating_sub(1),
        });
    }
    let lists = (members.len() as u64).saturating_mul(k as u64 * 16 + 16);
    let needed = landmark_bytes(m, p, n, params).saturating_add(lists);
    check_memory(m, params, needed, memory_limit_bytes)?;
    let measure = Measure::new(sets, metric)?;
    let (found, pivots) = select(&measure, params, progress);
    let knn = through::knn_through(&measure, &found, &pivots, members, k, progress);
    measure.failure(|s| s)?;
    Ok((found, knn))
}

/// Refuses `needed` bytes above the memory limit, before any work.
fn check_memory(
    sets: usize,
    params: &LandmarkValidParams,
    needed: u64,
    memory_limit_bytes: Option<u64>,
) -> Result<(), MetricError> {
    match memory_limit_bytes {
        Some(available) if needed > available => Err(MetricError::LandmarksOutOfMemory {
            sets,
            landmarks: params.count.min(sets),
            needed,
            available,
        }),
        _ => Ok(()),
    }
}

/// Pivots among the landmarks (positions) and their distances to every set,
/// `table[t · M + j]`.
struct PivotTable {
    pivots: Vec<usize>,
    table: Vec<f64>,
}

fn select(
    measure: &Measure<'_>,
    params: &LandmarkValidParams,
    progress: &dyn Progress,
) -> (LandmarkDistances, PivotTable) {
    match params.selection {
        LandmarkSelection::MaxMin => max_min(measure, params, progress),
        LandmarkSelection::Random => random(measure, params, progress),
    }
}

/// Max–min landmarks: each landmark's column, then the next landmark; the nearest lists
/// are the first `q` of every row of the columns.
fn max_min(
    measure: &Measure<'_>,
    params: &LandmarkValidParams,
    progress: &dyn Progress,
) -> (LandmarkDistances, PivotTable) {
    let m = measure.len();
    let l = params.count.min(m);
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let mut traversal =
        FarthestFirst::new(m, rng.random_range(0..m)).expect("the start is drawn in 0..M");
    // Column of each landmark among the landmarks, by set.
    let mut position: Vec<Option<usize>> = vec![None; m];
    let mut rows = Vec::with_capacity(l);
    let mut table = Array2::<f64>::zeros((m, l));
    let mut column = vec![0.0; m];
    progress.start("landmarks", l as u64);
    for t in 0..l {
        let landmark = traversal.next_landmark();
        measure_column(measure, landmark, &position, &mut column);
        // Pairs with earlier landmarks were measured in their columns.
        for (u, &earlier) in rows.iter().enumerate() {
            column[earlier] = table[[landmark, u]];
        }
        column[landmark] = 0.0;
        for (j, &d) in column.iter().enumerate() {
            table[[j, t]] = d;
        }
        position[landmark] = Some(t);
        rows.push(landmark);
        traversal.add(&column);
        progress.advance(1);
    }
    progress.finish();
    let covering_radius = traversal.finish().covering_radius;
    let landmarks = Array2::from_shape_fn((l, l), |(a, b)| table[[rows[a], b]]);
    let q = params.nearest.min(l);
    let mut nearest = Array2::zeros((m, q));
    let mut nearest_distances = Array2::zeros((m, q));
    nearest
        .as_slice_mut()
        .expect("a new array is in standard layout")
        .par_chunks_mut(q)
        .zip(
            nearest_distances
                .as_slice_mut()
                .expect("a new array is in standard layout")
                .par_chunks_mut(q),
        )
        .enumerate()
        .for_each(|(j, (index, distance))| {
            let mut best = Best::new(q);
            for (a, &d) in table.row(j).iter().enumerate() {
                best.offer(d, a);
            }
            best.write(index, distance);
        });
    // The first landmarks (farthest first) are the pivots.
    let pivots: Vec<usize> = if measure.bounds().0 {
        (0..LANDMARK_PIVOTS.min(l)).collect()
    } else {
        Vec::new()
    };
    let mut pivot_table = vec![0.0; pivots.len() * m];
    for (t, column) in pivot_table.chunks_mut(m).enumerate() {
        for (j, slot) in column.iter_mut().enumerate() {
            *slot = table[[j, t]];
        }
    }
    (
        LandmarkDistances {
            rows,
            selection: LandmarkSelection::MaxMin,
            covering_radius,
            landmarks: DistanceMatrix::from_symmetric(landmarks),
            nearest,
            nearest_distances,
        },
        PivotTable {
            pivots,
            table: pivot_table,
        },
    )
}

/// Random landmarks: their matrix, the pivots' columns, then every set's search.
fn random(
    measure: &Measure<'_>,
    params: &LandmarkValidParams,
    progress: &dyn Progress,
) -> (LandmarkDistances, PivotTable) {
    let m = measure.len();
    let l = params.count.min(m);
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let rows = sample(&mut rng, m, l).into_vec();
    let mut position: Vec<Option<usize>> = vec![None; m];
    for (a, &row) in rows.iter().enumerate() {
        position[row] = Some(a);
    }
    // The landmarks' matrix, row by row (each pair once, in the upper triangle).
    progress.start("landmarks", l as u64);
    let mut upper = Array2::<f64>::zeros((l, l));
    upper
        .as_slice_mut()
        .expect("a new array is in standard layout")
        .par_chunks_mut(l)
        .enumerate()
        .for_each_init(Scratch::default, |scratch, (a, out)| {
            measure.drive(
                scratch,
                PairsDriver {
                    from: rows[a],
                    to: &rows[a + 1..],
                    out: &mut out[a + 1..],
                },
            );
            progress.advance(1);
        });
    progress.finish();
    let landmarks = Array2::from_shape_fn((l, l), |(a, b)| match a.cmp(&b) {
        std::cmp::Ordering::Less => upper[[a, b]],
        std::cmp::Ordering::Greater => upper[[b, a]],
        std::cmp::Ordering::Equal => 0.0,
    });
    drop(upper);
    let (is_metric, tolerance) = measure.bounds();
    // Pivots: farthest first among the landmarks, from the first one (until every
    // landmark duplicates a pivot).
    let mut pivots = Vec::new();
    if is_metric {
        let mut picker = FarthestFirst::new(l, 0).expect("there are at least 3 landmarks");
        while pivots.len() < LANDMARK_PIVOTS.min(l) && !pivots.contains(&picker.next_landmark()) {
            let next = picker.next_landmark();
            pivots.push(next);
            picker.add(landmarks.row(next));
        }
    }
    // `[t][j]`: distance of pivot t to set j.
    let mut table = vec![0.0; pivots.len() * m];
    for (t, column) in table.chunks_mut(m.max(1)).enumerate().take(pivots.len()) {
        measure_column(measure, rows[pivots[t]], &[], column);
    }
    let q = params.nearest.min(l);
    let mut nearest = Array2::zeros((m, q));
    let mut nearest_distances = Array2::zeros((m, q));
    let index_rows = nearest.as_slice_mut().expect("a new array");
    let distance_rows = nearest_distances.as_slice_mut().expect("a new array");
    progress.start("nearest landmarks", m as u64);
    index_rows
        .par_chunks_mut(q * SEARCH_CHUNK)
        .zip(distance_rows.par_chunks_mut(q * SEARCH_CHUNK))
        .enumerate()
        .for_each_init(
            || (Scratch::default(), Vec::new(), Vec::new()),
            |(scratch, bounds, candidates), (c, (index, distance))| {
                let driver = SearchDriver {
                    first: c * SEARCH_CHUNK,
                    q,
                    margin: 3.0 * tolerance,
                    rows: &rows,
                    position: &position,
                    landmarks: &landmarks,
                    pivots: &pivots,
                    table: &table,
                    bounds,
                    candidates,
                    index,
                    distance,
                };
                let sets = driver.index.len() / q;
                measure.drive(scratch, driver);
                progress.advance(sets as u64);
            },
        );
    progress.finish();
    let covering_radius = nearest_distances
        .column(0)
        .iter()
        .copied()
        .fold(0.0, f64::max);
    (
        LandmarkDistances {
            rows,
            selection: LandmarkSelection::Random,
            covering_radius,
            landmarks: DistanceMatrix::from_symmetric(landmarks),
            nearest,
            nearest_distances,
        },
        PivotTable { pivots, table },
    )
}

/// Distances from `landmark` to every set into `column` (in parallel, fixed chunks);
/// sets marked in `known` are left at 0 for the caller to fill.
fn measure_column(
    measure: &Measure<'_>,
    landmark: usize,
    known: &[Option<usize>],
    column: &mut [f64],
) {
    column
        .par_chunks_mut(COLUMN_CHUNK)
        .enumerate()
        .for_each_init(Scratch::default, |scratch, (c, out)| {
            let driver = LandmarkColumn {
                landmark,
                first: c * COLUMN_CHUNK,
                known,
                out,
            };
            measure.drive(scratch, driver);
        });
}

/// Distances from one landmark to the sets `first..first + out.len()`, each pair as
/// `ρ(min, max)`; pairs with landmarks already measured (`known`) are skipped (filled
/// from the table by the caller).
struct LandmarkColumn<'a> {
    landmark: usize,
    first: usize,
    known: &'a [Option<usize>],
    out: &'a mut [f64],
}

impl Driver for LandmarkColumn<'_> {
    type Output = ();
    #[inline(always)]
    fn drive<E: Eval>(self, eval: &mut E) {
        let l = self.landmark;
        for (c, slot) in self.out.iter_mut().enumerate() {
            let j = self.first + c;
            *slot = if j == l || self.known.get(j).is_some_and(Option::is_some) {
                0.0
            } else {
                eval.distance(l.min(j), l.max(j), f64::INFINITY)
                    .unwrap_or(f64::INFINITY)
            };
        }
    }
}

/// Distances from set `from` to each of the sets `to`, each pair as `ρ(min, max)`.
struct PairsDriver<'a> {
    from: usize,
    to: &'a [usize],
    out: &'a mut [f64],
}

impl Driver for PairsDriver<'_> {
    type Output = ();
    #[inline(always)]
    fn drive<E: Eval>(self, eval: &mut E) {
        let i = self.from;
        for (slot, &j) in self.out.iter_mut().zip(self.to) {
            *slot = eval
                .distance(i.min(j), i.max(j), f64::INFINITY)
                .unwrap_or(f64::INFINITY);
        }
    }
}

/// The nearest-landmark search of the sets `first..`, one row of `q` per set.
struct SearchDriver<'a> {
    first: usize,
    q: usize,
    /// Absolute widening of the pivot bounds (three times the metric's tolerance).
    margin: f64,
    rows: &'a [usize],
    position: &'a [Option<usize>],
    landmarks: &'a Array2<f64>,
    pivots: &'a [usize],
    table: &'a [f64],
    bounds: &'a mut Vec<f64>,
    candidates: &'a mut Vec<(f64, u32)>,
    index: &'a mut [usize],
    distance: &'a mut [f64],
}

impl Driver for SearchDriver<'_> {
    type Output = ();
    #[inline(always)]
    fn drive<E: Eval>(self, eval: &mut E) {
        let SearchDriver {
            first,
            q,
            margin,
            rows,
            position,
            landmarks,
            pivots,
            table,
            bounds,
            candidates,
            index,
            distance,
        } = self;
        let l = rows.len();
        let m = position.len();
        let mut measure = |j: usize, a: usize, limit: f64| {
            let row = rows[a];
            eval.distance(j.min(row), j.max(row), limit)
        };
        for (r, (index, distance)) in index.chunks_mut(q).zip(distance.chunks_mut(q)).enumerate() {
            let j = first + r;
            let mut best = Best::new(q);
            if let Some(a) = position[j] {
                // A landmark: its row of the landmarks' matrix.
                for (b, &d) in landmarks.row(a).iter().enumerate() {
                    best.offer(d, b);
                }
            } else if pivots.is_empty() {
                for a in 0..l {
                    if let Some(d) = measure(j, a, best.radius()) {
                        best.offer(d, a);
                    }
                }
            } else {
                bounds.clear();
                bounds.resize(l, 0.0);
                for (t, &p) in pivots.iter().enumerate() {
                    let x = table[t * m + j];
                    for (bound, &y) in bounds.iter_mut().zip(landmarks.row(p)) {
                        let gap = (x - y).abs() - PIVOT_MARGIN * (x + y) - margin;
                        if gap > *bound {
                            *bound = gap;
                        }
                    }
                }
                // The pivots' own distances are known.
                for (t, &p) in pivots.iter().enumerate() {
                    best.offer(table[t * m + j], p);
                    bounds[p] = f64::INFINITY;
                }
                candidates.clear();
                candidates.extend(
                    bounds
                        .iter()
                        .enumerate()
                        .filter(|&(_, &b)| b.is_finite())
                        .map(|(a, &b)| (b, a as u32)),
                );
                let mut to_set = |a: usize, limit: f64| measure(j, a, limit);
                let rest = best.measure_smallest(candidates, &mut to_set);
                // The nearest landmarks found tighten the others' bounds through `Δ`.
                for &(d, u) in best.entries.iter().take(NEAR_PIVOTS) {
                    for (bound, a) in rest.iter_mut() {
                        let y = landmarks[[u, *a as usize]];
                        let gap = (d - y).abs() - PIVOT_MARGIN * (d + y) - margin;
                        if gap > *bound {
                            *bound = gap;
                        }
                    }
                }
                best.measure_within(rest, &mut to_set);
            }
            best.write(index, distance);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metric::{distance_matrix, DistanceParams, Period};
    use crate::neighbours::{farthest_first, DenseDistances};
    use crate::progress::Silent;
    use ndarray::Array3;

    /// Closed curves (circles of varying centre and radius) in 2 coordinates.
    fn loops(m: usize) -> (Array3<f64>, Vec<crate::metric::Closure>) {
        let p = 12;
        let sets = Array3::from_shape_fn((m, p, 2), |(i, q, c)| {
            let t = std::f64::consts::TAU * q as f64 / p as f64;
            let centre = 0.37 * (i as f64 * 1.3).sin() + 0.05 * i as f64;
            let radius = 0.2 + 0.1 * (i as f64 * 0.7).cos().abs();
            if c == 0 {
                centre + radius * t.cos()
            } else {
                0.3 * (i as f64 * 0.4).cos() + radius * t.sin()
            }
        });
        (sets, vec![crate::metric::Closure::Closed; m])
    }

    fn curve() -> DistanceParams {
        DistanceParams::new()
            .metric(crate::metric::MetricKind::Curve)
            .period(Period::None)
    }

    fn run(m: usize, count: usize, selection: LandmarkSelection, seed: u64) -> LandmarkDistances {
        let (sets, closure) = loops(m);
        let view = SetsView::new(sets.view()).with_closure(&closure);
        let metric = curve().check().unwrap().set_metric();
        let params = LandmarkParams::new(count, selection, seed).check().unwrap();
        landmark_distances_with(view, metric.as_ref(), &params, None, &Silent).unwrap()
    }

    #[test]
    fn every_entry_is_the_full_matrix_s_bit_for_bit() {
        let m = 70;
        let (sets, closure) = loops(m);
        let view = SetsView::new(sets.view()).with_closure(&closure);
        let d = distance_matrix(view, &curve(), &Silent).unwrap();
        for selection in [LandmarkSelection::MaxMin, LandmarkSelection::Random] {
            for q in [1, 3, 9, 40] {
                let (sets, closure) = loops(m);
                let view = SetsView::new(sets.view()).with_closure(&closure);
                let metric = curve().check().unwrap().set_metric();
                let params = LandmarkParams::new(9, selection, 5)
                    .nearest(q)
                    .check()
                    .unwrap();
                let l =
                    landmark_distances_with(view, metric.as_ref(), &params, None, &Silent).unwrap();
                assert_eq!(l.len(), 9);
                assert_eq!(l.measured(), q.min(9));
                for (a, &row) in l.rows.iter().enumerate() {
                    for (b, &other) in l.rows.iter().enumerate() {
                        assert_eq!(l.landmarks[[a, b]], d[[row, other]]);
                    }
                }
                let mut out = vec![0.0; 9];
                for j in 0..m {
                    // The first q of the row to the landmarks, by (distance, position).
                    let mut row: Vec<(f64, usize)> = l
                        .rows
                        .iter()
                        .enumerate()
                        .map(|(a, &r)| (d[[j, r]], a))
                        .collect();
                    row.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
                    for c in 0..l.measured() {
                        assert_eq!(
                            (l.nearest_distances[[j, c]], l.nearest[[j, c]]),
                            row[c],
                            "{selection} q {q} set {j} rank {c}"
                        );
                    }
                    // Exact on the nearest, an upper bound within twice the nearest
                    // distance elsewhere, exact everywhere once q = L.
                    l.distances_from(j, &mut out);
                    let near = row[0].0;
                    for (a, &r) in l.rows.iter().enumerate() {
                        let truth = d[[j, r]];
                        if q >= 9 || l.nearest.row(j).iter().any(|&u| u == a) {
                            assert_eq!(out[a], truth);
                        } else {
                            assert!(out[a] >= truth - 1e-9 && out[a] <= truth + 2.0 * near + 1e-9);
                        }
                    }
                }
                let radius = (0..m)
                    .map(|j| {
                        l.rows
                            .iter()
                            .map(|&r| d[[j, r]])
                            .fold(f64::INFINITY, f64::min)
                    })
                    .fold(0.0, f64::max);
                assert_eq!(l.covering_radius, radius);
                // The first 4 landmarks cover at most as the bound says.
                let first4 = (0..m)
                    .map(|j| {
                        l.rows[..4]
                            .iter()
                            .map(|&r| d[[j, r]])
                            .fold(f64::INFINITY, f64::min)
                    })
                    .fold(0.0, f64::max);
                assert!(l.covering_radius_of_first(4) >= first4 - 1e-12);
                assert_eq!(l.covering_radius_of_first(9), radius);
            }
        }
        // All sets as landmarks: the landmark matrix is D, reordered.
        let all = run(m, 200, LandmarkSelection::MaxMin, 1);
        assert_eq!(all.landmarks, d.select(&all.rows));
        let all = run(m, 200, LandmarkSelection::Random, 1);
        assert_eq!(all.landmarks, d.select(&all.rows));
    }

    #[test]
    fn the_nearest_sets_through_landmarks_are_knn_s() {
        let m = 160;
        let (sets, closure) = loops(m);
        let members: Vec<usize> = (0..m).filter(|j| j % 5 != 3).collect();
        let sub = sets.select(ndarray::Axis(0), &members);
        let sub_closure: Vec<_> = members.iter().map(|&j| closure[j]).collect();
        let metric = curve().check().unwrap().set_metric();
        for k in [1, 6] {
            let expected = crate::metric::knn_with(
                SetsView::new(sub.view()).with_closure(&sub_closure),
                metric.as_ref(),
                &curve(),
                &crate::metric::KnnParams::new().k(k),
                0..members.len(),
                &Silent,
            )
            .unwrap();
            for selection in [LandmarkSelection::Random, LandmarkSelection::MaxMin] {
                for (count, q) in [(12, 1), (12, 3), (30, 4), (9, 9)] {
                    let params = LandmarkParams::new(count, selection, 2)
                        .nearest(q)
                        .check()
                        .unwrap();
                    let view = SetsView::new(sets.view()).with_closure(&closure);
                    let (_, knn) = landmarks_and_knn_with(
                        view,
                        metric.as_ref(),
                        &params,
                        &members,
                        k,
                        None,
                        &Silent,
                    )
                    .unwrap();
                    assert_eq!(
                        knn.indices, expected.indices,
                        "{selection} L {count} q {q} k {k}"
                    );
                    assert_eq!(knn.distances, expected.distances);
                }
            }
        }
        // Bad members and k are refused.
        let params = LandmarkParams::new(5, LandmarkSelection::Random, 0)
            .check()
            .unwrap();
        for (members, k) in [(vec![0, 2, 1], 1), (vec![0, 1, m], 1), (vec![0, 1, 2], 3)] {
            let view = SetsView::new(sets.view()).with_closure(&closure);
            let err =
                landmarks_and_knn_with(view, metric.as_ref(), &params, &members, k, None, &Silent)
                    .unwrap_err();
            assert!(!err.to_string().is_empty());
        }
    }

    #[test]
    fn max_min_is_farthest_first_from_the_seeded_start() {
        let m = 50;
        let (sets, closure) = loops(m);
        let view = SetsView::new(sets.view()).with_closure(&closure);
        let d = distance_matrix(view, &curve(), &Silent).unwrap();
        let l = run(m, 12, LandmarkSelection::MaxMin, 3);
        let dense = farthest_first(&DenseDistances::new(d.view()).unwrap(), 12, l.rows[0]).unwrap();
        assert_eq!(l.rows, dense.rows);
        assert_eq!(l.covering_radius, dense.covering_radius);
        // Another seed, another start.
        assert_ne!(run(m, 12, LandmarkSelection::MaxMin, 4).rows[0], l.rows[0]);
        let random = run(m, 12, LandmarkSelection::Random, 3);
        let mut distinct = random.rows.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), 12);
    }

    #[test]
    fn one_and_two_threads_give_the_same_bits() {
        let with = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    (
                        run(150, 20, LandmarkSelection::MaxMin, 9),
                        run(150, 20, LandmarkSelection::Random, 9),
                    )
                })
        };
        assert_eq!(with(1), with(2));
    }

    #[test]
    fn bad_counts_and_memory_are_refused() {
        for count in [0, 2, MAX_LANDMARKS + 1] {
            let err = LandmarkParams::new(count, LandmarkSelection::MaxMin, 0)
                .check()
                .unwrap_err();
            assert!(err.to_string().contains("landmarks"), "{err}");
        }
        let (sets, closure) = loops(40);
        let view = SetsView::new(sets.view()).with_closure(&closure);
        let metric = curve().check().unwrap().set_metric();
        let params = LandmarkParams::new(10, LandmarkSelection::MaxMin, 0)
            .check()
            .unwrap();
        let err = landmark_distances_with(view, metric.as_ref(), &params, Some(1000), &Silent)
            .unwrap_err();
        assert!(err.to_string().contains("scale.landmarks"), "{err}");
    }
}
