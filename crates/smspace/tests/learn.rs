//! Kernel sets from recorded data (the `learn` module): logs checked where they enter,
//! the learned law against known functions, coverage (`left-data`), and the sets of a
//! simulated agent against the true ones.

use std::f64::consts::PI;
use std::path::PathBuf;

use ndarray::{Array2, Axis};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::agent::{Agent, AgentConfig, Environment, EnvironmentConfig, MotorSpace};
use smspace::kernel::{trace_sets, SetStatus, TraceParams};
use smspace::learn::{
    learn, set_errors, simulate, trace_learned, LawMethod, LawParams, LearnError, LogFiles,
    SensorimotorLog, SimulateParams,
};
use smspace::metric::Period;
use smspace::progress::Silent;

/// The first `count` rows of `a`.
fn first_rows(a: &Array2<f64>, count: usize) -> Array2<f64> {
    a.select(ndarray::Axis(0), &(0..count).collect::<Vec<_>>())
}

/// The local quadratic law: these tests measure the local laws (the default,
/// `invariants`, is tested in `tests/invariants.rs`).
fn local_quadratic() -> LawParams {
    LawParams {
        method: LawMethod::LocalQuadratic,
        ..LawParams::default()
    }
}

#[test]
fn the_default_law_is_the_invariants() {
    assert_eq!(LawParams::default().method, LawMethod::Invariants);
}

fn files() -> LogFiles {
    LogFiles {
        motors: PathBuf::from("m.npy"),
        sensors: PathBuf::from("s.npy"),
    }
}

/// `S` uniform hinge samples of two motors, `m1` in `[low1, high1)`, and the sensors
/// `f(m)`.
fn hinge_log(
    samples: usize,
    low1: f64,
    high1: f64,
    f: impl Fn(f64, f64) -> Vec<f64>,
) -> (Array2<f64>, Array2<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let motors = Array2::from_shape_fn((samples, 2), |(_, j)| {
        if j == 0 {
            rng.random_range(low1..high1)
        } else {
            rng.random_range(-PI..PI)
        }
    });
    let k = f(0.0, 0.0).len();
    let mut sensors = Array2::zeros((samples, k));
    for (m, mut s) in motors.outer_iter().zip(sensors.outer_iter_mut()) {
        for (a, b) in s.iter_mut().zip(f(m[0], m[1])) {
            *a = b;
        }
    }
    (motors, sensors)
}

fn smooth(m1: f64, m2: f64) -> Vec<f64> {
    vec![m1.sin() + 0.5 * m2.cos(), (m1 + m2).cos(), 0.3 * m2.sin()]
}

#[test]
fn the_law_fits_a_smooth_function_across_the_wrap() {
    let (motors, sensors) = hinge_log(6000, -PI, PI, smooth);
    let space = MotorSpace::hinges(2);
    let log = SensorimotorLog::new(motors, sensors, files(), &space).unwrap();
    let unused = Environment::from_lights(Vec::new());
    let mut errors = Vec::new();
    for method in [LawMethod::LocalLinear, LawMethod::LocalQuadratic] {
        let params = LawParams {
            method,
            ..LawParams::default()
        }
        .check()
        .unwrap();
        let law = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        let report = &law.report().logs[0];
        assert_eq!(report.held_out, 600);
        assert!(report.held_out_relative_rms < 0.05, "{report:?}");
        // Near the wrap (m = ±π) as well as inside, and continuous across it.
        let mut largest: f64 = 0.0;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..200 {
            let m = [rng.random_range(-PI..PI), rng.random_range(-PI..PI)];
            let mut s = [0.0; 3];
            law.sense(&unused, &m, &mut s);
            for (a, b) in s.iter().zip(smooth(m[0], m[1])) {
                largest = largest.max((a - b).abs());
            }
        }
        let (mut below, mut above) = ([0.0; 3], [0.0; 3]);
        law.sense(&unused, &[PI - 1e-9, 0.4], &mut below);
        law.sense(&unused, &[-PI + 1e-9, 0.4], &mut above);
        for (a, b) in below.iter().zip(above) {
            assert!((a - b).abs() < 1e-6, "{below:?} vs {above:?}");
        }
        // The same values as unwrapped configurations.
        let mut shifted = [0.0; 3];
        law.sense(
            &unused,
            &[PI - 1e-9 + 4.0 * PI, 0.4 - 2.0 * PI],
            &mut shifted,
        );
        for (a, b) in below.iter().zip(shifted) {
            assert!((a - b).abs() < 1e-6);
        }
        errors.push(largest);
    }
    // Both fit; the quadratic fit is the closer one.
    assert!(errors[0] < 0.1 && errors[1] < errors[0], "{errors:?}");
}

