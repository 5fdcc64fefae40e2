//! Benchmarks of kernel-set tracing: the paper's 2500 arm loops with fixed steps
//! (`step = 1e-3`, the paper's), adaptive steps, and the sensory method, plus a size
//! sweep of the adaptive kinematic tracer.
//!
//! `cargo bench -p smspace --bench trace`
#![allow(
    missing_docs,
    reason = "criterion_group! generates undocumented functions"
)]

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use ndarray::Array2;
use smspace::agent::{Agent, AgentConfig, Environment, EnvironmentConfig};
use smspace::explore::{explore, ExploreParams};
use smspace::kernel::{trace_sets, StepControl, TraceMethod, TraceParams};
use smspace::progress::Silent;

fn setup(n: usize) -> (Box<dyn Agent>, Environment, Array2<f64>) {
    let agent = AgentConfig::preset("planar-arm").unwrap().build().unwrap();
    let environment = EnvironmentConfig::default().build(agent.as_ref()).unwrap();
    let params = ExploreParams {
        n,
        ..ExploreParams::default()
    };
    let motors = explore(agent.as_ref(), &params).unwrap().motors;
    (agent, environment, motors)
}

fn bench_paper_size(c: &mut Criterion) {
    let (agent, environment, motors) = setup(2500);
    let mut group = c.benchmark_group("trace_2500_arm_loops");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(40));
    for (name, method, step_control) in [
        (
            "kinematic_fixed_step_1e-3",
            TraceMethod::Kinematic,
            StepControl::Fixed,
        ),
        (
            "kinematic_adaptive",
            TraceMethod::Kinematic,
            StepControl::Adaptive,
        ),
        (
            "sensory_adaptive",
            TraceMethod::Sensory,
            StepControl::Adaptive,
        ),
    ] {
        let params = TraceParams {
            method,
            step_control,
            ..TraceParams::default()
        }
        .check()
        .unwrap();
        group.bench_function(name, |b| {
            b.iter(|| {
                trace_sets(
                    agent.as_ref(),
                    Some(&environment),
                    motors.view(),
                    None,
                    &params,
                    &Silent,
                )
                .unwrap()
            })
        });
    }
    group.finish();
}

fn bench_size_sweep(c: &mut Criterion) {
    let mut group = c.benchmark_group("trace_kinematic_adaptive_by_size");
    group.sample_size(10);
    let params = TraceParams {
        step_control: StepControl::Adaptive,
        ..TraceParams::default()
    }
    .check()
    .unwrap();
    for n in [250, 1000, 4000] {
        let (agent, _, motors) = setup(n);
        group.bench_with_input(BenchmarkId::from_parameter(n), &motors, |b, motors| {
            b.iter(|| {
                trace_sets(agent.as_ref(), None, motors.view(), None, &params, &Silent).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_paper_size, bench_size_sweep);
criterion_main!(benches);
