//! Agents from Python: the built-in kinds (`Agent.preset`, `Agent.from_toml`) and
//! agents whose sensorimotor law is a Python callable ([`PythonAgent`]).
//!
//! A [`PythonAgent`] answers [`smspace::agent::Agent::sense_batch`] with one call of
//! `sense(motors: (B, N) float64) -> (B, K) float64`: the sensory tracer asks for the
//! `2N + 1` readings of each linearisation in one batch, and a pose callable likewise
//! gets the `2N + 1` rows of each pose Jacobian. The engine runs with the GIL released
//! on its own threads ([`crate::host`]); each call takes the GIL.
//!
//! **One call at a time.** The engine's threads never call a PythonAgent's callables
//! concurrently unless it was made with `thread_safe=True`: a simulator that keeps one
//! state (a MuJoCo `MjData` written by `sense`, read back after a step that releases
//! the GIL) sees each call from its start to its end alone. Each thread that calls
//! them keeps one interpreter thread state for its whole life, so a callable's
//! `threading.local()` lasts from one call to the next.
//!
//! The agent traits cannot fail, so the first exception (or wrong shape, dtype or
//! non-finite value) is kept, every later reading is NaN (the sets fail fast), and the
//! computation raises it when it returns ([`Agent::check_callbacks`]). After Ctrl-C
//! the next call unwinds the computation instead of calling Python
//! ([`crate::host::run_interruptible`]).

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ndarray::{Array2, ArrayView2, ArrayViewMut2};
use numpy::{IntoPyArray, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use smspace::agent::{
    check_agent, Agent as AgentLaw, AgentConfig, Calling, Environment, EnvironmentConfig, Motor,
    MotorSpace, Observer, PoseSpace,
};
use smspace_pipeline::config::{load_agent, AgentSpec};

use crate::host::{run_interruptible, Interrupt, Turnstile};
use crate::{to_py_err, value_error};

pyo3::create_exception!(
    _core,
    CallbackError,
    PyRuntimeError,
    "A callable of a PythonAgent raised, or returned an array of the wrong type, shape or values."
);

/// What a Python agent's callables share with the computations that call them: the
/// first failure, and the stop flag of the computation in progress.
#[derive(Debug, Default)]
pub(crate) struct CallState {
    failure: Mutex<Option<PyErr>>,
    interrupt: Mutex<Interrupt>,
}

impl CallState {
    fn failed(&self) -> bool {
        self.failure.lock().map_or(true, |e| e.is_some())
    }

    fn keep(&self, error: PyErr) {
        if let Ok(mut first) = self.failure.lock() {
            first.get_or_insert(error);
        }
    }

    fn take(&self) -> Option<PyErr> {
        self.failure.lock().ok().and_then(|mut e| e.take())
    }

    /// A new computation's stop flag, which the callables check from now on.
    fn begin(&self) -> Interrupt {
        let fresh = Interrupt::new();
        if let Ok(mut current) = self.interrupt.lock() {
            *current = fresh.clone();
        }
        fresh
    }

    /// Unwinds the computation when its stop flag is raised (never while unwinding).
    fn stop_if_interrupted(&self) {
        if std::thread::panicking() {
            return;
        }
        let current = self.interrupt.lock().map(|i| i.clone()).unwrap_or_default();
        current.stop_if_raised();
    }
}

/// A sensorimotor agent (built-in, from a TOML file, or a [`PythonAgent`]).
#[pyclass(subclass, frozen, module = "smspace._core")]
pub struct Agent {
    pub(crate) law: Arc<dyn AgentLaw>,
    /// The `[agent]` table and the agent file's `[environment]` table (built-in kinds).
    pub(crate) spec: Option<AgentSpec>,
    /// The failures and stop flag of a Python agent's callables.
    pub(crate) calls: Option<Arc<CallState>>,
}

impl Agent {
    fn built(spec: AgentSpec) -> PyResult<Self> {
        let law = spec.agent.build().map_err(to_py_err)?;
        Ok(Self {
            law: Arc::from(law),
            spec: Some(spec),
            calls: None,
        })
    }

    /// Raises the first failure of a Python agent's callables (and forgets it, so that
    /// the agent can be used again).
    pub(crate) fn check_callbacks(&self) -> PyResult<()> {
        match self.calls.as_ref().and_then(|f| f.take()) {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// The stop flags a computation with this agent raises on Ctrl-C: a Python
    /// agent's (new for each computation), none for a built-in one.
    pub(crate) fn interrupts(&self) -> Vec<Interrupt> {
        self.calls.iter().map(|c| c.begin()).collect()
    }

    /// The environment `env` names for this agent: `None` the agent file's
    /// `[environment]` table or the default random one (seed 1), an `int` a random one
    /// from that seed, an array `(L, 2)` or `(L, 3)` the lights themselves. A Python
    /// agent holds its own world: its environment is empty.
    pub(crate) fn environment(&self, env: Option<&Bound<'_, PyAny>>) -> PyResult<Environment> {
        if self.calls.is_some() {
            return Ok(Environment::from_lights(Vec::new()));
        }
        let table = self.spec.as_ref().and_then(|s| s.environment.clone());
        let Some(env) = env else {
            let config = table.unwrap_or_default();
            return config.build(self.law.as_ref()).map_err(to_py_err);
        };
        if let Ok(seed) = env.extract::<u64>() {
            let config = EnvironmentConfig {
                seed,
                ..table.unwrap_or_default()
            };
            return config.build(self.law.as_ref()).map_err(to_py_err);
        }
        let lights = matrix_arg(env, "env (None, an int seed, or lights (L, 2) or (L, 3))")?;
        let lights = lights.as_array();
        let environment = match lights.ncols() {
            2 => Environment::from_lights(lights.outer_iter().map(|r| [r[0], r[1]]).collect()),
            3 => Environment::from_lights_3d(
                lights.outer_iter().map(|r| [r[0], r[1], r[2]]).collect(),
            ),
            c => {
                return Err(value_error(format!(
                    "env has {c} columns; lights are (L, 2) in the plane or (L, 3) in a volume"
                )))
            }
        };
        if lights.iter().any(|v| !v.is_finite()) {
            return Err(value_error("env holds a non-finite light coordinate"));
        }
        environment
            .check_for(self.law.as_ref())
            .map_err(to_py_err)?;
        Ok(environment)
    }
}

/// `value` as an aligned float64 array of 2 dimensions (`numpy.require`: a copy only
/// when it is not one already, e.g. an unaligned buffer from unpickling), or a
/// `TypeError`/`ValueError` naming `argument`.
pub(crate) fn matrix_arg<'py>(
    value: &Bound<'py, PyAny>,
    argument: &str,
) -> PyResult<PyReadonlyArray2<'py, f64>> {
    let numpy = value.py().import("numpy")?;
    let array = numpy
        .call_method1("require", (value, "float64", "A"))
        .map_err(|e| {
            PyTypeError::new_err(format!(
                "{argument} must be an array of float64 numbers: {}",
                e.value(value.py())
            ))
        })?;
    let ndim: usize = array.getattr("ndim")?.extract()?;
    if ndim != 2 {
        return Err(value_error(format!(
            "{argument} must have 2 dimensions, got shape {}",
            array.getattr("shape")?
        )));
    }
    array
        .extract()
        .map_err(|_| PyTypeError::new_err(format!("{argument} must be a float64 array")))
}

/// Reads `params` (keyword arguments) as a TOML table, through their JSON.
fn params_table(params: Option<&Bound<'_, PyDict>>) -> PyResult<toml::Table> {
    let Some(params) = params else {
        return Ok(toml::Table::new());
    };
    let json: String = params
        .py()
        .import("json")?
        .call_method1("dumps", (params,))?
        .extract()?;
    serde_json::from_str(&json).map_err(|e| value_error(format!("invalid agent parameters: {e}")))
}

#[pymethods]
impl Agent {
    /// The built-in agent `name` (`planar-arm`, `toy-line`, `toy-redundant`, `chain`),
    /// with the `[agent]` table's keys as keyword arguments
    /// (`Agent.preset("planar-arm", retina_cells=8)`).
    #[staticmethod]
    #[pyo3(signature = (name, **params))]
    fn preset(name: &str, params: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut config = AgentConfig::preset(name).map_err(to_py_err)?;
        config.params = params_table(params)?;
        Self::built(AgentSpec {
            agent: config,
            environment: None,
        })
    }

    /// The agent of a TOML file's `[agent]` table (and its `[environment]` table, if
    /// any), as `smspace trace --agent FILE` reads it.
    #[staticmethod]
    fn from_toml(path: PathBuf) -> PyResult<Self> {
        let text = path.to_string_lossy().into_owned();
        if !path.exists() {
            return Err(pyo3::exceptions::PyFileNotFoundError::new_err(format!(
                "cannot read {text}: no such file"
            )));
        }
        Self::built(load_agent(&text).map_err(to_py_err)?)
    }

    /// The agent's name.
    #[getter]
    fn name(&self) -> String {
        self.law.name().to_owned()
    }

    /// Number of motors `N`.
    #[getter]
    fn n_motors(&self) -> usize {
        self.law.motor_dim()
    }

    /// Number of sensors `K`.
    #[getter]
    fn n_sensors(&self) -> usize {
        self.law.sensor_dim()
    }

    /// Each motor's coordinate: `("periodic", period)` or `("bounded", low, high)`.
    #[getter]
    fn motor_space(&self) -> Vec<(String, f64, f64)> {
        self.law
            .motor_space()
            .motors()
            .iter()
            .map(|m| match *m {
                Motor::Periodic { period } => ("periodic".to_owned(), 0.0, period),
                Motor::Bounded { low, high } => ("bounded".to_owned(), low, high),
            })
            .collect()
    }

    /// Whether the agent has a ground truth (poses; needed by the `kinematic` method).
    #[getter]
    fn has_ground_truth(&self) -> bool {
        self.law.ground_truth().is_some()
    }

    /// The lights of the environment `env` names (see `smspace.trace`), `(L, 2)` in the
    /// plane or `(L, 3)` in a volume.
    #[pyo3(signature = (env=None))]
    fn lights<'py>(
        &self,
        py: Python<'py>,
        env: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let environment = self.environment(env)?;
        let width = match environment.space {
            smspace::agent::LightSpace::Plane => 2,
            smspace::agent::LightSpace::Volume => 3,
        };
        let lights = Array2::from_shape_fn((environment.lights.len(), width), |(i, j)| {
            environment.lights[i][j]
        });
        Ok(lights.into_pyarray(py))
    }

    /// The sensor values `(M, K)` of the motor rows `(M, N)` in the environment `env`.
    #[pyo3(signature = (motors, env=None))]
    fn sense<'py>(
        &self,
        py: Python<'py>,
        motors: &Bound<'py, PyAny>,
        env: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let environment = self.environment(env)?;
        let motors = matrix_arg(motors, "motors")?;
        let motors = motors.as_array().to_owned();
        crate::stages::check_finite(motors.iter(), "motors")?;
        let law = self.law.clone();
        let sensors = run_interruptible(py, &self.interrupts(), move || {
            smspace::agent::sense_rows(law.as_ref(), &environment, motors.view())
        })?
        .map_err(to_py_err);
        self.check_callbacks()?;
        Ok(sensors?.into_pyarray(py))
    }

    /// The observer's poses `(M, d)` of the motor rows `(M, N)` (`(x, y, alpha)` for the
    /// planar agents).
    fn poses<'py>(
        &self,
        py: Python<'py>,
        motors: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let motors = matrix_arg(motors, "motors")?;
        let observer = self.law.ground_truth().ok_or_else(|| {
            value_error(format!("the {} agent has no ground truth", self.law.name()))
        })?;
        let motors = motors.as_array().to_owned();
        smspace::agent::check_motor_count(self.law.as_ref(), motors.ncols()).map_err(to_py_err)?;
        let d = observer.pose_space().dim();
        let law = self.law.clone();
        let poses = run_interruptible(py, &self.interrupts(), move || {
            let observer = law.ground_truth().expect("checked above");
            let mut poses = Array2::zeros((motors.nrows(), d));
            let mut row = vec![0.0; motors.ncols()];
            for (m, mut p) in motors.outer_iter().zip(poses.outer_iter_mut()) {
                row.iter_mut().zip(m.iter()).for_each(|(a, &b)| *a = b);
                let mut pose = vec![0.0; d];
                observer.pose(&row, &mut pose);
                p.iter_mut().zip(&pose).for_each(|(a, &b)| *a = b);
            }
            poses
        })?;
        self.check_callbacks()?;
        Ok(poses.into_pyarray(py))
    }

    fn __repr__(&self) -> String {
        format!(
            "Agent({:?}, n_motors={}, n_sensors={})",
            self.law.name(),
            self.law.motor_dim(),
            self.law.sensor_dim()
        )
    }
}

