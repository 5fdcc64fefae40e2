//! Analytic and property tests of kernel-set tracing (paper appendix A).

use approx::assert_abs_diff_eq;
use ndarray::{Array2, ArrayView2, Axis};
use proptest::prelude::*;
use smspace::agent::{
    wrap_angle, Agent, AgentConfig, Environment, EnvironmentConfig, MotorTopology,
};
use smspace::explore::{explore, ExploreParams, Workspace};
use smspace::kernel::{
    trace_one, trace_sets, KernelError, SetStatus, StepControl, TraceMethod, TraceParams,
    TracedSets,
};
use smspace::progress::Silent;

fn agent(name: &str) -> Box<dyn Agent> {
    AgentConfig::preset(name).unwrap().build().unwrap()
}

fn arm_starts(n: usize, seed: u64) -> Array2<f64> {
    let params = ExploreParams {
        n,
        seed,
        ..ExploreParams::default()
    };
    explore(agent("planar-arm").as_ref(), &params)
        .unwrap()
        .motors
}

fn trace(
    agent: &dyn Agent,
    env: Option<&Environment>,
    motors: ArrayView2<f64>,
    params: TraceParams,
) -> TracedSets {
    let params = params.check().unwrap();
    trace_sets(agent, env, motors, None, &params, &Silent).unwrap()
}

fn torus_distance(a: &[f64], b: &[f64]) -> f64 {
    MotorTopology::Periodic.distance(a, b)
}

/// Largest pointwise torus distance between two equally long sets.
fn set_distance(a: ArrayView2<f64>, b: ArrayView2<f64>) -> f64 {
    a.outer_iter()
        .zip(b.outer_iter())
        .map(|(p, q)| torus_distance(p.as_slice().unwrap(), q.as_slice().unwrap()))
        .fold(0.0, f64::max)
}

#[test]
fn toy_redundant_kernels_are_the_lines_m1_plus_m2_constant() {
    let toy = agent("toy-redundant");
    let motors = ndarray::array![[0.5, 0.25], [-2.0, 1.0], [3.0, 2.5], [0.0, 0.0]];
    let traced = trace(toy.as_ref(), None, motors.view(), TraceParams::default());
    assert_eq!(traced.kept, vec![0, 1, 2, 3]);
    let pi = std::f64::consts::PI;
    for (set, start) in traced.sets.outer_iter().zip(motors.outer_iter()) {
        let x = start[0] + start[1];
        for p in set.outer_iter() {
            assert_abs_diff_eq!(p[0] + p[1], x, epsilon = 1e-10);
        }
        // The segment spans the motor box [-π, π]²: its ends lie on the faces.
        let first = set.row(0);
        let last = set.row(set.nrows() - 1);
        for end in [first, last] {
            let on_face = end.iter().any(|v| (v.abs() - pi).abs() < 1e-9);
            assert!(
                on_face,
                "end {end:?} of the set m1 + m2 = {x} is inside the box"
            );
        }
        // Its length is √2 (2π − |x|) (toy motors are linear: no wrapping).
        let length = MotorTopology::Bounded { low: -pi, high: pi }
            .distance(first.as_slice().unwrap(), last.as_slice().unwrap());
        assert_abs_diff_eq!(length, 2f64.sqrt() * (2.0 * pi - x.abs()), epsilon = 1e-9);
    }
    assert!(traced
        .report
        .sets
        .iter()
        .all(|s| s.status == SetStatus::Open));
}

#[test]
fn toy_line_kernels_are_single_points() {
    let toy = agent("toy-line");
    let motors = ndarray::array![[0.3], [-1.0]];
    let traced = trace(toy.as_ref(), None, motors.view(), TraceParams::default());
    for (set, start) in traced.sets.outer_iter().zip(motors.outer_iter()) {
        assert!(set.iter().all(|&v| v == start[0]));
    }
    assert!(traced
        .report
        .sets
        .iter()
        .all(|s| s.status == SetStatus::Point));
}

