//! The fast pair kernels: exact Hausdorff and mean Hausdorff distances between two
//! prepared sets.
//!
//! # How the directed Hausdorff part `max_a min_b g²(a, b)` is found without the full
//! `P × P` scan
//!
//! Both sets are cut into chunks of eight consecutive points, each with a bounding box
//! (centre, half-width per coordinate). The points of `A` are processed one chunk at a
//! time as a SIMD block (lanes over `a`, one point `b` broadcast). A running lower
//! bound `c` of the answer is kept: a point `a` only matters if its nearest distance
//! exceeds `c`, so as soon as any `b` with `g²(a, b) ≤ c` is seen, `a` is settled (the
//! early break of Taha & Hanbury 2015).
//!
//! 1. *Centre table.* The squared distances between all chunk centres of `A` and `B`
//!    give, for every chunk of either set, the nearest chunk of the other (a warm
//!    start: the sets are ordered curves, so a point's nearest neighbour lies near the
//!    nearest chunk) and an ordering: blocks far from the other set first, so that `c`
//!    reaches its final value early. Without that order the matrix of 2500 arm sets
//!    takes 30 % longer. The table only steers the work, so it is computed in `f32`,
//!    sixteen chunks per vector (about 10 % less time than in `f64`).
//! 2. *Window.* The points of chunk `β` nearest to block `α` are scanned from the
//!    middle of the chunk outward (one more point past it); the scan stops as soon as
//!    every lane is `≤ c`.
//! 3. *Exact search.* Lanes still open get their exact nearest distance: the other
//!    chunks of `B` are visited outward from `β` (`β` itself was covered by the
//!    window), and a chunk is scanned only if its bounding box (per-coordinate periodic
//!    interval around the centre) can hold a point closer than a lane's best so far
//!    (`|h(a_n − b_n)| ≥ |h(a_n − centre_n)| − width_n`); the search stops as soon as
//!    every lane is `≤ c`. The exact distances found raise `c`.
//!
//! The result is the maximum over `a` of exactly computed minima: the same number the
//! brute force gives, for any order of work (up to rounding: the sums of squares use
//! fused multiply-adds; on the arm sets the largest difference is 9e-16). The symmetric
//! distance runs `B → A` starting from `c = h(A, B)`, where most blocks settle at once.
//! Bounds carry a relative margin ([`BOUND_MARGIN`]) so that rounding never prunes a
//! winner.

use super::prepared::{fold, PreparedSets, SetRef, BOUND_MARGIN, LANES, WIDE};

/// Window length of the warm-started scan (number of `b` tried per block).
///
/// A window centred on the middle of chunk `β` that runs to its end covers every point of
/// that chunk (`start − 4 ..= start + 4`), so the exact search can skip `β`.
const WINDOW: usize = 9;
const _: () = assert!(WINDOW > LANES);

/// Whether the window scan already went through every point of the nearest chunk.
#[derive(Debug, Clone, Copy)]
enum Scanned {
    /// The window ran to its end: chunk `β` is covered.
    Yes,
    /// No window ran.
    No,
}

/// Largest block count ordered by the branch-free rank sort.
const RANK_SORT_MAX: usize = 16;

/// Reusable buffers of one worker thread.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    row_key: Vec<f32>,
    row_near: Vec<u32>,
    col_key: Vec<f32>,
    col_near: Vec<u32>,
    order: Vec<u64>,
    curve: super::curve::CurveScratch,
}

/// The centre tables of both directions, the order buffer and the curve buffers.
type ScratchParts<'a> = (
    &'a [f32],
    &'a [u32],
    &'a [f32],
    &'a [u32],
    &'a mut Vec<u64>,
    &'a mut super::curve::CurveScratch,
);

impl Scratch {
    /// Borrows the centre tables (filled by [`center_table`]) and the work buffers.
    pub(crate) fn parts(&mut self) -> ScratchParts<'_> {
        (
            &self.row_key,
            &self.row_near,
            &self.col_key,
            &self.col_near,
            &mut self.order,
            &mut self.curve,
        )
    }
}

/// Shape of the prepared sets, copied out for the kernels.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shape {
    points: usize,
    points_pad: usize,
    chunks: usize,
    chunks_wide: usize,
    period: f64,
}

