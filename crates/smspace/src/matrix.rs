//! The distance matrix between kernel sets as a type, validated once where it enters.
//!
//! `D_ij = ρ(M^i, M^j)` (paper section 3.2, step 3) is what the embedding (step 4) and
//! the analysis (section 3.3) read. A [`DistanceMatrix`] is known to be one:
//!
//! * square `(M, M)`;
//! * every entry finite and non-negative;
//! * symmetric and zero on the diagonal within the stated tolerance
//!   `|D_ij − D_ji| ≤ τ` and `D_ii ≤ τ`, with `τ = `[`SYMMETRY_TOLERANCE`]` · max(1, max D)`;
//!   the values kept are then exactly symmetric (the mean of the two triangles) with
//!   an exact zero diagonal, so that no algorithm downstream needs to check or repair
//!   them;
//! * stored in C (row-major) order, whatever the layout or strides of the input
//!   (a NumPy array saved in Fortran order, a transposed or strided view).
//!
//! Errors name where the matrix came from (its file, for [`DistanceMatrix::load`]) and
//! the first bad entry. A matrix the metric computes ([`distance_matrix`](crate::metric::distance_matrix))
//! is one by construction: equal mirrored entries and a zero diagonal.

use std::path::Path;

use ndarray::{Array2, ArrayView2, Axis};

use crate::io::{self, IoError};

/// Relative tolerance of the symmetry and zero-diagonal checks of a
/// [`DistanceMatrix`]: entries may differ from symmetry, and the diagonal from zero, by
/// at most `SYMMETRY_TOLERANCE · max(1, max D)`.
pub const SYMMETRY_TOLERANCE: f64 = 1e-9;

/// Why an array is not a distance matrix. `origin` names it: its file, or "the
/// distance matrix".
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MatrixError {
    /// Not square.
    #[error("{origin} has shape ({rows}, {columns}); a distance matrix is square (M, M)")]
    NotSquare {
        /// Where the matrix came from.
        origin: String,
        /// Rows.
        rows: usize,
        /// Columns.
        columns: usize,
    },
    /// An entry is NaN or infinite.
    #[error("{origin} holds {value} at [{i}, {j}]; every distance must be a finite number")]
    NonFinite {
        /// Where the matrix came from.
        origin: String,
        /// Row.
        i: usize,
        /// Column.
        j: usize,
        /// The value.
        value: f64,
    },
    /// An entry is negative.
    #[error("{origin} holds a negative distance {value} at [{i}, {j}]")]
    Negative {
        /// Where the matrix came from.
        origin: String,
        /// Row.
        i: usize,
        /// Column.
        j: usize,
        /// The value.
        value: f64,
    },
    /// A diagonal entry is not zero.
    #[error("{origin} has [{i}, {i}] = {value} (tolerance {tolerance:.1e}); the distance of a set to itself must be 0")]
    NonZeroDiagonal {
        /// Where the matrix came from.
        origin: String,
        /// Index.
        i: usize,
        /// The value.
        value: f64,
        /// The tolerance used.
        tolerance: f64,
    },
    /// The matrix is not symmetric.
    #[error("{origin} is not symmetric: [{i}, {j}] = {a} but [{j}, {i}] = {b} (tolerance {tolerance:.1e}); symmetrise it, e.g. (D + D.T) / 2")]
    Asymmetric {
        /// Row (`i < j`).
        i: usize,
        /// Column.
        j: usize,
        /// `D[i, j]`.
        a: f64,
        /// `D[j, i]`.
        b: f64,
        /// The tolerance used.
        tolerance: f64,
        /// Where the matrix came from.
        origin: String,
    },
    /// Reading the file failed (missing, not a float64 `.npy`, not 2-D, a NaN, …).
    #[error(transparent)]
    Io(#[from] IoError),
}

/// A validated distance matrix `(M, M)` (see the module docs): square, finite,
/// non-negative, exactly symmetric with a zero diagonal, in C order.
///
/// It dereferences to the [`Array2`] it holds, read-only.
///
/// ```
/// use smspace::metric::DistanceMatrix;
/// // A matrix saved in Fortran order (here: a transposed view) is taken as it is meant.
/// let d = ndarray::array![[0.0, 1.0, 2.0], [1.0, 0.0, 1.5], [2.0, 1.5, 0.0]];
/// let m = DistanceMatrix::from_view(d.t())?;
/// assert_eq!(m.len(), 3);
/// assert!(m.view().is_standard_layout());
/// // Entries off by less than the tolerance are averaged; more is an error naming them.
/// let mut bad = d.clone();
/// bad[[0, 2]] = 2.5;
/// let err = DistanceMatrix::new(bad).unwrap_err().to_string();
/// assert!(err.contains("[0, 2] = 2.5 but [2, 0] = 2"), "{err}");
/// # Ok::<(), smspace::metric::MatrixError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceMatrix {
    values: Array2<f64>,
}

