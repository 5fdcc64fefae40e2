//! Set metrics by name: the `metric` key of a `[metric]` table picks an entry of a
//! [`MetricRegistry`], which builds the metric from the table's period and its own
//! parameters (`[metric.params]`).
//!
//! The built-in metrics register here, one line each ([`MetricRegistry::builtin`]); an
//! embedder registers its own the same way and hands the registry to the pipeline
//! (`pipeline::check_with`, with the agents in a `pipeline::Registries`): a new set
//! metric is one file (a [`SetMetric`] and, if it has parameters, a serde struct) plus
//! one registration line. A metric's parameters are a serde struct with
//! `#[serde(deny_unknown_fields, default)]`: unknown keys are errors that name the key,
//! and the resolved table (defaults included) is what the run records.
//!
//! ```
//! use ndarray::ArrayView2;
//! use smspace::metric::{DistanceParams, MetricError, MetricRegistry, Periodicity, SetMetric};
//!
//! /// The distance between the sets' centroids, scaled.
//! struct Centroids { scale: f64 }
//! impl SetMetric for Centroids {
//!     fn name(&self) -> &'static str { "centroids" }
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
//! registry.register_params("centroids", "distance between the centroids", |p: &CentroidParams, _period: &Periodicity| {
//!     Ok(Box::new(Centroids { scale: p.scale }))
//! });
//! let params: DistanceParams = toml::from_str("metric = \"centroids\"\n[params]\nscale = 2.0").unwrap();
//! let built = registry.build(&params)?;
//! assert_eq!(built.metric.name(), "centroids");
//! assert!(registry.names().any(|n| n == "curve"));
//! # Ok::<(), MetricError>(())
//! ```

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::Serialize;

use super::{Closure, DistanceParams, MetricError, MetricKind, Periodicity, SetMetric};

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

/// Builds a metric of one name from its parameter table (`[metric.params]`) and the
/// point metric's period; returns the metric and the resolved parameters.
pub type MetricBuilder = Arc<
    dyn Fn(&toml::Table, &Periodicity) -> Result<(Box<dyn SetMetric>, toml::Table), MetricError>
        + Send
        + Sync,
>;

#[derive(Clone)]
struct Entry {
    summary: String,
    build: MetricBuilder,
}

/// The set metrics a run can build, by name.
#[derive(Clone, Default)]
pub struct MetricRegistry {
    metrics: BTreeMap<String, Entry>,
}

impl std::fmt::Debug for MetricRegistry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.metrics.keys()).finish()
    }
}

/// The parameters of a metric that has none: an empty table.
#[derive(Debug, Default, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

impl MetricRegistry {
    /// A registry without any metric.
    pub fn empty() -> Self {
        Self::default()
    }

    /// The built-in metrics ([`MetricKind`]), which run on the SIMD kernels.
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
            r.register_params(kind.name(), summary, move |_: &NoParams, period| {
                Ok(kind.with_period(period, Closure::Closed))
            });
        }
        r.register_params(
            "surface",
            "the Hausdorff distance from the samples of one set to the tangent disks of the other's (kernels of dimension k >= 2)",
            |params: &super::SurfaceParams, period| {
                Ok(Box::new(super::Surface::new(params.clone(), period.clone())?))
            },
        );
        r
    }

    /// Registers (or replaces) the metric `name` with a builder of its own.
    pub fn register(
        &mut self,
        name: impl Into<String>,
        summary: impl Into<String>,
        build: MetricBuilder,
    ) {
        self.metrics.insert(
            name.into(),
            Entry {
                summary: summary.into(),
                build,
            },
        );
    }

    /// Registers the metric `name` whose parameters are the serde struct `P` (with
    /// `#[serde(deny_unknown_fields, default)]`), built by `new` from them and the
    /// point metric's period (`[metric] period`).
    pub fn register_params<P, F>(&mut self, name: &str, summary: &str, new: F)
    where
        P: DeserializeOwned + Serialize + 'static,
        F: Fn(&P, &Periodicity) -> Result<Box<dyn SetMetric>, MetricError> + Send + Sync + 'static,
    {
        let metric = name.to_owned();
        let build = move |table: &toml::Table, period: &Periodicity| {
            let params: P =
                toml::Value::Table(table.clone())
                    .try_into()
                    .map_err(|e: toml::de::Error| MetricError::InvalidTable {
                        metric: metric.clone(),
                        reason: e.to_string().trim_end().to_owned(),
                    })?;
            let built = new(&params, period)?;
            let resolved = match toml::Value::try_from(&params) {
                Ok(toml::Value::Table(t)) => t,
                _ => table.clone(),
            };
            Ok((built, resolved))
        };
        self.register(name, summary, Arc::new(build));
    }

    /// The registered names, in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.metrics.keys().map(String::as_str)
    }

    /// One line on a metric, if registered.
    pub fn summary(&self, name: &str) -> Option<&str> {
        self.metrics.get(name).map(|e| e.summary.as_str())
    }

    /// Builds the metric a `[metric]` table names.
    pub fn build(&self, params: &DistanceParams) -> Result<BuiltMetric, MetricError> {
        let entry =
            self.metrics
                .get(params.metric.as_str())
                .ok_or_else(|| MetricError::UnknownMetric {
                    name: params.metric.to_string(),
                    known: self.names().collect::<Vec<_>>().join(", "),
                })?;
        let (metric, resolved) = (entry.build)(&params.params, &params.period)?;
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
        assert!(err.contains("hausdorff") && err.contains("scale"), "{err}");
    }
}
