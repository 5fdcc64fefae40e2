//! The `f32` passes of the curve kernel: eight segments of `A` at a time (one lane
//! each), compared with points and segments of `B` near the nearest chunk. They only
//! *settle* segments (prove `max_t d_B(a_i + t v_i) ≤ c`), with the error bounds of
//! [`FilterBounds`](crate::metric::prepared::FilterBounds) to spare; every value that
//! enters the result is computed exactly afterwards.
//!
//! Both tests rest on convexity. With `w = h(a_i − p)` (the lifted difference to a
//! point `p`, one image) the Euclidean `|w + t·v_i|` is convex in `t` and at least
//! `g(a_i + t v_i, p) ≥ d_B(a_i + t v_i)` when `p` lies on `B`; so segment `i` is settled
//! when `max(|w|, |w + v_i|) ≤ c`. For a segment `s_j` of `B` (one image), the
//! Euclidean distance from `a_i + t v_i` to it is convex in `t` too (distance to a
//! convex set), and at most `|w − σ·v_j|` for any `σ ∈ [0, 1]`: segment `i` is settled
//! when both ends are within `c` of the same lifted `s_j`.

use crate::metric::kernel::{each, f32_at_least, Lanes, RING_WINDOW};
use crate::metric::prepared::RING;

/// The rows of a [`vertex_window`] around its centre, outward, every third point of `B`
/// (a point settles a segment of `A` about as well as its neighbours when they are all
/// far from it, and the window reaches three times as far along `B` for the same work:
/// 1 % fewer instructions on the paper's arm than every other point, 11 % fewer than
/// every point).
const VERTEX_WINDOW: [usize; 9] = [
    RING,
    RING + 3,
    RING - 3,
    RING + 6,
    RING - 6,
    RING + 9,
    RING - 9,
    RING + 12,
    RING - 12,
];
use crate::metric::prepared::LANES;

/// Per-coordinate constants of the lifted differences, as vectors.
#[derive(Clone, Copy)]
pub(super) struct Wraps<S: Lanes, const N: usize> {
    /// The period (`0` when not wrapped): `h(u) = u − T·round(u/T)`.
    pub period: [S::V; N],
    /// `1/T` (`0` when not wrapped).
    pub inverse: [S::V; N],
    /// The period for [`Lanes::fold`] (`+∞` when not wrapped).
    pub fold: [S::V; N],
}

impl<S: Lanes, const N: usize> Wraps<S, N> {
    #[inline(always)]
    pub(super) fn new(s: S, period: &[f64; N]) -> Self {
        let zero = s.splat(0.0);
        let finite = |k: usize, x: f64| if period[k].is_finite() { x as f32 } else { 0.0 };
        Self {
            period: each(zero, |k| s.splat(finite(k, period[k]))),
            inverse: each(zero, |k| s.splat(finite(k, 1.0 / period[k]))),
            fold: each(zero, |k| s.splat(period[k] as f32)),
        }
    }
}

/// The eight segments of one block of `A`: starts and directions, lanes over segments.
#[derive(Clone, Copy)]
pub(super) struct SegmentBlock<S: Lanes, const N: usize> {
    pub start: [S::V; N],
    pub dir: [S::V; N],
}

impl<S: Lanes, const N: usize> SegmentBlock<S, N> {
    #[inline(always)]
    pub(super) fn load(
        s: S,
        coords32: &[f32],
        dirs32: &[f32],
        chunks: usize,
        alpha: usize,
    ) -> Self {
        let (points, _) = coords32.as_chunks::<LANES>();
        let (dirs, _) = dirs32.as_chunks::<LANES>();
        let zero = s.splat(0.0);
        Self {
            start: each(zero, |k| s.load(&points[k * chunks + alpha])),
            dir: each(zero, |k| s.load(&dirs[k * chunks + alpha])),
        }
    }
}

