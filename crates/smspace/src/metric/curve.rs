//! The `curve` metric: the Hausdorff distance between kernel sets read as polylines.
//!
//! # Definitions
//!
//! A set of `P` points `x_0 … x_{P−1}` is a **closed** polyline (`P` segments, the last
//! one back to `x_0`: the loops of the paper's arm) or an **open** one (`P − 1`
//! segments: the segments of the redundant toy, sets that end on a joint limit).
//! Segment `i` runs from `x_i` to `x_i + v_i` with `v_i = h(x_{i+1} − x_i)` (every
//! coordinate difference wrapped into `[−π, π]`; with [`Period::None`](super::Period)
//! `v_i = x_{i+1} − x_i`). Its points are `s_i(t) = x_i + t·v_i`, `t ∈ [0, 1]`.
//!
//! The distance from a point `a` to a segment is the minimum over the segment of the
//! periodic point metric `g` of [`super`]:
//!
//! ```text
//! δ(a, s_i) = min_{t∈[0,1]} g(a, x_i + t v_i),    g(a, b)² = Σ_n h(a_n − b_n)²
//! ```
//!
//! computed exactly even when the segment crosses the torus' seam: with
//! `u = h(a − x_i)`, the function `f(t) = Σ_n h(u_n − t v_n)²` is a convex quadratic on
//! each piece of `[0, 1]` between the (at most `N`) values of `t` where some
//! `u_n − t v_n` crosses `±π`, and it is minimised on every piece in closed form. When
//! no coordinate crosses (`|u_n − v_n| ≤ π` for all `n`, almost always) there is one
//! piece and `δ² = |u − t* v|²` with `t* = clamp(u·v / |v|², 0, 1)`.
//!
//! The directed distance and the metric are taken over the **continuous** polylines:
//!
//! ```text
//! h(A, B) = max_{a∈A} min_{b∈B} g(a, b) = max_{a∈A} d_B(a),   ρ_c(A, B) = max(h(A, B), h(B, A)).
//! ```
//!
//! # Algorithm and bound
//!
//! `d_B(a) = min_j δ(a, s_j)` is evaluated exactly at any point. The maximum of `d_B`
//! over a segment of `A` is bracketed:
//!
//! * from below by `d_B` at the points evaluated (vertices first): the running maximum
//!   `c` is a lower bound of `h(A, B)`;
//! * from above, on a piece `[t₀, t₁]` of a segment `a(t) = a_i + t·v_i` of `A`, by two
//!   bounds. For any segment `s_j` of `B` and one fixed periodic image of it,
//!   `d_B(a(t)) ≤ E_j(t) = |ã(t) − s̃_j|` (Euclidean distance between lifts), and `E_j`
//!   is convex in `t` (the distance from a moving point to a convex set), so it lies
//!   below its chord: `d_B(a(t)) ≤ min_j chord_j(t)`, whose maximum over the piece is
//!   found exactly (the upper envelope of the lower envelope of a few lines). And
//!   `d_B` is 1-Lipschitz along the segment (`g` is at most the length travelled), so
//!   `max d_B ≤ (d_B(a(t₀)) + d_B(a(t₁)) + |v_i|·(t₁ − t₀)) / 2`.
//!
//! A piece whose upper bound is at most `c +` [`CURVE_TOLERANCE`] cannot raise the
//! answer by more than the tolerance and is dropped; otherwise `d_B` is evaluated at
//! the bound's maximiser (kept within the middle of the piece) and both halves are
//! examined. The Lipschitz bound guarantees termination (a piece shorter than twice the
//! tolerance is always dropped); the chord bound, tight to second order, makes it fast.
//! The result is the maximum of exactly evaluated distances, hence at most the true
//! `h(A, B)` and at least `h(A, B) − 10⁻¹⁰`.
//!
//! Most segments are settled without refinement: the vertices are processed as in the
//! point metric (eight at a time, far blocks first, the nearest segment of `B`
//! remembered), and a segment `[a_i, a_{i+1}]` of `A` is settled as soon as one segment
//! `s_j` (the one nearest to either end) has `E_j ≤ c` at both ends (convexity). Only
//! the few segments near the maximiser go through the refinement. Pairs are always
//! evaluated in the order (smaller index, larger index), so the value does not depend
//! on which of the two sets is the query.

use super::kernel::{around, Scratch};
use super::prepared::{fold, wrap, PreparedSets, SetRef, BOUND_MARGIN, LANES};

/// Absolute accuracy of the `curve` metric: every value is within this much below the
/// exact Hausdorff distance between the polylines (and never above it, up to rounding).
pub const CURVE_TOLERANCE: f64 = 1e-10;

/// Deepest refinement of one segment; the Lipschitz bound ends any refinement long
/// before (a segment of length `π√16` is below the tolerance after 37 halvings, and a
/// split removes at least a fifth of a piece).
const MAX_DEPTH: usize = 200;

