//! The curve-metric study: intrinsic dimension, topology and agreement with the poses
//! of the paper's arm for the point metric `hausdorff` and the polyline metric `curve`.
//!
//! ```sh
//! cargo run --release -p smspace --example curve_study -- OUT.json [quick]
//! ```
//!
//! 1. `P = 100` points per set, `M = 1000, 2500, 5000, 10 000` babbled configurations of
//!    the paper's working space: TwoNN and Levina–Bickel (k = 20) dimension for both
//!    metrics, from the full matrix up to `M = 5000` and from the `k = 20` nearest sets
//!    (exact kNN, no matrix) at `M = 10 000`.
//! 2. `M = 2500`, `P = 25, 50, 100, 200`: the same estimates.
//! 3. `M = 2500`, `P = 100`: Betti numbers, trustworthiness and continuity against the
//!    poses (the pipeline's analysis).
//!
//! Every number is measured here; the JSON keeps them all, the markdown table goes to
//! standard output. `quick` runs a small version (for trying the example).

use std::time::Instant;

use ndarray::Array2;
use smspace::agent::AgentConfig;
use smspace::analysis::dimension::{mle, mle_neighbours, twonn, twonn_neighbours};
use smspace::analysis::{analyze, AnalysisParams};
use smspace::explore::{explore, ExploreParams, Probes};
use smspace::kernel::{trace_sets, StepControl, TraceParams};
use smspace::metric::{distance_matrix, knn, DistanceParams, KnnParams, MetricKind, SetsView};
use smspace::progress::Silent;

const METRICS: [MetricKind; 2] = [MetricKind::Hausdorff, MetricKind::Curve];
const MLE_K: usize = 20;

struct Sets {
    sets: ndarray::Array3<f64>,
    closure: Vec<smspace::metric::Closure>,
    poses: Array2<f64>,
}

fn babble(m: usize, points: usize) -> Result<Sets, Box<dyn std::error::Error>> {
    let agent = AgentConfig::preset("planar-arm")?.build()?;
    let exploration = explore(
        agent.as_ref(),
        &ExploreParams {
            n: m,
            seed: 1,
            probes: Probes::None,
            ..ExploreParams::default()
        },
    )?;
    let params = TraceParams {
        points,
        step_control: StepControl::Adaptive,
        max_step: 0.05,
        ..TraceParams::default()
    }
    .check()?;
    let traced = trace_sets(
        agent.as_ref(),
        None,
        exploration.motors.view(),
        exploration.workspace.as_ref(),
        &params,
        &Silent,
    )?;
    let poses = exploration
        .planar_poses()
        .expect("the arm's poses are planar")
        .select(ndarray::Axis(0), &traced.kept);
    Ok(Sets {
        sets: traced.sets,
        closure: traced.closure,
        poses,
    })
}

#[derive(serde::Serialize)]
struct Row {
    metric: &'static str,
    sets: usize,
    points: usize,
    mode: &'static str,
    twonn: f64,
    mle: f64,
    seconds: f64,
}

/// A row of the table and, in matrix mode, the matrix.
type Measured = (Row, Option<Array2<f64>>);

fn dimensions(
    data: &Sets,
    metric: MetricKind,
    full: bool,
) -> Result<Measured, Box<dyn std::error::Error>> {
    let view = SetsView::new(data.sets.view()).with_closure(&data.closure);
    let params = DistanceParams::new().metric(metric);
    let started = Instant::now();
    let (m, p, _) = data.sets.dim();
    if full {
        let d = distance_matrix(view, &params, &Silent)?;
        let seconds = started.elapsed().as_secs_f64();
        let row = Row {
            metric: metric.name(),
            sets: m,
            points: p,
            mode: "matrix",
            twonn: twonn(d.view(), 0.1)?.dimension,
            mle: mle(d.view(), MLE_K)?.dimension,
            seconds,
        };
        Ok((row, Some(d.into_array())))
    } else {
        let found = knn(view, &params, &KnnParams::new().k(MLE_K), 0..m, &Silent)?;
        let seconds = started.elapsed().as_secs_f64();
        let row = Row {
            metric: metric.name(),
            sets: m,
            points: p,
            mode: "knn",
            twonn: twonn_neighbours(found.distances.view(), 0.1)?.dimension,
            mle: mle_neighbours(found.distances.view())?.dimension,
            seconds,
        };
        Ok((row, None))
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = args.first().ok_or("usage: curve_study OUT.json [quick]")?;
    let quick = args.get(1).is_some_and(|a| a == "quick");
    let (sizes, base, full_max) = if quick {
        (vec![300, 600], 300, 300)
    } else {
        (vec![1000, 2500, 5000, 10_000], 2500, 5000)
    };
    let mut by_size = Vec::new();
    let mut by_points = Vec::new();
    let mut agreement = Vec::new();
    for &m in &sizes {
        let data = babble(m, 100)?;
        for metric in METRICS {
            let (row, d) = dimensions(&data, metric, m <= full_max)?;
            eprintln!(
                "M = {m}, P = 100, {}: TwoNN {:.2}, MLE {:.2} ({} in {:.1} s)",
                row.metric, row.twonn, row.mle, row.mode, row.seconds
            );
            if m == base {
                let d = d.expect("the base size has its matrix");
                let params = AnalysisParams::default().check()?;
                let d = smspace::metric::DistanceMatrix::new(d)?;
                let report = analyze(&d, Some(data.poses.view()), &params, &Silent)?;
                let g = report.agreement.as_ref().expect("poses were given");
                agreement.push(serde_json::json!({
                    "metric": metric.name(),
                    "sets": m,
                    "points": 100,
                    "betti": report.betti,
                    "twonn": report.intrinsic_dimension.twonn,
                    "mle": report.intrinsic_dimension.mle,
                    "spearman": g.spearman,
                    "trustworthiness": g.trustworthiness,
                    "continuity": g.continuity,
                    "neighbors": g.neighbors,
                }));
                eprintln!(
                    "  betti {:?}, trustworthiness {:.4}, continuity {:.4}",
                    report.betti, g.trustworthiness, g.continuity
                );
            }
            by_size.push(row);
        }
    }
    for points in [25, 50, 100, 200] {
        let data = babble(base, points)?;
        for metric in METRICS {
            let (row, _) = dimensions(&data, metric, true)?;
            eprintln!(
                "M = {base}, P = {points}, {}: TwoNN {:.2}, MLE {:.2} ({:.1} s)",
                row.metric, row.twonn, row.mle, row.seconds
            );
            by_points.push(row);
        }
    }
    println!("| M | P | metric | mode | TwoNN | MLE (k = {MLE_K}) | seconds |");
    println!("|---|---|---|---|---|---|---|");
    for r in by_size.iter().chain(&by_points) {
        println!(
            "| {} | {} | {} | {} | {:.2} | {:.2} | {:.1} |",
            r.sets, r.points, r.metric, r.mode, r.twonn, r.mle, r.seconds
        );
    }
    let json = serde_json::json!({
        "agent": "planar-arm (paper working space, babbled only)",
        "threads": rayon::current_num_threads(),
        "by_sets": by_size,
        "by_points": by_points,
        "agreement": agreement,
    });
    smspace::io::write_json(std::path::Path::new(out), &json)?;
    Ok(())
}
