//! The **branch and bound** that ends phase 3 of the curve kernel for a segment the
//! lazy envelope leaves (never seen on the arm): within [`CURVE_TOLERANCE`] below the
//! exact maximum.
//!
//! A piece `[t₀, t₁]` of segment `i` of `A`, with `d_B` known at both ends, is bounded
//! two ways:
//!
//! ```text
//! Lipschitz:  max_{t∈[t₀,t₁]} d_B(a(t)) ≤ (d_B(a(t₀)) + d_B(a(t₁)) + |v_i|(t₁ − t₀)) / 2
//! chord:      max_{t∈[t₀,t₁]} d_B(a(t)) ≤ max_{τ∈[0,1]} min_j ((1 − τ) E_j(t₀) + τ E_j(t₁))
//! ```
//!
//! the second because every `E_j` (the Euclidean distance to one image of a segment
//! `s_j` of `B`) is convex along the piece and at least `d_B`; `j` runs over the
//! segments nearest to the ends and their neighbours ([`chord_bound`], the maximum of a
//! lower envelope of lines [`envelope_max`]). A piece whose bound is at most
//! `c +` [`CURVE_TOLERANCE`] is dropped, else split at the chord bound's maximiser (its
//! middle when that is within a fifth of an end), where the exact `d_B`
//! ([`nearest`]) may raise `c` ([`refine_segment`]).

use super::distance::{lifted_distance2, load, nearest};
use super::envelope::point_on;
use super::layout::CurveRef;
use super::CURVE_TOLERANCE;
use crate::metric::period::swrap;

/// Deepest refinement of one segment; the Lipschitz bound ends any refinement long
/// before (a segment of length `π√16` is below the tolerance after 37 halvings, and a
/// split removes at least a fifth of a piece).
const MAX_DEPTH: usize = 200;

/// A piece `[t0, t1]` of a segment of `A` still to examine, with `d_B` (not squared)
/// and the nearest segment of `B` at both ends.
#[derive(Debug, Clone, Copy)]
pub(super) struct Piece {
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
pub(super) fn refine_segment<const N: usize>(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_maximum_of_two_crossing_lines() {
        // 1 − τ and τ cross at τ = 1/2 with value 1/2; a flat line at 0.8 does not cut it.
        let (value, tau) = envelope_max(&[(1.0, 0.0), (0.0, 1.0), (0.8, 0.8)]);
        assert!((value - 0.5).abs() < 1e-15 && (tau - 0.5).abs() < 1e-15);
        let (value, tau) = envelope_max(&[(0.2, 0.9)]);
        assert!((value - 0.9).abs() < 1e-15 && tau == 1.0);
    }
}
