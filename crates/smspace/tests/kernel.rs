//! Analytic and property tests of kernel-set tracing (paper appendix A).

use approx::assert_abs_diff_eq;
use ndarray::{Array2, ArrayView2, Axis};
use proptest::prelude::*;
use smspace::agent::{
    wrap_angle, Agent, AgentConfig, Calling, Environment, EnvironmentConfig, LightRegion, Motor,
    MotorSpace, Observer, PoseSpace,
};
use smspace::explore::{explore, ExploreParams, Workspace};
use smspace::kernel::{
    tangent_space, trace_one, trace_sets, Closure, Components, KernelError, SetStatus, StepControl,
    TraceMethod, TraceParams, TracedSets,
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
    MotorSpace::hinges(a.len()).distance(a, b)
}

/// The observer's pose of `agent` at `motors`.
fn pose_of(agent: &dyn Agent, motors: &[f64]) -> Vec<f64> {
    let observer = agent.ground_truth().expect("the agent has a ground truth");
    let mut pose = vec![0.0; observer.pose_space().dim()];
    observer.pose(motors, &mut pose);
    pose
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
        let length = MotorSpace::bounded(2, -pi, pi)
            .unwrap()
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
        let target = pose_of(arm.as_ref(), start.as_slice().unwrap());
        // The resampled set starts at the explored configuration.
        assert!(torus_distance(set.row(0).as_slice().unwrap(), start.as_slice().unwrap()) < 1e-9);
        for p in set.outer_iter() {
            let pose = pose_of(arm.as_ref(), p.as_slice().unwrap());
            assert_abs_diff_eq!(pose[0], target[0], epsilon = 1e-9);
            assert_abs_diff_eq!(pose[1], target[1], epsilon = 1e-9);
            assert_abs_diff_eq!(wrap_angle(pose[2] - target[2]), 0.0, epsilon = 1e-9);
            assert!(p
                .iter()
                .all(|v| (-std::f64::consts::PI..std::f64::consts::PI).contains(v)));
        }
    }
    for line in &traced.report.sets {
        assert_eq!(line.status, SetStatus::Closed);
        assert!(line.steps >= 50);
        assert!(line.max_pose_deviation.unwrap() <= 1e-9, "{line:?}");
        assert_eq!(line.dimension, 1);
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

/// The arm's law behind a costly interface: its calls counted, gathered or not, and
/// its ground truth hidden or not.
#[derive(Debug)]
struct Remote {
    arm: Box<dyn Agent>,
    calling: Calling,
    truth: bool,
    calls: std::sync::atomic::AtomicUsize,
}

impl Remote {
    fn new(calling: Calling, truth: bool) -> Self {
        Self {
            arm: agent("planar-arm"),
            calling,
            truth,
            calls: Default::default(),
        }
    }

    fn calls(&self) -> usize {
        self.calls.load(std::sync::atomic::Ordering::Relaxed)
    }
}

impl Agent for Remote {
    fn motor_dim(&self) -> usize {
        self.arm.motor_dim()
    }
    fn sensor_dim(&self) -> usize {
        self.arm.sensor_dim()
    }
    fn sense(&self, env: &Environment, m: &[f64], s: &mut [f64]) {
        let m = ArrayView2::from_shape((1, m.len()), m).unwrap();
        let k = s.len();
        self.sense_batch(
            env,
            m,
            ndarray::ArrayViewMut2::from_shape((1, k), s).unwrap(),
        );
    }
    fn name(&self) -> &str {
        "remote-arm"
    }
    fn sense_batch(
        &self,
        env: &Environment,
        m: ArrayView2<'_, f64>,
        s: ndarray::ArrayViewMut2<'_, f64>,
    ) {
        self.calls
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.arm.sense_batch(env, m, s);
    }
    fn calling(&self) -> Calling {
        self.calling
    }
    fn ground_truth(&self) -> Option<&dyn Observer> {
        self.truth.then(|| self.arm.ground_truth()).flatten()
    }
}

#[test]
fn gathered_calls_trace_the_same_sets_in_far_fewer_calls() {
    let env = EnvironmentConfig::default()
        .build(agent("planar-arm").as_ref())
        .unwrap();
    let motors = arm_starts(24, 5);
    let sensory = || TraceParams {
        method: TraceMethod::Sensory,
        points: 40,
        ..TraceParams::default()
    };
    for truth in [true, false] {
        let direct = Remote::new(Calling::Direct, truth);
        let expected = trace(&direct, Some(&env), motors.view(), sensory());
        for callers in [1, 7, 64] {
            let gathered = Remote::new(Calling::Gathered { callers }, truth);
            let traced = trace(&gathered, Some(&env), motors.view(), sensory());
            assert_eq!(traced.kept, expected.kept, "{callers} callers");
            assert_eq!(
                traced.sets, expected.sets,
                "{callers} callers: not bit for bit"
            );
            assert_eq!(traced.pieces, expected.pieces);
            let steps = |t: &TracedSets| t.report.sets.iter().map(|s| s.steps).collect::<Vec<_>>();
            assert_eq!(steps(&traced), steps(&expected));
            // One caller makes every call alone; more share each round (in two
            // groups of callers: 4 + 3, then 12 + 12 for the 24 sets).
            if callers == 1 {
                assert_eq!(gathered.calls(), direct.calls());
            } else {
                let fewer = if callers == 7 { 2 } else { 4 };
                assert!(
                    gathered.calls() * fewer < direct.calls(),
                    "{callers} callers: {} calls, {} direct",
                    gathered.calls(),
                    direct.calls()
                );
            }
        }
    }
}

#[test]
fn a_set_out_of_steps_reports_the_steps_it_took() {
    // A step budget far too small to close the arm's loops: every set fails as
    // not-closed, and says how far it got instead of 0.
    let arm = agent("planar-arm");
    let motors = arm_starts(3, 7);
    let params = TraceParams {
        max_steps: 7,
        min_steps: 1,
        ..TraceParams::default()
    }
    .check()
    .unwrap();
    let traced = trace_sets(arm.as_ref(), None, motors.view(), None, &params, &Silent);
    let report = match traced {
        Ok(t) => t.report,
        Err(e) => panic!("{e}"),
    };
    for line in &report.sets {
        assert_eq!(line.status, SetStatus::NotClosed);
        assert_eq!(line.steps, 7, "the forward branch's 7 steps");
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
        let err = params.check().unwrap_err();
        let located = err.invalid_parameter().expect("a parameter error");
        assert_eq!(located.table, "kernel", "{err}");
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
        prop_assert!(line.max_pose_deviation.unwrap() <= 1e-9);
        prop_assert!(line.length > 1.0);
    }
}

/// A planar arm on a rail: the base slides along x by `s ∈ [−0.5, 0.5]` (a bounded
/// motor), then two unit links and the retina turn on hinges. Motors `(s, m1, m2, m3)`,
/// pose `x = s + cos m1 + cos(m1 + m2)`, `y = sin m1 + sin(m1 + m2)`,
/// `alpha = m1 + m2 + m3`: 1-D kernels along which the rail slides, ending on its
/// bounds. Its pose Jacobian is the default (central differences).
#[derive(Debug)]
struct RailArm;

impl Agent for RailArm {
    fn motor_dim(&self) -> usize {
        4
    }
    fn sensor_dim(&self) -> usize {
        1
    }
    fn sense(&self, _: &Environment, m: &[f64], s: &mut [f64]) {
        s[0] = m.iter().sum();
    }
    fn name(&self) -> &str {
        "rail-arm"
    }
    fn motor_space(&self) -> MotorSpace {
        MotorSpace::new(vec![
            Motor::Bounded {
                low: -0.5,
                high: 0.5,
            },
            Motor::HINGE,
            Motor::HINGE,
            Motor::HINGE,
        ])
        .unwrap()
    }
    fn ground_truth(&self) -> Option<&dyn Observer> {
        Some(self)
    }
}

impl Observer for RailArm {
    fn pose_space(&self) -> PoseSpace {
        PoseSpace::planar()
    }
    fn pose(&self, m: &[f64], pose: &mut [f64]) {
        let (t1, t2) = (m[1], m[1] + m[2]);
        pose[0] = m[0] + t1.cos() + t2.cos();
        pose[1] = t1.sin() + t2.sin();
        pose[2] = wrap_angle(m[1] + m[2] + m[3]);
    }
}

#[test]
fn a_mixed_motor_space_wraps_its_hinges_and_ends_sets_on_its_bounds() {
    let arm = RailArm;
    // The hand well inside the reach of the links (above or below the base, the
    // elbow bent), so that sliding the rail from one bound to the other never
    // stretches or folds the arm; hinges anywhere.
    let motors = ndarray::array![
        [0.0, 0.785, 1.571, 3.0],
        [0.2, 2.356, -1.571, -2.0],
        [-0.2, -2.17, 1.2, 0.5],
    ];
    let traced = trace(&arm, None, motors.view(), TraceParams::default());
    assert_eq!(traced.kept, vec![0, 1, 2], "{:?}", traced.report.summary);
    for ((set, start), line) in traced
        .sets
        .outer_iter()
        .zip(motors.outer_iter())
        .zip(&traced.report.sets)
    {
        // The rail slides from one bound to the other: an open set (its ends are
        // the clipped nodes, projected back onto the set by the corrector).
        assert_eq!(line.status, SetStatus::Open, "{line:?}");
        let rail = set.column(0);
        let (lo, hi) = rail
            .iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), &s| (lo.min(s), hi.max(s)));
        assert_abs_diff_eq!(lo, -0.5, epsilon = 1e-7);
        assert_abs_diff_eq!(hi, 0.5, epsilon = 1e-7);
        // Hinges are wrapped into [−π, π); every point keeps the start's pose.
        let target = pose_of(&arm, start.as_slice().unwrap());
        for p in set.outer_iter() {
            assert!(p
                .iter()
                .skip(1)
                .all(|v| (-std::f64::consts::PI..std::f64::consts::PI).contains(v)));
            let pose = pose_of(&arm, p.as_slice().unwrap());
            for c in 0..2 {
                assert_abs_diff_eq!(pose[c], target[c], epsilon = 1e-9);
            }
            assert_abs_diff_eq!(wrap_angle(pose[2] - target[2]), 0.0, epsilon = 1e-9);
        }
    }
    assert!(traced.closure.iter().all(|&c| c == Closure::Open));
}