/// An agent whose law is Python: `sense(motors (B, N)) -> (B, K)`, called in batches,
/// and optionally `pose(motors (B, N)) -> (B, d)`, the pose of the sensor (the ground
/// truth: the `kinematic` method, the working space, the agreement analysis):
/// `pose_space="planar"` (the default) for `(x, y, alpha)`, `d = 3`;
/// `pose_space="spatial"` for `(x, y, z, qw, qx, qy, qz)`, `d = 7`, a position and a
/// unit quaternion (as a 3-D chain's). `motor_space` lists each motor as `("periodic", period)` or
/// `("bounded", low, high)`; the default is `N` hinges (periodic `2π`).
/// `concurrent_sets` kernel sets are traced at once by the `sensory` method, their
/// readings gathered into one call of `sense` per round ([`Calling::Gathered`]): each
/// call then carries up to `concurrent_sets × (2N + 1)` rows instead of `2N + 1`.
/// `thread_safe=False` (the default) never calls `sense` or `pose` from two threads at
/// once; `thread_safe=True` lets the engine's threads call them concurrently, a promise
/// the user makes: each call must read only what it is given and write only what it
/// returns (or keep its state per thread, in `threading.local()`).
#[pyclass(extends = Agent, frozen, module = "smspace._core")]
pub struct PythonAgent {}

