//! Vietoris–Rips persistent homology of a distance matrix, with coefficients in `Z/2`.
//!
//! The Rips complex `R_t` holds every simplex whose vertices are pairwise at distance
//! at most `t`; its diameter filtration `t ↦ R_t` is cut at a threshold (by default
//! the enclosing radius `min_i max_j d(i, j)`, beyond which `R_t` is a cone and has
//! the homology of a point, so no bar is lost). A bar `[birth, death)` of dimension
//! `k` is a `k`-dimensional hole alive on `[birth, death)`; an infinite bar
//! (`death = None`) outlives the threshold.
//!
//! The algorithm is Bauer's Ripser (J. Appl. Comput. Topol. 5, 2021), ported for this
//! crate: simplices are named by the combinatorial number system, `H0` comes from
//! union–find on the edges, and higher dimensions from the reduction of the coboundary
//! matrix (persistent cohomology) column by column in reverse filtration order, with
//! - *clearing*: a simplex that was a pivot in dimension `k − 1` is not a column of
//!   dimension `k`;
//! - *apparent pairs*: a simplex `σ` whose oldest cofacet `τ` has `σ` as its youngest
//!   facet, at the same diameter, is a zero-length pair that is never reduced; and
//!   when a pivot lies in such a pair, the facet's coboundary is added directly;
//! - *emergent pairs*: the reduction of a column stops at its first cofacet of equal
//!   diameter when that cofacet is not yet a pivot;
//! - implicit matrices: coboundaries are enumerated from the distance matrix on demand
//!   and only the reduction matrix `V` is stored.
//!
//! One addition to Ripser: the reduction runs in passes over diameter bands (the first
//! ending at the 5 % quantile of the edge lengths, then growing by 1.2), with
//! coboundaries cut at the band's end. Cutting the late rows changes no earlier pivot,
//! so the result is exact, but the many short-lived classes of a sampled manifold are
//! settled with small heaps, and only the few long-lived ones pay for large
//! coboundaries (on the arm's 1500-point matrix: the same diagrams as the `ripser`
//! program, in about the same time, about 20 s, and a fifth of its memory).
//!
//! The refined filtration orders simplices by diameter, then by decreasing
//! combinatorial index (Ripser's order), so results match the `ripser` program's.
//! The apparent-pair test of the edges runs in parallel; the reduction itself is
//! sequential and deterministic.

use std::collections::{BinaryHeap, HashMap};
use std::hash::{BuildHasherDefault, Hasher};

use ndarray::ArrayView2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::collapse::collapse_edges;
use super::AnalysisError;
use crate::progress::Progress;

/// One bar of a persistence diagram.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bar {
    /// Diameter at which the class is born.
    pub birth: f64,
    /// Diameter at which it dies; `None` when it outlives the threshold.
    pub death: Option<f64>,
}

impl Bar {
    /// `death − birth`, with an infinite bar cut at `threshold`.
    pub fn length(&self, threshold: f64) -> f64 {
        self.death.unwrap_or(threshold).max(self.birth) - self.birth
    }
}

/// Persistence diagrams of dimensions `0..=max_dim`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Persistence {
    /// The Rips threshold used.
    pub threshold: f64,
    /// `diagrams[k]`: the bars of dimension `k` with positive length, sorted by birth
    /// then death (infinite last).
    pub diagrams: Vec<Vec<Bar>>,
}

/// The rule reading Betti numbers off the diagrams.
///
/// In each dimension the bar lengths are sorted, `l_1 ≥ l_2 ≥ … ≥ l_m`, with
/// `l_{m+1} = 0` and infinite bars cut at the threshold `t`. With the noise floor
/// `f = noise_fraction · t`, `b_k` is the largest `i` with
/// `l_i ≥ gap_ratio · max(l_{i+1}, f)`, or 0 when there is none: the long bars stand
/// `gap_ratio` times above the next bar and above the noise floor. `b_0` is at least
/// the number of infinite `H0` bars (components still apart at the threshold).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BettiRule {
    /// Smallest ratio between a significant bar and the next (or the noise floor).
    /// Default 3.
    pub gap_ratio: f64,
    /// The noise floor, as a fraction of the threshold. Default 0.1.
    pub noise_fraction: f64,
}

