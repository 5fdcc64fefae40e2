//! The fast pair kernels: exact Hausdorff and mean Hausdorff distances between two
//! prepared sets.
//!
//! # How the directed Hausdorff part `max_a min_b g²(a, b)` is found without the full
//! `P × P` scan
//!
//! A running lower bound `c` of the answer is kept (the largest exactly computed
//! `min_b g²(a, b)` so far): a point `a` only matters if its nearest distance exceeds
//! `c`, so as soon as any `b` with `g²(a, b) ≤ c` is seen, `a` is *settled* (the early
//! break of Taha & Hanbury 2015). Settling only needs an upper bound of `g²`, so it is
//! done in `f32`, eight points per AVX2 register; exact `f64` distances are computed
//! only for the few points that may raise `c`.
//!
//! 1. *Centre table.* Both sets are cut into chunks of eight consecutive points. The
//!    squared distances between all chunk centres of `A` and `B` give, for every chunk
//!    of either set, the nearest chunk of the other (a warm start: the sets are ordered
//!    curves, so a point's nearest neighbour lies near the nearest chunk) and an
//!    ordering: blocks far from the other set first, so that `c` reaches its final
//!    value early. The table only steers the work. (One pass, lanes over eight chunks
//!    of `A`: the minima over `B` lane by lane, those over `A` kept per column and
//!    lane and reduced across lanes once per column at the end.)
//! 2. *Window.* The eight points of a block of `A` (one lane each) are compared with
//!    the points of `B` around the middle of the nearest chunk (outward, up to nine
//!    points): the block is settled as soon as every lane has a `b` whose `f32` value
//!    `g̃²` proves `g(a, b) ≤ √c` (below the threshold `θ(c)`, see below).
//! 3. *Lanes left open*, largest window value first: the `f32` distances from that
//!    point to every point of `B` (lanes over `b`, no branch); if the smallest is
//!    `≤ θ(c)` the point is settled, else its exact nearest distance is computed in
//!    `f64` among the few points whose `f32` value is close enough to the smallest to
//!    be the exact minimiser ([`cut_above`]), and raises `c`.
//!
//! The result is the maximum over `a` of exactly computed minima: the same number the
//! brute force gives, for any order of work (up to rounding: the sums of squares use
//! fused multiply-adds in coordinate order). The symmetric distance runs `B → A`
//! starting from `c = h(A, B)`, where most blocks settle at once.
//!
//! # The `f32` error bound
//!
//! The `f32` copy of the coordinates (see [`PreparedSets`]) and every `f32` operation
//! round. From the largest coordinate magnitudes and the periods, [`FilterBounds`]
//! gives `δ` and `rel` with `√g² ≤ √(g̃²·(1 + rel)) + δ` (and the same with `g` and `g̃`
//! swapped); for four angles `δ ≈ 6·10⁻⁶` rad and `rel ≈ 5·10⁻⁷`. A lane is settled only
//! when `g̃² ≤ θ(c) ≤ (√c − δ)²/(1 + rel)` (rounded down to `f32`), which proves
//! `g² ≤ c`; nothing else depends on `f32` values, so every result is exact. `θ` is
//! computed without a square root or a division, since `c` rises a few times per pair
//! and every test waits for it: `2√c ≤ c/s + s` for any `s > 0`, so
//! `θ(c) = (c − δ·(c/s + s))·(1 − rel)`, with `s = 2^⌊e/2⌋` for `c = m·2^e` (`c/s`
//! exact, `s/√c ∈ (1/2, 1]`), gives up at most `δ·√c/2 + rel²·c` of the bound.
//! Coordinates beyond `10¹⁵` (after centring) do not enter the filter: such sets are
//! compared by brute force in `f64`.
//!
//! # Instruction sets
//!
//! The kernels run on eight `f32` lanes: one 256-bit register on CPUs with AVX-512
//! (with its mask registers and 32 vector registers) or with AVX2 + FMA, plain arrays
//! elsewhere, chosen at run time. Every operation rounds the same way on each, so the
//! distances are the same bit for bit. The environment variable `SMSPACE_SIMD`
//! (`avx512`, `avx2` or `portable`) caps the level, and [`force_simd_level`] sets it
//! for the process (for comparisons and tests); [`simd_level`] says which one runs.

mod lanes;

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::OnceLock;

pub(crate) use self::lanes::{each, Lanes, Portable, WIDTH};
#[cfg(doc)]
use super::prepared::FilterBounds;
use super::prepared::{fold, PreparedSets, SetRef, LANES, RING};

const _: () = assert!(WIDTH == LANES);

/// Rows of a window around its centre in a ring (see [`SetRef::ring32`]), outward.
pub(crate) const RING_WINDOW: [usize; 9] = [
    RING,
    RING + 1,
    RING - 1,
    RING + 2,
    RING - 2,
    RING + 3,
    RING - 3,
    RING + 4,
    RING - 4,
];

/// Window points compared before the first test of a block (most blocks settle after
/// one or two).
const WINDOW_FIRST: usize = 1;

/// Largest block count ordered by the branch-free rank sort.
const RANK_SORT_MAX: usize = 16;

/// Reusable buffers of one worker thread.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    row_key: Vec<f32>,
    row_near: Vec<u32>,
    col_key: Vec<f32>,
    col_near: Vec<u32>,
    order: Vec<u32>,
    lane: Vec<[f32; LANES]>,
    /// Per column of the centre table: the lanes' minima and their block indices.
    col_lanes: Vec<([f32; LANES], [f32; LANES])>,
    pub(crate) curve: super::curve::CurveScratch,
}

/// The centre tables of both directions, the order buffer and the curve buffers.
type ScratchParts<'a> = (
    &'a [f32],
    &'a [u32],
    &'a [f32],
    &'a [u32],
    &'a mut Vec<u32>,
    &'a mut super::curve::CurveScratch,
);

