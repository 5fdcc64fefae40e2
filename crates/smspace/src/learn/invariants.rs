//! The `invariants` law: the functions of the motors that the sensors cannot tell apart
//! within a sensory neighbourhood, found once for the whole log, and the kernel sets as
//! their level sets.
//!
//! # Why
//!
//! A local fit of `ŝ(m)` on the samples within a bandwidth `h` of `m` averages the law
//! over `h` in every motor direction: on the paper's arm (4 motors, a retina that changes
//! over a few tenths of a radian) `h` is 0.24 rad at 10⁶ samples, and the direction of
//! the kernel the fit gives is 0.3 rad off (median; README, "Kernel sets from recorded
//! data"). The kernels need the law's level sets, not its values: this method learns the
//! level sets directly, from pairs of samples that read the same sensor values.
//!
//! # The basis
//!
//! Per motor `j` three functions `b_j(x)`: `(1, cos ω x, sin ω x)` for a periodic motor of
//! period `T` (`ω = 2π/T`), `(1, u, 2u² − 1)` with `u = (2x − low − high)/(high − low)`
//! for a bounded one. The basis `φ(m)` is their tensor product without the constant,
//! `F = 3^N − 1` functions: for hinges, the trigonometric polynomials of degree at most
//! one in every joint. A chain of hinges places every link by such polynomials exactly
//! (`x = Σ_i l_i cos(θ_1 + … + θ_i)`, and `cos α`, `sin α` of the orientation
//! `α = Σ θ_i`), so on the paper's arm every coordinate of the retina's pose is a linear
//! combination of `φ`; the method does not know this, it finds those combinations.
//!
//! # The invariants
//!
//! Every fitted sample `i` is paired with the fitted sample `j(i)` nearest to it in
//! sensor space (each sensor divided by its standard deviation over the log). When the
//! sensors are a function of the sensor's pose and tell poses apart, a function of `m` is
//! constant on the kernels exactly when it is a function of the pose; such a function
//! changes little between `i` and `j(i)` (as little as their readings), while a function
//! that changes along the kernels differs between them by about its spread, since `j(i)`
//! lies anywhere on the kernel of `i`'s reading. With
//!
//! ```text
//! Σ = Cov(φ)   (over the fitted samples),    C = mean_i (φ(m_i) − φ(m_j(i))) (φ(m_i) − φ(m_j(i)))ᵀ,
//! ```
//!
//! the generalised symmetric eigenproblem `C w = λ Σ w` gives, for `z = wᵀ φ` with
//! `wᵀ Σ w = 1`, `λ = E[(z_i − z_j(i))²] / Var z`: 2 for a function whose values at the
//! pair are independent, towards 0 for an invariant. The **invariants** are the
//! eigenvectors of the smallest `λ` up to the largest gap: the `k` that maximises
//! `λ_{k+1} / max(λ_k, ZERO_SHARE × threshold)` among the `λ_k` below
//! `invariance_threshold` (default 0.4; [`ZERO_SHARE`] = 0.01: ratios between exact
//! invariants are rounding), when that
//! ratio is at least [`MIN_GAP`] (else all the `λ` below the threshold); or the
//! `invariants` smallest when that count is given (at most [`MAX_INVARIANTS`]); without
//! a given count, at least the rank `r` of `∂s/∂m` that the data show (see
//! [`super::noise`]): fewer than `r` invariants would trace sets of more than the
//! kernels' dimension `N − r`:
//! `z(m) = Wᵀ (φ(m) − μ)`, `Wᵀ Σ W = I`. Several logs (environments) pool their pairs
//! and samples into one `Σ` and one `C`: the invariants are common to all of them.
//!
//! # Aliased pairs
//!
//! Two poses far apart can read nearly the same sensor values (a cell's blind band, a
//! light seen by no cell, three cells for a 3-D pose): their pair is *aliased*, and an
//! invariant changes between its two samples as much as any function does. A fifth of
//! aliased pairs raises every `λ` of the invariants by about `0.4`, which hides the gap.
//! So the problem is solved again without them, [`TRIM_ROUNDS`] times: with the `w` of
//! every `λ` below `invariance_threshold` (or of the given count of invariants, when
//! it is larger), and in the last round of the invariants the count rule keeps; never
//! padded up to the rank `r` the count rule keeps at least: a function that is not
//! invariant would choose the pairs that make it look so (with three cells for a 3-D
//! pose at 10⁶ samples, one `λ` is below the threshold at first; two more functions
//! judging with it set aside the pairs that change them, and they, not the pose, become
//! the three invariants). Every round judges all the pairs afresh: the change
//! `d_i = ‖Wᵀ (φ(m_i) − φ(m_j(i)))‖²` of every pair is measured, the pairs with `d_i`
//! above [`ALIASED_FACTOR`] times the median are set aside (never more than half), and
//! `C` is the mean over the rest (`Σ` and `μ` stay those of every fitted sample). The
//! report gives the pairs kept. On a retina with cosine tuning (6 cells) at 10⁵
//! samples, a quarter of the pairs are aliased; the smallest `λ` fall from 0.11–0.4 to
//! 0–0.03, with a gap of 15 after the ninth.
//!
//! # Which pairs, and the cost
//!
//! `Σ` and `C` take `P F²` multiply-adds each for `P` pairs. Every fitted sample is
//! paired while `P F² ≤ 2^36` ([`PAIR_PRODUCTS`]: all of 10⁶ samples up to five motors);
//! past that, `max(2^36 / F², 64 F)` fitted samples drawn with the law's seed
//! ([`pair_count`]: about 130 000 for six motors, `64 F = 139 904` for seven, each
//! with its nearest neighbour among all the fitted samples). The sums run over blocks of
//! at most 8192 pairs (`2^21 / F` rows), each block's upper triangle in tiles of 256
//! columns, one task per tile; the blocks' sums are added in block order, so the result
//! is the same for any number of threads. The eigenproblem then takes `O(F³)` (about
//! `10¹¹` for seven motors: seconds), and its eight `F × F` matrices are the method's
//! memory past the log (`64 F²` bytes: 0.3 GB for seven motors), estimated before
//! learning starts. The basis of `N` motors has `3^N − 1` functions, so the method takes
//! at most [`MAX_MOTORS`] (seven: 2186 functions); a chain of eight hinges would need
//! 6560. Tracing evaluates `φ` and its `N` derivatives as tensor products of the
//! motors' factors (`(N + 1) 3^N` products) and applies `W` in one pass over its rows:
//! `(1 + 2N/3) 3^N` times the number of invariants multiply-adds per linearisation.
//!
//! # The law and its kernels
//!
//! The traced law is `z(m)`, with its exact Jacobian `∂z/∂m = Wᵀ ∂φ/∂m`: the kernel set
//! through `m^i` is the level set `z(m) = z(m^i)`, traced by the tracer's sensory method
//! unchanged (its rank, hence the kernel's dimension, is read from `∂z/∂m` as for the
//! local fits). The sensor values are `ŝ(m) = g(z(m))` with `g` the mean of the sensor
//! values of the [`REGRESSION_NEIGHBOURS`] fitted samples nearest to `z(m)` in invariant
//! space; `ŝ` and `z` have the same level sets where `g` tells invariants apart, and
//! tracing on `z` leaves `g`'s error out. The held-out error of the report is that of
//! `ŝ`. Coverage (status `left-data`) is that of the local fits: at least
//! `coverage_neighbours` samples (default 10) within `h`, the median distance to the
//! `neighbours`-th (default 40) nearest sample.

