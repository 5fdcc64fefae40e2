//! The `[scale]` table: which path a run takes through distances, embedding and
//! analysis.
//!
//! - **dense**: the full `M × M` matrix `D` (`D.npy`), as the paper does; `8 M²` bytes.
//! - **landmarks**: never an `M × M` matrix. The `distances` stage writes `L` landmark
//!   sets ([`smspace::metric::landmarks`]: max–min or random, seeded), their `L × L`
//!   matrix and the `M × L` distances of every set to them, and the exact `k` nearest
//!   sets of every babbled set ([`smspace::metric::knn_with`], same metric); `embed` fits
//!   the method on the landmarks and places every set out of sample
//!   ([`smspace::embed::landmarks`]); `analyze` computes persistent homology on the first
//!   `min(L, analysis.max_points)` landmarks (in the order chosen, with their covering
//!   radius over all `M` sets), the intrinsic dimension from the kNN distances (the
//!   same lists the dense path sorts out of `D`, so the same TwoNN and MLE), and the
//!   agreement with the poses on the `L` landmarks.
//!
//! `path = "auto"` (default) takes the landmark path when `M > above` (default 5000,
//! where `D` is 200 MB) and the dense path otherwise; `"dense"` and `"landmarks"` force
//! one (`smspace run --set scale.path=landmarks`).

use serde::{Deserialize, Serialize};

use smspace::metric::landmarks::{LandmarkParams, LandmarkSelection, LandmarkValidParams};
use smspace::metric::{KnnParams, MetricError};
use smspace::params::InvalidParameter;

/// Which path a run takes (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ScalePath {
    /// Landmarks above `above` sets, dense below.
    #[default]
    Auto,
    /// Always the `M × M` matrix.
    Dense,
    /// Always landmarks.
    Landmarks,
}

/// The path a run of `M` sets takes, once chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChosenPath {
    /// The `M × M` matrix.
    Dense,
    /// Landmarks and the kNN graph.
    Landmarks,
}

/// The `[scale]` table (unchecked; [`ScaleParams::check`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScaleParams {
    /// `"auto"` (default), `"dense"` or `"landmarks"`.
    pub path: ScalePath,
    /// `auto` takes the landmark path above this many sets. Default 5000.
    pub above: usize,
    /// Number of landmark sets `L`. Default 2000.
    pub landmarks: usize,
    /// `"random"` (default) or `"max-min"` (`L·M` distances to choose: for small `M`).
    pub selection: LandmarkSelection,
    /// Seed of the landmarks. Default 0.
    pub seed: u64,
    /// Nearest landmarks measured exactly per set, for the out-of-sample map (the
    /// others through them, [`smspace::metric::landmarks`]). Default 16.
    pub nearest: usize,
    /// Nearest sets per babbled set in the kNN graph (at least `analysis.mle_neighbors`
    /// and 2). Default 20.
    pub knn: usize,
}

impl Default for ScaleParams {
    fn default() -> Self {
        Self {
            path: ScalePath::Auto,
            above: 5000,
            landmarks: 2000,
            selection: LandmarkSelection::Random,
            seed: 0,
            nearest: 16,
            knn: 20,
        }
    }
}

impl ScaleParams {
    /// The path for `m` sets.
    pub fn choose(&self, m: usize) -> ChosenPath {
        match self.path {
            ScalePath::Dense => ChosenPath::Dense,
            ScalePath::Landmarks => ChosenPath::Landmarks,
            ScalePath::Auto if m > self.above => ChosenPath::Landmarks,
            ScalePath::Auto => ChosenPath::Dense,
        }
    }

    /// The landmark parameters.
    pub fn landmark_params(&self) -> LandmarkParams {
        LandmarkParams::new(self.landmarks, self.selection, self.seed).nearest(self.nearest)
    }

    /// The kNN parameters (the search's default pivots).
    pub fn knn_params(&self) -> KnnParams {
        KnnParams::new().k(self.knn)
    }

    /// Checks the landmarks and that `knn ≥ max(2, mle_neighbors)` (the dimension
    /// estimates read the kNN lists).
    pub fn check(&self, mle_neighbors: usize) -> Result<LandmarkValidParams, MetricError> {
        let landmarks = self.landmark_params().check()?;
        let least = mle_neighbors.max(2);
        if self.knn < least {
            return Err(InvalidParameter::new(
                "scale",
                "knn",
                self.knn,
                format!("at least {least}: the intrinsic dimension (analysis.mle_neighbors = {mle_neighbors}) reads that many nearest sets"),
            )
            .into());
        }
        if self.above < 3 {
            return Err(InvalidParameter::new(
                "scale",
                "above",
                self.above,
                "at least 3 sets (the dense path's analysis needs 3)",
            )
            .into());
        }
        Ok(landmarks)
    }

    /// Whether this is the default table (then the distances stage's key is the one
    /// it had before the table existed).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}