impl Scratch {
    /// Borrows the centre tables (filled by [`center_table`]) and the work buffers.
    pub(crate) fn parts(&mut self) -> ScratchParts<'_> {
        (
            &self.row_key,
            &self.row_near,
            &self.col_key,
            &self.col_near,
            &mut self.order,
            &mut self.curve,
        )
    }
}

/// What the kernels need to know of the prepared sets, for `N` padded coordinates.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frame<const N: usize> {
    pub points: usize,
    pub points_pad: usize,
    pub chunks: usize,
    pub chunks_wide: usize,
    /// `‖δ‖` of the `f32` point distances (see [`FilterBounds`]).
    pub delta: f64,
    /// `‖δ‖` of the `f32` lifted segment quantities (the curve kernels).
    pub segment_delta: f64,
    /// Relative error of an `f32` sum of squares.
    pub rel: f64,
    pub period: [f64; N],
    pub period32: [f32; N],
    /// The shift of the `f32` copy (see [`PreparedSets::offset`]).
    pub offset: [f64; N],
}

impl<const N: usize> Frame<N> {
    pub(crate) fn of(prepared: &PreparedSets) -> Self {
        let mut period = [f64::INFINITY; N];
        period.copy_from_slice(prepared.period_pad());
        Self {
            points: prepared.points(),
            points_pad: prepared.points_pad(),
            chunks: prepared.chunks(),
            chunks_wide: prepared.chunks_wide(),
            delta: prepared.filter().point_delta,
            segment_delta: prepared.filter().segment_delta,
            rel: prepared.filter().rel,
            period,
            period32: period.map(|t| t as f32),
            offset: std::array::from_fn(|k| prepared.offset()[k]),
        }
    }
}

/// An `f32` `θ` such that an `f32` squared distance `s̃ ≤ θ` proves the exact distance
/// at most `√c2`: `θ ≤ (√c2 − delta)² / (1 + rel)` (see [`FilterBounds`]), within
/// `delta·√c2/2 + rel²·c2` and one `f32` step of it. Negative when nothing can be
/// proven.
#[inline(always)]
pub(crate) fn threshold(c2: f64, delta: f64, rel: f64) -> f32 {
    // (√c − δ)² = c − 2δ√c + δ² ≥ c − δ·(c/s + s) for any s > 0 (2√c ≤ c/s + s), and
    // 1/(1 + rel) ≥ 1 − rel. With s = 2^k, k = ⌊e/2⌋ for c = m·2^e, c/s is exact and
    // s/√c lies in (1/2, 1]: no square root or division on the path from a new c to
    // the tests that wait for it. The factors 1 ± nε cover the roundings (rounded
    // up in the subtracted term, down in the result).
    if c2 > 1e300 {
        return threshold_exact(c2, delta, rel);
    }
    if c2.is_nan() || c2 < f64::MIN_POSITIVE {
        return -1.0;
    }
    let e = ((c2.to_bits() >> 52) & 0x7ff) as i64 - 1023;
    let k = e >> 1;
    let s = f64::from_bits(((k + 1023) as u64) << 52);
    let inv_s = f64::from_bits(((1023 - k) as u64) << 52);
    let reach = delta * c2.mul_add(inv_s, s) * (1.0 + 4.0 * f64::EPSILON);
    let u = c2 - reach;
    if u <= 0.0 {
        return -1.0;
    }
    f32_at_most(u * ((1.0 - rel) * (1.0 - 8.0 * f64::EPSILON)))
}

/// The largest `f32` at most `(√c2 − delta)² / (1 + rel)` (up to a few roundings),
/// negative when nothing can be proven: [`threshold`] with the square root, for `c2`
/// beyond `10³⁰⁰` and for the tests.
#[inline(always)]
pub(crate) fn threshold_exact(c2: f64, delta: f64, rel: f64) -> f32 {
    let margin = c2.sqrt() * (1.0 - 4.0 * f64::EPSILON) - delta;
    if margin <= 0.0 {
        return -1.0;
    }
    f32_at_most(margin * margin / (1.0 + rel) * (1.0 - 4.0 * f64::EPSILON))
}

/// The smallest `f32` at least `x ≥ 0` (`+∞` past the largest `f32`), without a branch:
/// for `t ≥ 0` the next `f32` up is the next bit pattern. A data-dependent branch here
/// is mispredicted about every other time (two or three times per pair of sets).
#[inline(always)]
pub(crate) fn f32_at_least(x: f64) -> f32 {
    debug_assert!(x >= 0.0 || x.is_nan());
    let t = x as f32;
    f32::from_bits(t.to_bits() + u32::from(f64::from(t) < x))
}

/// The largest `f32` at most `x > 0`, without a branch (see [`f32_at_least`]).
#[inline(always)]
pub(crate) fn f32_at_most(x: f64) -> f32 {
    debug_assert!(x > 0.0);
    let t = x as f32;
    f32::from_bits(t.to_bits() - u32::from(f64::from(t) > x))
}

/// The smallest `f32` at least `(√(s·(1 + rel)) + reach)²·(1 + rel)`: every point whose
/// exact distance is at most `√(s·(1 + rel)) + reach − delta` has an `f32` squared
/// distance at most this (with `reach ≥ delta`).
#[inline(always)]
pub(crate) fn cut_above(s: f32, reach: f64, rel: f64) -> f32 {
    let root = (f64::from(s) * (1.0 + rel)).sqrt() * (1.0 + 4.0 * f64::EPSILON) + reach;
    f32_at_least(root * root * (1.0 + rel) * (1.0 + 4.0 * f64::EPSILON))
}

