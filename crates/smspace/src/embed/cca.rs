//! Curvilinear Component Analysis (Demartines & Hérault 1997), the projection of the
//! paper's section 3.2.
//!
//! CCA minimises the stress `E = ½ Σ_{i≠j} (X_ij − Y_ij)² F(Y_ij, λ)`, where `X_ij` are
//! the input distances, `Y_ij = ‖y_i − y_j‖` the output ones, and `F` a decreasing
//! neighbourhood function of the *output* distance: short output distances are matched
//! first, long ones may stretch, which lets a curved manifold unfold. Minimisation is
//! stochastic: at each step a pivot `i` stays still and every other point moves,
//!
//! ```text
//! y_j ← y_j + α(t) F(Y_ij, λ(t)) (X_ij − Y_ij) / Y_ij · (y_j − y_i),
//! ```
//!
//! (Demartines & Hérault 1997, eq. 9). Every point pivots once per epoch, in a seeded
//! random order. The learning rate and the neighbourhood width decay geometrically over
//! the `epochs · M` steps: `α(t) = α_0 (α_1/α_0)^t`, `λ(t) = λ_0 (λ_1/λ_0)^t`, `t ∈ [0, 1]`
//! (defaults from the SOM Toolbox's `cca.m`: α from 0.5 to 0.005; λ from the largest input
//! distance down to a low quantile of them). `F` is the step `F = [Y ≤ λ]` of the
//! original paper or `F = exp(−Y/λ)` of the SOM Toolbox ([`Neighbourhood`]). The initial
//! layout is classical MDS ([`super::mds`]) of up to 300 landmarks, the other points
//! placed by triangulation (landmark MDS; `init_landmarks`).
//!
//! New points ([`super::Embedded::extend`]) are placed the same way with the old points
//! fixed: each new point starts at the distance-weighted mean of its nearest old points
//! and then follows the update above (as the moving `j`) for every old pivot, for a few
//! epochs, at the final width. This is the incremental extension of the internal
//! manifold that the paper sketches at the end of section 3.3.
//!
//! The inner loop runs over blocks of [`LANES`] points stored coordinate-major, which the
//! compiler vectorises (AVX2 where the CPU has it, through pulp's runtime dispatch). The
//! pivot loop is sequential, as in the original algorithm: splitting each pivot's
//! `M` updates over threads was measured 2–4 times slower at `M = 2500` (a fork–join
//! per pivot costs more than its few microseconds of work), so CCA uses one core; the
//! MDS initial layout and the quality measures use all of them.

use ndarray::{Array2, ArrayView1, ArrayView2};
use rand::rngs::ChaCha8Rng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::eigen::{classical_mds, distance_scale, landmark_mds, rescaled, EigenSolver};
use super::{check_dim, check_dim_param, check_distances, EmbedError, EmbedReport, Embedded};
use super::{Embedding, Extender};
use crate::neighbours::nearest;
use crate::params::InvalidParameter;
use crate::progress::Progress;

/// Points per block in the inner loop.
pub const LANES: usize = 8;

/// Coordinate of padding points: far beyond any `λ`, so that `F = 0` for them.
const FAR: f64 = 1e100;

/// The neighbourhood function `F(Y, λ)` of the output distance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Neighbourhood {
    /// `F = 1` if `Y ≤ λ`, else 0 (Demartines & Hérault 1997).
    #[default]
    Step,
    /// `F = exp(−Y/λ)` (SOM Toolbox, `cca.m`).
    Exp,
}

/// Most epochs of CCA (`embedding.epochs`, `extend_epochs`): each costs `M²`
/// operations and one float64 of the stress trace.
pub const MAX_EPOCHS: usize = 100_000;