pub use crate::kernel::Closure;

/// `u` brought into `[−T/2, T/2]` for `|u| < 3T/2`; unchanged without a period.
#[inline(always)]
pub(crate) fn swrap(u: f64, period: f64, half: f64) -> f64 {
    let u = if u > half { u - period } else { u };
    if u < -half {
        u + period
    } else {
        u
    }
}

/// The segments of every set, laid out for the curve kernels. Built by
/// [`PreparedSets::new`] when the sets come with their [`Closure`].
#[derive(Debug, Clone)]
pub(crate) struct CurveLayout {
    /// Segments of every set (`P` closed, `P − 1` open).
    pub segments: Vec<u32>,
    /// Closure of every set.
    pub closure: Vec<Closure>,
    /// `[set][segment][n]`, `points_pad × dims_pad` per set: `v_i`.
    pub dirs: Vec<f64>,
    /// `[set][n][segment]`, `dims_pad × points_pad` per set: `v_i` coordinate by
    /// coordinate (lanes over segments).
    pub dirs_soa: Vec<f64>,
    /// `[set][segment]`: `1 / |v_i|²` (0 for a segment of length 0).
    pub inv_len2: Vec<f64>,
    /// `[set][segment]`: `|v_i|`.
    pub lengths: Vec<f64>,
    /// `[set][chunk][n]`: centres of the boxes around the segments of every chunk of
    /// eight segments.
    pub centers: Vec<f64>,
    /// `[set][chunk][n]`: half-widths of those boxes (periodic intervals, with margin).
    pub widths: Vec<f64>,
}

/// One set's segments, as the kernels see them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CurveRef<'a> {
    pub set: SetRef<'a>,
    pub segments: usize,
    pub dirs: &'a [f64],
    pub dirs_soa: &'a [f64],
    pub inv_len2: &'a [f64],
    pub lengths: &'a [f64],
    pub centers: &'a [f64],
    pub widths: &'a [f64],
}

impl CurveLayout {
    /// Builds the segments of the prepared (wrapped, padded) points.
    #[allow(
        clippy::too_many_arguments,
        reason = "the prepared layout's shape, passed while it is built"
    )]
    pub(crate) fn new(
        coords: &[f64],
        sets: usize,
        points: usize,
        points_pad: usize,
        dims: usize,
        dims_pad: usize,
        period: f64,
        closure: &[Closure],
    ) -> Self {
        let half = 0.5 * period;
        let chunks = points_pad / LANES;
        let per = dims_pad * points_pad;
        let mut segments = Vec::with_capacity(sets);
        let mut dirs = vec![0.0; sets * per];
        let mut dirs_soa = vec![0.0; sets * per];
        let mut inv_len2 = vec![0.0; sets * points_pad];
        let mut lengths = vec![0.0; sets * points_pad];
        let mut centers = vec![0.0; sets * chunks * dims_pad];
        let mut widths = vec![0.0; sets * chunks * dims_pad];
        for s in 0..sets {
            let block = &coords[s * per..(s + 1) * per];
            let count = match closure[s] {
                Closure::Closed => points,
                Closure::Open => points - 1,
            };
            segments.push(count as u32);
            for i in 0..count {
                let next = if i + 1 == points { 0 } else { i + 1 };
                let mut len2 = 0.0;
                for k in 0..dims {
                    let v = swrap(
                        block[k * points_pad + next] - block[k * points_pad + i],
                        period,
                        half,
                    );
                    dirs[s * per + i * dims_pad + k] = v;
                    dirs_soa[s * per + k * points_pad + i] = v;
                    len2 += v * v;
                }
                inv_len2[s * points_pad + i] = if len2 > 0.0 { 1.0 / len2 } else { 0.0 };
                lengths[s * points_pad + i] = len2.sqrt();
            }
            for q in 0..chunks {
                let first = q * LANES;
                let last = (first + LANES).min(count);
                let at = (s * chunks + q) * dims_pad;
                if first >= last {
                    // No segment in this chunk (an open set with P = 8k + 1): a box that
                    // no bound can reach is never used, since the loops stop at `count`.
                    widths[at..at + dims_pad].fill(0.0);
                    continue;
                }
                for k in 0..dims_pad {
                    // The lifted path through the chunk's segments: every point of
                    // them lies within [lo, hi], so within `(hi − lo)/2` of the middle
                    // (a periodic distance is at most the lifted one).
                    let mut y = block[k * points_pad + first];
                    let (mut lo, mut hi) = (y, y);
                    for i in first..last {
                        y += dirs[s * per + i * dims_pad + k];
                        lo = lo.min(y);
                        hi = hi.max(y);
                    }
                    centers[at + k] = wrap(0.5 * (lo + hi), period);
                    widths[at + k] = 0.5 * (hi - lo) * (1.0 + BOUND_MARGIN) + 1e-13;
                }
            }
        }
        Self {
            segments,
            closure: closure.to_vec(),
            dirs,
            dirs_soa,
            inv_len2,
            lengths,
            centers,
            widths,
        }
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> u64 {
        ((self.dirs.len() + self.dirs_soa.len()) * 8
            + (self.inv_len2.len() + self.lengths.len()) * 8
            + (self.centers.len() + self.widths.len()) * 8
            + self.segments.len() * 5) as u64
    }

    /// Bytes a layout of this shape holds.
    pub(crate) fn estimate_bytes(sets: usize, points_pad: usize, dims_pad: usize) -> u64 {
        let chunks = points_pad / LANES;
        (sets as u64)
            * ((2 * points_pad * dims_pad + 2 * points_pad + 2 * chunks * dims_pad) * 8 + 5) as u64
    }
}