/// An agent with the required methods only: a cart at `x = sin m1 + sin(m2)/2` (two
/// hinges, the default motor space) with two light sensors, and no ground truth.
#[derive(Debug)]
struct BlindCart;

impl Agent for BlindCart {
    fn motor_dim(&self) -> usize {
        2
    }
    fn sensor_dim(&self) -> usize {
        2
    }
    fn sense(&self, environment: &Environment, m: &[f64], s: &mut [f64]) {
        let x = m[0].sin() + 0.5 * m[1].sin();
        for (s, offset) in s.iter_mut().zip([-0.25, 0.25]) {
            *s = environment
                .lights
                .iter()
                .map(|l| 1.0 / ((l[0] - x - offset).powi(2) + l[1].powi(2)))
                .sum();
        }
    }
    fn name(&self) -> &str {
        "blind-cart"
    }
}

/// Two hinges and no ground truth. The first sensor reads `x = sin m1 + sin(m2)/2`;
/// the second, with `Spot::Local`, reacts only within about 0.15 rad of `SPOT` (a light
/// seen from one spot), so the sensors change along one motor direction almost
/// everywhere and along both at `SPOT`; with `Spot::Everywhere` it reads
/// `cos m1 + sin m2`, and the sensors change along both directions everywhere.
#[derive(Debug)]
enum Spot {
    Local,
    Everywhere,
}