use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{Accum, Mat, MatRef, Par};
use rand::rngs::ChaCha8Rng;
use rand::seq::index::sample;
use rand::SeedableRng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::law::{covered, image_tree};
use super::log::held_out_report;
use super::tree::KdTree;
use super::{observe, LawValidParams, LearnError, LogReport, SensorimotorLog};
use crate::agent::{Motor, MotorSpace};
use crate::progress::{Progress, Silent};

/// Most invariants kept (the tree of the held-out regression holds one coordinate per
/// invariant).
pub const MAX_INVARIANTS: usize = 32;

/// Most motors: the basis of seven has `3^7 − 1 = 2186` functions, and its matrices
/// `Σ`, `C` take 38 MB each.
pub const MAX_MOTORS: usize = 7;

/// Most basis functions (`3^N − 1`): [`MAX_MOTORS`] motors.
pub const MAX_FEATURES: usize = 2186;

/// Fitted samples whose mean sensor values are `ŝ` at a configuration (nearest in
/// invariant space).
pub const REGRESSION_NEIGHBOURS: usize = 8;

/// Least pairs per basis function that the sums of `Σ` and `C` take (all the fitted
/// samples when there are fewer).
pub const PAIRS_PER_FEATURE: usize = 64;

/// Pairs times squared basis size (`P F²`, the multiply-adds of each of `Σ` and `C`)
/// up to which every fitted sample is paired: `2^36`, all of 10⁶ samples up to five
/// motors; past it `max(2^36 / F², 64 F)` seeded samples are.
pub const PAIR_PRODUCTS: f64 = 68_719_476_736.0;

/// Basis values per block of the sums of `Σ` and `C` (`rows × F`, at most 8192 rows):
/// each block's sums are taken apart and added in block order, so the result does not
/// depend on the thread count.
const BLOCK_VALUES: usize = 1 << 21;

/// Columns per tile of a block's sums: a block of more than 256 basis functions is
/// summed by tiles of its upper triangle, one task each.
const TILE: usize = 256;

/// Bytes of the blocks' sums held at once (a group of blocks summed in parallel).
const GROUP_BYTES: usize = 1 << 26;

/// What the eigenproblem found, in the law's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InvariantsReport {
    /// Basis functions `F = 3^N − 1`.
    pub features: usize,
    /// Invariants kept.
    pub invariants: usize,
    /// The threshold on `λ` that chose them (when their count was not given).
    pub threshold: Option<f64>,
    /// The smallest generalised eigenvalues `λ` (at most `2 × invariants + 4`, at
    /// least 12 when there are that many), ascending.
    pub eigenvalues: Vec<f64>,
    /// Sample pairs (each fitted sample and its nearest in sensor space).
    pub pairs: usize,
    /// The pairs left after the aliased ones were set aside (see the module docs,
    /// "Aliased pairs"): `C` and the eigenvalues are theirs.
    pub kept_pairs: usize,
    /// The mean `λ` of the kept invariants on the fitted pairs.
    pub fitted_lambda: f64,
    /// The same on the held-out samples, each paired with its nearest fitted sample in
    /// sensor space (`E[(z_i − z_j)²]` over them and the invariants; `Var z = 1` on the
    /// fitted samples), over the pairs that are not aliased (a change at most
    /// 9 times the median, as in the fit): near `fitted_lambda` when
    /// the invariants generalise. Absent without held-out samples.
    pub held_out_lambda: Option<f64>,
    /// The share of the held-out pairs set aside as aliased (their invariants change
    /// more than 9 times the median): poses the sensors confuse.
    pub held_out_aliased: Option<f64>,
}

/// One motor's three basis functions.
#[derive(Debug, Clone, Copy)]
enum Factor {
    /// `(1, cos ω x, sin ω x)`.
    Periodic { frequency: f64 },
    /// `(1, u, 2u² − 1)`, `u = (x − centre) · inverse_half`.
    Bounded { centre: f64, inverse_half: f64 },
}

impl Factor {
    fn of(motor: Motor) -> Self {
        match motor {
            Motor::Periodic { period } => Factor::Periodic {
                frequency: std::f64::consts::TAU / period,
            },
            Motor::Bounded { low, high } => Factor::Bounded {
                centre: 0.5 * (low + high),
                inverse_half: if high > low { 2.0 / (high - low) } else { 1.0 },
            },
        }
    }

    /// The three values and their derivatives at `x`.
    #[inline]
    fn at(self, x: f64) -> ([f64; 3], [f64; 3]) {
        match self {
            Factor::Periodic { frequency } => {
                let (s, c) = (frequency * x).sin_cos();
                ([1.0, c, s], [0.0, -frequency * s, frequency * c])
            }
            Factor::Bounded {
                centre,
                inverse_half,
            } => {
                let u = (x - centre) * inverse_half;
                (
                    [1.0, u, 2.0 * u * u - 1.0],
                    [0.0, inverse_half, 4.0 * u * inverse_half],
                )
            }
        }
    }
}

/// The tensor basis `φ` (see the module docs); index `Σ_j i_j 3^j`, index 0 the
/// constant, which the features leave out.
#[derive(Debug, Clone)]
struct Basis {
    factors: Vec<Factor>,
    /// `3^N`.
    len: usize,
}

impl Basis {
    fn new(space: &MotorSpace) -> Self {
        let factors: Vec<Factor> = space.motors().iter().map(|&m| Factor::of(m)).collect();
        let len = 3usize.pow(factors.len() as u32);
        Self { factors, len }
    }

    /// `3^N − 1` for `n` motors, `None` past [`MAX_FEATURES`].
    fn features(n: usize) -> Option<usize> {
        3usize
            .checked_pow(n as u32)
            .map(|l| l - 1)
            .filter(|&f| f <= MAX_FEATURES)
    }

    /// The tensor product of one factor per motor into `out` (`3^N`), `pick(j)`
    /// choosing motor `j`'s values or derivatives.
    #[inline]
    fn product(&self, factor: impl Fn(usize) -> [f64; 3], out: &mut [f64]) {
        out[0] = 1.0;
        let mut size = 1;
        for j in 0..self.factors.len() {
            let b = factor(j);
            for a in 0..size {
                let v = out[a];
                out[a] = v * b[0];
                out[a + size] = v * b[1];
                out[a + 2 * size] = v * b[2];
            }
            size *= 3;
        }
    }

    /// `φ(m)` with the constant, into `out` (`3^N`).
    fn values(&self, m: &[f64], out: &mut [f64]) {
        self.product(|j| self.factors[j].at(m[j]).0, out);
    }

