//! Isomap (Tenenbaum, de Silva & Langford 2000) and landmark Isomap (de Silva &
//! Tenenbaum 2003).
//!
//! 1. Each point is joined to its `k` nearest neighbours by edges weighted with their
//!    distance; the graph is made undirected (an edge exists if either end chose it).
//! 2. Geodesic distances are approximated by shortest paths (Dijkstra from every source,
//!    sources in parallel). A disconnected graph is an error: its geodesic distances are
//!    infinite.
//! 3. Classical MDS ([`super::mds`]) embeds the geodesic distances.
//!
//! Landmark Isomap runs Dijkstra only from `L ≪ M` landmarks (chosen at random or by
//! MaxMin: each new landmark is the point farthest from those already chosen), embeds
//! the `L × L` geodesic block with classical MDS, and places every point by
//! distance-based triangulation from its geodesic distances to the landmarks
//! (`y = −½ L^♯ (δ² − δ̄²)`). The `k`-nearest-neighbour graph alone suffices, so large
//! problems can start from a [`KnnGraph`] (the `knn_indices.npy` / `knn_distances.npy`
//! pair of the metric stage) instead of a dense `(M, M)` matrix.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::path::Path;

use ndarray::{Array2, ArrayView2};
use ndarray_npy::ReadNpyExt;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::eigen::{classical_mds, distance_scale, rescaled, EigenSolver, Triangulation};
use super::{check_dim, check_dim_param, EmbedError, EmbedReport, Embedded};
use super::{Embedding, Extender};
use crate::neighbours::{self, DenseDistances, FarthestFirst, Knn};
use crate::params::InvalidParameter;
use crate::progress::Progress;

/// How landmark Isomap chooses its landmarks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum LandmarkChoice {
    /// The first at random (seeded), then each the farthest (geodesically) from those
    /// already chosen; spreads the landmarks evenly, sequential Dijkstra.
    #[default]
    MaxMin,
    /// Uniformly at random (seeded); Dijkstra runs in parallel.
    Random,
}

/// Parameters of Isomap (unchecked).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IsomapParams {
    /// Output dimension `d`. Default 3.
    pub dim: usize,
    /// Neighbours per point in the graph. Default 10.
    pub k: usize,
    /// Number of landmarks; `None` (default), or at least `M`, runs exact Isomap from
    /// every point (which keeps the `M × M` geodesic matrix: use landmarks for large `M`).
    pub landmarks: Option<usize>,
    /// How landmarks are chosen. Default [`LandmarkChoice::MaxMin`].
    pub landmark_choice: LandmarkChoice,
    /// Eigensolver of the MDS step. Default `Auto`.
    pub solver: EigenSolver,
    /// Seed (landmarks, eigensolver start vector). Default 0.
    pub seed: u64,
}

impl Default for IsomapParams {
    fn default() -> Self {
        Self {
            dim: 3,
            k: 10,
            landmarks: None,
            landmark_choice: LandmarkChoice::MaxMin,
            solver: EigenSolver::Auto,
            seed: 0,
        }
    }
}

impl IsomapParams {
    /// Sets the output dimension (default 3).
    pub fn dim(mut self, dim: usize) -> Self {
        self.dim = dim;
        self
    }
    /// Sets the neighbour count (default 10).
    pub fn k(mut self, k: usize) -> Self {
        self.k = k;
        self
    }
    /// Uses landmark Isomap with `landmarks` landmarks (default: exact Isomap).
    pub fn landmarks(mut self, landmarks: Option<usize>) -> Self {
        self.landmarks = landmarks;
        self
    }
    /// Sets how landmarks are chosen (default MaxMin).
    pub fn landmark_choice(mut self, choice: LandmarkChoice) -> Self {
        self.landmark_choice = choice;
        self
    }
    /// Sets the eigensolver (default `Auto`).
    pub fn solver(mut self, solver: EigenSolver) -> Self {
        self.solver = solver;
        self
    }
    /// Sets the seed (default 0).
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// Validates the parameters.
    pub fn check(self) -> Result<IsomapValidParams, EmbedError> {
        check_dim_param(self.dim)?;
        if self.k == 0 {
            return Err(InvalidParameter::new("embedding", "k", 0, "at least 1 neighbour").into());
        }
        if let Some(l) = self.landmarks {
            if l <= self.dim {
                return Err(InvalidParameter::new(
                    "embedding",
                    "landmarks",
                    l,
                    "more landmarks than output dimensions (a few hundred is typical)",
                )
                .into());
            }
        }
        Ok(IsomapValidParams(self))
    }
}