const SPOT: [f64; 2] = [0.5, -0.3];

impl Agent for Spot {
    fn motor_dim(&self) -> usize {
        2
    }
    fn sensor_dim(&self) -> usize {
        2
    }
    fn sense(&self, _: &Environment, m: &[f64], s: &mut [f64]) {
        s[0] = m[0].sin() + 0.5 * m[1].sin();
        s[1] = match self {
            Spot::Local => {
                let d1 = wrap_angle(m[0] - SPOT[0]);
                let d2 = wrap_angle(m[1] - SPOT[1]);
                (-(d1 * d1 + d2 * d2) / 0.02).exp() * (d1 - d2 + 0.8)
            }
            Spot::Everywhere => m[0].cos() + m[1].sin(),
        };
    }
    fn name(&self) -> &str {
        "spot"
    }
}

#[test]
fn one_start_at_a_special_spot_does_not_decide_the_dimension_of_every_set() {
    let region = LightRegion {
        center: [0.0, 2.0],
        half_size: [3.0, 1.0],
        exclusion_half_size: [0.0, 0.0],
    };
    let env = Environment::random(4, 3, &region).unwrap();
    let sensory = TraceParams {
        method: TraceMethod::Sensory,
        noise: smspace::kernel::SensorNoise::Sigma(0.0),
        ..TraceParams::default()
    };
    // Four starts whose curves x = const stay far from the spot, and the spot itself.
    let starts = ndarray::array![
        [-1.2, -0.6],
        [-1.0, 0.0],
        [2.0, 2.0],
        [-0.5, -2.0],
        [SPOT[0], SPOT[1]]
    ];
    let traced = trace(&Spot::Local, Some(&env), starts.view(), sensory.clone());
    let summary = &traced.report.summary;
    let rank = summary
        .sensory_rank
        .as_ref()
        .expect("the rank the starts show");
    assert_eq!((rank.rank, rank.disagreeing.clone()), (1, vec![(4, 2)]));
    for (i, line) in traced.report.sets.iter().enumerate().take(4) {
        assert_eq!(line.dimension, 1, "{line:?}");
        assert!(traced.kept.contains(&i), "{summary:?}");
    }
    for (set, &row) in traced.sets.outer_iter().zip(&traced.kept).take(4) {
        let x0 = starts[[row, 0]].sin() + 0.5 * starts[[row, 1]].sin();
        for p in set.outer_iter() {
            assert_abs_diff_eq!(p[0].sin() + 0.5 * p[1].sin(), x0, epsilon = 1e-6);
        }
    }
    let warnings = summary.warnings().join("\n");
    assert!(
        warnings.contains("starts 4 (rank 2)") && warnings.contains("motor directions"),
        "{warnings}"
    );
    assert!(!warnings.contains("pose"), "{warnings}");
    // Sensors of full rank everywhere: every set a point, said in sensors and motors.
    let traced = trace(&Spot::Everywhere, Some(&env), starts.view(), sensory);
    let summary = &traced.report.summary;
    assert_eq!(summary.by_status.get("point"), Some(&summary.traced));
    let warnings = summary.warnings().join("\n");
    assert!(
        warnings.contains("single point") && warnings.contains("all 2 motor directions"),
        "{warnings}"
    );
    assert!(!warnings.contains("pose"), "{warnings}");
}

