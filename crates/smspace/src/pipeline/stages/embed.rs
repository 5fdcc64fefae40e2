//! `embed`: coordinates of the manifold of sets from its distance matrix (paper
//! section 3.2, step 4), with the embedding's quality against `D` and the `dy–dx`
//! sample of CCA.

use std::path::Path;

use ndarray::Array2;
use serde::Serialize;

use super::{Keyed, Stage, StageContext, StageInput};
use crate::embed::quality::{measure, Quality};
use crate::embed::{EmbedFile, EmbedParams, EmbedReport};
use crate::io::{self, Outputs};
use crate::metric::DistanceMatrix;
use crate::pipeline::StageId;

/// Pairs of `(dx, dy)` sampled for the CCA `dy–dx` plot (the default of `smspace
/// embed --dydx-pairs` too).
pub const DYDX_PAIRS: usize = 20_000;
/// Neighbours of the embedding's trustworthiness and continuity against `D` (the
/// default of `smspace embed --quality-k` too).
pub const QUALITY_NEIGHBOURS: usize = 10;

/// The `embed` stage: the `[embedding]` table, and the figures computed with the
/// embedding (their seed is `[report] seed`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EmbedStage {
    /// The embedding method and its parameters.
    pub embedding: EmbedParams,
    /// Neighbours of trustworthiness and continuity against `D` (capped below `M/2`).
    pub quality_neighbours: usize,
    /// Most `(dx, dy)` pairs of the Shepard sample.
    pub dydx_pairs: usize,
    /// Seed of the Shepard sample.
    pub dydx_seed: u64,
}

/// What `embed` reads.
#[derive(Debug, Clone, Copy)]
pub struct EmbedInput<'a> {
    /// The `(M, M)` distance matrix.
    pub distances: &'a Keyed<DistanceMatrix>,
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
        let distances = &input.distances.value;
        let fitted = self
            .embedding
            .clone()
            .build()?
            .fit(distances, context.progress)?;
        let (quality, dydx) = measure(
            distances.view(),
            fitted.coordinates.view(),
            self.quality_neighbours,
            self.dydx_pairs,
            self.dydx_seed,
        )?;
        Ok(EmbedOutputs {
            coordinates: fitted.coordinates,
            report: fitted.report,
            quality,
            dydx: dydx.unwrap_or_else(|| Array2::zeros((0, 2))),
        })
    }

    fn save(
        &self,
        _: &EmbedInput<'_>,
        y: &EmbedOutputs,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        // The method's own parameters, as `smspace embed` writes them.
        let params = self.embedding.clone().build()?.params_json();
        let file = EmbedFile {
            report: y.report.clone(),
            params,
            input: serde_json::json!({ "distances": "D.npy" }),
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
        let m = input.distances.len();
        let coordinates = io::read_matrix(&dir.join(COORDINATES_FILE), None, "(M, d)")?;
        if coordinates.nrows() != m {
            return Err(io::IoError::Shape {
                path: dir.join(COORDINATES_FILE),
                found: io::shape_string(coordinates.shape()),
                expected: format!("({m}, d), one row per row of D.npy"),
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
