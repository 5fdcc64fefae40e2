//! The learned law `ŝ(m)`: a local polynomial regression of one log's sensor values on
//! its motor samples, with smooth weights, and the law of several logs side by side.

use std::fmt;

use rand::rngs::ChaCha8Rng;
use rand::seq::index::sample;
use rand::SeedableRng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::invariants::{InvariantModel, InvariantsReport};
use super::memory::MemoryEstimate;
use super::noise::{self, LocalRank, NoiseEstimate};
use super::quality::LawQuality;
use super::tree::{Candidates, KdTree};
use super::{observe, LawMethod, LawValidParams, LearnError, SensorimotorLog};
use crate::agent::{Agent, Environment, MotorSpace};
use crate::progress::Progress;

/// Most samples whose neighbour distances fix the bandwidth, and at which the rank of
/// the law's Jacobian is estimated.
const PROBES: usize = 512;

/// A query's candidates are the samples within `(1 + CANDIDATE_MARGIN) h` of an
/// earlier query: the queries of a traced curve, a fraction of `h` apart, reuse them
/// (see [`KdTree::within_near`]; the answers are those of a fresh query, bit for bit).
const CANDIDATE_MARGIN: f64 = 0.5;

thread_local! {
    /// Each worker thread's candidates, one list per tree it queried last.
    static CANDIDATES: std::cell::RefCell<Vec<Candidates>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Most candidate lists a thread keeps (one per log's tree).
const CANDIDATE_LISTS: usize = 8;

/// [`KdTree::within_near`] with the calling thread's candidates for `tree`.
pub(super) fn within_cached(
    tree: &KdTree,
    query: &[f64],
    radius: f64,
    visit: impl FnMut(u32, &[f64], f64),
) {
    CANDIDATES.with(|lists| {
        let mut lists = lists.borrow_mut();
        let at = match lists.iter().position(|c| c.belongs_to(tree)) {
            Some(at) => at,
            None => {
                if lists.len() >= CANDIDATE_LISTS {
                    lists.remove(0);
                }
                lists.push(Candidates::default());
                lists.len() - 1
            }
        };
        tree.within_near(
            query,
            radius,
            CANDIDATE_MARGIN * radius,
            &mut lists[at],
            visit,
        );
    });
}

/// Lanes of the fit's sums: every sum over samples is taken as [`FIT_LANES`] partial
/// sums, added pairwise at the end, with the same IEEE operations (no fused
/// multiply–add) on every instruction set, so the law does not depend on the CPU.
const FIT_LANES: usize = 4;

thread_local! {
    /// Each worker thread's samples of its latest fit.
    static FIT: std::cell::RefCell<FitSamples> = std::cell::RefCell::new(FitSamples::new());
}

/// The samples of one fit (those within the bandwidth of the query), coordinate-major,
/// padded with samples of weight 0 (and displacement 0) to `len`, a whole number of
/// [`FIT_LANES`]: the sums of the fit and of the Jacobian's moving terms vectorise over
/// them, and the tree is queried once per evaluation.
struct FitSamples {
    /// The CPU's best instruction set (pulp's runtime dispatch).
    arch: pulp::Arch,
    /// Samples within the bandwidth.
    count: usize,
    /// `count` rounded up to whole lanes: the length of every row below.
    len: usize,
    /// `w_i = (1 − ‖d_i‖²/h²)³`.
    weight: Vec<f64>,
    /// `1 − ‖d_i‖²/h²`, for `∂w_i/∂m`.
    falloff: Vec<f64>,
    /// `N × len`: `d_ij = x_ij − m_j`.
    displacement: Vec<f64>,
    /// `p × len`: the basis `φ_q(d_i / h)`.
    basis: Vec<f64>,
    /// `p × len`: `w_i φ_q(d_i / h)`.
    weighted: Vec<f64>,
    /// `K × len`: the samples' sensor values.
    sensors: Vec<f64>,
    /// `K × len`: the residuals `r_i = s_i − βᵀ φ_i` (moving terms).
    residual: Vec<f64>,
    /// `len`: `g₀ᵀ φ_i` (moving terms).
    g0_phi: Vec<f64>,
    /// `len`: one coordinate's `∂(g₀ᵀ w_i φ_i)/∂m_j` (moving terms).
    alpha: Vec<f64>,
    /// The query's samples as the tree gives them: row and squared distance.
    found: Vec<(u32, f64)>,
    /// Their displacements, row-major (`count × N`).
    found_displacement: Vec<f64>,
    /// One sample's basis (`p`).
    phi: Vec<f64>,
}

impl FitSamples {
    fn new() -> Self {
        Self {
            arch: pulp::Arch::new(),
            count: 0,
            len: 0,
            weight: Vec::new(),
            falloff: Vec::new(),
            displacement: Vec::new(),
            basis: Vec::new(),
            weighted: Vec::new(),
            sensors: Vec::new(),
            residual: Vec::new(),
            g0_phi: Vec::new(),
            alpha: Vec::new(),
            found: Vec::new(),
            found_displacement: Vec::new(),
            phi: Vec::new(),
        }
    }

    /// Gathers `model`'s samples within its bandwidth of `query` (wrapped), in the
    /// tree's order.
    fn gather(&mut self, model: &LocalModel, query: &[f64]) {
        let (n, k) = (model.n, model.k);
        let p = parameter_count(model.method, n);
        let inverse_h = 1.0 / model.bandwidth;
        let inverse_h2 = inverse_h * inverse_h;
        self.found.clear();
        self.found_displacement.clear();
        let (found, found_displacement) = (&mut self.found, &mut self.found_displacement);
        within_cached(&model.tree, query, model.bandwidth, |row, d, d2| {
            found.push((row, d2));
            found_displacement.extend_from_slice(d);
        });
        let count = self.found.len();
        let len = count.div_ceil(FIT_LANES) * FIT_LANES;
        (self.count, self.len) = (count, len);
        for (rows, v) in [
            (1, &mut self.weight),
            (1, &mut self.falloff),
            (n, &mut self.displacement),
            (p, &mut self.basis),
            (p, &mut self.weighted),
            (k, &mut self.sensors),
        ] {
            v.clear();
            v.resize(rows * len, 0.0);
        }
        self.phi.resize(p, 0.0);
        for (i, &(row, d2)) in self.found.iter().enumerate() {
            let u = 1.0 - d2 * inverse_h2;
            let w = u * u * u;
            self.weight[i] = w;
            self.falloff[i] = u;
            let d = &self.found_displacement[i * n..(i + 1) * n];
            for (j, &dj) in d.iter().enumerate() {
                self.displacement[j * len + i] = dj;
            }
            model.basis(d, inverse_h, &mut self.phi);
            for (q, &phi) in self.phi.iter().enumerate() {
                self.basis[q * len + i] = phi;
                self.weighted[q * len + i] = w * phi;
            }
            let s = &model.sensors[row as usize * k..(row as usize + 1) * k];
            for (c, &sc) in s.iter().enumerate() {
                self.sensors[c * len + i] = sc;
            }
        }
    }
}

/// Row `q` of a [`FitSamples`] array of rows of `len`.
#[inline(always)]
fn lane_row(q: usize, len: usize) -> std::ops::Range<usize> {
    q * len..(q + 1) * len
}

/// `Σ_i x_i y_i` over whole lanes (see [`FIT_LANES`]).
#[inline(always)]
fn lane_dot(x: &[f64], y: &[f64]) -> f64 {
    let mut acc = [0.0f64; FIT_LANES];
    for (xs, ys) in x.chunks_exact(FIT_LANES).zip(y.chunks_exact(FIT_LANES)) {
        for l in 0..FIT_LANES {
            acc[l] += xs[l] * ys[l];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// The fit's normal equations: `G = Σ w_i φ_i φ_iᵀ` (upper triangle, `p × p`) and
/// `R = Σ w_i φ_i s_iᵀ` (`p × K`).
struct Sums<'a> {
    fit: &'a FitSamples,
    gram: &'a mut [f64],
    rhs: &'a mut [f64],
    p: usize,
    k: usize,
}

impl pulp::WithSimd for Sums<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let (fit, p, k) = (self.fit, self.p, self.k);
        let row = |q: usize| lane_row(q, fit.len);
        for a in 0..p {
            let wa = &fit.weighted[row(a)];
            for b in a..p {
                self.gram[a * p + b] = lane_dot(wa, &fit.basis[row(b)]);
            }
            for c in 0..k {
                self.rhs[a * k + c] = lane_dot(wa, &fit.sensors[row(c)]);
            }
        }
    }
}

/// The Jacobian's moving terms (see [`LocalModel::add_moving_terms`]), added to `jac`.
struct MovingTerms<'a> {
    fit: &'a mut FitSamples,
    beta: &'a [f64],
    g0: &'a [f64],
    jac: &'a mut [f64],
    /// `(N, K, p)`.
    shape: (usize, usize, usize),
    inverse_h: f64,
    quadratic: bool,
}

impl pulp::WithSimd for MovingTerms<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let (n, k, p) = self.shape;
        let (g0, beta) = (self.g0, self.beta);
        let inverse_h2 = self.inverse_h * self.inverse_h;
        let FitSamples {
            len,
            weight,
            falloff,
            displacement,
            basis,
            sensors,
            residual,
            g0_phi,
            alpha,
            ..
        } = self.fit;
        let len = *len;
        let row = |q: usize| lane_row(q, len);
        // r_i = s_i − βᵀ φ_i (0 on the padding): the fitted value, then the residual, in place.
        residual.clear();
        residual.resize(k * len, 0.0);
        for c in 0..k {
            let r = &mut residual[row(c)];
            for q in 0..p {
                let b = beta[q * k + c];
                for (f, &phi) in r.iter_mut().zip(&basis[row(q)]) {
                    *f += phi * b;
                }
            }
            for (r, &s) in r.iter_mut().zip(&sensors[row(c)]) {
                *r = s - *r;
            }
        }
        g0_phi.clear();
        g0_phi.resize(len, 0.0);
        for (q, &g) in g0.iter().enumerate() {
            for (v, &phi) in g0_phi.iter_mut().zip(&basis[row(q)]) {
                *v += g * phi;
            }
        }
        alpha.clear();
        alpha.resize(len, 0.0);
        for j in 0..n {
            // g₀ᵀ ∂φ/∂u_j: the linear term's 1, and u_b (u_a) for a quadratic u_a u_b.
            alpha.fill(g0[1 + j]);
            if self.quadratic {
                let mut at = 1 + n;
                for a in 0..n {
                    for b in a..n {
                        if a == j {
                            for (v, &u) in alpha.iter_mut().zip(&basis[row(1 + b)]) {
                                *v += g0[at] * u;
                            }
                        }
                        if b == j {
                            for (v, &u) in alpha.iter_mut().zip(&basis[row(1 + a)]) {
                                *v += g0[at] * u;
                            }
                        }
                        at += 1;
                    }
                }
            }
            // ∂w_i/∂m_j g₀ᵀφ_i − w_i/h g₀ᵀ ∂φ/∂u_j (0 on the padding: w = u = d = 0).
            let d = &displacement[row(j)];
            for i in 0..len {
                let u = falloff[i];
                let dw = 6.0 * u * u * d[i] * inverse_h2;
                alpha[i] = dw * g0_phi[i] - weight[i] * self.inverse_h * alpha[i];
            }
            for c in 0..k {
                self.jac[c * n + j] += lane_dot(alpha, &residual[row(c)]);
            }
        }
    }
}