impl PreparedSets {
    pub(crate) fn curve(&self, s: usize) -> CurveRef<'_> {
        let layout = self
            .curves()
            .expect("the curve metric checks that the closures were given");
        let dims_pad = self.dims_pad();
        let points_pad = self.points_pad();
        let per = dims_pad * points_pad;
        let chunks = self.chunks();
        CurveRef {
            set: self.set(s),
            segments: layout.segments[s] as usize,
            dirs: &layout.dirs[s * per..(s + 1) * per],
            dirs_soa: &layout.dirs_soa[s * per..(s + 1) * per],
            inv_len2: &layout.inv_len2[s * points_pad..(s + 1) * points_pad],
            lengths: &layout.lengths[s * points_pad..(s + 1) * points_pad],
            centers: &layout.centers[s * chunks * dims_pad..(s + 1) * chunks * dims_pad],
            widths: &layout.widths[s * chunks * dims_pad..(s + 1) * chunks * dims_pad],
        }
    }
}

/// [`segment_distance2`] for `N` coordinates with the fast single-image path inline.
#[inline(always)]
fn segment_distance2_n<const N: usize>(
    a: &[f64; N],
    b: &[f64; N],
    v: &[f64; N],
    inv_len2: f64,
    period: f64,
) -> f64 {
    let half = 0.5 * period;
    let mut u = [0.0; N];
    let mut dot = 0.0;
    let mut crosses = false;
    for k in 0..N {
        u[k] = swrap(a[k] - b[k], period, half);
        dot += u[k] * v[k];
        crosses |= (u[k] - v[k]).abs() > half;
    }
    if crosses {
        return segment_distance2(a, b, v, inv_len2, period);
    }
    let t = (dot * inv_len2).clamp(0.0, 1.0);
    let mut d2 = 0.0;
    for k in 0..N {
        let w = u[k] - t * v[k];
        d2 += w * w;
    }
    d2
}

/// Exact `δ(a, s)²` from a point `a` (wrapped) to the segment from `b` (wrapped) along
/// `v`, under the periodic metric: the convex quadratic of every piece between the
/// values of `t` where some `u_n − t v_n` crosses `±T/2` (once per coordinate at most,
/// since `|v_n| ≤ T/2`), minimised in closed form (see the module docs). The kernels
/// take the single-piece path inline and call this only when a coordinate crosses.
pub(crate) fn segment_distance2(
    a: &[f64],
    b: &[f64],
    v: &[f64],
    inv_len2: f64,
    period: f64,
) -> f64 {
    let half = 0.5 * period;
    let u: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(x, y)| swrap(x - y, period, half))
        .collect();
    let mut cuts = vec![0.0, 1.0];
    for k in 0..u.len() {
        let end = u[k] - v[k];
        if end > half {
            cuts.push((u[k] - half) / v[k]);
        } else if end < -half {
            cuts.push((u[k] + half) / v[k]);
        }
    }
    cuts.sort_unstable_by(f64::total_cmp);
    let mut best = f64::INFINITY;
    for w in cuts.windows(2) {
        let (t0, t1) = (w[0].clamp(0.0, 1.0), w[1].clamp(0.0, 1.0));
        let mid = 0.5 * (t0 + t1);
        let mut dot = 0.0;
        for k in 0..u.len() {
            let at_mid = u[k] - mid * v[k];
            dot += (u[k] + (swrap(at_mid, period, half) - at_mid)) * v[k];
        }
        let t = (dot * inv_len2).clamp(t0, t1);
        let d2: f64 = (0..u.len())
            .map(|k| swrap(u[k] - t * v[k], period, half).powi(2))
            .sum();
        best = best.min(d2);
    }
    best
}

/// `|u − t* v|²` in one fixed image (`u` given relative to the segment's start), the
/// Euclidean distance between lifts: an upper bound of the periodic `δ²`.
#[inline(always)]
fn lifted_distance2<const N: usize>(u: &[f64; N], v: &[f64; N], inv_len2: f64) -> f64 {
    let mut dot = 0.0;
    for k in 0..N {
        dot += u[k] * v[k];
    }
    let t = (dot * inv_len2).clamp(0.0, 1.0);
    let mut d2 = 0.0;
    for k in 0..N {
        let w = u[k] - t * v[k];
        d2 += w * w;
    }
    d2
}

