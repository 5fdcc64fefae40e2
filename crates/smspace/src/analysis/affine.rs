//! How well the sensor's positions can be read off a learned representation by one
//! affine map: the measures of Laflaquière & Garcia Ortiz, "Unsupervised emergence of
//! egocentric spatial structure from sensorimotor prediction" (NeurIPS 2019), so that
//! smspace's results can be put beside theirs.
//!
//! Given a representation `h_i ∈ ℝ^q` of `M` states (an embedding `Y`, or their learned
//! encodings) and the sensor's positions `p_i ∈ ℝ^d` (the linear coordinates of the
//! pose, without the orientation: their spatial variable is the position only):
//!
//! 1. the affine least-squares fit `p̂_i = A h_i + b`;
//! 2. with `D^P_ij = |p_i − p_j|`, `D^F_ij = |p̂_i − p̂_j|`, `D^H_ij = |h_i − h_j|` over
//!    the pairs `i < j`, and `D^P_max`, `D^H_max` their largest values,
//!    - **metric error** `E_0 = mean_{i<j} |D^F_ij − D^P_ij| / D^P_max`;
//!    - **topology error in P** `E_10`, the same weighted by
//!      `exp(−10 · D^P_ij / D^P_max)` (the small distances: are neighbours in space
//!      neighbours once mapped?);
//!    - **topology error in H** `mean_{i<j} D^H_ij / D^H_max · exp(−50 · D^P_ij / D^P_max)`
//!      (do states at the same position get the same representation?).
//!
//! All three are 0 for a representation that is an affine image of the positions; the
//! source evaluates them on a regular grid of motor states (`7³` or `5⁶`). Beside them,
//! `R²` of the fit (`1 − Σ|p − p̂|² / Σ|p − p̄|²`).

use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use super::AnalysisError;

/// The most states the measures take (`M(M − 1)/2` pairs each).
pub const MAX_STATES: usize = 50_000;

/// The affine-fit measures (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AffineErrors {
    /// States `M`.
    pub states: usize,
    /// Dimension `q` of the representation.
    pub representation_dim: usize,
    /// Dimension `d` of the positions.
    pub position_dim: usize,
    /// `R²` of the affine fit of the positions.
    pub r_squared: f64,
    /// `E_0`: the mean distance error of the fitted positions, over the largest
    /// distance.
    pub metric_error: f64,
    /// `E_10`: the same, weighted toward small distances in space.
    pub topology_error_positions: f64,
    /// The representation's spread among states close in space.
    pub topology_error_representation: f64,
    /// Which states they are (`all the states`, or as the caller says, e.g. the probe
    /// grid's sets).
    #[serde(default)]
    pub sets: String,
}

/// The measures of `representation` (`M × q`) against `positions` (`M × d`), same rows
/// (module docs).
pub fn affine_errors(
    representation: ArrayView2<'_, f64>,
    positions: ArrayView2<'_, f64>,
) -> Result<AffineErrors, AnalysisError> {
    let (m, q) = representation.dim();
    let d = positions.ncols();
    if positions.nrows() != m {
        return Err(AnalysisError::PosesShape {
            rows: positions.nrows(),
            columns: d,
            expected: m,
            coordinates: d,
        });
    }
    if m < 3 {
        return Err(AnalysisError::TooFewPoints {
            points: m,
            needed: 3,
        });
    }
    if m > MAX_STATES {
        return Err(AnalysisError::TooLarge {
            what: format!("the affine-fit measures of {m} states"),
            limit: "50 000 states; take a grid or a subsample",
        });
    }
    if q == 0 || d == 0 {
        return Err(AnalysisError::Degenerate {
            what: "the affine-fit measures",
            reason: format!("the representation has {q} columns and the positions {d}"),
        });
    }
    if let Some(bad) = representation
        .iter()
        .chain(positions.iter())
        .find(|v| !v.is_finite())
    {
        return Err(AnalysisError::Degenerate {
            what: "the affine-fit measures",
            reason: format!("a value is {bad}"),
        });
    }
    let fitted = affine_fit(representation, positions)?;
    let mean = positions.mean_axis(ndarray::Axis(0)).expect("M ≥ 3 rows");
    let total: f64 = positions
        .rows()
        .into_iter()
        .map(|p| (&p - &mean).mapv(|x| x * x).sum())
        .sum();
    let residual: f64 = (&fitted - &positions).mapv(|x| x * x).sum();
    let r_squared = if total > 0.0 {
        1.0 - residual / total
    } else {
        0.0
    };
    let distance = |a: ArrayView2<'_, f64>, i: usize, j: usize| -> f64 {
        a.row(i)
            .iter()
            .zip(a.row(j))
            .map(|(x, y)| (x - y) * (x - y))
            .sum::<f64>()
            .sqrt()
    };
    let (mut p_max, mut h_max) = (0.0f64, 0.0f64);
    for i in 0..m {
        for j in i + 1..m {
            p_max = p_max.max(distance(positions, i, j));
            h_max = h_max.max(distance(representation, i, j));
        }
    }
    if p_max <= 0.0 || h_max <= 0.0 {
        return Err(AnalysisError::Degenerate {
            what: "the affine-fit measures",
            reason: if p_max <= 0.0 {
                "every state has the same position".to_owned()
            } else {
                "every state has the same representation".to_owned()
            },
        });
    }
    let (mut e0, mut e10, mut eh) = (0.0, 0.0, 0.0);
    for i in 0..m {
        for j in i + 1..m {
            let dp = distance(positions, i, j) / p_max;
            let df = distance(fitted.view(), i, j) / p_max;
            let dh = distance(representation, i, j) / h_max;
            let error = (df - dp).abs();
            e0 += error;
            e10 += error * (-10.0 * dp).exp();
            eh += dh * (-50.0 * dp).exp();
        }
    }
    let pairs = (m * (m - 1) / 2) as f64;
    Ok(AffineErrors {
        states: m,
        representation_dim: q,
        position_dim: d,
        r_squared,
        metric_error: e0 / pairs,
        topology_error_positions: e10 / pairs,
        topology_error_representation: eh / pairs,
        sets: "all the states".to_owned(),
    })
}

