//! The front: what every door of smspace — the `smspace` command line, the Python
//! bindings and an experiment run — builds the same way from names, parameter tables
//! and defaults, so that the same words give the same answer behind each door.
//!
//! A door parses its own syntax (command-line flags, Python keywords) and converts its
//! arrays; everything after that is here:
//!
//! * the **memory limit** a stage is held to when the user gives none
//!   ([`memory_limit`]: the memory available now, `MemAvailable`; for learning a law,
//!   [`learn_memory_limit`]: that and at most [`DEFAULT_MEMORY_LIMIT_GIB`] GiB);
//! * the **period** a metric measures an agent's sets under ([`resolve_period`]:
//!   `"motors"` is the agent's own);
//! * the **working space** a door names ([`WorkspaceSpec`]: `default`, `none` or a
//!   box);
//! * the **run folder** of an experiment given no output folder ([`default_run_dir`]:
//!   `runs/<name>`, or `runs/<name>-<h>` with overrides, `h` the first 8 hex digits of
//!   their BLAKE3 hash, so that a modified run never overwrites the experiment's own);
//! * a **set metric** from its name, its period, its parameter table and the kernels'
//!   shape ([`metric`], through a [`MetricRegistry`]: the built-in metrics and those
//!   registered by the caller);
//! * a **parameter table** with `KEY=VALUE` entries set on it ([`parse_param`],
//!   [`with_params`]): the table's own reader checks every key and value, so a door
//!   reaches every parameter of a stage with the stage's own defaults and messages;
//! * the **log lines** of a run ([`stage_line`]), the same on the terminal and in
//!   Python's `log` callback.

use std::path::{Path, PathBuf};

use smspace::agent::Agent;
use smspace::explore::Workspace;
use smspace::learn::{gib_bytes, DEFAULT_MEMORY_LIMIT_GIB};
use smspace::metric::Periodicity;
use smspace::metric::{BuiltMetric, DistanceParams, KernelShape, MetricError, MetricRegistry};
use smspace::params::InvalidParameter;

use crate::manifest::{StageId, StageRecord};

/// An error of the front: a `KEY=VALUE` parameter that its table does not take.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FrontError {
    /// `KEY=VALUE` without `=` or without a key.
    #[error("parameter {text:?}: expected KEY=VALUE (e.g. points=200)")]
    Syntax {
        /// What was given.
        text: String,
    },
    /// The same key given twice.
    #[error("parameter {key} is given twice")]
    Twice {
        /// The key.
        key: String,
    },
    /// A key that the door sets by an argument of its own.
    #[error("parameter {key}=…: {key} has its own argument, {argument}")]
    HasArgument {
        /// The key.
        key: String,
        /// The argument that sets it (e.g. `--points`).
        argument: String,
    },
    /// The table's reader refused the entries (an unknown key or a bad value).
    #[error("the [{table}] table: {reason}")]
    Table {
        /// The table (`kernel`, `analysis`, …).
        table: String,
        /// Its reader's message, naming the key.
        reason: String,
    },
    /// A working space that is none of `default`, `none` or a box.
    #[error("workspace {spec}: {reason}")]
    Workspace {
        /// What was given.
        spec: String,
        /// What a valid one looks like.
        reason: String,
    },
}

/// A working space as a door names it: the agent's own (`default`: the paper's for
/// the arm, none for the toys), none (the whole motor space), or a box of the sensor's
/// position: its centre `(cx, cy)` and full extents `(depth, width)` along x and y.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WorkspaceSpec {
    /// The agent's own ([`smspace::explore::default_workspace`]).
    Default,
    /// The whole motor space.
    None,
    /// `[cx, cy, depth, width]`.
    Box([f64; 4]),
}