impl Default for BettiRule {
    fn default() -> Self {
        Self {
            gap_ratio: 3.0,
            noise_fraction: 0.1,
        }
    }
}

impl BettiRule {
    /// Betti numbers of every dimension of `persistence`.
    pub fn betti(&self, persistence: &Persistence) -> Vec<usize> {
        let t = persistence.threshold;
        let floor = self.noise_fraction * t;
        persistence
            .diagrams
            .iter()
            .enumerate()
            .map(|(dim, bars)| {
                let mut lengths: Vec<f64> = bars.iter().map(|b| b.length(t)).collect();
                lengths.sort_by(|a, b| b.total_cmp(a));
                lengths.push(0.0);
                let by_gap = (0..lengths.len() - 1)
                    .rev()
                    .find(|&i| {
                        lengths[i] > 0.0 && lengths[i] >= self.gap_ratio * lengths[i + 1].max(floor)
                    })
                    .map_or(0, |i| i + 1);
                let infinite = bars.iter().filter(|b| b.death.is_none()).count();
                if dim == 0 {
                    by_gap.max(infinite)
                } else {
                    by_gap
                }
            })
            .collect()
    }
}

/// Whether the Rips filtration is edge-collapsed before its reduction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Collapse {
    /// Collapse dominated edges (Glisse & Pritam 2022): the same diagrams, from a
    /// sparser graph.
    Edges,
    /// Reduce the full Rips filtration. The default.
    #[default]
    None,
}

/// `min_i max_j d(i, j)`: from this diameter on the Rips complex is a cone.
pub fn enclosing_radius(distances: ArrayView2<'_, f64>) -> f64 {
    distances
        .outer_iter()
        .map(|row| row.iter().copied().fold(0.0, f64::max))
        .fold(f64::INFINITY, f64::min)
}

/// The reduction's first band ends at this quantile of the edge lengths (see
/// `Rips::reduce`)...
const LEVEL_QUANTILE: f64 = 0.05;
/// ...the next ones grow by this factor...
const LEVEL_RATIO: f64 = 1.1;
/// ...when there are at least this many edges.
const LEVEL_MIN_EDGES: usize = 20_000;

/// Largest number of triangles (`C(n, 3)`) the `H2` computation enumerates.
const MAX_TRIANGLES: u64 = 100_000_000;

/// Persistent homology of the Rips filtration of `distances` (symmetric, zero
/// diagonal, checked by the caller) in dimensions `0..=max_dim`, up to `threshold`
/// (`None`: the enclosing radius).
///
/// `H1` needs `O(n²)` memory and about `O(n³)` time in the worst case; `H2` enumerates
/// triangles and is refused above `C(n, 3) = 10⁸` (about 850 points): subsample first.
pub fn rips_persistence(
    distances: ArrayView2<'_, f64>,
    max_dim: usize,
    threshold: Option<f64>,
    progress: &dyn Progress,
) -> Result<Persistence, AnalysisError> {
    rips_persistence_with(distances, max_dim, threshold, Collapse::default(), progress)
}

