//! `embed`: coordinates of the manifold of sets from its distance matrix (paper
//! section 3.2, step 4), with the embedding's quality against `D` and the `dy–dx`
//! sample of CCA. On the landmark path ([`crate::scale`]) the method is
//! fitted on the landmarks and every other set placed out of sample
//! ([`smspace::embed::landmarks`]); the quality and the `dy–dx` sample are then those of
//! the landmarks' fit against their `L × L` matrix (said in `Y.embed.json`'s `input`).

use std::path::Path;
use std::sync::Arc;

use ndarray::Array2;
use serde::Serialize;

use super::{Keyed, SetDistances, Stage, StageContext, StageInput};
use crate::manifest::StageId;
use smspace::embed::landmarks::fit_on_landmarks;
use smspace::embed::quality::{measure, Quality};
use smspace::embed::{EmbedFile, EmbedParams, EmbedReport, Embedding};
use smspace::io::{self, Outputs};

/// Pairs of `(dx, dy)` sampled for the CCA `dy–dx` plot (the default of `smspace
/// embed --dydx-pairs` too).
pub const DYDX_PAIRS: usize = 20_000;
/// Neighbours of the embedding's trustworthiness and continuity against `D` (the
/// default of `smspace embed --quality-k` too).
pub const QUALITY_NEIGHBOURS: usize = 10;

/// The `embed` stage: the `[embedding]` table (resolved: every parameter), the method
/// it builds (built-in or registered, [`smspace::embed::EmbeddingRegistry`]), and the
/// figures computed with the embedding (their seed is `[report] seed`).
#[derive(Debug, Clone, Serialize)]
pub struct EmbedStage {
    /// The embedding method and its parameters.
    pub embedding: EmbedParams,
    /// Neighbours of trustworthiness and continuity against `D` (capped below `M/2`).
    pub quality_neighbours: usize,
    /// Most `(dx, dy)` pairs of the Shepard sample.
    pub dydx_pairs: usize,
    /// Seed of the Shepard sample.
    pub dydx_seed: u64,
    /// The method built from `embedding`.
    #[serde(skip)]
    method: Arc<dyn Embedding>,
}

impl PartialEq for EmbedStage {
    /// Stages are equal when their keyed fields are (the method is built from them).
    fn eq(&self, other: &Self) -> bool {
        (
            &self.embedding,
            self.quality_neighbours,
            self.dydx_pairs,
            self.dydx_seed,
        ) == (
            &other.embedding,
            other.quality_neighbours,
            other.dydx_pairs,
            other.dydx_seed,
        )
    }
}

impl EmbedStage {
    /// The stage of `method`, built from `embedding`, with the default figures.
    pub fn new(embedding: EmbedParams, method: Arc<dyn Embedding>) -> Self {
        Self {
            embedding,
            quality_neighbours: QUALITY_NEIGHBOURS,
            dydx_pairs: DYDX_PAIRS,
            dydx_seed: 0,
            method,
        }
    }

    /// The same stage with the figures' neighbours, pairs and seed.
    pub fn with_figures(self, quality_neighbours: usize, dydx_pairs: usize, seed: u64) -> Self {
        Self {
            quality_neighbours,
            dydx_pairs,
            dydx_seed: seed,
            ..self
        }
    }

    /// The embedding method.
    pub fn method(&self) -> &dyn Embedding {
        self.method.as_ref()
    }
}

/// What `embed` reads.
#[derive(Debug, Clone, Copy)]
pub struct EmbedInput<'a> {
    /// The `(M, M)` distance matrix, or the landmarks.
    pub distances: &'a Keyed<SetDistances>,
}

impl StageInput for EmbedInput<'_> {
    fn keys(&self) -> Vec<&str> {
        vec![&self.distances.key]
    }
}

/// What the embed stage produces.
#[derive(Debug, Clone, PartialEq)]
pub struct EmbedOutputs {
    /// `(M, d)` coordinates.
    pub coordinates: Array2<f64>,
    /// The method's report.
    pub report: EmbedReport,
    /// Trustworthiness, continuity and stress against `D` (none below 3 points).
    pub quality: Option<Quality>,
    /// `(pairs, 2)` Shepard sample `(dx, dy)`.
    pub dydx: Array2<f64>,
}

