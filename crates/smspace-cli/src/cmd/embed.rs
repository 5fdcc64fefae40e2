//! `smspace embed`: coordinates `(M, d)` for a distance matrix, by CCA (the paper's),
//! Isomap or classical MDS.
//!
//! Writes, next to `--out Y.npy`:
//!
//! | file | content |
//! |---|---|
//! | `Y.npy` | `(M, d)` float64 coordinates |
//! | `Y.embed.json` | [`smspace::embed::EmbedFile`], the same fields as `smspace run` writes: the fit report (method, stress trace, eigenvalues, …), parameters, input, quality (trustworthiness, continuity, stress), the dy–dx and extension files, seconds |
//! | `Y.dydx.npy` | `(P, 2)` float64 Shepard sample: columns `dx = X_ij`, `dy = Y_ij` for `P` seeded random pairs `i < j` (all pairs when there are fewer than `--dydx-pairs`), for the `dy–dx` plot |
//! | `Y.extended.npy` | with `--extend N.npy`: `(N, d)` coordinates of the new points |

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context};
use clap::ValueEnum;
use serde_json::json;
use smspace::embed::quality::measure;
use smspace::embed::{
    CcaParams, EmbedFile, EmbedParams, Embedded, ExtendedPoints, IsomapParams, KnnGraph,
    LandmarkChoice, MdsParams, Neighbourhood,
};
use smspace::io::{read_matrix, write_npy};
use smspace::metric::DistanceMatrix;

use super::common::sibling;
use crate::ui;

/// The embedding method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Curvilinear Component Analysis (Demartines & Hérault 1997), the paper's.
    Cca,
    /// Isomap (exact, or landmark with --landmarks).
    Isomap,
    /// Classical (Torgerson) MDS.
    Mds,
}

/// CCA's neighbourhood function.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum NeighbourhoodArg {
    /// F = 1 if Y ≤ λ else 0 (the original paper).
    Step,
    /// F = exp(−Y/λ) (SOM Toolbox).
    Exp,
}

/// Landmark choice of landmark Isomap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LandmarkArg {
    /// Farthest-point (MaxMin) landmarks.
    Maxmin,
    /// Uniformly random landmarks.
    Random,
}

/// Embed a distance matrix in `--dim` dimensions.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Distance matrix, (M, M) float64 .npy (symmetric, zero diagonal).
    #[arg(long, value_name = "D.npy", required_unless_present = "knn_indices")]
    pub distances: Option<PathBuf>,
    /// Isomap from a kNN graph instead of a dense matrix: (M, K) int64 neighbour indices
    /// (row i: the K nearest other sets of set i, nearest first).
    #[arg(
        long,
        value_name = "knn_indices.npy",
        requires = "knn_distances",
        conflicts_with = "distances"
    )]
    pub knn_indices: Option<PathBuf>,
    /// The matching (M, K) float64 neighbour distances.
    #[arg(long, value_name = "knn_distances.npy", requires = "knn_indices")]
    pub knn_distances: Option<PathBuf>,
    /// Embedding method.
    #[arg(long, value_enum, default_value_t = Method::Cca)]
    pub method: Method,
    /// Output dimension.
    #[arg(long, default_value_t = CcaParams::default().dim)]
    pub dim: usize,
    /// Seed (CCA pivot order, landmarks, eigensolver start vector, dy–dx sample).
    #[arg(long, default_value_t = CcaParams::default().seed)]
    pub seed: u64,
    /// Output coordinates (M, dim) .npy; the report goes to <stem>.embed.json.
    #[arg(long, value_name = "Y.npy")]
    pub out: PathBuf,
    /// New points to place without re-running the embedding: (N, M) float64 distances
    /// from each new set to the M embedded ones; written to <stem>.extended.npy.
    #[arg(long, value_name = "new_to_old.npy")]
    pub extend: Option<PathBuf>,
    /// CCA: epochs (default 50).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// CCA: neighbourhood function (default step).
    #[arg(long, value_enum)]
    pub neighbourhood: Option<NeighbourhoodArg>,
    /// CCA: final neighbourhood width λ (default: the 1 % quantile of the distances).
    #[arg(long, value_name = "LAMBDA")]
    pub lambda_end: Option<f64>,
    /// Isomap: neighbours per point (default 10).
    #[arg(long)]
    pub k: Option<usize>,
    /// Isomap: use landmark Isomap with this many landmarks (default: exact Isomap).
    #[arg(long, value_name = "L")]
    pub landmarks: Option<usize>,
    /// Isomap: how landmarks are chosen (default maxmin).
    #[arg(long, value_enum)]
    pub landmark_choice: Option<LandmarkArg>,
    /// Neighbourhood size of trustworthiness and continuity (capped below M/2).
    #[arg(long, default_value_t = smspace_pipeline::stages::QUALITY_NEIGHBOURS)]
    pub quality_k: usize,
    /// Most (dx, dy) pairs written to <stem>.dydx.npy (0: none).
    #[arg(long, default_value_t = smspace_pipeline::stages::DYDX_PAIRS)]
    pub dydx_pairs: usize,
}

