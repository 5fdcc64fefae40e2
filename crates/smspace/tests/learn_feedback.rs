//! Learning's feedback (`smspace::learn`): its stages as a progress observer sees them,
//! its memory estimate, and its quality without the truth (a short log warns, a good one
//! does not), on seeded logs of a three-hinge arm whose sensors read the tip's position.

use std::path::PathBuf;
use std::sync::Mutex;

use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use smspace::agent::MotorSpace;
use smspace::learn::{
    law_trace_params, learn, learn_with_progress, observe, trace_learned, LawMethod, LawParams,
    LogFiles, SensorimotorLog,
};
use smspace::progress::{Progress, Silent};

/// `samples` uniform configurations of three hinges, and the sensors `(x, y)` of the tip
/// of links 1, 0.8, 0.6: a sensory manifold of dimension 2, kernels of dimension 1.
fn arm_log(samples: usize, seed: u64) -> (MotorSpace, SensorimotorLog) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let motors = Array2::from_shape_fn((samples, 3), |_| {
        rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)
    });
    let sensors = Array2::from_shape_fn((samples, 2), |(i, c)| {
        let (mut angle, mut x, mut y) = (0.0, 0.0, 0.0);
        for (j, length) in [1.0, 0.8, 0.6].into_iter().enumerate() {
            angle += motors[[i, j]];
            x += length * f64::cos(angle);
            y += length * f64::sin(angle);
        }
        if c == 0 {
            x
        } else {
            y
        }
    });
    let space = MotorSpace::hinges(3);
    let files = LogFiles {
        motors: PathBuf::from("m.npy"),
        sensors: PathBuf::from("s.npy"),
    };
    let log = SensorimotorLog::new(motors, sensors, files, &space).unwrap();
    (space, log)
}

fn invariants() -> LawParams {
    LawParams {
        method: LawMethod::Invariants,
        // Coverage only: small enough for the short log's bandwidth.
        neighbours: Some(10),
        ..LawParams::default()
    }
}

/// Every call, in order: `(stage, total)` at a start, the units advanced until its end.
#[derive(Default)]
struct Recorder {
    stages: Mutex<Vec<(String, u64, u64)>>,
}

impl Progress for Recorder {
    fn start(&self, stage: &str, total: u64) {
        self.stages
            .lock()
            .unwrap()
            .push((stage.to_owned(), total, 0));
    }
    fn advance(&self, done: u64) {
        if let Some(last) = self.stages.lock().unwrap().last_mut() {
            last.2 += done;
        }
    }
}

#[test]
fn every_stage_of_learning_is_reported_and_the_law_does_not_depend_on_the_observer() {
    let (space, log) = arm_log(6000, 1);
    let params = invariants().check().unwrap();
    let recorder = Recorder::default();
    let pool = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
    };
    let observed = pool(3).install(|| {
        learn_with_progress(std::slice::from_ref(&log), &space, &params, None, &recorder)
    });
    let silent = pool(1).install(|| learn(std::slice::from_ref(&log), &space, &params, None));
    let (observed, silent) = (observed.unwrap(), silent.unwrap());
    // The same law, and the same report.
    assert_eq!(observed.report(), silent.report());
    let stages = recorder.stages.into_inner().unwrap();
    let names: Vec<&str> = stages.iter().map(|s| s.0.as_str()).collect();
    assert_eq!(
        names,
        [
            observe::NOISE,
            observe::SENSOR_TREE,
            observe::PAIRS,
            observe::BASIS,
            observe::EIGEN,
            observe::HELD_PAIRS,
            observe::TREE,
            observe::INVARIANT_TREE,
            observe::HELD_OUT,
            observe::RANK,
        ]
    );
    // Every stage reaches its total.
    for (stage, total, done) in &stages {
        assert_eq!(done, total, "{stage}");
    }
    let fitted = observed.report().logs[0].fitted as u64;
    assert_eq!(stages[2].1, fitted);
    let memory = observed.report().memory.expect("the estimate");
    assert_eq!(memory.threads, None);
    assert!(memory.bytes_per_thread > 0);
    assert_eq!(memory.log_bytes, 6000 * 5 * 8);
}

#[test]
fn the_local_fits_report_their_stages_too() {
    let (space, log) = arm_log(6000, 2);
    let params = LawParams {
        method: LawMethod::LocalLinear,
        ..LawParams::default()
    }
    .check()
    .unwrap();
    let recorder = Recorder::default();
    learn_with_progress(&[log], &space, &params, None, &recorder).unwrap();
    let stages = recorder.stages.into_inner().unwrap();
    let names: Vec<&str> = stages.iter().map(|s| s.0.as_str()).collect();
    assert_eq!(
        names,
        [
            observe::NOISE,
            observe::TREE,
            observe::HELD_OUT,
            observe::RANK
        ]
    );
    assert!(stages.iter().all(|(_, total, done)| done == total));
}

#[test]
fn a_log_over_the_memory_limit_is_refused_with_its_parts_and_the_fix() {
    let (space, log) = arm_log(2000, 3);
    let params = invariants().check().unwrap();
    let error = learn(&[log], &space, &params, Some(100_000))
        .unwrap_err()
        .to_string();
    assert!(error.contains("but the limit is 97.7 KiB"), "{error}");
    // The parts: the log is 2000 × 5 float64.
    assert!(error.contains("(log 78.1 KiB, trees "), "{error}");
    assert!(error.contains("raise the limit"), "{error}");
}

#[test]
fn a_too_short_log_warns_that_it_cannot_resolve_its_manifold() {
    let (space, log) = arm_log(400, 4);
    let law = learn(&[log], &space, &invariants().check().unwrap(), None).unwrap();
    let report = law.report();
    let per = report.quality.samples_per_dimension.expect("figure");
    assert_eq!(report.quality.resolved_dimension, Some(2), "{report:?}");
    assert!(per < 20.0, "{per}");
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.contains("per dimension") && w.contains("record about 1600 samples")),
        "{:?}",
        report.warnings
    );
}

#[test]
fn a_good_log_gives_its_quality_and_no_warning() {
    let (space, log) = arm_log(20_000, 5);
    let law = learn(&[log], &space, &invariants().check().unwrap(), None).unwrap();
    let report = law.report();
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    let quality = &report.quality;
    let per = quality.samples_per_dimension.unwrap();
    assert_eq!(quality.resolved_dimension, Some(2));
    assert!(per > 100.0, "{per}");
    // Exact sensors: the invariants barely change between sensory neighbours, held out
    // as fitted.
    let change = quality.neighbour_change.unwrap();
    assert!(change < 0.2, "{quality:?}");
    assert!(quality.held_out_ratio.unwrap() < 2.0, "{quality:?}");
    // Tracing closes the curves: the closure rate, and still no warning.
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let starts = Array2::from_shape_fn((12, 3), |_| rng.random_range(-3.0..3.0));
    let traced = trace_learned(&law, starts.view(), &law_trace_params(), &Silent).unwrap();
    let completed = report.with_trace(&traced.report.summary);
    let rate = completed.quality.closure_rate.expect("curves were traced");
    assert!(rate >= 0.75, "{:?}", traced.report.summary.by_status);
    assert!(completed.warnings.is_empty(), "{:?}", completed.warnings);
    // The sets' report carries the completed law report.
    let law_json = traced.report.law.as_ref().expect("the law's report");
    assert_eq!(
        law_json["quality"]["closure_rate"].as_f64(),
        Some(rate),
        "{law_json}"
    );
}
