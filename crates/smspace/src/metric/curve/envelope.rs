//! Phase 3 of the curve kernel: **the envelope**, exact, for the few segments left
//! (those near the maximiser).
//!
//! For one periodic image of a segment `s_j` of `B`, `E_j(t) = |ã(t) − s̃_j|` (the
//! Euclidean distance between lifts) bounds `d_B(a(t))` from above, `a(t) = a_i + t v_i`.
//! The foot `s*(t)` on `s̃_j` is linear in `t`, clamped to 0 or 1, so
//!
//! ```text
//! E_j(t)² = |p + t q|² = α t² + β t + γ
//! ```
//!
//! piecewise in `t`, with at most three pieces ([`image_pieces`]), and the lower
//! envelope `F = min E_j²` over a set of images is a minimum of convex quadratics.
//! Between two points where the minimising image changes, `F` is one convex function,
//! at most its end values; so the maximum of `F` is at `t = 0, 1` (the vertices,
//! already in `c`) or at a root of `E_x² − E_y²` on a common piece ([`roots_in`]):
//! every such root where both exceed `c` is evaluated ([`segment_max`]).
//!
//! The envelope is **lazy** ([`Pass::exact_segment`]): it starts with the images of the
//! segments nearest to both ends (and up to three between them along `B`); `F ≥ d_B`,
//! so when the exact `d_B` at the maximiser `t*` of `F` equals `F(t*)` (up to a relative
//! `10⁻¹²` in the square) the segment's maximum is found; else the segment of `B`
//! nearest to `a(t*)` joins the envelope and the maximum is taken again. After eight
//! rounds, or more than 32 images (never seen on the arm), the segment goes to the
//! branch and bound (`bound.rs`).

use super::bound::refine_segment;
use super::distance::{lifted_distance2, load, nearest_image};
use super::layout::CurveRef;
use super::pass::{CurveScratch, Pass};
use crate::metric::kernel::Lanes;
use crate::metric::prepared::wrap;

/// Largest number of periodic images of segments of `B` that [`segment_max`] puts in
/// one envelope; past it the segment goes to the branch and bound.
const MAX_IMAGES: usize = 32;

/// An interval `[t_a, t_b]` of a segment of `A` with the images of the envelope
/// smallest at its ends, `(t_a, t_b, m_a, m_b)` (see [`segment_max`]).
pub(super) type Interval = (f64, f64, usize, usize);

/// One piece of `E_j(t)²` on `[t0, t1]`: `|p + t·q|² = α t² + β t + γ`.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Quad {
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

/// The point `a_i + t·v_i` of segment `i` of `A`, wrapped.
#[inline(always)]
pub(super) fn point_on<const N: usize>(
    a: CurveRef<'_>,
    i: usize,
    t: f64,
    period: &[f64; N],
) -> [f64; N] {
    let start = load::<N>(a.set.points, i);
    let v = load::<N>(a.dirs, i);
    let mut x = [0.0; N];
    for k in 0..N {
        x[k] = wrap(start[k] + t * v[k], period[k]);
    }
    x
}

impl<S: Lanes, const N: usize> Pass<'_, S, N> {
    /// Settles segment `i` of `A` exactly, raising `c2` to its maximum `max_t d_B²` when
    /// that is larger; `None` once `c2 > abort2`. The exact values at its ends come
    /// first, then the Lipschitz bound `(d_i + d_{i+1} + |v_i|)/2`, convexity with the
    /// segments nearest to either end, and last the lazy envelope (the module docs).
    #[inline(always)]
    pub(super) fn exact_segment(
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
        // attained (the module docs).
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
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