/// Sensors that depend on `m2` only: the kernel sets are the loops `m2 = const`.
fn ring(_m1: f64, m2: f64) -> Vec<f64> {
    vec![m2.cos(), m2.sin(), 0.5 * (2.0 * m2).sin()]
}

fn ring_sets(low1: f64) -> (smspace::kernel::TracedSets, Array2<f64>) {
    let (motors, sensors) = hinge_log(6000, low1, PI, ring);
    let space = MotorSpace::hinges(2);
    let starts = ndarray::array![[-0.5, -2.0], [-0.25, 0.3], [-1.0, 1.7]];
    let log = SensorimotorLog::new(motors, sensors, files(), &space).unwrap();
    let params = local_quadratic().check().unwrap();
    let law = learn(&[log], &space, &params, None).unwrap();
    assert_eq!(law.report().rank, 1, "{:?}", law.report());
    let traced = trace_learned(&law, starts.view(), &TraceParams::default(), &Silent).unwrap();
    (traced, starts)
}

#[test]
fn learned_sets_follow_the_true_kernel_and_end_where_the_data_end() {
    let (traced, starts) = ring_sets(-PI);
    assert_eq!(traced.kept, vec![0, 1, 2], "{:?}", traced.report.summary);
    for (set, start) in traced.sets.outer_iter().zip(starts.outer_iter()) {
        assert_eq!(set.nrows(), 100);
        for point in set.outer_iter() {
            let off = smspace::agent::wrap_angle(point[1] - start[1]);
            assert!(off.abs() < 0.02, "m2 moved by {off}");
        }
        // The loop goes round m1.
        let spread = set.column(0).iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!(spread > 3.0);
    }
    // The same law learned from data with m1 in [-1.5, π) only: the loops leave the data.
    let (traced, _) = ring_sets(-1.5);
    assert!(traced.kept.is_empty(), "{:?}", traced.report.summary);
    assert!(traced
        .report
        .sets
        .iter()
        .all(|s| s.status == SetStatus::LeftData));
    let json = serde_json::to_string(&traced.report).unwrap();
    assert!(json.contains("\"left-data\""));
}

/// A curved level-set function on the 2-torus: `u = sin m1 + cos m2` (critical values
/// ±2 and 0), read through three nonlinear sensors (rank 1).
fn bowl(m1: f64, m2: f64) -> Vec<f64> {
    let u = m1.sin() + m2.cos();
    vec![u, u * u * u / 3.0, (1.5 * u).sin()]
}

#[test]
fn a_learned_smooth_law_traces_its_curved_level_sets_quickly_and_closely() {
    let (motors, sensors) = hinge_log(8000, -PI, PI, bowl);
    let space = MotorSpace::hinges(2);
    let log = SensorimotorLog::new(motors, sensors, files(), &space).unwrap();
    let law = learn(&[log], &space, &local_quadratic().check().unwrap(), None).unwrap();
    assert_eq!(law.report().rank, 1, "{:?}", law.report());
    // Loops around the maximum (π/2, 0) and the minimum (−π/2, π), away from the
    // saddles' level 0.
    let starts = ndarray::array![[PI / 2.0, 1.2], [PI / 2.0 + 0.8, 0.3], [-PI / 2.0, 2.0]];
    let params = smspace::learn::law_trace_params();
    let traced = trace_learned(&law, starts.view(), &params, &Silent).unwrap();
    assert_eq!(traced.kept, vec![0, 1, 2], "{:?}", traced.report.summary);
    for ((set, start), report) in traced
        .sets
        .outer_iter()
        .zip(starts.outer_iter())
        .zip(&traced.report.sets)
    {
        assert_eq!(report.status, SetStatus::Closed, "{report:?}");
        // A loop of length ≤ 2π·√2 in adaptive steps of up to 0.05: a few hundred
        // steps, not the thousands of a corrector that cannot converge.
        assert!(report.steps < 600, "{report:?}");
        let target = bowl(start[0], start[1])[0];
        for point in set.outer_iter() {
            let (m1, m2) = (point[0], point[1]);
            let gradient = m1.cos().hypot(m2.sin());
            // The distance to the true level set, to first order.
            let off = (bowl(m1, m2)[0] - target).abs() / gradient;
            assert!(off < 0.01, "{point} is {off} rad off the true set");
        }
    }
}

