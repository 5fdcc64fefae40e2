//! What the sensory method costs an agent that is slow to sense: the paper's arm traced
//! with `method = "sensory"` from `N` explored starts (the paper's working space, the
//! default environment of 10 lights), printing the sensor rows per start (median, 90th
//! percentile, largest, mean) and by phase of tracing (mean and median over the
//! starts), the engine's own time, and the projected run time for a
//! simulator that costs 10 µs and 1 ms per row (engine time + rows × cost: a cost
//! model, nothing sleeps).
//!
//! ```text
//! cargo bench -p smspace --bench trace_rows
//! SMSPACE_BENCH_STARTS=500 cargo bench -p smspace --bench trace_rows
//! ```
//!
//! `SMSPACE_BENCH_STARTS` sets `N` (default 200); `SMSPACE_BENCH_JACOBIAN` traces with
//! one `[kernel] jacobian` only (`finite-differences` or `secant`; default both, and
//! then the sets of the two are compared: the `curve` metric between the two sets
//! through each start, and the largest distance between their corresponding points);
//! `SMSPACE_BENCH_SAVE=DIR` writes each method's sets to `DIR/<jacobian>/sets.npy`
//! (with the trace report beside it), and `SMSPACE_BENCH_COMPARE=FILE` compares each
//! method's sets with those of `FILE` (a `sets.npy` written so, e.g. by another build).
//! `SMSPACE_BENCH_MAX_STEP` sets `[kernel] max_step` (default: the default's).

use std::path::PathBuf;
use std::time::Instant;

use ndarray::{ArrayView2, Axis};
use smspace::agent::{Agent, AgentConfig, Environment, EnvironmentConfig};
use smspace::explore::{explore, ExploreParams};
use smspace::kernel::{
    trace_sets, JacobianMethod, SensorRowPhases, TraceMethod, TraceParams, TracedSets,
};
use smspace::metric::{Curve, Period, Periodicity, SetMetric};
use smspace::progress::Silent;

/// Simulator costs per sensor row of the projection, seconds.
const COSTS: [(&str, f64); 2] = [("10 µs", 1e-5), ("1 ms", 1e-3)];

