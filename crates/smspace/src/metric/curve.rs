//! The `curve` metric: the Hausdorff distance between kernel sets read as polylines.
//!
//! # Definitions
//!
//! A set of `P` points `x_0 … x_{P−1}` is a **closed** polyline (`P` segments, the last
//! one back to `x_0`: the loops of the paper's arm) or an **open** one (`P − 1`
//! segments: the segments of the redundant toy, sets that end on a joint limit).
//! Segment `i` runs from `x_i` to `x_i + v_i` with `v_i = h(x_{i+1} − x_i)` (every
//! coordinate difference `n` wrapped into `[−T_n/2, T_n/2]` with its own period `T_n`,
//! `[−π, π]` for the arm's joints, see [`Periods`](super::Periods); an unwrapped
//! coordinate, as everywhere with [`Period::None`](super::Period), is not changed).
//! Its points are `s_i(t) = x_i + t·v_i`, `t ∈ [0, 1]`. Where the sets come in pieces
//! ([`SetsView::with_pieces`](super::SetsView::with_pieces)), a segment whose ends lie in
//! different pieces is its first point alone (`v_i = 0`), and so is an extra segment
//! at the last point of an open set when that point is a piece of its own: every point
//! of the set lies on its polyline, and no segment joins two pieces.
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
//! `u_n − t v_n` crosses `±T_n/2`, and it is minimised on every piece in closed form. When
//! no coordinate crosses (`|u_n − v_n| ≤ T_n/2` for all `n`, almost always) there is one
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
//! `d_B(a) = min_j δ(a, s_j)` is evaluated exactly at any point. Both directions are
//! worked on together, with one running maximum `c` of exactly evaluated distances
//! (`d_B` on `A` or `d_A` on `B`): a lower bound of `ρ_c(A, B)`, so a segment whose
//! maximum is at most `c` cannot change the result, whichever direction it belongs to.
//!
//! 1. **Blocks**, eight segments of one set at a time, the blocks of both directions in
//!    one order, far from the other set first (by the distance from a block's centre
//!    to the other set's nearest chunk centre), so that `c` reaches its final value
//!    early whichever direction holds the maximum. For each block, `f32` windows
//!    around the other set's nearest chunk: a point `p` of `B` settles segment `i` when
//!    `max(|w|, |w + v_i|) ≤ c` with `w = h(a_i − p)` (`|w + t v_i|` is convex in `t`
//!    and at least `d_B(a_i + t v_i)`), trying every third point of `B` outward up to
//!    twelve points away; else a segment `s_j` of `B` settles it when both its ends
//!    are within `c` of one lifted image of `s_j` (the distance to a convex set is
//!    convex along a segment). A vertex the windows do not prove within `c` gets its
//!    exact `d_B` (largest window value first), which may raise `c`, from a scan of
//!    `B` for its segment that can settle the segment as well. The `f32` scans skip
//!    whole chunks of eight segments of `B` by their boxes (a chunk whose box is
//!    farther than an upper bound already found, plus what the later tests need,
//!    cannot change any result), and first try the one chunk whose box is nearest.
//!    The exact `d_B` of a point then computes the segments whose `f32` value is near
//!    the smallest; a segment that crosses the seam relative to the point (its lifted
//!    `f32` value is only an upper bound) is computed when lower bounds allow it: its
//!    chunk's box gap, then coordinate by coordinate the least periodic distance along
//!    the segment, which is at one end unless the coordinate passes 0
//!    (`δ² ≥ Σ_n min_t h(u_n − t v_n)²`).
//! 2. **Open segments**, of both directions, largest window value first, tested again
//!    with the final `c`: `d_B` is 1-Lipschitz along a segment (`g` is at most the
//!    length travelled), so `max_t d_B(a_i + t v_i) ≤ (d_B(a_i) + d_B(a_{i+1}) + |v_i|)/2`
//!    settles it when at most `c`; so does convexity with the segment of `B` nearest to
//!    an end whose exact value is known; else a scan of `B` (as above).
//! 3. **The envelope**, exact, for the few segments left (those near the maximiser).
//!    For one periodic image of `s_j`, `E_j(t) = |ã(t) − s̃_j|` (Euclidean distance
//!    between lifts) bounds `d_B(a(t))` from above; `E_j(t)² = |p + t q|²` piecewise in
//!    `t`, with at most three pieces (the foot `s*(t)` is linear in `t`, clamped to 0
//!    or 1), so the lower envelope `F = min E_j²` over a set of images is a minimum of
//!    convex quadratics. Between two points where the minimising image changes, `F` is
//!    one convex function, at most its end values; so the maximum of `F` is at
//!    `t = 0, 1` (the vertices, already in `c`) or at a root of `E_x² − E_y²` on a
//!    common piece: every such root where both exceed `c` is evaluated. The envelope is
//!    **lazy**: it starts with the images of the segments nearest to both ends (and up
//!    to three between them along `B`); `F ≥ d_B`, so when the exact `d_B` at the
//!    maximiser `t*` of `F` equals `F(t*)` (up to a relative `10⁻¹²` in the square)
//!    the segment's maximum is found; else the segment of `B` nearest to `a(t*)` joins
//!    the envelope and the maximum is taken again. After eight rounds, or more than 32
//!    images (never seen on the arm), the segment goes to a branch and bound: a piece
//!    whose chord or Lipschitz bound `(d_B(a(t₀)) + d_B(a(t₁)) + |v_i|(t₁ − t₀))/2` is at
//!    most `c +` [`CURVE_TOLERANCE`] is dropped, else split at the bound's maximiser.
//!
//! The result is the maximum of exactly evaluated distances: the exact `h(A, B)` up to
//! rounding (and within [`CURVE_TOLERANCE`] below it on the branch-and-bound path).
//! Pairs are always evaluated in the order (smaller index, larger index), so the value
//! does not depend on which of the two sets is the query.

mod filter;

use std::cell::Cell;

use self::filter::{
    segment_probe, segment_scan, segment_window, vertex_window, ScanChunk, SegmentBlock, Skip,
    Wraps,
};
use super::kernel::{
    cut_above, each, f32_at_least, rank_among, threshold, Frame, Lanes, Portable, Scratch, Simd,
    RING_WINDOW,
};
use super::period::swrap;
use super::prepared::{fold, wrap, PreparedSets, SetRef, BOUND_MARGIN, LANES, RING};

/// Absolute accuracy of the `curve` metric: every value is within this much below the
/// exact Hausdorff distance between the polylines (and never above it, up to rounding).
pub const CURVE_TOLERANCE: f64 = 1e-10;

/// Deepest refinement of one segment; the Lipschitz bound ends any refinement long
/// before (a segment of length `π√16` is below the tolerance after 37 halvings, and a
/// split removes at least a fifth of a piece).
const MAX_DEPTH: usize = 200;

pub use crate::kernel::Closure;

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
    /// `[set][n][segment]`: `v_i` in `f32` (lanes over segments, 0 past the last).
    pub dirs32: Vec<f32>,
    /// `[set][r][n]`, `(P + 2·RING) × dims_pad`: the `f32` direction of segment
    /// `(r − RING) mod P` (0 for the missing last segment of an open set), next to the
    /// ring of points of [`SetRef::ring32`].
    pub dir_ring32: Vec<f32>,
    /// `[set][r]`: `1 / |v|²` of the same segments in `f32` (0 for a segment too short
    /// for it, which then counts as its first point).
    pub inv_ring32: Vec<f32>,
    /// `[set][segment]`: `1 / |v_i|²` in `f32` (0 past the last segment, and for a
    /// segment too short for it, which then counts as its first point).
    pub inv32: Vec<f32>,
    /// `[set]`: the longest segment `max_i |v_i|`.
    pub max_len: Vec<f64>,
    /// `[set][2][n][chunk]`: the boxes of `centers` and `widths` in the `f32` frame of
    /// the coordinates (centres shifted like them, half-widths rounded up; a chunk
    /// without segments holds the last point), chunks padded to a multiple of eight
    /// (see [`filter::segment_scan`]).
    pub boxes32: Vec<f32>,
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
    pub dirs32: &'a [f32],
    pub dir_ring32: &'a [f32],
    pub inv_ring32: &'a [f32],
    pub inv32: &'a [f32],
    pub max_len: f64,
    pub boxes32: &'a [f32],
}

/// The box (`center`, half-`width` per coordinate, periodic) around the segments
/// `range` of one chunk of a set (`block` its coordinates `[n][point]`, `dirs` its
/// directions `[segment][n]`): the lifted path through them, a new lift where
/// `joins(i, next)` is false (a new piece), lies within `[lo, hi]`, so every point of them
/// within `(hi − lo)/2` of the middle (a periodic distance is at most the lifted one).
/// An empty range (no segment in the chunk: an open set with `P = 8k + 1`) gets width 0:
/// a box that no bound can reach is never used, since the loops stop at the segment count.
fn chunk_box(
    block: &[f64],
    dirs: &[f64],
    range: std::ops::Range<usize>,
    (points, points_pad, dims_pad): (usize, usize, usize),
    period: &[f64],
    joins: impl Fn(usize, usize) -> bool,
    (center, width): (&mut [f64], &mut [f64]),
) {
    if range.is_empty() {
        width.fill(0.0);
        return;
    }
    for k in 0..dims_pad {
        let mut y = block[k * points_pad + range.start];
        let (mut lo, mut hi) = (y, y);
        for i in range.clone() {
            let next = if i + 1 == points { 0 } else { i + 1 };
            y = if joins(i, next) {
                y + dirs[i * dims_pad + k]
            } else {
                // A new piece: its own lift (any lift stays within [lo, hi]).
                block[k * points_pad + next]
            };
            lo = lo.min(y);
            hi = hi.max(y);
        }
        center[k] = wrap(0.5 * (lo + hi), period[k]);
        width[k] = 0.5 * (hi - lo) * (1.0 + BOUND_MARGIN) + 1e-13;
    }
}

