//! Agents and environments: the sensorimotor law `s = σ_E(m)` (paper section 2.1, eq. 2).
//!
//! An [`Agent`] maps motor commands `m ∈ ℝ^N` to raw sensor values `s ∈ ℝ^K` in an
//! [`Environment`] of point lights. For evaluation only, it also exposes the observer's
//! ground truth: the external configuration of its sensor, a [`Pose`] `(x, y, alpha)`.
//! The agent itself never uses the pose; the `kinematic` tracing method does, as the
//! paper's simulation does "only to accelerate the simulation" (section 3.2, step 2).
//!
//! Three agents are built in:
//!
//! | name | paper | motors `N` | sensors `K` | pose |
//! |---|---|---|---|---|
//! | [`ToyAgent`] `toy-line` | 2.2, agent 1 | 1 | 2 | `x = m1` |
//! | [`ToyAgent`] `toy-redundant` | 2.3, agent 2 | 2 | 2 | `x = m1 + m2` |
//! | [`PlanarArm`] `planar-arm` | 3.1 | links + 1 | `retina_cells` | retina `(x, y, alpha)` |
//!
//! Build one from its parameter table with [`AgentConfig::build`], or by name with
//! [`AgentConfig::preset`].

mod arm;
mod environment;
mod registry;
mod toy;
mod workspace;

use std::f64::consts::PI;
use std::fmt;

use ndarray::{ArrayView2, ArrayViewMut2};
use serde::{Deserialize, Serialize};

pub use arm::{ArmParams, PlanarArm, MAX_LINKS, MAX_RETINA_CELLS};
pub use environment::{
    Environment, EnvironmentConfig, LightRegion, MAX_DRAWS_PER_LIGHT, MAX_RANDOM_LIGHTS,
};
pub use registry::{AgentBuilder, AgentRegistry, BuiltAgent};
pub use toy::{ToyAgent, ToyKind, ToyParams};
pub use workspace::Workspace;

/// Errors of building agents and environments.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AgentError {
    /// No registered agent kind has this name.
    #[error("unknown agent '{name}'; the registered agents are {known} (or give a TOML file with an [agent] table)")]
    UnknownAgent {
        /// The name given.
        name: String,
        /// The registered kinds, comma-separated.
        known: String,
    },
    /// The `[agent]` table does not describe an agent of its kind (an unknown key, a
    /// value of the wrong type).
    #[error("invalid [agent] table for the {kind} agent: {reason}")]
    InvalidTable {
        /// The kind.
        kind: String,
        /// The reader's message, naming the key.
        reason: String,
    },
    /// A parameter is out of its domain.
    #[error("invalid agent parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// The parameter's name, as in the configuration file.
        name: &'static str,
        /// The value given, formatted.
        value: String,
        /// What a valid value looks like.
        reason: &'static str,
    },
    /// A motor array does not fit the agent.
    #[error(
        "motor configurations have {found} columns but the {agent} agent has {expected} motors"
    )]
    MotorDimension {
        /// The agent's name.
        agent: String,
        /// Columns found.
        found: usize,
        /// Motors of the agent.
        expected: usize,
    },
    /// An environment is invalid for this agent.
    #[error("invalid environment: {reason}")]
    InvalidEnvironment {
        /// What is wrong.
        reason: String,
    },
}

/// The observer's ground truth of the sensor's external configuration: position
/// `(x, y)` in the plane (length units of the agent) and orientation `alpha` (radians).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position along the world's x axis.
    pub x: f64,
    /// Position along the world's y axis.
    pub y: f64,
    /// Orientation of the sensor's optical axis, radians from the x axis.
    pub alpha: f64,
}

impl Pose {
    /// The pose as `[x, y, alpha]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.x, self.y, self.alpha]
    }

    /// `self − other` as `[Δx, Δy, Δalpha]`, with `Δalpha` wrapped into `[-π, π)`.
    pub fn difference(self, other: Pose) -> [f64; 3] {
        [
            self.x - other.x,
            self.y - other.y,
            wrap_angle(self.alpha - other.alpha),
        ]
    }

    /// The pose from `[x, y, alpha]`.
    pub fn from_array(a: [f64; 3]) -> Self {
        Self {
            x: a[0],
            y: a[1],
            alpha: a[2],
        }
    }
}

/// How motor coordinates behave.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MotorTopology {
    /// Every motor is a hinge angle: configurations live on the torus `[-π, π)^N` and
    /// kernel sets are closed loops.
    Periodic,
    /// Every motor ranges over `[low, high]` without wrapping (a linear actuator): kernel
    /// sets are segments ending on the boundary of the motor box.
    Bounded {
        /// Lower end of every motor's range.
        low: f64,
        /// Upper end of every motor's range.
        high: f64,
    },
}