/// The points of `B` around its point `start` (rows of its ring, see
/// [`SetRef::ring32`](crate::metric::prepared::SetRef)): compares every lane's segment with
/// them, outward, and returns per lane the smallest `max(|w|², |w + v|²)` (the segment
/// test) and the smallest `|w|²` (an upper bound of `d_B(a_i)²`). With `theta ≥ 0` it
/// stops once every lane of `live` has a segment value `≤ theta`.
#[inline(always)]
pub(super) fn vertex_window<S: Lanes, const N: usize>(
    s: S,
    block: &SegmentBlock<S, N>,
    ring: &[[f32; N]],
    wraps: &Wraps<S, N>,
    (theta, live, length): (f32, u32, usize),
) -> (S::V, S::V) {
    let mut best_segment = s.splat(f32::INFINITY);
    let mut best_vertex = s.splat(f32::INFINITY);
    let thv = s.splat(theta);
    for &r in &VERTEX_WINDOW[..length] {
        let p = &ring[r];
        let (mut d0, mut d1) = (s.splat(0.0), s.splat(0.0));
        for k in 0..N {
            let u = s.sub(block.start[k], s.splat(p[k]));
            let w = s.swrap(u, wraps.period[k], wraps.inverse[k]);
            d0 = s.mul_add(w, w, d0);
            let e = s.add(w, block.dir[k]);
            d1 = s.mul_add(e, e, d1);
        }
        best_vertex = s.min(d0, best_vertex);
        best_segment = s.min(s.max(d0, d1), best_segment);
        if theta >= 0.0 && s.gt(best_segment, thv) & live == 0 {
            break;
        }
    }
    (best_segment, best_vertex)
}

/// The segments of `B` around its segment `start` (rows of its rings): lowers `best`
/// (per lane the segment test value) with `max(E_j(0)², E_j(1)²)`, the squared
/// distances from both ends of the lane's segment to the lifted segment `j` of `B`.
/// Stops once every lane of `open` is `≤ theta`. Returns `best` and, per lane, the
/// smallest `E_j(0)²` and `E_j(1)²` over the segments seen (upper bounds of
/// `d_B(a_i)²` and `d_B(a_{i+1})²` up to the filter's error).
#[inline(always)]
pub(super) fn segment_window<S: Lanes, const N: usize>(
    s: S,
    block: &SegmentBlock<S, N>,
    (ring, dirs, inverse): (&[[f32; N]], &[[f32; N]], &[f32]),
    wraps: &Wraps<S, N>,
    (theta, open, length): (f32, u32, usize),
    mut best: S::V,
) -> (S::V, S::V, S::V) {
    let thv = s.splat(theta);
    let (zero, one) = (s.splat(0.0), s.splat(1.0));
    let (mut best0, mut best1) = (s.splat(f32::INFINITY), s.splat(f32::INFINITY));
    for &r in &RING_WINDOW[..length] {
        let (p, v) = (&ring[r], &dirs[r]);
        let inv = s.splat(inverse[r]);
        let mut w0 = [zero; N];
        let mut w1 = [zero; N];
        let (mut dot0, mut dot1) = (zero, zero);
        for k in 0..N {
            let u = s.sub(block.start[k], s.splat(p[k]));
            w0[k] = s.swrap(u, wraps.period[k], wraps.inverse[k]);
            w1[k] = s.add(w0[k], block.dir[k]);
            let vk = s.splat(v[k]);
            dot0 = s.mul_add(w0[k], vk, dot0);
            dot1 = s.mul_add(w1[k], vk, dot1);
        }
        let t0 = s.max(s.min(s.mul(dot0, inv), one), zero);
        let t1 = s.max(s.min(s.mul(dot1, inv), one), zero);
        let (mut e0, mut e1) = (zero, zero);
        for k in 0..N {
            let vk = s.splat(v[k]);
            let x0 = s.neg_mul_add(t0, vk, w0[k]);
            e0 = s.mul_add(x0, x0, e0);
            let x1 = s.neg_mul_add(t1, vk, w1[k]);
            e1 = s.mul_add(x1, x1, e1);
        }
        best = s.min(s.max(e0, e1), best);
        best0 = s.min(e0, best0);
        best1 = s.min(e1, best1);
        if s.gt(best, thv) & open == 0 {
            break;
        }
    }
    (best, best0, best1)
}

/// One chunk of a [`segment_scan`]: its index in `B`, the lifted squared distances from
/// both ends and the segments that cross the seam.
pub(super) type ScanChunk = (u32, [f32; LANES], [f32; LANES], u32);