/// The `f32` directions and `1 / |v|²` of every set's segments in ring order (row `r`
/// holds segment `(r − RING) mod P`, 0 for a missing segment), and each set's longest
/// segment: the parts of a [`CurveLayout`] read next to [`SetRef::ring32`].
fn ring_segments(
    dirs: &[f64],
    inv_len2: &[f64],
    lengths: &[f64],
    segments: &[u32],
    (points, points_pad, dims_pad): (usize, usize, usize),
) -> (Vec<f32>, Vec<f32>, Vec<f64>) {
    let sets = segments.len();
    let per = dims_pad * points_pad;
    let rows = points + 2 * RING;
    let mut dir_ring32 = vec![0.0f32; sets * rows * dims_pad];
    let mut inv_ring32 = vec![0.0f32; sets * rows];
    let mut max_len = vec![0.0f64; sets];
    for s in 0..sets {
        let count = segments[s] as usize;
        max_len[s] = lengths[s * points_pad..s * points_pad + count]
            .iter()
            .fold(0.0, |m: f64, &x| m.max(x));
        for r in 0..rows {
            let j = (r + RING * points - RING) % points;
            if j >= count {
                continue;
            }
            for k in 0..dims_pad {
                dir_ring32[(s * rows + r) * dims_pad + k] = dirs[s * per + j * dims_pad + k] as f32;
            }
            let inv = inv_len2[s * points_pad + j];
            // Beyond f32's range a segment counts as its first point (t = 0).
            inv_ring32[s * rows + r] = if inv < 1e30 { inv as f32 } else { 0.0 };
        }
    }
    (dir_ring32, inv_ring32, max_len)
}

/// The chunk boxes `centers`, `widths` (`[set][chunk][n]`, `f64`) in the `f32` frame of
/// the coordinates (`offset` subtracted), laid out `[set][2][n][chunk]` with the chunks
/// padded to a multiple of eight; a chunk without segments gets the last point of its
/// set (the padding lanes of the kernels repeat it).
fn chunk_boxes32(
    coords: &[f64],
    (centers, widths): (&[f64], &[f64]),
    segments: &[u32],
    offset: &[f64],
    (points, points_pad, dims_pad): (usize, usize, usize),
) -> Vec<f32> {
    let chunks = points_pad / LANES;
    let slots = chunks.div_ceil(LANES) * LANES;
    let per = 2 * dims_pad * slots;
    let mut boxes = vec![0.0f32; segments.len() * per];
    for (s, &count) in segments.iter().enumerate() {
        let out = &mut boxes[s * per..(s + 1) * per];
        for q in 0..chunks {
            let at = (s * chunks + q) * dims_pad;
            let empty = q * LANES >= count as usize;
            for k in 0..dims_pad {
                let (center, width) = if empty {
                    (coords[(s * dims_pad + k) * points_pad + points - 1], 0.0)
                } else {
                    (centers[at + k], widths[at + k])
                };
                out[k * slots + q] = (center - offset[k]) as f32;
                out[(dims_pad + k) * slots + q] = f32_at_least(width);
            }
        }
    }
    boxes
}

impl CurveLayout {
    /// Builds the segments of the prepared (wrapped, padded) points; `offset` is the
    /// shift of the `f32` frame of every coordinate.
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
        period: &[f64],
        closure: &[Closure],
        pieces: Option<ndarray::ArrayView2<'_, i64>>,
        offset: &[f64],
    ) -> Self {
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
            // Two consecutive points of different pieces: a segment of length 0 (the
            // point itself, already in the set), so that no segment joins two pieces.
            let joins = |i: usize, next: usize| {
                pieces.is_none_or(|labels| labels[[s, i]] == labels[[s, next]])
            };
            // An open set whose last point is a piece of its own: no segment ends there,
            // so it gets one of length 0 (the point), as every other point is the start
            // of a segment.
            let count = match closure[s] {
                Closure::Closed => points,
                Closure::Open if points >= 2 && !joins(points - 2, points - 1) => points,
                Closure::Open => points - 1,
            };
            segments.push(count as u32);
            for i in 0..count {
                let next = if i + 1 == points { 0 } else { i + 1 };
                let closing = closure[s] == Closure::Open && next == 0;
                let join = if joins(i, next) && !closing { 1.0 } else { 0.0 };
                let mut len2 = 0.0;
                for k in 0..dims {
                    let v = join
                        * swrap(
                            block[k * points_pad + next] - block[k * points_pad + i],
                            period[k],
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
                let at = (s * chunks + q) * dims_pad;
                chunk_box(
                    block,
                    &dirs[s * per..(s + 1) * per],
                    first..(first + LANES).min(count),
                    (points, points_pad, dims_pad),
                    period,
                    joins,
                    (
                        &mut centers[at..at + dims_pad],
                        &mut widths[at..at + dims_pad],
                    ),
                );
            }
        }
        let (dir_ring32, inv_ring32, max_len) = ring_segments(
            &dirs,
            &inv_len2,
            &lengths,
            &segments,
            (points, points_pad, dims_pad),
        );
        let inv32 = inv_len2
            .iter()
            .map(|&inv| if inv < 1e30 { inv as f32 } else { 0.0 })
            .collect();
        let boxes32 = chunk_boxes32(
            coords,
            (&centers, &widths),
            &segments,
            offset,
            (points, points_pad, dims_pad),
        );
        Self {
            boxes32,
            segments,
            closure: closure.to_vec(),
            inv32,
            dirs32: dirs_soa.iter().map(|&x| x as f32).collect(),
            dirs,
            dirs_soa,
            inv_len2,
            lengths,
            centers,
            widths,
            dir_ring32,
            inv_ring32,
            max_len,
        }
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> u64 {
        ((self.dirs.len() + self.dirs_soa.len()) * 8
            + (self.inv_len2.len() + self.lengths.len()) * 8
            + (self.centers.len() + self.widths.len()) * 8
            + (self.dirs32.len()
                + self.dir_ring32.len()
                + self.inv_ring32.len()
                + self.inv32.len()
                + self.boxes32.len())
                * 4
            + self.segments.len() * 13) as u64
    }

    /// Bytes a layout of this shape holds.
    pub(crate) fn estimate_bytes(
        sets: usize,
        points: usize,
        points_pad: usize,
        dims_pad: usize,
    ) -> u64 {
        let chunks = points_pad / LANES;
        let slots = chunks.div_ceil(LANES) * LANES;
        let rows = points + 2 * RING;
        (sets as u64)
            * ((2 * points_pad * dims_pad + 2 * points_pad + 2 * chunks * dims_pad) * 8
                + (points_pad * (dims_pad + 1) + rows * (dims_pad + 1) + 2 * dims_pad * slots) * 4
                + 13) as u64
    }
}

impl PreparedSets {
    #[inline(always)]
    pub(crate) fn curve(&self, s: usize) -> CurveRef<'_> {
        let layout = self
            .curves()
            .expect("the curve metric checks that the closures were given");
        let dims_pad = self.dims_pad();
        let points_pad = self.points_pad();
        let per = dims_pad * points_pad;
        let chunks = self.chunks();
        let rows = self.points() + 2 * RING;
        let boxes = 2 * dims_pad * chunks.div_ceil(LANES) * LANES;
        CurveRef {
            boxes32: &layout.boxes32[s * boxes..(s + 1) * boxes],
            set: self.set(s),
            segments: layout.segments[s] as usize,
            dirs: &layout.dirs[s * per..(s + 1) * per],
            dirs_soa: &layout.dirs_soa[s * per..(s + 1) * per],
            inv_len2: &layout.inv_len2[s * points_pad..(s + 1) * points_pad],
            lengths: &layout.lengths[s * points_pad..(s + 1) * points_pad],
            centers: &layout.centers[s * chunks * dims_pad..(s + 1) * chunks * dims_pad],
            widths: &layout.widths[s * chunks * dims_pad..(s + 1) * chunks * dims_pad],
            dirs32: &layout.dirs32[s * per..(s + 1) * per],
            dir_ring32: &layout.dir_ring32[s * rows * dims_pad..(s + 1) * rows * dims_pad],
            inv_ring32: &layout.inv_ring32[s * rows..(s + 1) * rows],
            inv32: &layout.inv32[s * points_pad..(s + 1) * points_pad],
            max_len: layout.max_len[s],
        }
    }
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
    period: &[f64],
) -> f64 {
    const MAX: usize = 16;
    let n = a.len();
    assert!(n <= MAX, "at most {MAX} coordinates");
    let mut u = [0.0; MAX];
    let mut crossing = false;
    let mut dot = 0.0;
    for k in 0..n {
        u[k] = swrap(a[k] - b[k], period[k]);
        crossing |= (u[k] - v[k]).abs() > 0.5 * period[k];
        dot += u[k] * v[k];
    }
    if !crossing {
        // One piece: the lifted distance.
        let t = (dot * inv_len2).clamp(0.0, 1.0);
        let mut d2 = 0.0;
        for k in 0..n {
            d2 += (u[k] - t * v[k]).powi(2);
        }
        return d2;
    }
    let mut cuts = [0.0; MAX + 2];
    cuts[1] = 1.0;
    let mut count = 2;
    for k in 0..n {
        let end = u[k] - v[k];
        let half = 0.5 * period[k];
        if end > half {
            cuts[count] = (u[k] - half) / v[k];
            count += 1;
        } else if end < -half {
            cuts[count] = (u[k] + half) / v[k];
            count += 1;
        }
    }
    let cuts = &mut cuts[..count];
    cuts.sort_unstable_by(f64::total_cmp);
    let mut best = f64::INFINITY;
    for w in cuts.windows(2) {
        let (t0, t1) = (w[0].clamp(0.0, 1.0), w[1].clamp(0.0, 1.0));
        let mid = 0.5 * (t0 + t1);
        let mut dot = 0.0;
        for k in 0..n {
            let at_mid = u[k] - mid * v[k];
            dot += (u[k] + (swrap(at_mid, period[k]) - at_mid)) * v[k];
        }
        let t = (dot * inv_len2).clamp(t0, t1);
        let mut d2 = 0.0;
        for k in 0..n {
            d2 += swrap(u[k] - t * v[k], period[k]).powi(2);
        }
        best = best.min(d2);
    }
    best
}