impl WorkspaceSpec {
    /// `default`, `none` or four numbers `CX,CY,DEPTH,WIDTH`.
    ///
    /// ```
    /// use smspace_pipeline::front::WorkspaceSpec;
    /// assert_eq!(WorkspaceSpec::parse("none").unwrap(), WorkspaceSpec::None);
    /// assert_eq!(
    ///     WorkspaceSpec::parse("1.75, 0, 1.5, 3").unwrap(),
    ///     WorkspaceSpec::Box([1.75, 0.0, 1.5, 3.0])
    /// );
    /// assert!(WorkspaceSpec::parse("1, 2").is_err());
    /// ```
    pub fn parse(text: &str) -> Result<Self, FrontError> {
        match text.trim() {
            "default" => Ok(Self::Default),
            "none" => Ok(Self::None),
            spec => {
                let values: Option<Vec<f64>> = spec
                    .split(',')
                    .map(|v| v.trim().parse::<f64>().ok())
                    .collect();
                match values.as_deref() {
                    Some(&[cx, cy, depth, width]) => Ok(Self::Box([cx, cy, depth, width])),
                    _ => Err(FrontError::Workspace {
                        spec: spec.to_owned(),
                        reason: "give default, none, or four numbers CX,CY,DEPTH,WIDTH".to_owned(),
                    }),
                }
            }
        }
    }

    /// The working space of `agent` this names; a box must be finite with a depth and
    /// a width greater than zero.
    pub fn resolve(self, agent: &dyn Agent) -> Result<Option<Workspace>, FrontError> {
        match self {
            Self::Default => Ok(smspace::explore::default_workspace(agent)),
            Self::None => Ok(None),
            Self::Box(values @ [cx, cy, depth, width]) => {
                if !values.iter().all(|v| v.is_finite()) || depth <= 0.0 || width <= 0.0 {
                    return Err(FrontError::Workspace {
                        spec: format!("({cx}, {cy}, {depth}, {width})"),
                        reason:
                            "the centre must be finite and the depth and width greater than zero"
                                .to_owned(),
                    });
                }
                Ok(Some(Workspace {
                    center: [cx, cy],
                    size: [depth, width],
                    z_range: None,
                }))
            }
        }
    }
}

/// Bytes of memory available now (`MemAvailable` of `/proc/meminfo`), when the system
/// says.
pub fn memory_available() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The memory limit of a stage: `explicit` when given, otherwise the memory available
/// now ([`memory_available`]; none where the system does not say).
pub fn memory_limit(explicit: Option<u64>) -> Option<u64> {
    explicit.or_else(memory_available)
}

/// The memory limit of learning a law: `explicit` when given, otherwise
/// `min(DEFAULT_MEMORY_LIMIT_GIB GiB, memory available)`.
pub fn learn_memory_limit(explicit: Option<u64>) -> u64 {
    explicit.unwrap_or_else(|| {
        let default = gib_bytes(DEFAULT_MEMORY_LIMIT_GIB);
        memory_available().map_or(default, |available| available.min(default))
    })
}

/// The run folder of the experiment `name` when no output folder is given:
/// `runs/<name>`, and with overrides (`key=value`, in order)
/// `runs/<name>-<first 8 hex digits of their BLAKE3 hash>`.
pub fn default_run_dir(name: &str, overrides: &[String]) -> PathBuf {
    let runs = PathBuf::from("runs");
    if overrides.is_empty() {
        return runs.join(name);
    }
    let parts: Vec<&[u8]> = overrides.iter().map(|o| o.as_bytes()).collect();
    let hash = crate::manifest::hash_parts(&parts);
    runs.join(format!("{name}-{}", &hash[..8]))
}

/// What names a set metric at a door: its name, the period of the motor coordinates,
/// its parameter table (`[metric.params]`), the memory limit and, when the door knows
/// them (from the trace report beside the sets), the kernels' shape.
#[derive(Debug, Clone)]
pub struct MetricRequest<'a> {
    /// A built-in or registered metric's name.
    pub name: &'a str,
    /// Period of the motor coordinates.
    pub period: Periodicity,
    /// The metric's own parameters.
    pub params: toml::Table,
    /// Bytes the computation may hold ([`memory_limit`] of the user's value).
    pub memory_limit_bytes: Option<u64>,
    /// The kernels' shape, when known.
    pub kernels: Option<KernelShape>,
}

