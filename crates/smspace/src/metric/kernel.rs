//! The fast pair kernels: exact Hausdorff and mean Hausdorff distances between two
//! prepared sets.
//!
//! # How the directed Hausdorff part `max_a min_b g²(a, b)` is found without the full
//! `P × P` scan
//!
//! The points of `A` are taken eight at a time (one SIMD block, lanes over `a`, one
//! point `b` broadcast). A running lower bound `c` of the answer is kept: a point `a`
//! only matters if its nearest distance exceeds `c`, so as soon as any `b` with
//! `g²(a, b) ≤ c` is seen, `a` is settled (the early break of Taha & Hanbury 2015).
//!
//! 1. *Window pass.* Sets are ordered closed curves, so the nearest `b` of consecutive
//!    points `a` moves little: each block scans a short window of `b` around the
//!    position found for the previous block (warm start), keeping for every lane the
//!    smallest distance seen, an upper bound of its nearest distance. A block whose
//!    lanes are all `≤ c` is settled; the others wait, with their upper bounds.
//! 2. *Exact pass.* Waiting blocks are taken by decreasing upper bound. A block whose
//!    bound is `≤ c` is settled, and so are all after it. Otherwise its unsettled lanes
//!    get their exact nearest distance by a best-first scan over the bounding balls
//!    of `B` (runs of eight points: `g(a, b) ≥ g(a, centre) − radius`), skipping balls
//!    that cannot beat the best so far and stopping as soon as every lane is `≤ c`;
//!    the exact distances found raise `c`.
//!
//! The result is the maximum over `a` of exactly computed minima: the same number the
//! brute force gives, for any order of work. The symmetric distance runs `B → A`
//! starting from `c = h(A, B)`, where most blocks settle in one step.

use super::prepared::{fold, PreparedSets, SetRef, BOUND_MARGIN, LANES};

/// Window length of the warm-started pass (number of `b` tried per block).
const WINDOW: usize = 7;

/// Reusable buffers of one worker thread.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    pending: Vec<Pending>,
    bounds: Vec<[f64; LANES]>,
    order: Vec<(f64, u32)>,
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    upper: f64,
    block: u32,
    best: [f64; LANES],
}

/// Shape of the prepared sets, copied out for the kernels.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shape {
    points: usize,
    points_pad: usize,
    chunks: usize,
    period: f64,
}

impl Shape {
    pub(crate) fn of(prepared: &PreparedSets) -> Self {
        Self {
            points: prepared.points(),
            points_pad: prepared.points_pad(),
            chunks: prepared.chunks(),
            period: prepared.period_value(),
        }
    }
}

#[inline(always)]
fn min(x: f64, y: f64) -> f64 {
    if y < x {
        y
    } else {
        x
    }
}

#[inline(always)]
fn max(x: f64, y: f64) -> f64 {
    if y > x {
        y
    } else {
        x
    }
}

#[inline(always)]
fn lanes_max(v: &[f64; LANES]) -> f64 {
    let a = [
        max(v[0], v[4]),
        max(v[1], v[5]),
        max(v[2], v[6]),
        max(v[3], v[7]),
    ];
    max(max(a[0], a[2]), max(a[1], a[3]))
}

#[inline(always)]
fn load_block<const N: usize>(set: SetRef<'_>, shape: Shape, block: usize) -> [[f64; LANES]; N] {
    let mut a = [[0.0; LANES]; N];
    for (k, lanes) in a.iter_mut().enumerate() {
        lanes.copy_from_slice(&set.coords[k * shape.points_pad + block * LANES..][..LANES]);
    }
    a
}

#[inline(always)]
fn load_point<const N: usize>(set: SetRef<'_>, shape: Shape, j: usize) -> [f64; N] {
    let mut b = [0.0; N];
    for (k, x) in b.iter_mut().enumerate() {
        *x = set.coords[k * shape.points_pad + j];
    }
    b
}