/// Parameters of CCA (unchecked).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CcaParams {
    /// Output dimension `d`. Default 3 (the paper's figure 6d).
    pub dim: usize,
    /// Epochs; every point pivots once per epoch. Default 50.
    pub epochs: usize,
    /// Initial learning rate `α_0`. Default 0.5.
    pub alpha_start: f64,
    /// Final learning rate `α_1`. Default 0.005.
    pub alpha_end: f64,
    /// Initial width `λ_0`; `None` (default): the largest input distance.
    pub lambda_start: Option<f64>,
    /// Final width `λ_1`; `None` (default): the `lambda_end_quantile` of the input
    /// distances.
    pub lambda_end: Option<f64>,
    /// Quantile of the off-diagonal input distances used as `λ_1` when `lambda_end` is
    /// `None`. Default 0.01.
    pub lambda_end_quantile: f64,
    /// Neighbourhood function. Default [`Neighbourhood::Step`].
    pub neighbourhood: Neighbourhood,
    /// Epochs of the out-of-sample placement of each new point. Default 20.
    pub extend_epochs: usize,
    /// The initial layout is classical MDS of at most this many MaxMin landmarks, the
    /// other points placed by triangulation (landmark MDS, de Silva & Tenenbaum 2003:
    /// identical to classical MDS for Euclidean distances, and `O(M L)` instead of an
    /// `M × M` eigenproblem); `None`: classical MDS of all points. Default 300.
    pub init_landmarks: Option<usize>,
    /// Eigensolver of the MDS initial layout when `init_landmarks` is `None`.
    /// Default `Auto`.
    pub solver: EigenSolver,
    /// Seed of the pivot order (and of the eigensolver). Default 0.
    pub seed: u64,
}

impl Default for CcaParams {
    fn default() -> Self {
        Self {
            dim: 3,
            epochs: 50,
            alpha_start: 0.5,
            alpha_end: 0.005,
            lambda_start: None,
            lambda_end: None,
            lambda_end_quantile: 0.01,
            neighbourhood: Neighbourhood::Step,
            extend_epochs: 20,
            init_landmarks: Some(300),
            solver: EigenSolver::Auto,
            seed: 0,
        }
    }
}

impl CcaParams {
    /// Sets the output dimension (default 3).
    pub fn dim(mut self, dim: usize) -> Self {
        self.dim = dim;
        self
    }
    /// Sets the number of epochs (default 50).
    pub fn epochs(mut self, epochs: usize) -> Self {
        self.epochs = epochs;
        self
    }
    /// Sets the learning-rate schedule (default 0.5 → 0.005).
    pub fn alpha(mut self, start: f64, end: f64) -> Self {
        self.alpha_start = start;
        self.alpha_end = end;
        self
    }
    /// Sets the width schedule (default: max distance → 1 % quantile).
    pub fn lambda(mut self, start: Option<f64>, end: Option<f64>) -> Self {
        self.lambda_start = start;
        self.lambda_end = end;
        self
    }
    /// Sets the neighbourhood function (default step).
    pub fn neighbourhood(mut self, f: Neighbourhood) -> Self {
        self.neighbourhood = f;
        self
    }
    /// Sets the seed (default 0).
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// Validates the parameters.
    pub fn check(self) -> Result<CcaValidParams, EmbedError> {
        check_dim_param(self.dim)?;
        let bad = |name, value: String, expected: &str| {
            Err(InvalidParameter::new("embedding", name, value, expected).into())
        };
        for (name, epochs) in [
            ("epochs", self.epochs),
            ("extend_epochs", self.extend_epochs),
        ] {
            if epochs == 0 && name == "epochs" {
                return bad(name, "0".into(), "at least 1");
            }
            if epochs > MAX_EPOCHS {
                return bad(
                    name,
                    epochs.to_string(),
                    &format!("at most {MAX_EPOCHS} (every epoch moves every point once and keeps its stress; the default is 50)"),
                );
            }
        }
        if !(self.alpha_start > 0.0 && self.alpha_start <= 1.0) {
            return bad("alpha_start", self.alpha_start.to_string(), "in (0, 1]");
        }
        if !(self.alpha_end > 0.0 && self.alpha_end <= self.alpha_start) {
            return bad(
                "alpha_end",
                self.alpha_end.to_string(),
                "in (0, alpha_start]",
            );
        }
        for (name, value) in [
            ("lambda_start", self.lambda_start),
            ("lambda_end", self.lambda_end),
        ] {
            if let Some(v) = value {
                if !(v > 0.0 && v.is_finite()) {
                    return bad(name, v.to_string(), "a positive distance");
                }
            }
        }
        if let Some(l) = self.init_landmarks {
            if l <= self.dim {
                return bad(
                    "init_landmarks",
                    l.to_string(),
                    "more landmarks than output dimensions (or none for full MDS)",
                );
            }
        }
        if !(self.lambda_end_quantile > 0.0 && self.lambda_end_quantile <= 1.0) {
            return bad(
                "lambda_end_quantile",
                self.lambda_end_quantile.to_string(),
                "in (0, 1]",
            );
        }
        Ok(CcaValidParams(self))
    }
}

