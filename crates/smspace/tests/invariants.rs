//! The `invariants` law (`smspace::learn`, method `invariants`): the functions of the
//! motors that sensory neighbours share, against cases whose invariants are known, and
//! the paper's arm against its true kernels.

use std::path::PathBuf;

use ndarray::{Array2, Axis};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::agent::{Agent, AgentConfig, Environment, EnvironmentConfig, MotorSpace};
use smspace::kernel::{trace_sets, SetStatus, TraceParams};
use smspace::learn::{
    law_trace_params, learn, set_errors, simulate, trace_learned, LawMethod, LawParams, LearnedLaw,
    LogFiles, RankSource, SensorimotorLog, SimulateParams,
};
use smspace::metric::Period;
use smspace::progress::Silent;

fn files() -> LogFiles {
    LogFiles {
        motors: PathBuf::from("m.npy"),
        sensors: PathBuf::from("s.npy"),
    }
}

fn invariants() -> LawParams {
    LawParams {
        method: LawMethod::Invariants,
        ..LawParams::default()
    }
}

/// Two bounded motors in `[-1.5, 1.5]` whose sensors see `x = m1 + m2` only: the
/// redundant toy's kernels, the lines `m1 + m2 = const`.
fn sum_log(samples: usize) -> (MotorSpace, SensorimotorLog) {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let motors = Array2::from_shape_fn((samples, 2), |_| rng.random_range(-1.5..1.5));
    let sensors = Array2::from_shape_fn((samples, 2), |(i, k)| {
        let x: f64 = motors[[i, 0]] + motors[[i, 1]];
        if k == 0 {
            (0.8 * x).sin()
        } else {
            (0.8 * x).cos() + 0.2 * x
        }
    });
    let space = MotorSpace::bounded(2, -1.5, 1.5).unwrap();
    let log = SensorimotorLog::new(motors, sensors, files(), &space).unwrap();
    (space, log)
}

#[test]
fn the_invariant_of_a_redundant_sum_is_the_sum_and_its_level_sets_are_the_kernels() {
    let (space, log) = sum_log(5000);
    let law = learn(&[log], &space, &invariants().check().unwrap(), None).unwrap();
    let report = law.report();
    let found = report.invariants.as_ref().expect("the invariants' report");
    // x and x² are both in the basis (products of 1, u, 2u² − 1) and both exact; every
    // other combination changes along the lines.
    assert_eq!((found.features, found.invariants), (8, 2), "{report:?}");
    assert!(
        found.eigenvalues[1] < 1e-3 && found.eigenvalues[2] > 0.1,
        "{found:?}"
    );
    let held_lambda = found.held_out_lambda.unwrap();
    assert!(held_lambda < 1e-3, "{found:?}");
    assert_eq!(report.rank, 1, "{report:?}");
    // ŝ = g(z) predicts the held-out sensors: z tells the sums apart.
    let held = &report.logs[0];
    assert!(held.held_out_relative_rms < 0.02, "{held:?}");
    // z is constant along m1 + m2 = c and changes across.
    let unused = Environment::from_lights(Vec::new());
    let z = |m: [f64; 2]| {
        let mut z = [0.0; 2];
        law.sense(&unused, &m, &mut z);
        z
    };
    let gap = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    for c in [-1.0, 0.2, 1.1] {
        let at = z([c / 2.0, c / 2.0]);
        for a in [-0.4, 0.1, 0.5] {
            let along = z([c / 2.0 + a, c / 2.0 - a]);
            assert!(gap(along, at) < 1e-3, "{c} {a}: {along:?} vs {at:?}");
        }
        assert!(gap(z([c / 2.0 + 0.2, c / 2.0]), at) > 0.05);
    }
    // The traced sets lie on their lines.
    let starts = ndarray::array![[0.3, -0.5], [-1.0, 0.4], [0.9, 0.3]];
    let traced = trace_learned(&law, starts.view(), &law_trace_params(), &Silent).unwrap();
    assert_eq!(traced.kept, vec![0, 1, 2], "{:?}", traced.report.summary);
    for (set, start) in traced.sets.outer_iter().zip(starts.outer_iter()) {
        let c = start[0] + start[1];
        let mut span: f64 = 0.0;
        for point in set.outer_iter() {
            assert!(
                (point[0] + point[1] - c).abs() < 2e-3,
                "{point} off m1 + m2 = {c}"
            );
            span = span.max((point[0] - start[0]).abs());
        }
        assert!(span > 0.3, "a set reaches along its line: {span}");
    }
    assert!(traced
        .report
        .sets
        .iter()
        .all(|s| s.status != SetStatus::Closed));
}