/// `g²(a_l, b)` for the eight lanes: `Σ_n h(a_n − b_n)²`, summed in coordinate order.
#[inline(always)]
fn dist2<const N: usize>(a: &[[f64; LANES]; N], b: &[f64; N], period: f64) -> [f64; LANES] {
    let mut acc = [0.0; LANES];
    for k in 0..N {
        let bk = b[k];
        for l in 0..LANES {
            let w = fold(a[k][l] - bk, period);
            acc[l] += w * w;
        }
    }
    acc
}

/// The `t`-th index of a scan centred on `start`: `start, start+1, start−1, start+2, …`.
#[inline(always)]
fn around(start: usize, t: usize, points: usize) -> usize {
    let step = t.div_ceil(2) % points;
    if t % 2 == 1 {
        let j = start + step;
        if j >= points {
            j - points
        } else {
            j
        }
    } else if start >= step {
        start - step
    } else {
        start + points - step
    }
}

/// Warm-started window scan of one block: per-lane smallest `g²` over the window, and
/// the next block's starting index. Stops early once every lane is `≤ settle`.
#[inline(always)]
fn window<const N: usize>(
    a: &[[f64; LANES]; N],
    b: SetRef<'_>,
    shape: Shape,
    start: usize,
    settle: f64,
) -> ([f64; LANES], usize, bool) {
    let mut best = [f64::INFINITY; LANES];
    let mut first = (f64::INFINITY, start);
    let mut last = (f64::INFINITY, start);
    let steps = WINDOW.min(shape.points);
    for t in 0..steps {
        let j = around(start, t, shape.points);
        let d = dist2(a, &load_point::<N>(b, shape, j), shape.period);
        for l in 0..LANES {
            best[l] = min(best[l], d[l]);
        }
        if d[0] < first.0 {
            first = (d[0], j);
        }
        if d[LANES - 1] < last.0 {
            last = (d[LANES - 1], j);
        }
        if lanes_max(&best) <= settle {
            return (best, last.1, true);
        }
    }
    // Move on by half the drift seen across this block, in the direction it went.
    let p = shape.points as isize;
    let mut drift = last.1 as isize - first.1 as isize;
    if drift > p / 2 {
        drift -= p;
    } else if drift < -p / 2 {
        drift += p;
    }
    let next = (last.1 as isize + drift / 2).rem_euclid(p) as usize;
    (best, next, false)
}

/// Lowers `best` (per-lane `g²` upper bounds) to the exact nearest distances to `B`,
/// except that lanes already `≤ settle` may stop early, and the whole search stops as
/// soon as every lane is `≤ settle`.
#[inline(always)]
fn refine<const N: usize>(
    a: &[[f64; LANES]; N],
    mut best: [f64; LANES],
    settle: f64,
    b: SetRef<'_>,
    shape: Shape,
    scratch: &mut Scratch,
) -> [f64; LANES] {
    let Scratch { bounds, order, .. } = scratch;
    bounds.clear();
    order.clear();
    for q in 0..shape.chunks {
        let mut center = [0.0; N];
        center.copy_from_slice(&b.centers[q * N..(q + 1) * N]);
        let d = dist2(a, &center, shape.period);
        let radius = b.radii[q];
        let mut lower = [0.0; LANES];
        let mut key = f64::INFINITY;
        for l in 0..LANES {
            let gap = d[l].sqrt() * (1.0 - BOUND_MARGIN) - radius;
            lower[l] = if gap > 0.0 { gap * gap } else { 0.0 };
            if best[l] > settle {
                key = min(key, lower[l]);
            }
        }
        bounds.push(lower);
        order.push((key, q as u32));
    }
    order.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    for &(key, q) in order.iter() {
        let q = q as usize;
        let mut worst_open = f64::NEG_INFINITY;
        let mut useful = false;
        for l in 0..LANES {
            if best[l] > settle {
                worst_open = max(worst_open, best[l]);
                useful |= bounds[q][l] < best[l];
            }
        }
        if worst_open == f64::NEG_INFINITY || key >= worst_open {
            break;
        }
        if !useful {
            continue;
        }
        for j in q * LANES..(q + 1) * LANES {
            let d = dist2(a, &load_point::<N>(b, shape, j), shape.period);
            for l in 0..LANES {
                best[l] = min(best[l], d[l]);
            }
        }
    }
    best
}