/// The rank of `x` among `keys` in decreasing order: how many of them are larger.
/// Without a branch (one vector comparison for several keys): the small sorts of the
/// kernels ([`far_first`], and the curve kernel's block and open-segment orders) pack
/// each entry into a distinct key and place it at its rank.
#[inline(always)]
pub(crate) fn rank_among<T: PartialOrd + Copy>(x: T, keys: &[T]) -> usize {
    let mut rank = 0u32;
    for &y in keys {
        rank += u32::from(y > x);
    }
    rank as usize
}

/// Exact `g²(x, y)` in `f64` (fused multiply-adds in coordinate order).
#[inline(always)]
pub(crate) fn exact2<const N: usize>(x: &[f64; N], y: &[f64], period: &[f64; N]) -> f64 {
    let mut d2 = 0.0;
    for k in 0..N {
        let w = fold(x[k] - y[k], period[k]);
        d2 = w.mul_add(w, d2);
    }
    d2
}

/// For every chunk of `a` the nearest chunk of `b` by centre distance and that squared
/// distance (`row_*`), and the same for the chunks of `b` (`col_*`), in `f32`: lanes
/// over eight chunks of `a`, the centres of `b` broadcast one by one. Ties keep the
/// lower index.
#[inline(always)]
pub(crate) fn center_table<S: Lanes, const N: usize>(
    s: S,
    a: SetRef<'_>,
    b: SetRef<'_>,
    frame: &Frame<N>,
    scratch: &mut Scratch,
) {
    let chunks = frame.chunks;
    let period: [S::V; N] = each(s.splat(0.0), |k| s.splat(frame.period32[k]));
    scratch.row_key.clear();
    scratch.row_near.clear();
    scratch.col_key.clear();
    scratch.col_key.resize(chunks, f32::INFINITY);
    scratch.col_near.clear();
    scratch.col_near.resize(chunks, 0);
    let (a_rows, _) = a.centers_wide.as_chunks::<LANES>();
    let (b_centers, _) = b.centers_narrow.as_chunks::<N>();
    let b_centers = &b_centers[..chunks];
    let groups = chunks.div_ceil(LANES);
    let per_row = frame.chunks_wide / LANES;
    // Column minima lane by lane over the groups (the lane's block index where
    // strictly smaller, so the lower index on ties), reduced across lanes once per
    // column at the end.
    let lane_index = s.load(&std::array::from_fn(|l| l as f32));
    scratch.col_lanes.clear();
    scratch
        .col_lanes
        .resize(chunks, ([f32::INFINITY; LANES], [0.0; LANES]));
    for g in 0..groups {
        let ca: [S::V; N] = each(s.splat(0.0), |k| s.load(&a_rows[k * per_row + g]));
        let mut best = s.splat(f32::INFINITY);
        let mut best_at = s.splat(0.0);
        let index = s.add(lane_index, s.splat((g * LANES) as f32));
        for (beta, cb) in b_centers.iter().enumerate() {
            let mut d = s.splat(0.0);
            for k in 0..N {
                let w = s.fold(s.sub(ca[k], s.splat(cb[k])), period[k]);
                d = s.mul_add(w, w, d);
            }
            best_at = s.select_lt(d, best, s.splat(beta as f32), best_at);
            best = s.min(d, best);
            let (col_min, col_at) = &mut scratch.col_lanes[beta];
            let (m, at) = (s.load(col_min), s.load(col_at));
            *col_at = s.array(s.select_lt(d, m, index, at));
            *col_min = s.array(s.min(d, m));
        }
        let (key, at) = (s.array(best), s.array(best_at));
        let live = (chunks - g * LANES).min(LANES);
        scratch.row_key.extend_from_slice(&key[..live]);
        scratch
            .row_near
            .extend(at[..live].iter().map(|&x| x as u32));
    }
    for (beta, (col_min, col_at)) in scratch.col_lanes.iter().enumerate() {
        let (m, at) = (s.load(col_min), s.load(col_at));
        let smallest = s.hmin(m);
        // The lowest block index among the lanes holding the minimum.
        let at = s.select_lt(s.splat(smallest), m, s.splat(f32::INFINITY), at);
        scratch.col_key[beta] = smallest;
        scratch.col_near[beta] = s.hmin(at) as u32;
    }
}

/// Fills `order[..chunks]` with the blocks ordered far from the other set first (by
/// `key`, the squared distance from a block's centre to the other set's nearest
/// centre; ties: lower index first), so that the running bound reaches its final value
/// early.
#[inline(always)]
pub(crate) fn far_first(key: &[f32], order: &mut Vec<u32>) {
    let chunks = key.len();
    order.clear();
    order.resize(chunks, 0);
    if chunks <= RANK_SORT_MAX {
        // A non-negative f32 orders like its bits, here read as `i32` (they stay
        // below 2³¹, and a signed comparison is one vector instruction for eight,
        // where an unsigned one is not); the low four bits take the (inverted) block
        // index, which makes the keys distinct. Ranked without branches: the rank of
        // a key is the number of larger keys (the padding, `i32::MIN`, is never one).
        let mut packed = [i32::MIN; RANK_SORT_MAX];
        for (alpha, slot) in packed.iter_mut().enumerate().take(chunks) {
            *slot = ((key[alpha].to_bits() & !15) | (15 - alpha as u32)) as i32;
        }
        for alpha in 0..chunks {
            order[rank_among(packed[alpha], &packed)] = alpha as u32;
        }
    } else {
        for (alpha, slot) in order.iter_mut().enumerate() {
            *slot = alpha as u32;
        }
        order.sort_by(|&x, &y| key[y as usize].total_cmp(&key[x as usize]));
    }
}