impl<'a> MetricRequest<'a> {
    /// The metric `name` under `period`, no parameters, the memory available as its
    /// limit, kernels unknown.
    pub fn new(name: &'a str, period: Periodicity) -> Self {
        Self {
            name,
            period,
            params: toml::Table::new(),
            memory_limit_bytes: memory_limit(None),
            kernels: None,
        }
    }
}

/// The set metric a door names, built by `registry` (the parameters it resolves are in
/// the result's `params`): an unknown name lists the metrics, an unknown parameter names
/// the metric's parameters.
pub fn metric(
    registry: &MetricRegistry,
    request: MetricRequest<'_>,
) -> Result<BuiltMetric, MetricError> {
    let mut params = DistanceParams::new()
        .metric(request.name)
        .period(request.period)
        .memory_limit_bytes(request.memory_limit_bytes);
    params.params = request.params;
    registry.build_for(&params, request.kernels)
}

/// The period of the motor coordinates a metric measures `agent`'s sets under:
/// `"motors"` becomes the periods of the agent's motors (hinges wrap with their
/// period, bounded motors do not: [`smspace::invariance::motor_periodicity`]), written
/// as `"2pi"` or `"none"` when all motors are alike, so that a run of hinges records and
/// keys the same table either way. A uniform period is refused when the motors are not
/// all alike (it would wrap a bounded motor or leave a hinge unwrapped), and a
/// per-motor list must have one entry per motor; the refusal is on the `[metric]
/// period` key and names the agent's own.
pub fn resolve_period(
    agent: &dyn Agent,
    period: &Periodicity,
) -> Result<Periodicity, InvalidParameter> {
    let space = agent.motor_space();
    let own = smspace::invariance::motor_periodicity(&space);
    let refuse = |why: String| InvalidParameter::new("metric", "period", period.to_string(), why);
    match period {
        Periodicity::FromMotors => Ok(own),
        Periodicity::Uniform(_) if space.is_hinges() || space.is_bounded() => Ok(period.clone()),
        Periodicity::Uniform(_) => Err(refuse(format!(
            "the {} agent's motors are {space}; a uniform period cannot describe them: set period = \"motors\" (the agent's own: {own}) or one entry per motor",
            agent.name()
        ))),
        Periodicity::PerCoordinate(periods) if periods.dims() != space.dim() => {
            Err(refuse(format!(
                "{} entries for the {} agent's {} motors; give one per motor, or period = \"motors\" ({own})",
                periods.dims(),
                agent.name(),
                space.dim()
            )))
        }
        Periodicity::PerCoordinate(_) => Ok(period.clone()),
    }
}

/// `KEY=VALUE`: a parameter, the value read as TOML (a bare word that is not TOML is a
/// string: `method=sensory` as `method="sensory"`).
pub fn parse_param(text: &str) -> Result<(String, toml::Value), FrontError> {
    let syntax = || FrontError::Syntax {
        text: text.to_owned(),
    };
    let (key, value) = text.split_once('=').ok_or_else(syntax)?;
    let key = key.trim();
    if key.is_empty() {
        return Err(syntax());
    }
    let value = match toml::from_str::<toml::Table>(&format!("v = {}", value.trim())) {
        Ok(mut table) => table
            .remove("v")
            .unwrap_or_else(|| toml::Value::String(value.trim().to_owned())),
        Err(_) => toml::Value::String(value.trim().to_owned()),
    };
    Ok((key.to_owned(), value))
}

