//! Set metrics by name: the `metric` key of a `[metric]` table picks an entry of a
//! [`MetricRegistry`] (the crate's one [`Registry`] type), which builds the metric from
//! its own parameters (`[metric.params]`) and a [`MetricContext`]: the table's period,
//! and the shape of the kernels when the caller knows it.
//!
//! The built-in metrics register here, one line each ([`MetricRegistry::builtin`]); an
//! embedder registers its own the same way and hands the registry to the pipeline
//! (`smspace_pipeline::check_with`, with the agents in a `smspace_pipeline::Registries`): a new set
//! metric is one file (a [`SetMetric`] and, if it has parameters, a serde struct) plus
//! one registration line. A metric's parameters are a serde struct with
//! `#[serde(deny_unknown_fields, default)]`: unknown keys are errors that name the key,
//! and the resolved table (defaults included) is what the run records.
//!
//! ```
//! use ndarray::ArrayView2;
//! use smspace::metric::{DistanceParams, MetricContext, MetricError, MetricRegistry, SetMetric};
//!
//! /// The distance between the sets' centroids, scaled.
//! struct Centroids { scale: f64 }
//! impl SetMetric for Centroids {
//!     fn name(&self) -> &str { "centroids" }
//!     fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
//!         let (ca, cb) = (a.mean_axis(ndarray::Axis(0)).unwrap(), b.mean_axis(ndarray::Axis(0)).unwrap());
//!         Ok(self.scale * (&ca - &cb).mapv(|x| x * x).sum().sqrt())
//!     }
//! }
//! /// Its `[metric.params]` table.
//! #[derive(serde::Serialize, serde::Deserialize)]
//! #[serde(deny_unknown_fields, default)]
//! struct CentroidParams { scale: f64 }
//! impl Default for CentroidParams { fn default() -> Self { Self { scale: 1.0 } } }
//!
//! let mut registry = MetricRegistry::builtin();
//! registry.register_params("centroids", "distance between the centroids", |p: &CentroidParams, _: &MetricContext| {
//!     Ok(Box::new(Centroids { scale: p.scale }))
//! });
//! let params: DistanceParams = toml::from_str("metric = \"centroids\"\n[params]\nscale = 2.0").unwrap();
//! let built = registry.build(&params)?;
//! assert_eq!(built.metric.name(), "centroids");
//! assert!(registry.names().any(|n| n == "curve"));
//! # Ok::<(), MetricError>(())
//! ```

use std::sync::Arc;

use super::{
    Closure, DistanceParams, KernelShape, MetricError, MetricKind, Periodicity, SetMetric,
};
use crate::registry::{Builder, Registry, RegistryError};

/// A metric built from its `[metric]` table, with the table resolved (defaults of its
/// parameters included).
#[derive(Clone)]
pub struct BuiltMetric {
    /// The metric.
    pub metric: Arc<dyn SetMetric>,
    /// Its `[metric]` table with every parameter, defaults included.
    pub params: DistanceParams,
}

impl std::fmt::Debug for BuiltMetric {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BuiltMetric")
            .field("metric", &self.metric.name())
            .field("params", &self.params)
            .finish()
    }
}

/// What a metric's builder knows besides its parameters.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MetricContext {
    /// The point metric's period (`[metric] period`).
    pub period: Periodicity,
    /// The shape of the kernels it will measure, when the caller knows it (a run knows
    /// it from the agent, `smspace distances` from the trace report beside the sets).
    pub kernels: Option<KernelShape>,
}

/// Builds a metric of one name from its parameter table (`[metric.params]`) and the
/// [`MetricContext`]; returns the metric and the resolved parameters.
pub type MetricBuilder = Builder<dyn SetMetric, MetricContext, MetricError>;

/// The set metrics a run can build, by name: register one with
/// [`Registry::register_params`] (`|params: &P, context: &MetricContext| …`).
pub type MetricRegistry = Registry<dyn SetMetric, MetricContext, MetricError>;

impl RegistryError for MetricError {
    fn unknown(name: &str, known: String) -> Self {
        MetricError::UnknownMetric {
            name: name.to_owned(),
            known,
        }
    }

    fn invalid_table(name: &str, reason: String) -> Self {
        MetricError::InvalidTable {
            metric: name.to_owned(),
            reason,
        }
    }
}

/// The parameters of a metric that has none: an empty table.
#[derive(Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

impl Registry<dyn SetMetric, MetricContext, MetricError> {
    /// The built-in metrics: the three that run on the SIMD kernels ([`MetricKind`])
    /// and `surface`.
    pub fn builtin() -> Self {
        let mut r = Self::empty();
        for (kind, summary) in [
            (
                MetricKind::Hausdorff,
                "paper section 3.2: the Hausdorff distance between the sampled points",
            ),
            (
                MetricKind::MeanHausdorff,
                "the mean of the two mean directed distances between the sampled points",
            ),
            (
                MetricKind::Curve,
                "the Hausdorff distance between the sets read as closed or open polylines",
            ),
        ] {
            r.register_params(kind.name(), summary, move |_: &NoParams, context| {
                Ok(kind.with_period(&context.period, Closure::Closed))
            });
        }
        r.register(
            "surface",
            "the Hausdorff distance from the samples of one set to the tangent disks of the other's (kernels of dimension k >= 2)",
            super::surface::default_table(),
            super::surface::builder(),
        );
        r
    }

    /// Builds the metric a `[metric]` table names.
    pub fn build(&self, params: &DistanceParams) -> Result<BuiltMetric, MetricError> {
        self.build_for(params, None)
    }

    /// Builds the metric a `[metric]` table names, for kernels of the shape `kernels`
    /// when the caller knows it (a parameter the table leaves out may follow it, as
    /// the surface metric's `dimension`).
    pub fn build_for(
        &self,
        params: &DistanceParams,
        kernels: Option<KernelShape>,
    ) -> Result<BuiltMetric, MetricError> {
        let context = MetricContext {
            period: params.period.clone(),
            kernels,
        };
        let (metric, resolved) = self.make(params.metric.as_str(), &params.params, &context)?;
        Ok(BuiltMetric {
            metric: Arc::from(metric),
            params: DistanceParams {
                params: resolved,
                ..params.clone()
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metric::Period;

    #[test]
    fn the_builtin_metrics_run_on_their_kernels() {
        let registry = MetricRegistry::builtin();
        for kind in MetricKind::ALL {
            let params = DistanceParams::new().metric(kind).period(Period::None);
            let built = registry.build(&params).unwrap();
            assert_eq!(built.metric.name(), kind.name());
            let spec = built.metric.kernel().unwrap();
            assert_eq!((spec.kind, spec.period), (kind, Period::None.into()));
            assert_eq!(built.params, params);
        }
    }

    #[test]
    fn unknown_names_and_keys_are_errors_that_name_them() {
        let registry = MetricRegistry::builtin();
        let err = registry
            .build(&DistanceParams::new().metric("curv"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("'curv'") && err.contains("curve, hausdorff, mean-hausdorff, surface"),
            "{err}"
        );
        let mut params = DistanceParams::new();
        params.params.insert("scale".into(), 2.into());
        let err = registry.build(&params).unwrap_err().to_string();
        assert!(err.contains("curve") && err.contains("scale"), "{err}");
    }
}
