//! Neighbour computations, one of each: farthest-first landmarks, the `k` nearest
//! neighbours of every point, and trustworthiness and continuity.
//!
//! Distances reach them through [`DistanceRows`], the distances from one point to every
//! point: a dense `(N, N)` matrix ([`DenseDistances`]) or coordinates `(N, d)` with the
//! Euclidean distance ([`Coordinates`]). Everywhere, a point is not its own neighbour and
//! ties in distance go to the smaller index: `j` comes before `j'` when
//! `(d(i, j), j) < (d(i, j'), j')` lexicographically (floats in IEEE total order).
//!
//! # Farthest-first landmarks ([`farthest_first`])
//!
//! From a start point `s` (a row index), `L ≤ N` landmarks are chosen greedily:
//!
//! ```text
//! l_1 = s,    l_{t+1} = argmax_j  min_{u ≤ t} d(l_u, j)     (smallest j on ties),
//! ```
//!
//! each the point farthest from those already chosen (max–min, Gonzalez 1985). The
//! covering radius `r = max_j min_u d(l_u, j)` is the largest distance of a point to its
//! nearest landmark; it is at most twice the best radius any `L` points can achieve.
//! Each landmark's row is read once: `O(N L)` work, `O(N)` memory. Once the radius is 0
//! (every point duplicates a landmark), further picks repeat row 0.
//!
//! # The `k` nearest neighbours ([`nearest`], [`nearest_neighbours`], [`Knn`])
//!
//! The `k` nearest neighbours of `i` are the first `k` of the other points in the order
//! above, `0 ≤ k < N`, listed nearest first with their distances. They equal the first
//! `k` entries of the row sorted by `(distance, index)` with `i` left out.
//!
//! # Trustworthiness and continuity ([`trustworthiness_continuity`])
//!
//! Venna & Kaski (2001, 2006). An output (a learned metric, an embedding) is judged
//! against an input (the reference). With `r(i, j)` the rank of `j` among the
//! neighbours of `i` by input distance (1 for the nearest), `r̂(i, j)` by output
//! distance, and `N_k(i)`, `N̂_k(i)` the `k` nearest in each,
//!
//! ```text
//! T(k) = 1 − 2 / (N k (2N − 3k − 1)) Σ_i Σ_{j ∈ N̂_k(i) \ N_k(i)} (r(i, j) − k),
//! C(k) = 1 − 2 / (N k (2N − 3k − 1)) Σ_i Σ_{j ∈ N_k(i) \ N̂_k(i)} (r̂(i, j) − k).
//! ```
//!
//! Trustworthiness `T` penalises false neighbours in the output, continuity `C`
//! missing ones; both are 1 when the `k`-neighbourhoods agree.
//!
//! **Valid range: `N ≥ 3` and `1 ≤ k ≤ N/2`.** The normaliser `k (2N − 3k − 1) / 2` is
//! the largest inner sum a point can have (its `k` output neighbours the `k` farthest in
//! the input, ranks `N − 1, …, N − k`) only while `2k ≤ N`: then `T, C ∈ [0, 1]`.
//! Beyond `N/2` a point has at most `N − 1 − k < k` false neighbours, whose largest sum
//! `(N − 1 − k)(N − k) / 2` exceeds the normaliser, so `T` and `C` can be negative (and
//! at `3k + 1 ≥ 2N` the normaliser is not even positive). Out of the range,
//! [`NeighboursError::TrustworthinessK`].

use std::ops::Range;

use ndarray::{Array2, ArrayView1, ArrayView2};
use rayon::prelude::*;

