//! A small end-to-end run that ends with the report stage, and the time the report
//! takes: `cargo run --release -p smspace-pipeline --example report_demo -- OUT_DIR [AGENT] [BABBLED]
//! [PROBE_POSITIONS] [PROBE_ORIENTATIONS]` (defaults: `planar-arm 300 5 10`).
//!
//! With `planar-arm 2500 10 10` it reproduces the paper's 3500 sets (2500 babbled plus
//! the 10 × 10 × 10 probe grid) and times [`write_report`] on them.

use std::error::Error;
use std::path::{Path, PathBuf};
use std::time::Instant;

use ndarray::{Array2, ArrayView2, Axis};
use smspace::agent::{Agent, AgentConfig, Environment};
use smspace::analysis::{analyze, AnalysisParams, AnalysisReport};
use smspace::embed::quality::{shepard_pairs, stress, trustworthiness_continuity};
use smspace::embed::{CcaParams, Embedded, Embedding};
use smspace::explore::{explore, Exploration, ExploreParams, Probes};
use smspace::invariance::invariance;
use smspace::kernel::{trace_sets, TraceMethod, TraceParams, TracedSets};
use smspace::metric::{distance_matrix, DistanceParams, Period};
use smspace::progress::Silent;
use smspace_pipeline::report::{
    figure_texts, write_report, InvarianceData, ReportInputs, ReportParams, SensoryManifold,
    StageTiming,
};

type DemoResult<T> = Result<T, Box<dyn Error>>;

fn main() -> DemoResult<()> {
    let args = Args::parse()?;
    let run = Run::new(&args)?;
    let config = format!(
        "[agent]\nkind = \"{}\"\n\n[exploration]\nn = {}\nprobe_positions = {}\nprobe_orientations = {}\n",
        args.agent, args.babbled, args.positions, args.orientations
    );
    let description = "A demonstration run of the pipeline: exploration, tracing of the kernel sets, their Hausdorff distances, a CCA embedding, the analysis and the environment invariance.";
    let inputs = ReportInputs {
        name: &format!("report demo: {}", args.agent),
        description,
        config_toml: &config,
        agent: run.agent.as_ref(),
        environments: &run.environments,
        workspace: run.exploration.workspace,
        motors: run.exploration.motors.view(),
        poses: run.exploration.planar_poses(),
        pose_view: smspace::agent::PlanarView::Planar,
        probes: run.exploration.probes.view(),
        sets: run.traced.sets.view(),
        kept: &run.traced.kept,
        trace: &run.traced.report.summary,
        law: None,
        embedding: run.embedded.coordinates.view(),
        embed_report: &run.embedded.report,
        embed_quality: Some(&run.quality),
        dydx: Some(run.dydx.view()),
        analysis: Some(&run.analysis),
        invariance: Some(&run.invariance),
        sensory_manifolds: &run.manifolds,
        stages: &run.stages,
        warnings: &[],
    };
    time_reports(&inputs, &args.out)
}

/// The command line: `OUT_DIR [AGENT] [BABBLED] [PROBE_POSITIONS] [PROBE_ORIENTATIONS]`.
struct Args {
    out: PathBuf,
    agent: String,
    babbled: usize,
    positions: usize,
    orientations: usize,
}

impl Args {
    fn parse() -> DemoResult<Self> {
        let args: Vec<String> = std::env::args().skip(1).collect();
        let out = PathBuf::from(args.first().ok_or(
            "usage: report_demo OUT_DIR [AGENT] [BABBLED] [PROBE_POSITIONS] [PROBE_ORIENTATIONS]",
        )?);
        Ok(Self {
            out,
            agent: args.get(1).map_or("planar-arm", String::as_str).to_owned(),
            babbled: args.get(2).map_or(Ok(300), |s| s.parse())?,
            positions: args.get(3).map_or(Ok(5), |s| s.parse())?,
            orientations: args.get(4).map_or(Ok(10), |s| s.parse())?,
        })
    }
}

