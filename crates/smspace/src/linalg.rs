//! Dense decompositions on faer, sequential (`Par::Seq`), so that every result is the
//! same for any number of threads (the callers run them inside their own parallel
//! loops).
//!
//! * [`self_adjoint_eigen`]: `A = V Λ Vᵀ` for a symmetric `A` (its lower triangle is
//!   read), `Λ` ascending, `V` orthonormal.
//! * [`singular_values`]: the `σ₁ ≥ … ≥ σ_min(m,n) ≥ 0` of `A = U Σ Vᵀ`.
//! * [`cholesky_in_place`]: `A = L Lᵀ` for a symmetric positive definite `A`; `L` is
//!   written over the lower triangle.

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{
    self_adjoint_evd, self_adjoint_evd_scratch, ComputeEigenvectors, EvdError,
};
use faer::linalg::svd::{svd, svd_scratch, ComputeSvdVectors, SvdError};
use faer::{Mat, MatMut, MatRef, Par};

/// The eigenvalues (ascending) and eigenvectors (the columns of `V`, in the same
/// order) of the symmetric matrix `a`; an error when the iteration does not converge
/// (non-finite entries).
pub(crate) fn self_adjoint_eigen(a: MatRef<'_, f64>) -> Result<(Vec<f64>, Mat<f64>), EvdError> {
    let n = a.nrows();
    let mut vectors = Mat::<f64>::zeros(n, n);
    let mut values = Diag::<f64>::zeros(n);
    let par = Par::Seq;
    let scratch =
        self_adjoint_evd_scratch::<f64>(n, ComputeEigenvectors::Yes, par, Default::default());
    self_adjoint_evd(
        a,
        values.as_mut(),
        Some(vectors.as_mut()),
        par,
        MemStack::new(&mut MemBuffer::new(scratch)),
        Default::default(),
    )?;
    Ok((values.column_vector().iter().copied().collect(), vectors))
}

/// The singular values of `a`, nonincreasing; an error when the iteration does not
/// converge (non-finite entries).
pub(crate) fn singular_values(a: MatRef<'_, f64>) -> Result<Vec<f64>, SvdError> {
    let (m, n) = a.shape();
    let mut s = Diag::<f64>::zeros(m.min(n));
    let par = Par::Seq;
    let no = ComputeSvdVectors::No;
    let scratch = svd_scratch::<f64>(m, n, no, no, par, Default::default());
    svd(
        a,
        s.as_mut(),
        None,
        None,
        par,
        MemStack::new(&mut MemBuffer::new(scratch)),
        Default::default(),
    )?;
    Ok(s.column_vector().iter().copied().collect())
}

/// The Cholesky factor `L` of the symmetric positive definite `a` (its lower triangle
/// is read), written over that lower triangle (the strict upper triangle is left as it
/// was); `false` when `a` is not positive definite.
pub(crate) fn cholesky_in_place(a: MatMut<'_, f64>) -> bool {
    use faer::linalg::cholesky::llt::factor;
    let par = Par::Seq;
    let scratch = factor::cholesky_in_place_scratch::<f64>(a.nrows(), par, Default::default());
    factor::cholesky_in_place(
        a,
        Default::default(),
        par,
        MemStack::new(&mut MemBuffer::new(scratch)),
        Default::default(),
    )
    .is_ok()
}