/// Errors of the neighbour computations.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NeighboursError {
    /// A distance matrix is not square.
    #[error("the distance matrix has shape ({rows}, {columns}), expected (N, N)")]
    NotSquare {
        /// Rows.
        rows: usize,
        /// Columns.
        columns: usize,
    },
    /// The input and output of trustworthiness and continuity differ in size.
    #[error("the input has {input} points but the output {output}; they must be the same points")]
    PointsMismatch {
        /// Points of the input.
        input: usize,
        /// Points of the output.
        output: usize,
    },
    /// The start of farthest-first traversal is not a point.
    #[error("farthest-first landmarks start at row {start}, outside the {points} points")]
    StartOutOfRange {
        /// The start row given.
        start: usize,
        /// `N`.
        points: usize,
    },
    /// Too many nearest neighbours asked for.
    #[error("k = {k} nearest neighbours asked of {points} points; use k < {points}")]
    KnnK {
        /// `k` given.
        k: usize,
        /// `N`.
        points: usize,
    },
    /// `k` of trustworthiness and continuity is out of its range.
    #[error("k = {k} is out of range for trustworthiness and continuity of {points} points: they need N ≥ 3 and 1 ≤ k ≤ N/2 = {max}")]
    TrustworthinessK {
        /// `k` given.
        k: usize,
        /// `N`.
        points: usize,
        /// The largest valid `k`, `⌊N/2⌋` (0 when `N < 3`: no `k` is valid).
        max: usize,
    },
}

/// The distances from any one point to every point, `N` points in all.
///
/// Implemented for a dense matrix ([`DenseDistances`]) and for coordinates with the
/// Euclidean distance ([`Coordinates`]); an algorithm that needs neighbours takes this
/// trait, so that it runs the same on either.
pub trait DistanceRows: Sync {
    /// Number of points `N`.
    fn points(&self) -> usize;

    /// Writes `d(i, j)` for every `j` into `out` (`out.len() == N`, `i < N`).
    fn distances_from(&self, i: usize, out: &mut [f64]);
}

/// A dense, square distance matrix `(N, N)`; row `i` holds `d(i, ·)`.
#[derive(Debug, Clone, Copy)]
pub struct DenseDistances<'a>(ArrayView2<'a, f64>);

impl<'a> DenseDistances<'a> {
    /// Wraps `distances`, which must be square (any memory order). Its values are used
    /// as they are: symmetry and a zero diagonal are the caller's (see
    /// [`crate::metric::DistanceMatrix`], which validates them).
    pub fn new(distances: ArrayView2<'a, f64>) -> Result<Self, NeighboursError> {
        let (rows, columns) = distances.dim();
        if rows != columns {
            return Err(NeighboursError::NotSquare { rows, columns });
        }
        Ok(Self(distances))
    }

    /// The matrix.
    pub fn view(&self) -> ArrayView2<'a, f64> {
        self.0
    }
}

impl DistanceRows for DenseDistances<'_> {
    fn points(&self) -> usize {
        self.0.nrows()
    }

    fn distances_from(&self, i: usize, out: &mut [f64]) {
        for (o, &d) in out.iter_mut().zip(self.0.row(i)) {
            *o = d;
        }
    }
}

/// Points given by coordinates `(N, d)`, at Euclidean distance
/// `d(i, j) = √(Σ_c (y_ic − y_jc)²)` (summed in coordinate order).
#[derive(Debug, Clone, Copy)]
pub struct Coordinates<'a>(pub ArrayView2<'a, f64>);

impl Coordinates<'_> {
    /// The Euclidean distance between points `i` and `j`.
    pub fn distance(&self, i: usize, j: usize) -> f64 {
        self.0
            .row(i)
            .iter()
            .zip(self.0.row(j).iter())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt()
    }
}

impl DistanceRows for Coordinates<'_> {
    fn points(&self) -> usize {
        self.0.nrows()
    }

    fn distances_from(&self, i: usize, out: &mut [f64]) {
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.distance(i, j);
        }
    }
}

/// Farthest-first landmarks and how well they cover the points.
#[derive(Debug, Clone, PartialEq)]
pub struct Landmarks {
    /// The landmark rows, in the order chosen (the start first).
    pub rows: Vec<usize>,
    /// The largest distance of a point to its nearest landmark (infinite without
    /// landmarks, 0 without points).
    pub covering_radius: f64,
}

/// Farthest-first traversal, one landmark at a time, for callers that produce each
/// landmark's distance row themselves (Dijkstra on a graph, a set metric) and keep it.
#[derive(Debug, Clone)]
pub(crate) struct FarthestFirst {
    rows: Vec<usize>,
    nearest: Vec<f64>,
    next: usize,
}

impl FarthestFirst {
    /// A traversal of `points` points starting at `start`.
    pub(crate) fn new(points: usize, start: usize) -> Result<Self, NeighboursError> {
        if start >= points {
            return Err(NeighboursError::StartOutOfRange { start, points });
        }
        Ok(Self {
            rows: Vec::new(),
            nearest: vec![f64::INFINITY; points],
            next: start,
        })
    }