const COORDINATES_FILE: &str = "Y.npy";
const DYDX_FILE: &str = "Y.dydx.npy";
const REPORT_FILE: &str = "Y.embed.json";

impl Stage for EmbedStage {
    const ID: StageId = StageId::Embed;
    type Input<'a> = EmbedInput<'a>;
    type Output = EmbedOutputs;

    fn compute(
        &self,
        input: &EmbedInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<EmbedOutputs> {
        let method = self.method();
        let (coordinates, report, quality, dydx) = match &input.distances.value {
            SetDistances::Dense(distances) => {
                let fitted = method.fit(distances, context.progress)?;
                let (quality, dydx) = measure(
                    distances.view(),
                    fitted.coordinates.view(),
                    self.quality_neighbours,
                    self.dydx_pairs,
                    self.dydx_seed,
                )?;
                (fitted.coordinates, fitted.report, quality, dydx)
            }
            SetDistances::Landmarks(graph) => {
                let l = &graph.landmarks;
                let fit = fit_on_landmarks(method, l, context.progress)?;
                // The landmarks' matrix in the fit's order (increasing set index).
                let mut order: Vec<usize> = (0..l.len()).collect();
                order.sort_unstable_by_key(|&a| l.rows[a]);
                let sorted = l.landmarks.view();
                let sorted = sorted
                    .select(ndarray::Axis(0), &order)
                    .select(ndarray::Axis(1), &order);
                let (quality, dydx) = measure(
                    sorted.view(),
                    fit.fitted.coordinates.view(),
                    self.quality_neighbours,
                    self.dydx_pairs,
                    self.dydx_seed,
                )?;
                let report = EmbedReport {
                    points: l.sets(),
                    ..fit.fitted.report
                };
                (fit.coordinates, report, quality, dydx)
            }
        };
        Ok(EmbedOutputs {
            coordinates,
            report,
            quality,
            dydx: dydx.unwrap_or_else(|| Array2::zeros((0, 2))),
        })
    }

    fn save(
        &self,
        input: &EmbedInput<'_>,
        y: &EmbedOutputs,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        // The method's own parameters, as `smspace embed` writes them.
        let params = self.method().params_json();
        let file = EmbedFile {
            report: y.report.clone(),
            params,
            input: match &input.distances.value {
                SetDistances::Dense(_) => serde_json::json!({ "distances": "D.npy" }),
                SetDistances::Landmarks(g) => serde_json::json!({
                    "landmarks": "D.landmarks.npy",
                    "nearest_landmarks": "landmarks.nearest.npy",
                    "nearest_landmark_distances": "D.nearest-landmarks.npy",
                    "fitted_on": format!("the {} landmarks (quality and dy-dx of their fit); every other set placed out of sample", g.landmarks.len()),
                }),
            },
            quality: y.quality,
            dydx: None,
            extended: None,
            seconds: None,
        };
        file.write_into(
            outputs,
            &dir.join(COORDINATES_FILE),
            y.coordinates.view(),
            Some(y.dydx.view()),
        )?;
        Ok(())
    }

    fn load(&self, input: &EmbedInput<'_>, dir: &Path) -> crate::Result<EmbedOutputs> {
        let file: EmbedFile = io::read_json(&dir.join(REPORT_FILE), "embedding report")?;
        let m = input.distances.sets();
        let coordinates = io::read_matrix(&dir.join(COORDINATES_FILE), None, "(M, d)")?;
        if coordinates.nrows() != m {
            return Err(io::IoError::Shape {
                path: dir.join(COORDINATES_FILE),
                found: io::shape_string(coordinates.shape()),
                expected: format!("({m}, d), one row per set"),
            }
            .into());
        }
        Ok(EmbedOutputs {
            coordinates,
            report: file.report,
            quality: file.quality,
            dydx: io::read_matrix(&dir.join(DYDX_FILE), Some(2), "(pairs, 2)")?,
        })
    }

    fn summary(&self, y: &EmbedOutputs) -> String {
        let quality = y
            .quality
            .map(|q| {
                format!(
                    "; trustworthiness {:.4}, continuity {:.4}",
                    q.trustworthiness, q.continuity
                )
            })
            .unwrap_or_default();
        format!(
            "{} points in {} dimensions with {}{quality}",
            y.report.points, y.report.dim, y.report.method
        )
    }
}
