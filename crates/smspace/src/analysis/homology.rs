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
//! ending at the 5 % quantile of the edge lengths, then growing by 2.5 %), with
//! coboundaries cut at the band's end. Cutting the late rows changes no earlier pivot,
//! so the result is exact, but the many short-lived classes of a sampled manifold are
//! settled with small heaps, and only the few long-lived ones pay for large
//! coboundaries. Such a column (on the arm's 1500 max–min landmarks, the one of the
//! loop, which carries about 70 000 edges at its death) restarts every band from its
//! partial reduction: the cofacets of its edges in the band are enumerated from the
//! matrix rows sorted by distance (a cost that follows the band, not `n`), in
//! parallel, and summed by a sort rather than pushed on a heap. On that matrix: the
//! same diagrams as the `ripser` program, in about 4.5 s of CPU instead of its 26 s,
//! and a tenth of its memory.
//!
//! The refined filtration orders simplices by diameter, then by decreasing
//! combinatorial index (Ripser's order), so results match the `ripser` program's.
//! The apparent-pair test of the edges and the restart of a column run in parallel;
//! the reduction itself is sequential, and the result deterministic.

use std::collections::{BinaryHeap, HashMap};
use std::hash::{BuildHasherDefault, Hasher};

use ndarray::ArrayView2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

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
                let mut lengths = longest_first(bars, t);
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

impl BettiRule {
    /// The dimensions whose reading is not clear, each with why and what to do: the
    /// longest bar the rule did not count stands at least `gap_ratio` times above the
    /// noise floor (a feature, not noise) but without a gap of `gap_ratio` to the bars
    /// around it, so that `b_k` depends on where the gap is drawn. The sets then form
    /// families at several scales, as kernel sets near a kinematic singularity do (the
    /// sensor within one link of an arm's base, where each set splits into pieces).
    pub fn ambiguities(&self, persistence: &Persistence) -> Vec<String> {
        let t = persistence.threshold;
        let floor = self.noise_fraction * t;
        let betti = self.betti(persistence);
        let mut out = Vec::new();
        for (dim, bars) in persistence.diagrams.iter().enumerate() {
            let lengths = longest_first(bars, t);
            let counted = betti[dim];
            let Some(&uncounted) = lengths.get(counted) else {
                continue;
            };
            if uncounted.is_finite() && uncounted >= self.gap_ratio * floor {
                out.push(format!(
                    "H{dim}: b{dim} = {counted} is ambiguous: the longest bar not counted ({uncounted:.3}, {:.0} % of the threshold {t:.3}) stands above the noise floor without a gap of {} to the bars around it; the sets form families at several scales, as kernel sets near a kinematic singularity do (the sensor within one link of the base, where each set splits into pieces): explore in a working space away from the singularities, or trace every piece (components = \"all\")",
                    100.0 * uncounted / t,
                    self.gap_ratio
                ));
            }
        }
        out
    }
}

