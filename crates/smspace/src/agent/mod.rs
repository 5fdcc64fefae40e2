//! Agents and environments: the sensorimotor law `s = σ_E(m)` (paper section 2.1, eq. 2).
//!
//! An [`Agent`] maps motor commands `m` of its [`MotorSpace`] (each motor periodic with
//! its period, a hinge, or bounded with its range) to raw sensor values `s ∈ ℝ^K` in
//! an [`Environment`] of point lights. For evaluation only, it may expose the
//! observer's ground truth ([`Agent::ground_truth`], an [`Observer`]): the external
//! configuration of its sensor, a pose of any dimension whose coordinates are linear,
//! angles or quaternion blocks ([`PoseSpace`]); the paper's agents use the planar
//! [`Pose`] `(x, y, alpha)`. The agent itself never uses the pose; the `kinematic`
//! tracing method does, as the paper's simulation does "only to accelerate the
//! simulation" (section 3.2, step 2), and so does the analysis of agreement.
//!
//! Three agents are built in:
//!
//! | name | paper | motors `N` | sensors `K` | pose |
//! |---|---|---|---|---|
//! | [`ToyAgent`] `toy-line` | 2.2, agent 1 | 1 bounded | 2 | `x = m1` |
//! | [`ToyAgent`] `toy-redundant` | 2.3, agent 2 | 2 bounded | 2 | `x = m1 + m2` |
//! | [`PlanarArm`] `planar-arm` | 3.1 | links + 1 hinges | `retina_cells` | retina `(x, y, alpha)` |
//! | [`Chain`] `chain` | 3.1, generalised | one per joint (hinge, or bounded by its `range`) | retina cells | `(x, y, alpha)` planar, `(x, y, z, qw, qx, qy, qz)` in 3-D |
//!
//! A chain may carry a pinhole [`Camera`] instead of its retina (`[agent.camera]`): its
//! sensors are the pixels of an image of the environment's [`Scene`] (textured walls,
//! boxes, spheres and discs), its ground truth the camera's pose.
//!
//! Either of the last two may have a pupil ([`Pupil`], `[agent.retina] aperture =
//! [low, high]`, the paper's conclusion): one more motor, the last, bounded, scaling
//! every cell's input; the pose stays the retina's.
//!
//! Build one from its parameter table with [`AgentConfig::build`], or by name with
//! [`AgentConfig::preset`]; an agent of your own (a simulator in another language, a
//! robot) implements the four required methods of [`Agent`] and registers in an
//! [`AgentRegistry`].

mod arm;
mod camera;
mod chain;
mod environment;
mod ground_truth;
mod motor_space;
mod noisy;
mod pupil;
mod registry;
mod scene;
mod toy;
mod workspace;

use std::f64::consts::PI;
use std::fmt;

use ndarray::{ArrayView2, ArrayViewMut2};
use serde::{Deserialize, Serialize};

pub use arm::{
    ArmParams, ArmRetinaParams, ArmValidParams, Falloff, PlanarArm, RetinaLaw, Tuning, MAX_LINKS,
    MAX_RETINA_CELLS,
};
pub use camera::{Camera, CameraParams, ColorMode, MAX_CAMERA_SENSORS};
pub use chain::{
    Chain, ChainParams, ChainValidParams, ChainWorkspace, JointParams, RetinaCells, RetinaParams,
};
pub use environment::{
    Environment, EnvironmentConfig, LightRegion, LightSpace, Stimulus, MAX_DRAWS_PER_LIGHT,
    MAX_RANDOM_LIGHTS,
};
pub use ground_truth::{
    CoordinateKind, GroundTruth, GroundTruthView, Observer, PlanarView, Pose, PoseComponent,
    PoseCoordinate, PoseSpace, QUATERNION_NORM_TOLERANCE,
};
pub use motor_space::{wrap_period, Motor, MotorSpace};
pub use noisy::{NoiseParams, NoisyAgent, STD_SAMPLE_ROWS, STD_SAMPLE_SEED};
pub use pupil::Pupil;
pub use registry::{AgentBuilder, AgentRegistry, BuiltAgent};
pub use scene::{
    Amplitude, BoxShape, Disc, Primitive, RandomTexture, Scene, Sphere, Texture, Wall, Wave,
    MAX_SCENE_PRIMITIVES, MAX_TEXTURE_WAVES,
};
pub use toy::{ToyAgent, ToyKind, ToyParams, ToyValidParams};
pub use workspace::Workspace;