#[test]
fn a_declared_noise_below_the_readings_rounding_is_exact_and_an_absurd_one_is_refused() {
    let region = LightRegion {
        center: [0.0, 2.0],
        half_size: [3.0, 1.0],
        exclusion_half_size: [0.0, 0.0],
    };
    let env = Environment::random(4, 3, &region).unwrap();
    let motors = ndarray::array![[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2]];
    let with = |noise: f64| TraceParams {
        method: TraceMethod::Sensory,
        noise: smspace::kernel::SensorNoise::Sigma(noise),
        ..TraceParams::default()
    };
    let exact = trace(&BlindCart, Some(&env), motors.view(), with(0.0));
    assert_eq!(exact.kept.len(), 3, "{:?}", exact.report.summary);
    for tiny in [1e-300, 1e-17, 1e-16] {
        let traced = trace(&BlindCart, Some(&env), motors.view(), with(tiny));
        assert_eq!(
            traced.kept, exact.kept,
            "{tiny}: {:?}",
            traced.report.summary
        );
        assert!(traced.report.summary.noise.is_none(), "{tiny}");
        for (a, b) in traced.sets.iter().zip(exact.sets.iter()) {
            assert_abs_diff_eq!(a, b, epsilon = 1e-9);
        }
    }
    let err = with(1e300).check().unwrap_err().to_string();
    assert!(
        err.contains("sensor_sigma") && err.contains("overflows"),
        "{err}"
    );
}