    /// The point the next call of [`FarthestFirst::add`] adds.
    pub(crate) fn next_landmark(&self) -> usize {
        self.next
    }

    /// Landmarks chosen so far.
    pub(crate) fn len(&self) -> usize {
        self.rows.len()
    }

    /// Adds [`FarthestFirst::next_landmark`], whose distances to every point are
    /// `row`, and picks the point farthest from all landmarks (smallest index on ties).
    pub(crate) fn add<'r>(&mut self, row: impl IntoIterator<Item = &'r f64>) {
        self.rows.push(self.next);
        let mut farthest = (f64::NEG_INFINITY, 0);
        let mut seen = 0;
        for (j, (near, &d)) in self.nearest.iter_mut().zip(row).enumerate() {
            *near = near.min(d);
            if *near > farthest.0 {
                farthest = (*near, j);
            }
            seen += 1;
        }
        assert_eq!(
            seen,
            self.nearest.len(),
            "a landmark row has one entry per point"
        );
        self.next = farthest.1;
    }

    /// The landmarks and their covering radius.
    pub(crate) fn finish(self) -> Landmarks {
        Landmarks {
            covering_radius: self.nearest.iter().copied().fold(0.0, f64::max),
            rows: self.rows,
        }
    }
}

/// `min(count, N)` farthest-first landmarks of `distances`, from row `start`.
pub fn farthest_first<D: DistanceRows + ?Sized>(
    distances: &D,
    count: usize,
    start: usize,
) -> Result<Landmarks, NeighboursError> {
    let n = distances.points();
    if n == 0 {
        return Ok(Landmarks {
            rows: Vec::new(),
            covering_radius: 0.0,
        });
    }
    let mut traversal = FarthestFirst::new(n, start)?;
    let mut row = vec![0.0; n];
    while traversal.len() < count.min(n) {
        distances.distances_from(traversal.next_landmark(), &mut row);
        traversal.add(&row);
    }
    Ok(traversal.finish())
}

/// The `k` nearest neighbours of a block of query rows `[i0, i1)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Knn {
    /// The query rows `[i0, i1)`.
    pub rows: Range<usize>,
    /// `(i1 − i0, k)`: indices of the nearest points, nearest first (ties: smaller index).
    pub indices: Array2<usize>,
    /// `(i1 − i0, k)`: their distances.
    pub distances: Array2<f64>,
}

impl Knn {
    /// Neighbours per row `k`.
    pub fn k(&self) -> usize {
        self.indices.ncols()
    }

    /// Writes the lists, together (all or none): `indices` `(rows, k)` as int64 and
    /// `distances` `(rows, k)` as float64 (what `smspace embed --knn-indices
    /// --knn-distances` reads). `smspace distances --knn` writes through here.
    pub fn save(
        &self,
        indices: &std::path::Path,
        distances: &std::path::Path,
    ) -> Result<Vec<std::path::PathBuf>, crate::io::IoError> {
        let mut outputs = crate::io::Outputs::new();
        outputs.npy(indices, &self.indices.mapv(|j| j as i64))?;
        outputs.npy(distances, &self.distances)?;
        outputs.commit()
    }
}

/// The `k` nearest entries of `row`, leaving out `exclude`, as `(index, distance)`
/// nearest first (ties: smaller index); all of them when fewer than `k` remain.
pub fn nearest(row: ArrayView1<'_, f64>, k: usize, exclude: Option<usize>) -> Vec<(usize, f64)> {
    let mut all: Vec<(usize, f64)> = row
        .iter()
        .enumerate()
        .filter(|&(j, _)| Some(j) != exclude)
        .map(|(j, &d)| (j, d))
        .collect();
    let by = |a: &(usize, f64), b: &(usize, f64)| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0));
    let k = k.min(all.len());
    if k == 0 {
        return Vec::new();
    }
    if k < all.len() {
        all.select_nth_unstable_by(k - 1, by);
        all.truncate(k);
    }
    all.sort_unstable_by(by);
    all
}

