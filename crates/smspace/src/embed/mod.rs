//! Embeddings of the learned metric: coordinates `Y` `(M, d)` for a distance matrix
//! `X` `(M, M)` between the sets `M^i`.
//!
//! The paper (section 3.2, last paragraphs) projects the manifold of sets to 3-D with
//! Curvilinear Component Analysis "for the reader to see it", and names Isomap as an
//! alternative (section 3.3). Three methods are offered, all behind the object-safe
//! [`Embedding`] trait so that a configuration picks one by name ([`EmbedParams`]):
//!
//! * [`cca`]: Curvilinear Component Analysis (Demartines & Hérault 1997), the paper's. For
//!   a pivot `i`, every other point moves as
//!   `y_j ← y_j + α(t) F(Y_ij, λ(t)) (X_ij − Y_ij) / Y_ij · (y_j − y_i)`,
//!   where `Y_ij = ‖y_i − y_j‖`; it preserves small output distances first.
//! * [`isomap`]: Isomap (Tenenbaum, de Silva & Langford 2000): shortest paths in the
//!   `k`-nearest-neighbour graph approximate geodesic distances, which classical MDS then
//!   embeds; landmark Isomap (de Silva & Tenenbaum 2003) for large `M`.
//! * [`mds`]: classical (Torgerson 1952) multidimensional scaling:
//!   `B = −½ J X^{∘2} J` with `J = I − 11ᵀ/M`, and `Y = U_d Λ_d^{1/2}` from the `d`
//!   largest eigenpairs of `B`. Negative eigenvalues of `B` measure how far the metric is
//!   from Euclidean.
//!
//! A fitted [`Embedded`] places new points from their distances to the embedded ones
//! ([`Embedded::extend`]) without re-running the embedding: the paper's incremental
//! extension of the internal manifold (end of section 3.3). [`quality`] measures an
//! embedding against its input distances (trustworthiness, continuity, stress, a
//! Shepard `dy–dx` sample).
//!
//! Every method is deterministic for its `seed`, whatever the number of threads: the
//! parallel loops either fill independent rows or reduce in fixed chunks.

pub mod cca;
mod eigen;
pub mod isomap;
pub mod landmarks;
pub mod mds;
pub mod quality;
mod registry;

use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use crate::metric::DistanceMatrix;
use crate::params::{CheckParams, InvalidParameter};
use crate::progress::Progress;

pub use cca::{CcaParams, CcaValidParams, Neighbourhood};
pub use eigen::EigenSolver;
pub use isomap::{IsomapParams, IsomapValidParams, KnnGraph, LandmarkChoice};
pub use mds::{MdsParams, MdsValidParams};
pub use registry::EmbeddingRegistry;

