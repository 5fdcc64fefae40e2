//! `smspace analyze`: topology, intrinsic dimension and agreement with the poses of a
//! distance matrix between kernel sets.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use smspace::agent::{GroundTruthView, PoseSpace};
use smspace::analysis::affine::affine_errors;
use smspace::analysis::{analyze_on, AnalysisParams};
use smspace::io;
use smspace::metric::DistanceMatrix;

use crate::ui::Bar;

/// Arguments of `smspace analyze`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Distance matrix (M, M) between kernel sets.
    #[arg(long, value_name = "FILE")]
    distances: PathBuf,
    /// Observer's poses of the same rows, for the agreement with the poses: (M, 3)
    /// `(x, y, alpha)` of a planar agent, or (M, 7) `(x, y, z, qw, qx, qy, qz)` of a
    /// 3-D one (as `poses.npy` of a run).
    #[arg(long, value_name = "FILE")]
    poses: Option<PathBuf>,
    /// A learned representation of the same rows (M, q), e.g. the embedding `Y.npy`:
    /// the affine fit of the poses' positions from it and its metric and topology
    /// errors (needs --poses).
    #[arg(long, value_name = "FILE")]
    representation: Option<PathBuf>,
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
    /// A key of the [analysis] table that has no flag of its own (circle_landmarks,
    /// circle_scale, gap_ratio, noise_fraction, twonn_discard, …), the value read as
    /// TOML (repeatable).
    #[arg(long = "param", value_name = "KEY=VALUE", value_parser = super::common::parse_param)]
    params: Vec<(String, toml::Value)>,
    /// Report (JSON, with `circle.npy` beside it when there is a circular coordinate);
    /// printed to standard output when not given.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

/// The representation's file, for messages.
fn h_name(args: &Args) -> String {
    args.representation
        .as_deref()
        .map_or_else(String::new, |p| p.display().to_string())
}

/// [analysis] keys that have a flag of their own.
const ANALYSIS_FLAGS: [(&str, &str); 5] = [
    ("max_homology_dim", "max-dim"),
    ("threshold", "threshold"),
    ("max_points", "max-points"),
    ("neighbors", "neighbors"),
    ("mle_neighbors", "mle-neighbors"),
];

/// Runs `smspace analyze`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(out) = &args.out {
        super::common::spare_inputs(
            &[out],
            &[
                ("--distances", Some(args.distances.as_path())),
                ("--poses", args.poses.as_deref()),
            ],
        )?;
    }
    let params = AnalysisParams {
        max_homology_dim: args.max_dim,
        threshold: args.threshold,
        max_points: args.max_points,
        neighbors: args.neighbors,
        mle_neighbors: args.mle_neighbors,
        ..AnalysisParams::default()
    };
    let params =
        super::common::with_table_params(&params, &args.params, &ANALYSIS_FLAGS, "analysis")?
            .check()?;
    let distances = DistanceMatrix::load(&args.distances)?;
    let poses = match &args.poses {
        Some(path) => Some(read_poses(path, distances.len(), &args.distances)?),
        None => None,
    };
    let truth = match &poses {
        Some((space, poses)) => Some(GroundTruthView::new(space, poses.view())?),
        None => None,
    };
    let representation = match &args.representation {
        Some(path) => Some(read_representation(
            &args,
            path,
            truth.is_some(),
            distances.len(),
        )?),
        None => None,
    };
    let bar = Bar::new();
    let mut report = analyze_on(&distances, truth, None, &params, &bar)
        .with_context(|| format!("analysing {}", args.distances.display()))?;
    if let (Some(h), Some(truth)) = (&representation, truth) {
        let linear = truth.space().linear_columns();
        let positions = truth.poses().select(ndarray::Axis(1), &linear);
        report.affine = Some(
            affine_errors(h.view(), positions.view())
                .with_context(|| format!("fitting the positions from {}", h_name(&args)))?,
        );
    }
    match &args.out {
        // The analyze stage's writer.
        Some(path) => report.save(path)?,
        None => println!("{}", serde_json::to_string_pretty(&report)?),
    }
    print_summary(&report);
    Ok(())
}

/// The representation `--representation` names, `(M, q)`: it needs `--poses` (the
/// measures fit their positions) and one row per set of `--distances`.
fn read_representation(
    args: &Args,
    path: &std::path::Path,
    has_poses: bool,
    sets: usize,
) -> anyhow::Result<ndarray::Array2<f64>> {
    anyhow::ensure!(
        has_poses,
        "--representation {} needs --poses: the measures fit the poses' positions",
        path.display()
    );
    let h = io::read_matrix(path, None, "(M, q)")?;
    anyhow::ensure!(
        h.nrows() == sets,
        "{} has {} rows but {} has {sets} points; the representation must be that of the same sets",
        path.display(),
        h.nrows(),
        args.distances.display(),
    );
    Ok(h)
}

/// The report in a few lines on stderr: topology and dimension, the agreement, the
/// affine fit, the circle and the plane.
fn print_summary(report: &smspace::analysis::AnalysisReport) {
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
    if let Some(a) = &report.affine {
        eprintln!(
            "positions from the representation ({} columns): R² {:.3}, metric error {:.4}, topology error {:.4} (positions), {:.4} (representation)",
            a.representation_dim,
            a.r_squared,
            a.metric_error,
            a.topology_error_positions,
            a.topology_error_representation
        );
    }
    if let Some(c) = &report.circle {
        let scores: Vec<String> = c
            .agreement
            .iter()
            .map(|(name, g)| format!("{:.3} with {name}", g.circular_correlation))
            .collect();
        eprintln!(
            "circular coordinate from the loop [{:.3}, {:.3}) on {} landmarks ({} class{}){}",
            c.bar[0],
            c.bar[1],
            c.landmarks,
            c.classes,
            if c.classes == 1 { "" } else { "es" },
            if scores.is_empty() {
                String::new()
            } else {
                format!("; circular correlation {}", scores.join(", "))
            }
        );
        if let Some(plane) = &c.plane {
            eprintln!(
                "the plane at fixed circle coordinate: positions fitted from its two coordinates with R² {:.3} (median of {} slices, least {:.3})",
                plane.r_squared, plane.slices, plane.r_squared_min
            );
        }
    } else if let Some(why) = &report.circle_missing {
        eprintln!("no circular coordinate: {why}");
    }
}

/// The poses of `path` with their layout, read off the column count
/// ([`PoseSpace::from_columns`]: 2 a planar position, 3 planar, 7 3-D).
fn read_poses(
    path: &std::path::Path,
    sets: usize,
    distances: &std::path::Path,
) -> anyhow::Result<(PoseSpace, ndarray::Array2<f64>)> {
    let poses = io::read_matrix(path, None, "(M, 2), (M, 3) or (M, 7)")?;
    let Some(space) = PoseSpace::from_columns(poses.ncols()) else {
        anyhow::bail!(
            "{} has {} columns; poses are (M, 3) (x, y, alpha) of a planar agent, (M, 7) (x, y, z, qw, qx, qy, qz) of a 3-D one, or (M, 2) (x, y) of a sensor whose orientation is fixed",
            path.display(),
            poses.ncols()
        )
    };
    anyhow::ensure!(
        poses.nrows() == sets,
        "{} has {} rows but {} has {} points; the poses must be those of the same sets",
        path.display(),
        poses.nrows(),
        distances.display(),
        sets
    );
    Ok((space, poses))
}