/// `max(c, max_{a∈A} min_{b∈B} g²(a, b))`, or `None` as soon as it is proven to exceed
/// `abort` (pass `f64::INFINITY` for no such limit).
#[inline(always)]
pub(crate) fn directed_hausdorff<const N: usize>(
    a_set: SetRef<'_>,
    b_set: SetRef<'_>,
    shape: Shape,
    mut c: f64,
    abort: f64,
    scratch: &mut Scratch,
) -> Option<f64> {
    let mut pending = std::mem::take(&mut scratch.pending);
    pending.clear();
    let mut start = 0;
    for block in 0..shape.points_pad / LANES {
        let a = load_block::<N>(a_set, shape, block);
        let (best, next, settled) = window(&a, b_set, shape, start, c);
        start = next;
        if !settled {
            pending.push(Pending {
                upper: lanes_max(&best),
                block: block as u32,
                best,
            });
        }
    }
    pending.sort_unstable_by(|x, y| y.upper.total_cmp(&x.upper).then(x.block.cmp(&y.block)));
    let mut result = Some(c);
    for item in &pending {
        if item.upper <= c {
            break;
        }
        let a = load_block::<N>(a_set, shape, item.block as usize);
        let best = refine(&a, item.best, c, b_set, shape, scratch);
        c = max(c, lanes_max(&best));
        if c > abort {
            result = None;
            break;
        }
        result = Some(c);
    }
    scratch.pending = pending;
    result
}

/// `Σ_{a∈A} min_{b∈B} g(a, b)`, summed in point order.
#[inline(always)]
pub(crate) fn directed_mean_sum<const N: usize>(
    a_set: SetRef<'_>,
    b_set: SetRef<'_>,
    shape: Shape,
    scratch: &mut Scratch,
) -> f64 {
    let mut sum = 0.0;
    let mut start = 0;
    for block in 0..shape.points_pad / LANES {
        let a = load_block::<N>(a_set, shape, block);
        let (best, next, _) = window(&a, b_set, shape, start, f64::NEG_INFINITY);
        start = next;
        let best = refine(&a, best, f64::NEG_INFINITY, b_set, shape, scratch);
        for (l, d2) in best.iter().enumerate() {
            if block * LANES + l < shape.points {
                sum += d2.sqrt();
            }
        }
    }
    sum
}

/// Symmetric Hausdorff distance `ρ(A, B)`, or `None` once proven `> limit`.
#[inline(always)]
pub(crate) fn hausdorff<const N: usize>(
    a: SetRef<'_>,
    b: SetRef<'_>,
    shape: Shape,
    limit: f64,
    scratch: &mut Scratch,
) -> Option<f64> {
    let abort = if limit.is_finite() {
        limit * limit
    } else {
        f64::INFINITY
    };
    let c = directed_hausdorff::<N>(a, b, shape, 0.0, abort, scratch)?;
    let c = directed_hausdorff::<N>(b, a, shape, c, abort, scratch)?;
    Some(c.sqrt())
}

/// Mean Hausdorff distance: the average of the two mean directed distances.
#[inline(always)]
pub(crate) fn mean_hausdorff<const N: usize>(
    a: SetRef<'_>,
    b: SetRef<'_>,
    shape: Shape,
    scratch: &mut Scratch,
) -> f64 {
    let p = shape.points as f64;
    let ab = directed_mean_sum::<N>(a, b, shape, scratch) / p;
    let ba = directed_mean_sum::<N>(b, a, shape, scratch) / p;
    0.5 * (ab + ba)
}

/// Brute force over the prepared layout, for coordinate counts without a fixed kernel
/// (`N > 16`): `(max_a min_b g², max_b min_a g², Σ_a min_b g, Σ_b min_a g)`.
pub(crate) fn brute_pair(a: SetRef<'_>, b: SetRef<'_>, prepared: &PreparedSets) -> [f64; 4] {
    let p = prepared.points();
    let pp = prepared.points_pad();
    let dims = prepared.dims_pad();
    let period = prepared.period_value();
    let mut row_min = vec![f64::INFINITY; p];
    let mut col_min = vec![f64::INFINITY; p];
    for i in 0..p {
        for j in 0..p {
            let mut d2 = 0.0;
            for k in 0..dims {
                let w = fold(a.coords[k * pp + i] - b.coords[k * pp + j], period);
                d2 += w * w;
            }
            row_min[i] = min(row_min[i], d2);
            col_min[j] = min(col_min[j], d2);
        }
    }
    let fold_max = |v: &[f64]| v.iter().fold(0.0, |m: f64, &x| max(m, x));
    let fold_sum = |v: &[f64]| v.iter().fold(0.0, |s: f64, &x| s + x.sqrt());
    [
        fold_max(&row_min),
        fold_max(&col_min),
        fold_sum(&row_min),
        fold_sum(&col_min),
    ]
}