use crate::params::InvalidParameter;

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
    /// A parameter is out of its domain (located by its table and key).
    #[error(transparent)]
    Parameter(#[from] InvalidParameter),
    /// The agent's methods contradict each other (a plug-in agent's bug).
    #[error("the {agent} agent is inconsistent: {reason}")]
    Inconsistent {
        /// The agent's name.
        agent: String,
        /// What disagrees.
        reason: String,
    },
    /// A pose's quaternion is not a unit quaternion.
    #[error("the pose of row {row} has a quaternion (columns {column} to {}) of norm {norm}; an orientation is a unit quaternion (w, x, y, z) with w² + x² + y² + z² = 1: normalise it in the pose function", column + 3)]
    NonUnitQuaternion {
        /// The row of the pose.
        row: usize,
        /// The first column of the quaternion block.
        column: usize,
        /// Its norm.
        norm: f64,
    },
    /// Poses do not have the columns of their layout.
    #[error("poses have {found} columns but the observer's pose has {expected} coordinates")]
    PoseColumns {
        /// Columns found.
        found: usize,
        /// Coordinates of the pose space.
        expected: usize,
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
    /// An environment file could not be read.
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
}

impl AgentError {
    /// The parameter this error is about, when it is one of an `[agent]` or
    /// `[environment]` table.
    pub fn invalid_parameter(&self) -> Option<&InvalidParameter> {
        match self {
            AgentError::Parameter(p) => Some(p),
            _ => None,
        }
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

/// A sensorimotor agent: the law `s = σ_E(m)`, its motor space and, optionally, the
/// observer's ground truth.
///
/// Required: [`motor_dim`](Agent::motor_dim), [`sensor_dim`](Agent::sensor_dim),
/// [`sense`](Agent::sense) and [`name`](Agent::name), what every agent has. The rest
/// has defaults: [`motor_space`](Agent::motor_space) (`N` hinges),
/// [`sense_batch`](Agent::sense_batch) (row by row), no
/// [`ground_truth`](Agent::ground_truth) (then the `kinematic` tracer is unavailable
/// and the analysis against poses is skipped), no working space, no skeleton, and a
/// generic light region. An agent simulated outside Rust (or a robot) implements
/// `sense_batch` to be called rarely. The trait is object-safe: a run holds a
/// `Box<dyn Agent>` built by an [`AgentRegistry`].
pub trait Agent: Send + Sync + fmt::Debug {
    /// Number of motors `N`.
    fn motor_dim(&self) -> usize;

    /// Number of sensors `K`.
    fn sensor_dim(&self) -> usize;

    /// Writes the sensor values `s = σ_E(m)` for motors `m` (length `N`) into `sensors`
    /// (length `K`).
    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]);

    /// A short name, e.g. `planar-arm` (owned by the agent, so that an agent described
    /// at run time names itself).
    fn name(&self) -> &str;

    /// Each motor's coordinate: periodic with its period, or bounded with its range
    /// (length `N`). The default is `N` hinges ([`MotorSpace::hinges`]).
    fn motor_space(&self) -> MotorSpace {
        MotorSpace::hinges(self.motor_dim())
    }

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

    /// How tracing calls the agent from many kernel sets at once. The default,
    /// [`Calling::Direct`], suits an agent that is cheap to call (every built-in one);
    /// an agent with a large fixed cost per call (a simulator behind an interpreter
    /// lock or a process boundary) asks for [`Calling::Gathered`], so that the rows of
    /// many sets reach its [`sense_batch`](Agent::sense_batch) in one call.
    fn calling(&self) -> Calling {
        Calling::Direct
    }

    /// The long-lived threads on which the engine calls this agent when it gathers the
    /// readings of many sets ([`Calling::Gathered`]), or `None` (the default): threads
    /// started for each trace and ended with it. An agent whose calls enter an
    /// interpreter gives the threads of its host, each holding one interpreter thread
    /// state for the life of the process, so that the user's per-thread state (Python's
    /// `threading.local()`: a simulator's data per thread) lasts from one call and one
    /// trace to the next, and is never freed when a short-lived thread ends. Each thread's
    /// stack holds at least [`HOST_STACK_BYTES`](crate::kernel::HOST_STACK_BYTES).
    fn host_threads(&self) -> Option<&rayon::ThreadPool> {
        None
    }

    /// The generic rank of the sensory Jacobian `∂s/∂m`, when the agent knows it: a law
    /// learned from data ([`crate::learn::LearnedLaw`]) estimates it from its fits,
    /// where finite differences of its values would see the fit's noise as rank. The
    /// default is `None`: the tracer estimates it at the starts. An agent that gives it
    /// is read as a fitted law, whose values lie on an image of that rank only up to
    /// the fit's error: the tracer's sensory level set then holds the residual's part in
    /// the Jacobian's range at zero.
    fn sensory_rank(&self) -> Option<usize> {
        None
    }

    /// Writes the sensor values at `motors` into `sensors` (length `K`) and their
    /// Jacobian `∂s/∂m` (`K × N`, row-major) into `jacobian`, when the agent has it in
    /// closed form (a learned law: the local fit's slope, one fit instead of the `2N`
    /// of central differences); returns whether it did. The default returns `false`
    /// and writes nothing: the tracer then takes central differences of
    /// [`sense_batch`](Agent::sense_batch).
    fn sense_with_jacobian(
        &self,
        _environment: &Environment,
        _motors: &[f64],
        _sensors: &mut [f64],
        _jacobian: &mut [f64],
    ) -> bool {
        false
    }

    /// Whether the law is known at `motors`: everywhere for a simulated agent (the
    /// default); near its samples only for a law learned from data. The tracer ends a
    /// set that leaves this region (status `left-data`).
    fn covers(&self, _motors: &[f64]) -> bool {
        true
    }

    /// The observer's ground truth (the sensor's pose for any motors), for evaluation
    /// only. The default is none.
    fn ground_truth(&self) -> Option<&dyn Observer> {
        None
    }

    /// The configuration the sensations determine, which tracing holds fixed on a
    /// kernel set (both methods: its `configuration_dim` gives `k = N − C`, and the
    /// `kinematic` method constrains its pose). The default is the
    /// [`ground_truth`](Agent::ground_truth): the motors only move the sensor. A
    /// [`Pupil`] gives the retina's pose and the aperture, which changes the sensations
    /// without moving the retina.
    fn sensed_configuration(&self) -> Option<&dyn Observer> {
        self.ground_truth()
    }

    /// The motors that change an attribute of the sensor rather than its place (a
    /// pupil's aperture), as the observer knows them: for figures and tests only (the
    /// compensability analysis finds them from the sensations). The default is none.
    fn attribute_motors(&self) -> Vec<usize> {
        Vec::new()
    }

    /// The working space this agent explores when the experiment names none: a
    /// rectangle of sensor positions it can reach (it needs a
    /// [`ground_truth`](Agent::ground_truth) whose first two coordinates are the
    /// position). The default is none (babbling over the whole motor space).
    fn default_workspace(&self) -> Option<Workspace> {
        None
    }

    /// The body drawn for motors `m`: joint positions in the plane, from the base to the
    /// sensor, for figures only (paper Fig. 5a). The default is empty: the agent has no
    /// body to draw.
    fn skeleton(&self, _motors: &[f64]) -> Vec<[f64; 2]> {
        Vec::new()
    }

    /// Where random lights go by default for this agent. The default is the square
    /// `[−3, 3]²` around the origin, without exclusion.
    fn default_light_region(&self) -> LightRegion {
        LightRegion {
            center: [0.0, 0.0],
            half_size: [3.0, 3.0],
            exclusion_half_size: [0.0, 0.0],
        }
    }

    /// How many lights a random environment has by default (5 for the toys, 10 for the
    /// arm). The default is 10.
    fn default_light_count(&self) -> usize {
        10
    }

    /// Where the agent senses lights: in the plane (`[x, y]`, the default) or in a
    /// volume (`[x, y, z]`, a 3-D chain). An environment of the other kind is refused
    /// ([`Environment::check_for`]).
    fn light_space(&self) -> LightSpace {
        LightSpace::Plane
    }

    /// What the agent senses in its environment: point lights (the default) or a
    /// [`Scene`] of textured primitives (a [`Camera`]). An environment without what the
    /// agent senses is refused ([`Environment::check_for`]).
    fn stimulus(&self) -> Stimulus {
        Stimulus::Lights
    }

    /// The interval `[low, high]` of heights `z` random lights are drawn from when the
    /// agent senses lights in a volume (their `(x, y)` come from
    /// [`default_light_region`](Agent::default_light_region)). The default is
    /// `[−3, 3]`; unused in the plane.
    fn default_light_heights(&self) -> [f64; 2] {
        [-3.0, 3.0]
    }

    /// The same agent without the simulated noise of its readings, when it adds some
    /// ([`NoisyAgent`], an `[agent.noise]` table): for evaluation only (a run compares
    /// the sets traced from the noisy readings with the exact ones). The default is
    /// none.
    fn noiseless(&self) -> Option<&dyn Agent> {
        None
    }
}

/// How the sensory tracer calls an agent ([`Agent::calling`]).
///
/// Tracing a set asks for small batches: the `2N + 1` rows of one finite-difference
/// Jacobian, or one row for a residual. For an agent whose every call costs a fixed
/// overhead `c` (a Python function: the interpreter lock, the array conversions) on top
/// of a cost per row, `S` steps of `M` sets cost about `S · M · c` in overheads. With
/// [`Gathered`](Calling::Gathered), `callers` sets are traced at once in lockstep (as
/// coroutines on two threads), and every round of requests (one from each set still
/// being traced) is answered by one `sense_batch` call of all their rows: the overhead
/// falls to about `S · M · c / callers`. The agent (and its observer's
/// [`Observer::pose_batch`]) is then called on those two threads only, never on a
/// coroutine's stack. The kernel sets do not change, provided the agent answers each
/// row independently of the others in its batch (as the [`Agent::sense_batch`]
/// contract asks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Calling {
    /// Each set calls the agent when it needs a reading, on the rayon pool's threads.
    Direct,
    /// `callers` sets are traced at once and their readings gathered into one call per
    /// round (at least 1; more callers than sets is the same as one per set).
    Gathered {
        /// How many sets are traced at once.
        callers: usize,
    },
}