/// Errors of the embedding stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EmbedError {
    /// The distance matrix is not one.
    #[error(transparent)]
    Distances(#[from] crate::metric::MatrixError),
    /// Too few points for the requested output dimension.
    #[error("cannot embed {points} points in {dim} dimensions; {}", dim_advice(*points))]
    DimTooLarge {
        /// Output dimension asked for.
        dim: usize,
        /// Number of points.
        points: usize,
    },
    /// A parameter is out of its range.
    #[error(transparent)]
    Invalid(#[from] InvalidParameter),
    /// The neighbour count is too large for the number of points.
    #[error("k = {k} neighbours asked for {points} points; use k < {points}")]
    KTooLarge {
        /// Neighbours asked for.
        k: usize,
        /// Number of points.
        points: usize,
    },
    /// The neighbour graph is disconnected.
    #[error("the k={k} neighbour graph has {components} connected components (the largest holds {largest} of {points} points); use a larger --k")]
    Disconnected {
        /// Neighbours per point.
        k: usize,
        /// Number of connected components.
        components: usize,
        /// Size of the largest component.
        largest: usize,
        /// Number of points.
        points: usize,
    },
    /// A supplied kNN graph is malformed.
    #[error("invalid kNN graph: {0}")]
    Knn(String),
    /// The distance matrix has fewer positive eigenvalues than output dimensions.
    #[error("classical MDS found only {positive} positive eigenvalue(s) of the centred matrix, fewer than the {dim} dimensions asked; use a smaller --dim")]
    TooFewPositiveEigenvalues {
        /// Positive eigenvalues found.
        positive: usize,
        /// Output dimension asked for.
        dim: usize,
    },
    /// The eigensolver failed.
    #[error("the eigensolver did not converge ({0}); the distance matrix may be degenerate")]
    Eigen(String),
    /// Out-of-sample distances do not match the embedding.
    #[error("the new-to-old distances have shape ({rows}, {cols}) but the embedding has {points} points; expected (N, {points})")]
    ExtendShape {
        /// Rows found.
        rows: usize,
        /// Columns found.
        cols: usize,
        /// Points in the embedding.
        points: usize,
    },
    /// Out-of-sample distances hold a negative or non-finite value.
    #[error("the new-to-old distances hold {value} at [{i}, {j}]; every distance must be finite and non-negative")]
    ExtendValue {
        /// Row.
        i: usize,
        /// Column.
        j: usize,
        /// The value.
        value: f64,
    },
    /// A neighbour computation refused its input.
    #[error(transparent)]
    Neighbours(#[from] crate::neighbours::NeighboursError),
    /// Reading a file failed.
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
    /// No registered embedding method has this name.
    #[error("unknown embedding method '{name}'; the registered methods are {known}")]
    UnknownMethod {
        /// The name given.
        name: String,
        /// The registered methods, comma-separated.
        known: String,
    },
    /// A method's parameters (the `[embedding]` table) do not fit it.
    #[error("invalid [embedding] table for the {method} method: {reason}")]
    InvalidTable {
        /// The method.
        method: String,
        /// The reader's message, naming the key.
        reason: String,
    },
}

impl EmbedError {
    /// The parameter out of its domain, located by table and key, if this is one.
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            EmbedError::Invalid(p) => Some(p),
            _ => None,
        }
    }
}

/// An embedding method: turns an `(M, M)` distance matrix into coordinates `(M, d)`.
///
/// Object-safe, so that a configuration can pick the method by name
/// ([`EmbedParams::build`]).
///
/// ```
/// use smspace::embed::{CcaParams, Embedding, IsomapParams, MdsParams};
/// use smspace::metric::DistanceMatrix;
/// use smspace::progress::Silent;
/// // Eight points on a line, 1 apart: every method finds the line.
/// let d = ndarray::Array2::from_shape_fn((8, 8), |(i, j)| (i as f64 - j as f64).abs());
/// let d = DistanceMatrix::new(d)?;
/// let methods: [Box<dyn Embedding>; 3] = [
///     Box::new(MdsParams::default().dim(1).check()?),
///     Box::new(IsomapParams::default().dim(1).k(2).check()?),
///     Box::new(CcaParams::default().dim(1).epochs(20).check()?),
/// ];
/// for method in methods {
///     let y = method.fit(&d, &Silent)?.coordinates;
///     let span = (y[[7, 0]] - y[[0, 0]]).abs();
///     assert!((span - 7.0).abs() < 0.1, "{}: {span}", method.name());
/// }
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait Embedding: Send + Sync + std::fmt::Debug {
    /// The method's name (`"cca"`, `"isomap"`, `"mds"`).
    fn name(&self) -> &'static str;

    /// The output dimension `d`.
    fn dim(&self) -> usize;

    /// Embeds the points whose pairwise distances are `distances` `(M, M)` (validated
    /// when it was made: [`DistanceMatrix`]); the dimension is checked against its
    /// size, then [`fit_checked`](Embedding::fit_checked) runs.
    fn fit(
        &self,
        distances: &DistanceMatrix,
        progress: &dyn Progress,
    ) -> Result<Embedded, EmbedError> {
        check_dim(self.dim(), distances.len())?;
        self.fit_checked(distances.view(), progress)
    }

    /// The method itself, on a matrix that [`fit`](Embedding::fit) has validated (a
    /// [`DistanceMatrix`] in C order).
    fn fit_checked(
        &self,
        distances: ArrayView2<'_, f64>,
        progress: &dyn Progress,
    ) -> Result<Embedded, EmbedError>;

    /// The checked parameters, as JSON, for reports.
    fn params_json(&self) -> serde_json::Value;

    /// Embeds the points of a nearest-neighbour graph instead of a distance matrix
    /// (`smspace embed --knn-indices`), for a method that can (Isomap, from the
    /// graph's geodesic distances). Defaults to an error naming the method.
    fn fit_knn(&self, graph: &KnnGraph, progress: &dyn Progress) -> Result<Embedded, EmbedError> {
        let _ = (graph, progress);
        Err(EmbedError::Knn(format!(
            "the {} method embeds a distance matrix, not a kNN graph; give the matrix, or a method that reads a graph (isomap)",
            self.name()
        )))
    }

    /// Bytes the method works in to embed `points` points, besides the distance matrix
    /// it is given, for the run's memory estimate. Defaults to the size of that matrix
    /// again (one working copy).
    fn working_bytes(&self, points: usize) -> u64 {
        square_bytes(points as u64)
    }

    /// What lowers [`working_bytes`](Embedding::working_bytes), for the message of a
    /// run that would not fit.
    fn memory_fix(&self) -> &'static str {
        "lower exploration.n (M)"
    }
}