/// The `f32` `g²` from the eight points of `block` (lanes) to the point `b`.
#[inline(always)]
fn block_dist2<S: Lanes, const N: usize>(
    s: S,
    block: &[S::V; N],
    b: &[f32; N],
    period: &[S::V; N],
) -> S::V {
    let mut acc = s.splat(0.0);
    for k in 0..N {
        let w = s.fold(s.sub(block[k], s.splat(b[k])), period[k]);
        acc = s.mul_add(w, w, acc);
    }
    acc
}

/// The `f32` `g²` from point `x` to every point of `b`, chunk by chunk (lanes over the
/// points of a chunk), into `out`; returns the smallest.
#[inline(always)]
pub(crate) fn lane_scan<S: Lanes, const N: usize>(
    s: S,
    x: &[f32; N],
    b: SetRef<'_>,
    frame: &Frame<N>,
    out: &mut [[f32; LANES]],
) -> f32 {
    let chunks = frame.chunks;
    let (rows, _) = b.coords32.as_chunks::<LANES>();
    let rows: [&[[f32; LANES]]; N] = std::array::from_fn(|k| &rows[k * chunks..(k + 1) * chunks]);
    let xs: [S::V; N] = std::array::from_fn(|k| s.splat(x[k]));
    let period: [S::V; N] = std::array::from_fn(|k| s.splat(frame.period32[k]));
    let out = &mut out[..chunks];
    let mut smallest = s.splat(f32::INFINITY);
    for q in 0..chunks {
        let mut acc = s.splat(0.0);
        for k in 0..N {
            let w = s.fold(s.sub(xs[k], s.load(&rows[k][q])), period[k]);
            acc = s.mul_add(w, w, acc);
        }
        out[q] = s.array(acc);
        smallest = s.min(acc, smallest);
    }
    s.hmin(smallest)
}

/// The exact `min_b g²(x, b)`, given the `f32` values `scan` of every `b`: the exact
/// minimiser's `f32` value is at most [`cut_above`]`(smallest, 2·delta)` (it is no
/// farther than the `f32` minimiser, whose exact distance is at most
/// `√(smallest·(1 + rel)) + delta`), so only those points are computed in `f64`.
#[inline(always)]
fn exact_nearest<S: Lanes, const N: usize>(
    s: S,
    x: &[f64; N],
    b: SetRef<'_>,
    frame: &Frame<N>,
    scan: &[[f32; LANES]],
    smallest: f32,
) -> f64 {
    let cut = s.splat(cut_above(smallest, 2.0 * frame.delta, frame.rel));
    let (points, _) = b.points.as_chunks::<N>();
    let mut best = f64::INFINITY;
    for (q, lanes) in scan.iter().enumerate().take(frame.chunks) {
        let mut mask = s.le(s.load(lanes), cut);
        while mask != 0 {
            let l = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let d2 = exact2(x, &points[q * LANES + l], &frame.period);
            best = if d2 < best { d2 } else { best };
        }
    }
    best
}

/// The lanes of one block of `A`: its `f32` coordinates, and the `f64` point of a lane.
#[derive(Clone, Copy)]
struct Block<'a, S: Lanes, const N: usize> {
    lanes: [S::V; N],
    set: SetRef<'a>,
    first: usize,
}

impl<'a, S: Lanes, const N: usize> Block<'a, S, N> {
    #[inline(always)]
    fn load(s: S, set: SetRef<'a>, frame: &Frame<N>, alpha: usize) -> Self {
        let (rows, _) = set.coords32.as_chunks::<LANES>();
        Self {
            lanes: std::array::from_fn(|k| s.load(&rows[k * frame.chunks + alpha])),
            set,
            first: alpha * LANES,
        }
    }

    #[inline(always)]
    fn point32(&self, frame: &Frame<N>, l: usize) -> [f32; N] {
        std::array::from_fn(|k| self.set.coords32[k * frame.points_pad + self.first + l])
    }

    #[inline(always)]
    fn point64(&self, l: usize) -> [f64; N] {
        let (points, _) = self.set.points.as_chunks::<N>();
        points[self.first + l]
    }
}

/// The window of block `block` around point `start` of `b`: per-lane smallest `f32`
/// `g²`. With `theta ≥ 0` it stops once every live lane is `≤ theta`; without (nothing
/// found yet) it runs to its end, so that its values rank the lanes well.
#[inline(always)]
fn window<S: Lanes, const N: usize>(
    s: S,
    block: &[S::V; N],
    b: SetRef<'_>,
    frame: &Frame<N>,
    start: usize,
    theta: f32,
    live: u32,
) -> S::V {
    let period: [S::V; N] = std::array::from_fn(|k| s.splat(frame.period32[k]));
    let (ring, _) = b.ring32.as_chunks::<N>();
    let ring = &ring[start..start + 2 * RING + 1];
    let mut best = s.splat(f32::INFINITY);
    for &r in &RING_WINDOW[..WINDOW_FIRST] {
        best = s.min(block_dist2(s, block, &ring[r], &period), best);
    }
    let thv = s.splat(theta);
    if s.gt(best, thv) & live == 0 && theta >= 0.0 {
        return best;
    }
    for &r in &RING_WINDOW[WINDOW_FIRST..frame.points.min(RING_WINDOW.len()).max(WINDOW_FIRST)] {
        best = s.min(block_dist2(s, block, &ring[r], &period), best);
        if theta >= 0.0 && s.gt(best, thv) & live == 0 {
            break;
        }
    }
    best
}