    /// `φ(m)` into `out` and `∂φ/∂m_j` into `derivatives[j·3^N..]` (`N × 3^N`).
    fn with_derivatives(&self, m: &[f64], out: &mut [f64], derivatives: &mut [f64]) {
        let pairs: Vec<([f64; 3], [f64; 3])> =
            self.factors.iter().zip(m).map(|(f, &x)| f.at(x)).collect();
        self.product(|j| pairs[j].0, out);
        for (d, row) in derivatives.chunks_mut(self.len).enumerate() {
            self.product(|j| if j == d { pairs[j].1 } else { pairs[j].0 }, row);
        }
    }
}

/// The region one log covers: its fitted samples (and their periodic images) in a
/// k-d tree, and the bandwidth within which `min_count` of them make `m` covered.
struct Coverage {
    tree: KdTree,
    bandwidth: f64,
    min_count: usize,
}

/// The learned invariants (see the module docs).
pub(crate) struct InvariantModel {
    space: MotorSpace,
    basis: Basis,
    /// `μ`, the mean of `φ` over the fitted samples (`3^N`, index 0 unused).
    mean: Vec<f64>,
    /// `W`, `3^N × count` row-major (row 0, the constant, is zero).
    weights: Vec<f64>,
    count: usize,
    coverage: Vec<Coverage>,
    report: InvariantsReport,
}

impl std::fmt::Debug for InvariantModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InvariantModel")
            .field("report", &self.report)
            .finish()
    }
}

/// One block of `(i, j(i))` pairs.
type Block<'a> = &'a [(u32, u32)];

/// Rows per block of the sums of `Σ` and `C` for `features` basis functions:
/// [`BLOCK_VALUES`]` / F`, from 64 to 8192.
fn block_rows(features: usize) -> usize {
    (BLOCK_VALUES / features.max(1)).clamp(64, 8192)
}

/// The column ranges of the tiles of a block's sums ([`TILE`] columns each).
fn tiles(features: usize) -> Vec<(usize, usize)> {
    (0..features)
        .step_by(TILE)
        .map(|start| (start, (start + TILE).min(features)))
        .collect()
}

/// One task's sums over one block of pairs, for the basis functions (without the
/// constant) of columns `start..end`: rows `0..end` of those columns of `Σ φφᵀ` and
/// `Σ ΔΔᵀ` (their part of the upper triangle), and `Σ φ` of those columns.
struct TileSums {
    start: usize,
    second: Mat<f64>,
    first: Vec<f64>,
    pairs: Mat<f64>,
}

/// The sums of one block of `(i, j(i))` rows of `log`, columns `start..end`.
fn tile_sums(
    basis: &Basis,
    log: &SensorimotorLog,
    block: &[(u32, u32)],
    (start, end): (usize, usize),
) -> TileSums {
    let mut phi = Mat::<f64>::zeros(block.len(), end);
    let mut delta = Mat::<f64>::zeros(block.len(), end);
    let mut a = vec![0.0; basis.len];
    let mut b = vec![0.0; basis.len];
    for (r, &(i, j)) in block.iter().enumerate() {
        basis.values(&log.motors.row(i as usize).to_vec(), &mut a);
        basis.values(&log.motors.row(j as usize).to_vec(), &mut b);
        for f in 0..end {
            phi[(r, f)] = a[f + 1];
            delta[(r, f)] = a[f + 1] - b[f + 1];
        }
    }
    let first = (start..end).map(|f| phi.col(f).iter().sum()).collect();
    TileSums {
        start,
        second: upper_tile(phi.as_ref(), start),
        first,
        pairs: upper_tile(delta.as_ref(), start),
    }
}

/// `Xᵀ X[:, start..]`, sequential (the same sums for any number of threads); for
/// `start = 0`, `Xᵀ X`.
fn upper_tile(x: MatRef<'_, f64>, start: usize) -> Mat<f64> {
    let right = x.subcols(start, x.ncols() - start);
    let mut out = Mat::<f64>::zeros(x.ncols(), right.ncols());
    matmul(
        out.as_mut(),
        Accum::Replace,
        x.transpose(),
        right,
        1.0,
        Par::Seq,
    );
    out
}

/// Copies the upper triangle of `m` onto its lower one.
fn mirror_upper(m: &mut Mat<f64>) {
    for c in 0..m.ncols() {
        for r in c + 1..m.nrows() {
            m[(r, c)] = m[(c, r)];
        }
    }
}

/// Pairs the sums of `Σ` and `C` take for `features` basis functions out of `fitted`
/// samples: all while `fitted F² ≤` [`PAIR_PRODUCTS`], else `max(PAIR_PRODUCTS / F²,
/// 64 F)` ([`PAIRS_PER_FEATURE`]), at most `fitted`.
pub(crate) fn pair_count(features: usize, fitted: usize) -> usize {
    let squared = (features * features) as f64;
    if fitted as f64 * squared <= PAIR_PRODUCTS {
        return fitted;
    }
    let budget = (PAIR_PRODUCTS / squared) as usize;
    budget.max(PAIRS_PER_FEATURE * features).min(fitted)
}

/// Smallest ratio `λ_{k+1} / λ_k` that [`largest_gap`] takes for a gap between
/// invariants and the rest.
pub const MIN_GAP: f64 = 2.0;

/// Share of the threshold under which a `λ` counts as zero in the ratios of
/// [`largest_gap`]: a ratio between two exact invariants (orientation seen through far
/// lights, `λ ≈ 10⁻⁵`) is rounding, not a gap.
pub const ZERO_SHARE: f64 = 0.01;

/// How many of the ascending eigenvalues `λ` are invariants: those up to the largest
/// ratio `λ_{k+1} / max(λ_k, ZERO_SHARE × threshold)` among the `λ_k` below
/// `threshold`, when that ratio is at least [`MIN_GAP`]; else (no clear gap: too few
/// samples to tell invariants apart) all those below `threshold`. At most
/// [`MAX_INVARIANTS`]; 0 when none is below `threshold`.
fn largest_gap(eigenvalues: &[f64], threshold: f64) -> usize {
    let below = eigenvalues
        .iter()
        .take_while(|&&l| l < threshold)
        .count()
        .min(MAX_INVARIANTS);
    let ratio = |k: usize| {
        let next = eigenvalues.get(k).copied().unwrap_or(f64::INFINITY);
        next / eigenvalues[k - 1].max(ZERO_SHARE * threshold)
    };
    // The first of equal ratios.
    match (1..=below).max_by(|&a, &b| ratio(a).total_cmp(&ratio(b)).then(b.cmp(&a))) {
        Some(k) if ratio(k) >= MIN_GAP => k,
        _ => below,
    }
}

/// The fitted rows of one log in sensor space (every sensor divided by its standard
/// deviation over the fitted rows), for the nearest sensory neighbour of a row.
struct SensorIndex {
    tree: KdTree,
    scale: Vec<f64>,
}

