//! The sensor rows tracing costs: counted where the agent is called, and cut by the
//! secant Jacobian without moving the sets.

use std::sync::atomic::{AtomicU64, Ordering};

use ndarray::{Array2, ArrayView2, ArrayViewMut2, Axis};
use smspace::agent::{Agent, AgentConfig, Calling, Environment, EnvironmentConfig, Observer};
use smspace::explore::{explore, ExploreParams};
use smspace::kernel::{
    trace_sets, JacobianMethod, SetStatus, TraceMethod, TraceParams, TracedSets,
};
use smspace::metric::{Curve, Period, Periodicity, SetMetric};
use smspace::progress::Silent;

fn arm() -> Box<dyn Agent> {
    AgentConfig::preset("planar-arm").unwrap().build().unwrap()
}

fn arm_starts(n: usize, seed: u64) -> Array2<f64> {
    let params = ExploreParams {
        n,
        seed,
        ..ExploreParams::default()
    };
    explore(arm().as_ref(), &params).unwrap().motors
}

fn sensory(jacobian: JacobianMethod, points: usize) -> TraceParams {
    TraceParams {
        method: TraceMethod::Sensory,
        jacobian,
        points,
        ..TraceParams::default()
    }
}

fn trace(
    agent: &dyn Agent,
    env: &Environment,
    motors: ArrayView2<f64>,
    p: TraceParams,
) -> TracedSets {
    trace_sets(agent, Some(env), motors, None, &p.check().unwrap(), &Silent).unwrap()
}

/// The arm, counting every motor row it is asked to sense, by either call.
#[derive(Debug)]
struct Counting {
    arm: Box<dyn Agent>,
    calling: Calling,
    truth: bool,
    rows: AtomicU64,
}

impl Counting {
    fn new(calling: Calling, truth: bool) -> Self {
        Self::of(arm(), calling, truth)
    }

    fn of(arm: Box<dyn Agent>, calling: Calling, truth: bool) -> Self {
        Self {
            arm,
            calling,
            truth,
            rows: AtomicU64::new(0),
        }
    }
}

impl Agent for Counting {
    fn motor_dim(&self) -> usize {
        self.arm.motor_dim()
    }
    fn sensor_dim(&self) -> usize {
        self.arm.sensor_dim()
    }
    fn sense(&self, env: &Environment, m: &[f64], s: &mut [f64]) {
        self.rows.fetch_add(1, Ordering::Relaxed);
        self.arm.sense(env, m, s);
    }
    fn sense_batch(&self, env: &Environment, m: ArrayView2<'_, f64>, s: ArrayViewMut2<'_, f64>) {
        self.rows.fetch_add(m.nrows() as u64, Ordering::Relaxed);
        self.arm.sense_batch(env, m, s);
    }
    fn name(&self) -> &str {
        "counting-arm"
    }
    fn calling(&self) -> Calling {
        self.calling
    }
    fn ground_truth(&self) -> Option<&dyn Observer> {
        self.truth.then(|| self.arm.ground_truth()).flatten()
    }
}

#[test]
fn the_rows_reported_are_the_rows_the_agent_sensed() {
    let env = EnvironmentConfig::default().build(arm().as_ref()).unwrap();
    // The stretched arm (all zeros) is a singular posture: a failed set counts too.
    let mut motors = arm_starts(6, 4);
    motors.row_mut(5).fill(0.0);
    for jacobian in [JacobianMethod::FiniteDifferences, JacobianMethod::Secant] {
        // Without a ground truth the rank is estimated first: its rows count too.
        for truth in [true, false] {
            for calling in [Calling::Direct, Calling::Gathered { callers: 3 }] {
                let agent = Counting::new(calling, truth);
                let traced = trace(&agent, &env, motors.view(), sensory(jacobian, 20));
                let sensed = agent.rows.load(Ordering::Relaxed);
                let per_set: u64 = traced.report.sets.iter().map(|s| s.sensor_rows).sum();
                let label = format!("{jacobian:?}, truth {truth}, {calling:?}");
                assert_eq!(per_set, sensed, "{label}");
                let summary = traced.report.summary.sensor_rows.unwrap();
                assert_eq!(summary.total, sensed, "{label}");
                assert!(summary.median <= summary.p90 && summary.p90 <= summary.max);
                assert!(
                    traced.report.sets.iter().all(|s| s.sensor_rows > 0),
                    "{label}"
                );
            }
        }
    }
    // The kinematic method reads no sensor.
    let agent = Counting::new(Calling::Direct, true);
    let params = TraceParams {
        points: 20,
        ..TraceParams::default()
    };
    let traced = trace(&agent, &env, motors.view(), params);
    assert_eq!(agent.rows.load(Ordering::Relaxed), 0);
    assert!(traced.report.summary.sensor_rows.is_none());
    assert!(traced.report.sets.iter().all(|s| s.sensor_rows == 0));
}

