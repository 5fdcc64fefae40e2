//! Experiment files: one TOML table per stage of the pipeline, read with `--set`
//! overrides and every error located at its file, line and key (needs the `pipeline`
//! feature).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{parse_toml, read_text, ConfigError, LocatedError};
use crate::report::ReportParams;
use smspace::agent::{AgentConfig, EnvironmentConfig, LightRegion};
use smspace::analysis::AnalysisParams;
use smspace::embed::EmbedParams;
use smspace::explore::ExploreParams;
use smspace::kernel::TraceParams;
use smspace::metric::DistanceParams;
use smspace::params::InvalidParameter;

/// The `[environment]` table of an experiment: the environment the pipeline runs in and,
/// optionally, further environments to compare with it (paper Fig. 1; environment
/// invariance, section 3.3).
///
/// ```toml
/// [environment]
/// lights = 10
/// seed = 1
///
/// [[environment.compare]]
/// lights = 8
/// seed = 2
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExperimentEnvironment {
    /// Number of random lights (default: the agent's, 5 for the toys and 10 for the arm).
    pub lights: Option<usize>,
    /// Seed of the random lights. Default 1.
    pub seed: u64,
    /// Where the lights are drawn (default: the agent's region).
    pub region: Option<LightRegion>,
    /// For an agent with a camera: the extents `[x, y, z]` of the textured room it
    /// looks at, seeded by `seed` (default: around the agent's light region; see
    /// [`EnvironmentConfig::room`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub room: Option<[f64; 3]>,
    /// For an agent with a camera: objects standing on the room's floor, seeded by
    /// `seed` (see [`EnvironmentConfig::objects`]). Default 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub objects: usize,
    /// Further environments (`[[environment.compare]]` tables with `lights`, `seed`,
    /// `region`). Default none.
    pub compare: Vec<EnvironmentConfig>,
}

impl Default for ExperimentEnvironment {
    fn default() -> Self {
        let base = EnvironmentConfig::default();
        Self {
            lights: base.lights,
            seed: base.seed,
            region: base.region,
            room: base.room,
            objects: base.objects,
            compare: Vec::new(),
        }
    }
}

fn is_zero(value: &usize) -> bool {
    *value == 0
}

impl ExperimentEnvironment {
    /// Every environment's configuration, the main one first.
    pub fn configs(&self) -> Vec<EnvironmentConfig> {
        let main = EnvironmentConfig {
            lights: self.lights,
            seed: self.seed,
            region: self.region,
            room: self.room,
            objects: self.objects,
        };
        std::iter::once(main)
            .chain(self.compare.iter().cloned())
            .collect()
    }
}

/// An experiment file: one table per stage of the pipeline, run by `smspace run`.
/// Every table but `[agent]` may be left out (its defaults are the paper's); unknown
/// tables and keys are errors that name the key.
///
/// ```
/// use smspace_pipeline::config::Experiment;
/// let experiment: Experiment = toml::from_str(r#"
///     name = "small-arm"
///     [agent]
///     kind = "planar-arm"
///     [exploration]
///     n = 300
///     [embedding]
///     method = "cca"
///     dim = 3
/// "#).unwrap();
/// assert_eq!(experiment.exploration.n, 300);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Experiment {
    /// The experiment's name, used for the default output folder `runs/<name>`.
    /// Default: the file's stem.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// What the experiment shows (the report's first paragraph).
    #[serde(default)]
    pub description: String,
    /// The agent (paper section 2.2, 2.3 or 3.1). Required, except in a run from
    /// logged files (`[data]` with `motors` and `sensors`), which has no agent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agent: Option<AgentConfig>,
    /// A run from a sensorimotor log instead of a simulator
    /// ([`crate::data`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<crate::data::DataParams>,
    /// The environments.
    #[serde(default)]
    pub environment: ExperimentEnvironment,
    /// Motor babbling and the probe grid.
    #[serde(default)]
    pub exploration: ExploreParams,
    /// Tracing of the kernel sets.
    #[serde(default)]
    pub kernel: TraceParams,
    /// With `[kernel] method = "learned"`: the budget of sensor rows the agent may be
    /// read (`budget`, required), the babbling rounds, verification and the law
    /// (`[learn.law]`) of [`smspace::learn::budget`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learn: Option<smspace::learn::budget::BudgetParams>,
    /// The metric between sets.
    #[serde(default)]
    pub metric: DistanceParams,
    /// The embedding method, tagged by `method`.
    #[serde(default)]
    pub embedding: EmbedParams,
    /// Topology, dimension, agreement and invariance.
    #[serde(default)]
    pub analysis: AnalysisParams,
    /// Figures and report.
    #[serde(default)]
    pub report: ReportParams,
    /// The dense or landmark path through distances, embedding and analysis
    /// ([`crate::scale`]).
    #[serde(default)]
    pub scale: crate::scale::ScaleParams,
}