/// What a fit at one configuration found: its samples within the bandwidth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitSupport {
    /// Samples closer than the bandwidth.
    pub count: usize,
}

/// One log's local regression (see the module docs of [`crate::learn`]).
pub(crate) struct LocalModel {
    space: MotorSpace,
    method: LawMethod,
    tree: KdTree,
    /// Sensor values of the fitted rows, `S × K` row-major (rows as in the tree).
    sensors: Vec<f64>,
    n: usize,
    k: usize,
    bandwidth: f64,
    min_count: usize,
    ridge: f64,
}

/// Number of coefficients of the local polynomial in `n` motors.
pub(crate) fn parameter_count(method: LawMethod, n: usize) -> usize {
    match method {
        LawMethod::LocalLinear => 1 + n,
        LawMethod::LocalQuadratic => 1 + n + n * (n + 1) / 2,
        // The basis functions of the invariants, with the constant.
        LawMethod::Invariants => 3usize.saturating_pow(n as u32),
    }
}

impl LocalModel {
    /// Fits the model to the rows `fit` of `log` (bandwidth from the data's spacing).
    pub(crate) fn new(
        log: &SensorimotorLog,
        fit: &[u32],
        params: &LawValidParams,
        space: &MotorSpace,
        progress: &dyn Progress,
    ) -> Result<(Self, f64), LearnError> {
        let (n, k) = (log.motors.ncols(), log.sensors.ncols());
        let (tree, bandwidth, images) = image_tree(log, fit, space, params, progress)?;
        let mut sensors = vec![0.0; log.sensors.len()];
        for (out, row) in sensors.chunks_mut(k).zip(log.sensors.outer_iter()) {
            out.iter_mut().zip(row).for_each(|(a, &b)| *a = b);
        }
        let model = Self {
            space: space.clone(),
            method: params.method,
            tree,
            sensors,
            n,
            k,
            bandwidth,
            min_count: params.coverage_neighbours(n),
            ridge: params.ridge,
        };
        Ok((model, images))
    }

    /// The bandwidth `h` (motor units).
    pub(crate) fn bandwidth(&self) -> f64 {
        self.bandwidth
    }

    /// Writes `ŝ(m)` into `value` (length `K`) and, when asked, the fit's slope
    /// `∂ŝ/∂m` into `jacobian` (`K × N`, row-major); returns the fit's support. With no
    /// sample within the bandwidth the law is 0 there (and does not cover `m`).
    ///
    /// One query of the tree gathers the samples within the bandwidth
    /// ([`FitSamples`]); the fit's sums and the Jacobian's moving terms are then sums
    /// over those samples, taken [`FIT_LANES`] at a time.
    pub(crate) fn evaluate(
        &self,
        m: &[f64],
        value: &mut [f64],
        jacobian: Option<&mut [f64]>,
    ) -> FitSupport {
        let (n, k) = (self.n, self.k);
        let p = parameter_count(self.method, n);
        let query: Vec<f64> = m
            .iter()
            .enumerate()
            .map(|(j, &x)| self.space.motor(j).wrap(x))
            .collect();
        let inverse_h = 1.0 / self.bandwidth;
        FIT.with(|fit| {
            let fit = &mut *fit.borrow_mut();
            fit.gather(self, &query);
            let support = FitSupport { count: fit.count };
            let mut gram = vec![0.0; p * p];
            let mut rhs = vec![0.0; p * k];
            let arch = fit.arch;
            arch.dispatch(Sums {
                fit: &*fit,
                gram: &mut gram,
                rhs: &mut rhs,
                p,
                k,
            });
            if fit.count == 0 || !solve(&mut gram, &mut rhs, p, k, self.ridge) {
                value.fill(0.0);
                if let Some(j) = jacobian {
                    j.fill(0.0);
                }
                return support;
            }
            value.copy_from_slice(&rhs[..k]);
            if let Some(jac) = jacobian {
                for i in 0..k {
                    for j in 0..n {
                        jac[i * n + j] = rhs[(1 + j) * k + i] * inverse_h;
                    }
                }
                self.add_moving_terms(fit, (&gram, &rhs), jac);
            }
            support
        })
    }

