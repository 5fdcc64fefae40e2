//! One direction `A → B` of the curve kernel ([`Pass`]), the buffers of both directions
//! ([`CurveScratch`]), and the exact `d_B` of a point that every phase asks for.
//!
//! The exact `d_B(x)` of a point ([`Pass::exact_point`]) starts from an `f32` scan of the
//! segments of `B` ([`segment_scan`]): its smallest lifted value `m` gives, with the
//! error bounds of [`FilterBounds`](crate::metric::prepared::FilterBounds) (relative
//! `ε`, absolute `Δ`), an upper bound
//!
//! ```text
//! d_B(x) ≤ R = √(m (1 + ε)) + Δ,
//! ```
//!
//! and only the segments whose `f32` value allows `R` ([`cut_above`]) are computed
//! exactly. A segment that crosses the seam relative to the point (its lifted `f32`
//! value is only an upper bound) is at least `min_n T_n/2 − L` away (`L` the longest
//! segment of `B`), so it counts only when `R` reaches that; then it is computed when
//! the lower bounds allow it: its chunk's box gap, then coordinate by coordinate the
//! least periodic distance along the segment ([`seam_lower2`]). The scans skip whole
//! chunks of eight segments of `B` whose boxes are too far ([`Skip`]) and first try the
//! one chunk whose box is nearest.

use std::cell::Cell;

use super::bound::Piece;
use super::distance::{load, point_segment2, seam_lower2};
use super::envelope::{Interval, Quad};
use super::filter::{segment_scan, ScanChunk, Skip, Wraps};
use super::layout::CurveRef;
use super::segments::OpenSegment;
use crate::metric::kernel::{cut_above, each, threshold, Frame, Lanes};
use crate::metric::prepared::LANES;

/// Reusable buffers of the curve kernel.
#[derive(Debug, Default)]
pub(crate) struct CurveScratch {
    /// Per direction (`A → B`, then `B → A`), per vertex of the set the distances are
    /// taken from: its exact `d²` to the other set and nearest segment there, once
    /// computed (`NaN` before).
    pub(super) vertex: [Vec<(f64, u32)>; 2],
    /// Per direction, the entries of `vertex` written since the last reset (see
    /// [`CurveScratch::reset_vertices`]).
    touched: [Vec<u32>; 2],
    /// The packed keys of [`merged_order`](super::blocks::merged_order).
    pub(super) packed: Vec<u64>,
    /// Segments of `A` that the `f32` passes left open: their test value, index, and
    /// the smallest lifted `f32` squared distances from their two ends to the segments
    /// of `B` in the window (`+∞` when not computed).
    pub(super) open: Vec<OpenSegment>,
    /// The `f32` distances of the segment scan of the segment being settled.
    pub(super) scan: Vec<ScanChunk>,
    /// The same for the vertex whose exact distance is computed.
    pub(super) vertex_scan: Vec<ScanChunk>,
    /// The box gaps of the chunks of `B` in a scan.
    pub(super) lower: Vec<f32>,
    /// How far from the segment of `scan` its skipped chunks are at least (see
    /// [`Pass::scan_segment`]).
    pub(super) scan_reach: f64,
    /// The smallest `f32` lifted squared distance from the end of that segment to the
    /// segments of `B` it computed: a hint for the exact value there.
    pub(super) scan_min1: f32,
    pub(super) stack: Vec<Piece>,
    /// The pieces of the envelope in `segment_max` (`envelope.rs`).
    pub(super) quads: Vec<Quad>,
    /// The intervals still to examine in `segment_max` (`envelope.rs`).
    pub(super) intervals: Vec<Interval>,
}

impl CurveScratch {
    /// Records the exact `d_B²` of vertex `i` of direction `dir`.
    #[inline(always)]
    pub(super) fn set_vertex(&mut self, dir: usize, i: usize, value: (f64, u32)) {
        self.vertex[dir][i] = value;
        self.touched[dir].push(i as u32);
    }

    /// Both directions' vertices unknown again (`NaN`), for sets of `points` points:
    /// only the entries written since the last reset are rewritten.
    #[inline(always)]
    pub(super) fn reset_vertices(&mut self, points: usize) {
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

/// One direction `A → B` of the curve kernel.
pub(super) struct Pass<'a, S: Lanes, const N: usize> {
    pub(super) s: S,
    pub(super) a: CurveRef<'a>,
    pub(super) b: CurveRef<'a>,
    pub(super) frame: &'a Frame<N>,
    pub(super) wraps: Wraps<S, N>,
    /// Half of every period (`+∞` when not wrapped), as vectors.
    pub(super) half: [S::V; N],
    /// Smallest distance from a point to a segment of `B` that crosses the seam relative
    /// to it: `min_n T_n/2 − L` (`L` the longest segment of `B`; `+∞` without a period).
    pub(super) seam_reach: f64,
    /// Coordinates too large for the `f32` filter: nothing is settled in `f32`.
    pub(super) wide: bool,
    /// The direction: `0` for `A → B`, `1` for `B → A` (which records of
    /// [`CurveScratch::vertex`] it keeps).
    pub(super) dir: usize,
    /// The last `(c2, segment_threshold(c2))`: `c2` changes a few times per pass while
    /// the threshold (a square root and a division) is asked for at every test.
    pub(super) theta: Cell<(f64, f32)>,
}

impl<S: Lanes, const N: usize> Pass<'_, S, N> {
    /// The `f32` threshold of the lifted (segment) tests for the running `c2`.
    #[inline(always)]
    pub(super) fn segment_threshold(&self, c2: f64) -> f32 {
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
    /// [`FilterBounds`](crate::metric::prepared::FilterBounds)).
    #[inline(always)]
    pub(super) fn upper(&self, m: f32) -> f64 {
        (f64::from(m) * (1.0 + self.frame.rel)).sqrt() * (1.0 + 1e-12) + self.frame.segment_delta
    }

    /// The exact `d_B(a_i)²` of vertex `i` of `A` and its nearest segment of `B` (the
    /// lowest index among ties), computed once per pass.
    #[inline(always)]
    pub(super) fn vertex(&self, i: usize, hint: f32, scratch: &mut CurveScratch) -> (f64, u32) {
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
    pub(super) fn exact_point(
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
    pub(super) fn nearest_from_scan(
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
    pub(super) fn scan<const ENDS: bool>(
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
}
