//! A log simulated from an agent, so that learning can be tried (and measured against
//! the truth) without a robot: babbling as in [`crate::explore`] (seeded, in the working
//! space when there is one), the agent's sensor values in one environment, and optional
//! Gaussian sensor noise of `relative_noise` times each sensor's standard deviation. The poses
//! are kept aside, for evaluation only (`poses.npy`).

use std::path::{Path, PathBuf};

use ndarray::{Array2, ArrayView2, ArrayViewMut2};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::LearnError;
use crate::agent::{Agent, AgentConfig, Environment, GroundTruth, Workspace};
use crate::explore::{explore_in, ExploreParams};
use crate::io;
use crate::params::{InvalidParameter, Renamed};

/// Parameters of a simulated log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulateParams {
    /// Samples `S`. Default 100 000.
    pub samples: usize,
    /// The key `relative_noise`: the standard deviation of the Gaussian noise added to
    /// every sensor value, as a fraction of that sensor's standard deviation over the
    /// log (`0.01`: 1 % of the signal's spread). Default 0.
    #[serde(rename = "relative_noise")]
    pub noise: f64,
    /// The old name of `relative_noise`, refused with the new one.
    #[serde(rename = "noise", skip_serializing)]
    pub old_noise: Renamed,
    /// Seed of the babbling and of the noise. Default 1.
    pub seed: u64,
}

impl Default for SimulateParams {
    fn default() -> Self {
        Self {
            samples: 100_000,
            noise: 0.0,
            old_noise: Renamed::default(),
            seed: 1,
        }
    }
}

impl SimulateParams {
    /// Checks the parameters: the old key `noise` is refused with its new name
    /// (`relative_noise`), and the noise must be a finite fraction ≥ 0.
    pub fn check(&self) -> Result<(), InvalidParameter> {
        self.old_noise.refuse("data", "noise", "relative_noise")?;
        if !(self.noise.is_finite() && self.noise >= 0.0) {
            return Err(InvalidParameter::new(
                "data",
                "relative_noise",
                self.noise,
                "must be a finite fraction ≥ 0 of each sensor's spread (0.01 for 1 %)",
            ));
        }
        Ok(())
    }
}

/// A simulated log: what a robot would record, and the poses kept aside.
#[derive(Debug, Clone)]
pub struct SimulatedLog {
    /// Motor commands `(S, N)`.
    pub motors: Array2<f64>,
    /// Sensor values `(S, K)`, noise included.
    pub sensors: Array2<f64>,
    /// The observer's poses `(S, d)`, for evaluation only.
    pub poses: Option<GroundTruth>,
}

/// Rows sensed per parallel task.
const CHUNK_ROWS: usize = 4096;

/// Simulates a log of `agent` in `environment` (see the module docs); `workspace`
/// restricts babbling as in exploration (`None`: the whole motor space).
pub fn simulate(
    agent: &dyn Agent,
    environment: &Environment,
    workspace: Option<Workspace>,
    params: &SimulateParams,
) -> Result<SimulatedLog, LearnError> {
    params.check()?;
    let explore = ExploreParams {
        n: params.samples,
        seed: params.seed,
        ..ExploreParams::default()
    };
    let explored = explore_in(agent, &explore, workspace)?;
    let (s, n, k) = (
        explored.motors.nrows(),
        agent.motor_dim(),
        agent.sensor_dim(),
    );
    let mut sensors = Array2::<f64>::zeros((s, k));
    let motors = explored
        .motors
        .as_slice()
        .expect("exploration's motors are in C order");
    sensors
        .as_slice_mut()
        .expect("a new array is in C order")
        .par_chunks_mut(CHUNK_ROWS * k)
        .zip(motors.par_chunks(CHUNK_ROWS * n))
        .for_each(|(out, m)| {
            let rows = m.len() / n;
            let m = ArrayView2::from_shape((rows, n), m).expect("whole rows");
            let out = ArrayViewMut2::from_shape((rows, k), out).expect("whole rows");
            agent.sense_batch(environment, m, out);
        });
    if params.noise > 0.0 {
        add_noise(&mut sensors, params.noise, params.seed);
    }
    Ok(SimulatedLog {
        motors: explored.motors,
        sensors,
        poses: explored.ground_truth,
    })
}

/// Adds `N(0, (noise · std_k)²)` to every sensor `k` (Box–Muller on one seeded stream).
fn add_noise(sensors: &mut Array2<f64>, noise: f64, seed: u64) {
    let deviations: Vec<f64> = sensors
        .columns()
        .into_iter()
        .map(|c| {
            let mean = c.mean().unwrap_or(0.0);
            (c.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / c.len().max(1) as f64).sqrt()
        })
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x006e_6f69_7365);
    for mut row in sensors.outer_iter_mut() {
        for (v, sd) in row.iter_mut().zip(&deviations) {
            let u1: f64 = 1.0 - rng.random::<f64>();
            let u2: f64 = rng.random();
            let normal = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            *v += noise * sd * normal;
        }
    }
}

/// The record of a simulated log (`log.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LogRecord {
    /// The agent's table.
    pub agent: AgentConfig,
    /// The simulation's parameters.
    pub simulate: SimulateParams,
    /// The working space babbling was restricted to.
    pub workspace: Option<Workspace>,
    /// The files, relative to the folder.
    pub files: Vec<String>,
}

/// The files [`SimulatedLog::save`] writes into its folder (`poses.npy` only when the
/// agent has a ground truth).
pub const SIMULATED_LOG_FILES: [&str; 5] = [
    "motors.npy",
    "sensors.npy",
    "poses.npy",
    "environment.json",
    "log.json",
];

impl SimulatedLog {
    /// Bytes of a log of `samples` rows: motors, sensors, poses, and the exploration's
    /// arrays while it is made.
    pub fn bytes(samples: usize, n: usize, k: usize, pose_dim: usize) -> u64 {
        (samples as u64).saturating_mul(8 * (2 * n + k + 2 * pose_dim + 3) as u64)
    }

    /// Writes `motors.npy`, `sensors.npy`, `poses.npy` (when there are poses),
    /// `environment.json` and `log.json` into `dir`, all together; returns their paths.
    pub fn save(
        &self,
        dir: &Path,
        environment: &Environment,
        record: &LogRecord,
    ) -> Result<Vec<PathBuf>, io::IoError> {
        let mut outputs = io::Outputs::new();
        // The names of `SIMULATED_LOG_FILES`.
        outputs.npy(&dir.join("motors.npy"), &self.motors)?;
        outputs.npy(&dir.join("sensors.npy"), &self.sensors)?;
        if let Some(poses) = &self.poses {
            outputs.npy(&dir.join("poses.npy"), poses.poses())?;
        }
        outputs.json(&dir.join("environment.json"), environment)?;
        outputs.json(&dir.join("log.json"), record)?;
        outputs.commit()
    }
}