/// The lifted squared distances from the point `x` (and, with `ENDS`, from `x + v`, in
/// the image of `x`) to every segment of `B`, eight segments per vector: per chunk
/// computed `(chunk, e(x), e(x + v), crossing)` pushed to `out` (emptied first), where bit `l` of `crossing` marks a segment
/// that crosses the seam relative to `x` (its lifted `e(x)` is then only an upper bound
/// of the periodic distance). Returns the smallest `e(x)`, the smallest `e(x + v)` and
/// the smallest `max(e(x), e(x + v))` over the chunks computed.
///
/// Chunks far from the segment `[x, x + v]` are skipped: every chunk of `B` has a box
/// (`boxes32`, see [`CurveLayout`](super::CurveLayout)), and the gap between it and the
/// box of `[x, x + v]` (per coordinate, periodic) bounds from below the distance from
/// any point of the segment to any point of the chunk's segments. A chunk is skipped
/// when its `f32` squared gap exceeds `skip.threshold(hint)`, where `hint` is an `f32`
/// test value already known of some segment of `B` (`max(e(x), e(x + v))` with `ENDS`,
/// else `e(x)`, or `+∞`): nothing in such a chunk can matter (see [`Skip`]), and it
/// is left out of `out`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn segment_scan<S: Lanes, const N: usize, const ENDS: bool>(
    s: S,
    (x, v): (&[f32; N], &[f32; N]),
    (coords32, dirs32, inv32, boxes32): (&[f32], &[f32], &[f32], &[f32]),
    chunks: usize,
    (wraps, half): (&Wraps<S, N>, &[S::V; N]),
    (skip, hint): (Skip, f32),
    (lower, gaps_ready): (&mut Vec<f32>, bool),
    out: &mut Vec<ScanChunk>,
) -> (f32, f32, f32) {
    let (points, _) = coords32.as_chunks::<LANES>();
    let (dirs, _) = dirs32.as_chunks::<LANES>();
    let (inverse, _) = inv32.as_chunks::<LANES>();
    let points: [&[[f32; LANES]]; N] = each(&[], |k| &points[k * chunks..(k + 1) * chunks]);
    let dirs: [&[[f32; LANES]]; N] = each(&[], |k| &dirs[k * chunks..(k + 1) * chunks]);
    let inverse = &inverse[..chunks];
    out.clear();
    if !gaps_ready {
        box_gaps::<S, N>(s, (x, v), boxes32, chunks, wraps, lower);
    }
    let xs: [S::V; N] = each(s.splat(0.0), |k| s.splat(x[k]));
    let vs: [S::V; N] = each(s.splat(0.0), |k| s.splat(v[k]));
    let chunk = (&points, &dirs, inverse);
    let infinity = s.splat(f32::INFINITY);
    let (mut min0, mut min1, mut min_max) = (infinity, infinity, infinity);
    let limit = s.splat(skip.threshold(hint));
    let (gaps, _) = lower.as_chunks::<LANES>();
    for (g, gap) in gaps.iter().enumerate() {
        let mut kept = s.le(s.load(gap), limit);
        while kept != 0 {
            let q = g * LANES + kept.trailing_zeros() as usize;
            kept &= kept - 1;
            if q >= chunks {
                break;
            }
            let (e0, e1, crossing) =
                scan_chunk::<S, N, ENDS>(s, (&xs, &vs), chunk, q, (wraps, half));
            out.push((q as u32, s.array(e0), s.array(e1), crossing));
            min0 = s.min(e0, min0);
            if ENDS {
                min1 = s.min(e1, min1);
                min_max = s.min(s.max(e0, e1), min_max);
            }
        }
    }
    (s.hmin(min0), s.hmin(min1), s.hmin(min_max))
}