#[pymethods]
impl PythonAgent {
    #[new]
    #[pyo3(signature = (sense, n_motors, n_sensors, motor_space=None, pose=None, name="python", pose_space="planar", concurrent_sets=DEFAULT_CONCURRENT_SETS, thread_safe=false))]
    #[allow(clippy::too_many_arguments)] // the Python signature's keywords
    fn new(
        py: Python<'_>,
        sense: Py<PyAny>,
        n_motors: usize,
        n_sensors: usize,
        motor_space: Option<Vec<Bound<'_, PyAny>>>,
        pose: Option<Py<PyAny>>,
        name: &str,
        pose_space: &str,
        concurrent_sets: usize,
        thread_safe: bool,
    ) -> PyResult<PyClassInitializer<Self>> {
        check_count("n_motors", n_motors, MAX_MOTORS)?;
        check_count("n_sensors", n_sensors, MAX_SENSORS)?;
        if !(1..=MAX_CONCURRENT_SETS).contains(&concurrent_sets) {
            return Err(value_error(format!(
                "concurrent_sets = {concurrent_sets} must be 1 to {MAX_CONCURRENT_SETS} (each set being traced at once has a thread); the default is {DEFAULT_CONCURRENT_SETS}"
            )));
        }
        if !sense.bind(py).is_callable() {
            return Err(PyTypeError::new_err(
                "sense must be callable: sense(motors: (B, N) ndarray) -> (B, K) ndarray",
            ));
        }
        if let Some(p) = &pose {
            if !p.bind(py).is_callable() {
                return Err(PyTypeError::new_err(
                    "pose must be None or callable: pose(motors: (B, N) ndarray) -> (B, d) ndarray",
                ));
            }
        }
        let pose_space = match pose_space {
            "planar" => PoseSpace::planar(),
            "spatial" => PoseSpace::spatial(),
            other => {
                return Err(value_error(format!(
                    "pose_space '{other}' must be 'planar' (x, y, alpha) or 'spatial' (x, y, z, qw, qx, qy, qz)"
                )))
            }
        };
        let space = match motor_space {
            None => MotorSpace::hinges(n_motors),
            Some(motors) => parse_motor_space(&motors)?,
        };
        let calls = Arc::new(CallState::default());
        let law = Callbacks {
            name: name.to_owned(),
            sense,
            pose,
            pose_space,
            n: n_motors,
            k: n_sensors,
            space,
            concurrent_sets,
            thread_safe,
            turnstile: Turnstile::default(),
            calls: calls.clone(),
        };
        check_agent(&law).map_err(to_py_err)?;
        Ok(PyClassInitializer::from(Agent {
            law: Arc::new(law),
            spec: None,
            calls: Some(calls),
        })
        .add_subclass(Self {}))
    }
}