/// `max(c2, max_{a∈A} min_{b∈B} g²(a, b))`, or `None` as soon as it is proven to exceed
/// `abort2`. `(key[α], near[α])`: squared distance from the centre of block `α` of `A`
/// to the nearest centre of `B`, and that chunk.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn directed_hausdorff<S: Lanes, const N: usize>(
    s: S,
    a: SetRef<'_>,
    b: SetRef<'_>,
    frame: &Frame<N>,
    (key, near): (&[f32], &[u32]),
    mut c2: f64,
    abort2: f64,
    (order, scan): (&mut Vec<u32>, &mut Vec<[f32; LANES]>),
) -> Option<f64> {
    far_first(key, order);
    scan.resize(frame.chunks, [0.0; LANES]);
    let mut theta = threshold(c2, frame.delta, frame.rel);
    for &alpha in order.iter() {
        let alpha = alpha as usize;
        let block = Block::<S, N>::load(s, a, frame, alpha);
        let start = (near[alpha] as usize * LANES + LANES / 2).min(frame.points - 1);
        let live = (1u32 << (frame.points - alpha * LANES).min(LANES)) - 1;
        let best = window(s, &block.lanes, b, frame, start, theta, live);
        let mut open = s.gt(best, s.splat(theta)) & live;
        let mut values = s.array(best);
        // The open lanes, largest window value first.
        while open != 0 {
            let mut l = open.trailing_zeros() as usize;
            let mut rest = open & (open - 1);
            while rest != 0 {
                let m = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                if values[m] > values[l] {
                    l = m;
                }
            }
            open &= !(1 << l);
            values[l] = f32::NEG_INFINITY;
            let smallest = lane_scan(s, &block.point32(frame, l), b, frame, scan);
            if smallest <= theta {
                continue;
            }
            let d2 = exact_nearest(s, &block.point64(l), b, frame, scan, smallest);
            if d2 > c2 {
                c2 = d2;
                if c2 > abort2 {
                    return None;
                }
                theta = threshold(c2, frame.delta, frame.rel);
                // Lanes whose window value now settles them.
                open &= s.gt(s.load(&values), s.splat(theta));
            }
        }
    }
    Some(c2)
}

/// `Σ_{a∈A} min_{b∈B} g(a, b)`, summed in point order.
#[inline(always)]
fn directed_mean_sum<S: Lanes, const N: usize>(
    s: S,
    a: SetRef<'_>,
    b: SetRef<'_>,
    frame: &Frame<N>,
    scan: &mut Vec<[f32; LANES]>,
) -> f64 {
    scan.resize(frame.chunks, [0.0; LANES]);
    let mut sum = 0.0;
    for alpha in 0..frame.chunks {
        let block = Block::<S, N>::load(s, a, frame, alpha);
        for l in 0..(frame.points - alpha * LANES).min(LANES) {
            let smallest = lane_scan(s, &block.point32(frame, l), b, frame, scan);
            sum += exact_nearest(s, &block.point64(l), b, frame, scan, smallest).sqrt();
        }
    }
    sum
}

/// Symmetric Hausdorff distance `ρ(A, B)`, or `None` once proven `> limit`.
#[inline(always)]
fn hausdorff<S: Lanes, const N: usize>(
    s: S,
    a: SetRef<'_>,
    b: SetRef<'_>,
    frame: &Frame<N>,
    limit: f64,
    scratch: &mut Scratch,
) -> Option<f64> {
    let abort2 = if limit.is_finite() {
        limit * limit
    } else {
        f64::INFINITY
    };
    center_table(s, a, b, frame, scratch);
    let Scratch {
        row_key,
        row_near,
        col_key,
        col_near,
        order,
        lane,
        ..
    } = scratch;
    let c2 = directed_hausdorff(
        s,
        a,
        b,
        frame,
        (row_key, row_near),
        0.0,
        abort2,
        (order, lane),
    )?;
    let c2 = directed_hausdorff(
        s,
        b,
        a,
        frame,
        (col_key, col_near),
        c2,
        abort2,
        (order, lane),
    )?;
    Some(c2.sqrt())
}

/// Mean Hausdorff distance: the average of the two mean directed distances.
#[inline(always)]
fn mean_hausdorff<S: Lanes, const N: usize>(
    s: S,
    a: SetRef<'_>,
    b: SetRef<'_>,
    frame: &Frame<N>,
    scratch: &mut Scratch,
) -> f64 {
    let p = frame.points as f64;
    let ab = directed_mean_sum(s, a, b, frame, &mut scratch.lane) / p;
    let ba = directed_mean_sum(s, b, a, frame, &mut scratch.lane) / p;
    0.5 * (ab + ba)
}

/// Brute force over the prepared layout, for coordinate counts without a fixed kernel
/// (`N > 16`) and coordinates beyond the `f32` filter:
/// `(max_a min_b g², max_b min_a g², Σ_a min_b g, Σ_b min_a g)`.
pub(crate) fn brute_pair(a: SetRef<'_>, b: SetRef<'_>, prepared: &PreparedSets) -> [f64; 4] {
    let p = prepared.points();
    let dims = prepared.dims_pad();
    let period = prepared.period_pad();
    let mut row_min = vec![f64::INFINITY; p];
    let mut col_min = vec![f64::INFINITY; p];
    for i in 0..p {
        for j in 0..p {
            let mut d2 = 0.0;
            for k in 0..dims {
                let w = fold(a.points[i * dims + k] - b.points[j * dims + k], period[k]);
                d2 = w.mul_add(w, d2);
            }
            row_min[i] = row_min[i].min(d2);
            col_min[j] = col_min[j].min(d2);
        }
    }
    let fold_max = |v: &[f64]| v.iter().fold(0.0, |m: f64, &x| m.max(x));
    let fold_sum = |v: &[f64]| v.iter().fold(0.0, |s: f64, &x| s + x.sqrt());
    [
        fold_max(&row_min),
        fold_max(&col_min),
        fold_sum(&row_min),
        fold_sum(&col_min),
    ]
}

/// Evaluates distances between prepared sets; implemented once per coordinate count so
/// that the kernels inline with their fixed `N`.
pub(crate) trait Eval {
    /// `ρ(set i, set j)`, or `None` once it is proven to exceed `limit`.
    fn distance(&mut self, i: usize, j: usize, limit: f64) -> Option<f64>;

