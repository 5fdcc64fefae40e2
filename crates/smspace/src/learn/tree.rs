//! A k-d tree over the motor samples, for the fixed-radius and k-nearest queries of the
//! local fits: points of any dimension `N` (known at run time), split at the median of
//! the widest coordinate, leaves of at most [`LEAF_SIZE`] points.
//!
//! The tree is built once (`O(S log S)`), holds the points in its own order (row-major,
//! `S × N`) with each point's row in the caller's array, and answers
//! [`within`](KdTree::within) (every point closer than a radius, with its displacement)
//! and [`kth_distance`](KdTree::kth_distance) (the distance to the `k`-th nearest point).
//! It is deterministic: the same points give the same tree and the same answers, in the
//! same order, whatever the thread count. (A crate such as `kiddo` fixes the dimension at
//! compile time; the agents' motor counts are known only at run time.)

/// Most points in a leaf.
pub const LEAF_SIZE: usize = 16;

/// A node: a leaf `[start, end)` of the stored points, or a split.
#[derive(Debug, Clone, Copy)]
enum Node {
    Leaf {
        start: u32,
        end: u32,
    },
    Split {
        axis: u32,
        value: f64,
        left: u32,
        right: u32,
    },
}

/// Identities of trees, for [`Candidates`].
static NEXT_TREE: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// See the module docs.
#[derive(Debug, Clone)]
pub struct KdTree {
    /// This tree's identity (a [`Candidates`] list belongs to one tree).
    id: u64,
    dim: usize,
    /// Points in tree order, row-major.
    points: Vec<f64>,
    /// The caller's row of each stored point.
    rows: Vec<u32>,
    nodes: Vec<Node>,
}

