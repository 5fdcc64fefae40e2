//! Arguments shared by several subcommands: the agent, the environment, the working space.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use smspace::agent::{Agent, Environment, EnvironmentConfig};
use smspace::explore::Workspace;
use smspace_pipeline::config::{load_agent, AgentSpec};
use smspace_pipeline::front;

/// `--agent NAME|FILE`.
#[derive(Debug, Clone, Args)]
pub struct AgentArgs {
    /// Agent: a preset (toy-line, toy-redundant, planar-arm) or a TOML file with an
    /// [agent] table (and optionally an [environment] table).
    #[arg(long, value_name = "NAME|FILE", default_value = "planar-arm")]
    pub agent: String,
}

impl AgentArgs {
    /// The agent file, when `--agent` names a file rather than a preset.
    pub fn file(&self) -> Option<&Path> {
        let path = Path::new(&self.agent);
        path.is_file().then_some(path)
    }

    /// Resolves and builds the agent.
    pub fn load(&self) -> anyhow::Result<(AgentSpec, Box<dyn Agent>)> {
        let spec = load_agent(&self.agent)?;
        let agent = spec
            .agent
            .build()
            .with_context(|| format!("agent '{}'", self.agent))?;
        Ok((spec, agent))
    }
}

/// `--env FILE | --env-seed S [--lights L]`.
#[derive(Debug, Clone, Args)]
pub struct EnvArgs {
    /// Environment file (JSON, as written by `smspace env`).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["env_seed", "lights"])]
    pub env: Option<PathBuf>,
    /// Draw a random environment from this seed.
    #[arg(long, value_name = "S")]
    pub env_seed: Option<u64>,
    /// Number of random lights (default: the agent's, 10 for the arm, 5 for the toys).
    #[arg(long, value_name = "L")]
    pub lights: Option<usize>,
}

impl EnvArgs {
    /// The environment asked for: a file, a seed, or the agent file's `[environment]`
    /// table; `None` when nothing names one.
    pub fn resolve(
        &self,
        spec: &AgentSpec,
        agent: &dyn Agent,
    ) -> anyhow::Result<Option<Environment>> {
        if let Some(path) = &self.env {
            let environment = Environment::load(path)?;
            environment
                .check_for(agent)
                .with_context(|| format!("environment {}", path.display()))?;
            return Ok(Some(environment));
        }
        let table = spec.environment.clone();
        if self.env_seed.is_none() && self.lights.is_none() && table.is_none() {
            return Ok(None);
        }
        let mut config = table.unwrap_or_default();
        if let Some(seed) = self.env_seed {
            config.seed = seed;
        }
        if self.lights.is_some() {
            config.lights = self.lights;
        }
        Ok(Some(config.build(agent)?))
    }

    /// Like [`resolve`](Self::resolve), but a default random environment (seed 1) when
    /// nothing names one.
    pub fn resolve_or_default(
        &self,
        spec: &AgentSpec,
        agent: &dyn Agent,
    ) -> anyhow::Result<Environment> {
        match self.resolve(spec, agent)? {
            Some(env) => Ok(env),
            None => Ok(EnvironmentConfig::default().build(agent)?),
        }
    }
}

/// `--workspace default|none|CX,CY,DEPTH,WIDTH`.
#[derive(Debug, Clone, Args)]
pub struct WorkspaceArgs {
    /// Working space: `default` (the paper's for the arm, none for the toys), `none`, or
    /// `CX,CY,DEPTH,WIDTH` (centre and full extents along x and y).
    #[arg(long, value_name = "SPEC", default_value = "default")]
    pub workspace: String,
}

impl WorkspaceArgs {
    /// The working space `--workspace` names ([`front::WorkspaceSpec`]).
    pub fn resolve(&self, agent: &dyn Agent) -> anyhow::Result<Option<Workspace>> {
        let spec = front::WorkspaceSpec::parse(&self.workspace).context("--workspace")?;
        spec.resolve(agent).context("--workspace")
    }
}

/// Refuses, before any work, an output that names one of the inputs (by path, link or
/// inode; `None` inputs are skipped): the library's check, which the files staged later
/// pass again ([`smspace::io::Outputs::sparing`]).
pub fn spare_inputs(outputs: &[&Path], inputs: &[(&str, Option<&Path>)]) -> anyhow::Result<()> {
    let inputs = present(inputs);
    smspace::io::check_outputs_spare_inputs(outputs.iter().copied(), &inputs)?;
    Ok(())
}

/// The inputs that are given, for [`smspace::io::check_outputs_spare_inputs`].
pub fn present<'a>(inputs: &[(&'a str, Option<&'a Path>)]) -> Vec<smspace::io::Input<'a>> {
    inputs
        .iter()
        .filter_map(|(what, path)| path.map(|p| smspace::io::Input::new(what, p)))
        .collect()
}

/// The file beside `out` named `<stem>.<suffix>` (`sets.npy` → `sets.trace.json`), for
/// the reports and side arrays a command writes next to its main output.
pub fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    out.with_file_name(format!("{stem}.{suffix}"))
}

/// Refuses to start when `what` needs more than `limit` bytes (default: the memory
/// available, [`smspace_pipeline::front::memory_limit`]), naming the sizes and `fix`.
pub fn check_memory(what: &str, needed: u64, limit: Option<u64>, fix: &str) -> anyhow::Result<()> {
    if let Some(available) = front::memory_limit(limit) {
        anyhow::ensure!(
            needed <= available,
            "the {what} need {} but only {} is available (--max-memory); {fix}",
            smspace::metric::human_bytes(needed),
            smspace::metric::human_bytes(available)
        );
    }
    Ok(())
}

/// `--param KEY=VALUE`: a parameter, the value read as TOML (a bare word that is not
/// TOML is a string); [`front::parse_param`].
pub fn parse_param(text: &str) -> Result<(String, toml::Value), String> {
    front::parse_param(text).map_err(|e| e.to_string())
}

/// `--param KEY=VALUE` entries, in the order given.
pub type Params = Vec<(String, toml::Value)>;

/// The `--param` entries whose key starts with `prefix` (`learn.`), the prefix taken
/// off, and the others, each in the order given.
pub fn split_params(params: &[(String, toml::Value)], prefix: &str) -> (Params, Params) {
    let mut prefixed = Vec::new();
    let mut rest = Vec::new();
    for (key, value) in params {
        match key.strip_prefix(prefix) {
            Some(key) => prefixed.push((key.to_owned(), value.clone())),
            None => rest.push((key.clone(), value.clone())),
        }
    }
    (prefixed, rest)
}

/// `value`, a parameter table, with the `--param KEY=VALUE` keys set: read back by the
/// table's own reader, which names an unknown key or a bad value
/// ([`front::with_params`]). A key in `flags` (`(key, flag)`, the flag without its
/// dashes) has a flag of its own and is refused here, naming the flag; a key given
/// twice too.
pub fn with_table_params<T>(
    value: &T,
    params: &[(String, toml::Value)],
    flags: &[(&str, &str)],
    table: &str,
) -> anyhow::Result<T>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let flags: Vec<(&str, String)> = flags.iter().map(|&(k, f)| (k, format!("--{f}"))).collect();
    let arguments: Vec<(&str, &str)> = flags.iter().map(|(k, f)| (*k, f.as_str())).collect();
    front::with_params(value, params, &arguments, table).context("--param")
}