impl SensorIndex {
    fn new(log: &SensorimotorLog, fit: &[u32]) -> Self {
        let k = log.sensors.ncols();
        let mut scale = vec![0.0; k];
        for (c, s) in scale.iter_mut().enumerate() {
            let column = log.sensors.column(c);
            let mean = fit.iter().map(|&i| column[i as usize]).sum::<f64>() / fit.len() as f64;
            let variance = fit
                .iter()
                .map(|&i| (column[i as usize] - mean).powi(2))
                .sum::<f64>()
                / fit.len() as f64;
            *s = if variance > 0.0 {
                1.0 / variance.sqrt()
            } else {
                1.0
            };
        }
        let mut index = Self {
            tree: KdTree::new(1, vec![0.0], vec![0]),
            scale,
        };
        let mut points = Vec::with_capacity(fit.len() * k);
        for &i in fit {
            points.extend(index.scaled(log, i));
        }
        index.tree = KdTree::new(k, points, fit.to_vec());
        index
    }

    /// Row `i`'s sensor values, scaled.
    fn scaled(&self, log: &SensorimotorLog, i: u32) -> Vec<f64> {
        log.sensors
            .row(i as usize)
            .iter()
            .zip(&self.scale)
            .map(|(v, s)| v * s)
            .collect()
    }

    /// The fitted row nearest to row `i` in sensor space, other than `i` itself (`i`
    /// when there is none).
    fn nearest_other(&self, log: &SensorimotorLog, i: u32) -> u32 {
        self.tree
            .nearest_rows(&self.scaled(log, i), 2)
            .into_iter()
            .map(|(_, row)| row)
            .find(|&row| row != i)
            .unwrap_or(i)
    }
}

/// The second moments of the basis over every log's fitted samples: `Σ` (regularised
/// by `10⁻¹²` of its mean diagonal), `C` and `μ`, and the number of pairs.
struct Moments {
    covariance: Mat<f64>,
    pair_covariance: Mat<f64>,
    mean: Vec<f64>,
    pairs: usize,
}

