//! Simulated sensor noise: an agent whose readings are another agent's plus seeded
//! Gaussian noise (the `[agent.noise]` table of any agent kind).
//!
//! A reading of motors `m` is `s̃_k = σ_E(m)_k + σ_k z_k` with `z_k ~ N(0, 1)` and
//!
//! `σ_k = √(sigma² + (relative · std_k)²)`,
//!
//! `sigma` in sensor units, `relative` a fraction of sensor `k`'s standard deviation
//! `std_k`: the population standard deviation of the exact readings of
//! [`STD_SAMPLE_ROWS`] motor rows drawn uniformly from the agent's motor space (a fixed
//! seeded sample, [`STD_SAMPLE_SEED`]) in the environment the agent is sensed in. It is
//! computed once per environment (by the environment's lights and intensities) and
//! kept.
//!
//! The noise of a row is a function of the noise `seed`, the bits of the row's motors
//! and the row's index among the identical rows before it in the same batch call (the
//! `z` of a row come from a ChaCha8 stream seeded by a hash of the three): the same
//! rows give the same readings whichever thread asks and in whatever order, and a
//! batch of `r` identical rows gives `r` independent readings, so that a caller can
//! average repeats. A single reading ([`Agent::sense`]) is index 0.
//!
//! ```
//! use smspace::agent::{sense_rows, AgentConfig, Environment};
//! let config: smspace::agent::AgentConfig = toml::from_str(r#"
//!     kind = "planar-arm"
//!     noise = { relative = 0.01, seed = 3 }
//! "#).unwrap();
//! let agent = config.build()?;
//! let environment = Environment::from_lights(vec![[0.0, 2.0], [1.0, 1.5]]);
//! let motors = ndarray::array![[0.1, 0.2, 0.3, 0.4], [0.1, 0.2, 0.3, 0.4]];
//! let readings = sense_rows(agent.as_ref(), &environment, motors.view())?;
//! assert_ne!(readings.row(0), readings.row(1)); // two repeats, two readings
//! # Ok::<(), smspace::agent::AgentError>(())
//! ```

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use ndarray::{ArrayView2, ArrayViewMut2};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use super::{
    Agent, Calling, Environment, LightRegion, LightSpace, MotorSpace, Observer, Workspace,
};
use crate::params::InvalidParameter;

/// Motor rows of the sample the sensors' standard deviations are taken over.
pub const STD_SAMPLE_ROWS: usize = 1024;

/// Seed of the sample of motor rows the sensors' standard deviations are taken over.
pub const STD_SAMPLE_SEED: u64 = 0x5e45_0a5d;

/// The `[agent.noise]` table: Gaussian noise added to every sensor reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseParams {
    /// Standard deviation of each sensor's noise as a fraction of that sensor's
    /// standard deviation over the motor space (see the module docs). Default 0.
    pub relative: f64,
    /// Standard deviation of every sensor's noise in sensor units (added in quadrature
    /// to `relative`'s). Default 0.
    pub sigma: f64,
    /// Seed of the noise. Default 0.
    pub seed: u64,
}

impl Default for NoiseParams {
    fn default() -> Self {
        Self {
            relative: 0.0,
            sigma: 0.0,
            seed: 0,
        }
    }
}

impl NoiseParams {
    /// Checks the values: both standard deviations finite and `≥ 0`.
    pub fn check(&self) -> Result<(), InvalidParameter> {
        for (key, value) in [("relative", self.relative), ("sigma", self.sigma)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(InvalidParameter::new(
                    "agent.noise",
                    key,
                    value,
                    "must be a finite number ≥ 0 (a standard deviation)",
                ));
            }
        }
        Ok(())
    }

    /// Whether any noise is added.
    pub fn is_noisy(&self) -> bool {
        self.relative > 0.0 || self.sigma > 0.0
    }
}

/// An agent whose readings carry seeded Gaussian noise (see the module docs); every
/// other part (motor space, ground truth, working space, body) is the wrapped agent's.
#[derive(Debug)]
pub struct NoisyAgent {
    inner: Box<dyn Agent>,
    params: NoiseParams,
    /// `std_k` of every environment met so far, by a hash of the environment.
    stds: Mutex<HashMap<u64, Arc<Vec<f64>>>>,
}

/// SplitMix64's finaliser: a well-mixed 64-bit hash step.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash of a sequence of words, seeded.
fn hash_words(seed: u64, words: impl Iterator<Item = u64>) -> u64 {
    words.fold(mix(seed ^ 0x9e37_79b9_7f4a_7c15), |h, w| {
        mix(h.wrapping_add(0x9e37_79b9_7f4a_7c15) ^ w)
    })
}

impl NoisyAgent {
    /// `inner`'s readings with the noise of `params` (checked).
    pub fn new(inner: Box<dyn Agent>, params: NoiseParams) -> Result<Self, InvalidParameter> {
        params.check()?;
        Ok(Self {
            inner,
            params,
            stds: Mutex::new(HashMap::new()),
        })
    }

    /// The agent without noise.
    pub fn inner(&self) -> &dyn Agent {
        self.inner.as_ref()
    }

    /// The noise parameters.
    pub fn params(&self) -> NoiseParams {
        self.params
    }

    /// Each sensor's noise standard deviation `σ_k` in `environment` (sensor units).
    pub fn sigmas(&self, environment: &Environment) -> Vec<f64> {
        let stds = self.stds(environment);
        stds.iter()
            .map(|s| (self.params.sigma.powi(2) + (self.params.relative * s).powi(2)).sqrt())
            .collect()
    }