/// Bytes of an `m × m` float64 matrix (saturating).
pub fn square_bytes(m: u64) -> u64 {
    m.saturating_mul(m).saturating_mul(8)
}

/// Bytes classical MDS works in on `m` points (the centred matrix and the
/// eigensolver's workspace: four matrices up to 1000 points, two beyond).
pub fn mds_bytes(m: u64) -> u64 {
    let factor = if m <= 1000 { 4 } else { 2 };
    square_bytes(m).saturating_mul(factor)
}

/// The `[embedding]` table: the method's name in an [`EmbeddingRegistry`] and its
/// parameters (the rest of the table), as in configuration files:
/// `{"method": "cca", "dim": 3, "epochs": 50}`.
///
/// ```
/// use smspace::embed::{CcaParams, EmbedParams};
/// let p: EmbedParams = toml::from_str("method = \"isomap\"\nk = 12").unwrap();
/// assert_eq!((p.method.as_str(), p.params["k"].as_integer()), ("isomap", Some(12)));
/// let cca = EmbedParams::from(CcaParams::default().epochs(7));
/// assert_eq!(cca.method, "cca");
/// assert_eq!(cca.build()?.name(), "cca");
/// # Ok::<(), smspace::embed::EmbedError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct EmbedParams {
    /// The method's name (`cca`, `isomap`, `mds`, or a registered one).
    pub method: String,
    /// Its parameters.
    pub params: toml::Table,
}

impl Default for EmbedParams {
    /// CCA, the paper's method, with its defaults.
    fn default() -> Self {
        Self::from(CcaParams::default())
    }
}

impl EmbedParams {
    /// The parameters of `method` given as a serde struct (e.g. [`CcaParams`]).
    pub fn of<P: Serialize>(method: &str, params: &P) -> Self {
        Self {
            method: method.to_owned(),
            params: crate::registry::table_of(params).unwrap_or_default(),
        }
    }

    /// Checks the parameters and returns the method, ready to fit (a built-in one).
    pub fn build(&self) -> Result<Box<dyn Embedding>, EmbedError> {
        self.build_with(&EmbeddingRegistry::builtin())
    }

    /// The method, from `registry`.
    pub fn build_with(
        &self,
        registry: &EmbeddingRegistry,
    ) -> Result<Box<dyn Embedding>, EmbedError> {
        Ok(registry.make(&self.method, &self.params, &())?.0)
    }