/// Checked parameters of CCA; [`Embedding::fit`] runs it.
#[derive(Debug, Clone, PartialEq)]
pub struct CcaValidParams(CcaParams);

impl CcaValidParams {
    /// The parameters.
    pub fn params(&self) -> &CcaParams {
        &self.0
    }

    /// Runs CCA from a given initial layout `(M, d)` instead of classical MDS.
    pub fn fit_from(
        &self,
        distances: ArrayView2<'_, f64>,
        initial: ArrayView2<'_, f64>,
        progress: &dyn Progress,
    ) -> Result<Embedded, EmbedError> {
        check_distances(distances)?;
        let n = distances.nrows();
        check_dim(self.0.dim, n)?;
        if initial.dim() != (n, self.0.dim) {
            return Err(InvalidParameter::new(
                "embedding",
                "initial",
                format!("shape {:?}", initial.dim()),
                "the initial layout has shape (M, dim)",
            )
            .into());
        }
        Ok(self.run(distances, initial.to_owned(), Vec::new(), None, progress))
    }

    fn run(
        &self,
        distances: ArrayView2<'_, f64>,
        initial: Array2<f64>,
        eigenvalues: Vec<f64>,
        trace: Option<f64>,
        progress: &dyn Progress,
    ) -> Embedded {
        let p = &self.0;
        let n = distances.nrows();
        let (lambda_start, lambda_end) = widths(distances, p);
        let mut layout = make_layout(initial.view(), p.neighbourhood);
        let x = PaddedRows::new(distances, n.div_ceil(LANES) * LANES);
        let steps = p.epochs * n;
        let mut rng = ChaCha8Rng::seed_from_u64(p.seed);
        let mut order: Vec<usize> = (0..n).collect();
        let mut stress_trace = Vec::with_capacity(p.epochs);
        progress.start("cca", p.epochs as u64);
        for epoch in 0..p.epochs {
            order.shuffle(&mut rng);
            let mut stress = 0.0;
            for (s, &i) in order.iter().enumerate() {
                let t = if steps > 1 {
                    (epoch * n + s) as f64 / (steps - 1) as f64
                } else {
                    0.0
                };
                let alpha = p.alpha_start * (p.alpha_end / p.alpha_start).powf(t);
                let lambda = lambda_start * (lambda_end / lambda_start).powf(t);
                stress += layout.pivot(i, x.row(i), alpha, lambda);
            }
            stress_trace.push(0.5 * stress);
            progress.advance(1);
        }
        progress.finish();
        let report = EmbedReport {
            method: "cca".into(),
            points: n,
            dim: p.dim,
            stress_trace,
            lambda_end: Some(lambda_end),
            eigenvalues,
            eigenvalue_trace: trace,
            ..Default::default()
        };
        Embedded {
            coordinates: layout.to_array(n),
            report,
            extender: Extender::Cca(CcaExtender {
                lambda: lambda_end,
                alpha_start: p.alpha_start,
                alpha_end: p.alpha_end,
                epochs: p.extend_epochs,
                neighbourhood: p.neighbourhood,
                seed: p.seed,
            }),
        }
    }
}