    /// `std_k` in `environment`, computed on first use (see the module docs).
    fn stds(&self, environment: &Environment) -> Arc<Vec<f64>> {
        let key = hash_words(
            environment.lights.len() as u64,
            environment
                .lights
                .iter()
                .flatten()
                .chain(&environment.intensities)
                .map(|v| v.to_bits()),
        );
        if let Some(found) = self.stds.lock().ok().and_then(|m| m.get(&key).cloned()) {
            return found;
        }
        let stds = Arc::new(sensor_stds(self.inner.as_ref(), environment));
        if let Ok(mut map) = self.stds.lock() {
            map.insert(key, stds.clone());
        }
        stds
    }

    /// Adds the noise of the row `motors`, the `index`-th repeat of it in its batch.
    fn add_noise(&self, motors: &[f64], index: u64, sigmas: &[f64], sensors: &mut [f64]) {
        let words = motors.iter().map(|m| m.to_bits()).chain([index]);
        let mut rng = ChaCha8Rng::seed_from_u64(hash_words(self.params.seed, words));
        for (s, sigma) in sensors.iter_mut().zip(sigmas) {
            *s += sigma * standard_normal(&mut rng);
        }
    }
}

/// A standard normal draw (Box–Muller).
fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random_range(0.0..1.0);
    let u2: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Population standard deviation of every sensor over [`STD_SAMPLE_ROWS`] motor rows
/// drawn uniformly from the motor space (hinges over their period, bounded motors over
/// their range).
fn sensor_stds(agent: &dyn Agent, environment: &Environment) -> Vec<f64> {
    let (n, k) = (agent.motor_dim(), agent.sensor_dim());
    let space = agent.motor_space();
    let mut rng = ChaCha8Rng::seed_from_u64(STD_SAMPLE_SEED);
    let mut motors = ndarray::Array2::zeros((STD_SAMPLE_ROWS, n));
    for mut row in motors.outer_iter_mut() {
        for (x, motor) in row.iter_mut().zip(space.motors()) {
            let (low, high) = motor.range();
            *x = if high > low {
                rng.random_range(low..high)
            } else {
                low
            };
        }
    }
    let mut sensors = ndarray::Array2::zeros((STD_SAMPLE_ROWS, k));
    agent.sense_batch(environment, motors.view(), sensors.view_mut());
    sensors
        .columns()
        .into_iter()
        .map(|c| {
            let mean = c.sum() / c.len() as f64;
            (c.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / c.len() as f64).sqrt()
        })
        .collect()
}

impl Agent for NoisyAgent {
    fn motor_dim(&self) -> usize {
        self.inner.motor_dim()
    }
    fn sensor_dim(&self) -> usize {
        self.inner.sensor_dim()
    }
    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        self.inner.sense(environment, motors, sensors);
        self.add_noise(motors, 0, &self.sigmas(environment), sensors);
    }
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn motor_space(&self) -> MotorSpace {
        self.inner.motor_space()
    }
    fn sense_batch(
        &self,
        environment: &Environment,
        motors: ArrayView2<'_, f64>,
        mut sensors: ArrayViewMut2<'_, f64>,
    ) {
        self.inner
            .sense_batch(environment, motors, sensors.view_mut());
        let sigmas = self.sigmas(environment);
        let mut seen: HashMap<Vec<u64>, u64> = HashMap::new();
        let mut row = vec![0.0; motors.ncols()];
        let mut out = vec![0.0; sensors.ncols()];
        for (m, mut s) in motors.outer_iter().zip(sensors.outer_iter_mut()) {
            row.iter_mut().zip(m.iter()).for_each(|(a, &b)| *a = b);
            let index = if motors.nrows() > 1 {
                let count = seen
                    .entry(row.iter().map(|v| v.to_bits()).collect())
                    .or_default();
                *count += 1;
                *count - 1
            } else {
                0
            };
            out.iter_mut().zip(s.iter()).for_each(|(a, &b)| *a = b);
            self.add_noise(&row, index, &sigmas, &mut out);
            s.iter_mut().zip(&out).for_each(|(a, &b)| *a = b);
        }
    }
    fn calling(&self) -> Calling {
        Calling::Direct
    }
    fn host_threads(&self) -> Option<&rayon::ThreadPool> {
        self.inner.host_threads()
    }
    fn covers(&self, motors: &[f64]) -> bool {
        self.inner.covers(motors)
    }
    fn ground_truth(&self) -> Option<&dyn Observer> {
        self.inner.ground_truth()
    }
    fn sensed_configuration(&self) -> Option<&dyn Observer> {
        self.inner.sensed_configuration()
    }
    fn attribute_motors(&self) -> Vec<usize> {
        self.inner.attribute_motors()
    }
    fn default_workspace(&self) -> Option<Workspace> {
        self.inner.default_workspace()
    }
    fn skeleton(&self, motors: &[f64]) -> Vec<[f64; 2]> {
        self.inner.skeleton(motors)
    }
    fn default_light_region(&self) -> LightRegion {
        self.inner.default_light_region()
    }
    fn default_light_count(&self) -> usize {
        self.inner.default_light_count()
    }
    fn light_space(&self) -> LightSpace {
        self.inner.light_space()
    }
    fn stimulus(&self) -> super::Stimulus {
        self.inner.stimulus()
    }
    fn default_light_heights(&self) -> [f64; 2] {
        self.inner.default_light_heights()
    }
    fn noiseless(&self) -> Option<&dyn Agent> {
        Some(self.inner.as_ref())
    }
}
