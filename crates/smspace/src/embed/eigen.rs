//! Classical MDS on faer's self-adjoint eigensolvers, and landmark triangulation.
//!
//! `B = −½ J Δ J` (Δ: squared distances, `J = I − 11ᵀ/n`) is formed in place; its
//! largest eigenpairs come from faer's dense solver (`self_adjoint_evd`, all
//! eigenvalues) for small matrices, or from its restarted Lanczos solver
//! (`partial_self_adjoint_eigen`, the largest in magnitude) for large ones. faer runs
//! sequentially here and the matrix–vector product is ours (parallel over rows, each
//! row summed in a fixed order), so that results do not depend on the thread count.
//!
//! Distances of any finite size embed without overflow: a matrix whose largest entry
//! is outside `[2^-64, 2^64]`, whose squares (MDS, Isomap) or `f32` copy (CCA) would
//! overflow or underflow, is embedded divided by a power of two near that entry
//! ([`distance_scale`]: exact, every entry keeps its digits) and the results are
//! multiplied back ([`rescaled`]). Coordinates and widths then come out exactly scaled;
//! a squared quantity whose true value is beyond `f64` (an eigenvalue or a stress of
//! distances above about `1e154`) is reported as `±f64::MAX`. Matrices inside that
//! range are used as they are, so ordinary results do not change by a bit.

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::matrix_free::eigen::{
    partial_self_adjoint_eigen, partial_self_adjoint_eigen_scratch, PartialEigenParams,
};
use faer::matrix_free::LinOp;
use faer::{ColRef, Mat, MatMut, MatRef, Par};
use ndarray::{Array1, Array2, ArrayView1, ArrayView2, Axis};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::EmbedError;
use crate::neighbours::{farthest_first, nearest, DenseDistances};

/// Which eigensolver classical MDS uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum EigenSolver {
    /// Dense for at most 1000 points, partial (Lanczos) above.
    #[default]
    Auto,
    /// faer's dense self-adjoint eigendecomposition: every eigenvalue, `O(M³)`.
    Dense,
    /// faer's restarted Lanczos: the largest-magnitude eigenvalues, `O(M²)` per step.
    Partial,
}

/// Above this size, `Auto` uses the partial solver.
const DENSE_MAX: usize = 1000;

/// Result of classical MDS.
#[derive(Debug, Clone)]
pub(crate) struct MdsFit {
    /// Coordinates `(n, d)`.
    pub coordinates: Array2<f64>,
    /// Eigenvalues found, decreasing.
    pub eigenvalues: Vec<f64>,
    /// `trace(B)`.
    pub trace: f64,
    /// The `d` eigenvalues used.
    pub used: Vec<f64>,
    /// Column means of the squared distances (for triangulation).
    pub mean_sq: Array1<f64>,
}

/// Largest distances inside `[2^-SAFE_EXPONENT, 2^SAFE_EXPONENT]` are embedded as they
/// are (see the module docs).
const SAFE_EXPONENT: i32 = 64;

/// The power of two to divide `distances` by before embedding: `None` when its largest
/// entry is inside `[2^-64, 2^64]` (or zero), else the power of two at or below it.
pub(crate) fn distance_scale<'a>(distances: impl IntoIterator<Item = &'a f64>) -> Option<f64> {
    let largest = distances.into_iter().fold(0.0_f64, |m, &x| m.max(x.abs()));
    let safe = 2f64.powi(-SAFE_EXPONENT)..=2f64.powi(SAFE_EXPONENT);
    if largest == 0.0 || !largest.is_finite() || safe.contains(&largest) {
        return None;
    }
    Some(2f64.powi(largest.log2().floor() as i32))
}

/// `value · factor`, saturated at `±f64::MAX` when the true product is beyond `f64`.
pub(crate) fn times(value: f64, factor: f64) -> f64 {
    let product = value * factor;
    if product.is_infinite() && value.is_finite() {
        f64::MAX.copysign(product)
    } else {
        product
    }
}

/// An embedding of distances divided by `scale` ([`distance_scale`]), brought back to
/// the distances' own units: lengths times `scale`, squared quantities (eigenvalues,
/// stress) times `scale²`.
pub(crate) fn rescaled(mut embedded: super::Embedded, scale: f64) -> super::Embedded {
    let length = |v: &mut f64| *v = times(*v, scale);
    let square = |v: &mut f64| *v = times(times(*v, scale), scale);
    embedded.coordinates.iter_mut().for_each(length);
    let report = &mut embedded.report;
    report.stress_trace.iter_mut().for_each(square);
    report.eigenvalues.iter_mut().for_each(square);
    report.lambda_end.iter_mut().for_each(length);
    report.eigenvalue_trace.iter_mut().for_each(square);
    match &mut embedded.extender {
        super::Extender::Cca(cca) => cca.rescale(scale),
        super::Extender::Triangulation(tri) => {
            tri.landmark_coordinates.iter_mut().for_each(length);
            tri.eigenvalues.iter_mut().for_each(square);
            tri.mean_sq.iter_mut().for_each(square);
            if let Some((geodesic, _)) = &mut tri.geodesic {
                geodesic.iter_mut().for_each(length);
            }
        }
    }
    embedded
}