impl Moments {
    /// The sums of every log's pairs `(i, j(i))`, block by block, added in block order
    /// (a group of blocks, and the tiles of each, summed in parallel).
    fn new(
        basis: &Basis,
        logs: &[SensorimotorLog],
        pairs: &[Vec<(u32, u32)>],
        progress: &dyn Progress,
    ) -> Self {
        let features = basis.len - 1;
        let tiles = tiles(features);
        let group = (GROUP_BYTES / (16 * features * features)).max(1);
        let mut second = Mat::<f64>::zeros(features, features);
        let mut pair_sums = Mat::<f64>::zeros(features, features);
        let mut first = vec![0.0; features];
        for (log, pairs) in logs.iter().zip(pairs) {
            let blocks: Vec<&[(u32, u32)]> = pairs.chunks(block_rows(features)).collect();
            for group in blocks.chunks(group) {
                let tasks: Vec<(Block<'_>, (usize, usize))> = group
                    .iter()
                    .flat_map(|&block| tiles.iter().map(move |&tile| (block, tile)))
                    .collect();
                let sums: Vec<TileSums> = tasks
                    .into_par_iter()
                    .map(|(block, tile)| tile_sums(basis, log, block, tile))
                    .collect();
                for tile in sums {
                    let (rows, width) = tile.second.shape();
                    let mut part = second.as_mut().submatrix_mut(0, tile.start, rows, width);
                    part += &tile.second;
                    let mut part = pair_sums.as_mut().submatrix_mut(0, tile.start, rows, width);
                    part += &tile.pairs;
                    first[tile.start..]
                        .iter_mut()
                        .zip(&tile.first)
                        .for_each(|(a, b)| *a += b);
                }
                progress.advance(group.iter().map(|block| block.len() as u64).sum());
            }
        }
        if tiles.len() > 1 {
            mirror_upper(&mut second);
            mirror_upper(&mut pair_sums);
        }
        let total: usize = pairs.iter().map(Vec::len).sum();
        let inverse = 1.0 / total as f64;
        let mean: Vec<f64> = first.iter().map(|x| x * inverse).collect();
        let mut covariance = Mat::from_fn(features, features, |a, b| {
            second[(a, b)] * inverse - mean[a] * mean[b]
        });
        let trace: f64 = (0..features).map(|a| covariance[(a, a)]).sum();
        for a in 0..features {
            covariance[(a, a)] += 1e-12 * trace / features as f64;
        }
        Self {
            covariance,
            pair_covariance: Mat::from_fn(features, features, |a, b| pair_sums[(a, b)] * inverse),
            mean,
            pairs: total,
        }
    }

    /// The generalised eigenproblem `C w = λ Σ w`: every `λ` ascending and the `w` of
    /// the `columns` smallest (`F × columns`, `Wᵀ Σ W = I`); errors name `path` (the
    /// first log's motors).
    fn solve(
        &self,
        columns: usize,
        path: &std::path::Path,
    ) -> Result<(Vec<f64>, Mat<f64>), LearnError> {
        let features = self.mean.len();
        let samples = self.pairs;
        // Σ = L Lᵀ.
        let mut l = self.covariance.clone();
        if !crate::linalg::cholesky_in_place(l.as_mut()) {
            return Err(LearnError::TooFewSamples {
                path: path.to_owned(),
                samples,
                reason: format!(
                    "the {features} basis functions of the invariants are linearly dependent on the samples"
                ),
                fix: "record a log that moves every motor over its range",
            });
        }
        let l = l.as_ref();
        let par = Par::Seq;
        // A = L⁻¹ C L⁻ᵀ, symmetric; its eigenvectors y give w = L⁻ᵀ y.
        let mut x = self.pair_covariance.clone();
        solve_lower_triangular_in_place(l, x.as_mut(), par);
        let mut a = x.transpose().to_owned();
        solve_lower_triangular_in_place(l, a.as_mut(), par);
        let a = Mat::from_fn(features, features, |r, c| 0.5 * (a[(r, c)] + a[(c, r)]));
        let (eigen, vectors) = crate::linalg::self_adjoint_eigen(a.as_ref()).map_err(|e| {
            LearnError::TooFewSamples {
                path: path.to_owned(),
                samples,
                reason: format!("the eigenproblem of the invariants does not converge ({e:?})"),
                fix: "record a log that moves every motor over its range",
            }
        })?;
        let mut order: Vec<usize> = (0..features).collect();
        order.sort_by(|&p, &q| eigen[p].total_cmp(&eigen[q]).then(p.cmp(&q)));
        let eigenvalues: Vec<f64> = order.iter().map(|&p| eigen[p]).collect();
        let mut w = Mat::from_fn(features, columns.min(features), |r, c| {
            vectors[(r, order[c])]
        });
        solve_upper_triangular_in_place(l.transpose(), w.as_mut(), par);
        Ok((eigenvalues, w))
    }

    /// `C` over the pairs `kept` only (`Σ` and `μ` stay those of every fitted sample).
    fn keep_pairs(&mut self, basis: &Basis, logs: &[SensorimotorLog], kept: &[Vec<(u32, u32)>]) {
        self.pair_covariance = Moments::new(basis, logs, kept, &Silent).pair_covariance;
    }
}

/// How many invariants to keep from the ascending `eigenvalues`: the given count, else
/// those up to the largest gap below the threshold and at least `least` (0 when none is
/// below the threshold).
fn invariant_count(eigenvalues: &[f64], params: &LawValidParams, least: usize) -> usize {
    let features = eigenvalues.len();
    params.invariants.unwrap_or_else(|| {
        match largest_gap(eigenvalues, params.invariance_threshold) {
            0 => 0,
            gap => gap.max(least).min(MAX_INVARIANTS.min(features)),
        }
    })
}

/// Rounds of setting aliased pairs aside (module docs, "Aliased pairs").
const TRIM_ROUNDS: usize = 3;

/// How many of the functions of the ascending `eigenvalues` judge the pairs in trimming
/// round `round`: every one below `invariance_threshold` (at least the given count),
/// and in the last round the count rule's invariants; never padded up to the rank the
/// count rule keeps at least (module docs, "Aliased pairs").
fn aliased_judges(eigenvalues: &[f64], params: &LawValidParams, round: usize) -> usize {
    if round + 1 == TRIM_ROUNDS {
        return invariant_count(eigenvalues, params, 0);
    }
    let below = eigenvalues
        .iter()
        .take_while(|&&l| l < params.invariance_threshold)
        .count();
    params.invariants.unwrap_or(0).max(below)
}

/// A pair is aliased when its invariants change by more than this factor times the
/// median change of the pairs.
pub const ALIASED_FACTOR: f64 = 9.0;

/// The pairs of every log whose change `‖Wᵀ (φ(m_i) − φ(m_j))‖²` is at most
/// [`ALIASED_FACTOR`] times the median over all pairs; the changes are collected in pair
/// order, so the choice is the same for any thread count.
fn unaliased_pairs(
    basis: &Basis,
    logs: &[SensorimotorLog],
    pairs: &[Vec<(u32, u32)>],
    w: MatRef<'_, f64>,
) -> Vec<Vec<(u32, u32)>> {
    let changes: Vec<Vec<f64>> = logs
        .iter()
        .zip(pairs)
        .map(|(log, pairs)| {
            pairs
                .par_iter()
                .map(|&(i, j)| {
                    let (mut a, mut b) = (vec![0.0; basis.len], vec![0.0; basis.len]);
                    basis.values(&log.motors.row(i as usize).to_vec(), &mut a);
                    basis.values(&log.motors.row(j as usize).to_vec(), &mut b);
                    (0..w.ncols())
                        .map(|c| {
                            let z: f64 = (0..w.nrows())
                                .map(|f| w[(f, c)] * (a[f + 1] - b[f + 1]))
                                .sum();
                            z * z
                        })
                        .sum()
                })
                .collect()
        })
        .collect();
    let mut all: Vec<f64> = changes.iter().flatten().copied().collect();
    if all.is_empty() {
        return pairs.to_vec();
    }
    let limit = aliased_limit(&mut all);
    pairs
        .iter()
        .zip(&changes)
        .map(|(pairs, changes)| {
            pairs
                .iter()
                .zip(changes)
                .filter(|(_, &change)| change <= limit)
                .map(|(&pair, _)| pair)
                .collect()
        })
        .collect()
}

/// [`ALIASED_FACTOR`] times the median of `changes` (not empty; reordered): the
/// largest change of a pair that is not aliased.
fn aliased_limit(changes: &mut [f64]) -> f64 {
    let middle = changes.len() / 2;
    ALIASED_FACTOR * *changes.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// The mean of `changes` at most [`ALIASED_FACTOR`] times their median, and the share
/// of the others; `None` when empty. Added in order: the same for any thread count.
fn unaliased_mean(changes: &[f64]) -> Option<(f64, f64)> {
    if changes.is_empty() {
        return None;
    }
    let limit = aliased_limit(&mut changes.to_vec());
    let (sum, kept) = changes
        .iter()
        .filter(|&&c| c <= limit)
        .fold((0.0, 0usize), |(s, k), c| (s + c, k + 1));
    let aliased = (changes.len() - kept) as f64 / changes.len() as f64;
    Some((sum / kept.max(1) as f64, aliased))
}

/// The invariants of the pairs `pairs`, after [`TRIM_ROUNDS`] rounds of setting aliased
/// pairs aside.
fn learn_invariants(
    basis: &Basis,
    logs: &[SensorimotorLog],
    pairs: &[Vec<(u32, u32)>],
    params: &LawValidParams,
    (least, progress): (usize, &dyn Progress),
) -> Result<Learned, LearnError> {
    let fitted: usize = pairs.iter().map(Vec::len).sum();
    let mut moments = observe::stage(progress, observe::BASIS, fitted as u64, || {
        Moments::new(basis, logs, pairs, progress)
    });
    observe::stage(progress, observe::EIGEN, 1 + TRIM_ROUNDS as u64, || {
        solve_without_aliased(&mut moments, basis, logs, pairs, params, (least, progress))
    })
}

/// The eigenproblem of `moments`, solved again after each of [`TRIM_ROUNDS`] rounds of
/// setting aliased pairs aside (a step of `progress` per solve).
fn solve_without_aliased(
    moments: &mut Moments,
    basis: &Basis,
    logs: &[SensorimotorLog],
    pairs: &[Vec<(u32, u32)>],
    params: &LawValidParams,
    (least, progress): (usize, &dyn Progress),
) -> Result<Learned, LearnError> {
    let path = &logs[0].files.motors;
    let mut kept_pairs = moments.pairs;
    // One solve per round gives every λ and the w of as many functions as may be kept.
    let (mut eigenvalues, mut w) = moments.solve(MAX_INVARIANTS, path)?;
    progress.advance(1);
    for round in 0..TRIM_ROUNDS {
        // Every function below the threshold judges the pairs (aliased pairs change
        // many of them), never padded up to the rank `least`: a function above the
        // threshold is not invariant, and as a judge it would set aside the pairs
        // that change it and look invariant in the next round.
        let judges = aliased_judges(&eigenvalues, params, round).min(w.ncols());
        if judges == 0 {
            // Nothing to judge by: the rounds left are done.
            progress.advance((TRIM_ROUNDS - round) as u64);
            break;
        }
        let kept = unaliased_pairs(basis, logs, pairs, w.subcols(0, judges));
        kept_pairs = kept.iter().map(Vec::len).sum();
        moments.keep_pairs(basis, logs, &kept);
        (eigenvalues, w) = moments.solve(MAX_INVARIANTS, path)?;
        progress.advance(1);
    }
    let count = invariant_count(&eigenvalues, params, least);
    if count == 0 {
        return Err(LearnError::TooFewSamples {
            path: path.to_owned(),
            samples: moments.pairs,
            reason: format!(
                "no combination of the basis is invariant enough: the smallest λ is {:.3}, not below invariance_threshold = {}",
                eigenvalues[0], params.invariance_threshold
            ),
            fix: "record more samples, or raise invariance_threshold (or set invariants)",
        });
    }
    Ok(Learned {
        eigenvalues,
        w: w.subcols(0, count.min(w.ncols())).to_owned(),
        kept_pairs,
        mean: moments.mean.clone(),
    })
}

/// What [`learn_invariants`] finds.
struct Learned {
    /// Every `λ`, ascending.
    eigenvalues: Vec<f64>,
    /// The kept invariants' `w` (`F × count`).
    w: Mat<f64>,
    /// Pairs left after setting the aliased ones aside.
    kept_pairs: usize,
    /// `μ`, the basis' mean over the fitted samples.
    mean: Vec<f64>,
}

/// The fitted rows of every log that the sums of `Σ` and `C` pair: all of them, or
/// (past [`PAIR_PRODUCTS`]) [`pair_count`] of them in all, each log's share drawn with
/// `seed`, in row order.
fn paired_rows(fits: &[Vec<u32>], features: usize, seed: u64) -> Vec<Vec<u32>> {
    let total: usize = fits.iter().map(Vec::len).sum();
    let wanted = pair_count(features, total);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7061_6972);
    fits.iter()
        .map(|fit| {
            let share = (wanted as f64 * fit.len() as f64 / total as f64).ceil() as usize;
            if share >= fit.len() {
                return fit.clone();
            }
            let mut rows: Vec<u32> = sample(&mut rng, fit.len(), share)
                .into_iter()
                .map(|k| fit[k])
                .collect();
            rows.sort_unstable();
            rows
        })
        .collect()
}

impl InvariantModel {
    /// Learns the invariants from the rows `fits[l]` of every log `logs[l]`, and the
    /// report of every log (held-out rows `held[l]`); without a given count, at least
    /// `least` invariants are kept (the rank of the sensors the data show: fewer cannot
    /// make level sets of the kernels' dimension).
    /// `progress` sees the stages of [`observe`] from [`observe::SENSOR_TREE`] on.
    pub(crate) fn fit(
        logs: &[SensorimotorLog],
        (fits, held): (&[Vec<u32>], &[Vec<u32>]),
        space: &MotorSpace,
        params: &LawValidParams,
        (least, progress): (usize, &dyn Progress),
    ) -> Result<(Self, Vec<LogReport>), LearnError> {
        let basis = Basis::new(space);
        let indices: Vec<SensorIndex> =
            observe::stage(progress, observe::SENSOR_TREE, logs.len() as u64, || {
                logs.iter()
                    .zip(fits)
                    .map(|(log, fit)| {
                        let index = SensorIndex::new(log, fit);
                        progress.advance(1);
                        index
                    })
                    .collect()
            });
        let paired = paired_rows(fits, basis.len - 1, params.seed);
        let paired_count: u64 = paired.iter().map(|rows| rows.len() as u64).sum();
        let pairs: Vec<Vec<(u32, u32)>> =
            observe::stage(progress, observe::PAIRS, paired_count, || {
                logs.iter()
                    .zip(&paired)
                    .zip(&indices)
                    .map(|((log, rows), index)| {
                        observe::map_rows(rows, progress, |i| (i, index.nearest_other(log, i)))
                    })
                    .collect()
            });
        drop(paired);
        let Learned {
            eigenvalues,
            w,
            kept_pairs,
            mean: fitted_mean,
        } = learn_invariants(&basis, logs, &pairs, params, (least, progress))?;
        let total: usize = pairs.iter().map(Vec::len).sum();
        drop(pairs);
        let features = basis.len - 1;
        let mut mean = vec![0.0; basis.len];
        mean[1..].copy_from_slice(&fitted_mean);
        let count = w.ncols();
        let mut weights = vec![0.0; basis.len * count];
        for f in 0..features {
            for c in 0..count {
                weights[(f + 1) * count + c] = w[(f, c)];
            }
        }
        let shown = (2 * count + 4).max(12).min(features);
        let mut model = Self {
            space: space.clone(),
            basis,
            mean,
            weights,
            count,
            coverage: Vec::with_capacity(logs.len()),
            report: InvariantsReport {
                features,
                invariants: count,
                threshold: params
                    .invariants
                    .is_none()
                    .then_some(params.invariance_threshold),
                eigenvalues: eigenvalues[..shown].to_vec(),
                pairs: total,
                kept_pairs,
                fitted_lambda: eigenvalues[..count].iter().sum::<f64>() / count as f64,
                held_out_lambda: None,
                held_out_aliased: None,
            },
        };
        let mut reports = Vec::with_capacity(logs.len());
        let mut changes = Vec::new();
        for (((log, fit), held_rows), index) in logs.iter().zip(fits).zip(held).zip(&indices) {
            changes.extend(observe::stage(
                progress,
                observe::HELD_PAIRS,
                held_rows.len() as u64,
                || model.held_out_changes(log, held_rows, (index, progress)),
            ));
            reports.push(model.add_log(log, (fit, held_rows), params, progress)?);
        }
        if let Some((lambda, aliased)) = unaliased_mean(&changes) {
            model.report.held_out_lambda = Some(lambda / count as f64);
            model.report.held_out_aliased = Some(aliased);
        }
        Ok((model, reports))
    }