/// The `k` nearest neighbours (`0 ≤ k < N`) of every point, rows in parallel.
pub fn nearest_neighbours<D: DistanceRows + ?Sized>(
    distances: &D,
    k: usize,
) -> Result<Knn, NeighboursError> {
    let n = distances.points();
    if k >= n.max(1) {
        return Err(NeighboursError::KnnK { k, points: n });
    }
    let mut indices = Array2::zeros((n, k));
    let mut dists = Array2::zeros((n, k));
    if k > 0 {
        indices
            .as_slice_mut()
            .expect("a new array is in standard layout")
            .par_chunks_mut(k)
            .zip(
                dists
                    .as_slice_mut()
                    .expect("a new array is in standard layout")
                    .par_chunks_mut(k),
            )
            .enumerate()
            .for_each_init(
                || vec![0.0; n],
                |row, (i, (out_index, out_distance))| {
                    distances.distances_from(i, row);
                    for (c, (j, d)) in nearest(ArrayView1::from(&row[..]), k, Some(i))
                        .into_iter()
                        .enumerate()
                    {
                        out_index[c] = j;
                        out_distance[c] = d;
                    }
                },
            );
    }
    Ok(Knn {
        rows: 0..n,
        indices,
        distances: dists,
    })
}

/// Ranks of a row: `rank[j]` is the position (1 for the nearest) of `j ≠ i` in the
/// order by `(distance, index)`, and `rank[i] = 0`.
fn ranks(row: &[f64], i: usize, order: &mut Vec<(f64, usize)>, rank: &mut [usize]) {
    order.clear();
    order.extend(row.iter().copied().zip(0..).filter(|&(_, j)| j != i));
    order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    rank[i] = 0;
    for (r, &(_, j)) in order.iter().enumerate() {
        rank[j] = r + 1;
    }
}

/// Per-thread buffers of [`trustworthiness_continuity`].
struct RankScratch {
    input: Vec<f64>,
    output: Vec<f64>,
    order: Vec<(f64, usize)>,
    input_rank: Vec<usize>,
    output_rank: Vec<usize>,
}