/// Turns squared distances into `B = −½ J Δ J` in place; returns the column means of Δ.
fn double_centre(b: &mut Array2<f64>) -> Array1<f64> {
    let n = b.nrows();
    let data = b.as_slice_mut().expect("standard layout");
    let means: Array1<f64> = data
        .par_chunks(n)
        .map(|row| row.iter().sum::<f64>() / n as f64)
        .collect::<Vec<_>>()
        .into();
    let grand = means.sum() / n as f64;
    data.par_chunks_mut(n).enumerate().for_each(|(i, row)| {
        let ri = means[i];
        for (x, &rj) in row.iter_mut().zip(means.iter()) {
            *x = -0.5 * (*x - ri - rj + grand);
        }
    });
    means
}

/// The symmetric matrix `B` as a faer operator with a deterministic parallel product.
#[derive(Debug)]
struct SymOp<'a> {
    b: ArrayView2<'a, f64>,
}

impl LinOp<f64> for SymOp<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> faer::dyn_stack::StackReq {
        faer::dyn_stack::StackReq::EMPTY
    }
    fn nrows(&self) -> usize {
        self.b.nrows()
    }
    fn ncols(&self) -> usize {
        self.b.ncols()
    }
    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _stack: &mut MemStack) {
        let mut out = out;
        let n = self.b.nrows();
        let b = self.b.as_slice().expect("standard layout");
        for c in 0..rhs.ncols() {
            let x: Vec<f64> = (0..n).map(|j| rhs[(j, c)]).collect();
            let y = symmetric_product(b, n, &x);
            for (i, v) in y.into_iter().enumerate() {
                out[(i, c)] = v;
            }
        }
    }
    fn conj_apply(
        &self,
        out: MatMut<'_, f64>,
        rhs: MatRef<'_, f64>,
        par: Par,
        stack: &mut MemStack,
    ) {
        self.apply(out, rhs, par, stack);
    }
}

/// Row blocks of the symmetric product (fixed, so that sums do not depend on threads).
const PRODUCT_BLOCKS: usize = 8;

/// `y = B x` for a symmetric `B` (row-major, `n × n`) reading only its lower triangle:
/// half the memory traffic of a full product. Rows are cut into [`PRODUCT_BLOCKS`]
/// blocks of equal triangle area, each block scatters into its own buffer, and the
/// buffers are summed in block order.
fn symmetric_product(b: &[f64], n: usize, x: &[f64]) -> Vec<f64> {
    let mut bounds = vec![0];
    for k in 1..PRODUCT_BLOCKS {
        let r = (n as f64 * (k as f64 / PRODUCT_BLOCKS as f64).sqrt()).round() as usize;
        bounds.push(r.max(*bounds.last().expect("non-empty")));
    }
    bounds.push(n);
    let arch = pulp::Arch::new();
    let parts: Vec<Vec<f64>> = (0..PRODUCT_BLOCKS)
        .into_par_iter()
        .map(|k| {
            arch.dispatch(LowerRows {
                b,
                n,
                x,
                rows: bounds[k]..bounds[k + 1],
            })
        })
        .collect();
    let mut y = vec![0.0; n];
    for part in parts {
        for (a, v) in y.iter_mut().zip(part) {
            *a += v;
        }
    }
    y
}

/// Rows `rows` of the lower-triangle product, vectorised for the CPU at hand (pulp).
struct LowerRows<'a> {
    b: &'a [f64],
    n: usize,
    x: &'a [f64],
    rows: std::ops::Range<usize>,
}

impl pulp::WithSimd for LowerRows<'_> {
    type Output = Vec<f64>;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Vec<f64> {
        let Self { b, n, x, rows } = self;
        {
            let (r0, r1) = (rows.start, rows.end);
            let mut y = vec![0.0; r1];
            for i in r0..r1 {
                let row = &b[i * n..i * n + i];
                let xi = x[i];
                let (head, _) = y.split_at_mut(i);
                let mut acc = [0.0; 4];
                let chunks = i / 4;
                for q in 0..chunks {
                    for l in 0..4 {
                        let j = 4 * q + l;
                        acc[l] += row[j] * x[j];
                        head[j] += row[j] * xi;
                    }
                }
                let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
                for j in 4 * chunks..i {
                    s += row[j] * x[j];
                    head[j] += row[j] * xi;
                }
                y[i] += s + b[i * n + i] * xi;
            }
            y
        }
    }
}