/// The most motors of a [`PythonAgent`] (a motor space and every traced point hold
/// `N` numbers; a tracer's Jacobian `K × N`).
const MAX_MOTORS: usize = 1_000;

/// The most sensors of a [`PythonAgent`] (each gathered round holds
/// `concurrent_sets × (2N + 1) × K` readings).
const MAX_SENSORS: usize = 100_000;

/// Refuses a count of 0 or above `max` before anything of that size is allocated.
fn check_count(argument: &str, value: usize, max: usize) -> PyResult<()> {
    if (1..=max).contains(&value) {
        return Ok(());
    }
    Err(value_error(format!(
        "{argument} = {value} must be 1 to {max} (the engine holds arrays of that many numbers per point)"
    )))
}

/// `[("periodic", 6.28), ("bounded", -1, 1), "hinge", …]` as a [`MotorSpace`].
fn parse_motor_space(motors: &[Bound<'_, PyAny>]) -> PyResult<MotorSpace> {
    let bad = |j: usize| {
        PyTypeError::new_err(format!(
            "motor_space[{j}] must be \"hinge\", (\"periodic\", period) or (\"bounded\", low, high)"
        ))
    };
    let mut parsed = Vec::with_capacity(motors.len());
    for (j, m) in motors.iter().enumerate() {
        let motor = if let Ok(kind) = m.extract::<String>() {
            match kind.as_str() {
                "hinge" => Motor::HINGE,
                _ => return Err(bad(j)),
            }
        } else if let Ok((kind, period)) = m.extract::<(String, f64)>() {
            match kind.as_str() {
                "periodic" => Motor::Periodic { period },
                _ => return Err(bad(j)),
            }
        } else if let Ok((kind, low, high)) = m.extract::<(String, f64, f64)>() {
            match kind.as_str() {
                "bounded" => Motor::Bounded { low, high },
                _ => return Err(bad(j)),
            }
        } else {
            return Err(bad(j));
        };
        motor.check(j).map_err(to_py_err)?;
        parsed.push(motor);
    }
    MotorSpace::new(parsed).map_err(to_py_err)
}

/// The law of a [`PythonAgent`].
struct Callbacks {
    name: String,
    sense: Py<PyAny>,
    pose: Option<Py<PyAny>>,
    /// The layout of `pose`'s rows.
    pose_space: PoseSpace,
    n: usize,
    k: usize,
    space: MotorSpace,
    /// How many sets the sensory tracer traces at once, gathering their readings.
    concurrent_sets: usize,
    /// Whether the callables may be called from several threads at once.
    thread_safe: bool,
    /// Admits one call at a time unless `thread_safe`.
    turnstile: Turnstile,
    calls: Arc<CallState>,
}

/// How many kernel sets a [`PythonAgent`] has traced at once by default: enough that
/// one call of `sense` carries thousands of rows (`256 × (2N + 1)`), so that the
/// per-call cost of Python is spread over them.
const DEFAULT_CONCURRENT_SETS: usize = 256;

/// The most sets traced at once (one thread each).
const MAX_CONCURRENT_SETS: usize = 4096;

impl std::fmt::Debug for Callbacks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PythonAgent")
            .field("name", &self.name)
            .field("n_motors", &self.n)
            .field("n_sensors", &self.k)
            .finish()
    }
}

