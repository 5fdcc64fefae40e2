//! Phase 1 of the curve kernel: the **blocks**, eight segments of one set at a time.
//!
//! The blocks of both directions go in one order, far from the other set first (by the
//! distance from a block's centre to the other set's nearest chunk centre,
//! [`merged_order`]), so that the running bound `c` reaches its final value early
//! whichever direction holds the maximum. For each block, `f32` windows around the
//! other set's nearest chunk ([`Pass::windows`], the lane code in `filter.rs`):
//!
//! * a point `p` of `B` settles segment `i` when
//!
//!   ```text
//!   max(|w|, |w + v_i|) ≤ c,    w = h(a_i − p),
//!   ```
//!
//!   since `|w + t v_i|` is convex in `t` and at least `d_B(a_i + t v_i)`; every third
//!   point of `B` is tried, outward up to twelve points away;
//! * else a segment `s_j` of `B` settles it when both its ends are within `c` of one
//!   lifted image of `s_j` (the distance to a convex set is convex along a segment).
//!
//! A vertex the windows do not prove within `c` gets its exact `d_B` (largest window
//! value first, [`Pass::block`]), which may raise `c`, from a scan of `B` for its
//! segment that can settle the segment as well ([`Pass::scan_segment`]). The `f32`
//! scans skip whole chunks of eight segments of `B` by their boxes (a chunk whose box
//! is farther than an upper bound already found, plus what the later tests need,
//! cannot change any result), and first try the one chunk whose box is nearest. The
//! segments a block leaves open wait for phase 2 (`segments.rs`) with their window
//! values.

use super::distance::load;
use super::filter::{segment_probe, segment_window, vertex_window, SegmentBlock};
use super::pass::{CurveScratch, Pass};
use crate::metric::kernel::{each, rank_among, Lanes, RING_WINDOW};
use crate::metric::prepared::{LANES, RING};