#[inline(always)]
fn load<const N: usize>(data: &[f64], at: usize) -> [f64; N] {
    let mut x = [0.0; N];
    x.copy_from_slice(&data[at * N..(at + 1) * N]);
    x
}

/// Per-lane `δ²` from eight points (lanes) to segment `j` of `b`, exact: the lifted
/// distance, recomputed piece by piece for the (rare) lanes whose segment crosses the
/// seam relative to them.
#[inline(always)]
fn segment_lanes<const N: usize>(
    a: &[[f64; LANES]; N],
    b: CurveRef<'_>,
    j: usize,
    period: f64,
) -> [f64; LANES] {
    let half = 0.5 * period;
    let start = load::<N>(b.set.points, j);
    let v = load::<N>(b.dirs, j);
    let inv = b.inv_len2[j];
    let mut u = [[0.0; LANES]; N];
    let mut dot = [0.0; LANES];
    let mut worst = [0.0f64; LANES];
    for k in 0..N {
        for l in 0..LANES {
            let w = swrap(a[k][l] - start[k], period, half);
            u[k][l] = w;
            dot[l] = w.mul_add(v[k], dot[l]);
            let e = (w - v[k]).abs();
            worst[l] = if e > worst[l] { e } else { worst[l] };
        }
    }
    let mut t = [0.0; LANES];
    for l in 0..LANES {
        t[l] = (dot[l] * inv).clamp(0.0, 1.0);
    }
    let mut d2 = [0.0; LANES];
    for k in 0..N {
        for l in 0..LANES {
            let w = u[k][l] - t[l] * v[k];
            d2[l] = w.mul_add(w, d2[l]);
        }
    }
    let mut crosses = false;
    for l in 0..LANES {
        crosses |= worst[l] > half;
    }
    if crosses {
        for l in 0..LANES {
            if worst[l] > half {
                let mut x = [0.0; N];
                for k in 0..N {
                    x[k] = a[k][l];
                }
                d2[l] = segment_distance2(&x, &start, &v, inv, period);
            }
        }
    }
    d2
}

/// Window of `B`'s segments around `start`: per-lane smallest `δ²` and its segment.
/// Stops once every lane is `≤ settle`.
#[inline(always)]
fn window<const N: usize>(
    a: &[[f64; LANES]; N],
    b: CurveRef<'_>,
    period: f64,
    start: usize,
    settle: f64,
) -> ([f64; LANES], [u32; LANES], bool) {
    let mut best = [f64::INFINITY; LANES];
    let mut arg = [0u32; LANES];
    for t in 0..9.min(b.segments) {
        let j = around(start, t, b.segments);
        let d = segment_lanes(a, b, j, period);
        for l in 0..LANES {
            let closer = d[l] < best[l];
            best[l] = if closer { d[l] } else { best[l] };
            arg[l] = if closer { j as u32 } else { arg[l] };
        }
        let mut settled = true;
        for l in 0..LANES {
            settled &= best[l] <= settle;
        }
        if settled {
            return (best, arg, true);
        }
    }
    (best, arg, false)
}

/// Lowers `best` to the exact `d_B²` of every lane still `> settle`: the chunks of
/// `B`'s segments whose box may hold a closer point are scanned.
#[inline(always)]
fn refine_lanes<const N: usize>(
    a: &[[f64; LANES]; N],
    best: &mut [f64; LANES],
    arg: &mut [u32; LANES],
    settle: f64,
    b: CurveRef<'_>,
    period: f64,
    first_chunk: usize,
) {
    let chunks = b.segments.div_ceil(LANES);
    let shrink = 1.0 - 4.0 * BOUND_MARGIN;
    for t in 0..chunks {
        let q = around(first_chunk, t, chunks);
        let mut open = false;
        for l in 0..LANES {
            open |= best[l] > settle;
        }
        if !open {
            break;
        }
        let center = load::<N>(b.centers, q);
        let width = load::<N>(b.widths, q);
        let mut lower = [0.0; LANES];
        for k in 0..N {
            for l in 0..LANES {
                let gap = fold(a[k][l] - center[k], period) - width[k];
                let gap = if gap > 0.0 { gap } else { 0.0 };
                lower[l] += gap * gap;
            }
        }
        let mut useful = false;
        for l in 0..LANES {
            useful |= best[l] > settle && lower[l] * shrink < best[l];
        }
        if !useful {
            continue;
        }
        for j in q * LANES..((q + 1) * LANES).min(b.segments) {
            let d = segment_lanes(a, b, j, period);
            for l in 0..LANES {
                let closer = d[l] < best[l];
                best[l] = if closer { d[l] } else { best[l] };
                arg[l] = if closer { j as u32 } else { arg[l] };
            }
        }
    }
}