/// `log` with the rows `rows` recorded again after it: the same motor commands, the
/// sensors plus noise of standard deviation `noise` (0: the same readings).
fn with_repeats(log: &SensorimotorLog, rows: &[usize], noise: f64, seed: u64) -> SensorimotorLog {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let motors = ndarray::concatenate![Axis(0), log.motors, log.motors.select(Axis(0), rows)];
    let mut again = log.sensors.select(Axis(0), rows);
    again.mapv_inplace(|v| v + noise * (rng.random::<f64>() - 0.5) * 12f64.sqrt());
    let sensors = ndarray::concatenate![Axis(0), log.sensors, again];
    let space = MotorSpace::bounded(2, -1.5, 1.5).unwrap();
    SensorimotorLog::new(motors, sensors, files(), &space).unwrap()
}

/// The largest distance of a traced point from its start's line `m1 + m2 = c`, over
/// the sets of `law` through `starts`, and the sets kept.
fn sum_line_error(law: &LearnedLaw, starts: &Array2<f64>) -> (f64, usize) {
    let traced = trace_learned(law, starts.view(), &law_trace_params(), &Silent).unwrap();
    let mut worst: f64 = 0.0;
    for (set, &row) in traced.sets.outer_iter().zip(&traced.kept) {
        let c = starts[[row, 0]] + starts[[row, 1]];
        for point in set.outer_iter() {
            worst = worst.max((point[0] + point[1] - c).abs());
        }
    }
    (worst, traced.kept.len())
}

#[test]
fn repeated_samples_are_learned_from_once_and_counted() {
    // A robot that holds still records a sample again: every row twice, or half the
    // rows again with fresh sensor noise. A repeat's nearest sensory neighbour is its
    // own twin, a pair no function of the motors changes across; left in, every
    // eigenvalue falls to zero and every function passes for an invariant.
    let (space, log) = sum_log(3000);
    let params = invariants().check().unwrap();
    let starts = ndarray::array![[0.3, -0.5], [-1.0, 0.4], [0.9, 0.3]];
    let clean = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
    let clean_count = clean.report().invariants.as_ref().unwrap().invariants;
    let (clean_error, clean_kept) = sum_line_error(&clean, &starts);
    assert_eq!(clean.report().logs[0].repeated, 0);
    let every: Vec<usize> = (0..3000).collect();
    let half: Vec<usize> = (0..3000).step_by(2).collect();
    for (repeated, noise) in [
        (with_repeats(&log, &every, 0.0, 1), 0.0),
        (with_repeats(&log, &half, 1e-3, 2), 1e-3),
    ] {
        let law = learn(std::slice::from_ref(&repeated), &space, &params, None).unwrap();
        let report = law.report();
        let found = report.invariants.as_ref().unwrap();
        let expected = repeated.samples() - 3000;
        assert_eq!(report.logs[0].repeated, expected, "noise {noise}");
        assert_eq!(report.logs[0].samples, repeated.samples());
        assert_eq!(found.invariants, clean_count, "noise {noise}: {found:?}");
        assert!(found.eigenvalues[2] > 0.1, "noise {noise}: {found:?}");
        assert!(
            report
                .warnings
                .iter()
                .any(|w| w.contains(&format!("{expected} of"))
                    && w.contains("repeat an earlier sample's motor command")),
            "{:?}",
            report.warnings
        );
        let (error, kept) = sum_line_error(&law, &starts);
        assert_eq!(kept, clean_kept);
        assert!(
            error < clean_error + 2e-3,
            "noise {noise}: {error} rad from the lines, {clean_error} without repeats"
        );
    }
}