    /// Adds to the fit's slope `B/h` (in `jac`, `K × N`) the rest of the derivative of
    /// the law's value `a(m) = e₀ᵀ β(m)`, so that the Jacobian is that of the value the
    /// tracer follows. With `G = Σ w_i φ_i φ_iᵀ`, `β = G⁻¹ Σ w_i φ_i s_iᵀ`, residuals
    /// `r_i = s_i − βᵀ φ_i` and `g₀ = G⁻¹ e₀`:
    ///
    /// ```text
    /// ∂a/∂m_j = β_{1+j}/h + Σ_i g₀ᵀ (∂w_i/∂m_j φ_i + w_i ∂φ_i/∂m_j) r_i
    /// ```
    ///
    /// (the term `−G⁻¹ Σ w_i φ_i (∂φ_i/∂m_j)ᵀ β` is the slope, since the derivatives of
    /// a polynomial basis lie in its span), with `∂w_i/∂m_j = 6 (1 − ‖d_i‖²/h²)² d_ij/h²`
    /// and `∂φ_i/∂m_j = −(1/h) ∂φ/∂u_j` at `u = d_i/h`, `d_i = x_i − m`. The ridge's own
    /// derivative is left out (its order, `10⁻⁶` of the weight by default). Without
    /// these terms (the slope alone) the direction the tracer predicts along leaves the
    /// level set of the value by more than the adaptive step allows, and the step
    /// collapses. The sums run over the fit's own samples (`fit`, gathered by
    /// [`LocalModel::evaluate`]).
    fn add_moving_terms(
        &self,
        fit: &mut FitSamples,
        (factor, beta): (&[f64], &[f64]),
        jac: &mut [f64],
    ) {
        let (n, k) = (self.n, self.k);
        let p = parameter_count(self.method, n);
        // g₀ = G⁻¹ e₀ from the Cholesky factor L (lower triangle of `factor`).
        let mut g0 = vec![0.0; p];
        g0[0] = 1.0;
        substitute(factor, &mut g0, p, 1);
        let arch = fit.arch;
        arch.dispatch(MovingTerms {
            fit,
            beta,
            g0: &g0,
            jac,
            shape: (n, k, p),
            inverse_h: 1.0 / self.bandwidth,
            quadratic: self.method == LawMethod::LocalQuadratic,
        });
    }

    /// The polynomial basis at a displacement: `1`, `d/h`, and for the quadratic fit
    /// `d_a d_b / h²` (`a ≤ b`).
    #[inline]
    fn basis(&self, displacement: &[f64], inverse_h: f64, out: &mut [f64]) {
        let n = self.n;
        out[0] = 1.0;
        for j in 0..n {
            out[1 + j] = displacement[j] * inverse_h;
        }
        if self.method == LawMethod::LocalQuadratic {
            let mut at = 1 + n;
            for a in 0..n {
                for b in a..n {
                    out[at] = out[1 + a] * out[1 + b];
                    at += 1;
                }
            }
        }
    }

    /// Whether `m` is in the region the data cover (see [`crate::learn`]).
    pub(crate) fn covers(&self, m: &[f64]) -> bool {
        covered(&self.space, &self.tree, self.bandwidth, self.min_count, m)
    }
}

/// Whether at least `min_count` points of `tree` (fitted samples with their periodic
/// images) lie within `bandwidth` of `m` (wrapped into `space`): the coverage of a law
/// (see [`crate::learn`]). Within `h` of a bounded motor's limit, part of the ball is
/// outside the motor space and holds no sample however dense the babbling: the count
/// asked for is `min_count` times the share of the ball inside,
/// `Π_j (1 + min(d_j / h, 1)) / 2` over the bounded motors (`d_j` the distance to the
/// nearer limit), at least 1.
pub(super) fn covered(
    space: &MotorSpace,
    tree: &KdTree,
    bandwidth: f64,
    min_count: usize,
    m: &[f64],
) -> bool {
    let query: Vec<f64> = m
        .iter()
        .enumerate()
        .map(|(j, &x)| space.motor(j).wrap(x))
        .collect();
    let inside: f64 = query
        .iter()
        .enumerate()
        .filter(|(j, _)| !space.motor(*j).is_periodic())
        .map(|(j, &x)| {
            let (low, high) = space.motor(j).range();
            let d = (x - low).min(high - x).max(0.0);
            0.5 * (1.0 + (d / bandwidth).min(1.0))
        })
        .product();
    let needed = ((min_count as f64 * inside).ceil() as usize).clamp(1, min_count.max(1));
    let mut count = 0;
    within_cached(tree, &query, bandwidth, |_, _, _| count += 1);
    count >= needed
}

/// The bandwidth `h` of a log's fitted rows (`bandwidth_factor` times the median
/// distance to the `neighbours`-th nearest sample), refused when it reaches a quarter
/// of the shortest period, and the k-d tree of those rows with their periodic images
/// within `h` of the ends, with the images per fitted row: the stage
/// [`observe::TREE`] of `progress` (two steps: the bandwidth, then the images' tree).
pub(super) fn image_tree(
    log: &SensorimotorLog,
    fit: &[u32],
    space: &MotorSpace,
    params: &LawValidParams,
    progress: &dyn Progress,
) -> Result<(KdTree, f64, f64), LearnError> {
    progress.start(observe::TREE, 2);
    let built = build_image_tree(log, fit, space, params, progress);
    progress.finish();
    built
}

/// [`image_tree`]'s work.
fn build_image_tree(
    log: &SensorimotorLog,
    fit: &[u32],
    space: &MotorSpace,
    params: &LawValidParams,
    progress: &dyn Progress,
) -> Result<(KdTree, f64, f64), LearnError> {
    let n = log.motors.ncols();
    let mut points = Vec::with_capacity(fit.len() * n);
    for &row in fit {
        points.extend(log.motors.row(row as usize).iter().copied());
    }
    let plain = KdTree::new(n, points, fit.to_vec());
    let neighbours = params.neighbours(n);
    let bandwidth = params.bandwidth_factor * median_kth_distance(&plain, neighbours, params);
    drop(plain);
    if let Some(period) = space
        .motors()
        .iter()
        .filter_map(|m| m.period())
        .reduce(f64::min)
    {
        if bandwidth.is_nan() || bandwidth >= period / 4.0 {
            return Err(LearnError::TooFewSamples {
                path: log.files.motors.clone(),
                samples: fit.len(),
                reason: format!(
                    "the {neighbours} nearest samples of a typical sample lie within {bandwidth:.3}, more than a quarter period ({:.3}): the data are too sparse for the law's bandwidth",
                    period / 4.0
                ),
                fix: "record more samples, or lower neighbours",
            });
        }
    }
    progress.advance(1);
    let (points, rows) = periodic_images(log, fit, space, bandwidth);
    let images = rows.len() as f64 / fit.len().max(1) as f64;
    let tree = KdTree::new(n, points, rows);
    progress.advance(1);
    Ok((tree, bandwidth, images))
}

/// Solves `(G + ridge·tr)·C = R` in place (`G` upper triangle given, `p × p`; `R`
/// `p × k`), the ridge added to the non-constant coefficients relative to the total
/// weight `G₀₀`. Returns false when the system is not positive definite.
fn solve(gram: &mut [f64], rhs: &mut [f64], p: usize, k: usize, ridge: f64) -> bool {
    let total = gram[0];
    for a in 1..p {
        gram[a * p + a] += ridge * total;
    }
    // Cholesky G = L Lᵀ, L stored in the lower triangle.
    for i in 0..p {
        for j in 0..=i {
            let mut s = gram[j * p + i];
            for q in 0..j {
                s -= gram[i * p + q] * gram[j * p + q];
            }
            if i == j {
                if s.is_nan() || s <= 1e-300 {
                    return false;
                }
                gram[i * p + i] = s.sqrt();
            } else {
                gram[i * p + j] = s / gram[j * p + j];
            }
        }
    }
    substitute(gram, rhs, p, k);
    true
}

/// Solves `L Lᵀ C = R` in place for the Cholesky factor `L` (the lower triangle of
/// `factor`, `p × p`, as [`solve`] leaves it) and `R` (`p × k`).
fn substitute(factor: &[f64], rhs: &mut [f64], p: usize, k: usize) {
    for c in 0..k {
        for i in 0..p {
            let mut s = rhs[i * k + c];
            for q in 0..i {
                s -= factor[i * p + q] * rhs[q * k + c];
            }
            rhs[i * k + c] = s / factor[i * p + i];
        }
        for i in (0..p).rev() {
            let mut s = rhs[i * k + c];
            for q in i + 1..p {
                s -= factor[q * p + i] * rhs[q * k + c];
            }
            rhs[i * k + c] = s / factor[i * p + i];
        }
    }
}