/// Eigenpairs, decreasing by value: `(values, vectors (n, count))`.
type Pairs = (Vec<f64>, Array2<f64>);

fn dense_eigen(b: &Array2<f64>) -> Result<Pairs, EmbedError> {
    let n = b.nrows();
    let a = MatRef::from_row_major_slice(b.as_slice().expect("standard layout"), n, n);
    let mut u = Mat::<f64>::zeros(n, n);
    let mut s = Diag::<f64>::zeros(n);
    let par = Par::Seq;
    let scratch = faer::linalg::evd::self_adjoint_evd_scratch::<f64>(
        n,
        faer::linalg::evd::ComputeEigenvectors::Yes,
        par,
        Default::default(),
    );
    faer::linalg::evd::self_adjoint_evd(
        a,
        s.as_mut(),
        Some(u.as_mut()),
        par,
        MemStack::new(&mut MemBuffer::new(scratch)),
        Default::default(),
    )
    .map_err(|e| EmbedError::Eigen(format!("{e:?}")))?;
    // faer sorts increasingly; reverse.
    let values: Vec<f64> = (0..n).rev().map(|i| s.column_vector()[i]).collect();
    let vectors = Array2::from_shape_fn((n, n), |(r, c)| u[(r, n - 1 - c)]);
    Ok((values, vectors))
}

fn partial_eigen(b: &Array2<f64>, count: usize, seed: u64) -> Result<Pairs, EmbedError> {
    let n = b.nrows();
    let op = SymOp { b: b.view() };
    let params = PartialEigenParams::default();
    let par = Par::Seq;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_e16e);
    let v0: Vec<f64> = (0..n).map(|_| rng.random::<f64>() - 0.5).collect();
    let mut vectors = Mat::<f64>::zeros(n, count);
    let mut values = vec![0.0; count];
    let scratch = partial_self_adjoint_eigen_scratch::<f64>(&op, count, par, params);
    let info = partial_self_adjoint_eigen(
        vectors.as_mut(),
        &mut values,
        &op,
        ColRef::from_slice(&v0),
        1e-10,
        par,
        MemStack::new(&mut MemBuffer::new(scratch)),
        params,
    );
    let found = info.n_converged_eigen.min(count);
    let mut order: Vec<usize> = (0..found).collect();
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    let sorted: Vec<f64> = order.iter().map(|&i| values[i]).collect();
    let vecs = Array2::from_shape_fn((n, found), |(r, c)| vectors[(r, order[c])]);
    Ok((sorted, vecs))
}

/// Classical MDS of squared distances `sq` `(n, n)` (consumed) to `dim` dimensions.
///
/// Fewer than `dim` positive eigenvalues is an error unless `allow_degenerate`, in
/// which case the missing coordinates are 0 (and `used` holds only the positive ones).
pub(crate) fn classical_mds(
    mut sq: Array2<f64>,
    dim: usize,
    solver: EigenSolver,
    seed: u64,
    allow_degenerate: bool,
) -> Result<MdsFit, EmbedError> {
    let n = sq.nrows();
    let mean_sq = double_centre(&mut sq);
    let trace = sq.diag().sum();
    let dense = match solver {
        EigenSolver::Dense => true,
        EigenSolver::Partial => false,
        EigenSolver::Auto => n <= DENSE_MAX,
    };
    let (values, vectors) = if dense || n <= dim + 12 {
        dense_eigen(&sq)?
    } else {
        partial_eigen(&sq, (dim + 10).min(n), seed)?
    };
    // The d largest, which must be positive.
    let scale = values
        .iter()
        .fold(0.0_f64, |m, v| m.max(v.abs()))
        .max(1e-300);
    let positive = values.iter().filter(|&&v| v > 1e-12 * scale).count();
    if positive < dim && !allow_degenerate {
        return Err(EmbedError::TooFewPositiveEigenvalues { positive, dim });
    }
    let mut coordinates = Array2::zeros((n, dim));
    for c in 0..dim.min(positive) {
        let mut v = vectors.column(c).to_owned();
        orient(&mut v);
        let f = values[c].sqrt();
        coordinates.column_mut(c).assign(&(v * f));
    }
    Ok(MdsFit {
        coordinates,
        used: values[..dim.min(positive)].to_vec(),
        eigenvalues: values,
        trace,
        mean_sq,
    })
}