impl Embedding for CcaValidParams {
    fn name(&self) -> &'static str {
        "cca"
    }
    fn dim(&self) -> usize {
        self.0.dim
    }
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(&self.0).expect("parameters serialise")
    }
    fn fit_checked(
        &self,
        distances: ArrayView2<'_, f64>,
        progress: &dyn Progress,
    ) -> Result<Embedded, EmbedError> {
        if let Some(scale) = distance_scale(distances) {
            let scaled = distances.mapv(|x| x / scale);
            return Ok(rescaled(self.fit_checked(scaled.view(), progress)?, scale));
        }
        let n = distances.nrows();
        let p = &self.0;
        let mut init = match p.init_landmarks {
            Some(l) if l < n => landmark_mds(distances, p.dim, l, p.seed)?,
            _ => classical_mds(distances.mapv(|x| x * x), p.dim, p.solver, p.seed, true)?,
        };
        // Directions MDS could not fill (a metric of lower rank than `dim`) start with a
        // small seeded spread, so that CCA can use them.
        if init.used.len() < self.0.dim {
            let spread = 1e-3
                * init
                    .used
                    .first()
                    .map_or(1.0, |v| v.sqrt() / (n as f64).sqrt());
            let mut rng = ChaCha8Rng::seed_from_u64(self.0.seed ^ 0xdead_beef);
            for c in init.used.len()..self.0.dim {
                for v in init.coordinates.column_mut(c) {
                    *v = spread * (rng.random::<f64>() - 0.5);
                }
            }
        }
        Ok(self.run(
            distances,
            init.coordinates,
            init.eigenvalues,
            Some(init.trace),
            progress,
        ))
    }

    /// The matrix again, the start (landmark MDS on `init_landmarks`, or classical
    /// MDS), and the stress of every epoch, kept for the report.
    fn working_bytes(&self, points: usize) -> u64 {
        let m = points as u64;
        let start = match self.0.init_landmarks {
            Some(l) if (l as u64) < m => (l as u64)
                .saturating_mul(m.saturating_add(l as u64))
                .saturating_mul(8),
            _ => super::mds_bytes(m),
        };
        super::square_bytes(m)
            .saturating_add(start)
            .saturating_add((self.0.epochs as u64).saturating_mul(8))
    }

    fn memory_fix(&self) -> &'static str {
        "lower exploration.n (M), or keep embedding.init_landmarks small"
    }
}

/// The width schedule's end points `(λ_0, λ_1)`.
fn widths(distances: ArrayView2<'_, f64>, p: &CcaParams) -> (f64, f64) {
    let n = distances.nrows();
    let mut off: Vec<f64> = Vec::with_capacity(n * (n - 1) / 2);
    for i in 0..n {
        for j in 0..i {
            off.push(distances[[i, j]]);
        }
    }
    let max = off
        .iter()
        .copied()
        .fold(0.0_f64, f64::max)
        .max(f64::MIN_POSITIVE);
    let start = p.lambda_start.unwrap_or(max);
    let end = p.lambda_end.unwrap_or_else(|| {
        let at = ((off.len() as f64 - 1.0) * p.lambda_end_quantile).round() as usize;
        let last = off.len() - 1;
        let (_, q, _) = off.select_nth_unstable_by(at.min(last), f64::total_cmp);
        q.max(1e-12 * max)
    });
    (start, end.min(start))
}

/// The input distance rows, converted to `f32` (half the memory traffic) and padded to
/// whole blocks.
struct PaddedRows {
    width: usize,
    data: Vec<f32>,
}

impl PaddedRows {
    fn new(distances: ArrayView2<'_, f64>, width: usize) -> Self {
        let n = distances.nrows();
        let mut data = vec![0.0_f32; n * width];
        data.par_chunks_mut(width).enumerate().for_each(|(i, out)| {
            for (o, &x) in out.iter_mut().zip(distances.row(i).iter()) {
                *o = x as f32;
            }
        });
        Self { width, data }
    }
    fn row(&self, i: usize) -> &[f32] {
        &self.data[i * self.width..(i + 1) * self.width]
    }
}

/// Tiny floor of output distances in the update's division (coincident points do not
/// move each other, and never produce NaN).
const TINY: f64 = 1e-150;

/// A layout that CCA steps can move.
trait PivotLayout: Send {
    /// One CCA step with pivot `i` and its input distance row `x` (padded); returns
    /// `Σ_j (X_ij − Y_ij)² F(Y_ij, λ)` measured before the move.
    fn pivot(&mut self, i: usize, x: &[f32], alpha: f64, lambda: f64) -> f64;
    /// The coordinates `(n, d)`.
    fn to_array(&self, n: usize) -> Array2<f64>;
}