impl DistanceMatrix {
    /// Validates `values` (any layout) as a distance matrix.
    pub fn new(values: Array2<f64>) -> Result<Self, MatrixError> {
        Self::checked(values, "the distance matrix")
    }

    /// Validates a view in any layout or strides (copied into C order).
    pub fn from_view(values: ArrayView2<'_, f64>) -> Result<Self, MatrixError> {
        Self::checked(values.to_owned(), "the distance matrix")
    }

    /// Reads and validates an `(M, M)` float64 `.npy` file (any NumPy order); errors
    /// name the file and the first bad entry.
    pub fn load(path: &Path) -> Result<Self, MatrixError> {
        let values = io::read_matrix(path, None, "(M, M)")?;
        Self::checked(values, &path.display().to_string())
    }

    /// Writes the matrix to `path` (atomically, as a C-order float64 `.npy`).
    pub fn save(&self, path: &Path) -> Result<(), IoError> {
        let mut outputs = io::Outputs::new();
        self.write_into(&mut outputs, path)?;
        outputs.commit().map(drop)
    }

    /// Stages the matrix for `path` into `outputs`, to be renamed into place with the
    /// other files of a command or stage (the bytes [`save`](Self::save) writes).
    pub fn write_into(&self, outputs: &mut io::Outputs, path: &Path) -> Result<(), IoError> {
        outputs.npy(path, &self.values)
    }

    /// A matrix the caller built symmetric with a zero diagonal (the metric's):
    /// checked only in debug builds.
    pub(crate) fn from_symmetric(values: Array2<f64>) -> Self {
        debug_assert!(
            Self::new(values.clone()).is_ok_and(|m| m.values == values),
            "a computed distance matrix is symmetric with a zero diagonal"
        );
        Self {
            values: standard(values),
        }
    }

    fn checked(values: Array2<f64>, origin: &str) -> Result<Self, MatrixError> {
        let mut values = standard(values);
        let (rows, columns) = values.dim();
        if rows != columns {
            return Err(MatrixError::NotSquare {
                origin: origin.to_owned(),
                rows,
                columns,
            });
        }
        let mut largest = 0.0_f64;
        for ((i, j), &value) in values.indexed_iter() {
            if !value.is_finite() {
                let origin = origin.to_owned();
                return Err(MatrixError::NonFinite {
                    origin,
                    i,
                    j,
                    value,
                });
            }
            if value < 0.0 {
                let origin = origin.to_owned();
                return Err(MatrixError::Negative {
                    origin,
                    i,
                    j,
                    value,
                });
            }
            largest = largest.max(value);
        }
        let tolerance = SYMMETRY_TOLERANCE * largest.max(1.0);
        for i in 0..rows {
            let value = values[[i, i]];
            if value > tolerance {
                return Err(MatrixError::NonZeroDiagonal {
                    origin: origin.to_owned(),
                    i,
                    value,
                    tolerance,
                });
            }
            values[[i, i]] = 0.0;
            for j in i + 1..rows {
                let (a, b) = (values[[i, j]], values[[j, i]]);
                if a == b {
                    continue;
                }
                if (a - b).abs() > tolerance {
                    return Err(MatrixError::Asymmetric {
                        origin: origin.to_owned(),
                        i,
                        j,
                        a,
                        b,
                        tolerance,
                    });
                }
                // Halving is exact: this is 0.5 (a + b) without its overflow.
                let mean = 0.5 * a + 0.5 * b;
                values[[i, j]] = mean;
                values[[j, i]] = mean;
            }
        }
        Ok(Self { values })
    }

    /// Number of sets `M`.
    pub fn len(&self) -> usize {
        self.values.nrows()
    }

    /// True for the `0 × 0` matrix.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The matrix, in C order.
    pub fn view(&self) -> ArrayView2<'_, f64> {
        self.values.view()
    }

    /// The array.
    pub fn as_array(&self) -> &Array2<f64> {
        &self.values
    }

    /// The array, owned.
    pub fn into_array(self) -> Array2<f64> {
        self.values
    }

    /// The distances between the sets `rows` (in that order): a distance matrix of
    /// `rows.len()` sets. Panics when a row is out of range, like indexing.
    pub fn select(&self, rows: &[usize]) -> Self {
        Self {
            values: self.values.select(Axis(0), rows).select(Axis(1), rows),
        }
    }
}

impl std::ops::Deref for DistanceMatrix {
    type Target = Array2<f64>;
    fn deref(&self) -> &Array2<f64> {
        &self.values
    }
}

impl PartialEq<Array2<f64>> for DistanceMatrix {
    fn eq(&self, other: &Array2<f64>) -> bool {
        self.values == *other
    }
}

impl PartialEq<DistanceMatrix> for Array2<f64> {
    fn eq(&self, other: &DistanceMatrix) -> bool {
        *self == other.values
    }
}