/// What `value` is, for an error message: its dtype and shape, or its type.
fn describe(value: &Bound<'_, PyAny>) -> String {
    match (value.getattr("dtype"), value.getattr("shape")) {
        (Ok(dtype), Ok(shape)) => format!("an array of dtype {dtype} and shape {shape}"),
        _ => format!(
            "an object of type {}",
            value
                .get_type()
                .name()
                .map_or_else(|_| "?".to_owned(), |n| n.to_string())
        ),
    }
}

impl Callbacks {
    /// Calls `callable` (the argument `argument` of `PythonAgent`) on the motor rows and
    /// writes its `(B, cols)` answer into `out`; NaN everywhere after a failure. One
    /// call at a time unless the agent is `thread_safe`; unwinds the computation
    /// instead after Ctrl-C.
    fn call(
        &self,
        argument: &str,
        callable: &Py<PyAny>,
        motors: ArrayView2<'_, f64>,
        mut out: ArrayViewMut2<'_, f64>,
    ) {
        self.calls.stop_if_interrupted();
        if self.calls.failed() {
            out.fill(f64::NAN);
            return;
        }
        let result = crate::host::attach(|py| {
            let mut inside = || {
                // A call may have waited for its turn while Ctrl-C was pressed.
                self.calls.stop_if_interrupted();
                self.call_now(py, argument, callable, motors, out.view_mut())
            };
            if self.thread_safe {
                inside()
            } else {
                self.turnstile.call(py, inside)
            }
        });
        if let Err(e) = result {
            if crate::host::attach(|py| crate::host::asks_to_stop(py, &e)) {
                crate::host::stop_with(e);
            }
            self.calls.keep(e);
            out.fill(f64::NAN);
        }
    }

