//! Kernel sets from noisy sensors: the seeded noisy agent, the noise measured at the
//! starts, and the sets of the mean law against the exact ones.

use ndarray::{Array2, ArrayView2};
use smspace::agent::{
    sense_rows, Agent, AgentConfig, Environment, EnvironmentConfig, NoiseParams, NoisyAgent,
};
use smspace::explore::{explore, ExploreParams};
use smspace::kernel::{trace_sets, SensorNoise, TraceMethod, TraceParams, TracedSets};
use smspace::metric::Period;
use smspace::progress::Silent;

fn arm() -> Box<dyn Agent> {
    AgentConfig::preset("planar-arm").unwrap().build().unwrap()
}

fn noisy_arm(relative: f64) -> NoisyAgent {
    let params = NoiseParams {
        relative,
        sigma: 0.0,
        seed: 7,
    };
    NoisyAgent::new(arm(), params).unwrap()
}

fn starts(n: usize, seed: u64) -> Array2<f64> {
    let params = ExploreParams {
        n,
        seed,
        ..ExploreParams::default()
    };
    explore(arm().as_ref(), &params).unwrap().motors
}

fn sensory(noise: SensorNoise) -> TraceParams {
    TraceParams {
        method: TraceMethod::Sensory,
        noise,
        points: 50,
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

#[test]
fn the_noisy_agent_is_seeded_and_repeats_differ() {
    let agent = noisy_arm(0.01);
    let env = EnvironmentConfig::default().build(&agent).unwrap();
    let row = [0.3, -0.2, 1.0, 0.5];
    let motors = ndarray::array![
        [0.3, -0.2, 1.0, 0.5],
        [0.3, -0.2, 1.0, 0.5],
        [0.1, 0.0, 0.0, 0.0]
    ];
    let a = sense_rows(&agent, &env, motors.view()).unwrap();
    let b = sense_rows(&agent, &env, motors.view()).unwrap();
    assert_eq!(a, b, "the same batch gives the same readings");
    assert_ne!(a.row(0), a.row(1), "repeats in one batch differ");
    let mut one = vec![0.0; agent.sensor_dim()];
    agent.sense(&env, &row, &mut one);
    assert_eq!(
        a.row(0).to_vec(),
        one,
        "a single reading is the first repeat"
    );
    // The noise has the standard deviation asked for, sensor by sensor.
    let sigmas = agent.sigmas(&env);
    let repeats = Array2::from_shape_fn((4000, 4), |(_, j)| row[j]);
    let readings = sense_rows(&agent, &env, repeats.view()).unwrap();
    let mut exact = vec![0.0; agent.sensor_dim()];
    agent.inner().sense(&env, &row, &mut exact);
    for (k, sigma) in sigmas.iter().enumerate() {
        let column = readings.column(k);
        let sd = (column.iter().map(|v| (v - exact[k]).powi(2)).sum::<f64>() / 4000.0).sqrt();
        assert!(
            (sd / sigma - 1.0).abs() < 0.06,
            "sensor {k}: {sd} vs {sigma}"
        );
    }
}

#[test]
fn the_noise_is_measured_within_a_fifth_of_the_truth() {
    for relative in [0.005, 0.01, 0.05] {
        let agent = noisy_arm(relative);
        let env = EnvironmentConfig::default().build(&agent).unwrap();
        let truth = {
            let s = agent.sigmas(&env);
            (s.iter().map(|x| x * x).sum::<f64>() / s.len() as f64).sqrt()
        };
        let motors = starts(4, 3);
        let mut p = sensory(SensorNoise::Auto);
        p.max_steps = 1;
        p.piece_starts = 0;
        let traced = trace_sets(
            &agent,
            Some(&env),
            motors.view(),
            None,
            &p.check().unwrap(),
            &Silent,
        );
        let reports = match traced {
            Ok(t) => t.report.sets,
            Err(e) => panic!("{e}"),
        };
        for set in reports {
            let sigma = set.noise.expect("noise measured").sigma;
            assert!(
                (sigma / truth - 1.0).abs() < 0.2,
                "{relative}: {sigma} vs {truth}"
            );
        }
    }
}

#[test]
fn noisy_sets_close_near_the_exact_ones_for_any_thread_count() {
    let agent = noisy_arm(0.01);
    let env = EnvironmentConfig::default().build(&agent).unwrap();
    let motors = starts(6, 5);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| trace(&agent, &env, motors.view(), sensory(SensorNoise::Auto)))
    };
    let one = run(1);
    let two = run(2);
    assert_eq!(one.sets, two.sets);
    assert_eq!(one.report, two.report);
    assert!(one.kept.len() >= 3, "{:?}", one.report.summary);
    assert!(one.report.summary.noise.is_some());
    let exact = trace(
        agent.inner(),
        &env,
        motors.view(),
        sensory(SensorNoise::Auto),
    );
    let errors = smspace::learn::set_errors(&one, &exact, Period::TwoPi).unwrap();
    assert!(errors.median <= 0.05, "{errors:?}");
}

#[test]
fn exact_readings_trace_as_before_with_one_row_more() {
    let agent = arm();
    let env = EnvironmentConfig::default().build(agent.as_ref()).unwrap();
    let motors = starts(5, 9);
    let auto = trace(
        agent.as_ref(),
        &env,
        motors.view(),
        sensory(SensorNoise::Auto),
    );
    let zero = trace(
        agent.as_ref(),
        &env,
        motors.view(),
        sensory(SensorNoise::Sigma(0.0)),
    );
    assert_eq!(auto.sets, zero.sets);
    assert_eq!(auto.kept, zero.kept);
    for (a, z) in auto.report.sets.iter().zip(&zero.report.sets) {
        assert_eq!(a.sensor_rows, z.sensor_rows + 1);
        assert!(a.noise.is_none());
    }
    assert!(auto.report.summary.noise.is_none());
}

#[test]
fn bad_noise_values_name_their_key() {
    let err = toml::from_str::<TraceParams>("noise = \"foo\"")
        .unwrap_err()
        .to_string();
    assert!(err.contains("noise") && err.contains("auto"), "{err}");
    let p: TraceParams = toml::from_str("noise = -1").unwrap();
    let err = p.check().unwrap_err().to_string();
    assert!(err.contains("noise"), "{err}");
    let p: TraceParams = toml::from_str("noise = 0.02").unwrap();
    assert_eq!(p.noise, SensorNoise::Sigma(0.02));
    assert!(p.check().is_ok());
    let build = |text: &str| toml::from_str::<AgentConfig>(text).unwrap().build();
    let err = build("kind = \"planar-arm\"\nnoise = { relative = -1.0 }").unwrap_err();
    assert!(err.to_string().contains("relative"), "{err}");
    let err = build("kind = \"planar-arm\"\nnoise = { relativ = 0.1 }").unwrap_err();
    assert!(err.to_string().contains("relativ"), "{err}");
    let built = smspace::agent::AgentRegistry::builtin()
        .build(&toml::from_str("kind = \"planar-arm\"\n[noise]\nrelative = 0.01").unwrap())
        .unwrap();
    assert!(built.agent.noiseless().is_some());
    assert!(built.config.params["noise"].get("seed").is_some());
}
