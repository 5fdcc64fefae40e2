//! The segments of every set laid out for the curve kernels ([`CurveLayout`], built
//! once by [`PreparedSets::new`] when the sets come with their [`Closure`]), and one
//! set's view of them ([`CurveRef`]).
//!
//! Segment `i` of a set runs along `v_i = h(x_{i+1} − x_i)`, with `v_i = 0` where its
//! ends lie in different pieces and for the closing segment of an open set (a segment
//! of length 0 is its first point); an open set whose last point is a piece of its own
//! keeps a segment of length 0 there. Stored with it: `|v_i|` and `1/|v_i|²` (0 for
//! length 0), in `f64` in the orders `[segment][n]` and `[n][segment]`, and in `f32`
//! for the filters, also in the ring order of the points' `f32` windows.
//!
//! Every chunk of eight segments gets a box: the lifted path through them (a new lift
//! where a piece starts) lies within `[lo_n, hi_n]` in coordinate `n`, so every point of
//! the chunk is within the half-width `w_n = (hi_n − lo_n)/2` of the centre
//! `c_n = h((lo_n + hi_n)/2)` (a periodic distance is at most the lifted one), and
//!
//! ```text
//! δ(x, s_j)² ≥ Σ_n max(0, |h(x_n − c_n)| − w_n)²    for every segment j of the chunk.
//! ```
//!
//! The widths carry a relative margin, and the boxes are copied into the `f32` frame of
//! the coordinates (centres shifted like them, half-widths rounded up) for the `f32`
//! scans.

use super::Closure;
use crate::metric::kernel::f32_at_least;
use crate::metric::period::swrap;
use crate::metric::prepared::{wrap, PreparedSets, SetRef, BOUND_MARGIN, LANES, RING};

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
    /// (see [`filter::segment_scan`](super::filter::segment_scan)).
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