    /// `‖z(m_i) − z(m_j(i))‖²` for the held-out rows `i` of `log`, in row order, `j(i)`
    /// the fitted row nearest in sensor space.
    fn held_out_changes(
        &self,
        log: &SensorimotorLog,
        held_rows: &[u32],
        (index, progress): (&SensorIndex, &dyn Progress),
    ) -> Vec<f64> {
        observe::map_rows(held_rows, progress, |i| {
            let j = index.nearest_other(log, i);
            let (mut a, mut b) = (vec![0.0; self.count], vec![0.0; self.count]);
            self.invariants(&log.motors.row(i as usize).to_vec(), &mut a);
            self.invariants(&log.motors.row(j as usize).to_vec(), &mut b);
            a.iter()
                .zip(&b)
                .map(|(x, y)| (x - y) * (x - y))
                .sum::<f64>()
        })
    }

    /// Adds the coverage of one log (its fitted rows `fit`) and measures `ŝ = g(z)` on
    /// its held-out rows: `g` the mean sensor values of the
    /// [`REGRESSION_NEIGHBOURS`] fitted rows nearest in `z`.
    fn add_log(
        &mut self,
        log: &SensorimotorLog,
        (fit, held_rows): (&[u32], &[u32]),
        params: &LawValidParams,
        progress: &dyn Progress,
    ) -> Result<LogReport, LearnError> {
        let n = self.space.dim();
        let (tree, bandwidth, images) = image_tree(log, fit, &self.space, params, progress)?;
        self.coverage.push(Coverage {
            tree,
            bandwidth,
            min_count: params.coverage_neighbours(n),
        });
        let at = self.coverage.len() - 1;
        let count = self.count;
        let z_tree = observe::stage(progress, observe::INVARIANT_TREE, 1, || {
            let mut z_points = vec![0.0; fit.len() * count];
            z_points
                .par_chunks_mut(count)
                .zip(fit.par_iter())
                .for_each(|(out, &row)| {
                    self.invariants(&log.motors.row(row as usize).to_vec(), out)
                });
            let z_tree = KdTree::new(count, z_points, fit.to_vec());
            progress.advance(1);
            z_tree
        });
        let model = &*self;
        Ok(held_out_report(
            log,
            (held_rows, fit.len()),
            (bandwidth, images),
            progress,
            |m, s| {
                let coverage = &model.coverage[at];
                if !covered(
                    &model.space,
                    &coverage.tree,
                    coverage.bandwidth,
                    coverage.min_count,
                    m,
                ) {
                    return false;
                }
                let mut z = vec![0.0; count];
                model.invariants(m, &mut z);
                let near = z_tree.nearest_rows(&z, REGRESSION_NEIGHBOURS);
                s.fill(0.0);
                for &(_, row) in &near {
                    s.iter_mut()
                        .zip(log.sensors.row(row as usize))
                        .for_each(|(a, b)| *a += b);
                }
                let share = 1.0 / near.len().max(1) as f64;
                s.iter_mut().for_each(|a| *a *= share);
                true
            },
        ))
    }

