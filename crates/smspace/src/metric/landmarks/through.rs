//! The `k` nearest sets of every member set through the landmarks: the search of
//! [`super::landmarks_and_knn_with`] (the bounds and the order are stated in the docs
//! of [`super`], "The `k` nearest sets through the landmarks").

use ndarray::Array2;
use rayon::prelude::*;

use super::{LandmarkDistances, PivotTable, PIVOT_MARGIN};
use crate::metric::kernel::{Driver, Eval, Scratch};
use crate::metric::knn::Best;
use crate::metric::tiles::Measure;
use crate::metric::Knn;
use crate::progress::Progress;

/// Rows of the nearest-set search per parallel task.
const KNN_CHUNK: usize = 16;

/// The `k` nearest of every member among the members, through the landmarks (module
/// docs).
pub(super) fn knn_through(
    measure: &Measure<'_>,
    found: &LandmarkDistances,
    pivots: &PivotTable,
    members: &[usize],
    k: usize,
    progress: &dyn Progress,
) -> Knn {
    let m = measure.len();
    let l = found.len();
    let (is_metric, tolerance) = measure.bounds();
    let reach = |r: usize| found.nearest_distances[[members[r], 0]];
    // Members by the landmark nearest to them, each cluster by decreasing distance to
    // it (ties by position).
    let mut cluster_start = vec![0usize; l + 1];
    for &j in members {
        cluster_start[found.nearest[[j, 0]] + 1] += 1;
    }
    for a in 0..l {
        cluster_start[a + 1] += cluster_start[a];
    }
    let mut fill = cluster_start.clone();
    let mut clusters = vec![0u32; members.len()];
    for (r, &j) in members.iter().enumerate() {
        let a = found.nearest[[j, 0]];
        clusters[fill[a]] = r as u32;
        fill[a] += 1;
    }
    for a in 0..l {
        clusters[cluster_start[a]..cluster_start[a + 1]].sort_unstable_by(|&x, &y| {
            reach(y as usize)
                .total_cmp(&reach(x as usize))
                .then(x.cmp(&y))
        });
    }
    let cluster_reach: Vec<f64> = (0..l)
        .map(|a| {
            clusters[cluster_start[a]..cluster_start[a + 1]]
                .first()
                .map_or(0.0, |&r| reach(r as usize))
        })
        .collect();
    // The pivots' distances of every member, member by member.
    let t = pivots.pivots.len();
    let mut member_pivots = vec![0.0; members.len() * t];
    for (r, &j) in members.iter().enumerate() {
        for p in 0..t {
            member_pivots[r * t + p] = pivots.table[p * m + j];
        }
    }
    let shared = KnnShared {
        found,
        pivots: &pivots.pivots,
        member_pivots: &member_pivots,
        members,
        cluster_start: &cluster_start,
        clusters: &clusters,
        cluster_reach: &cluster_reach,
        margin: 6.0 * tolerance,
        is_metric,
        k,
    };
    let rows = members.len();
    progress.start("neighbours", rows as u64);
    let mut indices = Array2::zeros((rows, k));
    let mut distances = Array2::zeros((rows, k));
    indices
        .as_slice_mut()
        .expect("a new array is in standard layout")
        .par_chunks_mut(k * KNN_CHUNK)
        .zip(
            distances
                .as_slice_mut()
                .expect("a new array is in standard layout")
                .par_chunks_mut(k * KNN_CHUNK),
        )
        .enumerate()
        .for_each_init(
            || (Scratch::default(), KnnScratch::new(l)),
            |(scratch, local), (c, (index, distance))| {
                let count = index.len() / k;
                measure.drive(
                    scratch,
                    KnnDriver {
                        shared: &shared,
                        local,
                        first: c * KNN_CHUNK,
                        index,
                        distance,
                    },
                );
                progress.advance(count as u64);
            },
        );
    progress.finish();
    Knn {
        rows: 0..rows,
        indices,
        distances,
    }
}

/// What every query of [`knn_through`] reads.
struct KnnShared<'a> {
    found: &'a LandmarkDistances,
    /// Positions of the pivot landmarks.
    pivots: &'a [usize],
    /// `[r · T + t]`: distance of member `r` to pivot `t`.
    member_pivots: &'a [f64],
    members: &'a [usize],
    /// `clusters[cluster_start[a]..cluster_start[a + 1]]`: the members whose nearest
    /// landmark is `a` (positions in `members`), by decreasing distance to it.
    cluster_start: &'a [usize],
    clusters: &'a [u32],
    /// Largest distance of a member of each cluster to its landmark.
    cluster_reach: &'a [f64],
    margin: f64,
    is_metric: bool,
    k: usize,
}

/// Per-thread buffers of [`knn_through`].
struct KnnScratch {
    /// Lower bounds of `ρ(query, l_a)`, exact for the query's nearest landmarks.
    to_query: Vec<f64>,
    /// Whether `to_query[a]` is exact.
    exact: Vec<bool>,
    candidates: Vec<(f64, u32)>,
}

impl KnnScratch {
    fn new(landmarks: usize) -> Self {
        Self {
            to_query: vec![0.0; landmarks],
            exact: vec![false; landmarks],
            candidates: Vec::new(),
        }
    }
}