/// [`rips_persistence`], with the edge collapse chosen.
pub fn rips_persistence_with(
    distances: ArrayView2<'_, f64>,
    max_dim: usize,
    threshold: Option<f64>,
    collapse: Collapse,
    progress: &dyn Progress,
) -> Result<Persistence, AnalysisError> {
    let n = distances.nrows();
    let threshold = threshold.unwrap_or_else(|| enclosing_radius(distances));
    let binomial = Binomial::new(n, max_dim + 2);
    if max_dim >= 2 && binomial.get(n, 3) > MAX_TRIANGLES {
        return Err(AnalysisError::TooLarge {
            what: format!("H{max_dim} of {n} points"),
            limit: "C(n, 3) <= 1e8 triangles (about 850 points); lower max_points",
        });
    }
    let dist: Vec<f64> = distances.iter().copied().collect();
    let collapsed = match collapse {
        Collapse::Edges => {
            // Beyond the enclosing radius the complex is a cone: no bar lives there,
            // so the whole filtration (ending on the complete graph, which
            // collapses best) has the same diagrams as the one cut at the radius.
            let radius = enclosing_radius(distances);
            let whole = if threshold >= radius {
                f64::INFINITY
            } else {
                threshold
            };
            let g = collapse_edges(n, &dist, whole, threshold);
            Some(g)
        }
        Collapse::None => None,
    };
    let rips = match &collapsed {
        Some(graph) => Rips {
            n,
            dist: &graph.values,
            neighbors: Some(&graph.neighbors),
            threshold,
            binomial,
        },
        None => Rips {
            n,
            dist: &dist,
            neighbors: None,
            threshold,
            binomial,
        },
    };
    let mut diagrams = Vec::with_capacity(max_dim + 1);
    progress.start("homology", max_dim as u64 + 1);
    let (h0, mut columns, levels) = rips.dim_zero(max_dim > 0);
    diagrams.push(h0);
    progress.advance(1);
    let mut simplices: Vec<Entry> = Vec::new();
    if max_dim >= 2 {
        simplices = rips.edges();
    }
    for dim in 1..=max_dim {
        let (bars, pivots) = rips.reduce(dim, &columns, &levels);
        diagrams.push(bars);
        if dim < max_dim {
            let (next_columns, next_simplices) =
                rips.assemble(&simplices, dim + 1, &pivots, dim + 1 < max_dim);
            columns = next_columns;
            simplices = next_simplices;
        }
        progress.advance(1);
    }
    progress.finish();
    for bars in &mut diagrams {
        bars.sort_by(|a, b| {
            a.birth.total_cmp(&b.birth).then_with(|| {
                a.death
                    .unwrap_or(f64::INFINITY)
                    .total_cmp(&b.death.unwrap_or(f64::INFINITY))
            })
        });
    }
    Ok(Persistence {
        threshold,
        diagrams,
    })
}

/// A simplex: its diameter and its index in the combinatorial number system.
#[derive(Debug, Clone, Copy)]
struct Entry {
    diameter: f64,
    index: u64,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.index == other.index
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    /// Greater = earlier in the filtration (smaller diameter, then larger index), so
    /// that the top of a max-heap is a coboundary's pivot.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other
            .diameter
            .total_cmp(&self.diameter)
            .then(self.index.cmp(&other.index))
    }
}

/// `C(n, k)` for `n ≤ n_max`, `k ≤ k_max`.
struct Binomial {
    k_max: usize,
    table: Vec<u64>,
}

impl Binomial {
    fn new(n_max: usize, k_max: usize) -> Self {
        let width = k_max + 1;
        let mut table = vec![0u64; (n_max + 1) * width];
        for i in 0..=n_max {
            table[i * width] = 1;
            for j in 1..=k_max.min(i) {
                table[i * width + j] =
                    table[(i - 1) * width + j - 1].saturating_add(table[(i - 1) * width + j]);
            }
        }
        Self { k_max, table }
    }

    #[inline]
    fn get(&self, n: usize, k: usize) -> u64 {
        if k > n {
            0
        } else {
            self.table[n * (self.k_max + 1) + k]
        }
    }
}

/// Hash of simplex indices (Fx-style multiply; indices are already well spread).
#[derive(Default)]
struct IndexHasher(u64);

impl Hasher for IndexHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(5) ^ u64::from(b)).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
        }
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

type PivotMap = HashMap<u64, usize, BuildHasherDefault<IndexHasher>>;

struct Rips<'a> {
    n: usize,
    /// Edge values, row-major; `∞` where an edge was collapsed.
    dist: &'a [f64],
    /// With a collapsed graph: the neighbours of every vertex, decreasing.
    neighbors: Option<&'a [Vec<u32>]>,
    threshold: f64,
    binomial: Binomial,
}