#[test]
fn without_a_ground_truth_the_sensory_method_traces_and_the_kinematic_one_explains() {
    let cart = BlindCart;
    let region = LightRegion {
        center: [0.0, 2.0],
        half_size: [3.0, 1.0],
        exclusion_half_size: [0.0, 0.0],
    };
    let env = Environment::random(4, 3, &region).unwrap();
    let motors = ndarray::array![[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2]];
    let params = TraceParams::default().check().unwrap();
    let err = trace_sets(&cart, Some(&env), motors.view(), None, &params, &Silent).unwrap_err();
    assert!(matches!(err, KernelError::NoGroundTruth { .. }), "{err}");
    assert!(err.to_string().contains("blind-cart") && err.to_string().contains("sensory"));
    let err = trace_sets(
        &cart,
        Some(&env),
        motors.view(),
        Some(&Workspace::PAPER),
        &TraceParams {
            method: TraceMethod::Sensory,
            ..TraceParams::default()
        }
        .check()
        .unwrap(),
        &Silent,
    )
    .unwrap_err();
    assert!(err.to_string().contains("working space"), "{err}");
    // The sensors see x only: the sensory Jacobian has rank 1, the kernels are the
    // curves sin m1 + sin(m2)/2 = const on the torus.
    let sensory = trace(
        &cart,
        Some(&env),
        motors.view(),
        TraceParams {
            method: TraceMethod::Sensory,
            ..TraceParams::default()
        },
    );
    assert_eq!(sensory.kept.len(), 3, "{:?}", sensory.report.summary);
    for (set, start) in sensory.sets.outer_iter().zip(motors.outer_iter()) {
        let x0 = start[0].sin() + 0.5 * start[1].sin();
        for p in set.outer_iter() {
            assert_abs_diff_eq!(p[0].sin() + 0.5 * p[1].sin(), x0, epsilon = 1e-9);
        }
    }
    for line in &sensory.report.sets {
        assert_eq!(line.max_pose_deviation, None);
        assert_eq!(line.dimension, 1);
    }
    assert_eq!(sensory.dimensions(), vec![1, 1, 1]);
}

/// The planar arm with `links` (unit lengths unless given).
fn arm_with(links: &str) -> Box<dyn Agent> {
    AgentConfig {
        kind: "planar-arm".into(),
        params: toml::from_str(&format!("link_lengths = {links}")).unwrap(),
    }
    .build()
    .unwrap()
}

/// Motors that put the retina of `arm` at distance `r` from the base, at polar angle
/// `phi`, looking along `alpha`.
fn retina_at(arm: &dyn Agent, r: f64, phi: f64, alpha: f64) -> Vec<f64> {
    arm.ground_truth()
        .unwrap()
        .inverse_kinematics(&[r * phi.cos(), r * phi.sin(), alpha])
        .expect("the pose is reachable")
}

#[test]
fn kernels_of_two_dimensions_are_covered_on_their_level_set() {
    // Four links and the retina hinge: five motors for a 3-D pose, k = 2.
    let arm = arm_with("[1.0, 1.0, 1.0, 1.0]");
    let motors = ndarray::array![[0.1, 0.2, 0.3, 0.4, 0.5], [1.0, -0.5, 0.8, 1.2, -2.0]];
    let params = TraceParams {
        points: 60,
        cover_step: 0.4,
        ..TraceParams::default()
    }
    .check()
    .unwrap();
    // Known before any start is traced (the pipeline checks it with the experiment).
    assert_eq!(params.dimension_for(arm.as_ref()).unwrap(), Some(2));
    let traced = trace_sets(arm.as_ref(), None, motors.view(), None, &params, &Silent).unwrap();
    assert_eq!(traced.sets.dim(), (2, 60, 5));
    for (s, line) in traced.report.sets.iter().enumerate() {
        assert_eq!((line.status, line.dimension), (SetStatus::Covered, 2));
        // Every sampled point keeps the start's pose to 1e-9.
        let start_pose = pose_of(arm.as_ref(), motors.row(s).as_slice().unwrap());
        for p in traced.sets.index_axis(Axis(0), s).outer_iter() {
            let pose = pose_of(arm.as_ref(), p.as_slice().unwrap());
            for c in 0..3 {
                assert!(wrap_angle(pose[c] - start_pose[c]).abs() < 1e-9, "{pose:?}");
            }
        }
        assert!(line.max_pose_deviation.unwrap() < 1e-9);
        let radius = line
            .covering_radius
            .expect("a k-D set has a covering radius");
        assert!(radius > 0.0 && radius < 2.0, "{radius}");
        // The points are distinct and spread: none closer than a fraction of the radius.
        let set = traced.sets.index_axis(Axis(0), s);
        for i in 0..60 {
            for j in 0..i {
                let d = torus_distance(
                    set.row(i).as_slice().unwrap(),
                    set.row(j).as_slice().unwrap(),
                );
                assert!(
                    d > 0.2 * radius,
                    "points {i} and {j}: {d} (radius {radius})"
                );
            }
        }
    }
    assert_eq!(traced.dimensions(), vec![2, 2]);
    let summary = &traced.report.summary;
    let [low, _, high] = summary.covering_radius.unwrap();
    assert!(low <= high);
    // The curve metric does not apply: an error naming hausdorff.
    let curve = smspace::metric::MetricKind::Curve.with_period(
        smspace::metric::Period::None,
        smspace::sets::Closure::Closed,
    );
    let message = curve
        .check_kernels(smspace::sets::KernelShape::of_dimension(2))
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("hausdorff") && message.contains("k = 2"),
        "{message}"
    );
    assert!(curve
        .check_kernels(smspace::sets::KernelShape::of_dimension(1))
        .is_ok());
}

