//! Dense decompositions on faer, sequential (`Par::Seq`), so that every result is the
//! same for any number of threads (the callers run them inside their own parallel
//! loops).
//!
//! * [`self_adjoint_eigen`]: `A = V Λ Vᵀ` for a symmetric `A` (its lower triangle is
//!   read), `Λ` ascending, `V` orthonormal.
//! * [`singular_values`]: the `σ₁ ≥ … ≥ σ_min(m,n) ≥ 0` of `A = U Σ Vᵀ`.
//! * [`cholesky_in_place`]: `A = L Lᵀ` for a symmetric positive definite `A`; `L` is
//!   written over the lower triangle.
//! * [`cholesky_solve`]: `X = A⁻¹ B` by that factor, `L Y = B` then `Lᵀ X = Y`.

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{
    self_adjoint_evd, self_adjoint_evd_scratch, ComputeEigenvectors, EvdError,
};
use faer::linalg::svd::{svd, svd_scratch, ComputeSvdVectors, SvdError};
use faer::reborrow::{Reborrow, ReborrowMut};
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

/// Solves `A X = B` for the symmetric positive definite `a` (its lower triangle is
/// read, and overwritten by the Cholesky factor `L`): `rhs` holds `B` and receives `X`
/// (`L Y = B`, then `Lᵀ X = Y`); `false`, with `rhs` unchanged, when `a` is not positive
/// definite.
pub(crate) fn cholesky_solve(mut a: MatMut<'_, f64>, rhs: MatMut<'_, f64>) -> bool {
    use faer::linalg::cholesky::llt::solve;
    if !cholesky_in_place(a.rb_mut()) {
        return false;
    }
    let par = Par::Seq;
    let scratch = solve::solve_in_place_scratch::<f64>(a.nrows(), rhs.ncols(), par);
    solve::solve_in_place(
        a.rb(),
        rhs,
        par,
        MemStack::new(&mut MemBuffer::new(scratch)),
    );
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solve_solves_and_refuses_an_indefinite_matrix() {
        // A = M Mᵀ + I is symmetric positive definite.
        let m = Mat::<f64>::from_fn(4, 4, |i, j| ((i * 4 + j) as f64 * 0.7).sin());
        let a = Mat::<f64>::from_fn(4, 4, |i, j| {
            (0..4).map(|k| m[(i, k)] * m[(j, k)]).sum::<f64>() + if i == j { 1.0 } else { 0.0 }
        });
        let b = Mat::<f64>::from_fn(4, 2, |i, j| (i + 3 * j) as f64 - 2.0);
        let (mut factor, mut x) = (a.clone(), b.clone());
        assert!(cholesky_solve(factor.as_mut(), x.as_mut()));
        for i in 0..4 {
            for j in 0..2 {
                let ax: f64 = (0..4).map(|k| a[(i, k)] * x[(k, j)]).sum();
                assert!((ax - b[(i, j)]).abs() < 1e-12, "({i}, {j}): {ax}");
            }
        }
        let mut indefinite = Mat::<f64>::from_fn(2, 2, |i, j| if i == j { 1.0 } else { 2.0 });
        let mut rhs = Mat::<f64>::from_fn(2, 1, |i, _| i as f64);
        assert!(!cholesky_solve(indefinite.as_mut(), rhs.as_mut()));
        assert_eq!((rhs[(0, 0)], rhs[(1, 0)]), (0.0, 1.0));
    }
}
