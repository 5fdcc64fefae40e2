//! The exact distance from a point to a segment under the periodic metric, its cheaper
//! bounds, and the `f64` scan of a set's segments by chunks.
//!
//! With `u = h(x − x_j)` (wrapped coordinate by coordinate) and `v = v_j`, the distance
//! from `x` to segment `j` is
//!
//! ```text
//! δ(x, s_j)² = min_{t∈[0,1]} f(t),    f(t) = Σ_n h(u_n − t v_n)²,
//! ```
//!
//! a convex quadratic on each piece of `[0, 1]` between the values of `t` where some
//! `u_n − t v_n` crosses `±T_n/2` (once per coordinate at most, since `|v_n| ≤ T_n/2`),
//! minimised on every piece in closed form ([`segment_distance2`]). When no coordinate
//! crosses (`|u_n − v_n| ≤ T_n/2`, almost always) there is one piece and the lifted
//! distance
//!
//! ```text
//! |u − t* v|²,    t* = clamp(u·v / |v|², 0, 1)
//! ```
//!
//! is exact ([`lifted_distance2`]); when one coordinate crosses, the nearer of the image
//! as it is and the image one period over in that coordinate is exact
//! ([`nearest_image`]). The lifted distance to any one image is an upper bound of `δ²`;
//! a lower bound for the segments that cross, at the cost of about one lifted distance
//! ([`seam_lower2`]):
//!
//! ```text
//! δ² ≥ Σ_n min_t h(u_n − t v_n)²,
//! ```
//!
//! each term 0 where `u_n − t v_n` passes 0, else reached at an end of the segment.
//!
//! `d_B(x) = min_j δ(x, s_j)` by chunks of eight segments ([`nearest`]): a chunk's box
//! (centre `c`, half-widths `w`, see `layout.rs`) bounds the distance to its segments
//! from below, `δ² ≥ Σ_n max(0, |h(x_n − c_n)| − w_n)²` ([`chunk_gap2`]), so a chunk whose
//! gap is above the nearest value found is skipped.

use super::layout::CurveRef;
use crate::metric::period::swrap;
use crate::metric::prepared::{fold, BOUND_MARGIN, LANES};

/// Exact `δ(a, s)²` from a point `a` (wrapped) to the segment from `b` (wrapped) along
/// `v`, under the periodic metric: the convex quadratic of every piece between the
/// values of `t` where some `u_n − t v_n` crosses `±T/2` (once per coordinate at most,
/// since `|v_n| ≤ T/2`), minimised in closed form (see the module docs). The kernels
/// take the single-piece path inline and call this only when a coordinate crosses.
pub(super) fn segment_distance2(
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
pub(super) fn point_segment2<const N: usize>(
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
pub(super) fn seam_lower2<const N: usize>(
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
pub(super) fn nearest_image<const N: usize>(
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
pub(super) fn lifted_distance2<const N: usize>(u: &[f64; N], v: &[f64; N], inv_len2: f64) -> f64 {
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
pub(super) fn load<const N: usize>(data: &[f64], at: usize) -> [f64; N] {
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
pub(in crate::metric) fn around(start: usize, t: usize, len: usize) -> usize {
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
pub(super) fn nearest<const N: usize>(
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
}