    /// What the eigenproblem found.
    pub(crate) fn report(&self) -> &InvariantsReport {
        &self.report
    }

    /// The number of invariants (the law's outputs).
    pub(crate) fn count(&self) -> usize {
        self.count
    }

    /// The fitted samples of the first log (with images), for probing the rank.
    pub(crate) fn probe_tree(&self) -> &KdTree {
        &self.coverage[0].tree
    }

    /// `z(m)` into `out` (`count`).
    pub(crate) fn invariants(&self, m: &[f64], out: &mut [f64]) {
        let mut phi = vec![0.0; self.basis.len];
        self.basis.values(m, &mut phi);
        self.combine(&phi, out);
    }

    /// `out = Wᵀ (φ − μ)` for `φ` of length `3^N` (the constant's row of `W` is 0).
    fn combine(&self, phi: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for f in 1..self.basis.len {
            let x = phi[f] - self.mean[f];
            let row = &self.weights[f * self.count..(f + 1) * self.count];
            out.iter_mut().zip(row).for_each(|(o, w)| *o += w * x);
        }
    }

    /// `z(m)` into `value` (`count`) and, when asked, `∂z/∂m` into `jacobian`
    /// (`count × N`, row-major): one pass over `W`, each of its rows applied to `φ − μ`
    /// and to the `∂φ/∂m_j` that are not zero (those of the functions that have a
    /// factor of motor `j`).
    pub(crate) fn evaluate(&self, m: &[f64], value: &mut [f64], jacobian: Option<&mut [f64]>) {
        let n = self.space.dim();
        let Some(jac) = jacobian else {
            self.invariants(m, value);
            return;
        };
        let (len, count) = (self.basis.len, self.count);
        let mut phi = vec![0.0; len];
        let mut derivatives = vec![0.0; n * len];
        self.basis.with_derivatives(m, &mut phi, &mut derivatives);
        // Column j of the Jacobian in columns[j·count..].
        let mut columns = vec![0.0; n * count];
        value.fill(0.0);
        for f in 1..len {
            let row = &self.weights[f * count..(f + 1) * count];
            let x = phi[f] - self.mean[f];
            value.iter_mut().zip(row).for_each(|(o, w)| *o += w * x);
            for (j, column) in columns.chunks_mut(count).enumerate() {
                let d = derivatives[j * len + f];
                if d != 0.0 {
                    column.iter_mut().zip(row).for_each(|(o, w)| *o += w * d);
                }
            }
        }
        for (j, column) in columns.chunks(count).enumerate() {
            for (c, &v) in column.iter().enumerate() {
                jac[c * n + j] = v;
            }
        }
    }

    /// Whether every log covers `m` (see [`crate::learn`]).
    pub(crate) fn covers(&self, m: &[f64]) -> bool {
        self.coverage
            .iter()
            .all(|c| covered(&self.space, &c.tree, c.bandwidth, c.min_count, m))
    }

    /// The basis size for `n` motors, or the reason it is refused.
    pub(crate) fn check_motors(n: usize) -> Result<usize, String> {
        Basis::features(n).ok_or_else(|| {
            format!(
                "the invariants' basis has 3^N − 1 functions, {} for {n} motors: at most {MAX_FEATURES} ({MAX_MOTORS} motors)",
                3f64.powi(n as i32) - 1.0
            )
        })
    }

    /// Bytes the eigenproblem of `n` motors holds at most, besides the log, its trees
    /// and the threads' blocks: eight `F × F` matrices (the sums, `Σ`, `C`, the
    /// Cholesky factor, the whitened `C`, its eigenvectors and the eigensolver's
    /// scratch), a group of blocks' sums ([`GROUP_BYTES`], or one block's `16 F²`), and
    /// for the `pairs` pairs their rows twice (all, and those kept) and their changes.
    pub(crate) fn shared_bytes(n: usize, pairs: u64) -> u64 {
        let features = 3u64.saturating_pow(n as u32).saturating_sub(1);
        let matrices = features.saturating_mul(features).saturating_mul(8 * 8);
        let group = (GROUP_BYTES as u64).max(features.saturating_mul(features).saturating_mul(16));
        matrices
            .saturating_add(group)
            .saturating_add(pairs.saturating_mul(24))
    }