/// Landmark MDS (de Silva & Tenenbaum 2003) of a full distance matrix: classical MDS of
/// `landmarks` MaxMin landmarks (the first drawn with `seed`, each next the farthest
/// from those chosen), every other point placed by triangulation. Exact classical MDS
/// (up to a rotation) for Euclidean distances; `O(M L)` work besides the `L × L`
/// eigenproblem. Missing directions (fewer positive eigenvalues than `dim`) are 0.
pub(crate) fn landmark_mds(
    distances: ArrayView2<'_, f64>,
    dim: usize,
    landmarks: usize,
    seed: u64,
) -> Result<MdsFit, EmbedError> {
    let n = distances.nrows();
    let l = landmarks.min(n);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x1a4d_4a2c);
    let start = rng.random_range(0..n);
    let chosen = farthest_first(&DenseDistances::new(distances)?, l, start)?.rows;
    let sq = Array2::from_shape_fn((l, l), |(a, b)| {
        let d = distances[[chosen[a], chosen[b]]];
        d * d
    });
    let fit = classical_mds(sq, dim, EigenSolver::Dense, seed, true)?;
    let used = fit.used.len();
    let tri = Triangulation {
        landmark_coordinates: fit
            .coordinates
            .slice_axis(Axis(1), (..used).into())
            .to_owned(),
        eigenvalues: fit.used.clone(),
        mean_sq: fit.mean_sq.clone(),
        landmarks: chosen.clone(),
        geodesic: None,
    };
    let rows: Vec<Vec<f64>> = (0..n)
        .into_par_iter()
        .map(|a| {
            let delta: Array1<f64> = chosen
                .iter()
                .map(|&c| distances[[c, a]] * distances[[c, a]])
                .collect();
            tri.place(delta.view())
        })
        .collect();
    let coordinates =
        Array2::from_shape_fn((n, dim), |(a, c)| if c < used { rows[a][c] } else { 0.0 });
    Ok(MdsFit { coordinates, ..fit })
}

/// Fixes an eigenvector's sign: its largest-magnitude entry (first on ties) is positive.
fn orient(v: &mut Array1<f64>) {
    let mut best = 0;
    for (i, x) in v.iter().enumerate() {
        if x.abs() > v[best].abs() * (1.0 + 1e-9) {
            best = i;
        }
    }
    if v[best] < 0.0 {
        v.mapv_inplace(|x| -x);
    }
}

/// Landmark triangulation (de Silva & Tenenbaum 2003): a point with squared distances
/// `δ²` to the landmarks lands at `y_c = −½ Σ_l L_lc / λ_c (δ_l² − μ_l)`, where `L` are
/// the landmarks' MDS coordinates, `λ` the eigenvalues used and `μ` the column means of
/// the landmarks' squared distances. For a landmark itself this returns its coordinates.
#[derive(Debug, Clone)]
pub(crate) struct Triangulation {
    /// Landmark coordinates `(L, d)`.
    pub landmark_coordinates: Array2<f64>,
    /// Eigenvalues used `(d)`.
    pub eigenvalues: Vec<f64>,
    /// Column means of the landmarks' squared distances `(L)`.
    pub mean_sq: Array1<f64>,
    /// Indices of the landmarks among the embedded points.
    pub landmarks: Vec<usize>,
    /// Isomap: geodesic distances from each landmark to every embedded point `(L, M)`
    /// and the number of nearest old points a new point connects to.
    pub geodesic: Option<(Array2<f64>, usize)>,
}

impl Triangulation {
    /// Coordinates of one point from its squared distances to the landmarks.
    pub fn place(&self, delta_sq: ArrayView1<'_, f64>) -> Vec<f64> {
        let dim = self.eigenvalues.len();
        let mut y = vec![0.0; dim];
        for (l, (&d2, &mu)) in delta_sq.iter().zip(self.mean_sq.iter()).enumerate() {
            let w = d2 - mu;
            for c in 0..dim {
                y[c] += self.landmark_coordinates[[l, c]] * w;
            }
        }
        for c in 0..dim {
            y[c] *= -0.5 / self.eigenvalues[c];
        }
        y
    }

