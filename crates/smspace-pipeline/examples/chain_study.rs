//! How the intrinsic dimension of a chain's learned manifold converges with the number of
//! sets `M`: babbled configurations of the agent's working space, kinematic tracing
//! (adaptive steps, `P = 100`), the `k = 20` nearest sets by the `curve` metric (exact
//! kNN, no matrix), TwoNN (10 % of the largest ratios discarded) and Levina–Bickel
//! (`k = 20`) from them.
//!
//! ```sh
//! cargo run --release -p smspace-pipeline --example chain_study -- experiments/arm-3d.toml OUT.json 1000 2500 5000
//! cargo run --release -p smspace-pipeline --example chain_study -- --components=all experiments/arm-3d.toml OUT.json 1000 2500
//! ```
//!
//! `--components=all` traces every piece of each level set (`[kernel] components =
//! "all"`); the curve metric then joins no two pieces.
//!
//! The agent is the `[agent]` table of the file (a chain or any agent with a ground
//! truth); the exploration seed is 1 and nothing else of the file is read. Timings are
//! wall-clock on whatever the machine is doing.

use std::time::Instant;

use smspace::analysis::dimension::{mle_neighbours, twonn_neighbours};
use smspace::explore::{explore, ExploreParams};
use smspace::kernel::{trace_sets, Components, StepControl, TraceMethod, TraceParams};
use smspace::metric::{knn, DistanceParams, KnnParams, MetricKind, SetsView};
use smspace::progress::Silent;

const K: usize = 20;

#[derive(serde::Serialize)]
struct Row {
    sets: usize,
    traced: usize,
    twonn: f64,
    mle: f64,
    trace_seconds: f64,
    knn_seconds: f64,
}

fn measure(
    agent: &dyn smspace::agent::Agent,
    m: usize,
    components: Components,
) -> Result<Row, Box<dyn std::error::Error>> {
    let exploration = explore(
        agent,
        &ExploreParams {
            n: m,
            seed: 1,
            ..ExploreParams::default()
        },
    )?;
    let params = TraceParams {
        method: TraceMethod::Kinematic,
        points: 100,
        step_control: StepControl::Adaptive,
        max_step: 0.05,
        components,
        ..TraceParams::default()
    }
    .check()?;
    let started = Instant::now();
    let traced = trace_sets(
        agent,
        None,
        exploration.motors.view(),
        exploration.workspace.as_ref(),
        &params,
        &Silent,
    )?;
    let trace_seconds = started.elapsed().as_secs_f64();
    let view = SetsView::new(traced.sets.view())
        .with_closure(&traced.closure)
        .with_pieces(traced.pieces.view());
    let metric = DistanceParams::new().metric(MetricKind::Curve);
    let started = Instant::now();
    let sets = traced.sets.dim().0;
    let found = knn(view, &metric, &KnnParams::new().k(K), 0..sets, &Silent)?;
    Ok(Row {
        sets: m,
        traced: sets,
        twonn: twonn_neighbours(found.distances.view(), 0.1)?.dimension,
        mle: mle_neighbours(found.distances.view())?.dimension,
        trace_seconds,
        knn_seconds: started.elapsed().as_secs_f64(),
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (flags, args): (Vec<String>, Vec<String>) =
        std::env::args().skip(1).partition(|a| a.starts_with("--"));
    let usage = "usage: chain_study [--components=all|connected] AGENT.toml OUT.json M1 [M2 …]";
    let components = match flags.iter().map(String::as_str).next() {
        None | Some("--components=connected") => Components::Connected,
        Some("--components=all") => Components::All,
        Some(other) => return Err(format!("unknown flag {other}; {usage}").into()),
    };
    let (file, out) = (args.first().ok_or(usage)?, args.get(1).ok_or(usage)?);
    let sizes: Vec<usize> = args[2..]
        .iter()
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    let agent = smspace_pipeline::config::load_agent(file)?.agent.build()?;
    let mut rows = Vec::new();
    for &m in &sizes {
        let row = measure(agent.as_ref(), m, components)?;
        eprintln!(
            "M = {m}: TwoNN {:.2}, MLE {:.2} (trace {:.1} s, kNN {:.1} s)",
            row.twonn, row.mle, row.trace_seconds, row.knn_seconds
        );
        rows.push(row);
    }
    println!("| M | TwoNN | MLE (k = {K}) | trace s | kNN s |");
    println!("|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {:.2} | {:.2} | {:.1} | {:.1} |",
            r.sets, r.twonn, r.mle, r.trace_seconds, r.knn_seconds
        );
    }
    let json = serde_json::json!({
        "agent": file,
        "threads": rayon::current_num_threads(),
        "metric": "curve",
        "components": components,
        "k": K,
        "rows": rows,
    });
    smspace::io::write_json(std::path::Path::new(out), &json)?;
    Ok(())
}
