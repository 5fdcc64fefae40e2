//! Kernel sets learned from a simulated log of the paper's arm, measured against the
//! true (kinematic) sets: `cargo run --release --example learn_study -- S NOISE METHOD
//! STARTS` prints one JSON line (held-out error, set errors, timings, and the angle
//! between the learned and the true kernel direction at 200 log samples).

use std::time::Instant;

use rand::rngs::ChaCha8Rng;
use rand::seq::index::sample;
use rand::SeedableRng;
use smspace::agent::{AgentConfig, EnvironmentConfig};
use smspace::kernel::{trace_sets, TraceParams};
use smspace::learn::{
    learn, set_errors, simulate, trace_learned, LawParams, LogFiles, SensorimotorLog,
    SimulateParams,
};
use smspace::metric::Period;
use smspace::progress::Silent;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let samples: usize = args.get(1).map_or(Ok(100_000), |s| s.parse())?;
    let noise: f64 = args.get(2).map_or(Ok(0.0), |s| s.parse())?;
    let method = args
        .get(3)
        .map_or("local-quadratic", String::as_str)
        .parse()?;
    let starts: usize = args.get(4).map_or(Ok(100), |s| s.parse())?;
    let arm = AgentConfig::preset("planar-arm")?.build()?;
    let environment = EnvironmentConfig::default().build(arm.as_ref())?;
    let clock = Instant::now();
    let log = simulate(
        arm.as_ref(),
        &environment,
        arm.default_workspace(),
        &SimulateParams {
            samples,
            noise,
            seed: 1,
            ..SimulateParams::default()
        },
    )?;
    let simulated = clock.elapsed().as_secs_f64();
    let space = arm.motor_space();
    let files = LogFiles {
        motors: "simulated-motors".into(),
        sensors: "simulated-sensors".into(),
    };
    let checked = SensorimotorLog::new(log.motors.clone(), log.sensors.clone(), files, &space)?;
    let clock = Instant::now();
    let params = LawParams {
        method,
        ..LawParams::default()
    }
    .check()?;
    let law = learn(&[checked], &space, &params, None)?;
    let learned_seconds = clock.elapsed().as_secs_f64();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let rows = sample(&mut rng, samples, starts.min(samples)).into_vec();
    let start_motors = log.motors.select(ndarray::Axis(0), &rows);
    let clock = Instant::now();
    let trace_params = trace_params_from_env()?;
    let learned = trace_learned(&law, start_motors.view(), &trace_params, &Silent)?;
    let traced_seconds = clock.elapsed().as_secs_f64();
    let truth_params = TraceParams::default().check()?;
    let truth = trace_sets(
        arm.as_ref(),
        Some(&environment),
        start_motors.view(),
        None,
        &truth_params,
        &Silent,
    )?;
    let errors = set_errors(&learned, &truth, Period::TwoPi).ok();
    // The learned manifold: the Hausdorff matrix of the learned sets, its topology and
    // dimension, and its agreement with the poses the simulated log kept aside; the same
    // for the true sets through the same starts, for comparison.
    let poses = log
        .poses
        .as_ref()
        .map(|p| p.poses().select(ndarray::Axis(0), &rows));
    let manifold_of = |traced: &smspace::kernel::TracedSets| -> Result<serde_json::Value, Box<dyn std::error::Error>> {
        let distances = smspace::metric::distance_matrix(
            traced.sets.view(),
            &smspace::metric::DistanceParams::new()
                .metric(smspace::metric::MetricKind::Hausdorff),
            &Silent,
        )?;
        let kept_poses = poses
            .as_ref()
            .map(|p| p.select(ndarray::Axis(0), &traced.kept));
        let params = smspace::analysis::AnalysisParams::default().check()?;
        let report = smspace::analysis::analyze(
            &distances,
            kept_poses.as_ref().map(|p| p.view()),
            &params,
            &Silent,
        )?;
        Ok(serde_json::json!({
            "sets": traced.kept.len(),
            "betti": report.betti,
            "twonn": report.intrinsic_dimension.twonn,
            "trustworthiness": report.agreement.as_ref().map(|a| a.trustworthiness),
            "continuity": report.agreement.as_ref().map(|a| a.continuity),
        }))
    };
    let wanted = std::env::var("MANIFOLD").is_ok();
    let manifold = if wanted && learned.kept.len() > 20 {
        manifold_of(&learned)?
    } else {
        serde_json::Value::Null
    };
    let truth_manifold = if wanted && truth.kept.len() > 20 {
        manifold_of(&truth)?
    } else {
        serde_json::Value::Null
    };
    let tangent_angles = tangent_angles(&law, arm.as_ref(), log.motors.view(), 200);
    let line = serde_json::json!({
        "tangent_angle_rad": tangent_angles,
        "manifold": manifold,
        "truth_manifold": truth_manifold,
        "samples": samples,
        "noise": noise,
        "method": method,
        "simulate_s": simulated,
        "learn_s": learned_seconds,
        "trace_s": traced_seconds,
        "starts": starts,
        "law": law.report(),
        "learned_status": learned.report.summary.by_status,
        "truth_status": truth.report.summary.by_status,
        "median_rad": errors.as_ref().map(|e| e.median),
        "p90_rad": errors.as_ref().map(|e| e.p90),
        "compared": errors.as_ref().map(|e| e.compared),
    });
    println!("{line}");
    Ok(())
}