    /// The same table with every parameter, defaults included, and the method built
    /// from `registry`.
    pub fn resolve(
        &self,
        registry: &EmbeddingRegistry,
    ) -> Result<(Self, Box<dyn Embedding>), EmbedError> {
        let (method, params) = registry.make(&self.method, &self.params, &())?;
        let resolved = Self {
            method: self.method.clone(),
            params,
        };
        Ok((resolved, method))
    }
}

impl From<CcaParams> for EmbedParams {
    fn from(params: CcaParams) -> Self {
        Self::of("cca", &params)
    }
}

impl From<IsomapParams> for EmbedParams {
    fn from(params: IsomapParams) -> Self {
        Self::of("isomap", &params)
    }
}

impl From<MdsParams> for EmbedParams {
    fn from(params: MdsParams) -> Self {
        Self::of("mds", &params)
    }
}

impl Serialize for EmbedParams {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = serializer.serialize_map(Some(self.params.len() + 1))?;
        map.serialize_entry("method", &self.method)?;
        for (key, value) in self.params.iter().filter(|(k, _)| *k != "method") {
            map.serialize_entry(key, value)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for EmbedParams {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let mut params = toml::Table::deserialize(deserializer)?;
        let method = match params.remove("method") {
            Some(toml::Value::String(name)) => name,
            Some(other) => {
                return Err(serde::de::Error::custom(format!(
                    "method must be a name (cca, isomap, mds), got {other}"
                )))
            }
            None => return Err(serde::de::Error::missing_field("method")),
        };
        Ok(Self { method, params })
    }
}

impl CheckParams for EmbedParams {
    type Valid = Box<dyn Embedding>;
    type Error = EmbedError;
    fn check_params(&self) -> Result<Box<dyn Embedding>, EmbedError> {
        self.build()
    }
}

impl CheckParams for CcaParams {
    type Valid = CcaValidParams;
    type Error = EmbedError;
    fn check_params(&self) -> Result<CcaValidParams, EmbedError> {
        self.clone().check()
    }
}

impl CheckParams for IsomapParams {
    type Valid = IsomapValidParams;
    type Error = EmbedError;
    fn check_params(&self) -> Result<IsomapValidParams, EmbedError> {
        self.clone().check()
    }
}

impl CheckParams for MdsParams {
    type Valid = MdsValidParams;
    type Error = EmbedError;
    fn check_params(&self) -> Result<MdsValidParams, EmbedError> {
        self.clone().check()
    }
}

/// A fitted embedding: the coordinates, the method's diagnostics, and what is needed to
/// place new points ([`Embedded::extend`]).
#[derive(Debug, Clone)]
pub struct Embedded {
    /// Coordinates `(M, d)`.
    pub coordinates: Array2<f64>,
    /// The method's diagnostics.
    pub report: EmbedReport,
    pub(crate) extender: Extender,
}

/// Diagnostics of a fit, written to `*.embed.json` (inside an [`EmbedFile`]).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct EmbedReport {
    /// The method's name.
    pub method: String,
    /// Number of points `M`.
    pub points: usize,
    /// Output dimension `d`.
    pub dim: usize,
    /// CCA: the stress `½ Σ_{i≠j} (X_ij − Y_ij)² F(Y_ij, λ)` accumulated during each epoch
    /// (each pair measured when its pivot passes, before the move; λ of that step).
    /// Empty for the other methods.
    pub stress_trace: Vec<f64>,
    /// CCA: the final neighbourhood width λ (used by the out-of-sample extension).
    pub lambda_end: Option<f64>,
    /// Eigenvalues of the double-centred matrix `B` found by the solver, in decreasing
    /// order (all `M` for the dense solver, the largest in magnitude for the partial
    /// one; negative ones included). For CCA: those of its MDS initial layout (of the
    /// landmark block when the layout came from landmark MDS).
    pub eigenvalues: Vec<f64>,
    /// `trace(B) = Σ` of all eigenvalues, so that `eigenvalues[..d].sum() / trace`
    /// is the share of the (signed) total that the embedding keeps.
    pub eigenvalue_trace: Option<f64>,
    /// Isomap: the landmark indices (empty for exact Isomap).
    pub landmarks: Vec<usize>,
    /// Isomap: neighbours per point in the graph.
    pub k: Option<usize>,
}