#[test]
fn the_covering_radius_bounds_the_distance_from_a_dense_reference() {
    let arm = arm_with("[1.0, 1.0, 1.0, 1.0]");
    let start = [0.4, -0.9, 1.1, 0.6, 0.2];
    let coarse = TraceParams {
        points: 80,
        cover_step: 0.3,
        ..TraceParams::default()
    }
    .check()
    .unwrap();
    let (sample, line) = trace_one(arm.as_ref(), None, &start, None, &coarse).unwrap();
    let sample = sample.unwrap();
    let radius = line.covering_radius.unwrap();
    // A reference covering twice as dense, all of its nodes kept.
    let dense = TraceParams {
        points: 20_000,
        cover_step: 0.15,
        ..TraceParams::default()
    }
    .check()
    .unwrap();
    let (reference, _) = trace_one(arm.as_ref(), None, &start, None, &dense).unwrap();
    let reference = reference.unwrap();
    let farthest = reference
        .chunks(5)
        .map(|q| {
            sample
                .chunks(5)
                .map(|p| torus_distance(p, q))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    // Within the radius plus the coarse covering's own spacing.
    assert!(farthest <= radius + 0.3, "{farthest} vs {radius}");
    assert!(
        farthest >= 0.5 * radius,
        "{farthest} vs {radius}: the radius is not loose"
    );
}

#[test]
fn the_covering_of_a_surface_is_the_same_for_any_thread_count() {
    let arm = arm_with("[1.0, 1.0, 1.0, 1.0]");
    let motors = ndarray::array![
        [0.1, 0.2, 0.3, 0.4, 0.5],
        [1.0, -0.5, 0.8, 1.2, -2.0],
        [-2.0, 1.5, 0.2, -0.7, 0.9]
    ];
    let params = TraceParams {
        points: 40,
        cover_step: 0.4,
        ..TraceParams::default()
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| trace(arm.as_ref(), None, motors.view(), params.clone()))
    };
    let (one, two) = (run(1), run(2));
    assert_eq!(one.sets, two.sets);
    assert_eq!(one.report, two.report);
}

#[test]
fn the_paper_arm_has_two_pieces_inside_one_link_and_one_outside() {
    let arm = agent("planar-arm");
    let distances = [0.5, 0.7, 0.9, 0.95, 1.05, 1.1, 1.3, 1.7, 2.2];
    let motors: Vec<f64> = distances
        .iter()
        .enumerate()
        .flat_map(|(i, &r)| retina_at(arm.as_ref(), r, 0.3 * i as f64, 1.0 - 0.4 * i as f64))
        .collect();
    let motors = Array2::from_shape_vec((distances.len(), 4), motors).unwrap();
    for components in [Components::All, Components::Connected] {
        let params = TraceParams {
            step_control: StepControl::Adaptive,
            components,
            ..TraceParams::default()
        };
        let traced = trace(arm.as_ref(), None, motors.view(), params);
        for (line, &r) in traced.report.sets.iter().zip(&distances) {
            let expected = if r < 1.0 { 2 } else { 1 };
            assert_eq!(line.pieces, expected, "r = {r}, {components:?}: {line:?}");
            let unvisited = match components {
                Components::All => 0,
                Components::Connected => expected - 1,
            };
            assert_eq!(line.unvisited_pieces, unvisited, "r = {r}");
            let status = match (components, expected) {
                (Components::All, 2) => SetStatus::Pieces,
                _ => SetStatus::Closed,
            };
            assert_eq!(line.status, status, "r = {r}");
        }
        let near = distances.iter().filter(|&&r| r < 1.0).count();
        let summary = &traced.report.summary;
        match components {
            Components::All => {
                assert_eq!(summary.with_several_pieces, near);
                assert_eq!(summary.with_unvisited_pieces, 0);
                // The second pieces drew many of the 16 seeds: the search is reliable.
                for line in &traced.report.sets {
                    assert_eq!(line.piece_landings.len(), line.pieces - 1);
                    assert!(line.piece_landings.iter().all(|&h| h >= 1));
                }
                let search = summary.piece_search.unwrap();
                assert_eq!((search.pieces, search.seeds), (near, 16));
                assert!(search.miss_probability < 0.05, "{search:?}");
                assert!(summary.warnings().is_empty(), "{:?}", summary.warnings());
                // The points are shared between the pieces, each a run; every point
                // keeps the start's pose.
                for (s, row) in traced.pieces.outer_iter().enumerate() {
                    let pieces = 1 + *row.iter().max().unwrap() as usize;
                    assert_eq!(pieces, traced.report.sets[s].pieces);
                    let start = pose_of(arm.as_ref(), motors.row(s).as_slice().unwrap());
                    for p in traced.sets.index_axis(Axis(0), s).outer_iter() {
                        let pose = pose_of(arm.as_ref(), p.as_slice().unwrap());
                        for c in 0..3 {
                            assert!(wrap_angle(pose[c] - start[c]).abs() < 1e-9);
                        }
                    }
                    if pieces == 2 {
                        // Two congruent pieces (mirror images): about half the points each.
                        let first = row.iter().filter(|&&c| c == 0).count();
                        assert!((40..=60).contains(&first), "{first}");
                    }
                }
            }
            Components::Connected => {
                assert_eq!(summary.with_unvisited_pieces, near);
                assert!(traced.pieces.iter().all(|&c| c == 0));
                let warnings = summary.warnings();
                assert!(warnings[0].contains("miss pieces"), "{warnings:?}");
            }
        }
    }
}

#[test]
fn an_arm_with_unequal_links_warns_of_unvisited_pieces() {
    // Links [1.2, 0.8, 0.6]: for retina distances in (1.0, 1.4) the self-motion has two
    // pieces (issue 20); the paper's connected mode misses one and says so.
    let arm = arm_with("[1.2, 0.8, 0.6]");
    let motors = Array2::from_shape_vec(
        (2, 4),
        [
            retina_at(arm.as_ref(), 1.2, 0.5, 0.3),
            retina_at(arm.as_ref(), 2.2, -0.5, 0.3),
        ]
        .concat(),
    )
    .unwrap();
    let params = TraceParams {
        step_control: StepControl::Adaptive,
        ..TraceParams::default()
    };
    let traced = trace(arm.as_ref(), None, motors.view(), params);
    let lines = &traced.report.sets;
    assert_eq!((lines[0].pieces, lines[0].unvisited_pieces), (2, 1));
    assert_eq!((lines[1].pieces, lines[1].unvisited_pieces), (1, 0));
    let warnings = traced.report.summary.warnings();
    assert_eq!(warnings.len(), 1);
    assert!(
        warnings[0].starts_with("1 of 2 sets miss pieces"),
        "{warnings:?}"
    );
    // Without the search nothing is checked, and nothing is said.
    let unchecked = trace(
        arm.as_ref(),
        None,
        motors.view(),
        TraceParams {
            piece_starts: 0,
            ..TraceParams::default()
        },
    );
    assert!(unchecked.report.summary.warnings().is_empty());
}

#[test]
fn a_body_without_redundancy_is_warned_about() {
    // Two links and the retina: three motors for a 3-D pose, every set a point.
    let arm = arm_with("[1.0, 1.0]");
    let motors = Array2::from_shape_vec(
        (2, 3),
        [
            retina_at(arm.as_ref(), 1.2, 0.5, 0.3),
            retina_at(arm.as_ref(), 1.6, -0.5, 0.3),
        ]
        .concat(),
    )
    .unwrap();
    let traced = trace(arm.as_ref(), None, motors.view(), TraceParams::default());
    assert_eq!(traced.report.summary.by_status.get("point"), Some(&2));
    let warnings = traced.report.summary.warnings();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("single point") && w.contains("no redundancy")),
        "{warnings:?}"
    );
    // Elbow up and elbow down: the other solution is a second (unvisited) piece.
    assert!(traced
        .report
        .sets
        .iter()
        .all(|l| l.pieces == 2 && l.unvisited_pieces == 1));
}

