//! Distances to landmark sets: the `M × L` distances of every set to `L` landmarks and
//! the landmarks' own `L × L` matrix, without the `M × M` matrix (issue 18, the scale
//! path).
//!
//! # Landmarks
//!
//! `L ≤ M` landmark sets are chosen by one of two rules ([`LandmarkSelection`]):
//!
//! - **max–min** (farthest first, Gonzalez 1985; [`crate::neighbours`]): a seeded
//!   start `l_1` drawn uniformly from `0..M`, then
//!   `l_{t+1} = argmax_j min_{u ≤ t} ρ(l_u, j)` (smallest `j` on ties). The landmarks
//!   spread evenly over the manifold of sets; the covering radius
//!   `r = max_j min_u ρ(l_u, j)` is at most twice the best any `L` sets achieve.
//! - **random**: `L` distinct sets drawn uniformly (seeded; in the order drawn), an
//!   unbiased sample of the sets (what statistics over sets want).
//!
//! Either way the covering radius is reported: a feature of the manifold shorter than
//! about `2r` is not resolved by the landmarks.
//!
//! # Cost and exactness
//!
//! Landmark `t`'s column `ρ(l_t, j)` for every `j` is computed in parallel (rayon, in
//! fixed chunks) as the same call `ρ(M^min(l,j), M^max(l,j))` that
//! [`distance_matrix`](super::distance_matrix) makes, so every entry equals the full
//! matrix's bit for bit, for any number of threads. A pair of two landmarks is computed
//! once (in the column of the later one, copied from the earlier column). Work:
//! `L·M − L(L+1)/2` pairs; memory: the `(M, L)` table `8 M L` bytes, one column `8 M`
//! bytes per call, the prepared sets and the `(L, L)` matrix `8 L²` bytes
//! ([`landmark_bytes`]).

use ndarray::Array2;
use rand::seq::index::sample;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::kernel::{Driver, Eval, Scratch};
use super::tiles::Measure;
use super::{DistanceMatrix, MetricError, PreparedSets, SetMetric, SetsView};
use crate::error::{CheckParams, InvalidParameter};
use crate::neighbours::FarthestFirst;
use crate::progress::Progress;

/// Sets per parallel task of a landmark's column.
const COLUMN_CHUNK: usize = 64;

/// How landmarks are chosen (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum LandmarkSelection {
    /// Farthest first from a seeded start.
    #[default]
    MaxMin,
    /// Uniformly at random, seeded.
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
    /// How they are chosen. Default max–min.
    pub selection: LandmarkSelection,
    /// Seed of the start (max–min) or of the draw (random). Default 0.
    pub seed: u64,
}