/// The median over (at most [`PROBES`]) seeded samples of the distance to their
/// `neighbours`-th nearest other sample.
pub(super) fn median_kth_distance(
    tree: &KdTree,
    neighbours: usize,
    params: &LawValidParams,
) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed ^ 0x6b64);
    let probes = sample(&mut rng, tree.len(), PROBES.min(tree.len())).into_vec();
    let mut distances: Vec<f64> = probes
        .par_iter()
        .map(|&i| {
            let point = tree.point(i);
            // The sample itself is its own nearest point.
            tree.kth_distance(point, neighbours + 1)
        })
        .collect();
    distances.sort_by(f64::total_cmp);
    distances[distances.len() / 2]
}

/// The fitted rows and their images shifted by whole periods where a periodic
/// coordinate lies within `bandwidth` of its range's ends, so that a query in the range
/// finds every sample within `bandwidth` on the torus as one plain point.
pub(super) fn periodic_images(
    log: &SensorimotorLog,
    fit: &[u32],
    space: &MotorSpace,
    bandwidth: f64,
) -> (Vec<f64>, Vec<u32>) {
    let n = log.motors.ncols();
    let mut points = Vec::with_capacity(fit.len() * n * 3 / 2);
    let mut rows = Vec::with_capacity(fit.len() * 3 / 2);
    let mut shifts: Vec<Vec<f64>> = vec![Vec::new(); n];
    for &row in fit {
        let x = log.motors.row(row as usize);
        for j in 0..n {
            shifts[j].clear();
            shifts[j].push(0.0);
            if let Some(period) = space.motor(j).period() {
                if x[j] < -period / 2.0 + bandwidth {
                    shifts[j].push(period);
                }
                if x[j] >= period / 2.0 - bandwidth {
                    shifts[j].push(-period);
                }
            }
        }
        // Every combination of the shifts (mixed radix).
        let total: usize = shifts.iter().map(Vec::len).product();
        for combination in 0..total {
            let mut c = combination;
            for j in 0..n {
                let options = &shifts[j];
                points.push(x[j] + options[c % options.len()]);
                c /= options.len();
            }
            rows.push(row);
        }
    }
    (points, rows)
}

/// What learning found, written beside the sets (`<stem>.law.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LawReport {
    /// The regression.
    pub method: LawMethod,
    /// Per log: samples, fitted rows, held-out rows, bandwidth, images, error.
    pub logs: Vec<LogReport>,
    /// The rank the tracer uses: the rank given (`rank` of [`LawParams`](super::LawParams)),
    /// else the one the evidence reads ([`RankChoice`]: that of `data_rank`, or for
    /// `invariants` the invariants' Jacobian's where the evidence backs it, else the
    /// law's Jacobian's when the log is too short for the data's rank); after tracing,
    /// the next candidate when every set failed at it (see `rank_source`).
    pub rank: usize,
    /// Where `rank` comes from.
    #[serde(default)]
    pub rank_source: RankSource,
    /// How often each rank of the law's Jacobian was found at the probed samples
    /// (index = rank; by the largest gap of singular values).
    pub rank_counts: Vec<usize>,
    /// The `invariants` method's eigenproblem (absent for the local fits).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub invariants: Option<InvariantsReport>,
    /// The rank of `∂s/∂m` seen in the first log's data, with its evidence (the
    /// spectrum and the noise floor).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_rank: Option<LocalRank>,
    /// How `rank` was chosen: the rank given, the pieces of evidence, the candidates in
    /// the order they are tried and why ([`RankChoice`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rank_choice: Option<RankChoice>,
    /// What the data cannot support (too few samples, too much noise), with the
    /// measured noise and what would help.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// The law's quality without the truth: samples per dimension, the invariants'
    /// change between held-out sensory neighbours, and after tracing the closure rate
    /// (see the `quality` module).
    #[serde(default)]
    pub quality: LawQuality,
    /// The memory learning was estimated to need before it started.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub memory: Option<MemoryEstimate>,
}

/// The share of the probed samples at which the invariants' Jacobian must have one
/// rank, lower than the data's, for the law to be traced at that rank
/// ([`RankSource::Invariants`]).
pub const UNANIMOUS_SHARE: f64 = 0.9;

/// Where the rank of a [`LawReport`] comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RankSource {
    /// The rank of the sensors' local slopes in the data (`data_rank`).
    #[default]
    Data,
    /// The invariants' Jacobian, lower than the data's rank at nearly every probed
    /// sample ([`UNANIMOUS_SHARE`]): the kernels of a law whose values are the
    /// invariants have that rank. The data's slopes over-read it when the sensors curve
    /// across a neighbourhood of the samples' spacing (wide neighbourhoods in many
    /// motors); a direction the invariants' basis cannot express would also show so,
    /// and then the sets are too large.
    Invariants,
    /// The law's Jacobian (`rank_counts`), the log being too short for a data rank.
    Law,
    /// Given by the user (`rank` of [`LawParams`](super::LawParams)).
    Given,
    /// The agent's own slope, read at a few starts with a tight stencil
    /// ([`AgentRank`]): a direction of change too weak for the babbling's spacing.
    Agent,
    /// The next candidate of [`RankChoice::candidates`]: every set failed at the ranks
    /// before it ([`RankChoice::tried`]).
    Retried,
}

/// The least ratio `λ_{q+1} / λ_q` between the first eigenvalue left out and the last
/// one kept for the invariants' Jacobian to count as evidence of a rank above the
/// data's spectrum: the kept functions are far more invariant between sensory
/// neighbours than any other function of the basis (the paper's arm: 0.02 against
/// 0.52, a ratio of 25).
pub const INVARIANT_GAP: f64 = 3.0;

/// How far the invariants may change more between held-out sensory neighbours than
/// between the fitted ones (`held_out_lambda ≤ HELD_OUT_SLACK × fitted_lambda +
/// 0.01`) for their Jacobian's rank to count as evidence: functions that held-out
/// neighbours share as well as fitted ones are functions of what the sensors tell
/// apart.
pub const HELD_OUT_SLACK: f64 = 2.0;

/// How the law's rank was chosen (in the [`LawReport`], printed by `smspace learn` and
/// in the Python report's `law`): the pieces of evidence, the rank they read, the
/// candidates in the order they are tried, and why.
///
/// The evidence: the data's slope spectrum (`data`: the rank at its clear gap, see
/// [`super::spectrum_rank`]); the held-out prediction at each rank (`held_out`: the
/// rank whose fits predict unseen samples best, a lower bound where a direction is
/// weaker than the curvature across the data's spacing); for `invariants`, the rank of the invariants' Jacobian
/// at the probed samples (`invariants`, with the share of the probes that show it)
/// with the gap of their eigenvalues (`invariants_gap`, `λ_{q+1} / λ_q`) and their
/// held-out `λ`. The invariants' rank is chosen over the data's
///
/// - when it is lower at [`UNANIMOUS_SHARE`] of the probes: the data's affine slopes
///   over-read the rank when the sensors curve across the samples' spacing;
/// - when it is higher at [`UNANIMOUS_SHARE`] of the probes, the invariants stand
///   apart (`invariants_gap ≥` [`INVARIANT_GAP`]), held-out sensory neighbours share
///   them as the fitted ones do ([`HELD_OUT_SLACK`]) and the spectrum has a value
///   above its noise floor at that rank: functions that sensory neighbours share are
///   locally functions of the sensors, so `rank ∂s/∂m ≥ rank ∂z/∂m`; the spectrum's
///   gap at a lower rank is a weak direction of change (far lights, long ranges) read
///   as the leak of the kernel's direction.
///
/// Otherwise the data's rank stands. Where the held-out reading differs from the rank
/// chosen, the reason says so with the errors at both ranks; it is not used against
/// the spectrum, which sees weak directions that held-out prediction at the data's
/// spacing cannot, but it is among the candidates. A rank given by the user is used as
/// given; the estimate is reported beside it, with a warning when they differ. When
/// every traced set fails at the estimated rank, the next candidate is traced
/// (`tried`); with an agent at hand, when most of a few sets fail against its readings,
/// the next candidates above are tried ([`super::budget`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RankChoice {
    /// The rank used.
    pub rank: usize,
    /// Where it comes from.
    pub source: RankSource,
    /// The rank given by the user, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub given: Option<usize>,
    /// The rank the evidence reads (the rank used unless one was given or a retry
    /// moved on).
    pub estimate: usize,
    /// The rank of the data's slope spectrum (`data_rank`), absent for a short log.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<usize>,
    /// The rank at which held-out prediction is best (`data_rank.held_out_rank`, see
    /// [`super::held_out_rank`]), absent for a short log.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<usize>,
    /// The rank of the agent's own slope ([`AgentRank`]), when an agent was read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agent: Option<usize>,
    /// The most frequent rank of the law's Jacobian at the probed samples (the
    /// invariants' for `invariants`).
    pub invariants: usize,
    /// The share of the probed samples at that rank.
    pub invariants_share: f64,
    /// `invariants` only: the ratio of the first eigenvalue left out to the last one
    /// kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub invariants_gap: Option<f64>,
    /// The ranks to trace at, in order (`1..N−1` only; the first is `rank` unless a
    /// rank was given): when every set fails at one, the next is tried.
    pub candidates: Vec<usize>,
    /// The ranks tried before `rank`, each with what its sets did.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tried: Vec<TriedRank>,
    /// Why this rank.
    pub reason: String,
}