#[test]
fn the_tangent_space_of_a_surface_is_two_dimensional() {
    let arm = arm_with("[1.0, 1.0, 1.0, 1.0]");
    let motors = ndarray::array![[0.1, 0.2, 0.3, 0.4, 0.5]];
    let params = TraceParams::default().check().unwrap();
    // The tangent space there is 2-D, orthonormal, and the pose does not change along
    // it to first order.
    let tangent = tangent_space(
        arm.as_ref(),
        None,
        motors.row(0).as_slice().unwrap(),
        &params,
    )
    .unwrap();
    assert_eq!((tangent.rank, tangent.dimension()), (3, 2));
    let start = motors.row(0).to_vec();
    let base = pose_of(arm.as_ref(), &start);
    for direction in tangent.basis.outer_iter() {
        let norm: f64 = direction.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert_abs_diff_eq!(norm, 1.0, epsilon = 1e-12);
        let h = 1e-6;
        let moved: Vec<f64> = start
            .iter()
            .zip(direction)
            .map(|(m, d)| m + h * d)
            .collect();
        let pose = pose_of(arm.as_ref(), &moved);
        for c in 0..3 {
            assert!((pose[c] - base[c]).abs() < 1e-10, "{pose:?} vs {base:?}");
        }
    }
}

#[test]
fn the_tangent_space_of_the_arm_is_its_traced_direction() {
    let arm = agent("planar-arm");
    let env = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let start = arm_starts(1, 4).row(0).to_vec();
    for method in [TraceMethod::Kinematic, TraceMethod::Sensory] {
        let params = TraceParams {
            method,
            points: 400,
            ..TraceParams::default()
        }
        .check()
        .unwrap();
        let tangent = tangent_space(arm.as_ref(), Some(&env), &start, &params).unwrap();
        assert_eq!((tangent.rank, tangent.dimension()), (3, 1), "{method:?}");
        // The first resampled step leaves the start along ± the null direction.
        let (points, _) = trace_one(arm.as_ref(), Some(&env), &start, None, &params).unwrap();
        let points = points.unwrap();
        let step: Vec<f64> = (0..4)
            .map(|j| wrap_angle(points[4 + j] - points[j]))
            .collect();
        let norm: f64 = step.iter().map(|v| v * v).sum::<f64>().sqrt();
        let cosine: f64 = step
            .iter()
            .zip(tangent.basis.row(0))
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / norm;
        assert!(cosine.abs() > 0.999, "{method:?}: cosine {cosine}");
    }
}