/// The tables of an experiment file, for error messages.
pub const EXPERIMENT_TABLES: [&str; 11] = [
    "agent",
    "data",
    "environment",
    "exploration",
    "kernel",
    "learn",
    "metric",
    "embedding",
    "analysis",
    "report",
    "scale",
];

/// An experiment read from its file, with the `--set` overrides applied.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedExperiment {
    /// The file.
    pub path: PathBuf,
    /// The experiment's name: its `name` key, else the file's stem.
    pub name: String,
    /// The parameters.
    pub experiment: Experiment,
    /// The file's text as written.
    pub text: String,
    /// The overrides applied, as given (`kernel.points=50`).
    pub overrides: Vec<String>,
}

impl LoadedExperiment {
    /// The resolved experiment as TOML: every parameter, defaults included.
    pub fn resolved_toml(&self) -> String {
        let mut experiment = self.experiment.clone();
        experiment.name = Some(self.name.clone());
        toml::to_string_pretty(&experiment)
            .unwrap_or_else(|e| format!("# the experiment could not be written as TOML: {e}\n"))
    }

    /// An [`Invalid`](ConfigError::Invalid) error for a stage's error: located at the
    /// line of its key ([`LocatedError::invalid_parameter`]: the table and key it
    /// names), or at the override that set it; errors that name no parameter are
    /// located as [`invalid`](Self::invalid) does, in `table`.
    pub fn invalid_error(&self, table: &'static str, error: impl LocatedError) -> ConfigError {
        match error.invalid_parameter() {
            Some(parameter) => self.invalid_parameter(parameter),
            None => self.invalid(table, error),
        }
    }

    /// An [`Invalid`](ConfigError::Invalid) error for `parameter`, located at the line of
    /// its key in its table (`[table]` or a `[table.key]` sub-table), or at the `--set
    /// table.key=…` that gave it.
    pub fn invalid_parameter(&self, parameter: &InvalidParameter) -> ConfigError {
        let (table, key) = (parameter.table, parameter.key);
        let path = format!("{table}.{key}");
        let overridden = self.overrides.iter().find(|o| {
            o.split_once('=').is_some_and(|(p, _)| {
                let p = p.trim();
                p == path || p.starts_with(&format!("{path}."))
            })
        });
        let line = match overridden {
            Some(o) => format!(" (from --set {o})"),
            None => exact_key_line(&self.text, table, key)
                .map(|n| format!(", line {n}"))
                .unwrap_or_default(),
        };
        ConfigError::Invalid {
            path: self.path.clone(),
            line,
            table,
            reason: parameter.to_string(),
        }
    }

    /// An [`Invalid`](ConfigError::Invalid) error for the parameter table `section` of
    /// `table` (`embedding`, or `metric.params` in `metric`) that a registry entry
    /// reads: located as [`invalid_error`](Self::invalid_error) does when the error
    /// names a parameter or a `--set` gave the table a key; otherwise at the line of the
    /// key or value that `read` refuses in the section's text (the entry's own reader,
    /// [`smspace::registry::Registry::read_error`], given the file with every other line
    /// blanked and the keys in `skip`, such as the `method` that picks the entry, left
    /// out). So any registered entry's errors are located, with no code for each.
    pub fn invalid_table_error(
        &self,
        table: &'static str,
        section: &str,
        skip: &[&str],
        error: impl LocatedError,
        read: impl Fn(&str) -> Option<toml::de::Error>,
    ) -> ConfigError {
        let overridden = self.overrides.iter().any(|o| {
            o.split_once('=')
                .is_some_and(|(p, _)| p.trim().starts_with(&format!("{table}.")))
        });
        if error.invalid_parameter().is_some() || overridden {
            return self.invalid_error(table, error);
        }
        let document = section_document(&self.text, section, skip);
        let Some(line) = read(&document)
            .and_then(|e| e.span())
            .map(|span| document[..span.start].matches('\n').count() + 1)
        else {
            return self.invalid_error(table, error);
        };
        let message = error.to_string();
        let key = self
            .text
            .lines()
            .nth(line - 1)
            .and_then(|l| l.split_once('='))
            .map(|(k, _)| k.trim().trim_matches('"').to_owned())
            .filter(|k| !k.is_empty() && !mentions(&message, k));
        ConfigError::Invalid {
            path: self.path.clone(),
            line: format!(", line {line}"),
            table,
            reason: match key {
                Some(key) => format!("{key}: {message}"),
                None => message,
            },
        }
    }