impl Args {
    /// The parameters of `--method isomap`.
    fn isomap_params(&self) -> IsomapParams {
        let d = IsomapParams::default();
        IsomapParams {
            dim: self.dim,
            seed: self.seed,
            k: self.k.unwrap_or(d.k),
            landmarks: self.landmarks,
            landmark_choice: match self.landmark_choice {
                Some(LandmarkArg::Random) => LandmarkChoice::Random,
                Some(LandmarkArg::Maxmin) => LandmarkChoice::MaxMin,
                None => d.landmark_choice,
            },
            ..d
        }
    }

    /// The method's parameters, refusing options that belong to another method.
    fn params(&self) -> anyhow::Result<EmbedParams> {
        let cca_only =
            self.epochs.is_some() || self.neighbourhood.is_some() || self.lambda_end.is_some();
        let isomap_only =
            self.k.is_some() || self.landmarks.is_some() || self.landmark_choice.is_some();
        if cca_only && self.method != Method::Cca {
            bail!("--epochs, --neighbourhood and --lambda-end apply to --method cca only");
        }
        if isomap_only && self.method != Method::Isomap {
            bail!("--k, --landmarks and --landmark-choice apply to --method isomap only");
        }
        if self.knn_indices.is_some() && self.method != Method::Isomap {
            bail!("a kNN graph (--knn-indices/--knn-distances) can only be embedded with --method isomap; give --distances for {:?}", self.method);
        }
        Ok(match self.method {
            Method::Cca => {
                let d = CcaParams::default();
                EmbedParams::from(CcaParams {
                    dim: self.dim,
                    seed: self.seed,
                    epochs: self.epochs.unwrap_or(d.epochs),
                    neighbourhood: match self.neighbourhood {
                        Some(NeighbourhoodArg::Exp) => Neighbourhood::Exp,
                        Some(NeighbourhoodArg::Step) => Neighbourhood::Step,
                        None => d.neighbourhood,
                    },
                    lambda_end: self.lambda_end,
                    ..d
                })
            }
            Method::Isomap => EmbedParams::from(self.isomap_params()),
            Method::Mds => EmbedParams::from(MdsParams {
                dim: self.dim,
                seed: self.seed,
                ..MdsParams::default()
            }),
        })
    }
}

/// Runs `smspace embed`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let started = Instant::now();
    super::common::spare_inputs(
        &[&args.out, &sibling(&args.out, "extended.npy")],
        &[
            ("--distances", args.distances.as_deref()),
            ("--knn-indices", args.knn_indices.as_deref()),
            ("--knn-distances", args.knn_distances.as_deref()),
            ("--extend", args.extend.as_deref()),
        ],
    )?;
    let params = args.params()?;
    let params_json = serde_json::to_value(&params).context("cannot describe the parameters")?;
    let bar = ui::Bar::new();
    let (embedded, distances, input): (Embedded, Option<_>, _) =
        match (&args.distances, &args.knn_indices, &args.knn_distances) {
            (Some(path), _, _) => {
                let d = DistanceMatrix::load(path)?;
                let method = params.build()?;
                let e = method
                    .fit(&d, &bar)
                    .with_context(|| format!("cannot embed {}", path.display()))?;
                (e, Some(d), json!({ "distances": path }))
            }
            (None, Some(ip), Some(dp)) => {
                let graph = KnnGraph::read(ip, dp)?;
                // Only Isomap embeds a graph (checked in Args::params).
                let e = args
                    .isomap_params()
                    .check()?
                    .fit_knn(&graph, &bar)
                    .with_context(|| format!("cannot embed the kNN graph {}", ip.display()))?;
                (e, None, json!({ "knn_indices": ip, "knn_distances": dp }))
            }
            _ => bail!("give --distances D.npy, or --knn-indices and --knn-distances"),
        };
    let m = embedded.points();
    // The same measures as the pipeline's embed stage.
    let (quality, dydx) = match &distances {
        Some(d) => measure(
            d.view(),
            embedded.coordinates.view(),
            args.quality_k,
            args.dydx_pairs,
            args.seed,
        )?,
        None => (None, None),
    };

    let mut extended = None;
    if let Some(path) = &args.extend {
        let new_to_old = read_matrix(path, Some(m), &format!("(N, {m})"))?;
        let placed = embedded
            .extend(new_to_old.view())
            .with_context(|| format!("cannot place the points of {}", path.display()))?;
        let out = sibling(&args.out, "extended.npy");
        write_npy(&out, &placed)?;
        extended = Some(ExtendedPoints {
            from: path.clone(),
            file: out,
            points: placed.nrows(),
        });
    }

    let report = EmbedFile {
        report: embedded.report,
        params: params_json,
        input,
        quality,
        dydx: None,
        extended,
        seconds: Some(started.elapsed().as_secs_f64()),
    };
    // One writer for Y.npy, Y.dydx.npy and Y.embed.json: the pipeline's.
    let written = report.clone().write(
        &args.out,
        embedded.coordinates.view(),
        dydx.as_ref().map(|d| d.view()),
    )?;
    let report_path = written.last().cloned().unwrap_or_default();
    let quality_line = match &report.quality {
        Some(q) => format!(
            "; trustworthiness {:.4}, continuity {:.4}",
            q.trustworthiness, q.continuity
        ),
        None => String::new(),
    };
    eprintln!(
        "embedded {} points in {} dimensions with {} into {} (report {}){quality_line}",
        report.report.points,
        report.report.dim,
        report.report.method,
        args.out.display(),
        report_path.display()
    );
    Ok(())
}