/// Whether one chunk of `B` settles the segment `[x, x + v]` for the `f32` threshold
/// `theta`: the chunk whose box is nearest to the segment's box (the box gaps are left
/// in `lower`, as [`segment_scan`] leaves them) holds a segment with both ends' lifted
/// `f32` squared distances at most `theta` (convexity, see the module docs). A cheap
/// first try before a whole [`segment_scan`] for a segment the windows left open: its
/// witness usually lies just beyond the window. A negative `theta` (no `f32` filter)
/// settles nothing and leaves `lower` as it was.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn segment_probe<S: Lanes, const N: usize>(
    s: S,
    (x, v): (&[f32; N], &[f32; N]),
    (coords32, dirs32, inv32, boxes32): (&[f32], &[f32], &[f32], &[f32]),
    chunks: usize,
    (wraps, half): (&Wraps<S, N>, &[S::V; N]),
    lower: &mut Vec<f32>,
    theta: f32,
) -> bool {
    if theta < 0.0 {
        return false;
    }
    box_gaps::<S, N>(s, (x, v), boxes32, chunks, wraps, lower);
    let best = nearest_box(s, lower);
    let (points, _) = coords32.as_chunks::<LANES>();
    let (dirs, _) = dirs32.as_chunks::<LANES>();
    let (inverse, _) = inv32.as_chunks::<LANES>();
    let points: [&[[f32; LANES]]; N] = each(&[], |k| &points[k * chunks..(k + 1) * chunks]);
    let dirs: [&[[f32; LANES]]; N] = each(&[], |k| &dirs[k * chunks..(k + 1) * chunks]);
    let xs: [S::V; N] = each(s.splat(0.0), |k| s.splat(x[k]));
    let vs: [S::V; N] = each(s.splat(0.0), |k| s.splat(v[k]));
    let (e0, e1, _) = scan_chunk::<S, N, true>(
        s,
        (&xs, &vs),
        (&points, &dirs, &inverse[..chunks]),
        best,
        (wraps, half),
    );
    s.le(s.max(e0, e1), s.splat(theta)) != 0
}

/// The chunk with the smallest box gap in `lower` (as [`box_gaps`] leaves it; the lowest
/// index among ties), found without a branch per chunk.
#[inline(always)]
fn nearest_box<S: Lanes>(s: S, lower: &[f32]) -> usize {
    let (gaps, _) = lower.as_chunks::<LANES>();
    let mut least = s.splat(f32::INFINITY);
    for gap in gaps {
        least = s.min(s.load(gap), least);
    }
    let least = s.splat(s.hmin(least));
    let mut base = 0;
    for gap in gaps {
        let hit = s.le(s.load(gap), least);
        if hit != 0 {
            return base + hit.trailing_zeros() as usize;
        }
        base += LANES;
    }
    0
}

/// Per chunk of `B` (`lower[q]`), the `f32` squared gap between the box of the segment
/// `[x, x + v]` (its middle, half of `|v_n|` on either side) and the chunk's box in
/// `boxes32` (`[n][chunk]` centres, then `[n][chunk]` half-widths, eight chunks per
/// vector): `Σ_n max(fold(m_n − c_n) − w_n − |v_n|/2, 0)²`, and `+∞` past the last chunk.
#[inline(always)]
fn box_gaps<S: Lanes, const N: usize>(
    s: S,
    (x, v): (&[f32; N], &[f32; N]),
    boxes32: &[f32],
    chunks: usize,
    wraps: &Wraps<S, N>,
    lower: &mut Vec<f32>,
) {
    let groups = chunks.div_ceil(LANES);
    let (rows, _) = boxes32.as_chunks::<LANES>();
    lower.resize(groups * LANES, 0.0);
    let (gaps, _) = lower.as_chunks_mut::<LANES>();
    let mid: [S::V; N] = each(s.splat(0.0), |k| s.splat(x[k] + 0.5 * v[k]));
    let spread: [S::V; N] = each(s.splat(0.0), |k| s.splat(0.5 * v[k].abs()));
    let zero = s.splat(0.0);
    for (g, gap) in gaps.iter_mut().enumerate().take(groups) {
        let mut acc = zero;
        for k in 0..N {
            let center = s.load(&rows[k * groups + g]);
            let width = s.load(&rows[(N + k) * groups + g]);
            let d = s.fold(s.sub(mid[k], center), wraps.fold[k]);
            let d = s.max(s.sub(s.sub(d, width), spread[k]), zero);
            acc = s.mul_add(d, d, acc);
        }
        *gap = s.array(acc);
    }
    // The padding lanes past the last chunk: never near, never kept.
    lower[chunks..].fill(f32::INFINITY);
}

/// Per coordinate, the chunks of eight starts and of eight directions of the segments
/// of `B`, and the chunks of their `1 / |v|²`.
type ChunkRows<'a, const N: usize> = (
    &'a [&'a [[f32; LANES]]; N],
    &'a [&'a [[f32; LANES]]; N],
    &'a [[f32; LANES]],
);