/// A rank at which every traced set failed ([`RankChoice::tried`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TriedRank {
    /// The rank.
    pub rank: usize,
    /// Sets traced at it, of `total`.
    pub total: usize,
    /// The sets' statuses and their counts.
    pub by_status: std::collections::BTreeMap<String, usize>,
}

/// The rank of an agent's own slope `∂s/∂m`, read where a learned law is traced
/// ([`super::budget`]): at `P` starts `m`, the agent is read twice at `m` and at
/// `m ± δ e_j` for every motor `j` (`2N + 2` rows; a bounded motor's step is cut at
/// its limits). The central differences, each sensor divided by its spread `σ_k`,
/// give the slope `B` (`K × N`) with the error `O(δ²)` of the curvature and the noise
/// `σ̂_k / (√2 δ)` per entry (`σ̂_k` from the two readings at `m`, relative). As for
/// the data's spectrum ([`super::LocalRank`]), the spectrum is the median over the
/// starts of `β_r² − K σ̂² / (2δ²)` relative to that of `β_1²`, square-rooted, and
/// `floor` the noise's share on the same scale; the rank is read by
/// [`super::spectrum_rank`] with values at or under `floor` not counted.
///
/// It is weighed against the law's estimate ([`LearnedLaw::weigh_agent_rank`]): when it
/// is higher, inside `1..N`, and its value at that rank is at least
/// [`AGENT_FLOOR_MULTIPLE`] times its floor, the agent's rank is used (a direction
/// the babbling's spacing blurred into the curvature); a lower reading is reported, not
/// used (noise hides weak directions from a short stencil).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AgentRank {
    /// The rank read.
    pub rank: usize,
    /// The median spectrum, `β_r / β_1`, `r = 1..=N`.
    pub spectrum: Vec<f64>,
    /// The noise's share of the spectrum.
    pub floor: f64,
    /// Starts read.
    pub starts: usize,
    /// The stencil's step `δ` (motor units).
    pub step: f64,
}

/// How many times its noise floor the agent's spectrum must be at a rank above the
/// law's estimate for that rank to be used ([`AgentRank`]): 3.
pub const AGENT_FLOOR_MULTIPLE: f64 = 3.0;

impl LawReport {
    /// The report after every set failed at `tried.rank` (in tracing, or against the
    /// agent's readings) and the sets were traced again at `next`: `rank`,
    /// `rank_source` ([`RankSource::Retried`]) and `rank_choice.tried` say so.
    pub(crate) fn retried(&mut self, tried: TriedRank, next: usize) {
        self.rank = next;
        self.rank_source = RankSource::Retried;
        if let Some(choice) = self.rank_choice.as_mut() {
            choice.tried.push(tried);
            choice.rank = next;
            choice.source = RankSource::Retried;
        }
    }
}

/// The evidence on the rank that [`choose_rank`] weighs.
#[derive(Debug, Clone)]
pub(crate) struct RankEvidence<'a> {
    /// Motors `N`.
    pub n: usize,
    /// The law's regression.
    pub method: LawMethod,
    /// The rank given by the user.
    pub given: Option<usize>,
    /// The data's spectrum.
    pub data: Option<&'a LocalRank>,
    /// Counts of the law's Jacobian ranks at the probes (index = rank).
    pub counts: &'a [usize],
    /// The invariants' eigenproblem.
    pub invariants: Option<&'a InvariantsReport>,
}