impl Default for LandmarkParams {
    fn default() -> Self {
        Self {
            count: 2000,
            selection: LandmarkSelection::MaxMin,
            seed: 0,
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
    /// `count` landmarks chosen by `selection` from `seed`.
    pub fn new(count: usize, selection: LandmarkSelection, seed: u64) -> Self {
        Self {
            count,
            selection,
            seed,
        }
    }

    /// Checks `3 ≤ count ≤` [`MAX_LANDMARKS`] (errors name `[scale] landmarks`).
    pub fn check(&self) -> Result<LandmarkValidParams, MetricError> {
        if !(3..=MAX_LANDMARKS).contains(&self.count) {
            return Err(InvalidParameter::new(
                "scale",
                "landmarks",
                self.count,
                format!("between 3 and {MAX_LANDMARKS} landmark sets (2000 to 4000 cover the paper's arm; each costs M distances and 8·M bytes)"),
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

/// The landmarks and every set's distances to them.
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
    /// `(M, L)`: `to_landmarks[j, a] = ρ(j, l_a)` (zero at `j = l_a`).
    pub to_landmarks: Array2<f64>,
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
        self.to_landmarks.nrows()
    }
}

/// Bytes [`landmark_distances_with`] needs for `sets` sets of `points` points of `dims`
/// coordinates and `landmarks` landmarks: the `(M, L)` table, the `(L, L)` matrix, one
/// column per call and the prepared sets.
pub fn landmark_bytes(sets: usize, points: usize, dims: usize, landmarks: usize) -> u64 {
    let (m, l) = (sets as u64, landmarks.min(sets) as u64);
    m.saturating_mul(l)
        .saturating_add(l.saturating_mul(l))
        .saturating_add(2 * m)
        .saturating_mul(8)
        .saturating_add(PreparedSets::estimate_bytes_with_curves(sets, points, dims))
}

/// The landmarks of `sets` `(M, P, N)` under `metric` and every set's distance to them
/// (module docs); `min(L, M)` landmarks. Refused before any work when
/// [`landmark_bytes`] exceeds `memory_limit_bytes`. `progress` sees one stage,
/// "landmarks", counted in landmarks.
///
/// ```
/// use smspace::metric::landmarks::{landmark_distances_with, LandmarkParams, LandmarkSelection};
/// use smspace::metric::{distance_matrix, DistanceParams, Period};
/// use smspace::progress::Silent;
/// // Sets of one point at 0, 1, 3, 7, 8 on a line.
/// let sets = ndarray::Array3::from_shape_fn((5, 1, 1), |(i, _, _)| [0.0, 1.0, 3.0, 7.0, 8.0][i]);
/// let params = DistanceParams::new().period(Period::None);
/// let metric = params.check()?.set_metric();
/// let chosen = LandmarkParams::new(3, LandmarkSelection::MaxMin, 0).check()?;
/// let l = landmark_distances_with(sets.view(), metric.as_ref(), &chosen, None, &Silent)?;
/// assert_eq!(l.to_landmarks.dim(), (5, 3));
/// let d = distance_matrix(sets.view(), &params, &Silent)?;
/// for (a, &row) in l.rows.iter().enumerate() {
///     for j in 0..5 {
///         assert_eq!(l.to_landmarks[[j, a]], d[[j, row]]);
///     }
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
    let needed = landmark_bytes(m, p, n, params.count);
    if let Some(available) = memory_limit_bytes.filter(|&a| needed > a) {
        return Err(MetricError::LandmarksOutOfMemory {
            sets: m,
            landmarks: params.count.min(m),
            needed,
            available,
        });
    }
    let measure = Measure::new(sets, metric)?;
    let found = select_and_measure(&measure, params, progress);
    measure.failure(|s| s)?;
    Ok(found)
}

/// The landmark loop: each landmark's column, then the next landmark.
fn select_and_measure(
    measure: &Measure<'_>,
    params: &LandmarkValidParams,
    progress: &dyn Progress,
) -> LandmarkDistances {
    let m = measure.len();
    let l = params.count.min(m);
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let mut picker = match params.selection {
        LandmarkSelection::MaxMin => Picker::MaxMin(
            FarthestFirst::new(m, rng.gen_range(0..m)).expect("the start is drawn in 0..M"),
        ),
        LandmarkSelection::Random => Picker::Random {
            order: sample(&mut rng, m, l).into_vec(),
            nearest: vec![f64::INFINITY; m],
        },
    };
    // Column of each landmark among the landmarks, by set.
    let mut position: Vec<Option<usize>> = vec![None; m];
    let mut rows = Vec::with_capacity(l);
    let mut table = Array2::<f64>::zeros((m, l));
    let mut column = vec![0.0; m];
    progress.start("landmarks", l as u64);
    for t in 0..l {
        let landmark = picker.next(t);
        column
            .par_chunks_mut(COLUMN_CHUNK)
            .enumerate()
            .for_each_init(Scratch::default, |scratch, (c, out)| {
                let driver = LandmarkColumn {
                    landmark,
                    first: c * COLUMN_CHUNK,
                    known: &position,
                    out,
                };
                measure.drive(scratch, driver);
            });
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
        picker.add(&column);
        progress.advance(1);
    }
    progress.finish();
    let covering_radius = picker.covering_radius();
    let landmarks = Array2::from_shape_fn((l, l), |(a, b)| table[[rows[a], b]]);
    LandmarkDistances {
        rows,
        selection: params.selection,
        covering_radius,
        landmarks: DistanceMatrix::from_symmetric(landmarks),
        to_landmarks: table,
    }
}

/// The rule that picks the next landmark, with the distance of every set to its nearest
/// landmark so far.
enum Picker {
    MaxMin(FarthestFirst),
    Random {
        order: Vec<usize>,
        nearest: Vec<f64>,
    },
}

impl Picker {
    fn next(&self, t: usize) -> usize {
        match self {
            Self::MaxMin(traversal) => traversal.next_landmark(),
            Self::Random { order, .. } => order[t],
        }
    }

    fn add(&mut self, column: &[f64]) {
        match self {
            Self::MaxMin(traversal) => traversal.add(column),
            Self::Random { nearest, .. } => nearest
                .iter_mut()
                .zip(column)
                .for_each(|(near, &d)| *near = near.min(d)),
        }
    }

    fn covering_radius(self) -> f64 {
        match self {
            Self::MaxMin(traversal) => traversal.finish().covering_radius,
            Self::Random { nearest, .. } => nearest.iter().copied().fold(0.0, f64::max),
        }
    }
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
            *slot = if j == l || self.known[j].is_some() {
                0.0
            } else {
                eval.distance(l.min(j), l.max(j), f64::INFINITY)
                    .unwrap_or(f64::INFINITY)
            };
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
            let l = run(m, 9, selection, 5);
            assert_eq!(l.len(), 9);
            for (a, &row) in l.rows.iter().enumerate() {
                for j in 0..m {
                    assert_eq!(l.to_landmarks[[j, a]], d[[j, row]], "{selection} {j} {row}");
                }
                for (b, &other) in l.rows.iter().enumerate() {
                    assert_eq!(l.landmarks[[a, b]], d[[row, other]]);
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
        }
        // All sets as landmarks: the landmark matrix is D, reordered.
        let all = run(m, 200, LandmarkSelection::MaxMin, 1);
        assert_eq!(all.landmarks, d.select(&all.rows));
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
                .install(|| run(150, 20, LandmarkSelection::MaxMin, 9))
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
