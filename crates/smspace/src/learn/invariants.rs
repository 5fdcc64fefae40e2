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
//! every `λ` below `invariance_threshold` in the first round, then of the invariants
//! the count rule below keeps (a function that is not invariant would choose the pairs
//! that make it look so; every round judges all the pairs afresh), the change
//! `d_i = ‖Wᵀ (φ(m_i) − φ(m_j(i)))‖²` of every pair is measured, the pairs with `d_i`
//! above [`ALIASED_FACTOR`] times the median are set aside (never more than half), and
//! `C` is the mean over the rest (`Σ` and `μ` stay those of every fitted sample). The
//! report gives the pairs kept. On a retina with cosine tuning (6 cells) at 10⁵
//! samples, a quarter of the pairs are aliased; the smallest `λ` fall from 0.11–0.4 to
//! 0–0.03, with a gap of 15 after the ninth.
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
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::law::{covered, image_tree};
use super::log::held_out_report;
use super::tree::KdTree;
use super::{observe, LawValidParams, LearnError, LogReport, SensorimotorLog};
use crate::agent::{Motor, MotorSpace};
use crate::progress::Progress;

/// Most invariants kept (the tree of the held-out regression holds one coordinate per
/// invariant).
pub const MAX_INVARIANTS: usize = 32;

/// Most basis functions (`3^N − 1`): five motors.
pub const MAX_FEATURES: usize = 242;

/// Fitted samples whose mean sensor values are `ŝ` at a configuration (nearest in
/// invariant space).
pub const REGRESSION_NEIGHBOURS: usize = 8;

/// Samples per block of the sums of `Σ` and `C` (each block's sums are taken apart and
/// added in block order, so the result does not depend on the thread count).
const BLOCK: usize = 8192;

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
    /// [`ALIASED_FACTOR`] times the median, as in the fit): near `fitted_lambda` when
    /// the invariants generalise. Absent without held-out samples.
    pub held_out_lambda: Option<f64>,
    /// The share of the held-out pairs set aside as aliased (their invariants change
    /// more than [`ALIASED_FACTOR`] times the median): poses the sensors confuse.
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

/// Sums over one block of pairs: `Σ φφᵀ`, `Σ φ`, `Σ ΔΔᵀ` (features without the
/// constant).
struct BlockSums {
    second: Mat<f64>,
    first: Vec<f64>,
    pairs: Mat<f64>,
}

/// The sums of one block of `(i, j(i))` rows of `log`.
fn block_sums(basis: &Basis, log: &SensorimotorLog, block: &[(u32, u32)]) -> BlockSums {
    let features = basis.len - 1;
    let mut phi = Mat::<f64>::zeros(block.len(), features);
    let mut delta = Mat::<f64>::zeros(block.len(), features);
    let mut a = vec![0.0; basis.len];
    let mut b = vec![0.0; basis.len];
    for (r, &(i, j)) in block.iter().enumerate() {
        basis.values(&log.motors.row(i as usize).to_vec(), &mut a);
        basis.values(&log.motors.row(j as usize).to_vec(), &mut b);
        for f in 0..features {
            phi[(r, f)] = a[f + 1];
            delta[(r, f)] = a[f + 1] - b[f + 1];
        }
    }
    let first = (0..features).map(|f| phi.col(f).iter().sum()).collect();
    BlockSums {
        second: gram(phi.as_ref()),
        first,
        pairs: gram(delta.as_ref()),
    }
}