/// The learned law's tracing parameters, with `SENSOR_TOLERANCE`, `CLOSURE` and
/// `MAX_STEPS` from the environment when set.
fn trace_params_from_env() -> Result<TraceParams, Box<dyn std::error::Error>> {
    let tolerance: f64 = std::env::var("SENSOR_TOLERANCE")
        .map_or(Ok(smspace::learn::LAW_SENSOR_TOLERANCE), |s| s.parse())?;
    let closure: f64 = std::env::var("CLOSURE").map_or(Ok(3e-2), |s| s.parse())?;
    let max_steps: usize = std::env::var("MAX_STEPS").map_or(Ok(3000), |s| s.parse())?;
    Ok(TraceParams {
        sensor_tolerance: tolerance,
        closure_tolerance: closure,
        max_steps,
        ..smspace::learn::law_trace_params()
    })
}

/// The angle (radians) between the learned kernel direction (the right singular vector
/// of the law's Jacobian with the smallest singular value) and the true one (the null
/// vector of the arm's pose Jacobian, by central differences) at `count` seeded log
/// samples: median and 90th percentile.
fn tangent_angles(
    law: &smspace::learn::LearnedLaw,
    arm: &dyn smspace::agent::Agent,
    motors: ndarray::ArrayView2<'_, f64>,
    count: usize,
) -> serde_json::Value {
    use smspace::agent::Agent as _;
    let Some(observer) = arm.ground_truth() else {
        return serde_json::Value::Null;
    };
    let n = law.motor_dim();
    let k = law.sensor_dim();
    let d = observer.pose_space().dim();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let rows = sample(&mut rng, motors.nrows(), count.min(motors.nrows())).into_vec();
    let smallest = |matrix: Vec<f64>, r: usize| {
        let a = nalgebra::DMatrix::from_row_slice(r, n, &matrix);
        let gram = a.transpose() * a;
        let eigen = nalgebra::SymmetricEigen::new(gram);
        let i = eigen.eigenvalues.imin();
        eigen.eigenvectors.column(i).into_owned()
    };
    let mut angles: Vec<f64> = rows
        .iter()
        .map(|&row| {
            let m: Vec<f64> = motors.row(row).to_vec();
            let mut s = vec![0.0; k];
            let mut j = vec![0.0; k * n];
            law.evaluate_with_jacobian(&m, &mut s, &mut j);
            let learned = smallest(j, k);
            let mut pose_jacobian = vec![0.0; d * n];
            let (mut plus, mut minus) = (vec![0.0; d], vec![0.0; d]);
            let h = 1e-6;
            for c in 0..n {
                let mut a = m.clone();
                a[c] += h;
                observer.pose(&a, &mut plus);
                a[c] -= 2.0 * h;
                observer.pose(&a, &mut minus);
                for r in 0..d {
                    pose_jacobian[r * n + c] = (plus[r] - minus[r]) / (2.0 * h);
                }
            }
            let truth = smallest(pose_jacobian, d);
            learned.dot(&truth).abs().min(1.0).acos()
        })
        .collect();
    angles.sort_by(f64::total_cmp);
    let at = |q: f64| angles[((angles.len() - 1) as f64 * q).round() as usize];
    serde_json::json!({ "median": at(0.5), "p90": at(0.9) })
}