/// The embedding report written next to the coordinates (`<stem>.embed.json`): the same
/// fields whether `smspace embed` or `smspace run` wrote it.
///
/// The [`EmbedReport`] fields (`method`, `points`, `dim`, `stress_trace`, `eigenvalues`,
/// …) sit at the top level of the JSON object, beside the others.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct EmbedFile {
    /// What the method reports.
    #[serde(flatten)]
    pub report: EmbedReport,
    /// The method's parameters, defaults included (`method` names the method).
    pub params: serde_json::Value,
    /// Where the input came from: `{"distances": path}` or
    /// `{"knn_indices": path, "knn_distances": path}`.
    pub input: serde_json::Value,
    /// Trustworthiness, continuity and stress ([`quality::assess`]); `null` without a
    /// distance matrix or with too few points.
    pub quality: Option<quality::Quality>,
    /// The dy–dx sample ([`quality::shepard_pairs`]), if one was written.
    pub dydx: Option<DydxSample>,
    /// Points placed out of sample ([`Embedded::extend`]), if any.
    pub extended: Option<ExtendedPoints>,
    /// Wall-clock seconds of the command (`smspace embed` only; the pipeline keeps its
    /// timings in `manifest.json`, so that its outputs do not change between runs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
}

impl EmbedFile {
    /// Writes an embedding: `coordinates` `(M, d)` to `y_path`, the dy–dx sample (when
    /// given) to `<stem>.dydx.npy` and this report to `<stem>.embed.json`, with its
    /// `dydx` field naming the sample file (relative to the report). Returns the paths
    /// written. `smspace embed` and the pipeline's embed stage both write through here.
    pub fn write(
        self,
        y_path: &std::path::Path,
        coordinates: ArrayView2<'_, f64>,
        dydx: Option<ArrayView2<'_, f64>>,
    ) -> Result<Vec<std::path::PathBuf>, crate::io::IoError> {
        // All files or none (see `io::Outputs`).
        let mut outputs = crate::io::Outputs::new();
        self.write_into(&mut outputs, y_path, coordinates, dydx)?;
        outputs.commit()
    }

    /// Stages the files of [`write`](Self::write) into `outputs`, to be renamed into
    /// place with the other files of a command or stage.
    pub fn write_into(
        mut self,
        outputs: &mut crate::io::Outputs,
        y_path: &std::path::Path,
        coordinates: ArrayView2<'_, f64>,
        dydx: Option<ArrayView2<'_, f64>>,
    ) -> Result<(), crate::io::IoError> {
        outputs.npy(y_path, &coordinates)?;
        self.dydx = match dydx {
            Some(pairs) => {
                let path = crate::io::sibling(y_path, "dydx.npy");
                outputs.npy(&path, &pairs)?;
                let name = path.file_name().map(std::path::PathBuf::from);
                Some(DydxSample::new(
                    name.unwrap_or_default(),
                    pairs.nrows(),
                    coordinates.nrows(),
                ))
            }
            None => None,
        };
        let report = crate::io::sibling(y_path, "embed.json");
        outputs.json(&report, &self)
    }
}

/// The dy–dx sample file, as described in [`EmbedFile`].
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct DydxSample {
    /// The `.npy` file of shape `(pairs, 2)`.
    pub file: std::path::PathBuf,
    /// Number of pairs.
    pub pairs: usize,
    /// What the two columns hold.
    pub columns: [String; 2],
    /// How the pairs were chosen.
    pub sampling: String,
}