/// The rank of the law (see [`RankChoice`]).
pub(crate) fn choose_rank(evidence: &RankEvidence<'_>) -> RankChoice {
    let n = evidence.n;
    let counts = evidence.counts;
    let generic = (0..counts.len())
        .max_by_key(|&r| (counts[r], r))
        .unwrap_or(0);
    let probed: usize = counts.iter().sum();
    let share = counts.get(generic).copied().unwrap_or(0) as f64 / probed.max(1) as f64;
    let nearly_all = share >= UNANIMOUS_SHARE && probed > 0;
    let gap = evidence.invariants.and_then(|inv| {
        let q = inv.invariants;
        let (last, next) = (
            inv.eigenvalues.get(q.checked_sub(1)?)?,
            inv.eigenvalues.get(q)?,
        );
        Some(next / last.max(1e-12))
    });
    let held_out_shared = evidence.invariants.is_some_and(|inv| {
        inv.held_out_lambda
            .is_none_or(|h| h <= HELD_OUT_SLACK * inv.fitted_lambda + 0.01)
    });
    let invariants = evidence.method == LawMethod::Invariants;
    let inner = |r: usize| (1..n).contains(&r);
    let (estimate, source, reason) = match evidence.data {
        Some(data) if invariants && nearly_all && inner(generic) && generic < data.rank => (
            generic,
            RankSource::Invariants,
            format!(
                "the data's slope spectrum reads rank {} but the invariants change along {generic} directions at {:.0} % of the probed samples: the affine slopes count the sensors' curvature across the samples' spacing",
                data.rank,
                100.0 * share
            ),
        ),
        Some(data)
            if invariants
                && nearly_all
                && inner(generic)
                && generic > data.rank
                && gap.is_some_and(|g| g >= INVARIANT_GAP)
                && held_out_shared
                && data
                    .spectrum
                    .get(generic - 1)
                    .is_some_and(|&b| b > noise::FLOOR_SHARE * data.floor && b > 0.0) =>
        {
            let lambda = |i: &InvariantsReport, at: usize| i.eigenvalues.get(at).copied();
            let (q, last, next, held) = evidence.invariants.map_or((0, 0.0, 0.0, None), |i| {
                let q = i.invariants;
                (
                    q,
                    lambda(i, q.saturating_sub(1)).unwrap_or(0.0),
                    lambda(i, q).unwrap_or(0.0),
                    i.held_out_lambda,
                )
            });
            (
                generic,
                RankSource::Invariants,
                format!(
                    "the data's slope spectrum ({}) reads rank {}, but the {q} invariants (λ ≤ {last:.3}, the next {next:.3}: {:.0}× apart; held out λ {}) change along {generic} independent directions at {:.0} % of the probed samples; functions that sensory neighbours share are functions of the sensors, so the sensors change along at least {generic} directions (the spectrum's {:.3} at rank {generic} is a weak direction of change, not the kernel's leak)",
                    format_spectrum(&data.spectrum),
                    data.rank,
                    gap.unwrap_or(0.0),
                    held.map_or("-".to_owned(), |h| format!("{h:.3}")),
                    100.0 * share,
                    data.spectrum[generic - 1],
                ),
            )
        }
        Some(data) => {
            let mut reason = format!(
                "the data's slope spectrum ({}) reads rank {}",
                format_spectrum(&data.spectrum),
                data.rank
            );
            if generic != data.rank {
                let why = if !invariants {
                    "the law's Jacobian is not used against the data's rank for a local law".to_owned()
                } else if !nearly_all {
                    format!("only {:.0} % of the probed samples agree", 100.0 * share)
                } else if !inner(generic) {
                    format!("rank {generic} leaves no kernel of dimension 1 to {}", n.saturating_sub(1))
                } else if !gap.is_some_and(|g| g >= INVARIANT_GAP) {
                    format!(
                        "the invariants do not stand apart from the other functions (eigenvalue gap {}, below {INVARIANT_GAP})",
                        gap.map_or("-".to_owned(), |g| format!("{g:.1}"))
                    )
                } else if !held_out_shared {
                    "held-out sensory neighbours do not share the invariants as the fitted ones do".to_owned()
                } else {
                    format!("the spectrum has no value above its noise floor at rank {generic}")
                };
                reason.push_str(&format!(
                    "; the invariants' Jacobian has rank {generic} at {:.0} % of the probed samples, not used: {why}",
                    100.0 * share
                ));
            }
            (data.rank, RankSource::Data, reason)
        }
        None => (
            generic,
            RankSource::Law,
            format!(
                "the log is too short for the data's rank: the law's Jacobian has rank {generic} at {:.0} % of the probed samples",
                100.0 * share
            ),
        ),
    };
    let held_out = evidence.data.and_then(|d| d.held_out_rank);
    let reason = match (held_out, evidence.data) {
        (Some(h), Some(data)) if h != estimate && data.held_out.len() > h.max(estimate) => {
            format!(
                "{reason}; held-out prediction is best at rank {h} (error {:.4} of the sensors' spread, {:.4} at rank {estimate}){}",
                data.held_out[h],
                data.held_out[estimate],
                if h < estimate {
                    format!(": directions beyond rank {h} change the sensors less than the curvature across the data's spacing")
                } else {
                    String::new()
                }
            )
        }
        _ => reason,
    };
    // The candidates: the estimate, the other readings, then the spectrum's gaps from
    // the largest ratio down.
    let mut candidates = vec![estimate, generic];
    if let Some(data) = evidence.data {
        candidates.push(data.rank);
        candidates.extend(data.held_out_rank);
        let s = &data.spectrum;
        let mut gaps: Vec<(f64, usize)> = (1..s.len())
            .map(|r| (s[r - 1] / s[r].max(f64::MIN_POSITIVE), r))
            .collect();
        gaps.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        candidates.extend(gaps.into_iter().map(|(_, r)| r));
    }
    let mut unique = Vec::new();
    for r in candidates {
        if inner(r) && !unique.contains(&r) {
            unique.push(r);
        }
    }
    let (rank, source, reason) = match evidence.given {
        Some(given) => {
            let reason = if given == estimate {
                format!("rank {given} given; the evidence reads the same: {reason}")
            } else {
                format!("rank {given} given, used in place of the estimate {estimate}: {reason}")
            };
            (given, RankSource::Given, reason)
        }
        None => (estimate, source, reason),
    };
    RankChoice {
        rank,
        source,
        given: evidence.given,
        estimate,
        data: evidence.data.map(|d| d.rank),
        held_out,
        agent: None,
        invariants: generic,
        invariants_share: share,
        invariants_gap: gap,
        candidates: if evidence.given.is_some() {
            vec![rank]
        } else {
            unique
        },
        tried: Vec::new(),
        reason,
    }
}