impl MotorTopology {
    /// The interval motor babbling draws each coordinate from.
    pub fn range(self) -> (f64, f64) {
        match self {
            MotorTopology::Periodic => (-PI, PI),
            MotorTopology::Bounded { low, high } => (low, high),
        }
    }

    /// The difference `a − b` of one motor coordinate, wrapped into `[-π, π)` when periodic.
    #[inline]
    pub fn difference(self, a: f64, b: f64) -> f64 {
        match self {
            MotorTopology::Periodic => wrap_angle(a - b),
            MotorTopology::Bounded { .. } => a - b,
        }
    }

    /// Distance between two configurations: Euclidean, with every coordinate difference
    /// wrapped into `[-π, π)` when periodic (the paper's `g`, section 3.2).
    pub fn distance(self, a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(&x, &y)| {
                let d = self.difference(x, y);
                d * d
            })
            .sum::<f64>()
            .sqrt()
    }
}

/// Wraps an angle into `[-π, π)`.
#[inline]
pub fn wrap_angle(angle: f64) -> f64 {
    if (-PI..PI).contains(&angle) {
        return angle;
    }
    let wrapped = (angle + PI).rem_euclid(2.0 * PI) - PI;
    // rem_euclid can round up to exactly 2π for tiny negative inputs.
    if wrapped >= PI {
        wrapped - 2.0 * PI
    } else {
        wrapped
    }
}

/// A sensorimotor agent: the law `s = σ_E(m)` plus, for evaluation, the observer's pose.
///
/// Required: [`motor_dim`](Agent::motor_dim), [`sensor_dim`](Agent::sensor_dim),
/// [`sense`](Agent::sense) and [`pose`](Agent::pose). The other methods have defaults.
pub trait Agent: Send + Sync + fmt::Debug {
    /// Number of motors `N`.
    fn motor_dim(&self) -> usize;

    /// Number of sensors `K`.
    fn sensor_dim(&self) -> usize;

    /// Writes the sensor values `s = σ_E(m)` for motors `m` (length `N`) into `sensors`
    /// (length `K`).
    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]);

    /// The observer's ground truth: the sensor's pose for motors `m`.
    fn pose(&self, motors: &[f64]) -> Pose;

    /// A short name, e.g. `planar-arm` (owned by the agent, so that an agent described
    /// at run time names itself).
    fn name(&self) -> &str;

    /// Writes the sensor values of many motor rows: `motors` is `(M, N)`, `sensors`
    /// `(M, K)`. The default calls [`sense`](Agent::sense) row by row; an agent that is
    /// costly to call (a simulator in another language, a remote robot) overrides it to
    /// answer all rows at once.
    fn sense_batch(
        &self,
        environment: &Environment,
        motors: ArrayView2<'_, f64>,
        mut sensors: ArrayViewMut2<'_, f64>,
    ) {
        let mut m = vec![0.0; motors.ncols()];
        let mut s = vec![0.0; sensors.ncols()];
        for (row, mut out) in motors.outer_iter().zip(sensors.outer_iter_mut()) {
            m.iter_mut().zip(row.iter()).for_each(|(a, &b)| *a = b);
            self.sense(environment, &m, &mut s);
            out.iter_mut().zip(&s).for_each(|(a, &b)| *a = b);
        }
    }

    /// The working space this agent explores when the experiment names none: a
    /// rectangle of sensor positions it can reach. The default is none (babbling over
    /// the whole motor range).
    fn default_workspace(&self) -> Option<Workspace> {
        None
    }

    /// How many leading coordinates of the pose `(x, y, alpha)` the motors can change:
    /// 1 for the toys (`x`), 3 for the arm. The kernel sets have dimension
    /// `N − configuration_dim()` where the pose Jacobian has full rank.
    fn configuration_dim(&self) -> usize {
        3
    }

    /// Whether motors are hinge angles (periodic) or bounded linear actuators.
    fn motor_topology(&self) -> MotorTopology {
        MotorTopology::Periodic
    }

    /// Writes the pose Jacobian `∂(x, y, alpha)/∂m` (3 × N, row-major) into `jacobian`
    /// and returns the pose. The default uses central differences of [`pose`](Agent::pose)
    /// with step `1e-6`, wrapping the `alpha` difference.
    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64]) -> Pose {
        let n = self.motor_dim();
        let h = 1e-6;
        let mut m = motors.to_vec();
        for j in 0..n {
            m[j] = motors[j] + h;
            let plus = self.pose(&m);
            m[j] = motors[j] - h;
            let minus = self.pose(&m);
            m[j] = motors[j];
            jacobian[j] = (plus.x - minus.x) / (2.0 * h);
            jacobian[n + j] = (plus.y - minus.y) / (2.0 * h);
            jacobian[2 * n + j] = wrap_angle(plus.alpha - minus.alpha) / (2.0 * h);
        }
        self.pose(motors)
    }

    /// One motor configuration that puts the sensor at `pose`, if the agent can reach it
    /// (used for the probe grid). The default knows no inverse kinematics.
    fn inverse_kinematics(&self, _pose: Pose) -> Option<Vec<f64>> {
        None
    }

    /// The body drawn for motors `m`: joint positions in the plane, from the base to the
    /// sensor, for figures only (paper Fig. 5a). The default is empty: the agent has no
    /// body to draw.
    fn skeleton(&self, _motors: &[f64]) -> Vec<[f64; 2]> {
        Vec::new()
    }

    /// Where random lights go by default for this agent.
    fn default_light_region(&self) -> LightRegion;

    /// How many lights a random environment has by default (5 for the toys, 10 for the arm).
    fn default_light_count(&self) -> usize;
}

