//! Times the Hausdorff matrix of the first `M` kernel sets of a file and checks it
//! against a reference matrix: wall and CPU seconds (CPU from `/proc/self/stat`, so
//! that load from other processes does not hide a change), pairs per second, and the
//! largest difference to the reference's top-left `M × M` block.
//!
//! `cargo run --release -p smspace --example metric_timing -- SETS.npy [M] [REF.npy]
//! [repeats]`; `RAYON_NUM_THREADS=1` for one thread.

use std::path::Path;
use std::time::Instant;

use ndarray::{Axis, Slice};
use smspace::metric::{distance_matrix, DistanceParams};
use smspace::progress::Silent;

/// User + system CPU seconds of this process so far (0 where `/proc` is missing).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which ends with ')'): utime is the 12th, stime
    // the 13th, in clock ticks of 1/100 s.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<f64> = rest
        .split_whitespace()
        .map(|f| f.parse().unwrap_or(0.0))
        .collect();
    if fields.len() < 14 {
        return 0.0;
    }
    (fields[11] + fields[12]) / 100.0
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .expect("usage: metric_timing SETS.npy [M] [REF.npy] [repeats]");
    let all = smspace::io::read_cube(Path::new(path), "(M, P, N)").expect("readable sets");
    let m: usize = args
        .get(2)
        .and_then(|a| a.parse().ok())
        .unwrap_or(all.dim().0)
        .min(all.dim().0);
    let sets = all.slice_axis(Axis(0), Slice::from(..m)).to_owned();
    let reference = args
        .get(3)
        .filter(|a| !a.is_empty() && *a != "-")
        .map(|p| smspace::io::read_matrix(Path::new(p), None, "(M, M)").expect("readable matrix"));
    let repeats: usize = args.get(4).and_then(|a| a.parse().ok()).unwrap_or(1);
    let pairs = (m * (m - 1) / 2) as f64;
    for _ in 0..repeats {
        let cpu0 = cpu_seconds();
        let t0 = Instant::now();
        let d = distance_matrix(
            sets.view(),
            &DistanceParams::new().metric(smspace::metric::MetricKind::Hausdorff),
            &Silent,
        )
        .expect("matrix");
        let wall = t0.elapsed().as_secs_f64();
        let cpu = cpu_seconds() - cpu0;
        let diff = reference.as_ref().map_or(f64::NAN, |r| {
            let mut worst: f64 = 0.0;
            for i in 0..m {
                for j in 0..m {
                    worst = worst.max((d[[i, j]] - r[[i, j]]).abs());
                }
            }
            worst
        });
        println!(
            "M={m} wall={wall:.3}s cpu={cpu:.2}s cpu/pair={:.3}us pairs/s(wall)={:.3e} max|D-ref|={diff:e}",
            cpu / pairs * 1e6,
            pairs / wall
        );
    }
}