/// A spectrum as `1.000 0.234 …`.
fn format_spectrum(spectrum: &[f64]) -> String {
    spectrum
        .iter()
        .map(|b| format!("{b:.3}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// One log's part of the [`LawReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LogReport {
    /// The motors file.
    pub motors: String,
    /// The sensors file.
    pub sensors: String,
    /// Samples in the log.
    pub samples: usize,
    /// Samples the law was fitted to.
    pub fitted: usize,
    /// Samples held out to measure its error.
    pub held_out: usize,
    /// The bandwidth `h` (motor units, radians for hinges).
    pub bandwidth: f64,
    /// Points in the k-d tree per fitted sample (periodic images included).
    pub images_per_sample: f64,
    /// Held-out root-mean-square error over every sensor, relative to the root mean
    /// square of the sensors' standard deviations.
    pub held_out_relative_rms: f64,
    /// Largest held-out absolute error of one sensor value.
    pub held_out_max_abs: f64,
    /// Held-out samples outside the covered region (not counted in the error).
    pub held_out_uncovered: usize,
    /// Samples a typical local fit holds, as chosen (the measured noise may raise the
    /// default; absent for `invariants`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub neighbours: Option<usize>,
    /// The sensor noise measured from the log (absent when it has too few samples).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<NoiseEstimate>,
    /// Samples that repeat an earlier sample's motor command
    /// ([`REPEAT_TOLERANCE`](super::REPEAT_TOLERANCE)): counted once, left out of the
    /// fit and the held-out samples (`samples` counts them).
    #[serde(default)]
    pub repeated: usize,
}

/// The models behind a [`LearnedLaw`].
pub(crate) enum Models {
    /// One local regression per log; the law's values are their sensor values side by
    /// side.
    Local(Vec<LocalModel>),
    /// The invariants of all logs together; the law's values are the invariants.
    Invariants(Box<InvariantModel>),
}

/// The law learned from one or several logs (one per environment): the sensor values
/// of every log's model side by side, `K = Σ K_e` (the local fits), or the invariants
/// `z(m)` of all of them (`invariants`: see [`crate::learn`]). It is an [`Agent`]
/// without ground truth, whose `sense` ignores the environment it is given: the
/// tracer's sensory method runs on it unchanged.
pub struct LearnedLaw {
    space: MotorSpace,
    models: Models,
    sensor_dim: usize,
    rank: usize,
    report: LawReport,
}

impl fmt::Debug for LearnedLaw {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LearnedLaw")
            .field("space", &self.space)
            .field("sensor_dim", &self.sensor_dim)
            .field("report", &self.report)
            .finish()
    }
}

impl LearnedLaw {
    pub(crate) fn new(
        space: MotorSpace,
        models: Models,
        method: LawMethod,
        (logs, data_rank): (Vec<LogReport>, Option<LocalRank>),
        (seed, given, progress): (u64, Option<usize>, &dyn Progress),
    ) -> Self {
        let (sensor_dim, invariants) = match &models {
            Models::Local(models) => (models.iter().map(|m| m.k).sum(), None),
            Models::Invariants(model) => (model.count(), Some(model.report().clone())),
        };
        let mut law = Self {
            space,
            models,
            sensor_dim,
            rank: 0,
            report: LawReport {
                method,
                logs,
                rank: 0,
                rank_source: RankSource::Data,
                rank_counts: Vec::new(),
                invariants,
                data_rank,
                rank_choice: None,
                warnings: Vec::new(),
                quality: LawQuality::default(),
                memory: None,
            },
        };
        let counts = law.rank_counts(seed, progress);
        let choice = choose_rank(&RankEvidence {
            n: law.space.dim(),
            method,
            given,
            data: law.report.data_rank.as_ref(),
            counts: &counts,
            invariants: law.report.invariants.as_ref(),
        });
        law.report.rank_source = choice.source;
        law.rank = choice.rank;
        law.report.rank = choice.rank;
        law.report.rank_counts = counts;
        if choice.given.is_some_and(|g| g != choice.estimate) {
            law.report.warnings.push(format!(
                "rank {} was given and is used, but the evidence reads rank {}: {}",
                choice.rank, choice.estimate, choice.reason
            ));
        } else if choice.given.is_none() && choice.data.is_some_and(|d| d != choice.rank) {
            law.report.warnings.push(format!(
                "the pieces of evidence on the rank disagree; rank {} is used: {}",
                choice.rank, choice.reason
            ));
        }
        law.report.rank_choice = Some(choice);
        law
    }

    /// The law's rank (the tracer's [`Agent::sensory_rank`]).
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Weighs the agent's own slope ([`AgentRank`]) against the rank the law's evidence
    /// read: a higher reading, inside `1..N` and clear of its noise floor
    /// ([`AGENT_FLOOR_MULTIPLE`]), is used (source [`RankSource::Agent`], first of the
    /// candidates); otherwise the rank stands and the reason says what the agent read.
    /// A rank given by the user is never changed.
    pub fn weigh_agent_rank(&mut self, agent: &AgentRank) {
        let n = self.space.dim();
        let Some(choice) = self.report.rank_choice.as_mut() else {
            return;
        };
        choice.agent = Some(agent.rank);
        if agent.rank == self.rank {
            choice.reason.push_str(&format!(
                "; the agent's own slope at {} starts reads the same",
                agent.starts
            ));
            return;
        }
        let value = agent
            .rank
            .checked_sub(1)
            .and_then(|r| agent.spectrum.get(r));
        let clear = value.is_some_and(|&v| v >= AGENT_FLOOR_MULTIPLE * agent.floor && v > 0.0);
        let spectrum = format_spectrum(&agent.spectrum);
        if self.report.rank_source != RankSource::Given
            && agent.rank > self.rank
            && (1..n).contains(&agent.rank)
            && clear
        {
            let before = self.rank;
            choice.reason.push_str(&format!(
                "; the agent's own slope at {} starts (step {}) reads rank {} (spectrum {spectrum}, noise floor {:.4}): a direction of change too weak for the babbling's spacing, used in place of rank {before}",
                agent.starts, agent.step, agent.rank, agent.floor
            ));
            choice.rank = agent.rank;
            choice.source = RankSource::Agent;
            choice.candidates.retain(|&r| r != agent.rank);
            choice.candidates.insert(0, agent.rank);
            self.rank = agent.rank;
            self.report.rank = agent.rank;
            self.report.rank_source = RankSource::Agent;
            self.report.warnings.push(format!(
                "the agent's own readings show rank {} where the babbled data read {before}: the sets are traced at rank {} (kernels of dimension {})",
                agent.rank,
                agent.rank,
                n - agent.rank
            ));
        } else {
            let why = if self.report.rank_source == RankSource::Given {
                "the rank was given".to_owned()
            } else if agent.rank < self.rank {
                "a short stencil's noise can hide weak directions".to_owned()
            } else if !(1..n).contains(&agent.rank) {
                format!(
                    "rank {} leaves no kernel of dimension 1 to {}",
                    agent.rank,
                    n - 1
                )
            } else {
                format!(
                    "its value at rank {} is not {AGENT_FLOOR_MULTIPLE} times its noise floor {:.4}",
                    agent.rank, agent.floor
                )
            };
            choice.reason.push_str(&format!(
                "; the agent's own slope at {} starts reads rank {} (spectrum {spectrum}), not used: {why}",
                agent.starts, agent.rank
            ));
        }
    }

    /// Sets the rank and the candidates of the rank choice, as if the evidence had read
    /// them (tests of the retry).
    #[cfg(test)]
    pub(crate) fn set_candidates(&mut self, candidates: Vec<usize>) {
        self.rank = candidates[0];
        self.report.rank = candidates[0];
        if let Some(choice) = self.report.rank_choice.as_mut() {
            choice.rank = candidates[0];
            choice.candidates = candidates;
        }
    }

    /// What learning found.
    pub fn report(&self) -> &LawReport {
        &self.report
    }

    /// Adds warnings to the report.
    pub(crate) fn warn(&mut self, warnings: Vec<String>) {
        self.report.warnings.extend(warnings);
    }

    /// Sets the report's quality figures and memory estimate.
    pub(crate) fn describe(&mut self, quality: LawQuality, memory: Option<MemoryEstimate>) {
        self.report.quality = quality;
        self.report.memory = memory;
    }

    /// Writes the law's values `ŝ(m)` (or the invariants `z(m)`) into `sensors` (length
    /// [`Agent::sensor_dim`]) and, when asked, their Jacobian (`K × N` row-major) into
    /// `jacobian`.
    fn evaluate(&self, m: &[f64], sensors: &mut [f64], mut jacobian: Option<&mut [f64]>) {
        let n = self.space.dim();
        match &self.models {
            Models::Local(models) => {
                let mut at = 0;
                for model in models {
                    model.evaluate(
                        m,
                        &mut sensors[at..at + model.k],
                        jacobian
                            .as_deref_mut()
                            .map(|j| &mut j[at * n..(at + model.k) * n]),
                    );
                    at += model.k;
                }
            }
            Models::Invariants(model) => model.evaluate(m, sensors, jacobian),
        }
    }

    /// Writes `ŝ(m)` into `sensors` (length `K`; the invariants `z(m)` for the
    /// `invariants` method) and its Jacobian (`K × N` row-major) into `jacobian`.
    pub fn evaluate_with_jacobian(&self, m: &[f64], sensors: &mut [f64], jacobian: &mut [f64]) {
        self.evaluate(m, sensors, Some(jacobian));
    }

    /// Numerical ranks of the law's Jacobian at seeded fitted samples of the first log:
    /// counts per rank `0..=N` (the stage [`observe::RANK`] of `progress`).
    fn rank_counts(&self, seed: u64, progress: &dyn Progress) -> Vec<usize> {
        let n = self.space.dim();
        let tree = match &self.models {
            Models::Local(models) => match models.first() {
                Some(first) => &first.tree,
                None => return vec![0; n + 1],
            },
            Models::Invariants(model) => model.probe_tree(),
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7261);
        let probes: Vec<u32> = sample(&mut rng, tree.len(), PROBES.min(tree.len()))
            .into_iter()
            .map(|i| i as u32)
            .collect();
        let ranks = observe::stage(progress, observe::RANK, probes.len() as u64, || {
            observe::map_rows(&probes, progress, |i| {
                let m = tree.point(i as usize).to_vec();
                let mut s = vec![0.0; self.sensor_dim];
                let mut j = vec![0.0; self.sensor_dim * n];
                self.evaluate_with_jacobian(&m, &mut s, &mut j);
                gap_rank(&j, self.sensor_dim, n)
            })
        });
        let mut counts = vec![0; n + 1];
        for r in ranks {
            counts[r] += 1;
        }
        counts
    }
}

/// The numerical rank of a `rows × n` matrix by the largest gap of its singular values:
/// `n` when `σ_n / σ_1 > 0.1`, else the `r < n` with the largest `σ_r / σ_{r+1}` (0 for a
/// zero matrix).
pub(crate) fn gap_rank(matrix: &[f64], rows: usize, n: usize) -> usize {
    // Zero rows below a short matrix: `n` singular values, the missing ones zero.
    let a = faer::Mat::from_fn(rows.max(n), n, |i, j| {
        if i < rows {
            matrix[i * n + j]
        } else {
            0.0
        }
    });
    // NaN entries: no convergence, read as rank 0 below.
    let mut sigma =
        crate::linalg::singular_values(a.as_ref()).unwrap_or_else(|_| vec![f64::NAN; n]);
    sigma.sort_by(|a, b| b.total_cmp(a));
    let largest = sigma.first().copied().unwrap_or(0.0);
    if largest.is_nan() || largest <= 0.0 || !largest.is_finite() {
        return 0;
    }
    if sigma[n - 1] > 0.1 * largest {
        return n;
    }
    (1..n)
        .max_by(|&a, &b| {
            let gap = |r: usize| sigma[r - 1] / sigma[r].max(1e-300 * largest);
            gap(a).total_cmp(&gap(b))
        })
        .unwrap_or(n)
}

/// A [`LearnedLaw`] traced at another rank than its own (a retry of
/// [`super::trace_learned`]): the same values and Jacobian.
#[derive(Debug)]
pub(crate) struct AtRank<'a> {
    /// The law.
    pub law: &'a LearnedLaw,
    /// The rank the tracer uses.
    pub rank: usize,
}