/// Checked parameters of Isomap; [`Embedding::fit`] runs it on a distance matrix,
/// [`IsomapValidParams::fit_knn`] on a neighbour graph.
#[derive(Debug, Clone, PartialEq)]
pub struct IsomapValidParams(IsomapParams);

/// A `k`-nearest-neighbour graph: row `i` lists the `k` nearest other points of point
/// `i`, nearest first.
///
/// A checked [`Knn`] over all `M` rows (one kNN type, [`crate::neighbours::Knn`], which
/// the metric stage's `metric::knn` returns): every index names another point of
/// `[0, M)` and every distance is finite and non-negative.
#[derive(Debug, Clone, PartialEq)]
pub struct KnnGraph {
    knn: Knn,
}

/// Checks one entry `(j, d)` of row `i` of a graph of `points` points.
fn check_neighbour(i: usize, j: i64, d: f64, points: usize) -> Result<(), EmbedError> {
    if j < 0 || j as usize >= points || j as usize == i {
        return Err(EmbedError::Knn(format!(
            "row {i} lists neighbour {j}; neighbours must be other points in [0, {points})"
        )));
    }
    if !d.is_finite() || d < 0.0 {
        return Err(EmbedError::Knn(format!(
            "row {i} has distance {d}; distances must be finite and non-negative"
        )));
    }
    Ok(())
}

impl KnnGraph {
    /// The `k` nearest neighbours of every point of a validated distance matrix
    /// ([`neighbours::nearest_neighbours`]).
    pub fn from_distances(distances: ArrayView2<'_, f64>, k: usize) -> Result<Self, EmbedError> {
        let points = distances.nrows();
        if k >= points {
            return Err(EmbedError::KTooLarge { k, points });
        }
        let knn = neighbours::nearest_neighbours(&DenseDistances::new(distances)?, k)?;
        Ok(Self { knn })
    }

    /// A graph from the neighbours of all `M` rows (`knn.rows` is `0..M`, `M ≥ 2`,
    /// `k ≥ 1`), e.g. those `metric::knn` found for every set.
    pub fn from_knn(knn: Knn) -> Result<Self, EmbedError> {
        let (points, k) = knn.indices.dim();
        if knn.rows != (0..points) || knn.distances.dim() != (points, k) {
            return Err(EmbedError::Knn(format!(
                "the lists cover rows {}..{} with indices {:?} and distances {:?}; a graph needs rows 0..M and both (M, K)",
                knn.rows.start,
                knn.rows.end,
                knn.indices.dim(),
                knn.distances.dim()
            )));
        }
        if k == 0 || points < 2 {
            return Err(EmbedError::Knn(format!(
                "shape ({points}, {k}): need at least 2 points and 1 neighbour"
            )));
        }
        for (((i, _), &j), &d) in knn.indices.indexed_iter().zip(&knn.distances) {
            check_neighbour(i, i64::try_from(j).unwrap_or(i64::MAX), d, points)?;
        }
        Ok(Self { knn })
    }

    /// A graph from arrays `(M, K)`: `indices` (int64, each in `[0, M)`, not the row's own
    /// index) and `distances` (finite, non-negative). This is the layout of the metric
    /// stage's `knn_indices.npy` / `knn_distances.npy`.
    pub fn from_arrays(
        indices: ArrayView2<'_, i64>,
        distances: ArrayView2<'_, f64>,
    ) -> Result<Self, EmbedError> {
        if indices.dim() != distances.dim() {
            return Err(EmbedError::Knn(format!(
                "indices have shape {:?} but distances {:?}; both must be (M, K)",
                indices.dim(),
                distances.dim()
            )));
        }
        let (points, k) = indices.dim();
        if k == 0 || points < 2 {
            return Err(EmbedError::Knn(format!(
                "shape ({points}, {k}): need at least 2 points and 1 neighbour"
            )));
        }
        for (((i, _), &j), &d) in indices.indexed_iter().zip(&distances) {
            check_neighbour(i, j, d, points)?;
        }
        Ok(Self {
            knn: Knn {
                rows: 0..points,
                indices: indices.mapv(|j| j as usize),
                distances: distances.to_owned(),
            },
        })
    }