    /// Reads one value per cache line of set `j`, so that its data is on its way to the
    /// cache while another pair is computed (a software prefetch without `unsafe`).
    fn touch(&mut self, _j: usize) {}
}

/// Work run under runtime SIMD dispatch: it receives an [`Eval`] compiled for the
/// machine's best instruction set.
pub(crate) trait Driver {
    /// What the work returns.
    type Output;
    /// Runs the work; must be `#[inline(always)]` so that it is compiled in the
    /// dispatched context.
    fn drive<E: Eval>(self, eval: &mut E) -> Self::Output;
}

struct Evaluator<'a, S, const N: usize> {
    s: S,
    prepared: &'a PreparedSets,
    kind: super::MetricKind,
    frame: Frame<N>,
    scratch: &'a mut Scratch,
}

impl<S: Lanes, const N: usize> Eval for Evaluator<'_, S, N> {
    #[inline(always)]
    fn distance(&mut self, i: usize, j: usize, limit: f64) -> Option<f64> {
        let a = self.prepared.set(i);
        let b = self.prepared.set(j);
        match self.kind {
            super::MetricKind::Hausdorff => {
                hausdorff(self.s, a, b, &self.frame, limit, self.scratch)
            }
            super::MetricKind::MeanHausdorff => {
                Some(mean_hausdorff(self.s, a, b, &self.frame, self.scratch))
            }
            // Its own runtime dispatch (one per pair, negligible next to the pair), so
            // that the curve kernel is compiled once per instruction set and coordinate
            // count instead of once per driver as well.
            super::MetricKind::Curve => {
                super::curve::curve_pair(self.prepared, i, j, limit, self.scratch)
            }
        }
    }

    #[inline(always)]
    fn touch(&mut self, j: usize) {
        let set = self.prepared.set(j);
        let mut sum = 0.0;
        for x in set.points.iter().step_by(8) {
            sum += x;
        }
        for part in [set.coords32, set.ring32, set.centers_wide] {
            for &x in part.iter().step_by(16) {
                sum += f64::from(x);
            }
        }
        std::hint::black_box(sum);
    }
}

struct BruteEvaluator<'a> {
    prepared: &'a PreparedSets,
    kind: super::MetricKind,
}

impl Eval for BruteEvaluator<'_> {
    fn distance(&mut self, i: usize, j: usize, _limit: f64) -> Option<f64> {
        let [ab, ba, sum_ab, sum_ba] =
            brute_pair(self.prepared.set(i), self.prepared.set(j), self.prepared);
        Some(match self.kind {
            super::MetricKind::Hausdorff => ab.max(ba).sqrt(),
            super::MetricKind::MeanHausdorff => {
                let p = self.prepared.points() as f64;
                0.5 * (sum_ab / p + sum_ba / p)
            }
            super::MetricKind::Curve => {
                unreachable!(
                    "the curve metric is compiled for up to 16 coordinates, checked before"
                )
            }
        })
    }
}

/// The instruction set the kernels run with.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Simd {
    /// AVX-512 (F, BW, CD, DQ, VL) + FMA: eight lanes per 256-bit register, masks in
    /// mask registers.
    #[cfg(target_arch = "x86_64")]
    Avx512(pulp::x86::V4),
    /// AVX2 + FMA: one 256-bit register per eight lanes.
    #[cfg(target_arch = "x86_64")]
    Avx2(pulp::x86::V3),
    /// Plain arrays.
    Portable,
}

/// An instruction set the metric kernels can run with. Every level gives the same
/// distances, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SimdLevel {
    /// AVX-512 (F, BW, CD, DQ, VL) with FMA, x86-64 only.
    Avx512,
    /// AVX2 with FMA, x86-64 only.
    Avx2,
    /// Plain arrays, on every CPU.
    Portable,
}

impl SimdLevel {
    /// Every level, fastest first.
    pub const ALL: [SimdLevel; 3] = [SimdLevel::Avx512, SimdLevel::Avx2, SimdLevel::Portable];

    /// The level's name, as `SMSPACE_SIMD` takes it: `avx512`, `avx2` or `portable`.
    pub fn name(self) -> &'static str {
        match self {
            SimdLevel::Avx512 => "avx512",
            SimdLevel::Avx2 => "avx2",
            SimdLevel::Portable => "portable",
        }
    }

    /// Whether this CPU has the level's instructions.
    pub fn available(self) -> bool {
        self.token().is_some()
    }

    /// The level's token, where this CPU has it.
    fn token(self) -> Option<Simd> {
        match self {
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx512 => pulp::x86::V4::try_new().map(Simd::Avx512),
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx2 => pulp::x86::V3::try_new().map(Simd::Avx2),
            #[cfg(not(target_arch = "x86_64"))]
            SimdLevel::Avx512 | SimdLevel::Avx2 => None,
            SimdLevel::Portable => Some(Simd::Portable),
        }
    }

    /// The fastest level of this CPU at most as fast as `self`.
    fn best_up_to(self) -> Simd {
        SimdLevel::ALL
            .iter()
            .skip_while(|&&l| l != self)
            .find_map(|l| l.token())
            .unwrap_or(Simd::Portable)
    }
}

/// The level forced by [`force_simd_level`]: 0 for none, else 1 + its index in
/// [`SimdLevel::ALL`].
static FORCED: AtomicU8 = AtomicU8::new(0);

/// Makes the metric kernels of this process run with `level` (`None`: the default
/// again), for comparisons and tests; returns `false`, changing nothing, when this CPU
/// lacks the level. Distances do not depend on the level, only their speed.
pub fn force_simd_level(level: Option<SimdLevel>) -> bool {
    let code = match level {
        None => 0,
        Some(l) if l.available() => 1 + SimdLevel::ALL.iter().position(|&x| x == l).unwrap_or(0),
        Some(_) => return false,
    };
    FORCED.store(code as u8, Ordering::Relaxed);
    true
}