    /// Places new points from their distances `(N, M)` to the embedded ones.
    pub fn extend(&self, new_to_old: ArrayView2<'_, f64>) -> Array2<f64> {
        let dim = self.eigenvalues.len();
        let rows: Vec<Vec<f64>> = (0..new_to_old.nrows())
            .into_par_iter()
            .map(|p| {
                let x = new_to_old.row(p);
                let delta: Array1<f64> = match &self.geodesic {
                    None => self.landmarks.iter().map(|&l| x[l] * x[l]).collect(),
                    Some((g, k)) => {
                        let near = nearest(x, *k, None);
                        g.axis_iter(Axis(0))
                            .map(|gl| {
                                let d = near
                                    .iter()
                                    .map(|&(j, dj)| dj + gl[j])
                                    .fold(f64::INFINITY, f64::min);
                                d * d
                            })
                            .collect()
                    }
                };
                self.place(delta.view())
            })
            .collect();
        let mut out = Array2::zeros((rows.len(), dim));
        for (i, r) in rows.iter().enumerate() {
            for c in 0..dim {
                out[[i, c]] = r[c];
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::embed::{CcaParams, EmbedParams, Embedding, IsomapParams, MdsParams};
    use crate::metric::DistanceMatrix;
    use crate::progress::Silent;

    /// Distances between 40 points on a noisy circle.
    fn circle() -> Array2<f64> {
        let points: Vec<[f64; 2]> = (0..40)
            .map(|i| {
                let t = i as f64 * 0.157 + 0.01 * ((i * 7) % 5) as f64;
                [t.cos(), t.sin() * 0.8]
            })
            .collect();
        Array2::from_shape_fn((40, 40), |(i, j)| {
            let (a, b) = (points[i], points[j]);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
        })
    }

    fn methods() -> Vec<Box<dyn Embedding>> {
        [
            EmbedParams::from(CcaParams::default().dim(2).epochs(10)),
            EmbedParams::from(MdsParams::default().dim(2)),
            EmbedParams::from(IsomapParams::default().dim(2).k(6)),
        ]
        .into_iter()
        .map(|p| p.build().unwrap())
        .collect()
    }

    #[test]
    fn distances_of_any_finite_size_embed_to_scaled_coordinates() {
        let d = circle();
        for method in methods() {
            let name = method.name();
            let plain = method
                .fit(&DistanceMatrix::new(d.clone()).unwrap(), &Silent)
                .unwrap();
            // Exactly scaled by a power of two (1e300 and 1e-300 in size): exactly
            // the scaled coordinates.
            for exponent in [996, -996] {
                let factor = 2f64.powi(exponent);
                let fit = method
                    .fit(
                        &DistanceMatrix::new(d.mapv(|x| x * factor)).unwrap(),
                        &Silent,
                    )
                    .unwrap();
                assert_eq!(
                    fit.coordinates,
                    plain.coordinates.mapv(|y| y * factor),
                    "{name} × 2^{exponent}"
                );
                if let (Some(a), Some(b)) = (fit.report.lambda_end, plain.report.lambda_end) {
                    assert_eq!(a, b * factor, "{name}");
                }
                assert!(fit
                    .report
                    .eigenvalues
                    .iter()
                    .chain(&fit.report.stress_trace)
                    .all(|v| v.is_finite()));
            }
            // Scaled by 1e300 (not a power of two): finite, and the same embedding up
            // to rounding (distances between the embedded points agree).
            let fit = method
                .fit(
                    &DistanceMatrix::new(d.mapv(|x| x * 1e300)).unwrap(),
                    &Silent,
                )
                .unwrap();
            assert!(fit.coordinates.iter().all(|y| y.is_finite()), "{name}");
            let spread = |y: &Array2<f64>, scale: f64| {
                (0..y.nrows())
                    .map(|i| (y[[i, 0]] - y[[0, 0]]).hypot(y[[i, 1]] - y[[0, 1]]) / scale)
                    .collect::<Vec<f64>>()
            };
            let (a, b) = (
                spread(&fit.coordinates, 1e300),
                spread(&plain.coordinates, 1.0),
            );
            let worst = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            assert!(worst < 0.05, "{name}: distances off by {worst}");
        }
    }

    #[test]
    fn ordinary_distances_are_not_scaled() {
        assert_eq!(distance_scale(&circle()), None);
        assert_eq!(distance_scale(&[0.0, 0.0]), None);
        assert_eq!(distance_scale(&[3.0, 1e19]), None);
        assert_eq!(distance_scale(&[3.0, 1e20]), Some(2f64.powi(66)));
        assert_eq!(distance_scale(&[3.0, 1e300]), Some(2f64.powi(996)));
        assert_eq!(distance_scale(&[1e-300]), Some(2f64.powi(-997)));
        assert_eq!(times(f64::MAX, 4.0), f64::MAX);
        assert_eq!(times(-f64::MAX, 4.0), -f64::MAX);
    }
}