impl Shape {
    pub(crate) fn of(prepared: &PreparedSets) -> Self {
        Self {
            points: prepared.points(),
            points_pad: prepared.points_pad(),
            chunks: prepared.chunks(),
            chunks_wide: prepared.chunks_wide(),
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
pub(crate) fn load_block<const N: usize>(
    rows: &[f64],
    stride: usize,
    block: usize,
) -> [[f64; LANES]; N] {
    let mut a = [[0.0; LANES]; N];
    for (k, lanes) in a.iter_mut().enumerate() {
        lanes.copy_from_slice(&rows[k * stride + block * LANES..][..LANES]);
    }
    a
}

#[inline(always)]
fn load_point<const N: usize>(set: SetRef<'_>, _shape: Shape, j: usize) -> [f64; N] {
    let mut b = [0.0; N];
    b.copy_from_slice(&set.points[j * N..(j + 1) * N]);
    b
}

/// `g²(a_l, b)` for the eight lanes: `Σ_n h(a_n − b_n)²`, summed in coordinate order.
#[inline(always)]
pub(crate) fn dist2<const N: usize>(
    a: &[[f64; LANES]; N],
    b: &[f64; N],
    period: f64,
) -> [f64; LANES] {
    let mut acc = [0.0; LANES];
    for k in 0..N {
        let bk = b[k];
        for l in 0..LANES {
            let w = fold(a[k][l] - bk, period);
            acc[l] = w.mul_add(w, acc[l]);
        }
    }
    acc
}

/// The `t`-th index of a scan centred on `start`: `start, start+1, start−1, start+2, …`
/// (modulo `len`).
#[inline(always)]
pub(crate) fn around(start: usize, t: usize, len: usize) -> usize {
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

/// For every chunk of `a`, the nearest chunk of `b` by centre distance and that squared
/// distance, written to `key` and `near` (one entry per chunk of `a`).
///
/// The table only orders the work and picks where each scan starts; no distance depends
/// on it. It is therefore computed in `f32`, sixteen chunks of `a` per vector, while the
/// centres of `b` are broadcast one by one: the running minimum stays in registers and
/// needs no horizontal reduction. Indices are kept as `f32` (small exact integers) so
/// that the selects compile to vector blends. Ties keep the lower index.
#[inline(always)]
fn nearest_chunks<const N: usize>(
    a: SetRef<'_>,
    b: SetRef<'_>,
    shape: Shape,
    key: &mut Vec<f32>,
    near: &mut Vec<u32>,
) {
    key.clear();
    near.clear();
    let period = shape.period as f32;
    for v in 0..shape.chunks_wide / WIDE {
        let mut ca = [[0.0f32; WIDE]; N];
        for (k, lanes) in ca.iter_mut().enumerate() {
            lanes.copy_from_slice(&a.centers_wide[k * shape.chunks_wide + v * WIDE..][..WIDE]);
        }
        let mut best = [f32::INFINITY; WIDE];
        let mut best_at = [0.0f32; WIDE];
        for beta in 0..shape.chunks {
            let mut cb = [0.0f32; N];
            cb.copy_from_slice(&b.centers_narrow[beta * N..(beta + 1) * N]);
            let mut d = [0.0f32; WIDE];
            for k in 0..N {
                for l in 0..WIDE {
                    let u = (ca[k][l] - cb[k]).abs();
                    let v = period - u;
                    let w = if v < u { v } else { u };
                    d[l] = w.mul_add(w, d[l]);
                }
            }
            let beta_f = beta as f32;
            for l in 0..WIDE {
                let closer = d[l] < best[l];
                best[l] = if closer { d[l] } else { best[l] };
                best_at[l] = if closer { beta_f } else { best_at[l] };
            }
        }
        key.extend_from_slice(&best);
        near.extend(best_at.iter().map(|&x| x as u32));
    }
    key.truncate(shape.chunks);
    near.truncate(shape.chunks);
}

/// For both directions, the nearest chunk of the other set to every chunk (by centre
/// distance) and that squared distance: `row_*` for `A → B`, `col_*` for `B → A`.
#[inline(always)]
pub(crate) fn center_table<const N: usize>(
    a: SetRef<'_>,
    b: SetRef<'_>,
    shape: Shape,
    scratch: &mut Scratch,
) {
    nearest_chunks::<N>(a, b, shape, &mut scratch.row_key, &mut scratch.row_near);
    nearest_chunks::<N>(b, a, shape, &mut scratch.col_key, &mut scratch.col_near);
}

/// Window scan of one block around `start`: per-lane smallest `g²` over the window.
/// Stops early (and says so) once every lane is `≤ settle`.
#[inline(always)]
fn window<const N: usize>(
    a: &[[f64; LANES]; N],
    b: SetRef<'_>,
    shape: Shape,
    start: usize,
    settle: f64,
) -> ([f64; LANES], bool) {
    let mut best = [f64::INFINITY; LANES];
    for t in 0..WINDOW.min(shape.points) {
        let j = around(start, t, shape.points);
        let d = dist2(a, &load_point::<N>(b, shape, j), shape.period);
        for l in 0..LANES {
            best[l] = min(best[l], d[l]);
        }
        let mut settled = true;
        for l in 0..LANES {
            settled &= best[l] <= settle;
        }
        if settled {
            return (best, true);
        }
    }
    (best, false)
}

/// Lowers `best` (per-lane `g²` upper bounds) to the exact nearest distances to `B`,
/// except for lanes that reach `≤ settle`, which may stop there. Chunks of `B` are
/// visited outward from `near`; a chunk is scanned only if its bounding box can hold a
/// point closer than the best so far for some open lane.
#[inline(always)]
fn refine<const N: usize>(
    a: &[[f64; LANES]; N],
    mut best: [f64; LANES],
    settle: f64,
    b: SetRef<'_>,
    shape: Shape,
    near: usize,
    near_scanned: Scanned,
) -> [f64; LANES] {
    let shrink = 1.0 - 4.0 * BOUND_MARGIN;
    let first = match near_scanned {
        Scanned::Yes => 1,
        Scanned::No => 0,
    };
    for t in first..shape.chunks {
        let q = around(near, t, shape.chunks);
        let mut open = false;
        for l in 0..LANES {
            open |= best[l] > settle;
        }
        if !open {
            break;
        }
        let mut center = [0.0; N];
        center.copy_from_slice(&b.centers[q * N..(q + 1) * N]);
        let mut width = [0.0; N];
        width.copy_from_slice(&b.widths[q * N..(q + 1) * N]);
        // Squared distance to the chunk's bounding box: a lower bound of `g²` to each of
        // its points, coordinate by coordinate (`|h(a − b)| ≥ |h(a − centre)| − width`).
        let mut lower = [0.0; LANES];
        for k in 0..N {
            for l in 0..LANES {
                let gap = fold(a[k][l] - center[k], shape.period) - width[k];
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
        for j in q * LANES..(q + 1) * LANES {
            let d = dist2(a, &load_point::<N>(b, shape, j), shape.period);
            for l in 0..LANES {
                best[l] = min(best[l], d[l]);
            }
        }
    }
    best
}

/// Fills `scratch_order[..chunks]` with the blocks of a set ordered far from the other
/// set first (by `key`, the squared distance from a block's centre to the other set's
/// nearest centre), so that the running lower bound reaches its final value early.
#[inline(always)]
pub(crate) fn far_first(key: &[f32], chunks: usize, scratch_order: &mut Vec<u64>) {
    scratch_order.resize(chunks.max(scratch_order.len()), 0);
    // The order only decides how soon blocks can be settled, never the result, so the
    // keys may be coarse: a non-negative f32 orders like its bits, and the block index
    // takes the low bits, which makes the keys distinct integers. Up to RANK_SORT_MAX
    // blocks they are ranked without branches (the insertion and generic sorts
    // mispredicted); past that the comparison sort is used.
    let order = &mut scratch_order[..chunks];
    if chunks <= RANK_SORT_MAX {
        // Rank sort without branches: the keys are distinct (the block index is in the
        // low bits), so the rank of a key is the number of larger keys.
        let mut packed = [0u64; RANK_SORT_MAX];
        for (alpha, slot) in packed.iter_mut().enumerate().take(chunks) {
            *slot = (u64::from(key[alpha].to_bits()) << 8) | alpha as u64;
        }
        for (alpha, &x) in packed.iter().enumerate().take(chunks) {
            let mut rank = 0u64;
            for &y in &packed {
                rank += u64::from(y > x);
            }
            order[rank as usize] = alpha as u64;
        }
    } else {
        for (alpha, slot) in order.iter_mut().enumerate() {
            *slot = alpha as u64;
        }
        order.sort_unstable_by(|&x, &y| key[y as usize].total_cmp(&key[x as usize]));
    }
}

/// `max(c, max_{a∈A} min_{b∈B} g²(a, b))`, or `None` as soon as it is proven to exceed
/// `abort`. `(key[α], near[α])`: squared distance from the centre of block `α` of `A`
/// to the nearest centre of `B`, and that chunk.
#[inline(always)]
fn directed_hausdorff<const N: usize>(
    a_set: SetRef<'_>,
    b_set: SetRef<'_>,
    shape: Shape,
    (key, near): (&[f32], &[u32]),
    mut c: f64,
    abort: f64,
    scratch_order: &mut Vec<u64>,
) -> Option<f64> {
    far_first(key, shape.chunks, scratch_order);
    let order = &scratch_order[..shape.chunks];
    for &alpha in order.iter() {
        let alpha = alpha as usize;
        let near = near[alpha] as usize;
        let a = load_block::<N>(a_set.coords, shape.points_pad, alpha);
        let start = (near * LANES + LANES / 2).min(shape.points - 1);
        // With nothing found yet (c = 0) no window can settle the block: go straight to
        // the exact search, which scans the nearest chunk first anyway.
        let (best, settled) = if c > 0.0 {
            window(&a, b_set, shape, start, c)
        } else {
            ([f64::INFINITY; LANES], false)
        };
        if settled {
            continue;
        }
        let scanned = if c > 0.0 { Scanned::Yes } else { Scanned::No };
        let best = refine(&a, best, c, b_set, shape, near, scanned);
        c = max(c, lanes_max(&best));
        if c > abort {
            return None;
        }
    }
    Some(c)
}

/// `Σ_{a∈A} min_{b∈B} g(a, b)`, summed in point order.
#[inline(always)]
fn directed_mean_sum<const N: usize>(
    a_set: SetRef<'_>,
    b_set: SetRef<'_>,
    shape: Shape,
    near: &[u32],
) -> f64 {
    let mut sum = 0.0;
    for block in 0..shape.chunks {
        let a = load_block::<N>(a_set.coords, shape.points_pad, block);
        let near = near[block] as usize;
        let start = (near * LANES + LANES / 2).min(shape.points - 1);
        let (best, _) = window(&a, b_set, shape, start, f64::NEG_INFINITY);
        let best = refine(
            &a,
            best,
            f64::NEG_INFINITY,
            b_set,
            shape,
            near,
            Scanned::Yes,
        );
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
    center_table::<N>(a, b, shape, scratch);
    let Scratch {
        row_key,
        row_near,
        col_key,
        col_near,
        order,
        ..
    } = scratch;
    let c = directed_hausdorff::<N>(a, b, shape, (row_key, row_near), 0.0, abort, order)?;
    let c = directed_hausdorff::<N>(b, a, shape, (col_key, col_near), c, abort, order)?;
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
    center_table::<N>(a, b, shape, scratch);
    let p = shape.points as f64;
    let ab = directed_mean_sum::<N>(a, b, shape, &scratch.row_near) / p;
    let ba = directed_mean_sum::<N>(b, a, shape, &scratch.col_near) / p;
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

    /// Reads one value per cache line of set `j`, so that its data is on its way to the
    /// cache while another pair is computed (a software prefetch without `unsafe`).
    fn touch(&mut self, _j: usize) {}
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
            // Its own runtime dispatch (one per pair, negligible next to the pair), so
            // that the curve kernel is compiled once per SIMD level and coordinate
            // count instead of once per driver as well.
            super::MetricKind::Curve => {
                super::curve::curve_pair(self.prepared, i, j, limit, self.scratch)
            }
        }
    }

    #[inline(always)]
    fn touch(&mut self, j: usize) {
        let set = self.prepared.set(j);
        let mut sum = 0.0;
        for part in [set.coords, set.points, set.centers, set.widths] {
            for x in part.iter().step_by(8) {
                sum += x;
            }
        }
        for part in [set.centers_narrow, set.centers_wide] {
            for &x in part.iter().step_by(16) {
                sum += f64::from(x);
            }
        }
        std::hint::black_box(sum);
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
            super::MetricKind::Curve => {
                unreachable!(
                    "the curve metric is compiled for up to 16 coordinates, checked before"
                )
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