    /// Reads the metric stage's `knn_indices.npy` (int64) and `knn_distances.npy` (f64).
    pub fn read(indices: &Path, distances: &Path) -> Result<Self, EmbedError> {
        let open = |path: &Path| {
            std::fs::File::open(path)
                .map(std::io::BufReader::new)
                .map_err(|reason| crate::io::IoError::Read {
                    path: path.to_owned(),
                    reason,
                })
        };
        let idx = Array2::<i64>::read_npy(open(indices)?).map_err(|e| {
            EmbedError::Knn(format!(
                "{} is not a 2-D int64 .npy array: {e}",
                indices.display()
            ))
        })?;
        let dist = crate::io::read_matrix(distances, Some(idx.ncols()), "(M, K) as the indices")?;
        Self::from_arrays(idx.view(), dist.view())
    }

    /// Number of points `M`.
    pub fn points(&self) -> usize {
        self.knn.indices.nrows()
    }

    /// Neighbours per point `K`.
    pub fn k(&self) -> usize {
        self.knn.k()
    }

    /// Neighbour `c` of point `i`: `(index, distance)`.
    pub fn neighbour(&self, i: usize, c: usize) -> (usize, f64) {
        (self.knn.indices[[i, c]], self.knn.distances[[i, c]])
    }

    /// The neighbour lists.
    pub fn knn(&self) -> &Knn {
        &self.knn
    }
}

/// An undirected weighted graph in compressed sparse rows.
struct Csr {
    start: Vec<usize>,
    target: Vec<u32>,
    weight: Vec<f64>,
}

impl Csr {
    /// The undirected graph of the first `k` neighbours of every point (min weight on
    /// duplicate edges).
    fn from_knn(graph: &KnnGraph, k: usize) -> Self {
        let n = graph.points();
        let mut lists: Vec<Vec<(u32, f64)>> = vec![Vec::with_capacity(2 * k); n];
        for i in 0..n {
            for c in 0..k {
                let (j, d) = graph.neighbour(i, c);
                lists[i].push((j as u32, d));
                lists[j].push((i as u32, d));
            }
        }
        let mut start = Vec::with_capacity(n + 1);
        let mut target = Vec::new();
        let mut weight = Vec::new();
        start.push(0);
        for list in &mut lists {
            list.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
            list.dedup_by_key(|e| e.0);
            for &(j, d) in list.iter() {
                target.push(j);
                weight.push(d);
            }
            start.push(target.len());
        }
        Self {
            start,
            target,
            weight,
        }
    }

    fn len(&self) -> usize {
        self.start.len() - 1
    }

    /// Connected components: `(count, size of the largest)`.
    fn components(&self) -> (usize, usize) {
        let n = self.len();
        let mut label = vec![usize::MAX; n];
        let mut sizes = Vec::new();
        let mut stack = Vec::new();
        for s in 0..n {
            if label[s] != usize::MAX {
                continue;
            }
            let c = sizes.len();
            let mut size = 0;
            label[s] = c;
            stack.push(s);
            while let Some(u) = stack.pop() {
                size += 1;
                for e in self.start[u]..self.start[u + 1] {
                    let v = self.target[e] as usize;
                    if label[v] == usize::MAX {
                        label[v] = c;
                        stack.push(v);
                    }
                }
            }
            sizes.push(size);
        }
        (sizes.len(), sizes.into_iter().max().unwrap_or(0))
    }

    /// Shortest-path distances from `source` into `out` (Dijkstra, binary heap).
    fn dijkstra(&self, source: usize, out: &mut [f64], heap: &mut BinaryHeap<Item>) {
        out.fill(f64::INFINITY);
        heap.clear();
        out[source] = 0.0;
        heap.push(Item::new(0.0, source));
        while let Some(item) = heap.pop() {
            let (d, u) = item.get();
            if d > out[u] {
                continue;
            }
            let (e0, e1) = (self.start[u], self.start[u + 1]);
            for (&v, &w) in self.target[e0..e1].iter().zip(&self.weight[e0..e1]) {
                let v = v as usize;
                let nd = d + w;
                if nd < out[v] {
                    out[v] = nd;
                    heap.push(Item::new(nd, v));
                }
            }
        }
    }

