//! Phase 2 of the curve kernel: the **open segments** the blocks left, of both
//! directions, largest window value first ([`largest_first`]), tested again with the
//! final `c`.
//!
//! * `d_B` is 1-Lipschitz along a segment (`g` is at most the length travelled), so
//!
//!   ```text
//!   max_t d_B(a_i + t v_i) ≤ (d_B(a_i) + d_B(a_{i+1}) + |v_i|) / 2
//!   ```
//!
//!   settles segment `i` when at most `c`, with upper bounds of the end values (the
//!   `f32` window values, [`Pass::lipschitz_settles`]) or their exact values once known
//!   ([`Pass::ends_settle`]);
//! * convexity: the Euclidean distance to one lifted image of a segment `s_j` of `B` is
//!   convex along segment `i`, so both ends within `c` of it settle the segment
//!   ([`within_along`]), `s_j` the segment of `B` nearest to an end whose exact value
//!   is known;
//! * else a scan of `B` for the segment ([`Pass::scan_settles`], as in the blocks).
//!
//! A segment none of these settles goes to the envelope (`envelope.rs`).

use super::distance::{lifted_distance2, load};
use super::layout::CurveRef;
use super::pass::{CurveScratch, Pass};
use crate::metric::kernel::{rank_among, Lanes};
use crate::metric::period::swrap;

/// Whether segment `i` of `A` lies within `√c2` of segment `j` of `B` all along: the
/// Euclidean distance to one lifted image of `s_j` is convex along the segment, so it
/// is enough that both ends are within `√c2` of that image.
#[inline(always)]
fn within_along<const N: usize>(
    a: CurveRef<'_>,
    b: CurveRef<'_>,
    i: usize,
    j: usize,
    c2: f64,
    period: &[f64; N],
) -> bool {
    let p = load::<N>(a.set.points, i);
    let v = load::<N>(a.dirs, i);
    let bs = load::<N>(b.set.points, j);
    let w = load::<N>(b.dirs, j);
    let mut u0 = [0.0; N];
    let mut u1 = [0.0; N];
    for k in 0..N {
        u0[k] = swrap(p[k] - bs[k], period[k]);
        u1[k] = u0[k] + v[k];
    }
    lifted_distance2(&u0, &w, b.inv_len2[j]) <= c2 && lifted_distance2(&u1, &w, b.inv_len2[j]) <= c2
}

/// A segment left open by the `f32` passes: `(test value, index, (m0, m1))`, see
/// [`CurveScratch::open`]; the index of a segment of `B` (the direction `B → A`) has
/// bit 31 set.
pub(super) type OpenSegment = (f32, u32, (f32, f32));