/// The paper's arm from a simulated log of 50 000 samples (no noise): the invariants
/// give the sets' dimension (rank 3, one-dimensional kernels) and sets within a tenth
/// of a radian of the true ones (curve metric). At 10⁶ samples the README measures
/// 0.02 rad; the local quadratic law's sets are about 4 rad off at every S.
/// 50 000 exact samples of `arm` babbled in its working space among the default lights:
/// its `invariants` law, the samples of `rows` (the starts) and the environment.
fn learned_from_simulated(
    arm: &dyn Agent,
    rows: &[usize],
) -> (LearnedLaw, Array2<f64>, Environment) {
    let environment = EnvironmentConfig::default().build(arm).unwrap();
    let params = SimulateParams {
        samples: 50_000,
        noise: 0.0,
        seed: 1,
        ..SimulateParams::default()
    };
    let simulated = simulate(arm, &environment, arm.default_workspace(), &params).unwrap();
    let space = arm.motor_space();
    let starts = simulated.motors.select(Axis(0), rows);
    let log = SensorimotorLog::new(simulated.motors, simulated.sensors, files(), &space).unwrap();
    let law = learn(&[log], &space, &invariants().check().unwrap(), None).unwrap();
    (law, starts, environment)
}

#[test]
fn the_arm_learned_through_its_invariants_traces_sets_near_the_true_ones() {
    let arm = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let (law, starts, environment) =
        learned_from_simulated(arm.as_ref(), &[3, 500, 9000, 15000, 30000, 41000]);
    let report = law.report();
    let found = report.invariants.as_ref().unwrap();
    assert_eq!(report.rank, 3, "{report:?}");
    assert!(found.invariants >= 4, "{found:?}");
    // The invariants generalise: their change between held-out sensory neighbours is
    // close to that on the fitted pairs, far below 2 (unrelated values).
    let held_lambda = found.held_out_lambda.unwrap();
    assert!(held_lambda < 2.0 * found.fitted_lambda + 0.05, "{found:?}");
    let learned = trace_learned(&law, starts.view(), &law_trace_params(), &Silent).unwrap();
    let truth = trace_sets(
        arm.as_ref(),
        Some(&environment),
        starts.view(),
        None,
        &TraceParams::default().check().unwrap(),
        &Silent,
    )
    .unwrap();
    assert!(learned.kept.len() >= 5, "{:?}", learned.report.summary);
    let errors = set_errors(&learned, &truth, Period::TwoPi).unwrap();
    assert!(errors.compared >= 5 && errors.median < 0.1, "{errors:?}");
}

