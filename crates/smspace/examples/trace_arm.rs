//! Explores the paper's arm, traces its kernel sets, and prints what happened.
//!
//! `cargo run --release -p smspace --example trace_arm -- [n] [kinematic|sensory] [fixed|adaptive]`
use std::time::Instant;

use smspace::agent::{AgentConfig, EnvironmentConfig};
use smspace::explore::{explore, ExploreParams};
use smspace::kernel::{trace_sets, StepControl, TraceMethod, TraceParams};
use smspace::progress::Silent;

fn main() -> Result<(), smspace::Error> {
    let args: Vec<String> = std::env::args().collect();
    let n = args.get(1).map_or(500, |s| s.parse().expect("n"));
    let method: TraceMethod = args
        .get(2)
        .map_or(TraceMethod::Kinematic, |s| s.parse().expect("method"));
    let step_control = match args.get(3).map(String::as_str) {
        Some("fixed") => StepControl::Fixed,
        Some("adaptive") => StepControl::Adaptive,
        _ => StepControl::Auto,
    };
    let agent = AgentConfig::preset("planar-arm")?.build()?;
    let environment = EnvironmentConfig::default().build(agent.as_ref())?;
    let exploration = explore(
        agent.as_ref(),
        &ExploreParams {
            n,
            ..ExploreParams::default()
        },
    )?;
    let params = TraceParams {
        method,
        step_control,
        ..TraceParams::default()
    }
    .check()?;
    let clock = Instant::now();
    let traced = trace_sets(
        agent.as_ref(),
        Some(&environment),
        exploration.motors.view(),
        exploration.workspace.as_ref(),
        &params,
        &Silent,
    )?;
    let seconds = clock.elapsed().as_secs_f64();
    let r = &traced.report;
    let steps: usize = r.sets.iter().map(|s| s.steps).sum();
    let max_dev = r
        .sets
        .iter()
        .filter_map(|s| s.max_pose_deviation)
        .fold(0.0, f64::max);
    let lengths: Vec<f64> = r
        .sets
        .iter()
        .filter(|s| s.length > 0.0)
        .map(|s| s.length)
        .collect();
    let mean_len = lengths.iter().sum::<f64>() / lengths.len().max(1) as f64;
    let max_len = lengths.iter().cloned().fold(0.0, f64::max);
    println!(
        "{n} sets, {:?}/{:?}: {seconds:.3} s, {} steps, summary {:?}, max pose deviation {max_dev:.2e}, mean length {mean_len:.3}, max length {max_len:.3}",
        params.method(), params.step_control(), steps, r.summary.by_status
    );
    Ok(())
}
