//! An embedding fitted on landmark sets and extended to every set out of sample
//! (the scale path): `M` sets embedded from their `M × L` distances to `L`
//! landmarks and the landmarks' `L × L` matrix
//! ([`crate::metric::landmarks`]), never an `M × M` matrix.
//!
//! 1. **Fit.** The method ([`Embedding`]) is fitted on the landmarks' matrix `Δ`
//!    `(L, L)`, rows in increasing set index (so that with every set a landmark, `Δ` is
//!    the full matrix and the coordinates are the dense fit's, bit for bit).
//! 2. **Extend.** Every set that is not a landmark is placed from its distances
//!    `δ = (ρ(j, l_1), …, ρ(j, l_L))` (exact to its nearest landmarks, the triangle
//!    bound through them to the others:
//!    [`LandmarkDistances::distances_from`]) by the fitted method's out-of-sample map
//!    ([`Embedded::extend`]), the landmarks staying where the fit put them:
//!    - **MDS**: the landmark-MDS triangulation (de Silva & Tenenbaum 2004). With the
//!      fit's `d` largest eigenpairs `(λ_c, v_c)` of `B = −½ J Δ^{∘2} J`, landmark
//!      coordinates `L_lc = √λ_c v_lc` and `μ_l = (1/L) Σ_a Δ²_al`,
//!
//!      ```text
//!      y_c = −½ Σ_l (L_lc / λ_c) (δ_l² − μ_l),    i.e.  y = −½ L⁺ (δ² − μ),
//!      ```
//!
//!      exact (up to the fit's rotation) when the distances are Euclidean of rank `≤ d`,
//!      and a landmark's own `δ` gives back its coordinates.
//!    - **Isomap**: the same triangulation of geodesic distances: the landmarks' `k`
//!      nearest-neighbour graph gives the geodesics `g(l_a, l_b)` (Dijkstra), and a set
//!      reaches landmark `l` through its `k` nearest landmarks `u`:
//!      `δ_l = min_u (ρ(j, u) + g(u, l))`.
//!    - **CCA**: each new point `y` minimises CCA's stress against the fixed landmark
//!      layout `y_l` at the fit's final width `λ₁`,
//!
//!      ```text
//!      E(y) = ½ Σ_l (δ_l − ‖y − y_l‖)² F(‖y − y_l‖, λ),   λ = max(λ₁, δ_(2d+1)),
//!      ```
//!
//!      (`δ_(2d+1)`: the distance to its `2d + 1`-th nearest landmark, so that some
//!      landmarks are in reach of `F`), starting at the mean of its `2d + 1` nearest
//!      landmarks' coordinates weighted by `1/δ`, by `extend_epochs` epochs of CCA's own
//!      stochastic update `y ← y + α(t) F (δ_l − Y_l)/Y_l (y − y_l)` over the landmarks
//!      in a seeded order (per point), `α` from `alpha_start` to `alpha_end`
//!      geometrically ([`super::cca`]).
//!
//! Sets are extended in blocks of [`EXTEND_BLOCK`] rows (each block in parallel), so
//! the extension holds `O(block · L)` besides the `(M, d)` output. Deterministic for
//! the methods' seeds whatever the number of threads (each point is placed on its own).

use ndarray::{Array2, Axis};
use rayon::prelude::*;

use super::{EmbedError, Embedded, Embedding};
use crate::metric::landmarks::LandmarkDistances;
use crate::metric::DistanceMatrix;
use crate::progress::Progress;

/// Sets placed per block of the extension.
pub const EXTEND_BLOCK: usize = 4096;

/// An embedding of every set fitted on landmarks.
#[derive(Debug, Clone)]
pub struct LandmarkEmbedding {
    /// `(M, d)`: every set's coordinates (the landmarks' from the fit).
    pub coordinates: Array2<f64>,
    /// The fit on the landmarks, rows in the order of [`LandmarkEmbedding::fitted_rows`].
    pub fitted: Embedded,
    /// The landmark sets in the order of the fit (increasing set index).
    pub fitted_rows: Vec<usize>,
}

/// Fits `method` on the landmarks of `landmarks` and places every other set from its
/// distances to them (module docs).
pub fn fit_on_landmarks(
    method: &dyn Embedding,
    landmarks: &LandmarkDistances,
    progress: &dyn Progress,
) -> Result<LandmarkEmbedding, EmbedError> {
    let m = landmarks.sets();
    // Landmarks by increasing set index, and where each is among the computed columns.
    let mut order: Vec<usize> = (0..landmarks.len()).collect();
    order.sort_unstable_by_key(|&a| landmarks.rows[a]);
    let fitted_rows: Vec<usize> = order.iter().map(|&a| landmarks.rows[a]).collect();
    let sorted = DistanceMatrix::new(Array2::from_shape_fn(
        (order.len(), order.len()),
        |(a, b)| landmarks.landmarks[[order[a], order[b]]],
    ))?;
    let fitted = method.fit(&sorted, progress)?;
    let dim = fitted.coordinates.ncols();
    let mut coordinates = Array2::zeros((m, dim));
    let mut is_landmark = vec![None; m];
    for (a, &row) in fitted_rows.iter().enumerate() {
        is_landmark[row] = Some(a);
    }
    let others: Vec<usize> = (0..m).filter(|&j| is_landmark[j].is_none()).collect();
    progress.start("extend", others.len() as u64);
    for block in others.chunks(EXTEND_BLOCK) {
        let mut to_old = Array2::zeros((block.len(), order.len()));
        to_old
            .as_slice_mut()
            .expect("a new array is in standard layout")
            .par_chunks_mut(order.len())
            .zip(block.par_iter())
            .for_each_init(
                || vec![0.0; order.len()],
                |row_in_chosen_order, (row, &j)| {
                    landmarks.distances_from(j, row_in_chosen_order);
                    for (slot, &a) in row.iter_mut().zip(&order) {
                        *slot = row_in_chosen_order[a];
                    }
                },
            );
        let placed = fitted.extend(to_old.view())?;
        for (r, &j) in block.iter().enumerate() {
            coordinates.row_mut(j).assign(&placed.row(r));
        }
        progress.advance(block.len() as u64);
    }
    progress.finish();
    for (a, &row) in fitted_rows.iter().enumerate() {
        coordinates
            .row_mut(row)
            .assign(&fitted.coordinates.index_axis(Axis(0), a));
    }
    Ok(LandmarkEmbedding {
        coordinates,
        fitted,
        fitted_rows,
    })
}