/// `Xᵀ X`, sequential (the same sums for any number of threads).
fn gram(x: MatRef<'_, f64>) -> Mat<f64> {
    let mut out = Mat::<f64>::zeros(x.ncols(), x.ncols());
    matmul(
        out.as_mut(),
        Accum::Replace,
        x.transpose(),
        x,
        1.0,
        Par::Seq,
    );
    out
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
    /// The sums of every log's pairs `(i, j(i))`, block by block, added in block order.
    fn new(
        basis: &Basis,
        logs: &[SensorimotorLog],
        pairs: &[Vec<(u32, u32)>],
        progress: &dyn Progress,
    ) -> Self {
        let features = basis.len - 1;
        let mut second = Mat::<f64>::zeros(features, features);
        let mut pair_sums = Mat::<f64>::zeros(features, features);
        let mut first = vec![0.0; features];
        for (log, pairs) in logs.iter().zip(pairs) {
            let blocks: Vec<BlockSums> = pairs
                .par_chunks(BLOCK)
                .map(|block| {
                    let sums = block_sums(basis, log, block);
                    progress.advance(block.len() as u64);
                    sums
                })
                .collect();
            for block in blocks {
                second += &block.second;
                pair_sums += &block.pairs;
                first
                    .iter_mut()
                    .zip(&block.first)
                    .for_each(|(a, b)| *a += b);
            }
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
        let mut pair_sums = Mat::<f64>::zeros(self.mean.len(), self.mean.len());
        for (log, pairs) in logs.iter().zip(kept) {
            let blocks: Vec<BlockSums> = pairs
                .par_chunks(BLOCK)
                .map(|block| block_sums(basis, log, block))
                .collect();
            for block in blocks {
                pair_sums += &block.pairs;
            }
        }
        let total: usize = kept.iter().map(Vec::len).sum();
        let inverse = 1.0 / total.max(1) as f64;
        self.pair_covariance = Mat::from_fn(pair_sums.nrows(), pair_sums.ncols(), |a, b| {
            pair_sums[(a, b)] * inverse
        });
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
const TRIM_ROUNDS: usize = 2;

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
    let middle = all.len() / 2;
    let median = *all.select_nth_unstable_by(middle, f64::total_cmp).1;
    let limit = ALIASED_FACTOR * median;
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

/// The mean of `changes` at most [`ALIASED_FACTOR`] times their median, and the share
/// of the others; `None` when empty. Added in order: the same for any thread count.
fn unaliased_mean(changes: &[f64]) -> Option<(f64, f64)> {
    if changes.is_empty() {
        return None;
    }
    let mut sorted = changes.to_vec();
    let middle = sorted.len() / 2;
    let limit = ALIASED_FACTOR * *sorted.select_nth_unstable_by(middle, f64::total_cmp).1;
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
        // First every function below the threshold judges the pairs (aliased pairs
        // change many of them), then only the invariants the count rule keeps (a
        // function above the gap would choose the pairs that make it look invariant).
        let count = invariant_count(&eigenvalues, params, least);
        let below = eigenvalues
            .iter()
            .take_while(|&&l| l < params.invariance_threshold)
            .count();
        let judges = if round == 0 { count.max(below) } else { count }.min(w.ncols());
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
        let fitted: u64 = fits.iter().map(|f| f.len() as u64).sum();
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
        let pairs: Vec<Vec<(u32, u32)>> = observe::stage(progress, observe::PAIRS, fitted, || {
            logs.iter()
                .zip(fits)
                .zip(&indices)
                .map(|((log, fit), index)| {
                    observe::map_rows(fit, progress, |i| (i, index.nearest_other(log, i)))
                })
                .collect()
        });
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

    /// `out = Wᵀ (v − μ)` for `v` of length `3^N` (the constant's row of `W` is 0);
    /// `centred = false` leaves `μ` out (derivatives).
    fn combine_with(&self, v: &[f64], out: &mut [f64], centred: bool) {
        out.fill(0.0);
        for f in 1..self.basis.len {
            let x = if centred { v[f] - self.mean[f] } else { v[f] };
            let row = &self.weights[f * self.count..(f + 1) * self.count];
            out.iter_mut().zip(row).for_each(|(o, w)| *o += w * x);
        }
    }

    fn combine(&self, phi: &[f64], out: &mut [f64]) {
        self.combine_with(phi, out, true);
    }

    /// `z(m)` into `value` (`count`) and, when asked, `∂z/∂m` into `jacobian`
    /// (`count × N`, row-major).
    pub(crate) fn evaluate(&self, m: &[f64], value: &mut [f64], jacobian: Option<&mut [f64]>) {
        let n = self.space.dim();
        let Some(jac) = jacobian else {
            self.invariants(m, value);
            return;
        };
        let mut phi = vec![0.0; self.basis.len];
        let mut derivatives = vec![0.0; n * self.basis.len];
        self.basis.with_derivatives(m, &mut phi, &mut derivatives);
        self.combine(&phi, value);
        let mut column = vec![0.0; self.count];
        for (j, d) in derivatives.chunks(self.basis.len).enumerate() {
            self.combine_with(d, &mut column, false);
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
                "the invariants' basis has 3^N − 1 functions, {} for {n} motors: at most {MAX_FEATURES} (five motors)",
                3f64.powi(n as i32) - 1.0
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

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
    fn the_basis_size_is_bounded() {
        assert_eq!(Basis::features(4), Some(80));
        assert_eq!(Basis::features(5), Some(242));
        assert_eq!(Basis::features(6), None);
        assert!(InvariantModel::check_motors(7)
            .unwrap_err()
            .contains("2186"));
    }
}