/// Exact `d_B(x)²` at one (wrapped) point and the segment where it is reached,
/// scanning outward from segment `hint`.
fn nearest<const N: usize>(
    x: &[f64; N],
    b: CurveRef<'_>,
    period: f64,
    hint: usize,
) -> (f64, usize) {
    let mut best = f64::INFINITY;
    let mut arg = hint;
    let segments = b.segments;
    for t in 0..9.min(segments) {
        let j = around(hint, t, segments);
        let d = segment_distance2_n::<N>(
            x,
            &load::<N>(b.set.points, j),
            &load::<N>(b.dirs, j),
            b.inv_len2[j],
            period,
        );
        if d < best {
            best = d;
            arg = j;
        }
    }
    let chunks = segments.div_ceil(LANES);
    let shrink = 1.0 - 4.0 * BOUND_MARGIN;
    for q in 0..chunks {
        let center = load::<N>(b.centers, q);
        let width = load::<N>(b.widths, q);
        let mut lower = 0.0;
        for k in 0..N {
            let gap = fold(x[k] - center[k], period) - width[k];
            if gap > 0.0 {
                lower += gap * gap;
            }
        }
        if lower * shrink >= best {
            continue;
        }
        for j in q * LANES..((q + 1) * LANES).min(segments) {
            let d = segment_distance2_n::<N>(
                x,
                &load::<N>(b.set.points, j),
                &load::<N>(b.dirs, j),
                b.inv_len2[j],
                period,
            );
            if d < best || (d == best && j < arg) {
                best = d;
                arg = j;
            }
        }
    }
    (best, arg)
}

/// A piece `[t0, t1]` of a segment of `A` still to examine, with `d_B` (not squared)
/// and the nearest segment of `B` at both ends.
#[derive(Debug, Clone, Copy)]
struct Piece {
    t0: f64,
    t1: f64,
    d0: f64,
    d1: f64,
    j0: u32,
    j1: u32,
    depth: u32,
}

/// The largest value over `τ ∈ [0, 1]` of the lower envelope of the lines
/// `e0_k + (e1_k − e0_k)·τ`, and where it is reached.
fn envelope_max(lines: &[(f64, f64)]) -> (f64, f64) {
    let at = |tau: f64| {
        lines
            .iter()
            .fold(f64::INFINITY, |m, &(e0, e1)| m.min(e0 + (e1 - e0) * tau))
    };
    let mut best = (at(0.0), 0.0);
    let end = at(1.0);
    if end > best.0 {
        best = (end, 1.0);
    }
    for (x, &(a0, a1)) in lines.iter().enumerate() {
        for &(b0, b1) in &lines[x + 1..] {
            let slope = (a1 - a0) - (b1 - b0);
            if slope == 0.0 {
                continue;
            }
            let tau = (b0 - a0) / slope;
            if tau > 0.0 && tau < 1.0 {
                let value = at(tau);
                if value > best.0 {
                    best = (value, tau);
                }
            }
        }
    }
    best
}

/// The point `a_i + t·v_i` of segment `i` of `A`, wrapped.
#[inline(always)]
fn point_on<const N: usize>(a: CurveRef<'_>, i: usize, t: f64, period: f64) -> [f64; N] {
    let start = load::<N>(a.set.points, i);
    let v = load::<N>(a.dirs, i);
    let mut x = [0.0; N];
    for k in 0..N {
        x[k] = wrap(start[k] + t * v[k], period);
    }
    x
}

/// The chord bound on the piece `[t0, t1]` of segment `i` of `A`: the largest value of
/// the lower envelope of the chords of `E_j` (Euclidean distance to one image of
/// segment `j` of `B`, convex along the piece) over the segments `ends` of `B` and their
/// neighbours, each in the image nearest to the piece's first end; and where it is
/// reached (as a fraction of the piece).
#[inline(always)]
fn chord_bound<const N: usize>(
    a: CurveRef<'_>,
    b: CurveRef<'_>,
    i: usize,
    t0: f64,
    t1: f64,
    ends: [u32; 2],
    period: f64,
) -> (f64, f64) {
    let half = 0.5 * period;
    let start = load::<N>(a.set.points, i);
    let v = load::<N>(a.dirs, i);
    let span = t1 - t0;
    let mut x0 = [0.0; N];
    for k in 0..N {
        x0[k] = start[k] + t0 * v[k];
    }
    let mut candidates = [u32::MAX; 6];
    let mut count = 0;
    let s = b.segments as u32;
    for j in ends {
        for cand in [j, (j + 1) % s, (j + s - 1) % s] {
            if !candidates[..count].contains(&cand) {
                candidates[count] = cand;
                count += 1;
            }
        }
    }
    let mut lines = [(0.0, 0.0); 6];
    for (line, &j) in lines.iter_mut().zip(&candidates[..count]) {
        let j = j as usize;
        let bs = load::<N>(b.set.points, j);
        let w = load::<N>(b.dirs, j);
        let mut u0 = [0.0; N];
        let mut u1 = [0.0; N];
        for k in 0..N {
            u0[k] = swrap(x0[k] - bs[k], period, half);
            u1[k] = u0[k] + span * v[k];
        }
        *line = (
            lifted_distance2(&u0, &w, b.inv_len2[j]).sqrt(),
            lifted_distance2(&u1, &w, b.inv_len2[j]).sqrt(),
        );
    }
    envelope_max(&lines[..count])
}

