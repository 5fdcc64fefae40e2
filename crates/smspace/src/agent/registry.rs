//! Agent kinds by name: the `kind` of an `[agent]` table picks an entry of an
//! [`AgentRegistry`] (the crate's one [`Registry`] type), which builds the agent from
//! the rest of the table.
//!
//! The built-in agents register here, one line each ([`AgentRegistry::builtin`]); an
//! embedder registers its own kinds the same way and hands the registry to
//! `smspace_pipeline::check_with` (a new agent kind is one file plus one
//! registration line). A kind's parameters are a serde struct with
//! `#[serde(deny_unknown_fields, default)]`: unknown keys are errors that name the key,
//! and the resolved table (defaults included) is what the run records.
//!
//! ```
//! use smspace::agent::{AgentConfig, AgentRegistry};
//! let registry = AgentRegistry::builtin();
//! assert!(registry.names().any(|k| k == "planar-arm"));
//! let config: AgentConfig = toml::from_str("kind = \"planar-arm\"\nretina_cells = 8").unwrap();
//! let built = registry.build(&config)?;
//! assert_eq!(built.agent.sensor_dim(), 8);
//! // The resolved parameters hold every default.
//! assert!(built.config.params.contains_key("link_lengths"));
//! # Ok::<(), smspace::agent::AgentError>(())
//! ```

use super::{
    Agent, AgentConfig, AgentError, NoiseParams, NoisyAgent, PlanarArm, ToyAgent, ToyKind,
    ToyParams,
};
use crate::registry::{Builder, Registry, RegistryError};

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
pub type AgentBuilder = Builder<dyn Agent, (), AgentError>;

/// The agent kinds a run can build, by name: register a kind with
/// [`Registry::register_params`] (`|params: &P, _: &()| …`).
pub type AgentRegistry = Registry<dyn Agent, (), AgentError>;

impl RegistryError for AgentError {
    fn unknown(name: &str, known: String) -> Self {
        AgentError::UnknownAgent {
            name: name.to_owned(),
            known,
        }
    }

    fn invalid_table(name: &str, reason: String) -> Self {
        AgentError::InvalidTable {
            kind: name.to_owned(),
            reason,
        }
    }
}

impl Registry<dyn Agent, (), AgentError> {
    /// The built-in agents: the paper's two toys and its arm, and chains of your own.
    pub fn builtin() -> Self {
        let mut r = Self::empty();
        r.register_params(
            "toy-line",
            "paper section 2.2: one motor moves the body along a line",
            |p: &ToyParams, _: &()| Ok(Box::new(ToyAgent::new(ToyKind::Line, p)?)),
        );
        r.register_params(
            "toy-redundant",
            "paper section 2.3: two redundant motors move the body along a line",
            |p: &ToyParams, _: &()| Ok(Box::new(ToyAgent::new(ToyKind::Redundant, p)?)),
        );
        r.register_params(
            "planar-arm",
            "paper section 3.1: a planar arm with a pinhole retina at its end",
            |p, _: &()| PlanarArm::build(p),
        );
        r.register(
            "chain",
            "a kinematic chain of your own, planar or 3-D, with a pinhole retina at its end",
            toml::Table::new(),
            super::chain::builder(),
        );
        r
    }

    /// Builds the agent an `[agent]` table describes, and checks that its parts agree
    /// ([`check_agent`](super::check_agent)). A `noise` subtable, of any kind, wraps
    /// the agent in a [`NoisyAgent`] ([`NoiseParams`]; no noise: the agent itself).
    pub fn build(&self, config: &AgentConfig) -> Result<BuiltAgent, AgentError> {
        let mut table = config.params.clone();
        let noise = table.remove("noise");
        let (mut agent, mut params) = self.make(&config.kind, &table, &())?;
        if let Some(noise) = noise {
            let noise: NoiseParams = noise.try_into().map_err(|e: toml::de::Error| {
                AgentError::invalid_table(
                    &config.kind,
                    format!("[agent.noise]: {}", e.to_string().trim_end()),
                )
            })?;
            noise.check()?;
            if let Ok(toml::Value::Table(resolved)) = toml::Value::try_from(noise) {
                params.insert("noise".to_owned(), toml::Value::Table(resolved));
            }
            if noise.is_noisy() {
                agent = Box::new(NoisyAgent::new(agent, noise)?);
            }
        }
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