/// Exact `δ(x, s_j)²` from the (wrapped) point `x` to segment `j` of `b`: the lifted
/// distance when the segment does not cross the seam relative to `x` (almost always),
/// else [`segment_distance2`].
#[inline(always)]
fn point_segment2<const N: usize>(
    x: &[f64; N],
    b: CurveRef<'_>,
    j: usize,
    period: &[f64; N],
) -> f64 {
    let v = load::<N>(b.dirs, j);
    let inv = b.inv_len2[j];
    match nearest_image::<N>(x, b, j, period) {
        Some(u) => lifted_distance2(&u, &v, inv),
        None => segment_distance2(x, &load::<N>(b.set.points, j), &v, inv, period),
    }
}

/// A lower bound of `δ(x, s)²` from the (wrapped) point `x` to the segment from `start`
/// (wrapped) along `v`, for the segments that cross the seam relative to `x`, at the
/// cost of about one lifted distance: coordinate by coordinate, the lifted path
/// `u_n − t v_n` (`u = h(x − start)`, `|u_n| ≤ T_n/2`, `|v_n| ≤ T_n/2`) runs between `u_n`
/// and `e_n = u_n − v_n`, and its periodic distance to 0 is 0 where it passes 0
/// (`u_n e_n ≤ 0`), else at least `min(|u_n|, |e_n|, T_n − |e_n|)` (the distance to the
/// nearest multiple of `T_n` is concave between two of them, so it is least at an
/// end); `δ² = min_t Σ_n (…)² ≥ Σ_n min_t (…)²`.
#[inline(always)]
fn seam_lower2<const N: usize>(
    x: &[f64; N],
    start: &[f64; N],
    v: &[f64; N],
    period: &[f64; N],
) -> f64 {
    let mut lower = 0.0;
    for k in 0..N {
        let u = swrap(x[k] - start[k], period[k]);
        let e = u - v[k];
        let m = u.abs().min(e.abs()).min(period[k] - e.abs());
        // `m < 0` only by rounding, where the path reaches a multiple of the period.
        let m = if u * e <= 0.0 || m < 0.0 { 0.0 } else { m };
        lower = m.mul_add(m, lower);
    }
    lower
}

/// `x − s̃_j(0)` for the periodic image `s̃_j` of segment `j` of `B` nearest to the
/// point `x` (`u = h(x − b_j)`, or one period over in the one coordinate where
/// `u_n − v_n` leaves `[−T_n/2, T_n/2]` along the segment, when that image is nearer:
/// past that point it is), or `None` when the segment crosses the seam relative to `x`
/// in more than one coordinate (then only the piecewise [`segment_distance2`] tells).
#[inline(always)]
fn nearest_image<const N: usize>(
    x: &[f64; N],
    b: CurveRef<'_>,
    j: usize,
    period: &[f64; N],
) -> Option<[f64; N]> {
    let start = load::<N>(b.set.points, j);
    let v = load::<N>(b.dirs, j);
    let inv = b.inv_len2[j];
    let mut u = [0.0; N];
    let mut crossings = 0;
    let mut last = 0;
    for k in 0..N {
        u[k] = swrap(x[k] - start[k], period[k]);
        if (u[k] - v[k]).abs() > 0.5 * period[k] {
            crossings += 1;
            last = k;
        }
    }
    match crossings {
        0 => Some(u),
        1 => {
            let mut shifted = u;
            shifted[last] -= period[last].copysign(u[last] - v[last]);
            if lifted_distance2(&shifted, &v, inv) < lifted_distance2(&u, &v, inv) {
                Some(shifted)
            } else {
                Some(u)
            }
        }
        _ => None,
    }
}