/// Times the stages: each lap is the time since the previous one.
struct Laps {
    clock: Instant,
    stages: Vec<StageTiming>,
}

impl Laps {
    fn start() -> Self {
        Self {
            clock: Instant::now(),
            stages: Vec::new(),
        }
    }

    fn lap(&mut self, stage: &str) {
        self.stages.push(StageTiming {
            stage: stage.to_owned(),
            seconds: self.clock.elapsed().as_secs_f64(),
            cached: false,
        });
        self.clock = Instant::now();
    }
}

/// The outputs of every stage before the report.
struct Run {
    agent: Box<dyn Agent>,
    environments: Vec<Environment>,
    exploration: Exploration,
    traced: TracedSets,
    embedded: Embedded,
    quality: serde_json::Value,
    dydx: Array2<f64>,
    analysis: AnalysisReport,
    invariance: InvarianceData,
    manifolds: Vec<SensoryManifold>,
    stages: Vec<StageTiming>,
}

impl Run {
    /// Runs the stages in order, timing each.
    fn new(args: &Args) -> DemoResult<Self> {
        let mut laps = Laps::start();
        let agent: Box<dyn Agent> = AgentConfig::preset(&args.agent)?.build()?;
        let environments = (1..=2)
            .map(|seed| {
                Environment::random(
                    agent.default_light_count(),
                    seed,
                    &agent.default_light_region(),
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let arm = agent
            .ground_truth()
            .is_some_and(|o| o.configuration_dim() >= 2);
        let exploration = explore(
            agent.as_ref(),
            &ExploreParams {
                n: args.babbled,
                probes: if arm && args.positions > 0 {
                    Probes::Grid
                } else {
                    Probes::None
                },
                probe_positions: args.positions.max(1),
                probe_orientations: args.orientations.max(1),
                ..ExploreParams::default()
            },
        )?;
        laps.lap("explore");
        let traced = trace_sets(
            agent.as_ref(),
            Some(&environments[0]),
            exploration.motors.view(),
            exploration.workspace.as_ref(),
            &TraceParams::default().check()?,
            &Silent,
        )?;
        laps.lap("trace");
        let period = if agent.motor_space().is_hinges() {
            Period::TwoPi
        } else {
            Period::None
        };
        let metric = DistanceParams::new()
            .metric(smspace::metric::MetricKind::Hausdorff)
            .period(period);
        let distances = distance_matrix(traced.sets.view(), &metric, &Silent)?;
        laps.lap("distances");
        let embedded = CcaParams::default()
            .dim(if arm { 3 } else { 1 })
            .seed(1)
            .check()?
            .fit(&distances, &Silent)?;
        let y = embedded.coordinates.view();
        let quality = embedding_quality(distances.view(), y)?;
        let dydx = shepard_pairs(distances.view(), y, 20_000, 1)?;
        laps.lap("embed");
        let set_poses = exploration
            .planar_poses()
            .expect("the built-in agents have planar poses")
            .select(Axis(0), &traced.kept);
        let analysis = analyze(
            &distances,
            Some(set_poses.view()),
            &AnalysisParams::default().check()?,
            &Silent,
        )?;
        laps.lap("analyze");
        let invariance = invariance_data(
            agent.as_ref(),
            &environments,
            &exploration,
            args.babbled,
            &metric,
        )?;
        laps.lap("invariance");
        let manifolds = sensory_manifolds(agent.as_ref(), &environments);
        Ok(Self {
            agent,
            environments,
            exploration,
            traced,
            embedded,
            quality,
            dydx,
            analysis,
            invariance,
            manifolds,
            stages: laps.stages,
        })
    }
}

/// Trustworthiness, continuity and stress of the embedding `y`, as in `Y.embed.json`.
fn embedding_quality(
    distances: ArrayView2<'_, f64>,
    y: ArrayView2<'_, f64>,
) -> DemoResult<serde_json::Value> {
    let (trust, cont) = trustworthiness_continuity(distances, y, 10)?;
    let (raw_stress, normalized_stress) = stress(distances, y)?;
    Ok(serde_json::json!({
        "trustworthiness": trust,
        "continuity": cont,
        "stress": raw_stress,
        "normalized_stress": normalized_stress,
    }))
}

/// Invariance on the first babbled rows, traced with the sensory method: the numbers,
/// and for the rows traced in every environment their set distances and sensor values.
fn invariance_data(
    agent: &dyn Agent,
    environments: &[Environment],
    exploration: &Exploration,
    babbled: usize,
    metric: &DistanceParams,
) -> DemoResult<InvarianceData> {
    let rows = 40.min(babbled);
    let starts = exploration.motors.slice_axis(Axis(0), (0..rows).into());
    let sensory = TraceParams {
        method: TraceMethod::Sensory,
        ..TraceParams::default()
    }
    .check()?;
    let report = invariance(
        agent,
        starts,
        environments,
        exploration.workspace.as_ref(),
        &sensory,
        smspace::invariance::agent_metric(smspace::metric::MetricKind::Hausdorff, agent).as_ref(),
        &Silent,
    )?;
    let per_env = environments
        .iter()
        .map(|env| {
            trace_sets(
                agent,
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
    for (t, env) in per_env.iter().zip(environments) {
        let at: Vec<usize> = common
            .iter()
            .map(|r| t.kept.binary_search(r).unwrap_or(0))
            .collect();
        set_distances.push(
            distance_matrix(t.sets.select(Axis(0), &at).view(), metric, &Silent)?.into_array(),
        );
        let mut s = Array2::zeros((common.len(), agent.sensor_dim()));
        for (k, &r) in common.iter().enumerate() {
            let m = starts.row(r).to_vec();
            let mut out = vec![0.0; agent.sensor_dim()];
            agent.sense(env, &m, &mut out);
            s.row_mut(k).assign(&ndarray::ArrayView1::from(&out));
        }
        sensors.push(s);
    }
    Ok(InvarianceData {
        report,
        set_distances,
        sensors,
    })
}

/// Sensory manifolds of a one-motor agent: a sweep of its motor range (none for other
/// agents).
fn sensory_manifolds(agent: &dyn Agent, environments: &[Environment]) -> Vec<SensoryManifold> {
    if agent.motor_dim() != 1 {
        return Vec::new();
    }
    let (lo, hi) = agent.motor_space().motor(0).range();
    let t = 400;
    let motors = Array2::from_shape_fn((t, 1), |(i, _)| lo + (hi - lo) * i as f64 / (t - 1) as f64);
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
}

/// Writes the report three times into `out`, lists its figures and prints the median
/// wall time and the CPU time per report.
fn time_reports(inputs: &ReportInputs<'_>, out: &Path) -> DemoResult<()> {
    let params = ReportParams::default();
    let mut times = Vec::new();
    let mut summary = None;
    let cpu_start = cpu_seconds();
    for _ in 0..3 {
        let start = Instant::now();
        summary = Some(write_report(inputs, &params, out)?);
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
    for w in &summary.warnings {
        eprintln!("warning ({}): {}", w.stage, w.message);
    }
    // The reviewer's check: no two texts of any figure overlap, none leaves its figure.
    let problems: Vec<String> = figure_texts(inputs, &params)?
        .iter()
        .flat_map(|f| f.problems())
        .collect();
    for p in &problems {
        eprintln!("layout: {p}");
    }
    println!("{} layout problems in the figures", problems.len());
    println!(
        "{} sets x {} points: write_report took {:.3} s wall (median of 3; min {:.3} s), {} CPU per report",
        inputs.sets.len_of(Axis(0)),
        inputs.sets.len_of(Axis(1)),
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