/// An agent's `[agent]` table: `kind` picks a kind of an [`AgentRegistry`] and the other
/// keys are that kind's parameters (unknown keys are errors when the agent is built).
///
/// ```
/// use smspace::agent::AgentConfig;
/// let config: AgentConfig = toml::from_str(r#"
///     kind = "planar-arm"
///     link_lengths = [1.0, 1.0, 1.0]
///     retina_cells = 6
/// "#).unwrap();
/// let agent = config.build().unwrap();
/// assert_eq!((agent.motor_dim(), agent.sensor_dim()), (4, 6));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AgentConfig {
    /// The agent's kind (`toy-line`, `toy-redundant`, `planar-arm`, or a registered one).
    pub kind: String,
    /// The kind's parameters; missing ones take the kind's defaults.
    #[serde(flatten)]
    pub params: toml::Table,
}

impl AgentConfig {
    /// The built-in agent called `name` with default parameters.
    pub fn preset(name: &str) -> Result<Self, AgentError> {
        let registry = AgentRegistry::builtin();
        if registry.summary(name).is_none() {
            return Err(AgentError::UnknownAgent {
                name: name.to_owned(),
                known: registry.kinds().collect::<Vec<_>>().join(", "),
            });
        }
        Ok(Self {
            kind: name.to_owned(),
            params: toml::Table::new(),
        })
    }

    /// The agent's kind.
    pub fn name(&self) -> &str {
        &self.kind
    }

    /// Validates the parameters and builds a built-in agent (for registered kinds, see
    /// [`AgentRegistry::build`]).
    pub fn build(&self) -> Result<Box<dyn Agent>, AgentError> {
        AgentRegistry::builtin().build(self).map(|b| b.agent)
    }
}

/// Checks that motor configurations of `found` coordinates fit `agent`.
pub fn check_motor_count(agent: &dyn Agent, found: usize) -> Result<(), AgentError> {
    if found == agent.motor_dim() {
        return Ok(());
    }
    Err(AgentError::MotorDimension {
        agent: agent.name().to_owned(),
        found,
        expected: agent.motor_dim(),
    })
}

/// The sensor values `(M, K)` of the motor rows `(M, N)` in `environment`, through
/// [`Agent::sense_batch`].
///
/// ```
/// use smspace::agent::{sense_rows, AgentConfig, Environment};
/// let agent = AgentConfig::preset("toy-line")?.build()?;
/// let environment = Environment::from_lights(vec![[0.0, 1.0]]);
/// let motors = ndarray::array![[0.0], [0.5]];
/// let sensors = sense_rows(agent.as_ref(), &environment, motors.view())?;
/// assert_eq!(sensors.dim(), (2, agent.sensor_dim()));
/// # Ok::<(), smspace::agent::AgentError>(())
/// ```
pub fn sense_rows(
    agent: &dyn Agent,
    environment: &Environment,
    motors: ArrayView2<'_, f64>,
) -> Result<ndarray::Array2<f64>, AgentError> {
    check_motor_count(agent, motors.ncols())?;
    let mut sensors = ndarray::Array2::zeros((motors.nrows(), agent.sensor_dim()));
    agent.sense_batch(environment, motors, sensors.view_mut());
    Ok(sensors)
}

pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<(), AgentError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(AgentError::InvalidParameter {
            name,
            value: value.to_string(),
            reason: "must be a finite number greater than zero",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn sense_batch_answers_every_row_as_sense_does() {
        let arm = PlanarArm::new(&ArmParams::default()).unwrap();
        let region = arm.default_light_region();
        let environment = Environment::random(10, 3, &region).unwrap();
        let motors = ndarray::array![[0.3, -1.2, 2.0, 3.1], [0.0, 0.5, -0.5, 1.0]];
        let batch = sense_rows(&arm, &environment, motors.view()).unwrap();
        for (m, row) in motors.outer_iter().zip(batch.outer_iter()) {
            let mut one = vec![0.0; arm.sensor_dim()];
            arm.sense(&environment, m.as_slice().unwrap(), &mut one);
            assert_eq!(row.to_vec(), one);
        }
        // Columns that are not the agent's motors are an error, not a panic; so are
        // rows of a transposed (non-contiguous) array handled.
        let err = sense_rows(&arm, &environment, motors.t()).unwrap_err();
        assert!(err.to_string().contains("4 motors"), "{err}");
        let transposed = motors.t().to_owned();
        let again = sense_rows(&arm, &environment, transposed.t()).unwrap();
        assert_eq!(again, batch);
    }

    #[test]
    fn wrap_angle_maps_into_half_open_interval() {
        assert_abs_diff_eq!(wrap_angle(PI), -PI);
        assert_abs_diff_eq!(wrap_angle(-PI), -PI);
        assert_abs_diff_eq!(wrap_angle(3.0 * PI + 0.5), -PI + 0.5, epsilon = 1e-12);
        assert_abs_diff_eq!(wrap_angle(-0.25), -0.25);
        assert!(wrap_angle(-1e-300) < PI);
    }

    #[test]
    fn periodic_distance_wraps_each_coordinate() {
        let d = MotorTopology::Periodic.distance(&[-PI + 0.1, 0.0], &[PI - 0.1, 0.0]);
        assert_abs_diff_eq!(d, 0.2, epsilon = 1e-12);
        let e = MotorTopology::Bounded {
            low: -4.0,
            high: 4.0,
        }
        .distance(&[-3.0, 0.0], &[3.0, 0.0]);
        assert_abs_diff_eq!(e, 6.0);
    }

    #[test]
    fn unknown_fields_and_names_are_errors() {
        let build = |text: &str| toml::from_str::<AgentConfig>(text).unwrap().build();
        let err = build("kind = \"planar-arm\"\nlink_length = [1.0]").unwrap_err();
        assert!(err.to_string().contains("link_length"), "{err}");
        let err = build("kind = \"planar-arm\"\nsensor_height = 1.0").unwrap_err();
        assert!(err.to_string().contains("sensor_height"), "{err}");
        let err = build("kind = \"planar-arm\"\nretina_cells = \"six\"").unwrap_err();
        assert!(err.to_string().contains("retina_cells"), "{err}");
        let config: AgentConfig =
            toml::from_str("kind = \"toy-line\"\nsensor_height = 2.0").unwrap();
        let round = toml::to_string(&config).unwrap();
        assert_eq!(toml::from_str::<AgentConfig>(&round).unwrap(), config);
        let err = AgentConfig::preset("octopus").unwrap_err();
        assert!(err.to_string().contains("octopus"));
        assert!(err.to_string().contains("planar-arm"), "{err}");
    }

    #[test]
    fn a_registered_kind_builds_like_a_built_in_one() {
        let mut registry = AgentRegistry::builtin();
        registry.register_params("long-arm", "an arm with longer links", |p: &ArmParams| {
            Ok(Box::new(PlanarArm::new(p)?))
        });
        let config: AgentConfig =
            toml::from_str("kind = \"long-arm\"\nlink_lengths = [2.0, 2.0]").unwrap();
        let built = registry.build(&config).unwrap();
        assert_eq!(built.agent.motor_dim(), 3);
        // The resolved table holds the defaults it was not given.
        assert!(built.config.params.contains_key("retina_cells"));
        assert!(config.build().is_err(), "not a built-in kind");
    }

    #[test]
    fn finite_difference_pose_jacobian_matches_analytic_arm() {
        #[derive(Debug)]
        struct Wrapped(PlanarArm);
        impl Agent for Wrapped {
            fn motor_dim(&self) -> usize {
                self.0.motor_dim()
            }
            fn sensor_dim(&self) -> usize {
                self.0.sensor_dim()
            }
            fn sense(&self, e: &Environment, m: &[f64], s: &mut [f64]) {
                self.0.sense(e, m, s)
            }
            fn pose(&self, m: &[f64]) -> Pose {
                self.0.pose(m)
            }
            fn name(&self) -> &str {
                "wrapped"
            }
            fn default_light_region(&self) -> LightRegion {
                self.0.default_light_region()
            }
            fn default_light_count(&self) -> usize {
                10
            }
        }
        let arm = PlanarArm::new(&ArmParams::default()).unwrap();
        let m = [0.3, -1.2, 2.0, 3.1];
        let mut analytic = [0.0; 12];
        let mut numeric = [0.0; 12];
        arm.pose_jacobian(&m, &mut analytic);
        Wrapped(arm).pose_jacobian(&m, &mut numeric);
        for (a, b) in analytic.iter().zip(&numeric) {
            assert_abs_diff_eq!(a, b, epsilon = 1e-8);
        }
    }
}