impl<S: Lanes, const N: usize> Pass<'_, S, N> {
    /// The [`segment_scan`](super::filter::segment_scan) of segment `i` of `A` (see [`Self::scan_settles`]): whether it
    /// settles the segment for `max(c2, d_B(a_i)²)`, with the exact `d_B(a_i)` recorded
    /// when it is still unknown and `vertex` asks for it or the segment stays open.
    /// `hint` is a test value `max(e(a_i), e(a_{i+1}))` known of some segment of `B` (or
    /// `+∞`): chunks farther than it allows are skipped (see [`Self::scan`]).
    #[inline(always)]
    pub(super) fn scan_segment(
        &self,
        i: usize,
        c2: f64,
        (vertex, hint): (bool, f32),
        scratch: &mut CurveScratch,
    ) -> bool {
        let (a, frame) = (self.a, self.frame);
        let x: [f32; N] = each(0.0, |k| a.set.coords32[k * frame.points_pad + i]);
        let v: [f32; N] = each(0.0, |k| a.dirs32[k * frame.points_pad + i]);
        let theta = self.segment_threshold(c2);
        if segment_probe::<S, N>(
            self.s,
            (&x, &v),
            (
                self.b.set.coords32,
                self.b.dirs32,
                self.b.inv32,
                self.b.boxes32,
            ),
            frame.chunks,
            (&self.wraps, &self.half),
            &mut scratch.lower,
            theta,
        ) {
            return true;
        }
        let mut scan = std::mem::take(&mut scratch.scan);
        let extra = 0.5 * a.lengths[i];
        let (min0, min1, min_max) = self.scan::<true>(
            &x,
            &v,
            (hint, extra),
            (&mut scan, &mut scratch.lower, theta >= 0.0),
        );
        scratch.scan_reach = self.upper(hint) + extra;
        scratch.scan_min1 = min1;
        let mut c2 = c2;
        if vertex && scratch.vertex[self.dir][i].0.is_nan() {
            let x = load::<N>(self.a.set.points, i);
            let value = self.nearest_from_scan(&x, min0, (&scan, &scratch.lower));
            scratch.set_vertex(self.dir, i, value);
            c2 = c2.max(value.0);
        }
        let settled =
            min_max <= self.segment_threshold(c2) || self.lipschitz_settles(i, (min0, min1), c2);
        if !settled && scratch.vertex[self.dir][i].0.is_nan() {
            let x = load::<N>(self.a.set.points, i);
            let value = self.nearest_from_scan(&x, min0, (&scan, &scratch.lower));
            scratch.set_vertex(self.dir, i, value);
        }
        scratch.scan = scan;
        settled
    }

    /// The `f32` passes over one block `alpha` of segments of `A`: exact values of the
    /// vertices that may raise `c2` (largest window value first), and the segments
    /// left open pushed to `scratch.open`. Returns the new `c2`, or `None` once
    /// `c2 > abort2`.
    #[inline(always)]
    pub(super) fn block(
        &self,
        alpha: usize,
        near: usize,
        mut c2: f64,
        abort2: f64,
        scratch: &mut CurveScratch,
    ) -> Option<f64> {
        let (s, a) = (self.s, self.a);
        let live = (1u32 << a.segments.saturating_sub(alpha * LANES).min(LANES)) - 1;
        if live == 0 {
            return Some(c2);
        }
        let mut window = self.windows(alpha, near, c2, live);
        // Vertices whose window values do not prove them within c: exact values, from
        // the scan of their segment, which may settle it too.
        let bound = s.min(window.vertex, window.ends0);
        let mut values = s.array(bound);
        let hints = s.array(window.segment);
        let mut open = s.gt(bound, s.splat(self.segment_threshold(c2))) & live;
        let mut scanned = 0u32;
        while open != 0 {
            let l = largest(&values, open);
            open &= !(1 << l);
            values[l] = f32::NEG_INFINITY;
            let i = alpha * LANES + l;
            let d2 = if self.wide {
                self.vertex(i, f32::INFINITY, scratch).0
            } else {
                if self.scan_segment(i, c2, (true, hints[l]), scratch) {
                    scanned |= 1 << l;
                }
                scratch.vertex[self.dir][i].0
            };
            if d2 > c2 {
                c2 = d2;
                if c2 > abort2 {
                    return None;
                }
                open &= s.gt(s.load(&values), s.splat(self.segment_threshold(c2)));
            }
        }
        // Segments: the window of segments of B, unless it ran already.
        let theta = self.segment_threshold(c2);
        let mut open = s.gt(window.segment, s.splat(theta)) & live & !scanned;
        if open != 0 && !self.wide && !window.segments_done {
            window = self.segment_window(alpha, near, theta, open, window);
            open = s.gt(window.segment, s.splat(theta)) & live & !scanned;
        }
        let (values, ends0, ends1) = (
            s.array(window.segment),
            s.array(window.ends0),
            s.array(window.ends1),
        );
        while open != 0 {
            let l = open.trailing_zeros() as usize;
            open &= open - 1;
            scratch
                .open
                .push((values[l], (alpha * LANES + l) as u32, (ends0[l], ends1[l])));
        }
        Some(c2)
    }

    /// The windows of block `alpha` of `A` around the chunk `near` of `B`: the window of
    /// vertices of `B`, and when it leaves a vertex of `A` open for `c2`, the window of
    /// segments too (its lifted distances bound `d_B` at the vertices more tightly than
    /// the nearest vertex, which spares exact values).
    #[inline(always)]
    fn windows(&self, alpha: usize, near: usize, c2: f64, live: u32) -> Window<S> {
        let s = self.s;
        let infinity = s.splat(f32::INFINITY);
        let mut window = Window {
            segment: infinity,
            vertex: infinity,
            ends0: infinity,
            ends1: infinity,
            segments_done: false,
        };
        if self.wide {
            return window;
        }
        let theta = self.segment_threshold(c2);
        let block = SegmentBlock::load(
            s,
            self.a.set.coords32,
            self.a.dirs32,
            self.frame.chunks,
            alpha,
        );
        let ring = &self.b.set.ring32.as_chunks::<N>().0[self.rows(near)];
        let length = self.frame.points.min(RING_WINDOW.len());
        (window.segment, window.vertex) =
            vertex_window(s, &block, ring, &self.wraps, (theta, live, length));
        let vertex_open = s.gt(window.vertex, s.splat(theta)) & live;
        if vertex_open != 0 {
            let open = s.gt(window.segment, s.splat(theta)) & live;
            window = self.segment_window(alpha, near, theta, open, window);
        }
        window
    }

    /// The rows of the rings of `B` in the window around chunk `near`.
    #[inline(always)]
    fn rows(&self, near: usize) -> std::ops::Range<usize> {
        let start = (near * LANES + LANES / 2).min(self.frame.points - 1);
        start..start + 2 * RING + 1
    }

    /// [`segment_window`] for the lanes `open` of block `alpha` of `A`.
    #[inline(always)]
    fn segment_window(
        &self,
        alpha: usize,
        near: usize,
        theta: f32,
        open: u32,
        window: Window<S>,
    ) -> Window<S> {
        let (s, b) = (self.s, self.b);
        let block = SegmentBlock::load(
            s,
            self.a.set.coords32,
            self.a.dirs32,
            self.frame.chunks,
            alpha,
        );
        let rows = self.rows(near);
        let ring = &b.set.ring32.as_chunks::<N>().0[rows.clone()];
        let dirs = &b.dir_ring32.as_chunks::<N>().0[rows.clone()];
        let inverse = &b.inv_ring32[rows];
        let length = self.frame.points.min(RING_WINDOW.len());
        let (segment, ends0, ends1) = segment_window(
            s,
            &block,
            (ring, dirs, inverse),
            &self.wraps,
            (theta, open, length),
            window.segment,
        );
        Window {
            segment,
            vertex: window.vertex,
            ends0,
            ends1,
            segments_done: true,
        }
    }
}