/// [`BlindCart`] with its sensor values multiplied by a constant.
#[derive(Debug)]
struct ScaledCart(f64);

impl Agent for ScaledCart {
    fn motor_dim(&self) -> usize {
        2
    }
    fn sensor_dim(&self) -> usize {
        2
    }
    fn sense(&self, environment: &Environment, m: &[f64], s: &mut [f64]) {
        BlindCart.sense(environment, m, s);
        s.iter_mut().for_each(|v| *v *= self.0);
    }
    fn name(&self) -> &str {
        "scaled-cart"
    }
}

#[test]
fn sensors_at_a_scale_the_tracer_cannot_square_are_refused_with_the_fix() {
    let region = LightRegion {
        center: [0.0, 2.0],
        half_size: [3.0, 1.0],
        exclusion_half_size: [0.0, 0.0],
    };
    let env = Environment::random(4, 3, &region).unwrap();
    let motors = ndarray::array![[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2]];
    let params = TraceParams {
        method: TraceMethod::Sensory,
        noise: smspace::kernel::SensorNoise::Sigma(0.0),
        ..TraceParams::default()
    }
    .check()
    .unwrap();
    for scale in [1e-6, 1e6] {
        let traced = trace_sets(
            &ScaledCart(scale),
            Some(&env),
            motors.view(),
            None,
            &params,
            &Silent,
        )
        .unwrap_or_else(|e| panic!("{scale}: {e}"));
        assert_eq!(traced.kept.len(), 3, "{scale}: {:?}", traced.report.summary);
    }
    for scale in [1e-200, 1e160, 1e300] {
        let err = trace_sets(
            &ScaledCart(scale),
            Some(&env),
            motors.view(),
            None,
            &params,
            &Silent,
        )
        .unwrap_err();
        assert!(
            matches!(err, KernelError::SensorScale { .. }),
            "{scale}: {err}"
        );
        assert!(err.to_string().contains("scale the sensor values"), "{err}");
    }
}