#[test]
fn impossible_invariant_parameters_and_logs_are_refused_with_the_fix() {
    for (count, threshold) in [
        (Some(0), 0.4),
        (Some(33), 0.4),
        (None, 0.0),
        (None, f64::NAN),
    ] {
        let e = LawParams {
            invariants: count,
            invariance_threshold: threshold,
            ..invariants()
        }
        .check()
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("invariants") || e.contains("invariance_threshold"),
            "{e}"
        );
    }
    // Eight motors: 6560 basis functions, more than the method takes.
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let motors: Array2<f64> = Array2::from_shape_fn((3000, 8), |_| rng.random_range(-3.0..3.0));
    let sensors = Array2::from_shape_fn((3000, 2), |(i, k)| motors[[i, k]].sin());
    let space = MotorSpace::hinges(8);
    let log = SensorimotorLog::new(motors.clone(), sensors.clone(), files(), &space).unwrap();
    let e = learn(&[log], &space, &invariants().check().unwrap(), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("6560")
            && e.contains("at most 2186 (7 motors)")
            && e.contains("local-quadratic"),
        "{e}"
    );
    // Seven motors whose eigenproblem does not fit in the memory allowed: the error
    // names the basis and the fix.
    let space = MotorSpace::hinges(7);
    let motors = Array2::from_shape_fn((3000, 7), |(i, j)| motors[[i, j]]);
    let log = SensorimotorLog::new(motors, sensors, files(), &space).unwrap();
    let e = learn(
        &[log],
        &space,
        &invariants().check().unwrap(),
        Some(100 << 20),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("the limit is 100") && e.contains("F × F") && e.contains("--max-memory"),
        "{e}"
    );
    // Too few samples for the 8 functions of two motors.
    let (space, log) = sum_log(60);
    let e = learn(&[log], &space, &invariants().check().unwrap(), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("m.npy has too few samples (60)") && e.contains("at least 90"),
        "{e}"
    );
    // No invariant below the threshold.
    let (space, log) = sum_log(2000);
    let e = learn(
        &[log],
        &space,
        &LawParams {
            invariance_threshold: 1e-9,
            ..invariants()
        }
        .check()
        .unwrap(),
        None,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("raise invariance_threshold"), "{e}");
}

#[test]
fn learning_the_invariants_is_the_same_for_one_thread_and_many() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (space, log) = sum_log(30_000);
            let law = learn(&[log], &space, &invariants().check().unwrap(), None).unwrap();
            let mut z = [0.0; 2];
            law.sense(&Environment::from_lights(Vec::new()), &[0.3, -0.8], &mut z);
            (format!("{:?}", law.report()), z)
        })
    };
    assert_eq!(run(1), run(3));
}

/// An arm whose six cells have cosine tuning: poses far apart often read nearly the
/// same values (a cell's blind band), so about a fifth of the nearest sensory pairs are
/// aliased. Set aside, they leave the pose's functions with `λ` far below the rest, and
/// the traced sets follow the true ones.
#[test]
fn aliased_sensory_pairs_are_set_aside_and_the_pose_functions_stand_out() {
    let arm: AgentConfig =
        toml::from_str("kind = \"planar-arm\"\n[retina]\ntuning = \"cosine\"\n").unwrap();
    let arm = arm.build().unwrap();
    let environment = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let simulated = simulate(
        arm.as_ref(),
        &environment,
        arm.default_workspace(),
        &SimulateParams {
            samples: 60_000,
            noise: 0.0,
            seed: 3,
            ..SimulateParams::default()
        },
    )
    .unwrap();
    let space = arm.motor_space();
    let starts = simulated
        .motors
        .select(Axis(0), &[7, 800, 9000, 21000, 40000, 52000]);
    let log = SensorimotorLog::new(simulated.motors, simulated.sensors, files(), &space).unwrap();
    let law = learn(&[log], &space, &LawParams::default().check().unwrap(), None).unwrap();
    let found = law.report().invariants.clone().unwrap();
    assert!(
        found.kept_pairs < found.pairs * 19 / 20 && 2 * found.kept_pairs >= found.pairs,
        "{found:?}"
    );
    let count = found.invariants;
    assert!(count >= 4, "{found:?}");
    assert!(
        found.eigenvalues[count - 1] < 0.1 && found.eigenvalues[count] > 0.3,
        "{found:?}"
    );
    let learned = trace_learned(&law, starts.view(), &law_trace_params(), &Silent).unwrap();
    let truth = trace_sets(
        arm.as_ref(),
        Some(&environment),
        starts.view(),
        None,
        &TraceParams::default().check().unwrap(),
        &Silent,
    )
    .unwrap();
    let errors = set_errors(&learned, &truth, Period::TwoPi).unwrap();
    assert!(errors.compared >= 4 && errors.median < 0.1, "{errors:?}");
}