#[test]
fn bad_logs_are_refused_with_the_file_and_the_fix() {
    let space = MotorSpace::hinges(2);
    let (motors, sensors) = hinge_log(500, -PI, PI, smooth);
    let message = |e: LearnError| e.to_string();
    // Different row counts.
    let short = first_rows(&sensors, 499);
    let e = message(SensorimotorLog::new(motors.clone(), short, files(), &space).unwrap_err());
    assert!(e.contains("m.npy has 500 rows but s.npy has 499"), "{e}");
    // NaN.
    let mut nan = sensors.clone();
    nan[[7, 1]] = f64::NAN;
    let e = message(SensorimotorLog::new(motors.clone(), nan, files(), &space).unwrap_err());
    assert!(e.contains("s.npy") && e.contains("(7, 1)"), "{e}");
    // A constant sensor.
    let mut constant = sensors.clone();
    constant.column_mut(2).fill(0.25);
    let e = message(SensorimotorLog::new(motors.clone(), constant, files(), &space).unwrap_err());
    assert!(e.contains("sensor column 2 of s.npy is constant"), "{e}");
    // A bounded motor outside its declared range.
    let bounded = MotorSpace::bounded(2, -1.0, 1.0).unwrap();
    let e = message(
        SensorimotorLog::new(motors.clone(), sensors.clone(), files(), &bounded).unwrap_err(),
    );
    assert!(e.contains("outside its declared range [-1, 1]"), "{e}");
    // Motor columns that do not fit the declaration.
    let e = message(
        SensorimotorLog::new(
            motors.clone(),
            sensors.clone(),
            files(),
            &MotorSpace::hinges(3),
        )
        .unwrap_err(),
    );
    assert!(e.contains("2 motor columns but 3"), "{e}");
    // Too few samples for the method.
    let small = SensorimotorLog::new(
        first_rows(&motors, 40),
        first_rows(&sensors, 40),
        files(),
        &space,
    )
    .unwrap();
    let params = local_quadratic().check().unwrap();
    let e = message(learn(&[small], &space, &params, None).unwrap_err());
    assert!(
        e.contains("too few samples (40)") && e.contains("local-linear"),
        "{e}"
    );
    // Memory, up front.
    let log = SensorimotorLog::new(motors, sensors, files(), &space).unwrap();
    let e = message(learn(&[log], &space, &params, Some(1000)).unwrap_err());
    assert!(e.contains("--max-memory"), "{e}");
}

#[test]
fn periodic_motors_are_wrapped_and_learning_is_deterministic() {
    let (motors, sensors) = hinge_log(3000, -PI, PI, smooth);
    let space = MotorSpace::hinges(2);
    let shifted = motors.mapv(|m| m + 2.0 * PI);
    let a = SensorimotorLog::new(motors, sensors.clone(), files(), &space).unwrap();
    let b = SensorimotorLog::new(shifted, sensors, files(), &space).unwrap();
    for (x, y) in a.motors.iter().zip(&b.motors) {
        assert!((x - y).abs() < 1e-12);
    }
    let params = local_quadratic().check().unwrap();
    let first = learn(std::slice::from_ref(&a), &space, &params, None).unwrap();
    let second = learn(&[a], &space, &params, None).unwrap();
    assert_eq!(first.report(), second.report());
}