#[test]
fn every_traced_arm_point_keeps_the_start_pose_and_loops_close() {
    let arm = agent("planar-arm");
    let motors = arm_starts(12, 3);
    let traced = trace(arm.as_ref(), None, motors.view(), TraceParams::default());
    assert_eq!(traced.kept.len(), 12);
    for (set, start) in traced.sets.outer_iter().zip(motors.outer_iter()) {
        let target = arm.pose(start.as_slice().unwrap());
        // The resampled set starts at the explored configuration.
        assert!(torus_distance(set.row(0).as_slice().unwrap(), start.as_slice().unwrap()) < 1e-9);
        for p in set.outer_iter() {
            let pose = arm.pose(p.as_slice().unwrap());
            assert_abs_diff_eq!(pose.x, target.x, epsilon = 1e-9);
            assert_abs_diff_eq!(pose.y, target.y, epsilon = 1e-9);
            assert_abs_diff_eq!(wrap_angle(pose.alpha - target.alpha), 0.0, epsilon = 1e-9);
            assert!(p
                .iter()
                .all(|v| (-std::f64::consts::PI..std::f64::consts::PI).contains(v)));
        }
    }
    for line in &traced.report.sets {
        assert_eq!(line.status, SetStatus::Closed);
        assert!(line.steps >= 50);
        assert!(line.max_pose_deviation <= 1e-9, "{line:?}");
        assert!(line.max_residual <= 1e-11, "{line:?}");
    }
}

#[test]
fn resampled_points_are_equally_spaced_in_arc_length() {
    // Point k of a 100-point resampling sits at arc length kL/100: it is point 10k of
    // a 1000-point resampling of the same loop.
    let arm = agent("planar-arm");
    let motors = arm_starts(4, 5);
    let coarse = trace(arm.as_ref(), None, motors.view(), TraceParams::default());
    let fine = trace(
        arm.as_ref(),
        None,
        motors.view(),
        TraceParams {
            points: 1000,
            ..TraceParams::default()
        },
    );
    for (c, f) in coarse.sets.outer_iter().zip(fine.sets.outer_iter()) {
        let every_tenth = f.select(Axis(0), &(0..100).map(|k| 10 * k).collect::<Vec<_>>());
        assert!(set_distance(c, every_tenth.view()) < 1e-6);
        // Consecutive chords are nearly equal (they differ only through curvature).
        let chords: Vec<f64> = (0..100)
            .map(|k| {
                torus_distance(
                    c.row(k).as_slice().unwrap(),
                    c.row((k + 1) % 100).as_slice().unwrap(),
                )
            })
            .collect();
        let (lo, hi) = chords
            .iter()
            .fold((f64::MAX, 0.0_f64), |(lo, hi), &d| (lo.min(d), hi.max(d)));
        assert!(hi / lo < 1.1, "chords from {lo} to {hi}");
    }
}

#[test]
fn adaptive_steps_give_the_same_resampled_sets_as_fixed_steps() {
    let arm = agent("planar-arm");
    let motors = arm_starts(10, 7);
    let fixed = trace(arm.as_ref(), None, motors.view(), TraceParams::default());
    let adaptive = trace(
        arm.as_ref(),
        None,
        motors.view(),
        TraceParams {
            step_control: StepControl::Adaptive,
            ..TraceParams::default()
        },
    );
    assert_eq!(fixed.kept, adaptive.kept);
    for (a, b) in fixed.sets.outer_iter().zip(adaptive.sets.outer_iter()) {
        let d = set_distance(a, b);
        assert!(d < 1e-3, "adaptive set differs by {d}");
    }
    let steps = |t: &TracedSets| t.report.sets.iter().map(|s| s.steps).sum::<usize>();
    assert!(steps(&adaptive) * 10 < steps(&fixed));
}

#[test]
fn sensory_and_kinematic_tracing_give_the_same_sets() {
    let arm = agent("planar-arm");
    let env = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let motors = arm_starts(40, 11);
    let kinematic = trace(arm.as_ref(), None, motors.view(), TraceParams::default());
    let sensory = trace(
        arm.as_ref(),
        Some(&env),
        motors.view(),
        TraceParams {
            method: TraceMethod::Sensory,
            ..TraceParams::default()
        },
    );
    // A rich environment: most sets trace from the sensors alone, and those that do
    // not are reported, never traced wrongly.
    assert!(sensory.kept.len() >= 36, "{:?}", sensory.report.summary);
    for (si, row) in sensory.kept.iter().enumerate() {
        let ki = kinematic.kept.binary_search(row).unwrap();
        let d = set_distance(
            kinematic.sets.index_axis(Axis(0), ki),
            sensory.sets.index_axis(Axis(0), si),
        );
        assert!(d < 1e-5, "row {row}: sensory set differs by {d}");
    }
    for line in &sensory.report.sets {
        if !line.status.is_traced() {
            assert!(matches!(
                line.status,
                SetStatus::Singular | SetStatus::CorrectorFailed
            ));
        }
    }
}

