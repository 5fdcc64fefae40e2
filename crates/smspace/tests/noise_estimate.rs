//! The noise of a log and the rank of its sensors, measured from the log alone
//! (`smspace::learn::estimate_local`), against simulated logs whose noise and rank are
//! known; and the retina laws of the arm.

use std::f64::consts::PI;
use std::path::PathBuf;

use ndarray::Array2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use smspace::agent::{
    Agent, AgentConfig, ArmParams, ArmRetinaParams, Environment, EnvironmentConfig, Falloff,
    MotorSpace, PlanarArm, Tuning,
};
use smspace::learn::{
    estimate_local, learn, simulate, spectrum_rank, LawParams, LogFiles, SensorimotorLog,
    SimulateParams,
};

fn files() -> LogFiles {
    LogFiles {
        motors: PathBuf::from("m.npy"),
        sensors: PathBuf::from("s.npy"),
    }
}

/// A simulated log of `agent` with `noise`, checked.
fn log_of(agent: &dyn Agent, samples: usize, noise: f64) -> SensorimotorLog {
    let environment = EnvironmentConfig::default().build(agent).unwrap();
    let simulated = simulate(
        agent,
        &environment,
        None,
        &SimulateParams {
            samples,
            noise,
            seed: 3,
            ..SimulateParams::default()
        },
    )
    .unwrap();
    SensorimotorLog::new(
        simulated.motors,
        simulated.sensors,
        files(),
        &agent.motor_space(),
    )
    .unwrap()
}

fn all_rows(log: &SensorimotorLog) -> Vec<u32> {
    (0..log.samples() as u32).collect()
}

#[test]
fn the_noise_of_a_redundant_toy_log_is_measured_within_a_fifth() {
    let toy = AgentConfig::preset("toy-redundant")
        .unwrap()
        .build()
        .unwrap();
    for noise in [0.01, 0.05] {
        let log = log_of(toy.as_ref(), 20_000, noise);
        let (found, rank) = estimate_local(&log, &all_rows(&log), 1).unwrap();
        assert!(found.measurable(), "{noise}: {found:?}");
        for (c, &relative) in found.relative.iter().enumerate() {
            assert!(
                (relative / noise - 1.0).abs() < 0.2,
                "{noise}, sensor {c}: measured {relative} ({found:?})"
            );
        }
        // The sensors see m1 + m2 only: rank 1, one-dimensional kernels.
        assert_eq!(rank.rank, 1, "{noise}: {rank:?}");
    }
    let exact = log_of(toy.as_ref(), 20_000, 0.0);
    let (found, rank) = estimate_local(&exact, &all_rows(&exact), 1).unwrap();
    assert!(found.relative_overall < 0.002, "{found:?}");
    assert_eq!(rank.rank, 1, "{rank:?}");
    // Held out, m1 + m2 predicts as well as both motors: rank 1.
    assert_eq!(rank.held_out_rank, Some(1), "{rank:?}");
    assert!(rank.held_out[1] < 0.1 * rank.held_out[0], "{rank:?}");
}

/// Two hinges, three smooth sensors of rank 2, and Gaussian noise of `noise` (absolute:
/// the sensors' spread is about 0.7).
fn hinge_log(samples: usize, noise: f64) -> SensorimotorLog {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let motors = Array2::from_shape_fn((samples, 2), |_| rng.random_range(-PI..PI));
    let sensors = Array2::from_shape_fn((samples, 3), |(i, k)| {
        let (a, b) = (motors[[i, 0]], motors[[i, 1]]);
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random();
        let normal = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        let value = match k {
            0 => a.sin() + 0.5 * b.cos(),
            1 => (a + b).cos(),
            _ => 0.7 * a.cos() * b.sin(),
        };
        value + noise * normal
    });
    SensorimotorLog::new(motors, sensors, files(), &MotorSpace::hinges(2)).unwrap()
}