/// `value`, a parameter table (a serde struct such as `TraceParams`), with the
/// `KEY=VALUE` entries of `params` set on it and read back by the table's own reader,
/// which names an unknown key or a bad value. A key in `arguments` (`(key, argument)`)
/// is set by an argument of the door's own and is refused here, naming it; a key given
/// twice too.
pub fn with_params<T>(
    value: &T,
    params: &[(String, toml::Value)],
    arguments: &[(&str, &str)],
    table: &str,
) -> Result<T, FrontError>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let refused = |reason: String| FrontError::Table {
        table: table.to_owned(),
        reason,
    };
    let mut keys = match toml::Value::try_from(value) {
        Ok(toml::Value::Table(keys)) => keys,
        Ok(_) => return Err(refused("it does not read as a table".to_owned())),
        Err(e) => return Err(refused(e.to_string())),
    };
    for (i, (key, v)) in params.iter().enumerate() {
        if params[..i].iter().any(|(k, _)| k == key) {
            return Err(FrontError::Twice { key: key.clone() });
        }
        if let Some((_, argument)) = arguments.iter().find(|(k, _)| k == key) {
            return Err(FrontError::HasArgument {
                key: key.clone(),
                argument: (*argument).to_owned(),
            });
        }
        keys.insert(key.clone(), v.clone());
    }
    toml::Value::Table(keys)
        .try_into::<T>()
        .map_err(|e| refused(e.to_string().trim_end().to_owned()))
}