    /// An [`Invalid`](ConfigError::Invalid) error for `table`, located at the line of the
    /// first of the table's keys that `message` names (or at the override that set it):
    /// for errors that carry no [`InvalidParameter`].
    pub fn invalid(&self, table: &'static str, message: impl ToString) -> ConfigError {
        let reason = message.to_string();
        let overridden = self.overrides.iter().find(|o| {
            o.split_once('=').is_some_and(|(path, _)| {
                let path = path.trim();
                path.split_once('.').is_some_and(|(t, key)| {
                    t == table && mentions(&reason, key.rsplit('.').next().unwrap_or(key))
                })
            })
        });
        let line = match overridden {
            Some(o) => format!(" (from --set {o})"),
            None => key_line(&self.text, table, &reason)
                .map(|n| format!(", line {n}"))
                .unwrap_or_default(),
        };
        ConfigError::Invalid {
            path: self.path.clone(),
            line,
            table,
            reason,
        }
    }
}

/// The 1-based line where `key` of `[table]` is written: `key = …` inside `[table]`
/// (or one of its `[[table.…]]` entries), or the header of a `[table.key]` sub-table;
/// `table = ""` is the file's top level, before the first table.
fn exact_key_line(text: &str, table: &str, key: &str) -> Option<usize> {
    let sub_table = format!("{table}.{key}");
    let mut in_table = table.is_empty();
    for (n, line) in text.lines().enumerate() {
        let t = line.trim();
        if let Some(header) = table_header(t) {
            if header == sub_table {
                return Some(n + 1);
            }
            in_table = header == table || header.starts_with(&format!("{table}."));
            continue;
        }
        if in_table {
            let written = t.split_once('=').map(|(k, _)| k.trim().trim_matches('"'));
            if written == Some(key) {
                return Some(n + 1);
            }
        }
    }
    None
}

