//! Configuration files: TOML tables for the pipeline's stages.
//!
//! An agent can be named by a preset (`toy-line`, `toy-redundant`, `planar-arm`) or by
//! a TOML file whose `[agent]` table holds `kind` and the agent's parameters, with an
//! optional `[environment]` table (`lights`, `seed`, `region`). Other tables of the
//! file (an experiment's `[exploration]`, `[kernel]`, …) are left to their stages, so an
//! experiment file can serve as an agent file. Unknown keys inside `[agent]` and
//! `[environment]` are errors that name the key.
//!
//! ```toml
//! [agent]
//! kind = "planar-arm"
//! link_lengths = [1.0, 1.0, 1.0]
//! retina_cells = 6
//! retina_half_width = 1.0
//! focal_length = 1.0
//!
//! [environment]
//! lights = 10
//! seed = 1
//! ```

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::Deserialize;

use smspace::agent::{AgentConfig, AgentError, EnvironmentConfig};

mod experiment;
pub use experiment::*;

/// An error that may be about one parameter, which the experiment reader then locates
/// at its key's line ([`LoadedExperiment::invalid_error`]).
pub trait LocatedError: std::fmt::Display {
    /// The parameter the error is about, if it is about one.
    fn invalid_parameter(&self) -> Option<&smspace::params::InvalidParameter>;
}

impl LocatedError for smspace::Error {
    fn invalid_parameter(&self) -> Option<&smspace::params::InvalidParameter> {
        smspace::Error::invalid_parameter(self)
    }
}

/// Errors of configuration files.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The file is not valid TOML, or a table has a wrong or unknown key.
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message, with line, column and key.
        message: String,
    },
    /// A required table is missing.
    #[error("{path} has no [{table}] table")]
    MissingTable {
        /// The file.
        path: PathBuf,
        /// The table's name.
        table: &'static str,
    },
    /// The name is neither a preset nor an existing file.
    #[error(transparent)]
    Agent(#[from] AgentError),
    /// The file's `[agent]` table does not describe an agent.
    #[error("{path}: {reason}")]
    AgentTable {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the key.
        reason: AgentError,
    },
    /// A `--set stage.key=value` override is malformed or gives a wrong value.
    #[error("--set {assignment}: {reason}")]
    Override {
        /// The override as given.
        assignment: String,
        /// What is wrong, and how to write it.
        reason: String,
    },
    /// A value parses but is impossible (checked before anything runs).
    #[error("{path}{line}: [{table}] {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// `", line N"` when the key is written in the file, `" (from --set)"` when an
        /// override gave it, empty otherwise.
        line: String,
        /// The table (stage) whose parameter is wrong.
        table: &'static str,
        /// The stage's own message, naming the key and the value.
        reason: String,
    },
}

/// An agent and, optionally, how to make its environment.
#[derive(Debug, Clone, PartialEq)]
pub struct AgentSpec {
    /// The agent's parameters.
    pub agent: AgentConfig,
    /// The `[environment]` table, when the file has one.
    pub environment: Option<EnvironmentConfig>,
}

fn read_text(path: &Path) -> Result<String, ConfigError> {
    smspace::io::read_text_bounded(path, smspace::io::MAX_TEXT_BYTES).map_err(|e| match e {
        smspace::io::IoError::Read { path, reason } => ConfigError::Read { path, reason },
        other => ConfigError::Read {
            path: path.to_owned(),
            reason: std::io::Error::other(other.to_string()),
        },
    })
}

/// Parses TOML text into `T`; errors carry the file, line, column and key.
pub fn parse_toml<T: DeserializeOwned>(path: &Path, text: &str) -> Result<T, ConfigError> {
    toml::from_str(text).map_err(|e| ConfigError::Parse {
        path: path.to_owned(),
        message: e.to_string().trim_end().to_owned(),
    })
}

/// The tables of an agent file; other tables are left to their stages.
#[derive(Debug, Deserialize)]
struct AgentFile {
    agent: Option<AgentConfig>,
    environment: Option<EnvironmentConfig>,
}