/// The window values of one block of `A` (lanes over its segments), `f32` squared:
/// the segment test (`max` over both ends, smallest over the window), the nearest
/// vertex of `B` to `a_i` in the window, and the nearest lifted segment of `B` to `a_i`
/// and to `a_{i+1}` (`+∞` until the window of segments ran).
#[derive(Clone, Copy)]
struct Window<S: Lanes> {
    segment: S::V,
    vertex: S::V,
    ends0: S::V,
    ends1: S::V,
    segments_done: bool,
}

/// The lane of `mask` with the largest value (the lowest among ties).
#[inline(always)]
fn largest(values: &[f32; LANES], mask: u32) -> usize {
    let mut l = mask.trailing_zeros() as usize;
    let mut rest = mask & (mask - 1);
    while rest != 0 {
        let m = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        if values[m] > values[l] {
            l = m;
        }
    }
    l
}

/// The blocks of both directions, far from the other set first: entry `e` is block
/// `e & 0x7fff_ffff` of `A` (`e >> 31 == 0`, key `row_key`) or of `B` (`1`, key
/// `col_key`), by decreasing key (ties: `A` first, then the lower block; keys that
/// differ in their last five bits only may count as ties), so that the running bound
/// reaches its final value early whichever direction holds the maximum.
#[inline(always)]
pub(super) fn merged_order(
    row_key: &[f32],
    col_key: &[f32],
    packed: &mut Vec<u64>,
    order: &mut Vec<u32>,
) {
    let chunks = row_key.len();
    order.clear();
    if chunks <= 16 && col_key.len() == chunks {
        // Ranked without branches: a non-negative `f32` orders like its bits, here
        // read as `i32` (they stay below 2³¹) so that one vector instruction compares
        // eight; the low five bits take the direction (`A` above) and the inverted
        // block, so keys are distinct, and an entry's rank is the number above it.
        let mut all = [i32::MIN; 32];
        for (alpha, key) in row_key.iter().enumerate() {
            all[alpha] = ((key.to_bits() & !31) | 16 | (15 - alpha as u32)) as i32;
        }
        for (beta, key) in col_key.iter().enumerate() {
            all[16 + beta] = ((key.to_bits() & !31) | (15 - beta as u32)) as i32;
        }
        let mut sorted = [0u32; 32];
        for &x in all[..chunks].iter().chain(&all[16..16 + chunks]) {
            sorted[rank_among(x, &all)] = x as u32;
        }
        order.extend(sorted[..2 * chunks].iter().map(|&x| {
            let block = 15 - (x & 15);
            if x & 16 != 0 {
                block
            } else {
                block | 1 << 31
            }
        }));
        return;
    }
    // A non-negative `f32` orders like its bits; the low half of the word takes the
    // inverted entry, so that a descending sort puts ties in increasing entry order.
    let pack = |key: f32, entry: u32| (u64::from(key.to_bits()) << 32) | u64::from(!entry);
    packed.clear();
    packed.extend(row_key.iter().enumerate().map(|(a, &k)| pack(k, a as u32)));
    packed.extend(
        col_key
            .iter()
            .enumerate()
            .map(|(b, &k)| pack(k, b as u32 | 1 << 31)),
    );
    packed.sort_unstable_by(|x, y| y.cmp(x));
    order.extend(packed.iter().map(|&p| !(p as u32)));
}