impl Agent for AtRank<'_> {
    fn motor_dim(&self) -> usize {
        self.law.motor_dim()
    }

    fn sensor_dim(&self) -> usize {
        self.law.sensor_dim()
    }

    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        self.law.sense(environment, motors, sensors);
    }

    fn name(&self) -> &str {
        self.law.name()
    }

    fn motor_space(&self) -> MotorSpace {
        self.law.motor_space()
    }

    fn sensory_rank(&self) -> Option<usize> {
        Some(self.rank)
    }

    fn sense_with_jacobian(
        &self,
        environment: &Environment,
        motors: &[f64],
        sensors: &mut [f64],
        jacobian: &mut [f64],
    ) -> bool {
        self.law
            .sense_with_jacobian(environment, motors, sensors, jacobian)
    }

    fn covers(&self, motors: &[f64]) -> bool {
        self.law.covers(motors)
    }
}

impl Agent for LearnedLaw {
    fn motor_dim(&self) -> usize {
        self.space.dim()
    }

    fn sensor_dim(&self) -> usize {
        self.sensor_dim
    }

    fn sense(&self, _environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        self.evaluate(motors, sensors, None);
    }

    fn name(&self) -> &str {
        "learned"
    }

    fn motor_space(&self) -> MotorSpace {
        self.space.clone()
    }

    fn sensory_rank(&self) -> Option<usize> {
        Some(self.rank)
    }

    fn sense_with_jacobian(
        &self,
        _environment: &Environment,
        motors: &[f64],
        sensors: &mut [f64],
        jacobian: &mut [f64],
    ) -> bool {
        self.evaluate_with_jacobian(motors, sensors, jacobian);
        true
    }

    fn covers(&self, motors: &[f64]) -> bool {
        match &self.models {
            Models::Local(models) => models.iter().all(|m| m.covers(motors)),
            Models::Invariants(model) => model.covers(motors),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_at_a_bounded_motors_limit_asks_for_the_share_of_the_ball_inside() {
        // Samples on a grid 0.01 apart over [0, 1]²: a ball of radius 0.05 holds about
        // 80 of them inside the square, 40 on an edge and 20 at a corner.
        let space = MotorSpace::bounded(2, 0.0, 1.0).unwrap();
        let mut points = Vec::new();
        for i in 0..=100 {
            for j in 0..=100 {
                points.extend([i as f64 * 0.01, j as f64 * 0.01]);
            }
        }
        let tree = KdTree::new(2, points, (0..101 * 101).collect());
        let (h, min_count) = (0.05, 60);
        for m in [[0.5, 0.5], [0.5, 0.0], [1.0, 0.3], [0.0, 0.0], [1.0, 1.0]] {
            assert!(covered(&space, &tree, h, min_count, &m), "{m:?}");
        }
        // Outside the samples, and with too few of them, it is not covered.
        assert!(!covered(&space, &tree, h, min_count, &[0.5, 1.2]));
        assert!(!covered(&space, &tree, h, 200, &[0.5, 0.5]));
        assert!(!covered(&space, &tree, h, 100, &[0.5, 0.0]));
        // Hinges have no limit: the whole count is asked for.
        let hinges = MotorSpace::hinges(2);
        assert!(!covered(&hinges, &tree, h, min_count, &[0.5, 0.0]));
    }

    fn data(rank: usize, spectrum: &[f64]) -> LocalRank {
        LocalRank {
            rank,
            spectrum: spectrum.to_vec(),
            floor: 0.0,
            probes: 4096,
            held_out: Vec::new(),
            held_out_rank: None,
        }
    }

    /// Nine invariants whose largest `λ` is `last`, the next function's `next`.
    fn invariants(last: f64, next: f64, held_out: f64) -> InvariantsReport {
        let mut eigenvalues: Vec<f64> = (0..9).map(|i| last * i as f64 / 8.0).collect();
        eigenvalues.extend([next, next * 1.02, 0.9, 1.1]);
        InvariantsReport {
            features: 80,
            invariants: 9,
            threshold: Some(0.4),
            eigenvalues,
            pairs: 900_000,
            kept_pairs: 880_000,
            fitted_lambda: last / 2.0,
            held_out_lambda: Some(held_out),
            held_out_aliased: Some(0.01),
        }
    }

    fn choose(
        given: Option<usize>,
        data: &LocalRank,
        counts: &[usize],
        inv: &InvariantsReport,
    ) -> RankChoice {
        choose_rank(&RankEvidence {
            n: 4,
            method: LawMethod::Invariants,
            given,
            data: Some(data),
            counts,
            invariants: Some(inv),
        })
    }

    #[test]
    fn a_weak_direction_read_as_the_kernels_leak_is_outvoted_by_clear_invariants() {
        // The retina of 8 Cauchy cells with far lights at 10⁶ samples: the spectrum's
        // gap of 4.3 after the first value reads rank 1; the nine invariants (λ ≤
        // 0.005, next 0.544) change along 3 directions at every probe.
        let mut spectrum = data(1, &[1.0, 0.234, 0.083, 0.026]);
        // Held out, the fits predict best at rank 1 (the paper's arm's kind of errors).
        spectrum.held_out = vec![0.319, 0.179, 0.175, 0.183, 0.193];
        spectrum.held_out_rank = Some(1);
        let counts = [0, 0, 0, 512, 0];
        let choice = choose(None, &spectrum, &counts, &invariants(0.005, 0.544, 0.004));
        assert_eq!(choice.rank, 3, "{choice:?}");
        assert_eq!(choice.held_out, Some(1));
        assert!(
            choice
                .reason
                .contains("held-out prediction is best at rank 1 (error 0.1790 of the sensors' spread, 0.1830 at rank 3)"),
            "{}",
            choice.reason
        );
        assert_eq!(choice.source, RankSource::Invariants);
        assert_eq!(choice.candidates[0], 3);
        assert!(choice.candidates.contains(&1), "{choice:?}");
        assert!(choice.reason.contains("rank 1"), "{}", choice.reason);
        // The lidar of 9 rays: no clear gap in the spectrum (largest ratio at 1).
        let lidar = data(1, &[1.0, 0.386, 0.206, 0.097]);
        let choice = choose(None, &lidar, &counts, &invariants(0.004, 0.52, 0.003));
        assert_eq!(choice.rank, 3, "{choice:?}");
    }

    #[test]
    fn invariants_that_do_not_stand_apart_leave_the_datas_rank() {
        let spectrum = data(1, &[1.0, 0.234, 0.083, 0.026]);
        let counts = [0, 0, 0, 512, 0];
        // No gap between the kept invariants and the next function.
        let choice = choose(None, &spectrum, &counts, &invariants(0.3, 0.45, 0.2));
        assert_eq!(choice.rank, 1, "{choice:?}");
        assert_eq!(choice.source, RankSource::Data);
        assert!(
            choice.reason.contains("do not stand apart"),
            "{}",
            choice.reason
        );
        // Held-out neighbours that do not share them.
        let choice = choose(None, &spectrum, &counts, &invariants(0.005, 0.544, 0.3));
        assert_eq!(choice.rank, 1, "{choice:?}");
        // Probes that disagree.
        let split = [0, 0, 200, 312, 0];
        let choice = choose(None, &spectrum, &split, &invariants(0.005, 0.544, 0.004));
        assert_eq!(choice.rank, 1, "{choice:?}");
        // The retry still has rank 3 to try.
        assert_eq!(choice.candidates[0], 1);
        assert!(choice.candidates.contains(&3), "{choice:?}");
    }

    #[test]
    fn a_lower_invariant_rank_is_kept_and_a_given_rank_wins() {
        // The 4-link arm's case: the spectrum over-reads the rank.
        let spectrum = data(4, &[1.0, 0.37, 0.13, 0.036]);
        let counts = [0, 0, 0, 512, 0];
        let choice = choose(None, &spectrum, &counts, &invariants(0.01, 0.5, 0.01));
        assert_eq!((choice.rank, choice.source), (3, RankSource::Invariants));
        // A given rank is used, the estimate beside it, and nothing else is tried.
        let choice = choose(Some(2), &spectrum, &counts, &invariants(0.01, 0.5, 0.01));
        assert_eq!((choice.rank, choice.estimate), (2, 3));
        assert_eq!(choice.source, RankSource::Given);
        assert_eq!(choice.candidates, vec![2]);
        assert!(
            choice.reason.contains("in place of the estimate 3"),
            "{}",
            choice.reason
        );
    }
}