#[test]
fn a_simulated_arm_log_is_seeded_and_its_law_has_rank_3() {
    let arm = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let environment = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let params = SimulateParams {
        samples: 20_000,
        noise: 0.0,
        seed: 1,
        ..SimulateParams::default()
    };
    let log = simulate(arm.as_ref(), &environment, arm.default_workspace(), &params).unwrap();
    assert_eq!(log.motors.dim(), (20_000, 4));
    assert_eq!(log.sensors.dim(), (20_000, 6));
    assert_eq!(log.poses.as_ref().unwrap().poses().nrows(), 20_000);
    // The same seed, the same log.
    let again = simulate(arm.as_ref(), &environment, arm.default_workspace(), &params).unwrap();
    assert_eq!(log.sensors, again.sensors);
    let space = arm.motor_space();
    let starts = log.motors.select(Axis(0), &[3, 500, 9000, 15000]);
    let checked = SensorimotorLog::new(log.motors, log.sensors, files(), &space).unwrap();
    let law_params = local_quadratic().check().unwrap();
    let law = learn(&[checked], &space, &law_params, None).unwrap();
    assert_eq!(law.report().rank, 3, "{:?}", law.report());
    // The true sets against themselves: zero error (the learned sets against them are
    // measured by examples/learn_study.rs, too slow for a test).
    let truth_params = TraceParams::default().check().unwrap();
    let truth = trace_sets(
        arm.as_ref(),
        Some(&environment),
        starts.view(),
        None,
        &truth_params,
        &Silent,
    )
    .unwrap();
    // A set compared with itself.
    let zero = set_errors(&truth, &truth, Period::TwoPi).unwrap();
    assert!(zero.p90 < 1e-9);
    // Motors that mix hinges and a bounded motor (the last one, say, a pupil's
    // aperture): a turn of a hinge is no error, a shift of the bounded motor is one of
    // its size (the shifted set's extreme point is that far from every true point).
    let mixed = smspace::learn::comparison_period(&[
        Some(std::f64::consts::TAU),
        Some(std::f64::consts::TAU),
        Some(std::f64::consts::TAU),
        None,
    ])
    .unwrap();
    assert_eq!(mixed.to_string(), "[2pi, 2pi, 2pi, none]");
    let mut turned = truth.clone();
    turned
        .sets
        .index_axis_mut(Axis(2), 0)
        .mapv_inplace(|m| m + std::f64::consts::TAU);
    assert!(set_errors(&turned, &truth, &mixed).unwrap().p90 < 1e-9);
    let mut shifted = truth.clone();
    shifted
        .sets
        .index_axis_mut(Axis(2), 3)
        .mapv_inplace(|m| m + 0.5);
    let errors = set_errors(&shifted, &truth, &mixed).unwrap();
    assert!(
        (errors.median - 0.5).abs() < 1e-9 && (errors.p90 - 0.5).abs() < 1e-9,
        "{errors:?}"
    );
    // Under 2π on every motor a shift by a whole turn would be no error.
    shifted
        .sets
        .index_axis_mut(Axis(2), 3)
        .mapv_inplace(|m| m - 0.5 + std::f64::consts::TAU);
    assert!(set_errors(&shifted, &truth, Period::TwoPi).unwrap().p90 < 1e-9);
    assert!(set_errors(&shifted, &truth, &mixed).unwrap().median > 1.0);
}

#[test]
fn the_law_is_the_weighted_fit_of_the_samples_within_its_bandwidth() {
    // Brute force over the whole log: every sample within h of m (differences wrapped
    // into [−π, π]), weights (1 − d²/h²)³, the basis 1, d/h (and the products d_a d_b / h²),
    // the ridge on the non-constant coefficients, solved by nalgebra's Cholesky. The
    // law's sums run in lanes over the samples the tree gives, in its own order.
    let (motors, sensors) = hinge_log(3000, -PI, PI, smooth);
    let space = MotorSpace::hinges(2);
    let log = SensorimotorLog::new(motors.clone(), sensors.clone(), files(), &space).unwrap();
    let wrap = |x: f64| (x + PI).rem_euclid(2.0 * PI) - PI;
    for method in [LawMethod::LocalLinear, LawMethod::LocalQuadratic] {
        let params = LawParams {
            method,
            holdout: Some(0),
            ..LawParams::default()
        }
        .check()
        .unwrap();
        let law = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        let h = law.report().logs[0].bandwidth;
        let p = if method == LawMethod::LocalQuadratic {
            6
        } else {
            3
        };
        for q in 0..25 {
            // Across the seam of both motors too.
            let m = [-3.1 + 0.2583 * q as f64, 3.12 - 0.2601 * q as f64];
            let (mut s, mut jac) = (vec![0.0; 3], vec![0.0; 6]);
            law.evaluate_with_jacobian(&m, &mut s, &mut jac);
            let mut gram = nalgebra::DMatrix::<f64>::zeros(p, p);
            let mut rhs = nalgebra::DMatrix::<f64>::zeros(p, 3);
            let mut count = 0;
            for (x, y) in motors.outer_iter().zip(sensors.outer_iter()) {
                let d = [wrap(x[0] - m[0]), wrap(x[1] - m[1])];
                let d2 = d[0] * d[0] + d[1] * d[1];
                if d2 >= h * h {
                    continue;
                }
                count += 1;
                let w = (1.0 - d2 / (h * h)).powi(3);
                let u = [d[0] / h, d[1] / h];
                let phi = nalgebra::DVector::from_vec(
                    [1.0, u[0], u[1], u[0] * u[0], u[0] * u[1], u[1] * u[1]][..p].to_vec(),
                );
                gram += w * &phi * phi.transpose();
                rhs += w * &phi * nalgebra::RowDVector::from_iterator(3, y.iter().copied());
            }
            assert!(count > p, "{count} samples within h");
            let total = gram[(0, 0)];
            for a in 1..p {
                gram[(a, a)] += LawParams::default().ridge * total;
            }
            let beta = gram.cholesky().unwrap().solve(&rhs);
            for i in 0..3 {
                assert!(
                    (s[i] - beta[(0, i)]).abs() < 1e-9,
                    "{method:?} at {m:?}, sensor {i}: {} vs {}",
                    s[i],
                    beta[(0, i)]
                );
            }
        }
    }
}