impl KdTree {
    /// Builds the tree of `points` (row-major, `dim` values per point) whose rows in the
    /// caller's arrays are `rows` (one per point). At most `u32::MAX` points.
    pub fn new(dim: usize, points: Vec<f64>, rows: Vec<u32>) -> Self {
        assert!(
            dim > 0 && points.len() == rows.len() * dim,
            "one row per point"
        );
        let count = rows.len();
        let mut order: Vec<u32> = (0..count as u32).collect();
        let mut nodes = Vec::with_capacity(2 * count / LEAF_SIZE + 1);
        build(&points, dim, &mut order, 0, &mut nodes);
        let mut sorted = Vec::with_capacity(points.len());
        for &i in &order {
            let i = i as usize;
            sorted.extend_from_slice(&points[i * dim..(i + 1) * dim]);
        }
        let rows = order.iter().map(|&i| rows[i as usize]).collect();
        Self {
            id: NEXT_TREE.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            dim,
            points: sorted,
            rows,
            nodes,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// The dimension of the points.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The `i`-th stored point (in the tree's order).
    pub fn point(&self, i: usize) -> &[f64] {
        &self.points[i * self.dim..(i + 1) * self.dim]
    }

    /// Whether the tree holds no point.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Bytes held by a tree of `count` points of dimension `dim`.
    pub fn bytes(count: u64, dim: usize) -> u64 {
        let per_point = 8 * dim as u64 + 4 + 4;
        count
            .saturating_mul(per_point)
            .saturating_add(count / LEAF_SIZE as u64 * 2 * 24)
    }

    /// Calls `visit(row, displacement, squared distance)` for every point `x` with
    /// `‖x − query‖ < radius`, `displacement = x − query`, in the tree's order.
    pub fn within(&self, query: &[f64], radius: f64, mut visit: impl FnMut(u32, &[f64], f64)) {
        let r2 = radius * radius;
        let mut displacement = vec![0.0; self.dim];
        self.leaves_near(query, radius, |stored| {
            for p in stored {
                self.visit_if_within(p, query, r2, &mut displacement, &mut visit);
            }
        });
    }

    /// Calls `leaf(stored indices)` for every leaf whose cell can hold a point closer
    /// than `radius` to `query`, in the tree's order (left child first).
    fn leaves_near(
        &self,
        query: &[f64],
        radius: f64,
        mut leaf: impl FnMut(std::ops::Range<usize>),
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = vec![0u32];
        while let Some(node) = stack.pop() {
            match self.nodes[node as usize] {
                Node::Leaf { start, end } => leaf(start as usize..end as usize),
                Node::Split {
                    axis,
                    value,
                    left,
                    right,
                } => {
                    let offset = query[axis as usize] - value;
                    // Right first, so that the left child is visited first.
                    if offset > -radius {
                        stack.push(right);
                    }
                    if offset < radius {
                        stack.push(left);
                    }
                }
            }
        }
    }

    /// The stored point `p`: `displacement = x − query` and, when `‖x − query‖² < r2`,
    /// `visit(row, displacement, squared distance)`. The one place where a point's
    /// distance is computed, so that every query answers bit for bit alike.
    fn visit_if_within(
        &self,
        p: usize,
        query: &[f64],
        r2: f64,
        displacement: &mut [f64],
        visit: &mut impl FnMut(u32, &[f64], f64),
    ) {
        let point = &self.points[p * self.dim..(p + 1) * self.dim];
        let mut d2 = 0.0;
        for ((d, &x), &q) in displacement.iter_mut().zip(point).zip(query) {
            *d = x - q;
            d2 += *d * *d;
        }
        if d2 < r2 {
            visit(self.rows[p], displacement, d2);
        }
    }

    /// [`within`](KdTree::within) answered from `candidates`, the points within a
    /// larger radius of an earlier query, when they hold every point within `radius`
    /// of this one (`‖query − centre‖ + radius ≤ reach`); else the candidates are
    /// refilled with the points within `radius + margin` of `query`. The points are
    /// visited in the tree's order and their displacements computed as `within` does,
    /// so the answer is the same, bit for bit, whatever the candidates held before: a
    /// run of nearby queries (a traced curve) scans a few hundred candidates instead
    /// of the tree's leaves.
    pub fn within_near(
        &self,
        query: &[f64],
        radius: f64,
        margin: f64,
        candidates: &mut Candidates,
        mut visit: impl FnMut(u32, &[f64], f64),
    ) {
        let dim = self.dim;
        let inside = candidates.tree == self.id
            && candidates.centre.len() == dim
            && candidates
                .centre
                .iter()
                .zip(query)
                .map(|(c, q)| (c - q) * (c - q))
                .sum::<f64>()
                .sqrt()
                + radius
                <= candidates.reach;
        if !inside {
            candidates.tree = self.id;
            candidates.centre.clear();
            candidates.centre.extend_from_slice(query);
            candidates.reach = radius + margin;
            candidates.indices.clear();
            let indices = &mut candidates.indices;
            self.within_stored(query, radius + margin, |p| indices.push(p));
        }
        let r2 = radius * radius;
        let mut displacement = vec![0.0; dim];
        for &p in &candidates.indices {
            self.visit_if_within(p as usize, query, r2, &mut displacement, &mut visit);
        }
    }

    /// Calls `visit(stored index)` for every point closer than `radius` to `query`, in
    /// the tree's order.
    fn within_stored(&self, query: &[f64], radius: f64, mut visit: impl FnMut(u32)) {
        let r2 = radius * radius;
        let mut displacement = vec![0.0; self.dim];
        self.leaves_near(query, radius, |stored| {
            for p in stored {
                self.visit_if_within(p, query, r2, &mut displacement, &mut |_, _, _| {
                    visit(p as u32)
                });
            }
        });
    }

    /// The distance from `query` to its `k`-th nearest point (`k ≥ 1`; infinite when the
    /// tree holds fewer than `k` points).
    pub fn kth_distance(&self, query: &[f64], k: usize) -> f64 {
        if k == 0 || k > self.len() {
            return f64::INFINITY;
        }
        let mut best = Vec::with_capacity(k + 1);
        self.nearest(0, query, k, &mut best);
        best[k - 1].0.sqrt()
    }

    /// The `k` points nearest to `query` (fewer when the tree holds fewer), nearest
    /// first: `(squared distance, row)`. Ties keep the tree's order, so the answer does
    /// not depend on the thread that asks.
    pub fn nearest_rows(&self, query: &[f64], k: usize) -> Vec<(f64, u32)> {
        if k == 0 || self.is_empty() {
            return Vec::new();
        }
        let mut best = Vec::with_capacity(k + 1);
        self.nearest(0, query, k, &mut best);
        best.into_iter()
            .map(|(d2, p)| (d2, self.rows[p as usize]))
            .collect()
    }

    /// The `k` smallest `(squared distance, stored index)` below `node`, kept sorted
    /// ascending in `best`.
    fn nearest(&self, node: u32, query: &[f64], k: usize, best: &mut Vec<(f64, u32)>) {
        let dim = self.dim;
        match self.nodes[node as usize] {
            Node::Leaf { start, end } => {
                for p in start as usize..end as usize {
                    let point = &self.points[p * dim..(p + 1) * dim];
                    let d2: f64 = point
                        .iter()
                        .zip(query)
                        .map(|(x, q)| (x - q) * (x - q))
                        .sum();
                    if best.len() < k || d2 < best[k - 1].0 {
                        let at = best.partition_point(|b| b.0 <= d2);
                        best.insert(at, (d2, p as u32));
                        best.truncate(k);
                    }
                }
            }
            Node::Split {
                axis,
                value,
                left,
                right,
            } => {
                let offset = query[axis as usize] - value;
                let (near, far) = if offset < 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.nearest(near, query, k, best);
                if best.len() < k || offset * offset < best[k - 1].0 {
                    self.nearest(far, query, k, best);
                }
            }
        }
    }
}

/// The points of a tree within `reach` of `centre` (stored indices, in the tree's
/// order): the cache of [`KdTree::within_near`]. Empty by default.
#[derive(Debug, Clone, Default)]
pub struct Candidates {
    tree: u64,
    centre: Vec<f64>,
    reach: f64,
    indices: Vec<u32>,
}

impl Candidates {
    /// Whether these are candidates of `tree`.
    pub fn belongs_to(&self, tree: &KdTree) -> bool {
        self.tree == tree.id
    }
}

/// Builds the subtree of the points `order` (whose first entry is stored at `start`),
/// pushing its nodes; returns its root's index.
fn build(
    points: &[f64],
    dim: usize,
    order: &mut [u32],
    start: usize,
    nodes: &mut Vec<Node>,
) -> u32 {
    let index = nodes.len() as u32;
    let count = order.len();
    if count <= LEAF_SIZE {
        nodes.push(Node::Leaf {
            start: start as u32,
            end: (start + count) as u32,
        });
        return index;
    }
    // The widest coordinate of these points.
    let mut low = vec![f64::INFINITY; dim];
    let mut high = vec![f64::NEG_INFINITY; dim];
    for &i in order.iter() {
        let point = &points[i as usize * dim..(i as usize + 1) * dim];
        for a in 0..dim {
            low[a] = low[a].min(point[a]);
            high[a] = high[a].max(point[a]);
        }
    }
    let axis = (0..dim)
        .max_by(|&a, &b| (high[a] - low[a]).total_cmp(&(high[b] - low[b])))
        .unwrap_or(0);
    let half = count / 2;
    let coordinate = |i: &u32| points[*i as usize * dim + axis];
    order.select_nth_unstable_by(half, |a, b| {
        coordinate(a).total_cmp(&coordinate(b)).then(a.cmp(b))
    });
    let value = coordinate(&order[half]);
    nodes.push(Node::Leaf { start: 0, end: 0 });
    let (left_points, right_points) = order.split_at_mut(half);
    let left = build(points, dim, left_points, start, nodes);
    let right = build(points, dim, right_points, start + half, nodes);
    nodes[index as usize] = Node::Split {
        axis: axis as u32,
        value,
        left,
        right,
    };
    index
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};

    fn random_points(count: usize, dim: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..count * dim)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect()
    }