/// Refines segment `i` of `A` (ends with exact `d_B`), raising `c` (not squared) to
/// within [`CURVE_TOLERANCE`] of `max_t d_B(a_i + t v_i)`. Returns `None` once
/// `c > abort`.
#[allow(clippy::too_many_arguments)]
fn refine_segment<const N: usize>(
    a: CurveRef<'_>,
    b: CurveRef<'_>,
    i: usize,
    ends: [(f64, u32); 2],
    period: f64,
    mut c: f64,
    abort: f64,
    stack: &mut Vec<Piece>,
) -> Option<f64> {
    let length = a.lengths[i];
    stack.clear();
    stack.push(Piece {
        t0: 0.0,
        t1: 1.0,
        d0: ends[0].0,
        d1: ends[1].0,
        j0: ends[0].1,
        j1: ends[1].1,
        depth: 0,
    });
    while let Some(piece) = stack.pop() {
        let span = piece.t1 - piece.t0;
        let lipschitz = 0.5 * (piece.d0 + piece.d1 + length * span);
        if lipschitz <= c + CURVE_TOLERANCE {
            continue;
        }
        let (chord, tau) =
            chord_bound::<N>(a, b, i, piece.t0, piece.t1, [piece.j0, piece.j1], period);
        // Rounding of the chord (a few ulps of values below 2π√N) is far below the
        // tolerance; the margin keeps the drop decision safe anyway.
        if chord.min(lipschitz) <= c + CURVE_TOLERANCE * 0.5 {
            continue;
        }
        if piece.depth as usize >= MAX_DEPTH {
            // Unreachable in exact arithmetic (the Lipschitz bound ends the recursion);
            // keep the bound so that the value never falls below the truth by more
            // than the tolerance.
            c = c.max(chord.min(lipschitz) - CURVE_TOLERANCE * 0.5);
            continue;
        }
        let tau = if (0.2..=0.8).contains(&tau) { tau } else { 0.5 };
        let t = piece.t0 + tau * span;
        let x = point_on::<N>(a, i, t, period);
        let hint = if tau < 0.5 { piece.j0 } else { piece.j1 } as usize;
        let (d2, j) = nearest::<N>(&x, b, period, hint);
        let d = d2.sqrt();
        if d > c {
            c = d;
            if c > abort {
                return None;
            }
        }
        let depth = piece.depth + 1;
        stack.push(Piece {
            t0: piece.t0,
            t1: t,
            d0: piece.d0,
            d1: d,
            j0: piece.j0,
            j1: j as u32,
            depth,
        });
        stack.push(Piece {
            t0: t,
            t1: piece.t1,
            d0: d,
            d1: piece.d1,
            j0: j as u32,
            j1: piece.j1,
            depth,
        });
    }
    Some(c)
}

/// Reusable buffers of the curve kernel.
#[derive(Debug, Default)]
pub(crate) struct CurveScratch {
    /// Per vertex of `A`: the segment of `B` that settled it (or its nearest).
    arg: Vec<u32>,
    /// Segments of `A` that the quick test did not settle.
    open: Vec<u32>,
    stack: Vec<Piece>,
}