/// The lines of the table `section` (`embedding`, `metric.params`) of `text` as a
/// document of their own, with every other line blank so that lines keep their
/// numbers: the section's header becomes `[section]`'s last part alone (its sub-tables
/// follow), and the keys in `skip` are blanked.
fn section_document(text: &str, section: &str, skip: &[&str]) -> String {
    let own = section.rsplit('.').next().unwrap_or(section);
    let mut inside = false;
    text.lines()
        .map(|line| {
            let t = line.trim();
            if let Some(header) = table_header(t) {
                let rest = if header == section {
                    Some(String::new())
                } else {
                    header
                        .strip_prefix(section)
                        .filter(|r| r.starts_with('.'))
                        .map(str::to_owned)
                };
                inside = rest.is_some();
                return match rest {
                    Some(rest) if t.starts_with("[[") => format!("[[{own}{rest}]]"),
                    Some(rest) => format!("[{own}{rest}]"),
                    None => String::new(),
                };
            }
            let key = t.split_once('=').map(|(k, _)| k.trim().trim_matches('"'));
            if inside && !key.is_some_and(|k| skip.contains(&k)) {
                line.to_owned()
            } else {
                String::new()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The name of the table a trimmed line opens (`[table]` or `[[table]]`), if it is a
/// table header.
fn table_header(line: &str) -> Option<&str> {
    line.starts_with('[').then(|| {
        line.trim_start_matches('[')
            .split(']')
            .next()
            .unwrap_or("")
            .trim()
    })
}

/// Whether `message` names `key` as a word.
fn mentions(message: &str, key: &str) -> bool {
    message.match_indices(key).any(|(at, _)| {
        let before = message[..at].chars().next_back();
        let after = message[at + key.len()..].chars().next();
        let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
        !word(before) && !word(after)
    })
}

/// The 1-based line of the first key of `[table]` in `text` that `message` names.
fn key_line(text: &str, table: &str, message: &str) -> Option<usize> {
    let mut in_table = false;
    for (n, line) in text.lines().enumerate() {
        let t = line.trim();
        if let Some(header) = table_header(t) {
            in_table = header == table || header.starts_with(&format!("{table}."));
            continue;
        }
        if !in_table {
            continue;
        }
        if let Some((key, _)) = t.split_once('=') {
            let key = key.trim().trim_matches('"');
            if !key.is_empty() && mentions(message, key) {
                return Some(n + 1);
            }
        }
    }
    None
}

/// Applies `stage.key=value` to a TOML table; `value` is read as TOML (`50`, `1e-3`,
/// `"sensory"`, `[1.0, 2.0]`), and as a string when it is not valid TOML (`sensory`).
fn apply_override(root: &mut toml::Table, assignment: &str) -> Result<(), ConfigError> {
    let fail = |reason: String| ConfigError::Override {
        assignment: assignment.to_owned(),
        reason,
    };
    let (path, raw) = assignment
        .split_once('=')
        .ok_or_else(|| fail("write it as stage.key=value, e.g. --set kernel.points=50".into()))?;
    let keys: Vec<&str> = path.trim().split('.').map(str::trim).collect();
    if keys.len() < 2 || keys.iter().any(|k| k.is_empty()) {
        return Err(fail(format!(
            "`{}` is not stage.key; the stages are {}",
            path.trim(),
            EXPERIMENT_TABLES.join(", ")
        )));
    }
    if !EXPERIMENT_TABLES.contains(&keys[0]) {
        return Err(fail(format!(
            "unknown stage `{}`; the stages are {}",
            keys[0],
            EXPERIMENT_TABLES.join(", ")
        )));
    }
    let raw = raw.trim();
    let value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_owned()));
    let mut table = root;
    for key in &keys[..keys.len() - 1] {
        let entry = table
            .entry(key.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        table = entry
            .as_table_mut()
            .ok_or_else(|| fail(format!("`{key}` is a value, not a table")))?;
    }
    table.insert(keys[keys.len() - 1].to_owned(), value);
    Ok(())
}

/// Reads an experiment file and applies the overrides (`stage.key=value`). Syntax
/// errors, unknown keys and wrong types name the file, line and key (or the override).
/// Values are checked by each stage's `check` before anything runs (see the pipeline).
pub fn load_experiment(path: &Path, overrides: &[String]) -> Result<LoadedExperiment, ConfigError> {
    let text = read_text(path)?;
    let mut experiment: Experiment = parse_toml(path, &text)?;
    if !overrides.is_empty() {
        let mut root: toml::Table = parse_toml(path, &text)?;
        for o in overrides {
            apply_override(&mut root, o)?;
        }
        experiment = Experiment::deserialize(toml::Value::Table(root)).map_err(|e| {
            ConfigError::Override {
                assignment: overrides.join(" "),
                reason: e.to_string().trim_end().to_owned(),
            }
        })?;
    }
    let name = match &experiment.name {
        Some(name) => name.clone(),
        None => path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "experiment".to_owned()),
    };
    if name.is_empty()
        || name.contains(['/', '\\'])
        || name.starts_with('.')
        || name.chars().any(char::is_control)
    {
        let parameter = InvalidParameter::new(
            "experiment",
            "name",
            format!("{name:?}"),
            "the name becomes the folder runs/<name>; use letters, digits and dashes",
        );
        return Err(ConfigError::Invalid {
            path: path.to_owned(),
            line: exact_key_line(&text, "", "name")
                .map(|n| format!(", line {n}"))
                .unwrap_or_default(),
            table: parameter.table,
            reason: parameter.to_string(),
        });
    }
    Ok(LoadedExperiment {
        path: path.to_owned(),
        name,
        experiment,
        text,
        overrides: overrides.to_vec(),
    })
}