    /// Geodesic distances from each source, one row per source, sources in parallel.
    fn geodesics(&self, sources: &[usize], progress: &dyn Progress) -> Array2<f64> {
        let n = self.len();
        let mut out = Array2::zeros((sources.len(), n));
        progress.start("dijkstra", sources.len() as u64);
        out.as_slice_mut()
            .expect("standard layout")
            .par_chunks_mut(32 * n)
            .zip(sources.par_chunks(32))
            .for_each_init(BinaryHeap::new, |heap, (block, srcs)| {
                for (row, &s) in block.chunks_mut(n).zip(srcs) {
                    self.dijkstra(s, row, heap);
                }
                progress.advance(srcs.len() as u64);
            });
        progress.finish();
        out
    }
}

/// A heap entry ordered by increasing distance (then index), for a max-heap. The
/// distance (non-negative, so its bits order like the numbers) and the node share one
/// `u128` key, compared in one instruction pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Item(u128);

impl Item {
    fn new(distance: f64, node: usize) -> Self {
        Self(u128::from(distance.to_bits()) << 32 | node as u128)
    }
    fn get(self) -> (f64, usize) {
        (
            f64::from_bits((self.0 >> 32) as u64),
            (self.0 & 0xffff_ffff) as usize,
        )
    }
}

impl PartialOrd for Item {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Item {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.cmp(&self.0)
    }
}

impl IsomapValidParams {
    /// The parameters.
    pub fn params(&self) -> &IsomapParams {
        &self.0
    }

    /// Runs Isomap on a neighbour graph (its first `k` neighbours per point).
    pub fn fit_knn(
        &self,
        graph: &KnnGraph,
        progress: &dyn Progress,
    ) -> Result<Embedded, EmbedError> {
        if let Some(scale) = distance_scale(&graph.knn().distances) {
            let knn = graph.knn();
            let scaled = KnnGraph::from_knn(Knn {
                rows: knn.rows.clone(),
                indices: knn.indices.clone(),
                distances: knn.distances.mapv(|x| x / scale),
            })?;
            return Ok(rescaled(self.fit_knn(&scaled, progress)?, scale));
        }
        let p = &self.0;
        let n = graph.points();
        check_dim(p.dim, n)?;
        if p.k >= n {
            return Err(EmbedError::KTooLarge { k: p.k, points: n });
        }
        if p.k > graph.k() {
            return Err(EmbedError::Knn(format!(
                "the graph has {} neighbours per point but k = {} was asked; use k ≤ {} or recompute the graph with more neighbours",
                graph.k(),
                p.k,
                graph.k()
            )));
        }
        let csr = Csr::from_knn(graph, p.k);
        let (components, largest) = csr.components();
        if components > 1 {
            return Err(EmbedError::Disconnected {
                k: p.k,
                components,
                largest,
                points: n,
            });
        }
        let mut rng = ChaCha8Rng::seed_from_u64(p.seed);
        match p.landmarks {
            Some(l) if l < n => {
                let (landmarks, g) = match p.landmark_choice {
                    LandmarkChoice::Random => {
                        let mut all: Vec<usize> = (0..n).collect();
                        for i in 0..l {
                            let j = rng.random_range(i..n);
                            all.swap(i, j);
                        }
                        all.truncate(l);
                        let g = csr.geodesics(&all, progress);
                        (all, g)
                    }
                    LandmarkChoice::MaxMin => maxmin(&csr, l, rng.random_range(0..n), progress)?,
                };
                let sq = Array2::from_shape_fn((l, l), |(a, b)| {
                    let d = 0.5 * (g[[a, landmarks[b]]] + g[[b, landmarks[a]]]);
                    d * d
                });
                let fit = classical_mds(sq, p.dim, p.solver, p.seed, false)?;
                let tri = Triangulation {
                    landmark_coordinates: fit.coordinates,
                    eigenvalues: fit.used,
                    mean_sq: fit.mean_sq,
                    landmarks: landmarks.clone(),
                    geodesic: None,
                };
                let rows: Vec<Vec<f64>> = (0..n)
                    .into_par_iter()
                    .map(|a| {
                        let delta = g.column(a).mapv(|d| d * d);
                        tri.place(delta.view())
                    })
                    .collect();
                let coordinates = Array2::from_shape_fn((n, p.dim), |(a, c)| rows[a][c]);
                let tri = Triangulation {
                    geodesic: Some((g, p.k)),
                    ..tri
                };
                Ok(Embedded {
                    coordinates,
                    report: self.report(n, fit.eigenvalues, fit.trace, landmarks),
                    extender: Extender::Triangulation(Box::new(tri)),
                })
            }
            _ => {
                let sources: Vec<usize> = (0..n).collect();
                let g = csr.geodesics(&sources, progress);
                // Dijkstra's sums are exact per path, but symmetrise anyway.
                let sq = Array2::from_shape_fn((n, n), |(a, b)| {
                    let d = 0.5 * (g[[a, b]] + g[[b, a]]);
                    d * d
                });
                let fit = classical_mds(sq, p.dim, p.solver, p.seed, false)?;
                let tri = Triangulation {
                    landmark_coordinates: fit.coordinates.clone(),
                    eigenvalues: fit.used,
                    mean_sq: fit.mean_sq,
                    landmarks: sources,
                    geodesic: Some((g, p.k)),
                };
                Ok(Embedded {
                    coordinates: fit.coordinates,
                    report: self.report(n, fit.eigenvalues, fit.trace, Vec::new()),
                    extender: Extender::Triangulation(Box::new(tri)),
                })
            }
        }
    }