/// `max(c², h(A, B)²)` (squared, the vertex pass) and then `h` over the continuous
/// polyline; `None` once the answer is proven `> abort` (not squared).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn directed<const N: usize>(
    a: CurveRef<'_>,
    b: CurveRef<'_>,
    period: f64,
    points: usize,
    points_pad: usize,
    (key, near): (&[f32], &[u32]),
    c: f64,
    abort: f64,
    order: &mut Vec<u64>,
    scratch: &mut CurveScratch,
) -> Option<f64> {
    let chunks = points_pad / LANES;
    let mut c2 = c * c;
    let abort2 = if abort.is_finite() {
        abort * abort
    } else {
        f64::INFINITY
    };
    super::kernel::far_first(key, chunks, order);
    scratch.arg.clear();
    scratch.arg.resize(points_pad, 0);
    // 1. Vertices, eight at a time, far blocks first: exact d_B for the lanes that
    //    raise c, the segment that settled them for the others.
    for &alpha in order.iter().take(chunks) {
        let alpha = alpha as usize;
        let block = super::kernel::load_block::<N>(a.set.coords, points_pad, alpha);
        let start = (near[alpha] as usize * LANES + LANES / 2).min(b.segments - 1);
        let (mut best, mut arg, settled) = if c2 > 0.0 {
            window(&block, b, period, start, c2)
        } else {
            ([f64::INFINITY; LANES], [0; LANES], false)
        };
        if !settled {
            refine_lanes(&block, &mut best, &mut arg, c2, b, period, start / LANES);
            for l in 0..LANES {
                if alpha * LANES + l < points && best[l] > c2 {
                    c2 = best[l];
                }
            }
            if c2 > abort2 {
                return None;
            }
        }
        scratch.arg[alpha * LANES..(alpha + 1) * LANES].copy_from_slice(&arg);
    }
    // 2. Segments, eight at a time: settled when one segment of B (nearest to either
    //    end) is within c of both ends in one image (the distance to it is convex).
    let half = 0.5 * period;
    scratch.open.clear();
    for block in 0..a.segments.div_ceil(LANES) {
        let p = super::kernel::load_block::<N>(a.set.coords, points_pad, block);
        let mut v = [[0.0; LANES]; N];
        for (k, lanes) in v.iter_mut().enumerate() {
            lanes.copy_from_slice(&a.dirs_soa[k * points_pad + block * LANES..][..LANES]);
        }
        let mut settled = [false; LANES];
        for side in 0..2 {
            let mut bs = [[0.0; LANES]; N];
            let mut w = [[0.0; LANES]; N];
            let mut inv = [0.0; LANES];
            for l in 0..LANES {
                let i = (block * LANES + l).min(a.segments - 1);
                let vertex = if side == 0 {
                    i
                } else if i + 1 == points {
                    0
                } else {
                    i + 1
                };
                let j = scratch.arg[vertex] as usize;
                let start = load::<N>(b.set.points, j);
                let dir = load::<N>(b.dirs, j);
                for k in 0..N {
                    bs[k][l] = start[k];
                    w[k][l] = dir[k];
                }
                inv[l] = b.inv_len2[j];
            }
            let mut dot0 = [0.0; LANES];
            let mut dot1 = [0.0; LANES];
            let mut u0 = [[0.0; LANES]; N];
            for k in 0..N {
                for l in 0..LANES {
                    let u = swrap(p[k][l] - bs[k][l], period, half);
                    u0[k][l] = u;
                    dot0[l] = u.mul_add(w[k][l], dot0[l]);
                    dot1[l] = (u + v[k][l]).mul_add(w[k][l], dot1[l]);
                }
            }
            let mut t0 = [0.0; LANES];
            let mut t1 = [0.0; LANES];
            for l in 0..LANES {
                t0[l] = (dot0[l] * inv[l]).clamp(0.0, 1.0);
                t1[l] = (dot1[l] * inv[l]).clamp(0.0, 1.0);
            }
            let mut e0 = [0.0; LANES];
            let mut e1 = [0.0; LANES];
            for k in 0..N {
                for l in 0..LANES {
                    let x = u0[k][l] - t0[l] * w[k][l];
                    e0[l] = x.mul_add(x, e0[l]);
                    let y = u0[k][l] + v[k][l] - t1[l] * w[k][l];
                    e1[l] = y.mul_add(y, e1[l]);
                }
            }
            let mut all = true;
            for l in 0..LANES {
                settled[l] |= e0[l] <= c2 && e1[l] <= c2;
                all &= settled[l];
            }
            if all {
                break;
            }
        }
        for (l, &done) in settled.iter().enumerate() {
            let i = block * LANES + l;
            if !done && i < a.segments {
                scratch.open.push(i as u32);
            }
        }
    }
    // 3. The rest by branch and bound on the chord and Lipschitz bounds.
    let mut c = c2.sqrt();
    for e in 0..scratch.open.len() {
        let i = scratch.open[e] as usize;
        let next = if i + 1 == points { 0 } else { i + 1 };
        // The chord envelope of the segments that settled either end and their
        // neighbours, without any exact search: settles most segments where the
        // nearest segment of B switches along the way.
        if chord_bound::<N>(
            a,
            b,
            i,
            0.0,
            1.0,
            [scratch.arg[i], scratch.arg[next]],
            period,
        )
        .0 <= c + 0.5 * CURVE_TOLERANCE
        {
            continue;
        }
        let p = load::<N>(a.set.points, i);
        let q = load::<N>(a.set.points, next);
        let (dp, jp) = nearest::<N>(&p, b, period, scratch.arg[i] as usize);
        let (dq, jq) = nearest::<N>(&q, b, period, scratch.arg[next] as usize);
        let ends = [(dp.sqrt(), jp as u32), (dq.sqrt(), jq as u32)];
        c = c.max(ends[0].0).max(ends[1].0);
        if c > abort {
            return None;
        }
        let mut stack = std::mem::take(&mut scratch.stack);
        let result = refine_segment::<N>(a, b, i, ends, period, c, abort, &mut stack);
        scratch.stack = stack;
        c = result?;
    }
    Some(c)
}