/// A planar chain of six hinges (links 1.0, 0.9, …, 0.5) whose sensors read the pose
/// of its end, `(x, y, cos α, sin α)`: 12 000 samples, and the poses (the sensors).
fn chain_6_log() -> (SensorimotorLog, Array2<f64>) {
    let samples = 12_000;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let motors = Array2::from_shape_fn((samples, 6), |_| {
        rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)
    });
    let sensors = Array2::from_shape_fn((samples, 4), |(i, k)| {
        let (mut x, mut y, mut alpha) = (0.0, 0.0, 0.0);
        for j in 0..6 {
            alpha += motors[[i, j]];
            let length = 1.0 - 0.1 * j as f64;
            x += length * f64::cos(alpha);
            y += length * f64::sin(alpha);
        }
        [x, y, alpha.cos(), alpha.sin()][k]
    });
    let poses = sensors.clone();
    let log = SensorimotorLog::new(motors, sensors, files(), &MotorSpace::hinges(6)).unwrap();
    (log, poses)
}

/// Six motors (728 basis functions) from a short log: the invariants are functions of
/// the chain's pose (they differ little between samples of nearly the same pose, and
/// as little between held-out sensory neighbours as between fitted ones), their
/// Jacobian is the derivative of their values, and one thread learns what two do.
#[test]
fn the_invariants_of_a_six_hinge_chain_are_functions_of_its_pose() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (log, poses) = chain_6_log();
            let motors = log.motors.clone();
            let space = MotorSpace::hinges(6);
            // 12 000 samples in six dimensions: the 4th nearest sample (not the 40th)
            // lies within a quarter period, as the coverage needs.
            let params = LawParams {
                neighbours: Some(4),
                ..invariants()
            };
            let law = learn(&[log], &space, &params.check().unwrap(), None).unwrap();
            (law, motors, poses)
        })
    };
    let (law, motors, poses) = run(1);
    let (other, _, _) = run(2);
    assert_eq!(
        format!("{:?}", law.report()),
        format!("{:?}", other.report())
    );
    let report = law.report();
    let found = report.invariants.as_ref().unwrap();
    assert_eq!(found.features, 728);
    // The law's Jacobian has the rank of the pose (x, y, α) nearly everywhere.
    let mode = (0..report.rank_counts.len())
        .max_by_key(|&r| report.rank_counts[r])
        .unwrap();
    assert_eq!(mode, 3, "{report:?}");
    assert!(found.invariants >= 3, "{found:?}");
    let held_lambda = found.held_out_lambda.unwrap();
    assert!(
        found.fitted_lambda < 0.4 && held_lambda < 2.0 * found.fitted_lambda + 0.05,
        "{found:?}"
    );
    // Every 40th sample and the sample nearest to it in pose: z differs by a small part of its spread (Var z = 1 over the fitted
    // samples; for unrelated values the mean square is 2).
    let count = found.invariants;
    let unused = Environment::from_lights(Vec::new());
    let z = |m: &[f64]| {
        let mut z = vec![0.0; count];
        law.sense(&unused, m, &mut z);
        z
    };
    let (mut change, mut pairs) = (0.0, 0);
    for i in (0..motors.nrows()).step_by(40) {
        let gap = |j: usize| {
            poses
                .row(i)
                .iter()
                .zip(poses.row(j))
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
        };
        let j = (0..motors.nrows())
            .filter(|&j| j != i)
            .min_by(|&a, &b| gap(a).total_cmp(&gap(b)))
            .unwrap();
        let (a, b) = (
            z(motors.row(i).as_slice().unwrap()),
            z(motors.row(j).as_slice().unwrap()),
        );
        change += a.iter().zip(&b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / count as f64;
        pairs += 1;
    }
    let change = change / pairs as f64;
    assert!(
        change < 0.2,
        "mean squared change between pose neighbours {change}"
    );
    // The exact Jacobian against central differences.
    let m = [0.4, -1.2, 2.0, 0.7, -2.5, 1.1];
    let mut value = vec![0.0; count];
    let mut jacobian = vec![0.0; count * 6];
    assert!(law.sense_with_jacobian(&unused, &m, &mut value, &mut jacobian));
    assert_eq!(value, z(&m));
    for j in 0..6 {
        let (mut plus, mut minus) = (m, m);
        plus[j] += 1e-6;
        minus[j] -= 1e-6;
        let (a, b) = (z(&plus), z(&minus));
        for c in 0..count {
            let numeric = (a[c] - b[c]) / 2e-6;
            assert!(
                (numeric - jacobian[c * 6 + j]).abs() < 1e-5 * (1.0 + numeric.abs()),
                "∂z{c}/∂m{j}: {numeric} vs {}",
                jacobian[c * 6 + j]
            );
        }
    }
}

