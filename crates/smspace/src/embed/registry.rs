//! Embedding methods by name: the `method` of an `[embedding]` table picks an entry of
//! an [`EmbeddingRegistry`] (the crate's one [`Registry`] type), which builds the method
//! from the rest of the table. The built-in methods register here, one line each; an
//! embedder registers its own the same way (a new method is one file plus one
//! registration line) and hands the registry to the pipeline
//! (`smspace_pipeline::Registries`).
//!
//! ```
//! use smspace::embed::{EmbedParams, EmbeddingRegistry};
//! let registry = EmbeddingRegistry::builtin();
//! assert_eq!(registry.names().collect::<Vec<_>>(), ["cca", "isomap", "mds"]);
//! let params: EmbedParams = toml::from_str("method = \"mds\"\ndim = 2").unwrap();
//! let (resolved, method) = params.resolve(&registry)?;
//! assert_eq!(method.dim(), 2);
//! // The resolved table holds every default.
//! assert!(resolved.params.contains_key("solver"));
//! # Ok::<(), smspace::embed::EmbedError>(())
//! ```

use super::{CcaParams, EmbedError, Embedding, IsomapParams, MdsParams};
use crate::registry::{Registry, RegistryError};

/// The embedding methods a run can build, by name: register one with
/// [`Registry::register_params`] (`|params: &P, _: &()| …`).
pub type EmbeddingRegistry = Registry<dyn Embedding, (), EmbedError>;

impl RegistryError for EmbedError {
    fn unknown(name: &str, known: String) -> Self {
        EmbedError::UnknownMethod {
            name: name.to_owned(),
            known,
        }
    }

    fn invalid_table(name: &str, reason: String) -> Self {
        EmbedError::InvalidTable {
            method: name.to_owned(),
            reason,
        }
    }
}

impl Registry<dyn Embedding, (), EmbedError> {
    /// The built-in methods: CCA (the paper's), Isomap and classical MDS.
    pub fn builtin() -> Self {
        let mut r = Self::empty();
        r.register_params(
            "cca",
            "Curvilinear Component Analysis, the paper's method",
            |p: &CcaParams, _: &()| Ok(Box::new(p.clone().check()?)),
        );
        r.register_params(
            "isomap",
            "Isomap: classical MDS of the geodesic distances of a kNN graph",
            |p: &IsomapParams, _: &()| Ok(Box::new(p.clone().check()?)),
        );
        r.register_params(
            "mds",
            "classical (Torgerson) MDS",
            |p: &MdsParams, _: &()| Ok(Box::new(p.clone().check()?)),
        );
        r
    }
}