/// The instruction set of the kernels: the one forced by [`force_simd_level`], else
/// the fastest of this CPU, capped by the environment variable `SMSPACE_SIMD`
/// (`avx512`, `avx2` or `portable`: the fastest level of this CPU at most that one),
/// detected once.
pub(crate) fn simd() -> Simd {
    static CHOICE: OnceLock<Simd> = OnceLock::new();
    let forced = FORCED.load(Ordering::Relaxed) as usize;
    if let Some(level) = forced.checked_sub(1).and_then(|k| SimdLevel::ALL.get(k)) {
        return level.best_up_to();
    }
    *CHOICE.get_or_init(|| {
        let cap = std::env::var("SMSPACE_SIMD")
            .ok()
            .and_then(|v| SimdLevel::ALL.into_iter().find(|l| l.name() == v.trim()))
            .unwrap_or(SimdLevel::Avx512);
        cap.best_up_to()
    })
}

/// Which instruction set the metric kernels run with, in words (for benchmarks and
/// reports), e.g. `"AVX-512 (F, BW, CD, DQ, VL) + FMA, 8 f32 lanes"`.
pub fn simd_level() -> &'static str {
    match simd() {
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512(_) => "AVX-512 (F, BW, CD, DQ, VL) + FMA, 8 f32 lanes",
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2(_) => "AVX2 + FMA, 8 f32 lanes",
        Simd::Portable => "portable (8 f32 lanes in arrays)",
    }
}

/// Runs `driver` with the evaluator of `prepared`'s coordinate count, on lanes `s`.
#[inline(always)]
fn drive_with<S: Lanes, D: Driver>(
    s: S,
    prepared: &PreparedSets,
    kind: super::MetricKind,
    scratch: &mut Scratch,
    driver: D,
) -> D::Output {
    macro_rules! fixed {
        ($n:literal) => {
            driver.drive(&mut Evaluator::<S, $n> {
                s,
                prepared,
                kind,
                frame: Frame::of(prepared),
                scratch,
            })
        };
    }
    if prepared.is_wide() && kind != super::MetricKind::Curve {
        return driver.drive(&mut BruteEvaluator { prepared, kind });
    }
    match prepared.dims_pad() {
        2 => fixed!(2),
        4 => fixed!(4),
        8 => fixed!(8),
        16 => fixed!(16),
        _ => driver.drive(&mut BruteEvaluator { prepared, kind }),
    }
}

/// Runs `driver` with the kernels compiled for the best instruction set of this CPU,
/// chosen at run time.
pub(crate) fn dispatch<D: Driver>(
    prepared: &PreparedSets,
    kind: super::MetricKind,
    scratch: &mut Scratch,
    driver: D,
) -> D::Output {
    match simd() {
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512(v4) => v4.vectorize(DriveCall {
            s: v4,
            prepared,
            kind,
            scratch,
            driver,
        }),
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2(v3) => v3.vectorize(DriveCall {
            s: v3,
            prepared,
            kind,
            scratch,
            driver,
        }),
        Simd::Portable => drive_with(Portable, prepared, kind, scratch, driver),
    }
}

/// A driver's work, for `pulp`'s target-feature context (its `call` is inlined there).
struct DriveCall<'a, S, D> {
    s: S,
    prepared: &'a PreparedSets,
    kind: super::MetricKind,
    scratch: &'a mut Scratch,
    driver: D,
}

