//! A small end-to-end run that ends with the report stage, and the time the report
//! takes: `cargo run --release --example report_demo -- OUT_DIR [AGENT] [BABBLED]
//! [PROBE_POSITIONS] [PROBE_ORIENTATIONS]` (defaults: `planar-arm 300 5 10`).
//!
//! With `planar-arm 2500 10 10` it reproduces the paper's 3500 sets (2500 babbled plus
//! the 10 × 10 × 10 probe grid) and times [`write_report`] on them.

use std::path::Path;
use std::time::Instant;

use ndarray::{Array2, Axis};
use smspace::agent::{Agent, AgentConfig, Environment, MotorTopology};
use smspace::analysis::{analyze, AnalysisParams};
use smspace::embed::quality::{shepard_pairs, stress, trustworthiness_continuity};
use smspace::embed::{CcaParams, Embedding};
use smspace::explore::{explore, ExploreParams, Probes};
use smspace::invariance::invariance;
use smspace::kernel::{trace_sets, TraceMethod, TraceParams};
use smspace::metric::{distance_matrix, DistanceParams, Period};
use smspace::progress::Silent;
use smspace::report::{
    write_report, InvarianceData, ReportInputs, ReportParams, SensoryManifold, StageTiming,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = Path::new(args.first().ok_or(
        "usage: report_demo OUT_DIR [AGENT] [BABBLED] [PROBE_POSITIONS] [PROBE_ORIENTATIONS]",
    )?);
    let name = args.get(1).map_or("planar-arm", String::as_str);
    let babbled: usize = args.get(2).map_or(Ok(300), |s| s.parse())?;
    let positions: usize = args.get(3).map_or(Ok(5), |s| s.parse())?;
    let orientations: usize = args.get(4).map_or(Ok(10), |s| s.parse())?;
    let mut stages = Vec::new();
    let mut clock = Instant::now();
    let mut lap = |stage: &str, stages: &mut Vec<StageTiming>| {
        stages.push(StageTiming {
            stage: stage.to_owned(),
            seconds: clock.elapsed().as_secs_f64(),
            cached: false,
        });
        clock = Instant::now();
    };

    let agent: Box<dyn Agent> = AgentConfig::preset(name)?.build()?;
    let environments = (1..=2)
        .map(|seed| {
            Environment::random(
                agent.default_light_count(),
                seed,
                &agent.default_light_region(),
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let arm = agent.configuration_dim() >= 2;
    let exploration = explore(
        agent.as_ref(),
        &ExploreParams {
            n: babbled,
            probes: if arm && positions > 0 {
                Probes::Grid
            } else {
                Probes::None
            },
            probe_positions: positions.max(1),
            probe_orientations: orientations.max(1),
            ..ExploreParams::default()
        },
    )?;
    lap("explore", &mut stages);
    let traced = trace_sets(
        agent.as_ref(),
        Some(&environments[0]),
        exploration.motors.view(),
        exploration.workspace.as_ref(),
        &TraceParams::default().check()?,
        &Silent,
    )?;
    lap("trace", &mut stages);
    let period = match agent.motor_topology() {
        MotorTopology::Periodic => Period::TwoPi,
        MotorTopology::Bounded { .. } => Period::None,
    };
    let metric = DistanceParams::new().period(period);
    let distances = distance_matrix(traced.sets.view(), &metric, &Silent)?;
    lap("distances", &mut stages);
    let dim = if arm { 3 } else { 1 };
    let embedded = CcaParams::default()
        .dim(dim)
        .seed(1)
        .check()?
        .fit(distances.view(), &Silent)?;
    let y = &embedded.coordinates;
    let (trust, cont) = trustworthiness_continuity(distances.view(), y.view(), 10)?;
    let (raw_stress, normalized_stress) = stress(distances.view(), y.view())?;
    let quality = serde_json::json!({
        "trustworthiness": trust,
        "continuity": cont,
        "stress": raw_stress,
        "normalized_stress": normalized_stress,
    });
    let dydx = shepard_pairs(distances.view(), y.view(), 20_000, 1)?;
    lap("embed", &mut stages);
    let set_poses = exploration.poses.select(Axis(0), &traced.kept);
    let analysis = analyze(
        distances.view(),
        Some(set_poses.view()),
        &AnalysisParams::default().check()?,
        &Silent,
    )?;
    lap("analyze", &mut stages);

    // Invariance on the first babbled rows, traced with the sensory method.
    let rows = 40.min(babbled);
    let starts = exploration.motors.slice_axis(Axis(0), (0..rows).into());
    let sensory = TraceParams {
        method: TraceMethod::Sensory,
        ..TraceParams::default()
    }
    .check()?;
    let report = invariance(
        agent.as_ref(),
        starts,
        &environments,
        exploration.workspace.as_ref(),
        &sensory,
        smspace::metric::MetricKind::Hausdorff,
        &Silent,
    )?;
    let per_env = environments
        .iter()
        .map(|env| {
            trace_sets(
                agent.as_ref(),
                Some(env),
                starts,
                exploration.workspace.as_ref(),
                &sensory,
                &Silent,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let common: Vec<usize> = per_env[0]
        .kept
        .iter()
        .copied()
        .filter(|r| per_env.iter().all(|t| t.kept.binary_search(r).is_ok()))
        .collect();
    let mut set_distances = Vec::new();
    let mut sensors = Vec::new();
    for (t, env) in per_env.iter().zip(&environments) {
        let at: Vec<usize> = common
            .iter()
            .map(|r| t.kept.binary_search(r).unwrap_or(0))
            .collect();
        set_distances.push(distance_matrix(
            t.sets.select(Axis(0), &at).view(),
            &metric,
            &Silent,
        )?);
        let mut s = Array2::zeros((common.len(), agent.sensor_dim()));
        for (k, &r) in common.iter().enumerate() {
            let m = starts.row(r).to_vec();
            let mut out = vec![0.0; agent.sensor_dim()];
            agent.sense(env, &m, &mut out);
            s.row_mut(k).assign(&ndarray::ArrayView1::from(&out));
        }
        sensors.push(s);
    }
    let invariance_data = InvarianceData {
        report,
        set_distances,
        sensors,
    };
    lap("invariance", &mut stages);

    // Sensory manifolds of a one-motor agent: a sweep of its motor range.
    let manifolds: Vec<SensoryManifold> = if agent.motor_dim() == 1 {
        let (lo, hi) = agent.motor_topology().range();
        let t = 400;
        let motors =
            Array2::from_shape_fn((t, 1), |(i, _)| lo + (hi - lo) * i as f64 / (t - 1) as f64);
        environments
            .iter()
            .enumerate()
            .map(|(k, env)| {
                let mut s = Array2::zeros((t, agent.sensor_dim()));
                for i in 0..t {
                    let mut out = vec![0.0; agent.sensor_dim()];
                    agent.sense(env, &[motors[[i, 0]]], &mut out);
                    s.row_mut(i).assign(&ndarray::ArrayView1::from(&out));
                }
                SensoryManifold {
                    label: format!("environment {} ({} lights)", k + 1, env.lights.len()),
                    motors: motors.clone(),
                    sensors: s,
                }
            })
            .collect()
    } else {
        Vec::new()
    };

    let config = format!(
        "[agent]\nkind = \"{name}\"\n\n[exploration]\nn = {babbled}\nprobe_positions = {positions}\nprobe_orientations = {orientations}\n"
    );
    let description = "A demonstration run of the pipeline: exploration, tracing of the kernel sets, their Hausdorff distances, a CCA embedding, the analysis and the environment invariance.";
    let inputs = ReportInputs {
        name: &format!("report demo: {name}"),
        description,
        config_toml: &config,
        agent: agent.as_ref(),
        environments: &environments,
        workspace: exploration.workspace,
        motors: exploration.motors.view(),
        poses: exploration.poses.view(),
        probes: exploration.probes.view(),
        sets: traced.sets.view(),
        kept: &traced.kept,
        trace: &traced.report.summary,
        embedding: y.view(),
        embed_report: &embedded.report,
        embed_quality: Some(&quality),
        dydx: Some(dydx.view()),
        analysis: Some(&analysis),
        invariance: Some(&invariance_data),
        sensory_manifolds: &manifolds,
        stages: &stages,
    };
    let params = ReportParams::default();
    let mut times = Vec::new();
    let mut summary = None;
    let cpu_start = cpu_seconds();
    for _ in 0..3 {
        let start = Instant::now();
        summary = Some(write_report(&inputs, &params, out)?);
        times.push(start.elapsed().as_secs_f64());
    }
    let cpu = cpu_seconds().zip(cpu_start).map(|(b, a)| (b - a) / 3.0);
    times.sort_by(f64::total_cmp);
    let summary = summary.ok_or("no report written")?;
    for f in &summary.figures {
        match &f.skipped {
            Some(reason) => eprintln!("{:<24} skipped: {reason}", f.name),
            None => eprintln!("{:<24} {:?}", f.name, f.files),
        }
    }
    println!(
        "{} sets x {} points: write_report took {:.3} s wall (median of 3; min {:.3} s), {} CPU per report",
        traced.sets.len_of(Axis(0)),
        traced.sets.len_of(Axis(1)),
        times[1],
        times[0],
        cpu.map_or_else(|| "unknown".to_owned(), |c| format!("{c:.3} s"))
    );
    Ok(())
}

/// User + system CPU time of this process so far (Linux; clock ticks of 10 ms).
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit(')').next()?.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
