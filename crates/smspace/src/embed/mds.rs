//! Classical (Torgerson) multidimensional scaling.
//!
//! With squared distances `Δ = X^{∘2}` and the centring matrix `J = I − 11ᵀ/M`, the
//! double-centred matrix `B = −½ J Δ J` is the Gram matrix of centred points when `X`
//! is Euclidean (Torgerson 1952; Gower 1966). Its `d` largest eigenpairs `(λ_c, u_c)` give
//! `Y = [√λ_1 u_1 … √λ_d u_d]`, which reproduces Euclidean points up to a rigid motion.
//! For a non-Euclidean metric (a Hausdorff distance, geodesic distances) `B` has negative
//! eigenvalues; [`super::EmbedReport::eigenvalues`] lists them so that one can see how far
//! from Euclidean the metric is. New points are placed by Gower's interpolation, the
//! landmark triangulation of de Silva & Tenenbaum (2003) with every point a landmark.

use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use super::eigen::{classical_mds, distance_scale, rescaled, EigenSolver, Triangulation};
use super::{check_dim_param, EmbedError, EmbedReport, Embedded};
use super::{Embedding, Extender};
use crate::progress::{Progress, Silent};

/// Parameters of classical MDS (unchecked).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MdsParams {
    /// Output dimension `d`. Default 3.
    pub dim: usize,
    /// Eigensolver. Default [`EigenSolver::Auto`] (dense up to 1000 points).
    pub solver: EigenSolver,
    /// Seed of the partial solver's start vector. Default 0.
    pub seed: u64,
}

impl Default for MdsParams {
    fn default() -> Self {
        Self {
            dim: 3,
            solver: EigenSolver::Auto,
            seed: 0,
        }
    }
}

impl MdsParams {
    /// Sets the output dimension (default 3).
    pub fn dim(mut self, dim: usize) -> Self {
        self.dim = dim;
        self
    }
    /// Sets the eigensolver (default `Auto`).
    pub fn solver(mut self, solver: EigenSolver) -> Self {
        self.solver = solver;
        self
    }
    /// Sets the seed (default 0).
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// Validates the parameters.
    pub fn check(self) -> Result<MdsValidParams, EmbedError> {
        check_dim_param(self.dim)?;
        Ok(MdsValidParams(self))
    }
}

/// Checked parameters of classical MDS; [`Embedding::fit`] runs it.
#[derive(Debug, Clone, PartialEq)]
pub struct MdsValidParams(MdsParams);

impl MdsValidParams {
    /// The parameters.
    pub fn params(&self) -> &MdsParams {
        &self.0
    }
}

impl Embedding for MdsValidParams {
    fn name(&self) -> &'static str {
        "mds"
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
        _progress: &dyn Progress,
    ) -> Result<Embedded, EmbedError> {
        if let Some(scale) = distance_scale(distances) {
            let scaled = distances.mapv(|x| x / scale);
            return Ok(rescaled(self.fit_checked(scaled.view(), &Silent)?, scale));
        }
        let n = distances.nrows();
        let sq: Array2<f64> = distances.mapv(|x| x * x);
        let fit = classical_mds(sq, self.0.dim, self.0.solver, self.0.seed, false)?;
        let report = EmbedReport {
            method: "mds".into(),
            points: n,
            dim: self.0.dim,
            eigenvalues: fit.eigenvalues.clone(),
            eigenvalue_trace: Some(fit.trace),
            ..Default::default()
        };
        let extender = Extender::Triangulation(Box::new(Triangulation {
            landmark_coordinates: fit.coordinates.clone(),
            eigenvalues: fit.used,
            mean_sq: fit.mean_sq,
            landmarks: (0..n).collect(),
            geodesic: None,
        }));
        Ok(Embedded {
            coordinates: fit.coordinates,
            report,
            extender,
        })
    }

    fn working_bytes(&self, points: usize) -> u64 {
        super::mds_bytes(points as u64)
    }

    fn memory_fix(&self) -> &'static str {
        "lower exploration.n (M), or embed with method = \"cca\" (landmark MDS start)"
    }
}