    /// The call itself, with the GIL held, checked: an exception, a wrong type, shape
    /// or a non-finite value is an error naming the callable.
    fn call_now(
        &self,
        py: Python<'_>,
        argument: &str,
        callable: &Py<PyAny>,
        motors: ArrayView2<'_, f64>,
        mut out: ArrayViewMut2<'_, f64>,
    ) -> PyResult<()> {
        let expected = out.dim();
        let input = motors.to_owned().into_pyarray(py);
        let answer = callable.call1(py, (input,)).map_err(|e| {
            if crate::host::asks_to_stop(py, &e) {
                // Raised as it is (KeyboardInterrupt, SystemExit): see `call`.
                return e;
            }
            let error = CallbackError::new_err(format!(
                "the {argument} callable of the {} agent raised {}",
                self.name,
                e.value(py)
                    .repr()
                    .map_or_else(|_| "an exception".to_owned(), |r| r.to_string())
            ));
            error.set_cause(py, Some(e));
            error
        })?;
        let answer = answer.bind(py);
        let wrong = || {
            CallbackError::new_err(format!(
                "the {argument} callable of the {} agent must return a float64 array of shape {expected:?} for motors of shape {:?}; it returned {}",
                self.name,
                motors.dim(),
                describe(answer)
            ))
        };
        let array = answer.cast::<PyArray2<f64>>().map_err(|_| wrong())?;
        if array.shape() != [expected.0, expected.1] {
            return Err(wrong());
        }
        // An unaligned buffer (rare: a view into unpickled bytes) is read from a copy.
        let aligned: bool = array.getattr("flags")?.getattr("aligned")?.extract()?;
        let array = if aligned {
            array.clone()
        } else {
            array
                .call_method0("copy")?
                .cast_into::<PyArray2<f64>>()
                .map_err(|_| wrong())?
        };
        let values = array.readonly();
        let values = values.as_array();
        if let Some((index, v)) = values.indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(CallbackError::new_err(format!(
                "the {argument} callable of the {} agent returned {v} at {index:?} for motors {}; every value must be finite",
                self.name,
                motors.row(index.0)
            )));
        }
        out.assign(&values);
        Ok(())
    }
}

