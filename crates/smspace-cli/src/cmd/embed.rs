//! `smspace embed`: coordinates `(M, d)` for a distance matrix, by any registered
//! embedding method (CCA, the paper's; Isomap; classical MDS): `--method NAME` picks
//! it from the library's `EmbeddingRegistry` and its parameters are its
//! `[embedding]` table's, given as `--param KEY=VALUE` or by the flags below.
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
    EmbedFile, EmbedParams, Embedded, EmbeddingRegistry, ExtendedPoints, KnnGraph, LandmarkChoice,
    Neighbourhood,
};
use smspace::io::{read_matrix, write_npy};
use smspace::metric::DistanceMatrix;

use super::common::{parse_param, sibling};
use crate::ui;

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
    /// Embedding method: a registered one (cca, the paper's Curvilinear Component
    /// Analysis; isomap, exact or landmark with --landmarks; mds, classical MDS). An
    /// unknown name lists them.
    #[arg(long, value_name = "NAME", default_value_t = EmbedParams::default().method)]
    pub method: String,
    /// A parameter of the method, as in an experiment's [embedding] table, the value
    /// in TOML (e.g. --param epochs=80 --param alpha_start=0.3); repeat for more.
    /// Parameters the method does not have are errors that name them.
    #[arg(long = "param", value_name = "KEY=VALUE", value_parser = parse_param)]
    pub params: Vec<(String, toml::Value)>,
    /// Output dimension (default: the method's, 3 for the built-in ones).
    #[arg(long)]
    pub dim: Option<usize>,
    /// Seed (CCA pivot order, landmarks, eigensolver start vector, dy–dx sample;
    /// default: the method's, 0 for the built-in ones).
    #[arg(long)]
    pub seed: Option<u64>,
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

/// A flag's value as the TOML of its parameter (numbers, and the names the
/// parameters' enums are written with).
macro_rules! value {
    ($v:expr) => {
        toml::Value::try_from($v).unwrap_or_else(|_| toml::Value::String(String::new()))
    };
}

impl Args {
    /// The method's `[embedding]` table: the `--param`s and the flags that set its
    /// keys (a key given twice is an error), resolved through the library's registry.
    /// A flag the method has no parameter for names the methods that have one.
    fn params(&self, registry: &EmbeddingRegistry) -> anyhow::Result<EmbedParams> {
        let flags: [(&str, &str, Option<toml::Value>); 8] = [
            ("--dim", "dim", self.dim.map(|d| value!(&d))),
            ("--seed", "seed", self.seed.map(|s| value!(&s))),
            ("--epochs", "epochs", self.epochs.map(|e| value!(&e))),
            (
                "--neighbourhood",
                "neighbourhood",
                self.neighbourhood.map(|n| value!(&Neighbourhood::from(n))),
            ),
            (
                "--lambda-end",
                "lambda_end",
                self.lambda_end.map(|l| value!(&l)),
            ),
            ("--k", "k", self.k.map(|k| value!(&k))),
            (
                "--landmarks",
                "landmarks",
                self.landmarks.map(|l| value!(&l)),
            ),
            (
                "--landmark-choice",
                "landmark_choice",
                self.landmark_choice
                    .map(|c| value!(&LandmarkChoice::from(c))),
            ),
        ];
        let mut table: toml::Table = toml::Table::new();
        for (key, v) in &self.params {
            anyhow::ensure!(
                key != "method",
                "--param method=…: the method is --method NAME"
            );
            if table.insert(key.clone(), v.clone()).is_some() {
                bail!("--param {key} is given twice");
            }
        }
        anyhow::ensure!(
            registry.contains(&self.method),
            "unknown embedding method '{}'; the registered methods are {}",
            self.method,
            registry.names().collect::<Vec<_>>().join(", ")
        );
        for (flag, key, v) in flags {
            let Some(v) = v else { continue };
            if table.contains_key(key) {
                bail!("{flag} and --param {key}=… both set {key}; give one");
            }
            if !accepts(registry, &self.method, key, &v) {
                let with: Vec<&str> = registry
                    .names()
                    .filter(|name| accepts(registry, name, key, &v))
                    .collect();
                bail!(
                    "{flag} applies to --method {} only (a method with the parameter {key}); --method {} has none",
                    if with.is_empty() { "(none registered)".to_owned() } else { with.join(" or ") },
                    self.method
                );
            }
            table.insert(key.to_owned(), v);
        }
        Ok(EmbedParams {
            method: self.method.clone(),
            params: table,
        })
    }
}

/// Whether the method `name` has the parameter `key` (for a value like `value`): its
/// own reader of a table refuses no `key` as unknown.
fn accepts(registry: &EmbeddingRegistry, name: &str, key: &str, value: &toml::Value) -> bool {
    let mut table = toml::Table::new();
    table.insert(key.to_owned(), value.clone());
    let mut document = toml::Table::new();
    document.insert("t".to_owned(), toml::Value::Table(table));
    let text = toml::to_string(&document).unwrap_or_default();
    match registry.read_error(name, &text) {
        Some(error) => !error.message().contains("unknown field"),
        None => true,
    }
}

impl From<NeighbourhoodArg> for Neighbourhood {
    fn from(arg: NeighbourhoodArg) -> Self {
        match arg {
            NeighbourhoodArg::Step => Neighbourhood::Step,
            NeighbourhoodArg::Exp => Neighbourhood::Exp,
        }
    }
}

impl From<LandmarkArg> for LandmarkChoice {
    fn from(arg: LandmarkArg) -> Self {
        match arg {
            LandmarkArg::Maxmin => LandmarkChoice::MaxMin,
            LandmarkArg::Random => LandmarkChoice::Random,
        }
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
    let registry = EmbeddingRegistry::builtin();
    let (params, method) = args
        .params(&registry)?
        .resolve(&registry)
        .context("--method and its parameters")?;
    let params_json = serde_json::to_value(&params).context("cannot describe the parameters")?;
    // The dy–dx sample's seed: --seed, else the method's.
    let seed = args
        .seed
        .or_else(|| params.params.get("seed")?.as_integer()?.try_into().ok())
        .unwrap_or_default();
    let bar = ui::Bar::new();
    let (embedded, distances, input): (Embedded, Option<_>, _) =
        match (&args.distances, &args.knn_indices, &args.knn_distances) {
            (Some(path), _, _) => {
                let d = DistanceMatrix::load(path)?;
                let e = method
                    .fit(&d, &bar)
                    .with_context(|| format!("cannot embed {}", path.display()))?;
                (e, Some(d), json!({ "distances": path }))
            }
            (None, Some(ip), Some(dp)) => {
                let graph = KnnGraph::read(ip, dp)?;
                let e = method
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
            seed,
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
