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

use crate::metric::kernel::{Lanes, RING_WINDOW};
use crate::metric::prepared::LANES;

/// Per-coordinate constants of the lifted differences, as vectors.
#[derive(Clone, Copy)]
pub(super) struct Wraps<S: Lanes, const N: usize> {
    /// The period (`0` when not wrapped): `h(u) = u − T·round(u/T)`.
    pub period: [S::V; N],
    /// `1/T` (`0` when not wrapped).
    pub inverse: [S::V; N],
}

impl<S: Lanes, const N: usize> Wraps<S, N> {
    #[inline(always)]
    pub(super) fn new(s: S, period: &[f64; N]) -> Self {
        Self {
            period: std::array::from_fn(|k| {
                s.splat(if period[k].is_finite() {
                    period[k] as f32
                } else {
                    0.0
                })
            }),
            inverse: std::array::from_fn(|k| {
                s.splat(if period[k].is_finite() {
                    (1.0 / period[k]) as f32
                } else {
                    0.0
                })
            }),
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
        Self {
            start: std::array::from_fn(|k| s.load(&points[k * chunks + alpha])),
            dir: std::array::from_fn(|k| s.load(&dirs[k * chunks + alpha])),
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
    for &r in &RING_WINDOW[..length] {
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

/// The lifted squared distances from the point `x` (and, with `ENDS`, from `x + v`, in
/// the image of `x`) to every segment of `B`, eight segments per vector: per chunk
/// `(e(x), e(x + v), crossing)` into `out`, where bit `l` of `crossing` marks a segment
/// that crosses the seam relative to `x` (its lifted `e(x)` is then only an upper bound
/// of the periodic distance). Returns the smallest `e(x)`, the smallest `e(x + v)` and
/// the smallest `max(e(x), e(x + v))` over all segments.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn segment_scan<S: Lanes, const N: usize, const ENDS: bool>(
    s: S,
    (x, v): (&[f32; N], &[f32; N]),
    (coords32, dirs32, inv32): (&[f32], &[f32], &[f32]),
    chunks: usize,
    wraps: &Wraps<S, N>,
    half: &[S::V; N],
    out: &mut [([f32; LANES], [f32; LANES], u32)],
) -> (f32, f32, f32) {
    let (points, _) = coords32.as_chunks::<LANES>();
    let (dirs, _) = dirs32.as_chunks::<LANES>();
    let (inverse, _) = inv32.as_chunks::<LANES>();
    let points: [&[[f32; LANES]]; N] =
        std::array::from_fn(|k| &points[k * chunks..(k + 1) * chunks]);
    let dirs: [&[[f32; LANES]]; N] = std::array::from_fn(|k| &dirs[k * chunks..(k + 1) * chunks]);
    let inverse = &inverse[..chunks];
    let out = &mut out[..chunks];
    let xs: [S::V; N] = std::array::from_fn(|k| s.splat(x[k]));
    let vs: [S::V; N] = std::array::from_fn(|k| s.splat(v[k]));
    let (zero, one) = (s.splat(0.0), s.splat(1.0));
    let infinity = s.splat(f32::INFINITY);
    let (mut min0, mut min1, mut min_max) = (infinity, infinity, infinity);
    for q in 0..chunks {
        let mut w0 = [zero; N];
        let mut w1 = [zero; N];
        let mut dir = [zero; N];
        let (mut dot0, mut dot1) = (zero, zero);
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
        min0 = s.min(e0, min0);
        if ENDS {
            min1 = s.min(e1, min1);
            min_max = s.min(s.max(e0, e1), min_max);
        }
        out[q] = (s.array(e0), s.array(e1), crossing);
    }
    (s.hmin(min0), s.hmin(min1), s.hmin(min_max))
}