/// A four-link planar arm (five hinges, the retina's pose 3-D, so the kernels are
/// surfaces): across the neighbourhoods of 50 000 samples in five motors the sensors'
/// affine slopes pick up their curvature, a fourth direction of change, while the nine
/// invariants change along three at every probed sample. The law is traced at the
/// invariants' rank, and every point of its sets holds the retina where the start does.
#[test]
fn a_five_hinge_arm_is_traced_at_the_rank_of_its_invariants() {
    let arm = AgentConfig {
        kind: "planar-arm".into(),
        params: toml::from_str("link_lengths = [1.0, 1.0, 1.0, 1.0]").unwrap(),
    }
    .build()
    .unwrap();
    let (law, starts, _) = learned_from_simulated(arm.as_ref(), &[3, 9000, 30000]);
    let report = law.report();
    assert_eq!(report.rank, 3, "{report:?}");
    assert_eq!(
        report.rank_counts[3],
        report.rank_counts.iter().sum::<usize>()
    );
    let data = report.data_rank.as_ref().expect("the data's rank");
    if data.rank > 3 {
        assert_eq!(report.rank_source, RankSource::Invariants, "{report:?}");
    }
    let learned = trace_learned(&law, starts.view(), &law_trace_params(), &Silent).unwrap();
    assert_eq!(learned.kept.len(), 3, "{:?}", learned.report.summary);
    assert_eq!(learned.dimensions(), vec![2, 2, 2]);
    // Surfaces have no closure rate, and no warning about one.
    assert_eq!(learned.report.summary.closure_rate, None);
    let completed = report.with_trace(&learned.report.summary);
    assert!(
        completed.warnings.iter().all(|w| !w.contains("closed")),
        "{:?}",
        completed.warnings
    );
    // The retina's pose along every set against the start's: position (x, y) and
    // orientation (wrapped).
    let truth = arm.ground_truth().unwrap();
    let mut worst: (f64, f64) = (0.0, 0.0);
    for (set, &row) in learned.sets.outer_iter().zip(&learned.kept) {
        let mut start = vec![0.0; 3];
        truth.pose(starts.row(row).as_slice().unwrap(), &mut start);
        for point in set.outer_iter() {
            let mut pose = vec![0.0; 3];
            truth.pose(point.to_vec().as_slice(), &mut pose);
            let position = ((pose[0] - start[0]).powi(2) + (pose[1] - start[1]).powi(2)).sqrt();
            let turn = (pose[2] - start[2] + std::f64::consts::PI)
                .rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            worst = (worst.0.max(position), worst.1.max(turn.abs()));
        }
    }
    // Measured: 0.020 and 0.013 rad (a law traced at the data's rank 4 traced curves
    // where its Jacobian is singular, and failed).
    assert!(worst.0 < 0.1 && worst.1 < 0.1, "{worst:?}");
}