impl Rips<'_> {
    #[inline]
    fn d(&self, i: usize, j: usize) -> f64 {
        self.dist[i * self.n + j]
    }

    /// Largest `v ≤ top` with `C(v, k) ≤ index`.
    fn max_vertex(&self, index: u64, k: usize, top: usize) -> usize {
        let (mut low, mut high) = (k.saturating_sub(1), top);
        // Invariant: C(low, k) ≤ index; the answer lies in [low, high].
        while low < high {
            let mid = high - (high - low) / 2;
            if self.binomial.get(mid, k) <= index {
                low = mid;
            } else {
                high = mid - 1;
            }
        }
        low
    }

    /// Vertices of simplex `index` of dimension `dim`, decreasing.
    fn vertices(&self, mut index: u64, dim: usize, out: &mut Vec<usize>) {
        out.clear();
        let mut top = self.n - 1;
        for k in (1..=dim + 1).rev() {
            let v = self.max_vertex(index, k, top);
            out.push(v);
            index -= self.binomial.get(v, k);
            top = v.saturating_sub(1);
        }
    }

    /// Every edge within the threshold, in increasing index order.
    fn edges(&self) -> Vec<Entry> {
        let mut edges = Vec::new();
        if let Some(neighbors) = self.neighbors {
            for (j, list) in neighbors.iter().enumerate() {
                for &i in list.iter().rev().filter(|&&i| (i as usize) < j) {
                    edges.push(Entry {
                        diameter: self.d(i as usize, j),
                        index: self.binomial.get(j, 2) + u64::from(i),
                    });
                }
            }
            return edges;
        }
        for j in 1..self.n {
            for i in 0..j {
                let diameter = self.d(i, j);
                if diameter <= self.threshold {
                    edges.push(Entry {
                        diameter,
                        index: self.binomial.get(j, 2) + i as u64,
                    });
                }
            }
        }
        edges
    }

    /// Cofacets of `simplex` (dimension `dim`) within the threshold, in decreasing
    /// index order; `only_new`: only those whose added vertex is the largest.
    fn for_each_cofacet(
        &self,
        simplex: Entry,
        dim: usize,
        vertices: &mut Vec<usize>,
        only_new: bool,
        (lower, limit): (f64, f64),
        mut visit: impl FnMut(Entry) -> bool,
    ) {
        self.vertices(simplex.index, dim, vertices);
        if let Some(neighbors) = self.neighbors {
            self.for_each_sparse_cofacet(
                neighbors,
                simplex,
                vertices,
                only_new,
                (lower, limit),
                visit,
            );
            return;
        }
        // From here on `vertices` holds the offsets of the vertices' rows.
        for v in vertices.iter_mut() {
            *v *= self.n;
        }
        let b = &self.binomial;
        let mut below = simplex.index;
        let mut above = 0u64;
        let mut k = dim + 1;
        let mut j = self.n as isize - 1;
        while j >= k as isize {
            let ju = j as usize;
            if only_new && b.get(ju, k) <= below {
                return;
            }
            while b.get(j as usize, k) <= below {
                below -= b.get(j as usize, k);
                above += b.get(j as usize, k + 1);
                j -= 1;
                k -= 1;
            }
            if j < 0 {
                return;
            }
            let ju = j as usize;
            // d(j, v) = d(v, j): walk the vertices' rows, which j sweeps in order.
            let mut diameter = simplex.diameter;
            for &row in vertices.iter() {
                diameter = diameter.max(self.dist[row + ju]);
            }
            if diameter <= limit && diameter > lower {
                let index = above + b.get(ju, k + 1) + below;
                if !visit(Entry { diameter, index }) {
                    return;
                }
            }
            j -= 1;
        }
    }

    /// [`Rips::for_each_cofacet`] of a collapsed graph, `vertices` holding the
    /// simplex's vertices (decreasing): the candidate vertices are the neighbours of
    /// the simplex's vertex of least degree.
    fn for_each_sparse_cofacet(
        &self,
        neighbors: &[Vec<u32>],
        simplex: Entry,
        vertices: &[usize],
        only_new: bool,
        (lower, limit): (f64, f64),
        mut visit: impl FnMut(Entry) -> bool,
    ) {
        let b = &self.binomial;
        let size = vertices.len();
        let Some(&sparsest) = vertices.iter().min_by_key(|&&v| neighbors[v].len()) else {
            return;
        };
        // With `t` vertices above `j`, the cofacet's index is
        // above + C(j, size + 1 − t) + below.
        let mut t = 0;
        let mut below = simplex.index;
        let mut above = 0u64;
        for &j in &neighbors[sparsest] {
            let j = j as usize;
            if only_new && j < vertices[0] {
                return;
            }
            while t < size && vertices[t] > j {
                below -= b.get(vertices[t], size - t);
                above += b.get(vertices[t], size + 1 - t);
                t += 1;
            }
            if t < size && vertices[t] == j {
                continue;
            }
            let mut diameter = simplex.diameter;
            for &v in vertices {
                diameter = diameter.max(self.dist[v * self.n + j]);
            }
            if diameter <= limit && diameter > lower {
                let index = above + b.get(j, size + 1 - t) + below;
                if !visit(Entry { diameter, index }) {
                    return;
                }
            }
        }
    }

    /// The cofacet of equal diameter that is the pivot of `simplex`'s coboundary, if any.
    fn zero_pivot_cofacet(
        &self,
        simplex: Entry,
        dim: usize,
        vertices: &mut Vec<usize>,
    ) -> Option<Entry> {
        let mut found = None;
        self.for_each_cofacet(simplex, dim, vertices, false, (-1.0, self.threshold), |c| {
            if c.diameter == simplex.diameter {
                found = Some(c);
                false
            } else {
                true
            }
        });
        found
    }

    /// The youngest facet of equal diameter of `simplex` (dimension `dim ≥ 1`), if any.
    fn zero_pivot_facet(
        &self,
        simplex: Entry,
        dim: usize,
        vertices: &mut Vec<usize>,
    ) -> Option<Entry> {
        self.vertices(simplex.index, dim, vertices);
        let b = &self.binomial;
        let mut below = simplex.index;
        let mut above = 0u64;
        // Facets in increasing index order: drop the largest vertex first.
        for (position, k) in (0..=dim).rev().enumerate() {
            let j = vertices[position];
            let index = above + below - b.get(j, k + 1);
            let mut diameter: f64 = 0.0;
            for (a, &u) in vertices.iter().enumerate() {
                if a == position {
                    continue;
                }
                for (c, &v) in vertices.iter().enumerate().skip(a + 1) {
                    if c != position {
                        diameter = diameter.max(self.d(u, v));
                    }
                }
            }
            if diameter == simplex.diameter {
                return Some(Entry { diameter, index });
            }
            below -= b.get(j, k + 1);
            above += b.get(j, k);
        }
        None
    }

    fn zero_apparent_cofacet(
        &self,
        simplex: Entry,
        dim: usize,
        vertices: &mut Vec<usize>,
    ) -> Option<Entry> {
        let cofacet = self.zero_pivot_cofacet(simplex, dim, vertices)?;
        let facet = self.zero_pivot_facet(cofacet, dim + 1, vertices)?;
        (facet.index == simplex.index).then_some(cofacet)
    }

    fn zero_apparent_facet(
        &self,
        simplex: Entry,
        dim: usize,
        vertices: &mut Vec<usize>,
    ) -> Option<Entry> {
        let facet = self.zero_pivot_facet(simplex, dim, vertices)?;
        let cofacet = self.zero_pivot_cofacet(facet, dim - 1, vertices)?;
        (cofacet.index == simplex.index).then_some(facet)
    }

    /// The band limits of the reduction (see [`Rips::reduce`]): the `LEVEL_QUANTILE`
    /// quantile of the edge lengths (`edges` in filtration order), then steps of
    /// `LEVEL_RATIO`, up to the threshold. A single band for small complexes.
    fn levels(&self, edges: &[Entry]) -> Vec<f64> {
        let mut levels = Vec::new();
        if edges.len() >= LEVEL_MIN_EDGES {
            let mut s = edges[(edges.len() as f64 * LEVEL_QUANTILE) as usize].diameter;
            while s > 0.0 && s < self.threshold {
                levels.push(s);
                s *= LEVEL_RATIO;
            }
        }
        levels.push(self.threshold);
        levels
    }

    /// `H0` by union–find over the edges, and the edge columns of `H1` (non-tree edges
    /// not in an apparent pair), in reverse filtration order.
    fn dim_zero(&self, want_columns: bool) -> (Vec<Bar>, Vec<Entry>, Vec<f64>) {
        let mut edges = self.edges();
        // Filtration order: diameter up, then index down.
        edges.par_sort_unstable_by(|a, b| b.cmp(a));
        let levels = self.levels(&edges);
        let apparent: Vec<bool> = if want_columns {
            edges
                .par_iter()
                .map_init(Vec::new, |vertices, &e| {
                    self.zero_apparent_cofacet(e, 1, vertices).is_some()
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut parent: Vec<usize> = (0..self.n).collect();
        let mut rank = vec![0u8; self.n];
        fn find(parent: &mut [usize], mut x: usize) -> usize {
            while parent[x] != x {
                parent[x] = parent[parent[x]];
                x = parent[x];
            }
            x
        }
        let mut bars = Vec::new();
        let mut columns = Vec::new();
        let mut vertices = Vec::with_capacity(2);
        for (position, &e) in edges.iter().enumerate() {
            self.vertices(e.index, 1, &mut vertices);
            let (u, v) = (
                find(&mut parent, vertices[0]),
                find(&mut parent, vertices[1]),
            );
            if u != v {
                if e.diameter > 0.0 {
                    bars.push(Bar {
                        birth: 0.0,
                        death: Some(e.diameter),
                    });
                }
                match rank[u].cmp(&rank[v]) {
                    std::cmp::Ordering::Less => parent[u] = v,
                    std::cmp::Ordering::Greater => parent[v] = u,
                    std::cmp::Ordering::Equal => {
                        parent[v] = u;
                        rank[u] += 1;
                    }
                }
            } else if want_columns && !apparent[position] {
                columns.push(e);
            }
        }
        columns.reverse();
        for i in 0..self.n {
            if find(&mut parent, i) == i {
                bars.push(Bar {
                    birth: 0.0,
                    death: None,
                });
            }
        }
        (bars, columns, levels)
    }

    /// Pushes `simplex` into the reduction column, and its cofacets with diameter in
    /// `band = (lower, limit]` into the coboundary heap.
    fn add_simplex_coboundary(
        &self,
        simplex: Entry,
        dim: usize,
        band: (f64, f64),
        work: &mut Working,
    ) {
        work.reduction.push(simplex);
        let coboundary = &mut work.coboundary;
        self.for_each_cofacet(simplex, dim, &mut work.vertices, false, band, |c| {
            coboundary.push(c);
            true
        });
    }

    /// Starts the working column from `partial` (a column followed by its partial
    /// reduction): the reduction column holds `partial`, and the sorted part of the
    /// coboundary its cofacets in `band`, summed (enumerated and sorted in
    /// parallel: a long-lived column carries tens of thousands of simplices).
    fn rebuild(&self, dim: usize, band: (f64, f64), partial: Vec<Entry>, w: &mut Working) {
        let chunks: Vec<Vec<Entry>> = partial
            .par_chunks(256)
            .map(|chunk| {
                let mut vertices = Vec::with_capacity(dim + 1);
                let mut out = Vec::new();
                for &e in chunk {
                    self.for_each_cofacet(e, dim, &mut vertices, false, band, |c| {
                        out.push(c);
                        true
                    });
                }
                out
            })
            .collect();
        let mut all = Vec::with_capacity(chunks.iter().map(Vec::len).sum());
        for chunk in chunks {
            all.extend(chunk);
        }
        // Filtration order (earliest first); equal entries are adjacent and cancel.
        all.par_sort_unstable_by(|a, b| b.cmp(a));
        let sorted = &mut w.sorted;
        sorted.clear();
        for e in all {
            if sorted
                .last()
                .is_some_and(|last: &Entry| last.index == e.index)
            {
                sorted.pop();
            } else {
                sorted.push(e);
            }
        }
        w.next = 0;
        w.reduction.extend(partial);
    }

    /// Reduces the coboundary columns of dimension `dim` (in reverse filtration order).
    /// Returns the bars and the pivots (cofacet index → column).
    ///
    /// The reduction runs in passes over increasing diameter bands
    /// `(s_{k−1}, s_k]` (`levels`, ending at the threshold). Cutting the rows after
    /// `s_k` changes no pivot `≤ s_k` (an addition is decided by a pivot, and all
    /// entries of an added column lie at or after its pivot), so pass `k` finishes
    /// exactly every column whose pivot lies in the band, with heaps that hold only
    /// the band. It takes, in column order, the columns of diameter in the band and
    /// the columns the previous pass left without a pivot, continuing from their
    /// partial reduction (whose coboundary is zero up to `s_{k−1}`); their pivots are
    /// all in the band or later, so they only ever meet each other's pivots.
    fn reduce(&self, dim: usize, columns: &[Entry], levels: &[f64]) -> (Vec<Bar>, PivotMap) {
        let mut pivots = PivotMap::default();
        pivots.reserve(columns.len());
        let mut bars = Vec::new();
        let mut left: Vec<(usize, Vec<Entry>)> = Vec::new();
        let mut lower = f64::NEG_INFINITY;
        for (k, &limit) in levels.iter().enumerate() {
            let mut work: Vec<(usize, Vec<Entry>)> = (0..columns.len())
                .filter(|&i| columns[i].diameter > lower && columns[i].diameter <= limit)
                .map(|i| (i, Vec::new()))
                .chain(std::mem::take(&mut left))
                .collect();
            work.sort_by_key(|w| w.0);
            let last = k + 1 == levels.len();
            left = self.reduce_pass(
                dim,
                columns,
                work,
                (lower, limit),
                last,
                &mut pivots,
                &mut bars,
            );
            lower = limit;
        }
        (bars, pivots)
    }

    /// One reduction pass over `work` (column positions, in order, each with the
    /// partial reduction column it starts from), with coboundaries cut to `band`.
    /// Columns left without a pivot are essential bars when `last`, and are returned
    /// with their partial reduction otherwise.
    #[allow(clippy::too_many_arguments, reason = "one private pass of `reduce`")]
    fn reduce_pass(
        &self,
        dim: usize,
        columns: &[Entry],
        work: Vec<(usize, Vec<Entry>)>,
        band: (f64, f64),
        last: bool,
        pivots: &mut PivotMap,
        bars: &mut Vec<Bar>,
    ) -> Vec<(usize, Vec<Entry>)> {
        // Reduction matrix V without its diagonal, in compressed columns, for the
        // columns of this pass (the only ones its pivots can meet).
        let mut v_range: Vec<(usize, usize)> = vec![(0, 0); columns.len()];
        let mut v_entries: Vec<Entry> = Vec::new();
        let mut left = Vec::new();
        let mut w = Working::default();
        let mut cofacets: Vec<Entry> = Vec::new();
        let mut scratch = Vec::with_capacity(dim + 2);
        for (position, partial) in work {
            let column = columns[position];
            w.clear();
            let mut pivot = if partial.is_empty() {
                // Coboundary of the column, stopping at an emergent pair.
                cofacets.clear();
                let mut check_emergent = true;
                let mut emergent = None;
                self.for_each_cofacet(column, dim, &mut w.vertices, false, band, |c| {
                    cofacets.push(c);
                    if check_emergent && c.diameter == column.diameter {
                        if !pivots.contains_key(&c.index)
                            && self.zero_apparent_facet(c, dim + 1, &mut scratch).is_none()
                        {
                            emergent = Some(c);
                            return false;
                        }
                        check_emergent = false;
                    }
                    true
                });
                match emergent {
                    Some(c) => Some(c),
                    None => {
                        w.coboundary.extend(cofacets.drain(..));
                        w.top_pivot()
                    }
                }
            } else {
                // `partial` is the column followed by its partial reduction; the
                // column itself (V's diagonal) is dropped again when V is stored.
                self.rebuild(dim, band, partial, &mut w);
                w.top_pivot()
            };
            loop {
                let Some(p) = pivot else {
                    if last {
                        bars.push(Bar {
                            birth: column.diameter,
                            death: None,
                        });
                    } else {
                        let mut partial = vec![column];
                        while let Some(e) = pop_pivot(&mut w.reduction) {
                            if e.index != column.index {
                                partial.push(e);
                            }
                        }
                        left.push((position, partial));
                    }
                    break;
                };
                if let Some(&other) = pivots.get(&p.index) {
                    let (start, end) = v_range[other];
                    debug_assert!(other < position);
                    self.add_simplex_coboundary(columns[other], dim, band, &mut w);
                    for &e in &v_entries[start..end] {
                        self.add_simplex_coboundary(e, dim, band, &mut w);
                    }
                    pivot = w.top_pivot();
                } else if let Some(e) = self.zero_apparent_facet(p, dim + 1, &mut scratch) {
                    self.add_simplex_coboundary(e, dim, band, &mut w);
                    pivot = w.top_pivot();
                } else {
                    if p.diameter > column.diameter {
                        bars.push(Bar {
                            birth: column.diameter,
                            death: Some(p.diameter),
                        });
                    }
                    pivots.insert(p.index, position);
                    let start = v_entries.len();
                    while let Some(e) = pop_pivot(&mut w.reduction) {
                        if e.index != column.index {
                            v_entries.push(e);
                        }
                    }
                    v_range[position] = (start, v_entries.len());
                    break;
                }
            }
        }
        left
    }

    /// Columns of dimension `dim` (cofacets of `simplices`, which have dimension
    /// `dim − 1`): those within the threshold, not cleared by `pivots` and not in an
    /// apparent pair, in reverse filtration order. Also returns the simplices of
    /// dimension `dim` when `keep_simplices`.
    fn assemble(
        &self,
        simplices: &[Entry],
        dim: usize,
        pivots: &PivotMap,
        keep_simplices: bool,
    ) -> (Vec<Entry>, Vec<Entry>) {
        let mut columns = Vec::new();
        let mut next = Vec::new();
        let mut vertices = Vec::new();
        let mut scratch = Vec::new();
        for &simplex in simplices {
            let mut found = Vec::new();
            self.for_each_cofacet(
                simplex,
                dim - 1,
                &mut vertices,
                true,
                (-1.0, self.threshold),
                |c| {
                    found.push(c);
                    true
                },
            );
            for c in found {
                if keep_simplices {
                    next.push(c);
                }
                if !pivots.contains_key(&c.index)
                    && self.zero_apparent_facet(c, dim, &mut scratch).is_none()
                    && self.zero_apparent_cofacet(c, dim, &mut scratch).is_none()
                {
                    columns.push(c);
                }
            }
        }
        // Reverse filtration order: diameter down, then index up.
        columns.par_sort_unstable();
        (columns, next)
    }
}

/// The working columns of one reduction.
#[derive(Default)]
struct Working {
    /// The reduction column (simplices of the column's dimension).
    reduction: BinaryHeap<Entry>,
    /// Its coboundary (cofacets): the sum of `coboundary` and `sorted[next..]`.
    coboundary: BinaryHeap<Entry>,
    /// Part of the coboundary, in filtration order, without repeated entries.
    sorted: Vec<Entry>,
    /// The first entry of `sorted` still in the coboundary.
    next: usize,
    /// Scratch for simplex vertices.
    vertices: Vec<usize>,
}

impl Working {
    fn clear(&mut self) {
        self.reduction.clear();
        self.coboundary.clear();
        self.sorted.clear();
        self.next = 0;
    }

    /// The pivot of the coboundary, left in it.
    fn top_pivot(&mut self) -> Option<Entry> {
        loop {
            let heap = pop_pivot(&mut self.coboundary);
            let sorted = self.sorted.get(self.next).copied();
            match (heap, sorted) {
                (Some(h), Some(s)) if h.index == s.index => self.next += 1,
                (Some(h), Some(s)) => {
                    self.coboundary.push(h);
                    return Some(if h > s { h } else { s });
                }
                (Some(h), None) => {
                    self.coboundary.push(h);
                    return Some(h);
                }
                (None, s) => return s,
            }
        }
    }
}

/// Pops the pivot of a `Z/2` column held as a heap (equal entries cancel in pairs).
fn pop_pivot(heap: &mut BinaryHeap<Entry>) -> Option<Entry> {
    loop {
        let top = heap.pop()?;
        match heap.peek() {
            Some(next) if next.index == top.index => {
                heap.pop();
            }
            _ => return Some(top),
        }
    }
}