impl TryFrom<Array2<f64>> for DistanceMatrix {
    type Error = MatrixError;
    fn try_from(values: Array2<f64>) -> Result<Self, MatrixError> {
        Self::new(values)
    }
}

/// `values` in C order (moved as is when it already is).
fn standard(values: Array2<f64>) -> Array2<f64> {
    if values.is_standard_layout() {
        values
    } else {
        values.as_standard_layout().into_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Slice};

    fn triangle() -> Array2<f64> {
        array![[0.0, 3.0, 4.0], [3.0, 0.0, 5.0], [4.0, 5.0, 0.0]]
    }

    #[test]
    fn any_layout_or_stride_is_read_in_c_order() {
        let d = triangle();
        let expected = DistanceMatrix::new(d.clone()).unwrap();
        // Transposed (Fortran order), and every other row and column of a larger array.
        let mut big = Array2::from_elem((6, 6), 7.0);
        let every_other =
            |a: ArrayView2<'_, f64>| a.slice_each_axis(|_| Slice::new(0, None, 2)).to_owned();
        let mut stepped = big.view_mut();
        stepped.slice_each_axis_inplace(|_| Slice::new(0, None, 2));
        stepped.assign(&d);
        assert_eq!(every_other(big.view()), d);
        let strided = big.slice_each_axis(|_| Slice::new(0, None, 2));
        for view in [d.t(), strided] {
            let m = DistanceMatrix::from_view(view).unwrap();
            assert!(m.view().is_standard_layout());
            assert_eq!(m, expected);
        }
        let mut fortran = Array2::zeros(ndarray::ShapeBuilder::f(d.raw_dim()));
        fortran.assign(&d);
        assert!(!fortran.is_standard_layout());
        assert_eq!(DistanceMatrix::new(fortran).unwrap(), expected);
    }

    #[test]
    fn every_fault_names_its_first_entry() {
        let err = |d: Array2<f64>| DistanceMatrix::new(d).unwrap_err();
        assert!(matches!(
            err(Array2::zeros((2, 3))),
            MatrixError::NotSquare {
                rows: 2,
                columns: 3,
                ..
            }
        ));
        let mut d = triangle();
        d[[2, 1]] = f64::NAN;
        d[[1, 2]] = f64::INFINITY;
        assert!(matches!(err(d), MatrixError::NonFinite { i: 1, j: 2, .. }));
        let mut d = triangle();
        d[[0, 1]] = -3.0;
        d[[1, 0]] = -3.0;
        assert!(matches!(err(d), MatrixError::Negative { i: 0, j: 1, .. }));
        let mut d = triangle();
        d[[2, 2]] = 1e-3;
        assert!(matches!(err(d), MatrixError::NonZeroDiagonal { i: 2, .. }));
        let mut d = triangle();
        d[[2, 0]] = 4.001;
        let e = err(d);
        assert!(
            matches!(e, MatrixError::Asymmetric { i: 0, j: 2, .. }),
            "{e}"
        );
        assert!(e
            .to_string()
            .contains("the distance matrix is not symmetric"));
    }

    #[test]
    fn small_asymmetry_is_averaged_and_a_small_diagonal_zeroed() {
        let mut d = triangle();
        d[[0, 1]] = 3.0 + 2e-9;
        d[[1, 1]] = 1e-9;
        let m = DistanceMatrix::new(d).unwrap();
        assert_eq!(m[[0, 1]], m[[1, 0]]);
        assert!((m[[0, 1]] - (3.0 + 1e-9)).abs() < 1e-15);
        assert_eq!(m[[1, 1]], 0.0);
        // An exactly symmetric matrix is kept bit for bit.
        assert_eq!(
            DistanceMatrix::new(triangle()).unwrap().into_array(),
            triangle()
        );
    }

    #[test]
    fn load_names_the_file_and_save_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("D.npy");
        let m = DistanceMatrix::new(triangle()).unwrap();
        m.save(&path).unwrap();
        assert_eq!(DistanceMatrix::load(&path).unwrap(), m);
        let mut bad = triangle();
        bad[[0, 1]] = 9.0;
        io::write_npy(&path, &bad).unwrap();
        let err = DistanceMatrix::load(&path).unwrap_err().to_string();
        assert!(
            err.starts_with(&format!("{} is not symmetric", path.display())),
            "{err}"
        );
        let missing = DistanceMatrix::load(&dir.path().join("none.npy")).unwrap_err();
        assert!(matches!(missing, MatrixError::Io(_)));
    }

    #[test]
    fn a_selection_is_a_distance_matrix_of_those_sets() {
        let m = DistanceMatrix::new(triangle()).unwrap();
        let sub = m.select(&[2, 0]);
        assert_eq!(sub.into_array(), array![[0.0, 4.0], [4.0, 0.0]]);
    }
}