impl DydxSample {
    /// Describes `pairs` rows written to `file` out of the `points (points − 1) / 2`
    /// pairs of an embedding of `points` points (all of them, or a seeded uniform sample).
    pub fn new(file: impl Into<std::path::PathBuf>, pairs: usize, points: usize) -> Self {
        let all = pairs == points * points.saturating_sub(1) / 2;
        Self {
            file: file.into(),
            pairs,
            columns: [
                "dx (input distance X_ij)".to_owned(),
                "dy (output distance Y_ij)".to_owned(),
            ],
            sampling: if all {
                "all pairs i < j".to_owned()
            } else {
                "uniform random pairs i != j, seeded".to_owned()
            },
        }
    }
}

/// Points placed out of sample, as described in [`EmbedFile`].
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ExtendedPoints {
    /// The `(N, M)` distances from the new points to the embedded ones.
    pub from: std::path::PathBuf,
    /// The `(N, d)` coordinates written.
    pub file: std::path::PathBuf,
    /// Number of points placed `N`.
    pub points: usize,
}

/// What an [`Embedded`] keeps to place new points.
#[derive(Debug, Clone)]
pub(crate) enum Extender {
    /// CCA: descend the stress of each new point against the fixed old ones.
    Cca(cca::CcaExtender),
    /// Distance-based triangulation (de Silva & Tenenbaum 2003) on landmarks, from
    /// direct (MDS) or geodesic (Isomap) distances.
    Triangulation(Box<eigen::Triangulation>),
}

impl Embedded {
    /// Number of embedded points `M`.
    pub fn points(&self) -> usize {
        self.coordinates.nrows()
    }

    /// Places new points given their distances `new_to_old` `(N, M)` to the embedded
    /// ones, without moving the embedded points. Returns `(N, d)` coordinates.
    ///
    /// CCA minimises each new point's CCA stress against the fixed layout, starting from
    /// its nearest old points; MDS and Isomap use landmark triangulation (for Isomap on
    /// geodesic distances through the new point's `k` nearest old points).
    ///
    /// `new_to_old` may have any layout or strides.
    pub fn extend(&self, new_to_old: ArrayView2<'_, f64>) -> Result<Array2<f64>, EmbedError> {
        let new_to_old = new_to_old.as_standard_layout();
        let new_to_old = new_to_old.view();
        let points = self.points();
        if new_to_old.ncols() != points {
            return Err(EmbedError::ExtendShape {
                rows: new_to_old.nrows(),
                cols: new_to_old.ncols(),
                points,
            });
        }
        if let Some(((i, j), &value)) = new_to_old
            .indexed_iter()
            .find(|(_, v)| !v.is_finite() || **v < 0.0)
        {
            return Err(EmbedError::ExtendValue { i, j, value });
        }
        Ok(match &self.extender {
            Extender::Cca(e) => e.extend(self.coordinates.view(), new_to_old),
            Extender::Triangulation(t) => t.extend(new_to_old),
        })
    }
}

/// Validates a distance matrix view (any layout): square, finite, non-negative, zero
/// diagonal and symmetric within [`SYMMETRY_TOLERANCE`](crate::metric::SYMMETRY_TOLERANCE)
/// (see [`DistanceMatrix`], which every entry point takes).
pub fn check_distances(distances: ArrayView2<'_, f64>) -> Result<(), EmbedError> {
    DistanceMatrix::from_view(distances)?;
    Ok(())
}

/// What to do about [`EmbedError::DimTooLarge`]: a dimension in range, or more points.
fn dim_advice(points: usize) -> String {
    if points < 2 {
        "an embedding needs at least 2 points (sets); explore more configurations".into()
    } else {
        format!("use a dimension between 1 and {}", points - 1)
    }
}

/// Checks `1 ≤ dim < points`.
pub(crate) fn check_dim(dim: usize, points: usize) -> Result<(), EmbedError> {
    if dim == 0 || dim >= points {
        return Err(EmbedError::DimTooLarge { dim, points });
    }
    Ok(())
}

/// Checks `dim ≥ 1` at parameter-check time (before the size is known).
pub(crate) fn check_dim_param(dim: usize) -> Result<(), EmbedError> {
    if dim == 0 {
        return Err(InvalidParameter::new("embedding", "dim", 0, "at least 1").into());
    }
    Ok(())
}