/// Per-lane `δ²` from points to segments given `u = h(a − start)` and the directions
/// `v`: the lifted distance `|u − t* v|²`, exact unless the segment crosses the seam
/// relative to the point (`|u_n − v_n| > T/2` in some coordinate `n`). Those lanes are
/// flagged (`true`) for the exact piecewise [`segment_distance2`].
#[inline(always)]
fn lanes_distance2<const N: usize>(
    u: &[[f64; LANES]; N],
    v: &[[f64; LANES]; N],
    inv: &[f64; LANES],
    period: &[f64; N],
) -> ([f64; LANES], [bool; LANES]) {
    let mut dot = [0.0; LANES];
    let mut crossings = [0u32; LANES];
    for k in 0..N {
        for l in 0..LANES {
            dot[l] = u[k][l].mul_add(v[k][l], dot[l]);
            crossings[l] += u32::from((u[k][l] - v[k][l]).abs() > 0.5 * period[k]);
        }
    }
    let mut t = [0.0; LANES];
    for l in 0..LANES {
        t[l] = (dot[l] * inv[l]).clamp(0.0, 1.0);
    }
    let mut d2 = [0.0; LANES];
    for k in 0..N {
        for l in 0..LANES {
            let w = u[k][l] - t[l] * v[k][l];
            d2[l] = w.mul_add(w, d2[l]);
        }
    }
    let mut crossing = [false; LANES];
    for l in 0..LANES {
        crossing[l] = crossings[l] > 0;
    }
    (d2, crossing)
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

/// The eight consecutive rows `block` of every coordinate of a `[n][point]` layout with
/// `stride` points per coordinate.
#[inline(always)]
fn load_block<const N: usize>(rows: &[f64], stride: usize, block: usize) -> [[f64; LANES]; N] {
    let mut a = [[0.0; LANES]; N];
    for (k, lanes) in a.iter_mut().enumerate() {
        lanes.copy_from_slice(&rows[k * stride + block * LANES..][..LANES]);
    }
    a
}

/// The `t`-th index of a scan centred on `start`: `start, start+1, start−1, start+2, …`
/// (modulo `len`).
#[inline(always)]
pub(super) fn around(start: usize, t: usize, len: usize) -> usize {
    // `t < 2·len`, so one subtraction brings the step into range.
    let step = t.div_ceil(2);
    let step = if step >= len { step - len } else { step };
    if t % 2 == 1 {
        let j = start + step;
        if j >= len {
            j - len
        } else {
            j
        }
    } else if start >= step {
        start - step
    } else {
        start + len - step
    }
}

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

/// `δ²` from one (wrapped) point `x` to the eight segments of chunk `q` of `b` (lanes
/// over segments), exact: the lifted distance, recomputed piece by piece for the (rare)
/// lanes whose segment crosses the seam relative to `x`. Lanes past the last segment
/// are `+∞`. `stride` is the padded point count of the layout.
#[inline(always)]
fn chunk_lanes<const N: usize>(
    x: &[f64; N],
    b: CurveRef<'_>,
    q: usize,
    stride: usize,
    period: &[f64; N],
) -> [f64; LANES] {
    let start = load_block::<N>(b.set.coords, stride, q);
    let dir = load_block::<N>(b.dirs_soa, stride, q);
    let mut inv = [0.0; LANES];
    inv.copy_from_slice(&b.inv_len2[q * LANES..][..LANES]);
    let mut u = [[0.0; LANES]; N];
    for k in 0..N {
        for l in 0..LANES {
            u[k][l] = swrap(x[k] - start[k][l], period[k]);
        }
    }
    let (mut d2, crossing) = lanes_distance2::<N>(&u, &dir, &inv, period);
    let live = b.segments.saturating_sub(q * LANES).min(LANES);
    for l in 0..live {
        if crossing[l] {
            let mut bs = [0.0; N];
            let mut v = [0.0; N];
            for k in 0..N {
                bs[k] = start[k][l];
                v[k] = dir[k][l];
            }
            d2[l] = segment_distance2(x, &bs, &v, inv[l], period);
        }
    }
    for lane in d2.iter_mut().skip(live) {
        *lane = f64::INFINITY;
    }
    d2
}

/// Squared lower bound of the distance from any point within `reach[n]` of `x` (per
/// coordinate, periodic) to the segments of chunk `q` of `b`: the gap between boxes.
#[inline(always)]
fn chunk_gap2<const N: usize>(
    x: &[f64; N],
    reach: &[f64; N],
    b: CurveRef<'_>,
    q: usize,
    period: &[f64; N],
) -> f64 {
    let center = load::<N>(b.centers, q);
    let width = load::<N>(b.widths, q);
    let mut lower = 0.0;
    for k in 0..N {
        let gap = fold(x[k] - center[k], period[k]) - width[k] - reach[k];
        if gap > 0.0 {
            lower += gap * gap;
        }
    }
    lower
}

/// Exact `d_B(x)²` at one (wrapped) point and the segment where it is reached (the
/// lowest index among ties), scanning the chunks of `B` outward from the one of
/// segment `hint` and skipping those whose box cannot hold a closer point.
#[inline(always)]
fn nearest<const N: usize>(
    x: &[f64; N],
    b: CurveRef<'_>,
    period: &[f64; N],
    stride: usize,
    hint: usize,
) -> (f64, usize) {
    let chunks = b.segments.div_ceil(LANES);
    let first = (hint / LANES).min(chunks - 1);
    let shrink = 1.0 - 4.0 * BOUND_MARGIN;
    let mut best = f64::INFINITY;
    let mut arg = usize::MAX;
    for t in 0..chunks {
        let q = around(first, t, chunks);
        if chunk_gap2::<N>(x, &[0.0; N], b, q, period) * shrink >= best {
            continue;
        }
        let d = chunk_lanes::<N>(x, b, q, stride, period);
        for (l, &d) in d.iter().enumerate() {
            let j = q * LANES + l;
            if d < best || (d == best && j < arg) {
                best = d;
                arg = j;
            }
        }
    }
    (best, arg)
}

/// Largest number of periodic images of segments of `B` that [`segment_max`] puts in
/// one envelope; past it the segment goes to the branch and bound.
const MAX_IMAGES: usize = 32;

/// An interval `[t_a, t_b]` of a segment of `A` with the images of the envelope
/// smallest at its ends, `(t_a, t_b, m_a, m_b)` (see [`segment_max`]).
type Interval = (f64, f64, usize, usize);

/// One piece of `E_j(t)²` on `[t0, t1]`: `|p + t·q|² = α t² + β t + γ`.
#[derive(Debug, Clone, Copy, Default)]
struct Quad {
    t0: f64,
    t1: f64,
    alpha: f64,
    beta: f64,
    gamma: f64,
    /// Which candidate segment of `B` it belongs to.
    owner: u32,
}

impl Quad {
    fn new<const N: usize>(range: (f64, f64), p: &[f64; N], q: &[f64; N], owner: usize) -> Self {
        let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
        for k in 0..N {
            alpha += q[k] * q[k];
            beta += 2.0 * p[k] * q[k];
            gamma += p[k] * p[k];
        }
        Self {
            t0: range.0,
            t1: range.1,
            alpha,
            beta,
            gamma,
            owner: owner as u32,
        }
    }

    fn at(&self, t: f64) -> f64 {
        (self.alpha * t + self.beta) * t + self.gamma
    }
}

/// The roots in `[lo, hi]` of `a t² + b t + c` (and, when the discriminant is slightly
/// negative, the vertex: two nearly equal roots that rounding merged), at most two.
fn roots_in(a: f64, b: f64, c: f64, lo: f64, hi: f64) -> ([f64; 2], usize) {
    let mut out = [0.0; 2];
    let mut count = 0;
    let slack = 1e-12;
    let mut push = |t: f64| {
        if t.is_finite() && t >= lo - slack && t <= hi + slack && count < 2 {
            out[count] = t.clamp(lo, hi);
            count += 1;
        }
    };
    if a == 0.0 {
        if b != 0.0 {
            push(-c / b);
        }
    } else {
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            push(-b / (2.0 * a));
        } else {
            let q = -0.5 * (b + disc.sqrt().copysign(b));
            push(q / a);
            if q != 0.0 {
                push(c / q);
            }
        }
    }
    (out, count)
}

/// What [`segment_max`] found on one segment of `A`.
enum SegmentMax {
    /// `max(c, max_t F(a(t)))` (`F` the lower envelope of the images given), exact, and
    /// where `F` reaches it when that is above `c` (`None`: `F ≤ c` all along).
    Done(f64, Option<f64>),
    /// Too many segments of `B` (or periodic images of them) come near: left to the
    /// branch and bound.
    Fallback,
}

/// Segments of `B` strictly between `j0` and `j1` along it (the shorter way round, at
/// most `most` of them; none when they are farther apart), the first candidates of the
/// lazy envelope besides the segments nearest to the ends.
fn between(j0: usize, j1: usize, segments: usize, most: usize) -> impl Iterator<Item = usize> {
    let forward = (j1 + segments - j0) % segments;
    let backward = (j0 + segments - j1) % segments;
    let (from, gap) = if forward <= backward {
        (j0, forward)
    } else {
        (j1, backward)
    };
    let count = if gap >= 2 && gap - 1 <= most {
        gap - 1
    } else {
        0
    };
    (1..=count).map(move |k| (from + k) % segments)
}

/// Segments of `B` between the nearest segments of a segment's ends taken into its first
/// lazy envelope (see [`between`]).
const LAZY_BETWEEN: usize = 3;

/// Images added to a lazy envelope before the segment goes to the branch and bound.
const MAX_LAZY_ROUNDS: usize = 8;

/// Relative gap between the envelope's maximum and the exact `d_B²` found there below
/// which the maximum counts as attained (both computed in `f64`, by different sums).
const LAZY_SLACK: f64 = 1e-12;

/// Adds to `images` the image of segment `j` of `B` nearest to the point `a_i + t·v_i` of
/// segment `i` of `A` (as its start relative to `a_i`), unless it is there already.
/// False when the image cannot be told in closed form (the segment crosses the seam in
/// two coordinates relative to the point) or `images` is full: the caller falls back.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn add_image<const N: usize>(
    a: CurveRef<'_>,
    b: CurveRef<'_>,
    i: usize,
    j: usize,
    t: f64,
    period: &[f64; N],
    images: &mut [(u32, [f64; N]); MAX_IMAGES],
    count: &mut usize,
) -> bool {
    let x = point_on::<N>(a, i, t, period);
    let v = load::<N>(a.dirs, i);
    let Some(u) = nearest_image::<N>(&x, b, j, period) else {
        return false;
    };
    let mut u0 = [0.0; N];
    for k in 0..N {
        u0[k] = u[k] - t * v[k];
    }
    let same = |&(jj, uu): &(u32, [f64; N])| {
        jj as usize == j && (0..N).all(|k| (uu[k] - u0[k]).abs() <= 0.25 * period[k].min(1.0))
    };
    if images[..*count].iter().any(same) {
        return true;
    }
    if *count == MAX_IMAGES {
        return false;
    }
    images[*count] = (j as u32, u0);
    *count += 1;
    true
}

/// `max(c, max_{t∈[0,1]} F(a_i + t v_i))` exactly, `F` the lower envelope of the
/// distances to the periodic `images` of segments of `B` given: an upper bound of `d_B`
/// (equal to it where the nearest image is among them), so its maximum proves nothing
/// against an abort limit; [`Pass::exact_segment`] evaluates `d_B` where it is reached.
///
/// On each image, `E(t)² = |p + t q|²` piecewise, with at most three pieces (the foot
/// `s*(t)` linear in `t`, clamped to `0` or `1`), so `F² = min E²` is a lower envelope
/// of convex quadratics. On an interval `[t_a, t_b]` whose ends are nearest to images
/// `m_a` and `m_b`, `F ≤ min(E_{m_a}, E_{m_b})`, and the maximum of the latter is at an
/// end or where the two cross (a root of `E_{m_a}² − E_{m_b}²` on a common piece; each piece
/// of `F` is convex). So every crossing above the running maximum is evaluated
/// exactly: if no third image is lower there, its value is attained and bounds the
/// interval; else the interval is split there with the lower image, and both halves
/// are examined the same way. Crossings below the running maximum are skipped
/// unevaluated. Past [`MAX_SPLITS`] splits the segment goes to the branch and bound.
#[inline(always)]
fn segment_max<const N: usize>(
    a: CurveRef<'_>,
    b: CurveRef<'_>,
    i: usize,
    images: &[(u32, [f64; N])],
    c: f64,
    (quads, stack): (&mut Vec<Quad>, &mut Vec<Interval>),
) -> SegmentMax {
    let v = load::<N>(a.dirs, i);
    // The pieces of every image, and where each image's pieces start.
    image_pieces::<N>(&v, images, b, quads);
    let quads = &quads[..];
    let mut first = [0usize; MAX_IMAGES + 1];
    for m in 0..images.len() {
        first[m + 1] = first[m]
            + quads[first[m]..]
                .iter()
                .take_while(|f| f.owner as usize == m)
                .count();
    }
    let envelope = |t: f64| envelope_at::<N>(images, &v, b, t);
    const SLACK: f64 = 1e-12;
    let (at0, m0) = envelope(0.0);
    let (at1, m1) = envelope(1.0);
    let mut c2 = c * c;
    let mut arg = None;
    for (at, t) in [(at0, 0.0), (at1, 1.0)] {
        if at > c2 {
            (c2, arg) = (at, Some(t));
        }
    }
    // Intervals [ta, tb] with the images minimal at their ends.
    stack.clear();
    stack.push((0.0, 1.0, m0, m1));
    let mut splits = 0;
    while let Some((ta, tb, ma, mb)) = stack.pop() {
        if ma == mb {
            // One convex function, at most its end values.
            continue;
        }
        let mut split = None;
        'pairs: for f in &quads[first[ma]..first[ma + 1]] {
            for g in &quads[first[mb]..first[mb + 1]] {
                let (lo, hi) = (f.t0.max(g.t0).max(ta), f.t1.min(g.t1).min(tb));
                // At a crossing both are equal, and a convex function is at most its
                // larger end value on the common range.
                if lo > hi
                    || f.at(lo).max(f.at(hi)) + SLACK <= c2
                    || g.at(lo).max(g.at(hi)) + SLACK <= c2
                {
                    continue;
                }
                let (roots, found) = roots_in(
                    f.alpha - g.alpha,
                    f.beta - g.beta,
                    f.gamma - g.gamma,
                    lo,
                    hi,
                );
                for &t in &roots[..found] {
                    let crossing = f.at(t);
                    if crossing + SLACK <= c2 {
                        continue;
                    }
                    let (value, m) = envelope(t);
                    if value > c2 {
                        (c2, arg) = (value, Some(t));
                    }
                    if m != ma && m != mb && value < crossing * (1.0 - 1e-13) - SLACK {
                        split = Some((t, m));
                        break 'pairs;
                    }
                }
            }
        }
        if let Some((t, m)) = split {
            splits += 1;
            if splits > MAX_SPLITS || stack.len() + 2 > MAX_SPLITS {
                return SegmentMax::Fallback;
            }
            stack.push((ta, t, ma, m));
            stack.push((t, tb, m, mb));
        }
    }
    SegmentMax::Done(c2.sqrt().max(c), arg)
}