struct KnnDriver<'a> {
    shared: &'a KnnShared<'a>,
    local: &'a mut KnnScratch,
    first: usize,
    index: &'a mut [usize],
    distance: &'a mut [f64],
}

impl KnnShared<'_> {
    /// A lower bound of `ρ(query i, member r)`, minus the rounding margins: from the
    /// pivots (`|ρ(i, p) − ρ(r, p)|`) and from every landmark `a` near `r`
    /// (`|ρ(i, a) − ρ(r, a)|` where `ρ(i, a)` is known, `lb(i, a) − ρ(r, a)` else).
    fn bound(&self, local: &KnnScratch, i: usize, r: usize) -> f64 {
        let t = self.pivots.len();
        let gap = |x: f64, y: f64| (x - y).abs() - PIVOT_MARGIN * (x + y);
        let mut bound = 0.0f64;
        let (qi, qr) = (
            &self.member_pivots[i * t..(i + 1) * t],
            &self.member_pivots[r * t..(r + 1) * t],
        );
        for (&x, &y) in qi.iter().zip(qr) {
            bound = bound.max(gap(x, y));
        }
        let gj = self.members[r];
        for (&a, &d) in self
            .found
            .nearest
            .row(gj)
            .iter()
            .zip(self.found.nearest_distances.row(gj))
        {
            let x = local.to_query[a];
            let b = if local.exact[a] {
                gap(x, d)
            } else {
                x - d - PIVOT_MARGIN * (x + d)
            };
            bound = bound.max(b);
        }
        bound - self.margin
    }
}

impl Driver for KnnDriver<'_> {
    type Output = ();
    #[inline(always)]
    fn drive<E: Eval>(self, eval: &mut E) {
        let KnnDriver {
            shared,
            local,
            first,
            index,
            distance,
        } = self;
        let k = shared.k;
        let rows = shared.members.len();
        let found = shared.found;
        let l = found.len();
        let t = shared.pivots.len();
        for (q, (index, distance)) in index.chunks_mut(k).zip(distance.chunks_mut(k)).enumerate() {
            let i = first + q;
            let gi = shared.members[i];
            let mut measure = |r: usize, limit: f64| {
                let gj = shared.members[r];
                eval.distance(gi.min(gj), gi.max(gj), limit)
            };
            let mut best = Best::new(k);
            if !shared.is_metric {
                for r in (0..rows).filter(|&r| r != i) {
                    if let Some(d) = measure(r, best.radius()) {
                        best.offer(d, r);
                    }
                }
                best.write(index, distance);
                continue;
            }
            let near = found.nearest.row(gi);
            let near_distances = found.nearest_distances.row(gi);
            // Lower bounds of the query's distance to every landmark: at least the
            // q-th nearest distance (the others are not nearer), the pivots' and the
            // near landmarks' triangle bounds; exact on the near landmarks.
            let floor = if near.len() < l {
                near_distances[near.len() - 1]
            } else {
                0.0
            };
            local.to_query.fill(floor);
            for (p, &pivot) in shared.pivots.iter().enumerate() {
                let x = shared.member_pivots[i * t + p];
                for (lb, &y) in local.to_query.iter_mut().zip(found.landmarks.row(pivot)) {
                    *lb = lb.max((x - y).abs() - PIVOT_MARGIN * (x + y));
                }
            }
            for (&u, &d) in near.iter().zip(near_distances) {
                for (lb, &y) in local.to_query.iter_mut().zip(found.landmarks.row(u)) {
                    *lb = lb.max(y - d - PIVOT_MARGIN * (y + d));
                }
            }
            for (&u, &d) in near.iter().zip(near_distances) {
                local.to_query[u] = d;
                local.exact[u] = true;
            }
            // Candidates: the members of the clusters of the query's nearest landmarks.
            local.candidates.clear();
            for &a in near.iter() {
                for &r in &shared.clusters[shared.cluster_start[a]..shared.cluster_start[a + 1]] {
                    let r = r as usize;
                    if r != i {
                        let b = shared.bound(local, i, r);
                        local.candidates.push((b, r as u32));
                    }
                }
            }
            let rest = best.measure_smallest(&mut local.candidates, &mut measure);
            best.measure_within(rest, &mut measure);
            // The other clusters: a member `r` of the cluster of landmark `a` is at
            // least `lb(i, a) − ρ(r, a)` away; clusters by their farthest member, then
            // members by decreasing distance to their landmark.
            for a in 0..l {
                if local.exact[a] {
                    continue;
                }
                let lb = local.to_query[a];
                if lb - shared.cluster_reach[a] - shared.margin > best.radius() {
                    continue;
                }
                for &r in &shared.clusters[shared.cluster_start[a]..shared.cluster_start[a + 1]] {
                    let r = r as usize;
                    let radius = best.radius();
                    let gr = shared.members[r];
                    if lb - found.nearest_distances[[gr, 0]] - shared.margin > radius {
                        break;
                    }
                    if shared.bound(local, i, r) > radius {
                        continue;
                    }
                    if let Some(d) = measure(r, radius) {
                        best.offer(d, r);
                    }
                }
            }
            best.write(index, distance);
            for &u in near.iter() {
                local.exact[u] = false;
            }
        }
    }
}