/// `ρ_c(set i, set j)`, or `None` once it is proven `> limit`, with the kernels
/// compiled for this CPU's best instruction set (chosen at run time).
#[inline(never)]
pub(crate) fn curve_pair(
    prepared: &PreparedSets,
    i: usize,
    j: usize,
    limit: f64,
    scratch: &mut Scratch,
) -> Option<f64> {
    pulp::Arch::new().dispatch(CurveJob {
        prepared,
        i,
        j,
        limit,
        scratch,
    })
}

struct CurveJob<'a> {
    prepared: &'a PreparedSets,
    i: usize,
    j: usize,
    limit: f64,
    scratch: &'a mut Scratch,
}

impl pulp::WithSimd for CurveJob<'_> {
    type Output = Option<f64>;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Option<f64> {
        let CurveJob {
            prepared,
            i,
            j,
            limit,
            scratch,
        } = self;
        match prepared.dims_pad() {
            2 => curve_hausdorff::<2>(prepared, i, j, limit, scratch),
            4 => curve_hausdorff::<4>(prepared, i, j, limit, scratch),
            8 => curve_hausdorff::<8>(prepared, i, j, limit, scratch),
            16 => curve_hausdorff::<16>(prepared, i, j, limit, scratch),
            _ => unreachable!("the curve metric is checked to have at most 16 coordinates"),
        }
    }
}

/// `ρ_c(set i, set j)`, or `None` once it is proven `> limit`. The pair is always
/// evaluated as (smaller index, larger index).
#[inline(always)]
fn curve_hausdorff<const N: usize>(
    prepared: &PreparedSets,
    i: usize,
    j: usize,
    limit: f64,
    scratch: &mut Scratch,
) -> Option<f64> {
    let (i, j) = if i <= j { (i, j) } else { (j, i) };
    let a = prepared.curve(i);
    let b = prepared.curve(j);
    let shape = super::kernel::Shape::of(prepared);
    super::kernel::center_table::<N>(a.set, b.set, shape, scratch);
    let (row_key, row_near, col_key, col_near, order, curve) = scratch.parts();
    let period = prepared.period_value();
    let (points, points_pad) = (prepared.points(), prepared.points_pad());
    let c = directed::<N>(
        a,
        b,
        period,
        points,
        points_pad,
        (row_key, row_near),
        0.0,
        limit,
        order,
        curve,
    )?;
    directed::<N>(
        b,
        a,
        period,
        points,
        points_pad,
        (col_key, col_near),
        c,
        limit,
        order,
        curve,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metric::{reference, Period};
    use ndarray::ArrayView1;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::PI;

    #[test]
    fn exact_segment_distance_equals_the_image_by_image_brute_force() {
        // Segments through the seam and points anywhere, 1 to 6 coordinates.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let period = 2.0 * PI;
        let mut crossing = 0;
        for trial in 0..4000 {
            let n = 1 + trial % 6;
            let start: Vec<f64> = (0..n).map(|_| rng.gen_range(-PI..PI)).collect();
            let end: Vec<f64> = (0..n).map(|_| rng.gen_range(-PI..PI)).collect();
            let a: Vec<f64> = (0..n).map(|_| rng.gen_range(-PI..PI)).collect();
            let v: Vec<f64> = start
                .iter()
                .zip(&end)
                .map(|(s, e)| swrap(e - s, period, PI))
                .collect();
            let len2: f64 = v.iter().map(|x| x * x).sum();
            let inv = if len2 > 0.0 { 1.0 / len2 } else { 0.0 };
            let fast = segment_distance2(&a, &start, &v, inv, period).sqrt();
            let slow = reference::segment_distance(
                ArrayView1::from(a.as_slice()),
                ArrayView1::from(start.as_slice()),
                ArrayView1::from(v.as_slice()),
                Period::TwoPi,
            );
            assert!(
                (fast - slow).abs() < 1e-12,
                "trial {trial}: {fast} vs {slow}"
            );
            let u: Vec<f64> = a
                .iter()
                .zip(&start)
                .map(|(x, y)| swrap(x - y, period, PI))
                .collect();
            crossing += usize::from(u.iter().zip(&v).any(|(x, y)| (x - y).abs() > PI));
        }
        // The piecewise path was exercised.
        assert!(crossing > 500, "{crossing}");
    }

    #[test]
    fn envelope_maximum_of_two_crossing_lines() {
        // 1 − τ and τ cross at τ = 1/2 with value 1/2; a flat line at 0.8 does not cut it.
        let (value, tau) = envelope_max(&[(1.0, 0.0), (0.0, 1.0), (0.8, 0.8)]);
        assert!((value - 0.5).abs() < 1e-15 && (tau - 0.5).abs() < 1e-15);
        let (value, tau) = envelope_max(&[(0.2, 0.9)]);
        assert!((value - 0.9).abs() < 1e-15 && tau == 1.0);
    }
}
