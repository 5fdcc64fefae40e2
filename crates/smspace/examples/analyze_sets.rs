//! Distances between kernel sets, then their topology, dimension and agreement with the
//! poses: `cargo run --release --example analyze_sets -- sets.npy poses.npy [D.npy]`
//! (the optional third path receives the distance matrix).

use std::path::Path;
use std::time::Instant;

use smspace::analysis::{analyze, AnalysisParams};
use smspace::io;
use smspace::metric::{distance_matrix, DistanceParams, MetricKind};
use smspace::progress::Silent;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [sets, poses, rest @ ..] = args.as_slice() else {
        return Err("usage: analyze_sets SETS.npy POSES.npy [D.npy]".into());
    };
    let sets = io::read_cube(Path::new(sets), "(M, P, N)")?;
    let poses = io::read_matrix(Path::new(poses), Some(3), "(M, 3)")?;
    let start = Instant::now();
    let distances = distance_matrix(
        sets.view(),
        &DistanceParams::new().metric(MetricKind::Hausdorff),
        &Silent,
    )?;
    eprintln!("distances: {:.2} s", start.elapsed().as_secs_f64());
    if let Some(out) = rest.first() {
        io::write_npy(Path::new(out), &distances)?;
    }
    let start = Instant::now();
    let params = AnalysisParams::default().check()?;
    let report = analyze(&distances, Some(poses.view()), &params, &Silent)?;
    eprintln!("analysis: {:.2} s", start.elapsed().as_secs_f64());
    println!(
        "betti {:?}, longest bars {:?}",
        report.betti, report.homology.longest_bars
    );
    println!("dimension: {:?}", report.intrinsic_dimension);
    println!("agreement: {:?}", report.agreement);
    Ok(())
}