#[test]
fn a_set_stops_at_its_row_cap_and_a_cap_it_never_reaches_changes_nothing() {
    let env = EnvironmentConfig::default().build(arm().as_ref()).unwrap();
    let motors = arm_starts(4, 7);
    let free = trace(
        arm().as_ref(),
        &env,
        motors.view(),
        sensory(JacobianMethod::Secant, 20),
    );
    let most = free
        .report
        .sets
        .iter()
        .map(|s| s.sensor_rows)
        .max()
        .unwrap();
    let least = free
        .report
        .sets
        .iter()
        .map(|s| s.sensor_rows)
        .min()
        .unwrap();
    assert!(least > 400, "{least} rows: too few to cap");
    // A cap above every set's cost: the same sets, bit for bit.
    let above = TraceParams {
        max_rows: most + 1,
        ..sensory(JacobianMethod::Secant, 20)
    };
    let same = trace(arm().as_ref(), &env, motors.view(), above);
    assert_eq!(same.sets, free.sets);
    assert_eq!(same.report.sets, free.report.sets);
    // A cap below every set's cost: each stops there, having read the cap and at most
    // one step's rows more, and the summary says which key to raise.
    let cap = least / 2;
    let below = TraceParams {
        max_rows: cap,
        ..sensory(JacobianMethod::Secant, 20)
    };
    let capped = trace(arm().as_ref(), &env, motors.view(), below);
    for line in &capped.report.sets {
        assert_eq!(line.status, SetStatus::RowBudget);
        assert!(
            (cap..cap + 100).contains(&line.sensor_rows),
            "{} rows against a cap of {cap}",
            line.sensor_rows
        );
    }
    assert!(capped.kept.is_empty());
    let message = capped.report.summary.require(1).unwrap_err().to_string();
    assert!(
        message.contains("4 row-budget") && message.contains("max_rows"),
        "{message}"
    );
    // The cap is part of the table only when set (the pipeline's cache keys of runs
    // without one stay as they were).
    let table = toml::to_string(&sensory(JacobianMethod::Secant, 20)).unwrap();
    assert!(!table.contains("max_rows"), "{table}");
}

#[test]
fn secant_sets_stay_within_a_micro_radian_of_finite_differences_in_fewer_rows() {
    let arm = arm();
    let env = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let motors = arm_starts(10, 7);
    let exact = trace(
        arm.as_ref(),
        &env,
        motors.view(),
        sensory(JacobianMethod::FiniteDifferences, 100),
    );
    let secant = trace(
        arm.as_ref(),
        &env,
        motors.view(),
        sensory(JacobianMethod::Secant, 100),
    );
    assert_eq!(secant.kept, exact.kept, "{:?}", secant.report.summary);
    assert!(exact.kept.len() >= 8, "{:?}", exact.report.summary);
    let period = Periodicity::from(Period::TwoPi);
    for (i, row) in exact.kept.iter().enumerate() {
        assert_eq!(secant.closure[i], exact.closure[i]);
        let (a, b) = (
            exact.sets.index_axis(Axis(0), i),
            secant.sets.index_axis(Axis(0), i),
        );
        let curve = Curve {
            period: period.clone(),
            closure: exact.closure[i],
        };
        let d = curve.distance(a, b).unwrap();
        assert!(
            d < 1e-6,
            "row {row}: the secant set is {d:e} rad from the exact one"
        );
    }
    let rows = |t: &TracedSets| t.report.summary.sensor_rows.unwrap();
    // Measured on 100 starts (the trace_rows benchmark): medians 3 525 and 7 587 rows
    // per start.
    assert!(
        5 * rows(&secant).total < 3 * rows(&exact).total,
        "secant {:?}, finite differences {:?}",
        rows(&secant),
        rows(&exact)
    );
}

#[test]
fn secant_tracing_is_the_same_on_one_thread_and_two() {
    let arm = arm();
    let env = EnvironmentConfig::default().build(arm.as_ref()).unwrap();
    let motors = arm_starts(8, 9);
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                trace(
                    arm.as_ref(),
                    &env,
                    motors.view(),
                    sensory(JacobianMethod::Secant, 40),
                )
            })
    };
    let (one, two) = (on(1), on(2));
    assert_eq!(one.kept, two.kept);
    assert_eq!(one.sets, two.sets, "not bit for bit");
    assert_eq!(one.report, two.report);
}

#[test]
fn three_dimensional_kernels_fail_as_cover_budget_before_any_covering() {
    // Five links and the retina hinge: six motors for a 3-D pose, k = 3, whose covering
    // at the default step is forecast at about 2e6 nodes (max_cover_points 1e5). Without
    // a ground truth the rank is estimated, and the calls are gathered, as a Python
    // agent's are: once the rank is known, no covering is started.
    let chain = AgentConfig {
        kind: "planar-arm".into(),
        params: toml::from_str("link_lengths = [1.0, 1.0, 1.0, 1.0, 1.0]").unwrap(),
    }
    .build()
    .unwrap();
    let agent = Counting::of(chain, Calling::Gathered { callers: 2 }, false);
    let env = EnvironmentConfig::default().build(&agent).unwrap();
    let starts = 4;
    let motors = Array2::from_shape_fn((starts, 6), |(i, j)| 0.4 * (i + 1) as f64 - 0.3 * j as f64);
    let traced = trace(
        &agent,
        &env,
        motors.view(),
        sensory(JacobianMethod::Secant, 20),
    );
    for line in &traced.report.sets {
        assert_eq!((line.dimension, line.status), (3, SetStatus::CoverBudget));
    }
    // The start's reading and a one-sided Jacobian (N rows) per start, for the rank.
    let sensed = agent.rows.load(Ordering::Relaxed);
    assert!(sensed <= (starts * (6 + 1)) as u64, "{sensed} rows sensed");
    let message = traced.report.summary.require(2).unwrap_err().to_string();
    assert!(
        message.contains("4 cover-budget")
            && message.contains("forecast")
            && message.contains("cover_step"),
        "{message}"
    );
}