#[test]
fn the_noise_of_a_two_hinge_log_is_measured_within_a_fifth() {
    for noise in [0.01, 0.05] {
        let log = hinge_log(40_000, noise);
        let (found, rank) = estimate_local(&log, &all_rows(&log), 2).unwrap();
        assert!(found.measurable(), "{noise}: {found:?}");
        for (c, &sigma) in found.sigma.iter().enumerate() {
            assert!(
                (sigma / noise - 1.0).abs() < 0.2,
                "{noise}, sensor {c}: measured {sigma} ({found:?})"
            );
        }
        // At 5 % the slopes of fits of 12 samples are as large as their noise (floor
        // about 0.9 of the largest): the weaker direction is left under the floor.
        if noise < 0.02 {
            assert_eq!(rank.rank, 2, "{noise}: {rank:?}");
        } else {
            assert!((1..=2).contains(&rank.rank) && rank.floor > 0.5, "{rank:?}");
        }
    }
    let exact = hinge_log(40_000, 0.0);
    let (found, rank) = estimate_local(&exact, &all_rows(&exact), 2).unwrap();
    assert!(found.relative_overall < 0.003, "{found:?}");
    assert_eq!(rank.rank, 2, "{rank:?}");
    // Held out, the fits predict best with both directions: each one lowers the error.
    let held = &rank.held_out;
    assert_eq!(held.len(), 3, "{rank:?}");
    assert!(
        held[2] < 0.5 * held[1] && held[1] < 0.8 * held[0],
        "{rank:?}"
    );
    assert_eq!(rank.held_out_rank, Some(2));
}

#[test]
fn the_estimate_is_the_same_for_one_thread_and_many() {
    let toy = AgentConfig::preset("toy-redundant")
        .unwrap()
        .build()
        .unwrap();
    let log = log_of(toy.as_ref(), 5000, 0.02);
    let rows = all_rows(&log);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| estimate_local(&log, &rows, 7));
    let many = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .unwrap()
        .install(|| estimate_local(&log, &rows, 7));
    assert_eq!(one, many);
}

#[test]
fn the_law_reports_the_noise_the_data_rank_and_what_the_data_cannot_support() {
    let toy = AgentConfig::preset("toy-redundant")
        .unwrap()
        .build()
        .unwrap();
    let space = toy.motor_space();
    let log = log_of(toy.as_ref(), 20_000, 0.05);
    // The local quadratic law, whose fits grow with the noise.
    let params = LawParams {
        method: smspace::learn::LawMethod::LocalQuadratic,
        ..LawParams::default()
    };
    let law = learn(&[log], &space, &params.check().unwrap(), None).unwrap();
    let report = law.report();
    let noise = report.logs[0].noise.as_ref().expect("the noise");
    assert!(
        (noise.relative_overall / 0.05 - 1.0).abs() < 0.2,
        "{noise:?}"
    );
    assert_eq!(report.rank, 1, "{report:?}");
    assert_eq!(report.data_rank.as_ref().unwrap().rank, 1);
    // 5 % noise needs fits of p (0.05 / 0.005)² = 600 samples for the quadratic law
    // (p = 6); the fit holds the most the log allows (16 p = 96, or S/100 = 180).
    let chosen = report.logs[0].neighbours.unwrap();
    assert_eq!(chosen, 96, "{report:?}");
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.contains("measured noise σ̂ = ") && w.contains("more samples")),
        "{:?}",
        report.warnings
    );
    // A log too short to measure its noise says so.
    let short = log_of(toy.as_ref(), 20, 0.0);
    let law = learn(
        &[short],
        &space,
        &LawParams {
            neighbours: Some(5),
            method: smspace::learn::LawMethod::LocalLinear,
            ..LawParams::default()
        }
        .check()
        .unwrap(),
        None,
    )
    .unwrap();
    assert!(
        law.report()
            .warnings
            .iter()
            .any(|w| w.contains("too few samples")),
        "{:?}",
        law.report().warnings
    );
}