impl AgentLaw for Callbacks {
    fn motor_dim(&self) -> usize {
        self.n
    }

    fn sensor_dim(&self) -> usize {
        self.k
    }

    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        let motors = ArrayView2::from_shape((1, self.n), motors).expect("one row of N motors");
        let sensors =
            ArrayViewMut2::from_shape((1, self.k), sensors).expect("one row of K sensors");
        self.sense_batch(environment, motors, sensors);
    }

    fn name(&self) -> &str {
        &self.name
    }

    fn motor_space(&self) -> MotorSpace {
        self.space.clone()
    }

    fn sense_batch(
        &self,
        _environment: &Environment,
        motors: ArrayView2<'_, f64>,
        sensors: ArrayViewMut2<'_, f64>,
    ) {
        self.call("sense", &self.sense, motors, sensors);
    }

    fn ground_truth(&self) -> Option<&dyn Observer> {
        self.pose.as_ref().map(|_| self as &dyn Observer)
    }

    fn calling(&self) -> Calling {
        Calling::Gathered {
            callers: self.concurrent_sets,
        }
    }

    /// The engine's threads, each with one interpreter thread state for the life of
    /// the process.
    fn host_threads(&self) -> Option<&rayon::ThreadPool> {
        crate::host::pool().ok()
    }
}

impl Observer for Callbacks {
    fn pose_space(&self) -> PoseSpace {
        self.pose_space.clone()
    }

    fn pose(&self, motors: &[f64], pose: &mut [f64]) {
        let Some(callable) = &self.pose else {
            pose.fill(f64::NAN);
            return;
        };
        let motors = ArrayView2::from_shape((1, self.n), motors).expect("one row of N motors");
        let d = self.pose_space.dim();
        let pose = ArrayViewMut2::from_shape((1, d), &mut pose[..d]).expect("one pose");
        self.call("pose", callable, motors, pose);
    }

    /// All rows in one call.
    fn pose_batch(&self, motors: ArrayView2<'_, f64>, mut poses: ArrayViewMut2<'_, f64>) {
        match &self.pose {
            Some(callable) => self.call("pose", callable, motors, poses),
            None => poses.fill(f64::NAN),
        }
    }

    /// Central differences as the default, with the `2N + 1` poses in one call.
    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        let Some(callable) = &self.pose else {
            jacobian.fill(f64::NAN);
            pose.fill(f64::NAN);
            return;
        };
        let (n, h) = (self.n, 1e-6);
        let rows = 2 * n + 1;
        let probes = Array2::from_shape_fn((rows, n), |(row, j)| {
            let shift = match row {
                0 => 0.0,
                r if (r - 1) / 2 != j => 0.0,
                r if r % 2 == 1 => h,
                _ => -h,
            };
            motors[j] + shift
        });
        let space = &self.pose_space;
        let d = space.dim();
        let mut poses = Array2::zeros((rows, d));
        self.call("pose", callable, probes.view(), poses.view_mut());
        let mut difference = vec![0.0; space.tangent_dim()];
        for j in 0..n {
            let plus = poses.row(2 * j + 1).to_vec();
            let minus = poses.row(2 * j + 2).to_vec();
            space.difference(&plus, &minus, &mut difference);
            for (row, v) in difference.iter().enumerate() {
                jacobian[row * n + j] = v / (2.0 * h);
            }
        }
        pose[..d].copy_from_slice(&poses.row(0).to_vec());
    }
}
