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
//! The work comes in three phases, each in a file of its own under `metric/curve/`
//! whose module documentation gives its part of the maths:
//!
//! 1. **Blocks** (`blocks.rs`), eight segments of one set at a time, the blocks of both
//!    directions in one order, far from the other set first, so that `c` reaches its
//!    final value early whichever direction holds the maximum. `f32` windows around the
//!    other set's nearest chunk settle a segment by convexity (`|w + t v_i|` is convex
//!    in `t`, and so is the distance to one lifted segment of `B`; the `f32` lane code
//!    is `filter.rs`); a vertex they do not prove within `c` gets its exact `d_B`, which
//!    may raise `c`.
//! 2. **Open segments** (`segments.rs`), of both directions, largest window value
//!    first, tested again with the final `c`: `d_B` is 1-Lipschitz along a segment, so
//!    `max_t d_B(a_i + t v_i) ≤ (d_B(a_i) + d_B(a_{i+1}) + |v_i|)/2`; convexity with the
//!    segment of `B` nearest to an end; else a scan of `B`.
//! 3. **The envelope** (`envelope.rs`), exact, for the few segments left (those near the
//!    maximiser): the lower envelope of the Euclidean distances to a few periodic images
//!    of segments of `B`, a minimum of convex quadratics whose maximum is at an end or
//!    where two of them cross, grown lazily until the exact `d_B` attains its maximum;
//!    past eight rounds, a **branch and bound** on the chord and Lipschitz bounds
//!    (`bound.rs`).
//!
//! Beside them: the segments of every set as the kernels read them (`layout.rs`); the
//! exact point-to-segment distance under the periodic metric, its lower bounds and the
//! `f64` scan of a set's segments (`distance.rs`); and one direction of the kernel with
//! its buffers and the exact `d_B` of a point from an `f32` scan (`pass.rs`).
//!
//! The result is the maximum of exactly evaluated distances: the exact `h(A, B)` up to
//! rounding (and within [`CURVE_TOLERANCE`] below it on the branch-and-bound path).
//! Pairs are always evaluated in the order (smaller index, larger index), so the value
//! does not depend on which of the two sets is the query.

mod blocks;
mod bound;
mod distance;
mod envelope;
mod filter;
mod layout;
mod pass;
mod segments;

use std::cell::Cell;

use self::blocks::merged_order;
use self::filter::Wraps;
use self::pass::Pass;
use self::segments::largest_first;
use super::kernel::{each, Frame, Lanes, Portable, Scratch, Simd};
use super::prepared::PreparedSets;

pub(super) use self::distance::around;
pub(crate) use self::layout::CurveLayout;
pub(crate) use self::pass::CurveScratch;

/// Absolute accuracy of the `curve` metric: every value is within this much below the
/// exact Hausdorff distance between the polylines (and never above it, up to rounding).
pub const CURVE_TOLERANCE: f64 = 1e-10;

use crate::sets::Closure;

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
    use crate::metric::Period;
    use rand::{RngExt, SeedableRng};
    use std::f64::consts::PI;

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
}
