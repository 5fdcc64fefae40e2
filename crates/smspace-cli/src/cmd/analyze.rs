//! `smspace analyze`: topology, intrinsic dimension and agreement with the poses of a
//! distance matrix between kernel sets.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use smspace::analysis::{analyze, AnalysisParams};
use smspace::io;
use smspace::metric::DistanceMatrix;

use crate::ui::Bar;

/// Arguments of `smspace analyze`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Distance matrix (M, M) between kernel sets.
    #[arg(long, value_name = "FILE")]
    distances: PathBuf,
    /// Observer's poses (M, 3) `(x, y, alpha)` of the same rows, for the agreement
    /// figures.
    #[arg(long, value_name = "FILE")]
    poses: Option<PathBuf>,
    /// Highest homology dimension (0, 1 or 2).
    #[arg(long, default_value_t = AnalysisParams::default().max_homology_dim)]
    max_dim: usize,
    /// Rips threshold (default: the enclosing radius, where every bar has died).
    #[arg(long, allow_negative_numbers = true)]
    threshold: Option<f64>,
    /// Homology of more points runs on this many max–min landmarks.
    #[arg(long, default_value_t = AnalysisParams::default().max_points)]
    max_points: usize,
    /// Neighbours of trustworthiness and continuity.
    #[arg(long, default_value_t = AnalysisParams::default().neighbors)]
    neighbors: usize,
    /// Neighbours of the Levina–Bickel dimension estimate.
    #[arg(long, default_value_t = AnalysisParams::default().mle_neighbors)]
    mle_neighbors: usize,
    /// Report (JSON); printed to standard output when not given.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

/// Runs `smspace analyze`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let params = AnalysisParams {
        max_homology_dim: args.max_dim,
        threshold: args.threshold,
        max_points: args.max_points,
        neighbors: args.neighbors,
        mle_neighbors: args.mle_neighbors,
        ..AnalysisParams::default()
    }
    .check()?;
    let distances = DistanceMatrix::load(&args.distances)?;
    let poses = match &args.poses {
        Some(path) => {
            let poses = io::read_matrix(path, Some(3), "(M, 3)")?;
            anyhow::ensure!(
                poses.nrows() == distances.len(),
                "{} has {} rows but {} has {} points; the poses must be those of the same sets",
                path.display(),
                poses.nrows(),
                args.distances.display(),
                distances.len()
            );
            Some(poses)
        }
        None => None,
    };
    let bar = Bar::new();
    let report = analyze(&distances, poses.as_ref().map(|p| p.view()), &params, &bar)
        .with_context(|| format!("analysing {}", args.distances.display()))?;
    match &args.out {
        // The analyze stage's writer.
        Some(path) => report.save(path)?,
        None => println!("{}", serde_json::to_string_pretty(&report)?),
    }
    let dimension = &report.intrinsic_dimension;
    let sub = &report.homology.subsampling;
    eprintln!(
        "{} points: betti {:?}{}; dimension {:.2} (TwoNN), {:.2} (MLE){}",
        report.points,
        report.betti,
        if sub.method == "none" {
            String::new()
        } else {
            format!(
                " on {} {} landmarks (covering radius {:.3})",
                sub.points, sub.method, sub.covering_radius
            )
        },
        dimension.twonn,
        dimension.mle,
        match &report.agreement {
            Some(a) => format!(
                "; Spearman {:.3}, trustworthiness {:.3}, continuity {:.3}",
                a.spearman, a.trustworthiness, a.continuity
            ),
            None => String::new(),
        }
    );
    Ok(())
}