impl<S: Lanes, const N: usize> Pass<'_, S, N> {
    /// The Lipschitz bound: segment `i` of `A` is settled when
    /// `(d_B(a_i) + d_B(a_{i+1}) + |v_i|)/2 ≤ √c2`, with the `f32` lifted squared
    /// distances `m0`, `m1` from its ends to some segments of `B` as upper bounds.
    #[inline(always)]
    pub(super) fn lipschitz_settles(&self, i: usize, (m0, m1): (f32, f32), c2: f64) -> bool {
        0.5 * (self.upper(m0) + self.upper(m1) + self.a.lengths[i]) <= c2.sqrt() * (1.0 - 1e-12)
    }

    /// Whether segment `i` of `A` is settled for `c2` by the exact values already known
    /// at its ends, without a scan of `B`: the Lipschitz bound
    /// `(d_B(a_i) + d_B(a_{i+1}) + |v_i|)/2 ≤ √c2` when both are known, else convexity
    /// with the segment of `B` nearest to a known end (both ends of segment `i` within
    /// `√c2` of one lifted image of it, [`within_along`]). It settles about 60 % of the
    /// segments the windows leave open on the paper's arm, which then need no
    /// [`segment_scan`](super::filter::segment_scan).
    #[inline(always)]
    pub(super) fn known_ends_settle(&self, i: usize, c2: f64, scratch: &CurveScratch) -> bool {
        let next = if i + 1 == self.frame.points { 0 } else { i + 1 };
        let known = &scratch.vertex[self.dir];
        self.ends_settle(i, [known[i], known[next]], c2)
    }

    /// Whether segment `i` of `A` is settled for `c2` by the exact `d_B²` at its ends and
    /// their nearest segments of `B` (`ends`; an end not yet known is `NaN` and proves
    /// nothing): the Lipschitz bound when both are at most `c2`, else convexity with the
    /// nearest segment of an end at most `c2` ([`within_along`]).
    #[inline(always)]
    pub(super) fn ends_settle(
        &self,
        i: usize,
        [(d0, j0), (d1, j1)]: [(f64, u32); 2],
        c2: f64,
    ) -> bool {
        let (a, b, period) = (self.a, self.b, &self.frame.period);
        if d0 <= c2
            && d1 <= c2
            && 0.5 * (d0.sqrt() + d1.sqrt() + a.lengths[i]) <= c2.sqrt() * (1.0 - 1e-12)
        {
            return true;
        }
        let along = |d: f64, j: u32| d <= c2 && within_along::<N>(a, b, i, j as usize, c2, period);
        along(d0, j0) || along(d1, j1)
    }

    /// Whether a [`segment_scan`](super::filter::segment_scan) of segment `i` of `A` settles it for the running `c2`:
    /// both ends within `√c2` of one lifted segment of `B` (convexity), or the Lipschitz
    /// bound `(d_B(a_i) + d_B(a_{i+1}) + |v_i|)/2 ≤ √c2` with the upper bounds of the
    /// scan. Records the exact `d_B(a_i)` it gives for free. `hint` is the segment's
    /// `f32` test value in its window.
    #[inline(always)]
    pub(super) fn scan_settles(
        &self,
        i: usize,
        c2: f64,
        hint: f32,
        scratch: &mut CurveScratch,
    ) -> bool {
        !self.wide && self.scan_segment(i, c2, (false, hint), scratch)
    }
}

/// Sorts the open segments by decreasing test value, ties by increasing entry. Up to
/// [`RANK_SORT_OPEN`] of them (almost always) are ranked without branches: a
/// non-negative `f32` orders like its bits, so `(value bits, inverted entry)` read as
/// an `i64` is a distinct key whose rank is the number of larger keys.
#[inline(always)]
pub(super) fn largest_first(open: &mut [OpenSegment]) {
    let n = open.len();
    if n > RANK_SORT_OPEN {
        open.sort_unstable_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
        return;
    }
    let mut keys = [i64::MIN; RANK_SORT_OPEN];
    for (key, &(value, entry, _)) in keys.iter_mut().zip(open.iter()) {
        *key = ((u64::from(value.to_bits()) << 32) | u64::from(!entry)) as i64;
    }
    let mut sorted = [(0.0f32, 0u32, (0.0f32, 0.0f32)); RANK_SORT_OPEN];
    for (&x, &item) in keys.iter().zip(open.iter()) {
        sorted[rank_among(x, &keys)] = item;
    }
    open.copy_from_slice(&sorted[..n]);
}

/// Most open segments ranked by [`largest_first`] without a sort.
const RANK_SORT_OPEN: usize = 16;

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn open_segments_rank_like_the_sort_by_value_then_entry() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(12);
        for n in [0, 1, 2, 5, 16, 17, 40] {
            for _ in 0..50 {
                // Few distinct values, so that ties (broken by the entry) are common.
                let mut open: Vec<OpenSegment> = (0..n)
                    .map(|e| {
                        let value = [0.0, 0.25, 1.5, f32::INFINITY][rng.random_range(0..4)];
                        let entry = e as u32 | u32::from(rng.random_bool(0.5)) << 31;
                        (value, entry, (rng.random(), rng.random()))
                    })
                    .collect();
                let mut sorted = open.clone();
                sorted.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
                largest_first(&mut open);
                assert_eq!(open, sorted, "{n} segments");
            }
        }
    }
}