/// The lifted squared distances `(e(x), e(x + v), crossing)` of the eight segments of
/// chunk `q` (see [`segment_scan`]).
#[inline(always)]
fn scan_chunk<S: Lanes, const N: usize, const ENDS: bool>(
    s: S,
    (xs, vs): (&[S::V; N], &[S::V; N]),
    (points, dirs, inverse): ChunkRows<'_, N>,
    q: usize,
    (wraps, half): (&Wraps<S, N>, &[S::V; N]),
) -> (S::V, S::V, u32) {
    let (mut w0, mut w1, mut dir) = ([s.splat(0.0); N], [s.splat(0.0); N], [s.splat(0.0); N]);
    let (mut dot0, mut dot1) = (s.splat(0.0), s.splat(0.0));
    let mut crossing = 0u32;
    for k in 0..N {
        dir[k] = s.load(&dirs[k][q]);
        let u = s.sub(xs[k], s.load(&points[k][q]));
        w0[k] = s.swrap(u, wraps.period[k], wraps.inverse[k]);
        crossing |= s.gt(s.abs(s.sub(w0[k], dir[k])), half[k]);
        dot0 = s.mul_add(w0[k], dir[k], dot0);
        if ENDS {
            w1[k] = s.add(w0[k], vs[k]);
            dot1 = s.mul_add(w1[k], dir[k], dot1);
        }
    }
    let (zero, one) = (s.splat(0.0), s.splat(1.0));
    let inv = s.load(&inverse[q]);
    let t0 = s.max(s.min(s.mul(dot0, inv), one), zero);
    let t1 = s.max(s.min(s.mul(dot1, inv), one), zero);
    let (mut e0, mut e1) = (zero, zero);
    for k in 0..N {
        let r0 = s.neg_mul_add(t0, dir[k], w0[k]);
        e0 = s.mul_add(r0, r0, e0);
        if ENDS {
            let r1 = s.neg_mul_add(t1, dir[k], w1[k]);
            e1 = s.mul_add(r1, r1, e1);
        }
    }
    (e0, e1, crossing)
}

/// When a [`segment_scan`] skips a chunk of `B`: the chunks farther than
/// `upper(m) + extra` from every point of the segment `[x, x + v]`, where `m` is the
/// `f32` test value of some segment of `B` and
/// `upper(m) = √(m·(1 + rel))·(1 + 10⁻¹²) + δ_segment` bounds the exact distance whose
/// lifted `f32` square is `m` (see [`FilterBounds`](crate::metric::prepared::FilterBounds)).
///
/// Such a chunk holds no segment nearest to `x` (that one is within `upper(m)`), nor one
/// within `extra` more; the smallest test values of the scan stay upper bounds of the
/// exact ones (over fewer segments). The box gap is an `f32` value whose error is below `margin`
/// (`2(δ_segment + δ_point)`: rounded inputs, the middle and spread of the segment, the
/// fold, two subtractions) and whose sum of squares is within `rel`; the threshold
/// adds both, with a relative `10⁻⁶` to spare.
#[derive(Debug, Clone, Copy)]
pub(super) struct Skip {
    pub rel: f64,
    pub segment_delta: f64,
    pub margin: f64,
    pub extra: f64,
}

impl Skip {
    /// The largest `f32` squared box gap of a chunk that is not skipped, given the
    /// smallest test value `m` so far.
    #[inline(always)]
    fn threshold(self, m: f32) -> f32 {
        let upper = (f64::from(m) * (1.0 + self.rel)).sqrt() * (1.0 + 1e-12) + self.segment_delta;
        self.beyond(upper)
    }

    /// The largest `f32` squared box gap of a chunk that may hold a point within
    /// `distance + extra` of the segment: a larger gap proves every point of the chunk's
    /// segments farther.
    #[inline(always)]
    pub(super) fn beyond(self, distance: f64) -> f32 {
        let reach = (distance + self.extra + self.margin) * (1.0 + 1e-6);
        f32_at_least(reach * reach * (1.0 + self.rel))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metric::kernel::Portable;

    #[test]
    fn the_nearest_box_is_the_first_smallest_gap_in_any_group() {
        let mut lower = vec![f32::INFINITY; 2 * LANES];
        lower[..5].copy_from_slice(&[3.0, 1.5, 2.0, 1.5, 4.0]);
        assert_eq!(nearest_box(Portable, &lower), 1);
        lower[LANES + 2] = 0.5;
        lower[LANES + 4] = 0.5;
        assert_eq!(nearest_box(Portable, &lower), LANES + 2);
        lower[0] = 0.5;
        assert_eq!(nearest_box(Portable, &lower), 0);
    }
}