/// Evaluates distances between prepared sets; implemented once per coordinate count so
/// that the kernels inline with their fixed `N`.
pub(crate) trait Eval {
    /// `ρ(set i, set j)`, or `None` once it is proven to exceed `limit`.
    fn distance(&mut self, i: usize, j: usize, limit: f64) -> Option<f64>;
}

/// Work run under runtime SIMD dispatch: it receives an [`Eval`] compiled for the
/// machine's best instruction set.
pub(crate) trait Driver {
    /// What the work returns.
    type Output;
    /// Runs the work; must be `#[inline(always)]` so that it is compiled in the
    /// dispatched context.
    fn drive<E: Eval>(self, eval: &mut E) -> Self::Output;
}

struct Evaluator<'a, const N: usize> {
    prepared: &'a PreparedSets,
    kind: super::MetricKind,
    shape: Shape,
    scratch: &'a mut Scratch,
}

impl<const N: usize> Eval for Evaluator<'_, N> {
    #[inline(always)]
    fn distance(&mut self, i: usize, j: usize, limit: f64) -> Option<f64> {
        let a = self.prepared.set(i);
        let b = self.prepared.set(j);
        match self.kind {
            super::MetricKind::Hausdorff => hausdorff::<N>(a, b, self.shape, limit, self.scratch),
            super::MetricKind::MeanHausdorff => {
                Some(mean_hausdorff::<N>(a, b, self.shape, self.scratch))
            }
        }
    }
}

struct BruteEvaluator<'a> {
    prepared: &'a PreparedSets,
    kind: super::MetricKind,
}

impl Eval for BruteEvaluator<'_> {
    fn distance(&mut self, i: usize, j: usize, _limit: f64) -> Option<f64> {
        let [ab, ba, sum_ab, sum_ba] =
            brute_pair(self.prepared.set(i), self.prepared.set(j), self.prepared);
        Some(match self.kind {
            super::MetricKind::Hausdorff => max(ab, ba).sqrt(),
            super::MetricKind::MeanHausdorff => {
                let p = self.prepared.points() as f64;
                0.5 * (sum_ab / p + sum_ba / p)
            }
        })
    }
}

struct Job<'a, D> {
    prepared: &'a PreparedSets,
    kind: super::MetricKind,
    scratch: &'a mut Scratch,
    driver: D,
}

impl<D: Driver> pulp::WithSimd for Job<'_, D> {
    type Output = D::Output;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> D::Output {
        let Job {
            prepared,
            kind,
            scratch,
            driver,
        } = self;
        let shape = Shape::of(prepared);
        macro_rules! fixed {
            ($n:literal) => {
                driver.drive(&mut Evaluator::<$n> {
                    prepared,
                    kind,
                    shape,
                    scratch,
                })
            };
        }
        match prepared.dims_pad() {
            2 => fixed!(2),
            4 => fixed!(4),
            8 => fixed!(8),
            16 => fixed!(16),
            _ => driver.drive(&mut BruteEvaluator { prepared, kind }),
        }
    }
}

/// Runs `driver` with the kernels compiled for the best instruction set of this CPU
/// (AVX-512, AVX2 + FMA, or plain code), chosen at run time.
pub(crate) fn dispatch<D: Driver>(
    prepared: &PreparedSets,
    kind: super::MetricKind,
    scratch: &mut Scratch,
    driver: D,
) -> D::Output {
    pulp::Arch::new().dispatch(Job {
        prepared,
        kind,
        scratch,
        driver,
    })
}