/// Checks that an agent's parts agree: a motor space of `N` motors, at least one
/// motor and one sensor, a default working space only with a ground truth whose first
/// two coordinates are a position, and a ground truth whose layout holds the
/// coordinates the motors change. The registry checks every agent it builds.
pub fn check_agent(agent: &dyn Agent) -> Result<(), AgentError> {
    let inconsistent = |reason: String| {
        Err(AgentError::Inconsistent {
            agent: agent.name().to_owned(),
            reason,
        })
    };
    let (n, space) = (agent.motor_dim(), agent.motor_space());
    if n == 0 || agent.sensor_dim() == 0 {
        return inconsistent(format!(
            "it has {n} motors and {} sensors; an agent needs at least one of each",
            agent.sensor_dim()
        ));
    }
    if space.dim() != n {
        return inconsistent(format!(
            "motor_space() describes {} motors but motor_dim() is {n}",
            space.dim()
        ));
    }
    for (j, motor) in space.motors().iter().enumerate() {
        motor.check(j)?;
    }
    let fits_workspace = agent
        .ground_truth()
        .is_some_and(|o| Workspace::fits(&o.pose_space()));
    if agent.default_workspace().is_some() && !fits_workspace {
        return inconsistent(
            "it has a default working space, which bounds the sensor's position, but no ground truth with a position first".into(),
        );
    }
    for observer in [agent.ground_truth(), agent.sensed_configuration()]
        .into_iter()
        .flatten()
    {
        let poses = observer.pose_space();
        let c = observer.configuration_dim();
        if c == 0 || c > poses.tangent_dim() {
            return inconsistent(format!(
                "its ground truth holds {c} pose coordinates fixed, but its pose has {} tangent coordinates ({} columns)",
                poses.tangent_dim(),
                poses.dim()
            ));
        }
    }
    Ok(())
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
                known: registry.names().collect::<Vec<_>>().join(", "),
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

pub(crate) fn check_positive(key: &'static str, value: f64) -> Result<(), InvalidParameter> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(InvalidParameter::new(
            "agent",
            key,
            value,
            "must be a finite number greater than zero",
        ))
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
        let d = MotorSpace::hinges(2).distance(&[-PI + 0.1, 0.0], &[PI - 0.1, 0.0]);
        assert_abs_diff_eq!(d, 0.2, epsilon = 1e-12);
        let e = MotorSpace::bounded(2, -4.0, 4.0)
            .unwrap()
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
        registry.register_params(
            "long-arm",
            "an arm with longer links",
            |p: &ArmParams, _: &()| Ok(Box::new(PlanarArm::new(p)?)),
        );
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
        /// The arm's pose without its analytic Jacobian.
        struct Numeric(PlanarArm);
        impl Observer for Numeric {
            fn pose_space(&self) -> PoseSpace {
                PoseSpace::planar()
            }
            fn pose(&self, m: &[f64], pose: &mut [f64]) {
                self.0.pose(m, pose)
            }
        }
        let arm = PlanarArm::new(&ArmParams::default()).unwrap();
        let m = [0.3, -1.2, 2.0, 3.1];
        let (mut analytic, mut numeric) = ([0.0; 12], [0.0; 12]);
        let (mut pose_a, mut pose_n) = ([0.0; 3], [0.0; 3]);
        arm.pose_jacobian(&m, &mut analytic, &mut pose_a);
        Numeric(arm).pose_jacobian(&m, &mut numeric, &mut pose_n);
        for (a, b) in analytic.iter().zip(&numeric) {
            assert_abs_diff_eq!(a, b, epsilon = 1e-8);
        }
        assert_eq!(pose_a, pose_n);
    }

    /// An agent with the required methods only: hinges, no ground truth.
    #[derive(Debug)]
    struct Bare;
    impl Agent for Bare {
        fn motor_dim(&self) -> usize {
            2
        }
        fn sensor_dim(&self) -> usize {
            1
        }
        fn sense(&self, _: &Environment, m: &[f64], s: &mut [f64]) {
            s[0] = m[0].cos() + m[1].cos();
        }
        fn name(&self) -> &str {
            "bare"
        }
    }

    #[test]
    fn an_agent_needs_only_its_law_and_parts_must_agree() {
        let bare = Bare;
        assert!(check_agent(&bare).is_ok());
        assert!(bare.ground_truth().is_none());
        assert_eq!(bare.motor_space(), MotorSpace::hinges(2));
        assert!(bare.default_workspace().is_none());
        assert!(bare.default_light_region().check().is_ok());
        /// Claims three motors in its motor space.
        #[derive(Debug)]
        struct Liar;
        impl Agent for Liar {
            fn motor_dim(&self) -> usize {
                2
            }
            fn sensor_dim(&self) -> usize {
                1
            }
            fn sense(&self, _: &Environment, _: &[f64], s: &mut [f64]) {
                s[0] = 0.0;
            }
            fn name(&self) -> &str {
                "liar"
            }
            fn motor_space(&self) -> MotorSpace {
                MotorSpace::hinges(3)
            }
        }
        let err = check_agent(&Liar).unwrap_err().to_string();
        assert!(err.contains("liar") && err.contains("3 motors"), "{err}");
    }
}