/// Trustworthiness and continuity `(T(k), C(k))` of `output` against `input` (module
/// docs), rows in parallel; `N ≥ 3` and `1 ≤ k ≤ N/2`.
pub fn trustworthiness_continuity<I, O>(
    input: &I,
    output: &O,
    k: usize,
) -> Result<(f64, f64), NeighboursError>
where
    I: DistanceRows + ?Sized,
    O: DistanceRows + ?Sized,
{
    let n = input.points();
    if output.points() != n {
        return Err(NeighboursError::PointsMismatch {
            input: n,
            output: output.points(),
        });
    }
    let max = if n < 3 { 0 } else { n / 2 };
    if k == 0 || k > max {
        return Err(NeighboursError::TrustworthinessK { k, points: n, max });
    }
    let (trust, cont) = (0..n)
        .into_par_iter()
        .map_init(
            || RankScratch {
                input: vec![0.0; n],
                output: vec![0.0; n],
                order: Vec::with_capacity(n),
                input_rank: vec![0; n],
                output_rank: vec![0; n],
            },
            |s, i| {
                input.distances_from(i, &mut s.input);
                output.distances_from(i, &mut s.output);
                ranks(&s.input, i, &mut s.order, &mut s.input_rank);
                ranks(&s.output, i, &mut s.order, &mut s.output_rank);
                let (mut t, mut c) = (0_u64, 0_u64);
                for (&r, &r_hat) in s.input_rank.iter().zip(&s.output_rank) {
                    // `i` itself has both ranks 0 and counts in neither.
                    if (1..=k).contains(&r_hat) && r > k {
                        t += (r - k) as u64;
                    }
                    if (1..=k).contains(&r) && r_hat > k {
                        c += (r_hat - k) as u64;
                    }
                }
                (t, c)
            },
        )
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    // The sums are integers far below 2^53, exact in f64.
    let (nf, kf) = (n as f64, k as f64);
    let norm = 2.0 / (nf * kf * (2.0 * nf - 3.0 * kf - 1.0));
    Ok((1.0 - norm * trust as f64, 1.0 - norm * cont as f64))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use ndarray::Array2;
    use proptest::prelude::*;
    use proptest::test_runner::{Config, RngSeed};

    /// Distances between points on a line.
    fn line(x: &[f64]) -> Array2<f64> {
        Array2::from_shape_fn((x.len(), x.len()), |(i, j)| (x[i] - x[j]).abs())
    }

    fn column(x: &[f64]) -> Array2<f64> {
        Array2::from_shape_fn((x.len(), 1), |(i, _)| x[i])
    }

    #[test]
    fn neighbours_on_a_line_nearest_first_ties_by_index() {
        let d = line(&[0.0, 1.0, 2.0, 4.0, 8.0]);
        let knn = nearest_neighbours(&DenseDistances::new(d.view()).unwrap(), 2).unwrap();
        assert_eq!(knn.rows, 0..5);
        assert_eq!(knn.k(), 2);
        // Point 1 has 0 and 2 both at distance 1: the smaller index first.
        let expected = [[1, 2], [0, 2], [1, 0], [2, 1], [3, 2]];
        let expected_distances = [[1.0, 2.0], [1.0, 1.0], [1.0, 2.0], [2.0, 3.0], [4.0, 6.0]];
        for i in 0..5 {
            assert_eq!(knn.indices.row(i).to_vec(), expected[i].to_vec(), "row {i}");
            for c in 0..2 {
                assert_abs_diff_eq!(knn.distances[[i, c]], expected_distances[i][c]);
            }
        }
        // The same from coordinates, and zero neighbours are no neighbours.
        let x = column(&[0.0, 1.0, 2.0, 4.0, 8.0]);
        let from_points = nearest_neighbours(&Coordinates(x.view()), 2).unwrap();
        assert_eq!(from_points.indices, knn.indices);
        assert_eq!(
            nearest_neighbours(&Coordinates(x.view()), 0).unwrap().k(),
            0
        );
        assert_eq!(
            nearest_neighbours(&Coordinates(x.view()), 5).unwrap_err(),
            NeighboursError::KnnK { k: 5, points: 5 }
        );
        assert_eq!(
            nearest(d.row(3), 10, None),
            vec![(3, 0.0), (2, 2.0), (1, 3.0), (0, 4.0), (4, 4.0)]
        );
    }

    #[test]
    fn landmarks_on_a_line() {
        let d = line(&[0.0, 1.0, 2.0, 3.0, 10.0]);
        let dense = DenseDistances::new(d.view()).unwrap();
        let l = farthest_first(&dense, 3, 0).unwrap();
        // 0; then 4 (10 from 0); then 3 (3 from 0, 7 from 4); rows 1 and 2 are then 1
        // from a landmark.
        assert_eq!(l.rows, vec![0, 4, 3]);
        assert_abs_diff_eq!(l.covering_radius, 1.0);
        let all = farthest_first(&dense, 99, 2).unwrap();
        assert_eq!(all.rows.len(), 5);
        assert_eq!(all.rows[..2], [2, 4]);
        assert_abs_diff_eq!(all.covering_radius, 0.0);
        let none = farthest_first(&dense, 0, 0).unwrap();
        assert!(none.rows.is_empty() && none.covering_radius.is_infinite());
        assert_eq!(
            farthest_first(&dense, 2, 5).unwrap_err(),
            NeighboursError::StartOutOfRange {
                start: 5,
                points: 5
            }
        );
        // Equal distances: the smallest index.
        let ties = line(&[0.0, 1.0, -1.0]);
        let l = farthest_first(&DenseDistances::new(ties.view()).unwrap(), 2, 0).unwrap();
        assert_eq!(l.rows, vec![0, 1]);
        assert_eq!(
            DenseDistances::new(Array2::zeros((2, 3)).view()).unwrap_err(),
            NeighboursError::NotSquare {
                rows: 2,
                columns: 3
            }
        );
    }

    #[test]
    fn an_exact_embedding_is_trustworthy_and_continuous() {
        let x: Vec<f64> = (0..12).map(|i| f64::from(i).powf(1.3)).collect();
        let d = line(&x);
        let dense = DenseDistances::new(d.view()).unwrap();
        let y = column(&x);
        for k in 1..=6 {
            let (t, c) = trustworthiness_continuity(&dense, &Coordinates(y.view()), k).unwrap();
            assert_abs_diff_eq!(t, 1.0);
            assert_abs_diff_eq!(c, 1.0);
        }
        // A monotone transform of the distances keeps every rank.
        let squared = d.mapv(|v| v * v + v);
        let (t, c) =
            trustworthiness_continuity(&dense, &DenseDistances::new(squared.view()).unwrap(), 3)
                .unwrap();
        assert_abs_diff_eq!(t, 1.0);
        assert_abs_diff_eq!(c, 1.0);
    }

    #[test]
    fn a_swapped_pair_costs_a_known_amount() {
        // Input: 0, 1, 2, 3, 4 on a line; output: points 0 and 1 swapped. With k = 1 the
        // only change is point 2: its output neighbour is 0 (input rank 3) instead of 1
        // (output rank 3). Both sums are 3 − 1 = 2, the normaliser 2 / (5 · 1 · 6).
        let input = line(&[0.0, 1.0, 2.0, 3.0, 4.0]);
        let output = column(&[1.0, 0.0, 2.0, 3.0, 4.0]);
        let (t, c) = trustworthiness_continuity(
            &DenseDistances::new(input.view()).unwrap(),
            &Coordinates(output.view()),
            1,
        )
        .unwrap();
        assert_abs_diff_eq!(t, 13.0 / 15.0, epsilon = 1e-15);
        assert_abs_diff_eq!(c, 13.0 / 15.0, epsilon = 1e-15);
    }

    #[test]
    fn k_outside_one_to_half_n_is_refused() {
        let d = line(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        let dense = DenseDistances::new(d.view()).unwrap();
        assert!(trustworthiness_continuity(&dense, &dense, 3).is_ok());
        for k in [0, 4] {
            assert_eq!(
                trustworthiness_continuity(&dense, &dense, k).unwrap_err(),
                NeighboursError::TrustworthinessK {
                    k,
                    points: 6,
                    max: 3
                }
            );
        }
        let two = line(&[0.0, 1.0]);
        let two = DenseDistances::new(two.view()).unwrap();
        assert!(matches!(
            trustworthiness_continuity(&two, &two, 1),
            Err(NeighboursError::TrustworthinessK { max: 0, .. })
        ));
        let y = column(&[0.0, 1.0, 2.0]);
        assert_eq!(
            trustworthiness_continuity(&dense, &Coordinates(y.view()), 1).unwrap_err(),
            NeighboursError::PointsMismatch {
                input: 6,
                output: 3
            }
        );
    }

    /// The documented range: the normaliser `k (2N − 3k − 1) / 2` is the largest inner
    /// sum of one point exactly while `2k ≤ N`, found here over every possible set of
    /// `k` output neighbours.
    #[test]
    fn the_normaliser_is_the_worst_case_up_to_half_n() {
        for n in 3..=9_usize {
            for k in 1..n - 1 {
                // Input ranks 1..N−1; an output neighbourhood is a k-subset of them.
                let mut worst = 0;
                for mask in 0_u32..1 << (n - 1) {
                    if mask.count_ones() as usize == k {
                        let sum: usize = (1..n)
                            .filter(|r| mask >> (r - 1) & 1 == 1 && *r > k)
                            .map(|r| r - k)
                            .sum();
                        worst = worst.max(sum);
                    }
                }
                let (nf, kf) = (n as f64, k as f64);
                let normaliser = kf * (2.0 * nf - 3.0 * kf - 1.0) / 2.0;
                if 2 * k <= n {
                    assert_abs_diff_eq!(worst as f64, normaliser);
                } else {
                    assert!(worst as f64 > normaliser, "n {n}, k {k}");
                }
            }
        }
    }

    fn seeded(cases: u32) -> Config {
        Config {
            cases,
            rng_seed: RngSeed::Fixed(0x6e65_6967),
            failure_persistence: None,
            ..Config::default()
        }
    }

    /// The brute-force definitions of the module docs, on a full sort of each row.
    fn reference(x: &Array2<f64>, y: &Array2<f64>, k: usize) -> (f64, f64) {
        let n = x.nrows();
        let sorted = |m: &Array2<f64>, i: usize| {
            let mut js: Vec<usize> = (0..n).filter(|&j| j != i).collect();
            js.sort_by(|&a, &b| m[[i, a]].total_cmp(&m[[i, b]]).then(a.cmp(&b)));
            js
        };
        let (mut t, mut c) = (0.0, 0.0);
        for i in 0..n {
            let (sx, sy) = (sorted(x, i), sorted(y, i));
            let rank = |s: &[usize], j: usize| s.iter().position(|&v| v == j).unwrap() + 1;
            for &j in &sy[..k] {
                if !sx[..k].contains(&j) {
                    t += (rank(&sx, j) - k) as f64;
                }
            }
            for &j in &sx[..k] {
                if !sy[..k].contains(&j) {
                    c += (rank(&sy, j) - k) as f64;
                }
            }
        }
        let norm = 2.0 / (n as f64 * k as f64 * (2.0 * n as f64 - 3.0 * k as f64 - 1.0));
        (1.0 - norm * t, 1.0 - norm * c)
    }

    proptest! {
        #![proptest_config(seeded(64))]

        /// Random points in the plane against a random projection to a line: T and C
        /// agree with the brute-force definitions, lie in [0, 1], and swap when input
        /// and output swap.
        #[test]
        fn trustworthiness_matches_its_definition(
            points in prop::collection::vec((-10_i32..10, -10_i32..10), 3..24),
            k_fraction in 0.0..1.0_f64,
        ) {
            let n = points.len();
            let k = 1 + ((n / 2 - 1) as f64 * k_fraction) as usize;
            let plane = Array2::from_shape_fn((n, 2), |(i, c)| {
                f64::from(if c == 0 { points[i].0 } else { points[i].1 })
            });
            let line = Array2::from_shape_fn((n, 1), |(i, _)| plane[[i, 0]] + 0.3 * plane[[i, 1]]);
            let x = Array2::from_shape_fn((n, n), |(i, j)| Coordinates(plane.view()).distance(i, j));
            let y = Array2::from_shape_fn((n, n), |(i, j)| Coordinates(line.view()).distance(i, j));
            let (t, c) = trustworthiness_continuity(
                &DenseDistances::new(x.view()).unwrap(),
                &Coordinates(line.view()),
                k,
            )
            .unwrap();
            let (rt, rc) = reference(&x, &y, k);
            prop_assert!((t - rt).abs() < 1e-12 && (c - rc).abs() < 1e-12);
            prop_assert!((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&c));
            let (ct, tc) = trustworthiness_continuity(
                &Coordinates(line.view()),
                &Coordinates(plane.view()),
                k,
            )
            .unwrap();
            prop_assert!((ct - c).abs() < 1e-15 && (tc - t).abs() < 1e-15);
        }

        /// Nearest neighbours are the head of the sorted row; landmarks are distinct,
        /// and the covering radius is the largest distance to the nearest landmark.
        #[test]
        fn neighbours_and_landmarks_match_brute_force(
            points in prop::collection::vec((-5_i32..5, -5_i32..5), 2..30),
            k_fraction in 0.0..1.0_f64,
            count in 1_usize..12,
        ) {
            let n = points.len();
            let plane = Array2::from_shape_fn((n, 2), |(i, c)| {
                f64::from(if c == 0 { points[i].0 } else { points[i].1 })
            });
            let xy = Coordinates(plane.view());
            let k = ((n - 1) as f64 * k_fraction) as usize;
            let knn = nearest_neighbours(&xy, k).unwrap();
            for i in 0..n {
                let mut js: Vec<usize> = (0..n).filter(|&j| j != i).collect();
                js.sort_by(|&a, &b| xy.distance(i, a).total_cmp(&xy.distance(i, b)).then(a.cmp(&b)));
                prop_assert_eq!(knn.indices.row(i).to_vec(), js[..k].to_vec());
            }
            let l = farthest_first(&xy, count, n - 1).unwrap();
            prop_assert_eq!(l.rows.len(), count.min(n));
            prop_assert_eq!(l.rows[0], n - 1);
            let mut distinct = l.rows.clone();
            distinct.sort_unstable();
            distinct.dedup();
            // Duplicated points are at distance 0 and may be picked only once all
            // distinct positions are landmarks.
            prop_assert!(distinct.len() == l.rows.len() || l.covering_radius == 0.0);
            let radius = (0..n)
                .map(|j| l.rows.iter().map(|&r| xy.distance(r, j)).fold(f64::INFINITY, f64::min))
                .fold(0.0, f64::max);
            prop_assert!((radius - l.covering_radius).abs() < 1e-12);
        }
    }
}