impl<S: Lanes, D: Driver> pulp::NullaryFnOnce for DriveCall<'_, S, D> {
    type Output = D::Output;

    #[inline(always)]
    fn call(self) -> D::Output {
        drive_with(self.s, self.prepared, self.kind, self.scratch, self.driver)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metric::{reference, MetricKind, Period};
    use rand::{RngExt, SeedableRng};

    /// The portable lanes give the same matrix as the brute force (the AVX2 lanes are
    /// checked against the portable ones in `lanes`, and the whole path in the tests).
    #[test]
    fn portable_kernels_equal_the_brute_force() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(3);
        let sets = ndarray::Array3::from_shape_fn((12, 21, 3), |_| rng.random_range(-4.0..4.0));
        for period in [Period::TwoPi, Period::None] {
            let prepared = PreparedSets::new(sets.view(), period).unwrap();
            let frame = Frame::<4>::of(&prepared);
            let mut scratch = Scratch::default();
            for kind in [MetricKind::Hausdorff, MetricKind::MeanHausdorff] {
                let slow = reference::distance_matrix(sets.view(), kind, period);
                for i in 0..12 {
                    for j in 0..12 {
                        let (a, b) = (prepared.set(i), prepared.set(j));
                        let fast = match kind {
                            MetricKind::Hausdorff => {
                                hausdorff(Portable, a, b, &frame, f64::INFINITY, &mut scratch)
                                    .unwrap()
                            }
                            _ => mean_hausdorff(Portable, a, b, &frame, &mut scratch),
                        };
                        assert!((fast - slow[[i, j]]).abs() < 1e-12, "{kind:?} {i} {j}");
                    }
                }
            }
        }
    }

    #[test]
    fn rounding_to_f32_up_and_down_without_a_branch_matches_next_up_and_down() {
        let values = [
            0.0,
            1e-50,
            1e-45,
            f64::from(f32::from_bits(1)),
            0.1,
            0.37,
            1.0,
            std::f64::consts::PI,
            4.0 * std::f64::consts::PI * std::f64::consts::PI,
            1e30,
            f64::from(f32::MAX),
            f64::from(f32::MAX) * (1.0 + 1e-9),
            1e300,
            f64::INFINITY,
        ];
        for x in values {
            let t = x as f32;
            let up = if f64::from(t) < x { t.next_up() } else { t };
            assert_eq!(f32_at_least(x).to_bits(), up.to_bits(), "{x}");
            assert!(f64::from(f32_at_least(x)) >= x);
            if x > 0.0 && x.is_finite() {
                let down = if f64::from(t) > x { t.next_down() } else { t };
                assert_eq!(f32_at_most(x).to_bits(), down.to_bits(), "{x}");
                assert!(f64::from(f32_at_most(x)) <= x);
            }
        }
        assert!(f32_at_least(f64::NAN).is_nan());
    }

    #[test]
    fn thresholds_round_down_and_cuts_up() {
        let (delta, rel) = (1e-5, 1e-6);
        for c2 in [1e-12, 0.37, 4.0, 39.0] {
            for (tight, t) in [
                (true, threshold_exact(c2, delta, rel)),
                (false, threshold(c2, delta, rel)),
            ] {
                if c2.sqrt() > delta {
                    let x = f64::from(t);
                    assert!((x * (1.0 + rel)).sqrt() + delta <= c2.sqrt());
                    let above = f64::from(t.next_up());
                    let slack = if tight { 1e-6 } else { 1e-6 + delta };
                    assert!((above * (1.0 + rel)).sqrt() + delta > c2.sqrt() * (1.0 - slack));
                } else {
                    assert!(t < 0.0);
                }
            }
            let cut = f64::from(cut_above(c2 as f32, delta, rel));
            assert!(cut.sqrt() >= (f64::from(c2 as f32) * (1.0 + rel)).sqrt() + delta);
        }
    }

    /// The threshold without a square root is never above the one with it (which
    /// proves `g ≤ √c`), and gives up at most `δ·√c/2` of it (plus an `f32` step).
    #[test]
    fn thresholds_without_a_square_root_stay_below_the_exact_ones() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(11);
        for _ in 0..200_000 {
            let c2 = 10f64.powf(rng.random_range(-30.0..30.0));
            let delta = 10f64.powf(rng.random_range(-12.0..2.0));
            let rel = 10f64.powf(rng.random_range(-9.0..-4.0));
            let fast = threshold(c2, delta, rel);
            let exact = threshold_exact(c2, delta, rel);
            assert!(fast <= exact, "{c2} {delta} {rel}: {fast} > {exact}");
            let lost = delta * c2.sqrt() / 2.0 + delta * delta + rel * rel * c2;
            if fast < 0.0 {
                assert!(f64::from(exact) <= lost + 1e-14 * c2, "{c2} {delta} {rel}");
            } else {
                let floor = f64::from(exact) * (1.0 - 3e-7) - lost * (1.0 + 1e-9);
                assert!(
                    f64::from(fast) >= floor,
                    "{c2} {delta} {rel}: {fast} < {floor}"
                );
            }
        }
        assert!(threshold(0.0, 1e-6, 1e-7) < 0.0);
        assert!(threshold(1e-14, 1e-6, 1e-7) < 0.0);
    }

    /// The centre table's nearest chunks and their squared distances are those of a
    /// scalar search (ties: the lower chunk), on every level.
    #[test]
    fn center_tables_match_a_scalar_search() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(7);
        for points in [5, 21, 64, 100, 131] {
            let sets =
                ndarray::Array3::from_shape_fn((3, points, 3), |_| rng.random_range(-4.0..4.0));
            for period in [Period::TwoPi, Period::None] {
                let prepared = PreparedSets::new(sets.view(), period).unwrap();
                let frame = Frame::<4>::of(&prepared);
                let (a, b) = (prepared.set(0), prepared.set(1));
                let mut scratch = Scratch::default();
                center_table(Portable, a, b, &frame, &mut scratch);
                let (c_a, _) = a.centers_narrow.as_chunks::<4>();
                let (c_b, _) = b.centers_narrow.as_chunks::<4>();
                let d = |x: &[f32; 4], y: &[f32; 4]| {
                    (0..4).fold(0.0f32, |acc, k| {
                        let u = (x[k] - y[k]).abs();
                        let v = frame.period32[k] - u;
                        let w = if u < v { u } else { v };
                        w.mul_add(w, acc)
                    })
                };
                let nearest = |x: &[f32; 4], others: &[[f32; 4]]| {
                    (0..frame.chunks).fold((f32::INFINITY, 0u32), |(m, at), q| {
                        let v = d(x, &others[q]);
                        if v < m {
                            (v, q as u32)
                        } else {
                            (m, at)
                        }
                    })
                };
                for q in 0..frame.chunks {
                    let row = nearest(&c_a[q], c_b);
                    assert_eq!((scratch.row_key[q], scratch.row_near[q]), row, "row {q}");
                    let col = nearest(&c_b[q], c_a);
                    assert_eq!((scratch.col_key[q], scratch.col_near[q]), col, "col {q}");
                }
            }
        }
    }

    /// The far-first order sorts by decreasing key, ties by the lower block.
    #[test]
    fn far_first_orders_by_decreasing_key_then_lower_block() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(9);
        for chunks in [1, 2, 7, 13, 16, 17, 40] {
            for _ in 0..50 {
                // Few distinct keys, so that ties occur.
                let key: Vec<f32> = (0..chunks)
                    .map(|_| f32::from(rng.random_range(0u8..5)) * 0.25)
                    .collect();
                let mut order = Vec::new();
                far_first(&key, &mut order);
                let mut expected: Vec<u32> = (0..chunks as u32).collect();
                expected.sort_by(|&x, &y| key[y as usize].total_cmp(&key[x as usize]));
                assert_eq!(order, expected, "{key:?}");
            }
        }
    }
}