    fn report(
        &self,
        n: usize,
        eigenvalues: Vec<f64>,
        trace: f64,
        landmarks: Vec<usize>,
    ) -> EmbedReport {
        EmbedReport {
            method: "isomap".into(),
            points: n,
            dim: self.0.dim,
            eigenvalues,
            eigenvalue_trace: Some(trace),
            landmarks,
            k: Some(self.0.k),
            ..Default::default()
        }
    }
}

/// MaxMin landmarks by geodesic distance: `(landmarks, geodesic rows (L, M))`. The
/// traversal is [`FarthestFirst`]'s; each landmark's row comes from Dijkstra on the
/// graph (there is no dense matrix) and is kept for the triangulation.
fn maxmin(
    csr: &Csr,
    l: usize,
    first: usize,
    progress: &dyn Progress,
) -> Result<(Vec<usize>, Array2<f64>), EmbedError> {
    let n = csr.len();
    let mut g = Array2::zeros((l, n));
    let mut traversal = FarthestFirst::new(n, first)?;
    let mut heap = BinaryHeap::new();
    progress.start("dijkstra", l as u64);
    for mut row in g.rows_mut() {
        let row = row.as_slice_mut().expect("standard layout");
        csr.dijkstra(traversal.next_landmark(), row, &mut heap);
        traversal.add(&*row);
        progress.advance(1);
    }
    progress.finish();
    Ok((traversal.finish().rows, g))
}

impl Embedding for IsomapValidParams {
    fn name(&self) -> &'static str {
        "isomap"
    }

    fn fit_knn(&self, graph: &KnnGraph, progress: &dyn Progress) -> Result<Embedded, EmbedError> {
        IsomapValidParams::fit_knn(self, graph, progress)
    }
    fn dim(&self) -> usize {
        self.0.dim
    }
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(&self.0).expect("parameters serialise")
    }
    fn fit_checked(
        &self,
        distances: ArrayView2<'_, f64>,
        progress: &dyn Progress,
    ) -> Result<Embedded, EmbedError> {
        let graph = KnnGraph::from_distances(distances, self.0.k)?;
        self.fit_knn(&graph, progress)
    }

    /// The geodesics from the landmarks (two `L × M` matrices), or all of them and
    /// classical MDS of their matrix.
    fn working_bytes(&self, points: usize) -> u64 {
        let m = points as u64;
        match self.0.landmarks {
            Some(l) if (l as u64) < m => 2u64
                .saturating_mul(l as u64)
                .saturating_mul(m)
                .saturating_mul(8),
            _ => super::square_bytes(m).saturating_add(super::mds_bytes(m)),
        }
    }

    fn memory_fix(&self) -> &'static str {
        "lower exploration.n (M), or set embedding.landmarks"
    }
}