/// The bars' lengths, longest first, infinite bars cut at `threshold`.
fn longest_first(bars: &[Bar], threshold: f64) -> Vec<f64> {
    let mut lengths: Vec<f64> = bars.iter().map(|b| b.length(threshold)).collect();
    lengths.sort_by(|a, b| b.total_cmp(a));
    lengths
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
const LEVEL_RATIO: f64 = 1.025;
/// ...when there are at least this many edges.
const LEVEL_MIN_EDGES: usize = 20_000;

/// The rows of a distance matrix sorted by distance, to enumerate an edge's
/// cofacets in a diameter band (see [`Rips::for_each_cofacet_in_band`]).
struct SortedRows {
    /// Every row of the `n × n` matrix as `(distance, column)` pairs sorted by
    /// distance (then column).
    rows: Vec<(f64, u32)>,
    /// The band limits of the reduction, increasing.
    levels: Vec<f64>,
    /// `positions[i · (L + 1) + k]`: how many entries of row `i` are at most
    /// `levels[k − 1]` (0 for `k = 0`), with `L` levels.
    positions: Vec<u32>,
}

impl SortedRows {
    fn new(n: usize, dist: &[f64], levels: &[f64]) -> Self {
        let mut rows: Vec<(f64, u32)> = dist
            .iter()
            .enumerate()
            .map(|(k, &d)| (d, (k % n) as u32))
            .collect();
        rows.par_chunks_mut(n).for_each(|row| {
            row.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        });
        let mut positions = Vec::with_capacity(n * (levels.len() + 1));
        for row in rows.chunks(n) {
            positions.push(0);
            positions.extend(
                levels
                    .iter()
                    .map(|&l| row.partition_point(|&(d, _)| d <= l) as u32),
            );
        }
        Self {
            rows,
            levels: levels.to_vec(),
            positions,
        }
    }

    /// The entries of row `i` (of `n`) with distance in `(lower, limit]`, where the
    /// band is one of the reduction's.
    #[inline]
    fn band(&self, i: usize, n: usize, (lower, limit): (f64, f64)) -> &[(f64, u32)] {
        let row = &self.rows[i * n..(i + 1) * n];
        let width = self.levels.len() + 1;
        let k = self.levels.partition_point(|&l| l < limit);
        if self.levels.get(k) == Some(&limit)
            && (k == 0 && lower == f64::NEG_INFINITY || k > 0 && self.levels[k - 1] == lower)
        {
            let p = &self.positions[i * width..(i + 1) * width];
            &row[p[k] as usize..p[k + 1] as usize]
        } else {
            let from = row.partition_point(|&(d, _)| d <= lower);
            let to = row.partition_point(|&(d, _)| d <= limit);
            &row[from..to]
        }
    }

    /// The entries of row `i` (of `n`) at most `limit`, a band's end.
    #[inline]
    fn within(&self, i: usize, n: usize, limit: f64) -> &[(f64, u32)] {
        let row = &self.rows[i * n..(i + 1) * n];
        let k = self.levels.partition_point(|&l| l < limit);
        if self.levels.get(k) == Some(&limit) {
            &row[..self.positions[i * (self.levels.len() + 1) + k + 1] as usize]
        } else {
            &row[..row.partition_point(|&(d, _)| d <= limit)]
        }
    }
}

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
    let mut rips = Rips {
        n,
        dist: &dist,
        sorted_rows: None,
        threshold,
        binomial,
    };
    let mut diagrams = Vec::with_capacity(max_dim + 1);
    progress.start("homology", max_dim as u64 + 1);
    let (h0, mut columns, levels) = rips.dim_zero(max_dim > 0);
    if max_dim >= 1 {
        rips.sorted_rows = Some(SortedRows::new(n, rips.dist, &levels));
    }
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
    dist: &'a [f64],
    /// With `H1`: every row of `dist` as `(distance, column)` sorted by distance, to
    /// enumerate an edge's cofacets in a diameter band.
    sorted_rows: Option<SortedRows>,
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
        if dim == 1 {
            // An edge: u(u − 1)/2 ≤ index < (u + 1)u/2, from a square root corrected
            // by one step either way.
            let b = &self.binomial;
            let mut u = (((8 * index + 1) as f64).sqrt() as usize).div_ceil(2);
            u = u.min(self.n - 1);
            while b.get(u, 2) > index {
                u -= 1;
            }
            while u + 1 < self.n && b.get(u + 1, 2) <= index {
                u += 1;
            }
            out.push(u);
            out.push((index - b.get(u, 2)) as usize);
            return;
        }
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

    /// The cofacets of `simplex` (dimension `dim`) with diameter in `band =
    /// (lower, limit]`, in no particular order. An edge `uv` of the full matrix takes
    /// its candidates from the rows of `u` and `v` sorted by distance: with
    /// `d(u, v) > lower`, the `j` within `limit` of both; otherwise the `j` in the
    /// band from `u` and within `limit` of `v`, and the `j` in the band from `v` and
    /// within `lower` of `u`. Its cost follows the band's size, not `n`.
    fn for_each_cofacet_in_band(
        &self,
        simplex: Entry,
        dim: usize,
        vertices: &mut Vec<usize>,
        (lower, limit): (f64, f64),
        mut visit: impl FnMut(Entry),
    ) {
        let Some(sorted) = self.sorted_rows.as_ref().filter(|_| dim == 1) else {
            self.for_each_cofacet(simplex, dim, vertices, false, (lower, limit), |c| {
                visit(c);
                true
            });
            return;
        };
        let n = self.n;
        self.vertices(simplex.index, 1, vertices);
        let (u, v) = (vertices[0], vertices[1]);
        let b = &self.binomial;
        let index = |j: usize| -> u64 {
            if j > u {
                b.get(j, 3) + b.get(u, 2) + v as u64
            } else if j > v {
                b.get(u, 3) + b.get(j, 2) + v as u64
            } else {
                b.get(u, 3) + b.get(v, 2) + j as u64
            }
        };
        let (dist_u, dist_v) = (
            &self.dist[u * n..(u + 1) * n],
            &self.dist[v * n..(v + 1) * n],
        );
        if simplex.diameter > lower {
            let (near_u, near_v) = (sorted.within(u, n, limit), sorted.within(v, n, limit));
            let (row, other) = if near_u.len() <= near_v.len() {
                (near_u, dist_v)
            } else {
                (near_v, dist_u)
            };
            for &(d, j) in row {
                let j = j as usize;
                let o = other[j];
                if o <= limit && j != u && j != v {
                    let diameter = simplex.diameter.max(d).max(o);
                    visit(Entry {
                        diameter,
                        index: index(j),
                    });
                }
            }
        } else {
            for (i, other, bound) in [(u, dist_v, limit), (v, dist_u, lower)] {
                for &(d, j) in sorted.band(i, n, (lower, limit)) {
                    let j = j as usize;
                    let o = other[j];
                    // `d > lower ≥ d(u, v)`: `j` is neither `u` nor `v`.
                    if o <= bound {
                        visit(Entry {
                            diameter: d.max(o),
                            index: index(j),
                        });
                    }
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
        self.for_each_cofacet_in_band(simplex, dim, &mut work.vertices, band, |c| {
            coboundary.push(c);
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
                    self.for_each_cofacet_in_band(e, dim, &mut vertices, band, |c| out.push(c));
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};

    /// `H1` bars of `dist` (`n × n`) reduced over `levels` (the default bands when
    /// `None`), sorted.
    fn h1(n: usize, dist: &[f64], levels: Option<Vec<f64>>) -> (usize, Vec<Bar>) {
        let threshold = enclosing_radius(ArrayView2::from_shape((n, n), dist).unwrap());
        let mut rips = Rips {
            n,
            dist,
            sorted_rows: None,
            threshold,
            binomial: Binomial::new(n, 3),
        };
        let (_, columns, default_levels) = rips.dim_zero(true);
        let levels = levels.unwrap_or(default_levels);
        rips.sorted_rows = Some(SortedRows::new(n, dist, &levels));
        let (mut bars, _) = rips.reduce(1, &columns, &levels);
        bars.sort_by(|a, b| {
            a.birth.total_cmp(&b.birth).then(
                a.death
                    .unwrap_or(f64::INFINITY)
                    .total_cmp(&b.death.unwrap_or(f64::INFINITY)),
            )
        });
        (levels.len(), bars)
    }

    #[test]
    fn bands_give_exactly_the_bars_of_a_single_pass() {
        // A noisy annulus in the plane: a loop living through most bands.
        let n = 400;
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let p: Vec<[f64; 2]> = (0..n)
            .map(|_| {
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                let r = rng.random_range(0.8..1.2);
                [r * a.cos(), r * a.sin()]
            })
            .collect();
        let dist: Vec<f64> = (0..n * n)
            .map(|k| {
                let (i, j) = (k / n, k % n);
                ((p[i][0] - p[j][0]).powi(2) + (p[i][1] - p[j][1]).powi(2)).sqrt()
            })
            .collect();
        let (bands, banded) = h1(n, &dist, None);
        assert!(bands > 20, "{bands} bands");
        let threshold = enclosing_radius(ArrayView2::from_shape((n, n), &dist[..]).unwrap());
        let (_, single) = h1(n, &dist, Some(vec![threshold]));
        // Exact equality: every endpoint is a distance of the matrix.
        assert_eq!(banded, single);
        assert!(banded.iter().any(|b| b.length(threshold) > 0.5));
    }
}