#[test]
fn the_law_jacobian_is_the_derivative_of_its_value() {
    // A noisy log of a smooth law: the fit's residuals are not zero, so the slope alone
    // differs from the derivative of the value by the moving weights' terms.
    let (motors, mut sensors) = hinge_log(6000, -PI, PI, |a, b| {
        vec![a.sin() + (2.0 * b).cos(), (a + b).sin() * 0.5]
    });
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for v in sensors.iter_mut() {
        *v += 0.02 * (rng.random::<f64>() - 0.5);
    }
    let space = MotorSpace::hinges(2);
    let log = SensorimotorLog::new(motors, sensors, files(), &space).unwrap();
    for method in [LawMethod::LocalLinear, LawMethod::LocalQuadratic] {
        let params = LawParams {
            method,
            ridge: 0.0,
            ..LawParams::default()
        }
        .check()
        .unwrap();
        let law = learn(std::slice::from_ref(&log), &space, &params, None).unwrap();
        let environment = Environment::from_lights(Vec::new());
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        for q in 0..20 {
            let m = [-2.5 + 0.25 * q as f64, 1.9 - 0.2 * q as f64];
            let (mut s, mut jac) = (vec![0.0; 2], vec![0.0; 4]);
            law.evaluate_with_jacobian(&m, &mut s, &mut jac);
            for j in 0..2 {
                let (mut plus, mut minus) = (m, m);
                plus[j] += h;
                minus[j] -= h;
                let (mut sp, mut sm) = (vec![0.0; 2], vec![0.0; 2]);
                law.sense(&environment, &plus, &mut sp);
                law.sense(&environment, &minus, &mut sm);
                for i in 0..2 {
                    let difference = (sp[i] - sm[i]) / (2.0 * h);
                    worst = worst.max((difference - jac[i * 2 + j]).abs());
                }
            }
        }
        assert!(
            worst < 1e-5,
            "{method:?}: Jacobian off its value's derivative by {worst}"
        );
    }
}

#[test]
fn a_noisy_log_traces_level_sets_of_the_range_held_at_the_start() {
    // With 1 % sensor noise the learned law has no exact rank 1, so s(m) = s⁰ has
    // isolated solutions; the tracer follows U₀ᵀ (ŝ(m) − s⁰) = 0, the range of the
    // Jacobian held at the start, a level set of a fixed map that ends on the bounds.
    let toy = AgentConfig::preset("toy-redundant")
        .unwrap()
        .build()
        .unwrap();
    let environment = EnvironmentConfig::default().build(toy.as_ref()).unwrap();
    let params = SimulateParams {
        samples: 20_000,
        noise: 0.01,
        seed: 1,
        ..SimulateParams::default()
    };
    let log = simulate(toy.as_ref(), &environment, None, &params).unwrap();
    let starts = first_rows(&log.motors, 60);
    let space = toy.motor_space();
    let files = files();
    let log = SensorimotorLog::new(log.motors, log.sensors, files, &space).unwrap();
    let law = learn(&[log], &space, &local_quadratic().check().unwrap(), None).unwrap();
    let traced = trace_learned(
        &law,
        starts.view(),
        &TraceParams {
            points: 20,
            ..smspace::learn::law_trace_params()
        },
        &Silent,
    )
    .unwrap();
    assert!(
        traced.kept.len() >= 55,
        "{:?}",
        traced.report.summary.by_status
    );
    let mut errors: Vec<f64> = traced
        .sets
        .outer_iter()
        .zip(&traced.kept)
        .map(|(set, &row)| {
            let x = starts[[row, 0]] + starts[[row, 1]];
            set.outer_iter()
                .map(|p| (p[0] + p[1] - x).abs())
                .fold(0.0, f64::max)
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    assert!(median < 0.03, "median largest error {median}");
}
