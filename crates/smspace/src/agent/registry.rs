//! Agent kinds by name: the `kind` of an `[agent]` table picks an entry of an
//! [`AgentRegistry`], which builds the agent from the rest of the table.
//!
//! The built-in agents register here, one line each ([`AgentRegistry::builtin`]); an
//! embedder registers its own kinds the same way and hands the registry to
//! [`crate::pipeline::check_with`] (a new agent kind is one file plus one
//! registration line). A kind's parameters are a serde struct with
//! `#[serde(deny_unknown_fields, default)]`: unknown keys are errors that name the key,
//! and the resolved table (defaults included) is what the run records.
//!
//! ```
//! use smspace::agent::{AgentConfig, AgentRegistry};
//! let registry = AgentRegistry::builtin();
//! assert!(registry.kinds().any(|k| k == "planar-arm"));
//! let config: AgentConfig = toml::from_str("kind = \"planar-arm\"\nretina_cells = 8").unwrap();
//! let built = registry.build(&config)?;
//! assert_eq!(built.agent.sensor_dim(), 8);
//! // The resolved parameters hold every default.
//! assert!(built.config.params.contains_key("link_lengths"));
//! # Ok::<(), smspace::agent::AgentError>(())
//! ```

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::Serialize;

use super::{Agent, AgentConfig, AgentError, PlanarArm, ToyAgent, ToyKind, ToyParams};

/// An agent built from its table, with the table resolved (defaults included).
#[derive(Debug)]
pub struct BuiltAgent {
    /// The agent.
    pub agent: Box<dyn Agent>,
    /// Its `[agent]` table with every parameter, defaults included.
    pub config: AgentConfig,
}

/// Builds an agent of one kind from the parameters of its `[agent]` table (`kind`
/// removed); returns the agent and the resolved parameters.
pub type AgentBuilder =
    Arc<dyn Fn(&toml::Table) -> Result<(Box<dyn Agent>, toml::Table), AgentError> + Send + Sync>;

#[derive(Clone)]
struct Entry {
    summary: String,
    build: AgentBuilder,
}

/// The agent kinds a run can build, by name.
#[derive(Clone, Default)]
pub struct AgentRegistry {
    kinds: BTreeMap<String, Entry>,
}

impl std::fmt::Debug for AgentRegistry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.kinds.keys()).finish()
    }
}

impl AgentRegistry {
    /// A registry without any kind.
    pub fn empty() -> Self {
        Self::default()
    }

    /// The built-in agents: the paper's two toys and its arm.
    pub fn builtin() -> Self {
        let mut r = Self::empty();
        r.register_params(
            "toy-line",
            "paper section 2.2: one motor moves the body along a line",
            |p: &ToyParams| Ok(Box::new(ToyAgent::new(ToyKind::Line, p)?)),
        );
        r.register_params(
            "toy-redundant",
            "paper section 2.3: two redundant motors move the body along a line",
            |p: &ToyParams| Ok(Box::new(ToyAgent::new(ToyKind::Redundant, p)?)),
        );
        r.register_params(
            "planar-arm",
            "paper section 3.1: a planar arm with a pinhole retina at its end",
            PlanarArm::build,
        );
        r.register(
            "chain",
            "a kinematic chain of your own, planar or 3-D, with a pinhole retina at its end",
            super::chain::builder(),
        );
        r
    }

    /// Registers (or replaces) the kind `kind` with a builder of its own.
    pub fn register(
        &mut self,
        kind: impl Into<String>,
        summary: impl Into<String>,
        build: AgentBuilder,
    ) {
        self.kinds.insert(
            kind.into(),
            Entry {
                summary: summary.into(),
                build,
            },
        );
    }

    /// Registers the kind `kind` whose parameters are the serde struct `P` (with
    /// `#[serde(deny_unknown_fields, default)]`), built by `new`.
    pub fn register_params<P, F>(&mut self, kind: &str, summary: &str, new: F)
    where
        P: DeserializeOwned + Serialize + 'static,
        F: Fn(&P) -> Result<Box<dyn Agent>, AgentError> + Send + Sync + 'static,
    {
        let name = kind.to_owned();
        let build = move |table: &toml::Table| {
            let params: P =
                toml::Value::Table(table.clone())
                    .try_into()
                    .map_err(|e: toml::de::Error| AgentError::InvalidTable {
                        kind: name.clone(),
                        reason: e.to_string().trim_end().to_owned(),
                    })?;
            let agent = new(&params)?;
            let resolved = match toml::Value::try_from(&params) {
                Ok(toml::Value::Table(t)) => t,
                _ => table.clone(),
            };
            Ok((agent, resolved))
        };
        self.register(kind, summary, Arc::new(build));
    }

    /// The registered kinds, in name order.
    pub fn kinds(&self) -> impl Iterator<Item = &str> {
        self.kinds.keys().map(String::as_str)
    }

    /// One line on a kind, if registered.
    pub fn summary(&self, kind: &str) -> Option<&str> {
        self.kinds.get(kind).map(|e| e.summary.as_str())
    }

    /// Builds the agent an `[agent]` table describes, and checks that its parts agree
    /// ([`check_agent`](super::check_agent)).
    pub fn build(&self, config: &AgentConfig) -> Result<BuiltAgent, AgentError> {
        let entry = self
            .kinds
            .get(&config.kind)
            .ok_or_else(|| AgentError::UnknownAgent {
                name: config.kind.clone(),
                known: self.kinds().collect::<Vec<_>>().join(", "),
            })?;
        let (agent, params) = (entry.build)(&config.params)?;
        super::check_agent(agent.as_ref())?;
        Ok(BuiltAgent {
            agent,
            config: AgentConfig {
                kind: config.kind.clone(),
                params,
            },
        })
    }
}