fn main() {
    let starts: usize = std::env::var("SMSPACE_BENCH_STARTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200);
    let methods: Vec<JacobianMethod> = match std::env::var("SMSPACE_BENCH_JACOBIAN") {
        Ok(name) => vec![name.parse().expect("SMSPACE_BENCH_JACOBIAN")],
        Err(_) => vec![JacobianMethod::FiniteDifferences, JacobianMethod::Secant],
    };
    let save = std::env::var_os("SMSPACE_BENCH_SAVE").map(PathBuf::from);
    let reference = std::env::var_os("SMSPACE_BENCH_COMPARE")
        .map(|path| TracedSets::load(&PathBuf::from(path)).expect("SMSPACE_BENCH_COMPARE"));
    let agent = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let environment = EnvironmentConfig::default().build(agent.as_ref()).unwrap();
    let explored = ExploreParams {
        n: starts,
        ..ExploreParams::default()
    };
    let motors = explore(agent.as_ref(), &explored).unwrap().motors;
    println!(
        "paper arm, sensory method, {starts} starts, {} threads, SIMD {} (the metric's, for the comparisons)",
        rayon::current_num_threads(),
        smspace::metric::simd_level()
    );
    let mut traced = Vec::new();
    for jacobian in methods {
        let sets = run(agent.as_ref(), &environment, motors.view(), jacobian);
        if let Some(dir) = &save {
            let path = dir.join(jacobian.name()).join("sets.npy");
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            sets.save(&path).unwrap();
            println!("  saved to {}", path.display());
        }
        if let Some(reference) = &reference {
            compare("the saved sets", reference, jacobian.name(), &sets);
        }
        traced.push((jacobian, sets));
    }
    if let [(a, first), (b, second)] = &traced[..] {
        compare(a.name(), first, b.name(), second);
    }
}

/// Traces the starts with `jacobian` and prints its rows and times.
fn run(
    agent: &dyn Agent,
    environment: &Environment,
    motors: ArrayView2<'_, f64>,
    jacobian: JacobianMethod,
) -> TracedSets {
    let defaults = TraceParams::default();
    let max_step = std::env::var("SMSPACE_BENCH_MAX_STEP")
        .ok()
        .map_or(defaults.max_step, |v| {
            v.parse().expect("SMSPACE_BENCH_MAX_STEP")
        });
    let params = TraceParams {
        method: TraceMethod::Sensory,
        jacobian,
        max_step,
        ..defaults
    }
    .check()
    .unwrap();
    let clock = Instant::now();
    let sets = trace_sets(agent, Some(environment), motors, None, &params, &Silent).unwrap();
    let engine = clock.elapsed().as_secs_f64();
    let starts = motors.nrows();
    let summary = &sets.report.summary;
    let rows = summary
        .sensor_rows
        .expect("the sensory method reads sensors");
    println!(
        "jacobian = {}: {} of {starts} sets traced {:?}, {} with pieces the set misses",
        jacobian.name(),
        summary.traced,
        summary.by_status,
        summary.with_unvisited_pieces
    );
    println!(
        "  sensor rows per start: median {}, p90 {}, max {}, mean {:.0} ({} in all)",
        rows.median,
        rows.p90,
        rows.max,
        rows.total as f64 / starts as f64,
        rows.total
    );
    print_phases(&sets, starts);
    println!(
        "  engine time {engine:.3} s ({:.2} ms per start)",
        1e3 * engine / starts as f64
    );
    for (label, cost) in COSTS {
        let total = engine + rows.total as f64 * cost;
        println!(
            "  with a simulator costing {label} per row: {total:.2} s ({:.2} s per 2500 starts on this machine's threads, rows in series)",
            total * 2500.0 / starts as f64
        );
    }
    sets
}

/// One phase's rows of a set.
type Phase = fn(&SensorRowPhases) -> u64;

/// The sensor rows per start of every phase of tracing (mean and median over the
/// starts).
fn print_phases(sets: &TracedSets, starts: usize) {
    let phases: Vec<SensorRowPhases> = sets
        .report
        .sets
        .iter()
        .map(|s| s.sensor_row_phases.unwrap_or_default())
        .collect();
    let fields: [(&str, Phase); 7] = [
        ("start and rank", |p| p.start),
        ("trace: readings", |p| p.trace_readings),
        ("trace: Jacobians", |p| p.trace_jacobians),
        ("piece search: readings", |p| p.search_readings),
        ("piece search: Jacobians", |p| p.search_jacobians),
        ("resampling: readings", |p| p.resample_readings),
        ("resampling: Jacobians", |p| p.resample_jacobians),
    ];
    println!("  rows per start by phase (mean, median):");
    for (name, field) in fields {
        let mut rows: Vec<u64> = phases.iter().map(field).collect();
        rows.sort_unstable();
        let mean = rows.iter().sum::<u64>() as f64 / starts as f64;
        println!("    {name:<24} {mean:>7.0} {:>7}", rows[rows.len() / 2]);
    }
}

/// The `curve` metric between the sets of `a` and `b` through the same starts, and the
/// largest distance between corresponding points (torus distance).
fn compare(a_name: &str, a: &TracedSets, b_name: &str, b: &TracedSets) {
    let period = Periodicity::from(Period::TwoPi);
    let mut curve: Vec<f64> = Vec::new();
    let mut points: f64 = 0.0;
    let mut only_one = 0;
    for (ai, row) in a.kept.iter().enumerate() {
        let Ok(bi) = b.kept.binary_search(row) else {
            only_one += 1;
            continue;
        };
        let (x, y) = (
            a.sets.index_axis(Axis(0), ai),
            b.sets.index_axis(Axis(0), bi),
        );
        let closure = a.closure[ai];
        if closure != b.closure[bi] {
            only_one += 1;
            continue;
        }
        let metric = Curve {
            period: period.clone(),
            closure,
        };
        curve.push(metric.distance(x, y).unwrap());
        points = points.max(largest_point_distance(x, y));
    }
    only_one += b.kept.len() - (a.kept.len() - only_one).min(b.kept.len());
    curve.sort_by(f64::total_cmp);
    let at = |q: f64| curve[((curve.len() - 1) as f64 * q).round() as usize];
    if curve.is_empty() {
        println!("{a_name} against {b_name}: no set traced by both");
        return;
    }
    println!(
        "{a_name} against {b_name}: {} sets in both, {only_one} in one only; curve metric median {:.2e}, p90 {:.2e}, max {:.2e} rad; largest point distance {points:.2e} rad",
        curve.len(),
        at(0.5),
        at(0.9),
        curve[curve.len() - 1]
    );
}

fn largest_point_distance(a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> f64 {
    let tau = std::f64::consts::TAU;
    a.outer_iter()
        .zip(b.outer_iter())
        .map(|(p, q)| {
            p.iter()
                .zip(q.iter())
                .map(|(x, y)| {
                    let d = (x - y).rem_euclid(tau);
                    d.min(tau - d).powi(2)
                })
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max)
}