/// Coordinates in blocks of [`LANES`] points, coordinate-major inside a block:
/// `blocks[b][c][l]` is coordinate `c` of point `b · LANES + l`. Padding points sit at
/// [`FAR`], where `F = 0`.
struct Blocks<const D: usize, const EXP: bool> {
    blocks: Vec<[[f64; LANES]; D]>,
    arch: pulp::Arch,
}

/// One pivot step over some blocks, compiled for the best instruction set the CPU has
/// (pulp's runtime dispatch; the arithmetic is the same IEEE operations on every path,
/// no fused multiply–add, so results do not depend on the CPU either).
struct Update<'a, const D: usize, const EXP: bool> {
    blocks: &'a mut [[[f64; LANES]; D]],
    x: &'a [f32],
    yi: [f64; D],
    alpha: f64,
    lambda: f64,
}

impl<const D: usize, const EXP: bool> pulp::WithSimd for Update<'_, D, EXP> {
    type Output = f64;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> f64 {
        block_update::<D, EXP>(self.blocks, self.x, &self.yi, self.alpha, self.lambda)
    }
}

impl<const D: usize, const EXP: bool> Blocks<D, EXP> {
    fn new(initial: ArrayView2<'_, f64>) -> Self {
        let n = initial.nrows();
        let mut blocks = vec![[[FAR; LANES]; D]; n.div_ceil(LANES)];
        for j in 0..n {
            for c in 0..D {
                blocks[j / LANES][c][j % LANES] = initial[[j, c]];
            }
        }
        Self {
            blocks,
            arch: pulp::Arch::new(),
        }
    }
}

impl<const D: usize, const EXP: bool> PivotLayout for Blocks<D, EXP> {
    fn pivot(&mut self, i: usize, x: &[f32], alpha: f64, lambda: f64) -> f64 {
        let mut yi = [0.0; D];
        for (c, v) in yi.iter_mut().enumerate() {
            *v = self.blocks[i / LANES][c][i % LANES];
        }
        self.arch.dispatch(Update::<D, EXP> {
            blocks: &mut self.blocks,
            x,
            yi,
            alpha,
            lambda,
        })
    }

    fn to_array(&self, n: usize) -> Array2<f64> {
        Array2::from_shape_fn((n, D), |(j, c)| self.blocks[j / LANES][c][j % LANES])
    }
}

/// The CCA update of every point of `blocks` around the pivot at `yi` (the kernel).
#[inline(always)]
fn block_update<const D: usize, const EXP: bool>(
    blocks: &mut [[[f64; LANES]; D]],
    x: &[f32],
    yi: &[f64; D],
    alpha: f64,
    lambda: f64,
) -> f64 {
    let inv_lambda = 1.0 / lambda;
    let mut acc = [0.0_f64; LANES];
    for (block, xs) in blocks.iter_mut().zip(x.chunks_exact(LANES)) {
        let xs: &[f32; LANES] = xs.try_into().expect("whole blocks");
        let mut delta = [[0.0_f64; LANES]; D];
        let mut d2 = [0.0_f64; LANES];
        for c in 0..D {
            for l in 0..LANES {
                let d = block[c][l] - yi[c];
                delta[c][l] = d;
                d2[l] += d * d;
            }
        }
        let mut coef = [0.0_f64; LANES];
        for l in 0..LANES {
            let dy = d2[l].sqrt();
            let diff = f64::from(xs[l]) - dy;
            let w = if EXP {
                exp_neg(dy * inv_lambda)
            } else if dy <= lambda {
                1.0
            } else {
                0.0
            };
            acc[l] += diff * diff * w;
            coef[l] = alpha * w * diff / dy.max(TINY);
        }
        for c in 0..D {
            for l in 0..LANES {
                block[c][l] += coef[l] * delta[c][l];
            }
        }
    }
    acc.iter().sum()
}