/// The envelope `F²` at `a(t) = a_i + t·v` (the smallest lifted squared distance to the
/// `images`) and the image reaching it (the lowest index among ties). A function, not
/// a closure, so that it is compiled inside the caller's instruction set.
#[inline(always)]
fn envelope_at<const N: usize>(
    images: &[(u32, [f64; N])],
    v: &[f64; N],
    b: CurveRef<'_>,
    t: f64,
) -> (f64, usize) {
    let mut best = (f64::INFINITY, 0usize);
    for (m, (j, u0)) in images.iter().enumerate() {
        let j = *j as usize;
        let mut u = [0.0; N];
        for k in 0..N {
            u[k] = u0[k] + t * v[k];
        }
        let d = lifted_distance2(&u, &load::<N>(b.dirs, j), b.inv_len2[j]);
        if d < best.0 {
            best = (d, m);
        }
    }
    best
}

/// Largest number of splits of the envelope of one segment (then the branch and bound
/// takes over).
const MAX_SPLITS: usize = 64;

/// The quadratic pieces of `E_m(t)²`, the squared lifted distance from `a(t) = u0 + t·v`
/// to each image `m` of a segment of `B` (at most 3 per image: before, along and after
/// the foot's clamp), in `quads` (emptied first), image by image.
#[inline(always)]
fn image_pieces<const N: usize>(
    v: &[f64; N],
    images: &[(u32, [f64; N])],
    b: CurveRef<'_>,
    quads: &mut Vec<Quad>,
) {
    let v = *v;
    quads.clear();
    for (m, (j, u0)) in images.iter().enumerate() {
        let j = *j as usize;
        let w = load::<N>(b.dirs, j);
        let inv = b.inv_len2[j];
        let (mut uw, mut vw) = (0.0, 0.0);
        for k in 0..N {
            uw += u0[k] * w[k];
            vw += v[k] * w[k];
        }
        // The foot s*(t) = s0 + s1·t before clamping.
        let (s0, s1) = (uw * inv, vw * inv);
        let mut at_end = [0.0; N];
        let mut foot_p = [0.0; N];
        let mut foot_q = [0.0; N];
        for k in 0..N {
            at_end[k] = u0[k] - w[k];
            foot_p[k] = u0[k] - s0 * w[k];
            foot_q[k] = v[k] - s1 * w[k];
        }
        let mut push = |range: (f64, f64), p: &[f64; N], q: &[f64; N]| {
            let (t0, t1) = (range.0.max(0.0), range.1.min(1.0));
            if t0 <= t1 {
                quads.push(Quad::new::<N>((t0, t1), p, q, m));
            }
        };
        if inv == 0.0 || s1 == 0.0 {
            let s = if inv == 0.0 { 0.0 } else { s0 };
            if s <= 0.0 {
                push((0.0, 1.0), u0, &v);
            } else if s >= 1.0 {
                push((0.0, 1.0), &at_end, &v);
            } else {
                push((0.0, 1.0), &foot_p, &foot_q);
            }
        } else {
            let (ta, tb) = (-s0 / s1, (1.0 - s0) / s1);
            let (lo, hi) = if ta < tb { (ta, tb) } else { (tb, ta) };
            let (before, after) = if s1 > 0.0 {
                (u0, &at_end)
            } else {
                (&at_end, u0)
            };
            push((f64::NEG_INFINITY, lo), before, &v);
            push((lo, hi), &foot_p, &foot_q);
            push((hi, f64::INFINITY), after, &v);
        }
    }
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
fn point_on<const N: usize>(a: CurveRef<'_>, i: usize, t: f64, period: &[f64; N]) -> [f64; N] {
    let start = load::<N>(a.set.points, i);
    let v = load::<N>(a.dirs, i);
    let mut x = [0.0; N];
    for k in 0..N {
        x[k] = wrap(start[k] + t * v[k], period[k]);
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
    period: &[f64; N],
) -> (f64, f64) {
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
            u0[k] = swrap(x0[k] - bs[k], period[k]);
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
    period: &[f64; N],
    mut c: f64,
    abort: f64,
    stride: usize,
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
        let (d2, j) = nearest::<N>(&x, b, period, stride, hint);
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
    /// Per direction (`A → B`, then `B → A`), per vertex of the set the distances are
    /// taken from: its exact `d²` to the other set and nearest segment there, once
    /// computed (`NaN` before).
    vertex: [Vec<(f64, u32)>; 2],
    /// Per direction, the entries of `vertex` written since the last reset (see
    /// [`CurveScratch::reset_vertices`]).
    touched: [Vec<u32>; 2],
    /// The packed keys of [`merged_order`].
    packed: Vec<u64>,
    /// Segments of `A` that the `f32` passes left open: their test value, index, and
    /// the smallest lifted `f32` squared distances from their two ends to the segments
    /// of `B` in the window (`+∞` when not computed).
    open: Vec<OpenSegment>,
    /// The `f32` distances of the segment scan of the segment being settled.
    scan: Vec<ScanChunk>,
    /// The same for the vertex whose exact distance is computed.
    vertex_scan: Vec<ScanChunk>,
    /// The box gaps of the chunks of `B` in a scan.
    lower: Vec<f32>,
    /// How far from the segment of `scan` its skipped chunks are at least (see
    /// [`Pass::scan_segment`]).
    scan_reach: f64,
    /// The smallest `f32` lifted squared distance from the end of that segment to the
    /// segments of `B` it computed: a hint for the exact value there.
    scan_min1: f32,
    stack: Vec<Piece>,
    /// The pieces of the envelope in [`segment_max`].
    quads: Vec<Quad>,
    /// The intervals still to examine in [`segment_max`].
    intervals: Vec<Interval>,
}

impl CurveScratch {
    /// Records the exact `d_B²` of vertex `i` of direction `dir`.
    #[inline(always)]
    fn set_vertex(&mut self, dir: usize, i: usize, value: (f64, u32)) {
        self.vertex[dir][i] = value;
        self.touched[dir].push(i as u32);
    }

    /// Both directions' vertices unknown again (`NaN`), for sets of `points` points:
    /// only the entries written since the last reset are rewritten.
    #[inline(always)]
    fn reset_vertices(&mut self, points: usize) {
        for (vertex, touched) in self.vertex.iter_mut().zip(&mut self.touched) {
            if vertex.len() != points {
                vertex.clear();
                vertex.resize(points, (f64::NAN, 0));
            } else {
                for &i in touched.iter() {
                    vertex[i as usize] = (f64::NAN, 0);
                }
            }
            touched.clear();
        }
    }
}

/// A segment left open by the `f32` passes: `(test value, index, (m0, m1))`, see
/// [`CurveScratch::open`]; the index of a segment of `B` (the direction `B → A`) has
/// bit 31 set.
type OpenSegment = (f32, u32, (f32, f32));

/// One direction `A → B` of the curve kernel.
struct Pass<'a, S: Lanes, const N: usize> {
    s: S,
    a: CurveRef<'a>,
    b: CurveRef<'a>,
    frame: &'a Frame<N>,
    wraps: Wraps<S, N>,
    /// Half of every period (`+∞` when not wrapped), as vectors.
    half: [S::V; N],
    /// Smallest distance from a point to a segment of `B` that crosses the seam relative
    /// to it: `min_n T_n/2 − L` (`L` the longest segment of `B`; `+∞` without a period).
    seam_reach: f64,
    /// Coordinates too large for the `f32` filter: nothing is settled in `f32`.
    wide: bool,
    /// The direction: `0` for `A → B`, `1` for `B → A` (which records of
    /// [`CurveScratch::vertex`] it keeps).
    dir: usize,
    /// The last `(c2, segment_threshold(c2))`: `c2` changes a few times per pass while
    /// the threshold (a square root and a division) is asked for at every test.
    theta: Cell<(f64, f32)>,
}

impl<S: Lanes, const N: usize> Pass<'_, S, N> {
    /// The `f32` threshold of the lifted (segment) tests for the running `c2`.
    #[inline(always)]
    fn segment_threshold(&self, c2: f64) -> f32 {
        if self.wide {
            return -1.0;
        }
        let (last, theta) = self.theta.get();
        if last == c2 {
            return theta;
        }
        let theta = threshold(c2, self.frame.segment_delta, self.frame.rel);
        self.theta.set((c2, theta));
        theta
    }

    /// An upper bound of the exact distance whose lifted `f32` square is `m` (see
    /// [`FilterBounds`](super::prepared::FilterBounds)).
    #[inline(always)]
    fn upper(&self, m: f32) -> f64 {
        (f64::from(m) * (1.0 + self.frame.rel)).sqrt() * (1.0 + 1e-12) + self.frame.segment_delta
    }

    /// The Lipschitz bound: segment `i` of `A` is settled when
    /// `(d_B(a_i) + d_B(a_{i+1}) + |v_i|)/2 ≤ √c2`, with the `f32` lifted squared
    /// distances `m0`, `m1` from its ends to some segments of `B` as upper bounds.
    #[inline(always)]
    fn lipschitz_settles(&self, i: usize, (m0, m1): (f32, f32), c2: f64) -> bool {
        0.5 * (self.upper(m0) + self.upper(m1) + self.a.lengths[i]) <= c2.sqrt() * (1.0 - 1e-12)
    }

    /// The exact `d_B(a_i)²` of vertex `i` of `A` and its nearest segment of `B` (the
    /// lowest index among ties), computed once per pass.
    #[inline(always)]
    fn vertex(&self, i: usize, hint: f32, scratch: &mut CurveScratch) -> (f64, u32) {
        if scratch.vertex[self.dir][i].0.is_nan() {
            let value = self.exact_vertex(i, hint, (&mut scratch.vertex_scan, &mut scratch.lower));
            scratch.set_vertex(self.dir, i, value);
        }
        scratch.vertex[self.dir][i]
    }

    /// [`Self::vertex`], computed ([`Self::exact_point`] at `a_i`).
    #[inline(always)]
    fn exact_vertex(
        &self,
        i: usize,
        hint: f32,
        (scan, lower): (&mut Vec<ScanChunk>, &mut Vec<f32>),
    ) -> (f64, u32) {
        let x = load::<N>(self.a.set.points, i);
        let x32: [f32; N] = each(0.0, |k| self.a.set.coords32[k * self.frame.points_pad + i]);
        self.exact_point(&x, Some(&x32), hint, (scan, lower))
    }

    /// The exact `d_B(x)²` of a (wrapped) point `x` and its nearest segment of `B` (the
    /// lowest index among ties): the `f32` distances from `x` to the segments of `B`
    /// (skipping the chunks that cannot hold one within `upper(hint)`, `hint` an `f32`
    /// test value known of some segment of `B`, or `+∞`) give an upper bound `R`, and
    /// only the segments whose `f32` value allows `R` ([`cut_above`]) are computed,
    /// exactly ([`point_segment2`]). `x32` is `x` in the `f32` frame when known.
    #[inline(always)]
    fn exact_point(
        &self,
        x: &[f64; N],
        x32: Option<&[f32; N]>,
        hint: f32,
        (scan, lower): (&mut Vec<ScanChunk>, &mut Vec<f32>),
    ) -> (f64, u32) {
        let (b, frame) = (self.b, self.frame);
        if self.wide {
            let mut best = (f64::INFINITY, u32::MAX);
            for j in 0..b.segments {
                let d2 = point_segment2::<N>(x, b, j, &frame.period);
                if d2 < best.0 {
                    best = (d2, j as u32);
                }
            }
            return best;
        }
        let x32: [f32; N] = match x32 {
            Some(x32) => *x32,
            None => each(0.0, |k| (x[k] - frame.offset[k]) as f32),
        };
        let (smallest, _, _) =
            self.scan::<false>(&x32, &[0.0; N], (hint, 0.0), (&mut *scan, lower, false));
        self.nearest_from_scan(x, smallest, (scan, lower))
    }

    /// The exact `d_B(x)²` and nearest segment from a [`segment_scan`] of the point `x`
    /// (smallest value `smallest`).
    #[inline(always)]
    fn nearest_from_scan(
        &self,
        x: &[f64; N],
        smallest: f32,
        (scan, gaps): (&[ScanChunk], &[f32]),
    ) -> (f64, u32) {
        let (b, frame) = (self.b, self.frame);
        let exact = |j: usize| point_segment2::<N>(x, b, j, &frame.period);
        let mut best = (f64::INFINITY, u32::MAX);
        let keep = |d2: f64, j: usize, best: &mut (f64, u32)| {
            if d2 < best.0 || (d2 == best.0 && (j as u32) < best.1) {
                *best = (d2, j as u32);
            }
        };
        let (delta, rel) = (frame.segment_delta, frame.rel);
        // d_B(x) ≤ radius. A segment that does not cross the seam relative to x has an
        // f32 value within the bounds of its exact distance, so the nearest one is
        // below `cut`; one that crosses is at least `T_n/2 − |v_n|` away in the
        // crossing coordinate, so it only counts when the radius reaches that, and then
        // only when neither its chunk's box gap nor its own lower bound ([`seam_lower2`])
        // exceeds the radius or the nearest segment found so far (those that do not
        // cross first).
        let radius = (f64::from(smallest) * (1.0 + rel)).sqrt() * (1.0 + 1e-12) + delta;
        let cut = self.s.splat(cut_above(smallest, 2.0 * delta, rel));
        for &(q, ref e0, _, crossing) in scan {
            let mut mask = self.s.le(self.s.load(e0), cut) & !crossing;
            while mask != 0 {
                let l = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let j = q as usize * LANES + l;
                if j < b.segments {
                    keep(exact(j), j, &mut best);
                }
            }
        }
        if radius >= self.seam_reach {
            // A chunk whose box is farther than the nearest distance found (or the
            // radius) holds nothing nearer, crossing or not.
            let far = self.skip(0.0).beyond(best.0.min(radius * radius).sqrt());
            for &(q, _, _, mut mask) in scan {
                if gaps[q as usize] > far {
                    continue;
                }
                while mask != 0 {
                    let l = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let j = q as usize * LANES + l;
                    if j < b.segments
                        && seam_lower2::<N>(
                            x,
                            &load::<N>(b.set.points, j),
                            &load::<N>(b.dirs, j),
                            &frame.period,
                        ) * (1.0 - 1e-9)
                            <= best.0.min(radius * radius)
                    {
                        keep(exact(j), j, &mut best);
                    }
                }
            }
        }
        best
    }

    /// [`segment_scan`] over the segments of `B` from the point `x` (and `x + v`),
    /// skipping the chunks farther than `upper(hint) + extra` from every point of
    /// `[x, x + v]` (`hint` a test value known of some segment of `B`, see
    /// [`Self::upper`] and [`Skip`]).
    #[inline(always)]
    fn scan<const ENDS: bool>(
        &self,
        x: &[f32; N],
        v: &[f32; N],
        (hint, extra): (f32, f64),
        (out, lower, gaps_ready): (&mut Vec<ScanChunk>, &mut Vec<f32>, bool),
    ) -> (f32, f32, f32) {
        let (b, frame) = (self.b, self.frame);
        segment_scan::<S, N, ENDS>(
            self.s,
            (x, v),
            (b.set.coords32, b.dirs32, b.inv32, b.boxes32),
            frame.chunks,
            (&self.wraps, &self.half),
            (self.skip(extra), hint),
            (lower, gaps_ready),
            out,
        )
    }

    /// The chunk skipping of the scans of `B`, for points within `extra` of the segment
    /// scanned (see [`Skip`]).
    #[inline(always)]
    fn skip(&self, extra: f64) -> Skip {
        let frame = self.frame;
        Skip {
            rel: frame.rel,
            segment_delta: frame.segment_delta,
            margin: 2.0 * (frame.segment_delta + frame.delta),
            extra,
        }
    }

    /// Settles segment `i` of `A` exactly, raising `c2` to its maximum `max_t d_B²` when
    /// that is larger; `None` once `c2 > abort2`. The exact values at its ends come
    /// first, then the Lipschitz bound `(d_i + d_{i+1} + |v_i|)/2`, convexity with the
    /// segments nearest to either end, and last the lazy envelope (module docs, step 3).
    #[inline(always)]
    fn exact_segment(
        &self,
        i: usize,
        mut c2: f64,
        abort2: f64,
        scratch: &mut CurveScratch,
    ) -> Option<f64> {
        let (a, b, period) = (self.a, self.b, &self.frame.period);
        let next = if i + 1 == self.frame.points { 0 } else { i + 1 };
        let (d0, j0) = self.vertex(i, f32::INFINITY, scratch);
        let (d1, j1) = self.vertex(next, scratch.scan_min1, scratch);
        c2 = c2.max(d0).max(d1);
        if c2 > abort2 {
            return None;
        }
        let c = c2.sqrt();
        if self.ends_settle(i, [(d0, j0), (d1, j1)], c2) {
            return Some(c2);
        }
        let abort = abort2.sqrt();
        let stride = self.frame.points_pad;
        // The envelope of a few images of segments of B, grown until its maximum is
        // attained (module docs, step 3).
        let mut images = [(0u32, [0.0; N]); MAX_IMAGES];
        let mut count = 0;
        let mut ok = add_image::<N>(a, b, i, j0 as usize, 0.0, period, &mut images, &mut count)
            && add_image::<N>(a, b, i, j1 as usize, 1.0, period, &mut images, &mut count);
        for j in between(j0 as usize, j1 as usize, b.segments, LAZY_BETWEEN) {
            ok &= add_image::<N>(a, b, i, j, 0.5, period, &mut images, &mut count);
        }
        let mut c = c;
        let mut rounds = 0;
        while ok && rounds < MAX_LAZY_ROUNDS {
            rounds += 1;
            let buffers = (&mut scratch.quads, &mut scratch.intervals);
            let (value, t) = match segment_max::<N>(a, b, i, &images[..count], c, buffers) {
                SegmentMax::Fallback => break,
                SegmentMax::Done(_, None) => return Some(c2),
                SegmentMax::Done(value, Some(t)) => (value, t),
            };
            // The envelope of these images bounds d_B from above and peaks at t: the
            // maximum is attained when no other image is nearer there.
            let x = point_on::<N>(a, i, t, period);
            let (d2, j) = self.exact_point(
                &x,
                None,
                (value * value * (1.0 + 1e-9)) as f32,
                (&mut scratch.vertex_scan, &mut scratch.lower),
            );
            if d2 > c2 {
                c2 = d2;
                if c2 > abort2 {
                    return None;
                }
                c = c2.sqrt();
            }
            if d2 >= value * value * (1.0 - LAZY_SLACK) {
                return Some(c2);
            }
            let before = count;
            ok = add_image::<N>(a, b, i, j as usize, t, period, &mut images, &mut count);
            if ok && count == before {
                ok = false;
            }
        }
        let ends = [(d0.sqrt(), j0), (d1.sqrt(), j1)];
        let mut stack = std::mem::take(&mut scratch.stack);
        let result = refine_segment::<N>(a, b, i, ends, period, c, abort, stride, &mut stack);
        scratch.stack = stack;
        result.map(|value| c2.max(value * value))
    }

    /// Whether segment `i` of `A` is settled for `c2` by the exact values already known
    /// at its ends, without a scan of `B`: the Lipschitz bound
    /// `(d_B(a_i) + d_B(a_{i+1}) + |v_i|)/2 ≤ √c2` when both are known, else convexity
    /// with the segment of `B` nearest to a known end (both ends of segment `i` within
    /// `√c2` of one lifted image of it, [`within_along`]). It settles about 60 % of the
    /// segments the windows leave open on the paper's arm, which then need no
    /// [`segment_scan`].
    #[inline(always)]
    fn known_ends_settle(&self, i: usize, c2: f64, scratch: &CurveScratch) -> bool {
        let next = if i + 1 == self.frame.points { 0 } else { i + 1 };
        let known = &scratch.vertex[self.dir];
        self.ends_settle(i, [known[i], known[next]], c2)
    }

    /// Whether segment `i` of `A` is settled for `c2` by the exact `d_B²` at its ends and
    /// their nearest segments of `B` (`ends`; an end not yet known is `NaN` and proves
    /// nothing): the Lipschitz bound when both are at most `c2`, else convexity with the
    /// nearest segment of an end at most `c2` ([`within_along`]).
    #[inline(always)]
    fn ends_settle(&self, i: usize, [(d0, j0), (d1, j1)]: [(f64, u32); 2], c2: f64) -> bool {
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

    /// Whether a [`segment_scan`] of segment `i` of `A` settles it for the running `c2`:
    /// both ends within `√c2` of one lifted segment of `B` (convexity), or the Lipschitz
    /// bound `(d_B(a_i) + d_B(a_{i+1}) + |v_i|)/2 ≤ √c2` with the upper bounds of the
    /// scan. Records the exact `d_B(a_i)` it gives for free. `hint` is the segment's
    /// `f32` test value in its window.
    #[inline(always)]
    fn scan_settles(&self, i: usize, c2: f64, hint: f32, scratch: &mut CurveScratch) -> bool {
        !self.wide && self.scan_segment(i, c2, (false, hint), scratch)
    }

    /// The [`segment_scan`] of segment `i` of `A` (see [`Self::scan_settles`]): whether it
    /// settles the segment for `max(c2, d_B(a_i)²)`, with the exact `d_B(a_i)` recorded
    /// when it is still unknown and `vertex` asks for it or the segment stays open.
    /// `hint` is a test value `max(e(a_i), e(a_{i+1}))` known of some segment of `B` (or
    /// `+∞`): chunks farther than it allows are skipped (see [`Self::scan`]).
    #[inline(always)]
    fn scan_segment(
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
    fn block(
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
fn merged_order(row_key: &[f32], col_key: &[f32], packed: &mut Vec<u64>, order: &mut Vec<u32>) {
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

/// Sorts the open segments by decreasing test value, ties by increasing entry. Up to
/// [`RANK_SORT_OPEN`] of them (almost always) are ranked without branches: a
/// non-negative `f32` orders like its bits, so `(value bits, inverted entry)` read as
/// an `i64` is a distinct key whose rank is the number of larger keys.
#[inline(always)]
fn largest_first(open: &mut [OpenSegment]) {
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

/// `max(h(A, B), h(B, A))²` over the continuous polylines; `None` once it is proven
/// `> abort2`. The blocks of both directions go through the `f32` passes
/// ([`Pass::block`]) in one order, far from the other set first ([`merged_order`]);
/// the segments they leave open, of either direction, are then settled exactly,
/// largest test value first ([`Pass::exact_segment`]).
#[inline(always)]
fn both_directions<S: Lanes, const N: usize>(
    passes: [&Pass<'_, S, N>; 2],
    near: [&[u32]; 2],
    order: &[u32],
    abort2: f64,
    scratch: &mut CurveScratch,
) -> Option<f64> {
    let points = passes[0].frame.points;
    scratch.reset_vertices(points);
    scratch.open.clear();
    let mut c2 = 0.0;
    for &entry in order {
        let (dir, alpha) = ((entry >> 31) as usize, (entry & 0x7fff_ffff) as usize);
        let first = scratch.open.len();
        c2 = passes[dir].block(alpha, near[dir][alpha] as usize, c2, abort2, scratch)?;
        for open in &mut scratch.open[first..] {
            open.1 |= (dir as u32) << 31;
        }
    }
    let mut open = std::mem::take(&mut scratch.open);
    largest_first(&mut open);
    for &(value, entry, ends) in &open {
        let (dir, i) = ((entry >> 31) as usize, (entry & 0x7fff_ffff) as usize);
        let pass = passes[dir];
        // The window's tests again with the final c2, before a scan of B (its chunks near the segment).
        if value <= pass.segment_threshold(c2) || pass.lipschitz_settles(i, ends, c2) {
            continue;
        }
        if pass.known_ends_settle(i, c2, scratch) || pass.scan_settles(i, c2, value, scratch) {
            continue;
        }
        match pass.exact_segment(i, c2, abort2, scratch) {
            Some(value) => c2 = value,
            None => {
                scratch.open = open;
                return None;
            }
        }
    }
    scratch.open = open;
    Some(c2)
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
    match super::kernel::simd() {
        // The AVX2 code on AVX-512 CPUs too: compiled for AVX-512 (the same eight
        // lanes, mask registers, 32 registers) it took 3–4 % more CPU time on the
        // paper's arm sets (the history of docs/curve-performance.md).
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512(v4) => {
            let v3 = *v4;
            v3.vectorize(CurveCall {
                s: v3,
                prepared,
                pair: (i, j),
                limit,
                scratch,
            })
        }
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2(v3) => v3.vectorize(CurveCall {
            s: v3,
            prepared,
            pair: (i, j),
            limit,
            scratch,
        }),
        Simd::Portable => curve_fixed(Portable, prepared, i, j, limit, scratch),
    }
}

/// One pair, as work for `pulp`'s target-feature context (its `call` is inlined there).
struct CurveCall<'a, S> {
    s: S,
    prepared: &'a PreparedSets,
    pair: (usize, usize),
    limit: f64,
    scratch: &'a mut Scratch,
}

impl<S: Lanes> pulp::NullaryFnOnce for CurveCall<'_, S> {
    type Output = Option<f64>;

    #[inline(always)]
    fn call(self) -> Option<f64> {
        let (i, j) = self.pair;
        curve_fixed(self.s, self.prepared, i, j, self.limit, self.scratch)
    }
}

/// [`curve_hausdorff`] for the coordinate count of `prepared`.
#[inline(always)]
fn curve_fixed<S: Lanes>(
    s: S,
    prepared: &PreparedSets,
    i: usize,
    j: usize,
    limit: f64,
    scratch: &mut Scratch,
) -> Option<f64> {
    match prepared.dims_pad() {
        2 => curve_hausdorff::<S, 2>(s, prepared, i, j, limit, scratch),
        4 => curve_hausdorff::<S, 4>(s, prepared, i, j, limit, scratch),
        8 => curve_hausdorff::<S, 8>(s, prepared, i, j, limit, scratch),
        16 => curve_hausdorff::<S, 16>(s, prepared, i, j, limit, scratch),
        _ => unreachable!("the curve metric is checked to have at most 16 coordinates"),
    }
}

/// `ρ_c(set i, set j)`, or `None` once it is proven `> limit`. The pair is always
/// evaluated as (smaller index, larger index).
#[inline(always)]
fn curve_hausdorff<S: Lanes, const N: usize>(
    s: S,
    prepared: &PreparedSets,
    i: usize,
    j: usize,
    limit: f64,
    scratch: &mut Scratch,
) -> Option<f64> {
    let (i, j) = if i <= j { (i, j) } else { (j, i) };
    let a = prepared.curve(i);
    let b = prepared.curve(j);
    let frame = Frame::<N>::of(prepared);
    super::kernel::center_table(s, a.set, b.set, &frame, scratch);
    let (row_key, row_near, col_key, col_near, order, curve) = scratch.parts();
    let abort2 = if limit.is_finite() {
        limit * limit
    } else {
        f64::INFINITY
    };
    let wraps = Wraps::new(s, &frame.period);
    let wide = prepared.is_wide();
    let half: [S::V; N] = each(s.splat(0.0), |k| s.splat((0.5 * frame.period[k]) as f32));
    let seam = frame
        .period
        .iter()
        .fold(f64::INFINITY, |m, &t| m.min(0.5 * t));
    let forward = Pass {
        s,
        a,
        b,
        frame: &frame,
        wraps,
        half,
        seam_reach: seam - b.max_len,
        wide,
        dir: 0,
        theta: Cell::new((f64::NAN, -1.0)),
    };
    let backward = Pass {
        s,
        a: b,
        b: a,
        frame: &frame,
        wraps,
        half,
        seam_reach: seam - a.max_len,
        wide,
        dir: 1,
        theta: Cell::new((f64::NAN, -1.0)),
    };
    let chunks = frame.chunks;
    merged_order(
        &row_key[..chunks],
        &col_key[..chunks],
        &mut curve.packed,
        order,
    );
    let c2 = both_directions(
        [&forward, &backward],
        [row_near, col_near],
        order,
        abort2,
        curve,
    )?;
    Some(c2.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metric::{reference, Period};
    use ndarray::ArrayView1;
    use rand::{RngExt, SeedableRng};
    use std::f64::consts::PI;

    #[test]
    fn exact_segment_distance_equals_the_image_by_image_brute_force() {
        // Segments through the seam and points anywhere, 1 to 6 coordinates.
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(7);
        let period = 2.0 * PI;
        let mut crossing = 0;
        for trial in 0..4000 {
            let n = 1 + trial % 6;
            let start: Vec<f64> = (0..n).map(|_| rng.random_range(-PI..PI)).collect();
            let end: Vec<f64> = (0..n).map(|_| rng.random_range(-PI..PI)).collect();
            let a: Vec<f64> = (0..n).map(|_| rng.random_range(-PI..PI)).collect();
            let v: Vec<f64> = start
                .iter()
                .zip(&end)
                .map(|(s, e)| swrap(e - s, period))
                .collect();
            let len2: f64 = v.iter().map(|x| x * x).sum();
            let inv = if len2 > 0.0 { 1.0 / len2 } else { 0.0 };
            let fast = segment_distance2(&a, &start, &v, inv, &vec![period; n]).sqrt();
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
                .map(|(x, y)| swrap(x - y, period))
                .collect();
            crossing += usize::from(u.iter().zip(&v).any(|(x, y)| (x - y).abs() > PI));
        }
        // The piecewise path was exercised.
        assert!(crossing > 500, "{crossing}");
    }

    #[test]
    fn the_seam_bound_is_below_the_exact_segment_distance_and_often_close() {
        // Points anywhere and segments through the seam, 8 coordinates (one of them
        // unwrapped): the bound never exceeds the exact distance, and it is a good
        // one (within 20 %) for most of the segments that cross the seam.
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(11);
        let mut period = [2.0 * PI; 8];
        period[7] = f64::INFINITY;
        let (mut crossing, mut close) = (0, 0);
        for trial in 0..4000 {
            let reach = [0.3, 0.8, 1.5, PI][trial % 4];
            let start: [f64; 8] = std::array::from_fn(|_| rng.random_range(-PI..PI));
            let x: [f64; 8] = std::array::from_fn(|_| rng.random_range(-PI..PI));
            let v: [f64; 8] = std::array::from_fn(|_| rng.random_range(-reach..reach));
            let len2: f64 = v.iter().map(|x| x * x).sum();
            let exact = segment_distance2(&x, &start, &v, 1.0 / len2, &period);
            let lower = seam_lower2::<8>(&x, &start, &v, &period);
            assert!(
                lower >= 0.0 && lower <= exact * (1.0 + 1e-12),
                "{trial}: {lower} > {exact}"
            );
            let u: Vec<f64> = (0..8).map(|k| swrap(x[k] - start[k], period[k])).collect();
            if (0..7).any(|k| (u[k] - v[k]).abs() > PI) {
                crossing += 1;
                close += usize::from(lower >= 0.8 * 0.8 * exact);
            }
        }
        assert!(crossing > 1000, "{crossing}");
        assert!(2 * close > crossing, "{close} of {crossing}");
    }

    /// Closed loops on the 4-torus shaped like the arm's kernel sets (one winding
    /// coordinate, two harmonics per coordinate, all affine in a random pose).
    fn arm_like_loops(m: usize, p: usize, seed: u64) -> ndarray::Array3<f64> {
        use std::f64::consts::TAU;
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
        let family: Vec<[f64; 4]> = (0..20)
            .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
            .collect();
        let mut sets = ndarray::Array3::zeros((m, p, 4));
        for i in 0..m {
            let pose: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..1.0));
            let affine = |c: &[f64; 4]| c[0] + c[1] * pose[0] + c[2] * pose[1] + c[3] * pose[2];
            let phase = rng.random_range(0.0..TAU);
            for k in 0..p {
                let s = TAU * k as f64 / p as f64;
                let t = phase + s + 0.25 * s.sin();
                for n in 0..4 {
                    let c = &family[5 * n..5 * n + 5];
                    let winding = if n == 0 { t } else { 0.0 };
                    let x = winding
                        + 2.0 * affine(&c[0])
                        + 0.8 * affine(&c[1]) * (t + 1.5 * affine(&c[2])).cos()
                        + 0.3 * affine(&c[3]) * (2.0 * t + 1.5 * affine(&c[4])).sin();
                    sets[[i, k, n]] = (x + PI).rem_euclid(TAU) - PI;
                }
            }
        }
        sets
    }

    /// A limit at or above the distance never drops the pair (the nearest-set search
    /// relies on it): the lazy envelope's maximum only bounds `d_B` from above, so it
    /// must not abort; only exactly evaluated distances may. Below the distance the
    /// pair is dropped or comes back above the limit.
    #[test]
    fn a_limit_above_the_distance_never_drops_the_pair() {
        let m = 60;
        let sets = arm_like_loops(m, 100, 11);
        let closures = vec![Closure::Closed; m];
        let view = crate::metric::SetsView::new(sets.view()).with_closure(&closures);
        let prepared = PreparedSets::new(view, Period::TwoPi).unwrap();
        let mut scratch = Scratch::default();
        for i in 0..m {
            for j in i + 1..m {
                let d = curve_pair(&prepared, i, j, f64::INFINITY, &mut scratch).unwrap();
                for limit in [d * (1.0 + 1e-12), d + 1e-3] {
                    let found = curve_pair(&prepared, i, j, limit, &mut scratch);
                    assert_eq!(found, Some(d), "({i}, {j}) limit {limit}");
                }
                let below = d * (1.0 - 1e-9);
                let found = curve_pair(&prepared, i, j, below, &mut scratch);
                assert!(found.is_none_or(|v| v > below), "({i}, {j}): {found:?}");
            }
        }
    }

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

    #[test]
    fn roots_of_quadratics_in_a_range() {
        // (t − 0.25)(t − 0.75) = t² − t + 3/16.
        let (roots, count) = roots_in(1.0, -1.0, 0.1875, 0.0, 1.0);
        let mut found = roots[..count].to_vec();
        found.sort_by(f64::total_cmp);
        assert_eq!(count, 2);
        assert!((found[0] - 0.25).abs() < 1e-15 && (found[1] - 0.75).abs() < 1e-15);
        // Only one in [0.5, 1]; a linear one; none outside the range.
        assert_eq!(roots_in(1.0, -1.0, 0.1875, 0.5, 1.0).1, 1);
        let (roots, count) = roots_in(0.0, 2.0, -1.0, 0.0, 1.0);
        assert!(count == 1 && (roots[0] - 0.5).abs() < 1e-15);
        assert_eq!(roots_in(0.0, 2.0, 1.0, 0.0, 1.0).1, 0);
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