#[test]
fn sensory_tracing_reports_a_blind_retina_as_singular() {
    // One light behind the working space: the retina sees too little to tell its pose.
    let arm = agent("planar-arm");
    let env = Environment::from_lights(vec![[-3.0, 0.0]]);
    let motors = arm_starts(3, 2);
    let sensory = trace(
        arm.as_ref(),
        Some(&env),
        motors.view(),
        TraceParams {
            method: TraceMethod::Sensory,
            ..TraceParams::default()
        },
    );
    assert!(sensory.kept.is_empty());
    assert_eq!(sensory.report.summary.failed, 3);
    assert!(sensory
        .report
        .sets
        .iter()
        .all(|s| s.status == SetStatus::Singular));
}

#[test]
fn output_is_identical_for_one_thread_and_many() {
    let arm = agent("planar-arm");
    let env = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let motors = arm_starts(16, 13);
    let run = |threads: usize, method: TraceMethod| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                trace(
                    arm.as_ref(),
                    Some(&env),
                    motors.view(),
                    TraceParams {
                        method,
                        ..TraceParams::default()
                    },
                )
            })
    };
    for method in [TraceMethod::Kinematic, TraceMethod::Sensory] {
        let one = run(1, method);
        let many = run(4, method);
        assert_eq!(one.kept, many.kept);
        assert_eq!(one.report, many.report);
        assert!(one
            .sets
            .iter()
            .zip(many.sets.iter())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}

#[test]
fn starts_outside_the_working_space_are_reported() {
    let arm = agent("planar-arm");
    let params = TraceParams::default().check().unwrap();
    let stretched = [0.0, 0.0, 0.0, 0.0]; // retina at (3, 0)
    let (points, report) = trace_one(
        arm.as_ref(),
        None,
        &stretched,
        Some(&Workspace::PAPER),
        &params,
    )
    .unwrap();
    assert!(points.is_none());
    assert_eq!(report.status, SetStatus::OutsideWorkspace);
    // Without a working space, the fully stretched arm is a singular posture.
    let (_, report) = trace_one(arm.as_ref(), None, &stretched, None, &params).unwrap();
    assert_eq!(report.status, SetStatus::Singular);
}

#[test]
fn a_tiny_step_budget_gives_not_closed() {
    let arm = agent("planar-arm");
    let motors = arm_starts(2, 1);
    let traced = trace(
        arm.as_ref(),
        None,
        motors.view(),
        TraceParams {
            max_steps: 100,
            ..TraceParams::default()
        },
    );
    assert!(traced.kept.is_empty());
    assert!(traced
        .report
        .sets
        .iter()
        .all(|s| s.status == SetStatus::NotClosed));
}

#[test]
fn impossible_parameters_and_inputs_are_errors() {
    for params in [
        TraceParams {
            points: 0,
            ..TraceParams::default()
        },
        TraceParams {
            step: -1e-3,
            ..TraceParams::default()
        },
        TraceParams {
            closure_tolerance: f64::NAN,
            ..TraceParams::default()
        },
        TraceParams {
            step: 0.1,
            step_control: StepControl::Fixed,
            ..TraceParams::default()
        },
    ] {
        assert!(matches!(
            params.check(),
            Err(KernelError::InvalidParameter { .. })
        ));
    }
    let arm = agent("planar-arm");
    let params = TraceParams::default().check().unwrap();
    let wrong = Array2::<f64>::zeros((3, 2));
    let err = trace_sets(arm.as_ref(), None, wrong.view(), None, &params, &Silent).unwrap_err();
    assert_eq!(
        err.to_string(),
        "motor configurations have 2 columns but the planar-arm agent has 4 motors"
    );
    let sensory = TraceParams {
        method: TraceMethod::Sensory,
        ..TraceParams::default()
    }
    .check()
    .unwrap();
    let motors = arm_starts(1, 1);
    let err = trace_sets(arm.as_ref(), None, motors.view(), None, &sensory, &Silent).unwrap_err();
    assert!(matches!(err, KernelError::MissingEnvironment));
    let empty = Array2::<f64>::zeros((0, 4));
    assert!(matches!(
        trace_sets(arm.as_ref(), None, empty.view(), None, &params, &Silent),
        Err(KernelError::NoMotors)
    ));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Any start in the working space gives a closed loop that keeps its pose.
    #[test]
    fn random_arm_starts_close_and_keep_their_pose(seed in 0u64..1_000_000) {
        let arm = agent("planar-arm");
        let motors = arm_starts(1, seed);
        let traced = trace(arm.as_ref(), None, motors.view(), TraceParams {
            step_control: StepControl::Adaptive,
            ..TraceParams::default()
        });
        let line = &traced.report.sets[0];
        prop_assert_eq!(line.status, SetStatus::Closed);
        prop_assert!(line.max_pose_deviation <= 1e-9);
        prop_assert!(line.length > 1.0);
    }
}