/// `exp(−u)` for `u ≥ 0`, branch-free so that it vectorises (relative error < 1e-14;
/// 0 below `exp(−700)`): `2^k · p(r)` with `−u = k ln 2 + r`, `|r| ≤ ln 2 / 2`, `p` the
/// degree-11 Taylor polynomial, `2^k` assembled in the exponent bits.
#[inline(always)]
pub(crate) fn exp_neg(u: f64) -> f64 {
    // 1.5 · 2^52: adding it rounds to an integer held in the low mantissa bits.
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    // ln 2 split as in fdlibm: LN2_HI has trailing zero bits, so k · LN2_HI is exact.
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    let x = (-u).max(-700.0);
    let shifted = x * std::f64::consts::LOG2_E + SHIFTER;
    let k = shifted - SHIFTER;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut p = 1.0 / 39_916_800.0;
    for f in [
        3_628_800.0,
        362_880.0,
        40_320.0,
        5_040.0,
        720.0,
        120.0,
        24.0,
        6.0,
        2.0,
        1.0,
        1.0,
    ] {
        p = p * r + 1.0 / f;
    }
    let kb = shifted.to_bits().wrapping_sub(SHIFTER.to_bits());
    let scale = f64::from_bits(kb.wrapping_add(1023) << 52);
    let y = p * scale;
    if u > 700.0 {
        0.0
    } else {
        y
    }
}

/// Any dimension: points one after the other, scalar loop.
struct Flat {
    dim: usize,
    exp: bool,
    coords: Vec<f64>,
}

impl PivotLayout for Flat {
    fn pivot(&mut self, i: usize, x: &[f32], alpha: f64, lambda: f64) -> f64 {
        let dim = self.dim;
        let yi: Vec<f64> = self.coords[i * dim..(i + 1) * dim].to_vec();
        let mut stress = 0.0;
        for (yj, &xj) in self.coords.chunks_exact_mut(dim).zip(x) {
            let d2: f64 = yj.iter().zip(&yi).map(|(a, b)| (a - b) * (a - b)).sum();
            let dy = d2.sqrt();
            let diff = f64::from(xj) - dy;
            let w = neighbourhood(self.exp, dy, lambda);
            stress += diff * diff * w;
            let coef = alpha * w * diff / dy.max(TINY);
            for (a, b) in yj.iter_mut().zip(&yi) {
                *a += coef * (*a - b);
            }
        }
        stress
    }

    fn to_array(&self, n: usize) -> Array2<f64> {
        Array2::from_shape_fn((n, self.dim), |(j, c)| self.coords[j * self.dim + c])
    }
}

fn neighbourhood(exp: bool, dy: f64, lambda: f64) -> f64 {
    if exp {
        (-dy / lambda).exp()
    } else if dy <= lambda {
        1.0
    } else {
        0.0
    }
}

/// The layout for `initial` `(n, d)`: vectorised blocks for `d ≤ 4`.
fn make_layout(initial: ArrayView2<'_, f64>, f: Neighbourhood) -> Box<dyn PivotLayout> {
    let exp = f == Neighbourhood::Exp;
    match (initial.ncols(), exp) {
        (1, false) => Box::new(Blocks::<1, false>::new(initial)),
        (1, true) => Box::new(Blocks::<1, true>::new(initial)),
        (2, false) => Box::new(Blocks::<2, false>::new(initial)),
        (2, true) => Box::new(Blocks::<2, true>::new(initial)),
        (3, false) => Box::new(Blocks::<3, false>::new(initial)),
        (3, true) => Box::new(Blocks::<3, true>::new(initial)),
        (4, false) => Box::new(Blocks::<4, false>::new(initial)),
        (4, true) => Box::new(Blocks::<4, true>::new(initial)),
        (dim, exp) => Box::new(Flat {
            dim,
            exp,
            coords: initial.iter().copied().collect(),
        }),
    }
}

/// What CCA keeps to place new points.
#[derive(Debug, Clone)]
pub(crate) struct CcaExtender {
    lambda: f64,
    alpha_start: f64,
    alpha_end: f64,
    epochs: usize,
    neighbourhood: Neighbourhood,
    seed: u64,
}

impl CcaExtender {
    /// The extender of the same fit in distances `scale` times larger (see
    /// [`super::eigen::rescaled`]).
    pub(super) fn rescale(&mut self, scale: f64) {
        self.lambda *= scale;
    }