/// An event of a run, for [`stage_line`].
#[derive(Debug, Clone, Copy)]
pub enum StageEvent<'a> {
    /// The stage started.
    Started,
    /// The stage ended (computed, or reused from the cache) with its one-line summary.
    Finished {
        /// Its record in the manifest.
        record: &'a StageRecord,
        /// The stage's summary.
        summary: &'a str,
    },
    /// A note of the stage.
    Note(&'a str),
    /// The stage was skipped, and why.
    Skipped(&'a str),
}

/// The log line of a stage's event, as every door writes it:
/// `[smspace] <stage>    <what>: <summary>`.
pub fn stage_line(stage: StageId, event: StageEvent<'_>) -> String {
    let name = stage.name();
    match event {
        StageEvent::Started => format!("[smspace] {name}: started"),
        StageEvent::Finished { record, summary } => {
            let how = if record.cached {
                format!("reused (computed in {:.2} s)", record.compute_seconds)
            } else {
                format!("{:.2} s", record.seconds)
            };
            format!("[smspace] {name:<10} {how}: {summary}")
        }
        StageEvent::Note(note) => format!("[smspace] {name:<10} note: {note}"),
        StageEvent::Skipped(why) => format!("[smspace] {name:<10} skipped: {why}"),
    }
}

/// The log line of a run that waits for another process to finish writing its folder
/// (`lock`, the folder's lock file).
pub fn waiting_line(lock: &Path) -> String {
    format!(
        "[smspace] another run is writing this folder ({} is locked); waiting for it to end",
        lock.display()
    )
}

/// The log line of a run given overrides (`overrides`: how the door calls them) and no
/// output folder (`out`: how the door gives one): it goes to `dir`
/// ([`default_run_dir`]), not to the unmodified experiment's `runs/<name>`.
pub fn own_folder_line(dir: &Path, name: &str, overrides: &str, out: &str) -> String {
    format!(
        "[smspace] with {overrides}, the run goes to its own folder {} (runs/{name} stays the unmodified experiment's; {out} chooses another)",
        dir.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_modified_run_has_its_own_folder() {
        assert_eq!(
            default_run_dir("paper-arm", &[]),
            Path::new("runs/paper-arm")
        );
        let a = default_run_dir("paper-arm", &["scale.path=dense".to_owned()]);
        let b = default_run_dir("paper-arm", &["scale.path=landmarks".to_owned()]);
        assert!(a.to_string_lossy().starts_with("runs/paper-arm-"));
        assert_eq!(a.to_string_lossy().len(), "runs/paper-arm-".len() + 8);
        assert_ne!(a, b);
    }

    #[test]
    fn parameters_read_as_toml_or_bare_words() {
        let (key, value) = parse_param("points = 200").unwrap();
        assert_eq!((key.as_str(), value), ("points", toml::Value::Integer(200)));
        let (_, value) = parse_param("method=sensory").unwrap();
        assert_eq!(value, toml::Value::String("sensory".into()));
        let (_, value) = parse_param("period=[1.0, 2.0]").unwrap();
        assert!(value.is_array());
        assert!(matches!(
            parse_param("points"),
            Err(FrontError::Syntax { .. })
        ));
        assert!(matches!(parse_param(" =3"), Err(FrontError::Syntax { .. })));
    }

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    #[serde(deny_unknown_fields, default)]
    struct Table {
        points: usize,
        step: f64,
    }

    impl Default for Table {
        fn default() -> Self {
            Self {
                points: 100,
                step: 0.1,
            }
        }
    }

    #[test]
    fn parameters_go_through_the_tables_reader() {
        let set = |p: &[&str]| {
            let p: Vec<_> = p.iter().map(|t| parse_param(t).unwrap()).collect();
            with_params(&Table::default(), &p, &[("points", "--points")], "kernel")
        };
        assert_eq!(
            set(&["step=0.5"]).unwrap(),
            Table {
                points: 100,
                step: 0.5
            }
        );
        let err = set(&["stpe=0.5"]).unwrap_err().to_string();
        assert!(err.contains("[kernel]") && err.contains("stpe"), "{err}");
        let err = set(&["step=fast"]).unwrap_err().to_string();
        assert!(err.contains("step"), "{err}");
        let err = set(&["points=3"]).unwrap_err().to_string();
        assert!(err.contains("--points"), "{err}");
        let err = set(&["step=1.0", "step=2.0"]).unwrap_err().to_string();
        assert!(err.contains("twice"), "{err}");
    }

    #[test]
    fn a_metric_is_built_from_its_name_and_table() {
        let registry = MetricRegistry::builtin();
        let built = metric(
            &registry,
            MetricRequest::new("hausdorff", Periodicity::default()),
        )
        .unwrap();
        assert_eq!(built.params.metric.as_str(), "hausdorff");
        let err = metric(
            &registry,
            MetricRequest::new("hausdorf", Periodicity::default()),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("curve"), "{err}");
        let mut request = MetricRequest::new("curve", Periodicity::default());
        request
            .params
            .insert("nope".into(), toml::Value::Integer(1));
        assert!(metric(&registry, request).is_err());
    }

    #[test]
    fn a_working_space_is_the_agents_none_or_a_valid_box() {
        let arm = smspace::agent::AgentConfig::preset("planar-arm")
            .unwrap()
            .build()
            .unwrap();
        let default = WorkspaceSpec::parse("default")
            .unwrap()
            .resolve(arm.as_ref());
        assert_eq!(
            default.unwrap(),
            smspace::explore::default_workspace(arm.as_ref())
        );
        assert_eq!(WorkspaceSpec::None.resolve(arm.as_ref()).unwrap(), None);
        let boxed = WorkspaceSpec::Box([1.75, 0.0, 1.5, 3.0]).resolve(arm.as_ref());
        assert_eq!(boxed.unwrap().unwrap().size, [1.5, 3.0]);
        for bad in [[0.0, 0.0, 0.0, 1.0], [f64::NAN, 0.0, 1.0, 1.0]] {
            let err = WorkspaceSpec::Box(bad).resolve(arm.as_ref()).unwrap_err();
            assert!(err.to_string().contains("greater than zero"), "{err}");
        }
        assert!(WorkspaceSpec::parse("a,b,c,d").is_err());
    }

    #[test]
    fn the_learn_limit_is_at_most_the_default() {
        assert!(learn_memory_limit(None) <= gib_bytes(DEFAULT_MEMORY_LIMIT_GIB));
        assert_eq!(learn_memory_limit(Some(5)), 5);
        assert_eq!(memory_limit(Some(7)), Some(7));
    }
}