/// Resolves `--agent`: a preset name, or a TOML file with an `[agent]` table.
pub fn load_agent(name_or_path: &str) -> Result<AgentSpec, ConfigError> {
    let path = Path::new(name_or_path);
    let looks_like_file = path.extension().is_some_and(|e| e == "toml") || path.exists();
    if !looks_like_file {
        return Ok(AgentSpec {
            agent: AgentConfig::preset(name_or_path)?,
            environment: None,
        });
    }
    let file: AgentFile = parse_toml(path, &read_text(path)?)?;
    let agent = file.agent.ok_or(ConfigError::MissingTable {
        path: path.to_owned(),
        table: "agent",
    })?;
    // Built once here so that a wrong key or value is reported with the file.
    agent.build().map_err(|reason| ConfigError::AgentTable {
        path: path.to_owned(),
        reason,
    })?;
    Ok(AgentSpec {
        agent,
        environment: file.environment,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_and_files() {
        assert_eq!(load_agent("toy-line").unwrap().agent.name(), "toy-line");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("arm.toml");
        std::fs::write(
            &path,
            "[agent]\nkind = \"planar-arm\"\nretina_cells = 8\n[environment]\nlights = 4\nseed = 9\n[kernel]\npoints = 3\n",
        )
        .unwrap();
        let spec = load_agent(path.to_str().unwrap()).unwrap();
        let agent = spec.agent.build().unwrap();
        assert_eq!(agent.sensor_dim(), 8);
        assert_eq!(spec.environment.unwrap().lights, Some(4));
    }

    #[test]
    fn errors_name_file_line_and_key() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, "[agent]\nkind = \"planar-arm\"\nfocal = 2.0\n").unwrap();
        let err = load_agent(path.to_str().unwrap()).unwrap_err().to_string();
        assert!(err.contains("bad.toml") && err.contains("focal"), "{err}");
        std::fs::write(
            &path,
            "[agent]\nkind = \"planar-arm\"\nretina_cells = \"six\"\n",
        )
        .unwrap();
        let err = load_agent(path.to_str().unwrap()).unwrap_err().to_string();
        assert!(err.contains("retina_cells"), "{err}");
        let err = load_agent("missing.toml").unwrap_err().to_string();
        assert!(err.contains("missing.toml"), "{err}");
        assert!(load_agent("snake")
            .unwrap_err()
            .to_string()
            .contains("snake"));
    }

    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn experiments_read_overrides_and_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(
            &dir,
            "small.toml",
            "description = \"a test\"\n[agent]\nkind = \"toy-redundant\"\n[kernel]\npoints = 20\n[[environment.compare]]\nseed = 2\n",
        );
        let loaded = load_experiment(&path, &[]).unwrap();
        assert_eq!(loaded.name, "small");
        assert_eq!(loaded.experiment.kernel.points, 20);
        assert_eq!(loaded.experiment.environment.configs().len(), 2);
        let loaded = load_experiment(
            &path,
            &["kernel.points=30".into(), "kernel.method=sensory".into()],
        )
        .unwrap();
        assert_eq!(loaded.experiment.kernel.points, 30);
        assert_eq!(
            loaded.experiment.kernel.method,
            smspace::kernel::TraceMethod::Sensory
        );
        // The resolved TOML reads back to the same experiment.
        let again: Experiment = toml::from_str(&loaded.resolved_toml()).unwrap();
        assert_eq!(again.kernel, loaded.experiment.kernel);
        assert_eq!(again.name.as_deref(), Some("small"));
    }

    #[test]
    fn experiment_errors_name_file_line_and_key() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(
            &dir,
            "bad.toml",
            "[agent]\nkind = \"planar-arm\"\n[kernel]\npoints = 20\nstpe = 0.1\n",
        );
        let err = load_experiment(&path, &[]).unwrap_err().to_string();
        assert!(
            err.contains("bad.toml") && err.contains("stpe") && err.contains("line 5"),
            "{err}"
        );
        let path = write(
            &dir,
            "bad2.toml",
            "[agent]\nkind = \"planar-arm\"\n[metrics]\n",
        );
        let err = load_experiment(&path, &[]).unwrap_err().to_string();
        assert!(err.contains("metrics"), "{err}");
        let path = write(
            &dir,
            "ok.toml",
            "[agent]\nkind = \"planar-arm\"\n[kernel]\npoints = 0\n",
        );
        let loaded = load_experiment(&path, &[]).unwrap();
        let err = loaded
            .invalid("kernel", "points = 0: must be at least 2")
            .to_string();
        assert!(err.contains("ok.toml, line 4: [kernel] points"), "{err}");
        for bad in ["kernel", "kernel.points", "kernal.points=3", ".x=1"] {
            let err = load_experiment(&path, &[bad.into()])
                .unwrap_err()
                .to_string();
            assert!(err.contains("--set"), "{bad}: {err}");
        }
        let err = load_experiment(&path, &["kernel.points=many".into()])
            .unwrap_err()
            .to_string();
        assert!(err.contains("--set") && err.contains("many"), "{err}");
        let loaded = load_experiment(&path, &["kernel.points=1".into()]).unwrap();
        let err = loaded
            .invalid("kernel", "points = 1: must be at least 2")
            .to_string();
        assert!(err.contains("(from --set kernel.points=1)"), "{err}");
    }

    /// A bad value in any table of an experiment gives an error that names the file,
    /// the line of its key, the table and the key: one case per table, each with the
    /// key below other keys of its table so that the line is the key's own.
    #[test]
    fn every_table_locates_a_bad_value_at_its_key_s_line() {
        let dir = tempfile::tempdir().unwrap();
        let arm = "[agent]\nkind = \"planar-arm\"\n";
        let cases: [(&str, &str, &str); 12] = [
            ("exploration", "seed = 3\nn = 1\n", "n"),
            (
                "kernel",
                "step_control = \"adaptive\"\nstep = 0.01\nmax_step = 0.001\n",
                "max_step",
            ),
            ("metric", "metric = \"curve\"\nperiod = [\"2pi\", \"none\"]\n", "period"),
            ("embedding", "method = \"cca\"\nepochs = 5\ndim = 0\n", "dim"),
            ("embedding", "method = \"isomap\"\ndim = 2\nk = 0\n", "k"),
            ("embedding", "method = \"mds\"\ndim = 2\nepochs = 5\n", "epochs"),
            ("embedding", "method = \"cca\"\ndim = 2\nepochs = \"many\"\n", "epochs"),
            ("analysis", "max_points = 500\nmax_homology_dim = 3\n", "max_homology_dim"),
            ("report", "seed = 2\ndpi = 10\n", "dpi"),
            ("scale", "path = \"dense\"\nknn = 1\n", "knn"),
            (
                "data",
                "law = { neighbours = 20 }\nmemory_limit_gib = -1.0\n[data.simulate]\nsamples = 100\n",
                "memory_limit_gib",
            ),
            ("environment", "seed = 2\nlights = 0\n", "lights"),
        ];
        for (table, body, key) in cases {
            let text = format!("{arm}\n[{table}]\n# the {table} table\n{body}");
            let line = 1 + text
                .lines()
                .position(|l| l.starts_with(&format!("{key} =")))
                .unwrap();
            let path = write(&dir, "tables.toml", &text);
            let err = match load_experiment(&path, &[]) {
                Ok(loaded) => crate::check(&loaded).unwrap_err().to_string(),
                Err(err) => err.to_string(),
            };
            assert!(
                err.contains(&format!("tables.toml, line {line}")) && err.contains(key),
                "[{table}] {key}: {err}"
            );
            assert!(
                err.contains(&format!("[{table}]")),
                "[{table}] {key}: {err}"
            );
        }
    }

    /// A renamed key (`[kernel] noise`, now `sensor_sigma`; `[data.simulate] noise`,
    /// now `relative_noise`) is refused at its line, with the new name and the value.
    #[test]
    fn a_renamed_key_is_refused_with_its_new_name_at_its_line() {
        let dir = tempfile::tempdir().unwrap();
        let cases = [
            (
                "[agent]\nkind = \"planar-arm\"\n[kernel]\nmethod = \"sensory\"\nnoise = \"auto\"\n",
                5,
                "sensor_sigma = \"auto\"",
            ),
            (
                "[agent]\nkind = \"toy-redundant\"\n[data]\nlaw = { neighbours = 20 }\n[data.simulate]\nsamples = 500\nnoise = 0.01\n",
                7,
                "relative_noise = 0.01",
            ),
        ];
        for (text, line, new) in cases {
            let path = write(&dir, "renamed.toml", text);
            let err = match load_experiment(&path, &[]) {
                Ok(loaded) => match crate::check(&loaded) {
                    Ok(plan) => {
                        let options = crate::RunOptions {
                            out_dir: dir.path().join("run"),
                            recompute: crate::Recompute::All,
                            memory_limit_bytes: None,
                            busy: crate::BusyFolder::Refuse,
                        };
                        struct Quiet;
                        impl crate::RunObserver for Quiet {
                            fn progress(&self) -> &dyn smspace::progress::Progress {
                                &smspace::progress::Silent
                            }
                        }
                        crate::run(&plan, &options, &Quiet).unwrap_err().to_string()
                    }
                    Err(err) => err.to_string(),
                },
                Err(err) => err.to_string(),
            };
            assert!(err.contains(new), "{err}");
            assert!(err.contains(&format!("renamed.toml, line {line}")), "{err}");
        }
    }

    /// An embedding method registered by an embedder is located like the built-in
    /// ones: a wrong key or value of its `[embedding]` table names its line, with no
    /// code for the method in the reader.
    #[test]
    fn a_registered_embedding_s_bad_key_is_located() {
        #[derive(serde::Serialize, serde::Deserialize)]
        #[serde(deny_unknown_fields, default)]
        struct PlainParams {
            dim: usize,
            gain: f64,
        }
        impl Default for PlainParams {
            fn default() -> Self {
                Self { dim: 2, gain: 1.0 }
            }
        }
        let mut registries = crate::Registries::builtin();
        registries.embeddings.register_params(
            "plain",
            "classical MDS under another name",
            |p: &PlainParams, _: &()| {
                Ok(Box::new(
                    smspace::embed::MdsParams::default().dim(p.dim).check()?,
                ))
            },
        );
        let dir = tempfile::tempdir().unwrap();
        let arm = "[agent]\nkind = \"planar-arm\"\n";
        for (body, line, key) in [
            ("method = \"plain\"\ndim = 2\ngian = 3.0\n", 7, "gian"),
            ("method = \"plain\"\ngain = \"high\"\ndim = 2\n", 6, "gain"),
            ("dim = 2\nmethod = \"plain\"\ndim_ = 0\n", 7, "dim_"),
        ] {
            let path = write(&dir, "plain.toml", &format!("{arm}\n[embedding]\n{body}"));
            let loaded = load_experiment(&path, &[]).unwrap();
            let err = crate::check_with(&loaded, registries.clone())
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(&format!("plain.toml, line {line}: [embedding]")) && err.contains(key),
                "{err}"
            );
        }
        let path = write(
            &dir,
            "plain.toml",
            &format!("{arm}[embedding]\nmethod = \"plain\"\n"),
        );
        let loaded = load_experiment(&path, &[]).unwrap();
        let plan = crate::check_with(&loaded, registries).unwrap();
        assert_eq!(
            plan.experiment.experiment.embedding.params["gain"].as_float(),
            Some(1.0)
        );
    }

    /// A stage's parameter error names its table and key, so the reader points at the
    /// key's own line even where the message names other keys too (here `max_step`'s
    /// message names `step`, written on an earlier line).
    #[test]
    fn parameter_errors_are_located_by_their_table_and_key() {
        let dir = tempfile::tempdir().unwrap();
        let check = |text: &str, overrides: &[&str]| {
            let path = write(&dir, "located.toml", text);
            let overrides: Vec<String> = overrides.iter().map(|o| o.to_string()).collect();
            let loaded = load_experiment(&path, &overrides).unwrap();
            crate::check(&loaded).unwrap_err().to_string()
        };
        let arm = "[agent]\nkind = \"planar-arm\"\n";
        let err = check(
            &format!("{arm}[kernel]\nstep_control = \"adaptive\"\nstep = 0.01\nmax_step = 0.001\n"),
            &[],
        );
        assert!(
            err.contains("located.toml, line 6: [kernel] invalid kernel parameter max_step"),
            "{err}"
        );
        let err = check(&format!("{arm}retina_cells = 0\n"), &[]);
        assert!(
            err.contains("line 3: [agent]") && err.contains("retina_cells = 0"),
            "{err}"
        );
        let err = check(
            &format!("{arm}[exploration]\nn = 10\nworkspace_center = [1.0, 0.0]\n"),
            &[],
        );
        assert!(
            err.contains("line 5: [exploration]") && err.contains("workspace_size"),
            "{err}"
        );
        let err = check(
            &format!("{arm}[environment]\nseed = 2\nlights = 5000\n"),
            &[],
        );
        assert!(err.contains("line 5: [environment]"), "{err}");
        let err = check(
            &format!("{arm}[kernel]\npoints = 10\n"),
            &["kernel.points=0"],
        );
        assert!(err.contains("(from --set kernel.points=0)"), "{err}");
    }
}