    #[test]
    fn queries_match_brute_force() {
        for (count, dim) in [(1, 1), (40, 2), (700, 4), (300, 7)] {
            let points = random_points(count, dim, count as u64);
            let rows: Vec<u32> = (0..count as u32).map(|i| i * 3).collect();
            let tree = KdTree::new(dim, points.clone(), rows);
            let queries = random_points(20, dim, 99);
            let mut candidates = Candidates::default();
            for q in queries.chunks(dim) {
                let mut distances: Vec<f64> = points
                    .chunks(dim)
                    .map(|p| p.iter().zip(q).map(|(a, b)| (a - b) * (a - b)).sum::<f64>())
                    .collect();
                let radius = 0.6;
                let expected: Vec<u32> = (0..count)
                    .filter(|&i| distances[i] < radius * radius)
                    .map(|i| i as u32 * 3)
                    .collect();
                let mut found = Vec::new();
                tree.within(q, radius, |row, d, d2| {
                    let i = row as usize / 3;
                    let point = &points[i * dim..(i + 1) * dim];
                    for a in 0..dim {
                        assert!((d[a] - (point[a] - q[a])).abs() < 1e-15);
                    }
                    assert!((d2 - distances[i]).abs() < 1e-12);
                    found.push(row);
                });
                found.sort_unstable();
                assert_eq!(found, expected);
                distances.sort_by(f64::total_cmp);
                for k in [1, count.min(5), count] {
                    let kth = tree.kth_distance(q, k);
                    assert!((kth - distances[k - 1].sqrt()).abs() < 1e-12);
                }
                assert!(tree.kth_distance(q, count + 1).is_infinite());
                // The nearest rows are the brute force's, nearest first.
                let nearest = tree.nearest_rows(q, count.min(5));
                assert_eq!(nearest.len(), count.min(5));
                for (r, &(d2, row)) in nearest.iter().enumerate() {
                    assert!((d2 - distances[r]).abs() < 1e-12);
                    let i = row as usize / 3;
                    let own: f64 = points[i * dim..(i + 1) * dim]
                        .iter()
                        .zip(q)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum();
                    assert_eq!(own, d2);
                }
                // The cached query answers the same, from a fresh or a reused cache.
                for margin in [0.0, 0.3] {
                    let mut cached = Vec::new();
                    tree.within_near(q, radius, margin, &mut candidates, |row, d, d2| {
                        cached.push((row, d.to_vec(), d2));
                    });
                    let mut direct = Vec::new();
                    tree.within(q, radius, |row, d, d2| direct.push((row, d.to_vec(), d2)));
                    assert_eq!(cached, direct);
                }
            }
        }
    }
}