/// `p̂ = [h, 1] B` with `B` the least-squares solution (normal equations, Cholesky, a
/// ridge of `1e-12` of the trace against an exactly collinear representation).
fn affine_fit(
    h: ArrayView2<'_, f64>,
    p: ArrayView2<'_, f64>,
) -> Result<Array2<f64>, AnalysisError> {
    let (m, q) = h.dim();
    let d = p.ncols();
    let column = |i: usize, c: usize| if c < q { h[[i, c]] } else { 1.0 };
    let mut a = faer::Mat::<f64>::zeros(q + 1, q + 1);
    let mut b = vec![vec![0.0; d]; q + 1];
    for i in 0..m {
        for r in 0..=q {
            let x = column(i, r);
            for c in 0..=r {
                a[(r, c)] += x * column(i, c);
            }
            for (k, t) in b[r].iter_mut().enumerate() {
                *t += x * p[[i, k]];
            }
        }
    }
    let trace: f64 = (0..=q).map(|r| a[(r, r)]).sum();
    for r in 0..=q {
        a[(r, r)] += 1e-12 * trace;
    }
    let mut coefficients = faer::Mat::<f64>::from_fn(q + 1, d, |r, k| b[r][k]);
    if !crate::linalg::cholesky_solve(a.as_mut(), coefficients.as_mut()) {
        return Err(AnalysisError::Degenerate {
            what: "the affine fit",
            reason: "the representation's normal matrix is not positive definite".to_owned(),
        });
    }
    Ok(Array2::from_shape_fn((m, d), |(i, k)| {
        (0..=q).map(|r| column(i, r) * coefficients[(r, k)]).sum()
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    fn grid() -> Array2<f64> {
        Array2::from_shape_fn((49, 2), |(i, c)| {
            if c == 0 {
                (i / 7) as f64
            } else {
                (i % 7) as f64
            }
        })
    }

    #[test]
    fn an_affine_image_of_the_positions_has_no_error() {
        let p = grid();
        // h = A p + b in 3-D, A of rank 2.
        let h = Array2::from_shape_fn((49, 3), |(i, c)| match c {
            0 => 2.0 * p[[i, 0]] - p[[i, 1]] + 3.0,
            1 => 0.5 * p[[i, 1]],
            _ => p[[i, 0]] + p[[i, 1]] - 1.0,
        });
        let e = affine_errors(h.view(), p.view()).unwrap();
        assert!(e.metric_error < 1e-9, "{e:?}");
        assert!(e.topology_error_positions < 1e-9, "{e:?}");
        assert!((e.r_squared - 1.0).abs() < 1e-9, "{e:?}");
        assert_eq!((e.states, e.representation_dim, e.position_dim), (49, 3, 2));
    }

    #[test]
    fn a_folded_representation_has_errors_and_a_collapsed_one_mixes_positions() {
        let p = grid();
        // Folded: the first coordinate through |x − 3|, so that x = 1 and x = 5 meet.
        let folded = Array2::from_shape_fn((49, 2), |(i, c)| {
            if c == 0 {
                (p[[i, 0]] - 3.0).abs()
            } else {
                p[[i, 1]]
            }
        });
        let e = affine_errors(folded.view(), p.view()).unwrap();
        assert!(e.metric_error > 0.05 && e.r_squared < 0.9, "{e:?}");
        // The topology error in H: states far apart in space share a representation
        // (no error there), states near in space are spread by noise in H.
        let exact = affine_errors(p.view(), p.view()).unwrap();
        let spread = Array2::from_shape_fn((49, 2), |(i, c)| {
            p[[i, c]] + if (i * 7 + c) % 3 == 0 { 2.0 } else { -1.0 }
        });
        let noisy = affine_errors(spread.view(), p.view()).unwrap();
        assert!(
            noisy.topology_error_representation > exact.topology_error_representation,
            "{noisy:?} {exact:?}"
        );
    }

    #[test]
    fn bad_inputs_are_refused() {
        let p = grid();
        let short = Array2::<f64>::zeros((10, 2));
        assert!(matches!(
            affine_errors(short.view(), p.view()),
            Err(AnalysisError::PosesShape { .. })
        ));
        let mut nan = p.clone();
        nan[[3, 1]] = f64::NAN;
        let e = affine_errors(nan.view(), p.view()).unwrap_err();
        assert!(e.to_string().contains("NaN"), "{e}");
        let constant = Array2::<f64>::ones((49, 2));
        let e = affine_errors(constant.view(), p.view()).unwrap_err();
        assert!(e.to_string().contains("same representation"), "{e}");
    }
}