#[test]
fn the_retina_laws_change_the_readings_and_the_default_is_the_papers() {
    // The retina near (3, 0) looking along +x, the lights in front.
    let environment = Environment::from_lights(vec![[5.0, 0.5], [6.0, -1.0], [4.0, 2.0]]);
    let motors = [0.1, -0.2, 0.1, 0.05];
    let read = |retina: ArmRetinaParams| {
        let arm = PlanarArm::new(&ArmParams {
            retina,
            ..ArmParams::default()
        })
        .unwrap();
        let mut s = [0.0; 6];
        arm.sense(&environment, &motors, &mut s);
        s
    };
    let paper = read(ArmRetinaParams::default());
    // The paper's law by hand: exp(−(cell − projection)²) / distance.
    let pose = PlanarArm::new(&ArmParams::default())
        .unwrap()
        .planar_pose(&motors);
    let mut expected = [0.0; 6];
    for light in &environment.lights {
        let (dx, dy) = (light[0] - pose.x, light[1] - pose.y);
        let (sin_a, cos_a) = pose.alpha.sin_cos();
        let forward = cos_a * dx + sin_a * dy;
        if forward <= 0.0 {
            continue;
        }
        let projection = -(-sin_a * dx + cos_a * dy) / forward;
        for (c, e) in expected.iter_mut().enumerate() {
            let cell = -1.0 + 2.0 * c as f64 / 5.0;
            *e += (-(cell - projection) * (cell - projection)).exp() / (dx * dx + dy * dy).sqrt();
        }
    }
    assert_eq!(paper, expected, "bit for bit");
    let mut seen = vec![paper];
    for (tuning, falloff) in [
        (Tuning::Cauchy, Falloff::Inverse),
        (Tuning::Cosine, Falloff::Inverse),
        (Tuning::Gaussian, Falloff::None),
        (Tuning::Gaussian, Falloff::InverseSquare),
        (Tuning::Gaussian, Falloff::Exponential),
    ] {
        let s = read(ArmRetinaParams {
            tuning,
            falloff,
            ..ArmRetinaParams::default()
        });
        assert!(s.iter().all(|v| v.is_finite() && *v >= 0.0), "{s:?}");
        assert!(
            seen.iter().all(|other| other != &s),
            "{tuning:?} {falloff:?}"
        );
        seen.push(s);
    }
    for (width, length) in [(0.0, 1.0), (1.0, -2.0), (f64::NAN, 1.0)] {
        let e = PlanarArm::new(&ArmParams {
            retina: ArmRetinaParams {
                tuning_width: width,
                falloff_length: length,
                ..ArmRetinaParams::default()
            },
            ..ArmParams::default()
        })
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("retina.tuning_width") || e.contains("retina.falloff_length"),
            "{e}"
        );
    }
}

#[test]
fn the_rank_of_measured_spectra_ends_at_the_last_clear_gap() {
    // Median slope spectra measured on exact logs of retina laws (experiments/laws):
    // the paper's arm at 10⁵ samples, far lights at 10⁵ and 10⁶ (the largest ratio is
    // between the orientation and the weak position there, yet the rank is 3).
    assert_eq!(spectrum_rank(&[1.0, 0.346, 0.105, 0.021], 0.0), 3);
    assert_eq!(spectrum_rank(&[1.0, 0.230, 0.068, 0.013], 0.0), 3);
    assert_eq!(spectrum_rank(&[1.0, 0.147, 0.045, 0.008], 0.0), 3);
    // The redundant toy, a full-rank law, and values under the floor.
    assert_eq!(spectrum_rank(&[1.0, 0.0007], 0.0), 1);
    assert_eq!(spectrum_rank(&[1.0, 0.4], 0.0), 2);
    assert_eq!(spectrum_rank(&[1.0, 0.147, 0.045, 0.008], 0.1), 2);
    assert_eq!(spectrum_rank(&[1.0, 0.5], 2.0), 0);
}