    /// Bytes each thread holds: its block of `φ` and `Δ` (`2 ×` [`BLOCK_VALUES`] values).
    pub(crate) fn thread_bytes() -> u64 {
        16 * BLOCK_VALUES as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use rand::RngExt;

    #[test]
    fn basis_derivatives_are_the_derivatives_of_its_values() {
        let space = MotorSpace::new(vec![
            Motor::HINGE,
            Motor::Bounded {
                low: -1.0,
                high: 3.0,
            },
            Motor::HINGE,
        ])
        .unwrap();
        let basis = Basis::new(&space);
        assert_eq!(basis.len, 27);
        let m = [0.3, 1.7, -2.9];
        let mut phi = vec![0.0; 27];
        let mut d = vec![0.0; 3 * 27];
        basis.with_derivatives(&m, &mut phi, &mut d);
        // The product of cos θ₁ (index 1), u (index 3) and sin θ₃ (index 18).
        let u = (1.7 - 1.0) / 2.0;
        assert_relative_eq!(phi[1 + 3 + 18], 0.3f64.cos() * u * (-2.9f64).sin());
        let step = 1e-6;
        for j in 0..3 {
            let mut plus = m;
            let mut minus = m;
            plus[j] += step;
            minus[j] -= step;
            let (mut a, mut b) = (vec![0.0; 27], vec![0.0; 27]);
            basis.values(&plus, &mut a);
            basis.values(&minus, &mut b);
            for f in 0..27 {
                let numeric = (a[f] - b[f]) / (2.0 * step);
                assert!((numeric - d[j * 27 + f]).abs() < 1e-8, "{j} {f}");
            }
        }
    }

    #[test]
    fn the_invariants_end_at_the_largest_gap_below_the_threshold() {
        // The paper's arm at 10⁶ samples: nine invariants, then a jump.
        let arm = [
            0.009, 0.014, 0.018, 0.024, 0.030, 0.038, 0.051, 0.062, 0.108, 0.547, 0.561,
        ];
        assert_eq!(largest_gap(&arm, 0.4), 9);
        // Lights far away: the orientation's two functions exact, the position's seven
        // weaker, then the jump (not at the rounding between the first two).
        let far = [
            1e-6, 3e-5, 0.006, 0.015, 0.021, 0.031, 0.036, 0.044, 0.060, 0.524, 0.541,
        ];
        assert_eq!(largest_gap(&far, 0.4), 9);
        // The redundant toy: two invariants (m1 + m2 and its square).
        assert_eq!(largest_gap(&[3.5e-5, 0.012, 0.147, 0.81, 1.97], 0.4), 2);
        assert_eq!(largest_gap(&[0.5, 0.6], 0.4), 0);
        // Every eigenvalue below the threshold: all of them.
        assert_eq!(largest_gap(&[0.01, 0.02], 0.4), 2);
        // The arm at 10⁴ samples: no clear gap, every λ below the threshold.
        let sparse = [0.124, 0.233, 0.330, 0.432, 0.461, 0.512];
        assert_eq!(largest_gap(&sparse, 0.4), 3);
    }

    #[test]
    fn the_judges_of_aliased_pairs_are_never_padded_up_to_the_rank() {
        use crate::params::CheckParams;
        let params = super::super::LawParams::default().check_params().unwrap();
        // Three cells for a 3-D pose at 10⁶ samples, first solve: one λ below the
        // threshold. It alone judges the pairs, though the rank (3) keeps three.
        let first = [0.133, 0.498, 0.575, 0.645, 0.714];
        assert_eq!(aliased_judges(&first, &params, 0), 1);
        assert_eq!(invariant_count(&first, &params, 3), 3);
        // The second solve: every function below the threshold judges, not only those
        // up to the largest gap (the first, 0.0025 against 0.109).
        let second = [
            0.0025, 0.109, 0.198, 0.220, 0.252, 0.265, 0.301, 0.314, 0.379, 0.726,
        ];
        assert_eq!(aliased_judges(&second, &params, 1), 9);
        assert_eq!(invariant_count(&second, &params, 0), 1);
        // The last round: only the invariants up to the gap judge (a function above it
        // would set aside the pairs that change it).
        let last = [1e-6, 1e-5, 0.15, 0.6, 1.4];
        assert_eq!(aliased_judges(&last, &params, TRIM_ROUNDS - 1), 2);
        assert_eq!(aliased_judges(&last, &params, 0), 3);
        // Nothing below the threshold: no judge.
        assert_eq!(aliased_judges(&[0.5, 0.6], &params, 0), 0);
        assert_eq!(aliased_judges(&[0.5, 0.6], &params, TRIM_ROUNDS - 1), 0);
        // A given count judges, and so does every function below the threshold.
        let given = super::super::LawParams {
            invariants: Some(4),
            ..Default::default()
        }
        .check_params()
        .unwrap();
        assert_eq!(aliased_judges(&first, &given, 0), 4);
        assert_eq!(aliased_judges(&second, &given, 1), 9);
        assert_eq!(aliased_judges(&second, &given, TRIM_ROUNDS - 1), 4);
    }

    #[test]
    fn the_basis_size_is_bounded() {
        assert_eq!(Basis::features(4), Some(80));
        assert_eq!(Basis::features(5), Some(242));
        assert_eq!(Basis::features(6), Some(728));
        assert_eq!(Basis::features(7), Some(2186));
        assert_eq!(Basis::features(8), None);
        assert!(InvariantModel::check_motors(8)
            .unwrap_err()
            .contains("6560"));
        // Seven motors: eight matrices of 2186² values, 306 MB, and the blocks.
        let bytes = InvariantModel::shared_bytes(7, 139_904) + 2 * InvariantModel::thread_bytes();
        assert!((300 << 20..500 << 20).contains(&bytes), "{bytes}");
    }

    #[test]
    fn seven_motors_derivatives_are_the_derivatives_of_the_values() {
        let mut motors = vec![Motor::HINGE; 7];
        motors[4] = Motor::Bounded {
            low: -2.0,
            high: 0.5,
        };
        let space = MotorSpace::new(motors).unwrap();
        let basis = Basis::new(&space);
        let len = 2187;
        assert_eq!(basis.len, len);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..3 {
            let mut m = [0.0; 7];
            for (j, x) in m.iter_mut().enumerate() {
                *x = if j == 4 {
                    rng.random_range(-2.0..0.5)
                } else {
                    rng.random_range(-3.0..3.0)
                };
            }
            let mut phi = vec![0.0; len];
            let mut d = vec![0.0; 7 * len];
            basis.with_derivatives(&m, &mut phi, &mut d);
            // The last function: sin of every hinge times 2u² − 1 of the bounded motor.
            let u = (m[4] + 0.75) / 1.25;
            let expected: f64 = (0..7)
                .map(|j| {
                    if j == 4 {
                        2.0 * u * u - 1.0
                    } else {
                        m[j].sin()
                    }
                })
                .product();
            assert_relative_eq!(phi[len - 1], expected, max_relative = 1e-12);
            let step = 1e-6;
            for j in 0..7 {
                let (mut plus, mut minus) = (m, m);
                plus[j] += step;
                minus[j] -= step;
                let (mut a, mut b) = (vec![0.0; len], vec![0.0; len]);
                basis.values(&plus, &mut a);
                basis.values(&minus, &mut b);
                for f in 0..len {
                    let numeric = (a[f] - b[f]) / (2.0 * step);
                    assert!((numeric - d[j * len + f]).abs() < 1e-8, "{j} {f}");
                }
            }
        }
    }

    #[test]
    fn the_pairs_are_all_samples_up_to_five_motors_and_64_per_function_past_them() {
        assert_eq!(pair_count(80, 1_000_000), 1_000_000);
        assert_eq!(pair_count(242, 1_000_000), 1_000_000);
        assert_eq!(pair_count(728, 1_000_000), 129_663);
        assert_eq!(pair_count(2186, 1_000_000), 64 * 2186);
        assert_eq!(pair_count(2186, 50_000), 50_000);
        assert_eq!(block_rows(80), 8192);
        assert_eq!(block_rows(242), 8192);
        assert_eq!(block_rows(2186), 959);
        assert_eq!(tiles(80), vec![(0, 80)]);
        assert_eq!(tiles(600), vec![(0, 256), (256, 512), (512, 600)]);
    }

    #[test]
    fn tiled_sums_are_the_symmetric_sums() {
        // 26 columns in tiles of 10: the upper triangle's tiles, mirrored.
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let x = Mat::from_fn(50, 26, |_, _| rng.random_range(-1.0..1.0));
        let full = upper_tile(x.as_ref(), 0);
        let mut tiled = Mat::<f64>::zeros(26, 26);
        for start in [0, 10, 20] {
            let end = (start + 10).min(26);
            let part = upper_tile(x.as_ref().subcols(0, end), start);
            for c in 0..end - start {
                for r in 0..end {
                    tiled[(r, start + c)] = part[(r, c)];
                }
            }
        }
        mirror_upper(&mut tiled);
        for r in 0..26 {
            for c in 0..26 {
                assert_relative_eq!(tiled[(r, c)], full[(r, c)], max_relative = 1e-12);
            }
        }
    }
}