    /// Places each new point against the fixed old layout `old` `(M, d)`.
    pub fn extend(&self, old: ArrayView2<'_, f64>, new_to_old: ArrayView2<'_, f64>) -> Array2<f64> {
        let dim = old.ncols();
        let rows: Vec<Vec<f64>> = (0..new_to_old.nrows())
            .into_par_iter()
            .map(|p| self.place(old, new_to_old.row(p), p as u64))
            .collect();
        Array2::from_shape_fn((rows.len(), dim), |(p, c)| rows[p][c])
    }

    fn place(&self, old: ArrayView2<'_, f64>, x: ArrayView1<'_, f64>, index: u64) -> Vec<f64> {
        let (m, dim) = old.dim();
        let exp = self.neighbourhood == Neighbourhood::Exp;
        // Start at the distance-weighted mean of the nearest old points.
        let near = nearest(x, (2 * dim + 1).min(m), None);
        let mut y = vec![0.0; dim];
        let mut total = 0.0;
        for &(j, d) in &near {
            let w = 1.0 / (d + 1e-12);
            total += w;
            for c in 0..dim {
                y[c] += w * old[[j, c]];
            }
        }
        y.iter_mut().for_each(|v| *v /= total);
        // At least the nearest few old points must be within reach of F.
        let lambda = self.lambda.max(near.last().map_or(0.0, |n| n.1));
        let mut rng =
            ChaCha8Rng::seed_from_u64(self.seed ^ index.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let mut order: Vec<usize> = (0..m).collect();
        let steps = (self.epochs * m).max(2);
        let mut step = 0;
        for _ in 0..self.epochs {
            order.shuffle(&mut rng);
            for &i in &order {
                let t = step as f64 / (steps - 1) as f64;
                step += 1;
                let alpha = self.alpha_start * (self.alpha_end / self.alpha_start).powf(t);
                let d2: f64 = (0..dim).map(|c| (y[c] - old[[i, c]]).powi(2)).sum();
                let dy = d2.sqrt();
                let w = neighbourhood(exp, dy, lambda);
                let coef = alpha * w * (x[i] - dy) / dy.max(TINY);
                for c in 0..dim {
                    y[c] += coef * (y[c] - old[[i, c]]);
                }
            }
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vectorised block layout is the scalar reference, operation for operation.
    #[test]
    fn blocks_match_the_scalar_reference_bit_for_bit() {
        let n = 37; // not a multiple of LANES: padding is exercised
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let points = Array2::from_shape_fn((n, 5), |_| rng.random::<f64>());
        let x = Array2::from_shape_fn((n, n), |(i, j)| {
            let d = &points.row(i) - &points.row(j);
            d.dot(&d).sqrt()
        });
        let init = Array2::from_shape_fn((n, 3), |(i, c)| points[[i, c]]);
        let rows = PaddedRows::new(x.view(), n.div_ceil(LANES) * LANES);
        for f in [Neighbourhood::Step, Neighbourhood::Exp] {
            let mut fast = make_layout(init.view(), f);
            let mut slow = Flat {
                dim: 3,
                exp: f == Neighbourhood::Exp,
                coords: init.iter().copied().collect(),
            };
            for step in 0..3 * n {
                let i = (step * 7) % n;
                let lambda = 1.5 / (1.0 + step as f64 / 20.0);
                let a = fast.pivot(i, rows.row(i), 0.3, lambda);
                let b = slow.pivot(i, rows.row(i), 0.3, lambda);
                assert!(
                    (a - b).abs() <= 1e-9 * b.abs().max(1.0),
                    "{f:?}: stress {a} vs {b}"
                );
            }
            let (fa, sa) = (fast.to_array(n), slow.to_array(n));
            if f == Neighbourhood::Step {
                assert_eq!(fa, sa);
            } else {
                // exp_neg vs f64::exp: equal to ~1e-14.
                for (p, q) in fa.iter().zip(sa.iter()) {
                    assert!((p - q).abs() < 1e-9, "{p} vs {q}");
                }
            }
        }
    }

    #[test]
    fn exp_neg_matches_std() {
        let mut u = 0.0;
        while u < 720.0 {
            let (a, b) = (exp_neg(u), (-u).exp());
            assert!((a - b).abs() <= 1e-14 * b + 1e-300, "u = {u}: {a} vs {b}");
            u += 0.013_7;
        }
        assert_eq!(exp_neg(1e100), 0.0);
    }
}
