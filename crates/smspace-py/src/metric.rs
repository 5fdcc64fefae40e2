//! Set metrics written in Python: `smspace.register_metric(name, distance)` adds a
//! callable `distance(a, b, **params) -> float` (`a`, `b`: the points `(P, N)` of two
//! sets) to the metrics every function of the package builds by name
//! (`smspace.distances`, `knn`, the tiles, and `smspace.run`'s `[metric] metric`, its
//! `[metric.params]` passed as keyword arguments). The engine calls it once per pair,
//! one call at a time unless it is declared thread-safe (as a `PythonAgent`'s
//! callables).

use std::sync::{Arc, LazyLock, PoisonError, RwLock};

use ndarray::ArrayView2;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use smspace::metric::{MetricContext, MetricError, MetricRegistry, SetMetric};

use crate::host::Turnstile;
use crate::value_error;

/// The metrics of this process: the built-in ones and those registered from Python.
static METRICS: LazyLock<RwLock<MetricRegistry>> =
    LazyLock::new(|| RwLock::new(MetricRegistry::builtin()));

/// The metrics every function builds by name, as registered now.
pub(crate) fn registry() -> MetricRegistry {
    METRICS
        .read()
        .unwrap_or_else(PoisonError::into_inner)
        .clone()
}

/// A metric whose distance is a Python callable.
struct PythonMetric {
    name: String,
    distance: Arc<Py<PyAny>>,
    /// `[metric.params]`, as keyword arguments.
    params: Py<PyDict>,
    is_metric: bool,
    thread_safe: bool,
    turnstile: Arc<Turnstile>,
}

impl PythonMetric {
    fn failed(&self, reason: impl Into<String>) -> MetricError {
        MetricError::Failed {
            metric: self.name.clone(),
            reason: reason.into(),
        }
    }

    /// One call, with the interpreter lock held.
    fn call(
        &self,
        py: Python<'_>,
        a: ArrayView2<'_, f64>,
        b: ArrayView2<'_, f64>,
    ) -> Result<f64, MetricError> {
        let args = (a.to_owned().into_pyarray(py), b.to_owned().into_pyarray(py));
        let value = self
            .distance
            .call(py, args, Some(self.params.bind(py)))
            .map_err(|e| self.failed(format!("its callable raised {}", e.value(py))))?;
        let value: f64 = value.extract(py).map_err(|_| {
            self.failed("its callable must return a float (the distance between the two sets)")
        })?;
        if !(value.is_finite() && value >= 0.0) {
            return Err(self.failed(format!(
                "its callable returned {value}; a distance is finite and at least 0"
            )));
        }
        Ok(value)
    }
}

impl SetMetric for PythonMetric {
    fn name(&self) -> &str {
        &self.name
    }

    fn distance(&self, a: ArrayView2<'_, f64>, b: ArrayView2<'_, f64>) -> Result<f64, MetricError> {
        if a.nrows() == 0 || b.nrows() == 0 {
            return Err(self.failed("a set has no points"));
        }
        if a.ncols() != b.ncols() {
            return Err(MetricError::DimensionMismatch {
                a: a.ncols(),
                b: b.ncols(),
            });
        }
        Python::attach(|py| {
            if self.thread_safe {
                self.call(py, a, b)
            } else {
                self.turnstile.call(py, || self.call(py, a, b))
            }
        })
    }

    fn is_metric(&self) -> bool {
        self.is_metric
    }
}

/// `register_metric(name, distance, *, summary, is_metric, thread_safe)`.
#[pyfunction]
#[pyo3(signature = (name, distance, *, summary="a metric written in Python", is_metric=false, thread_safe=false))]
fn register_metric(
    py: Python<'_>,
    name: &str,
    distance: Py<PyAny>,
    summary: &str,
    is_metric: bool,
    thread_safe: bool,
) -> PyResult<()> {
    if !distance.bind(py).is_callable() {
        return Err(value_error(format!(
            "register_metric({name:?}, ...): distance must be a callable distance(a, b, **params) -> float"
        )));
    }
    let valid = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if !valid {
        return Err(value_error(format!(
            "register_metric: {name:?} is not a metric name; use letters, digits, '-' and '_'"
        )));
    }
    if MetricRegistry::builtin().contains(name) {
        return Err(value_error(format!(
            "register_metric: {name:?} is a built-in metric; choose another name"
        )));
    }
    let (entry, distance, turnstile) = (
        name.to_owned(),
        Arc::new(distance),
        Arc::new(Turnstile::default()),
    );
    let build = move |table: &toml::Table, _: &MetricContext| {
        let params = Python::attach(|py| -> PyResult<Py<PyDict>> {
            let json = serde_json::to_string(table).map_err(|e| value_error(e.to_string()))?;
            let loads = py.import("json")?.getattr("loads")?;
            Ok(loads.call1((json,))?.cast_into::<PyDict>()?.unbind())
        })
        .map_err(|e| MetricError::InvalidTable {
            metric: entry.clone(),
            reason: e.to_string(),
        })?;
        let metric = PythonMetric {
            name: entry.clone(),
            distance: distance.clone(),
            params,
            is_metric,
            thread_safe,
            turnstile: turnstile.clone(),
        };
        Ok((Box::new(metric) as Box<dyn SetMetric>, table.clone()))
    };
    METRICS
        .write()
        .unwrap_or_else(PoisonError::into_inner)
        .register(name, summary, toml::Table::new(), Arc::new(build));
    Ok(())
}

/// The metrics registered now: `[(name, summary)]`, in name order.
#[pyfunction]
fn metrics() -> Vec<(String, String)> {
    let registry = registry();
    registry
        .names()
        .map(|n| (n.to_owned(), registry.summary(n).unwrap_or("").to_owned()))
        .collect()
}

/// Adds the functions of this file to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(register_metric, m)?)?;
    m.add_function(wrap_pyfunction!(metrics, m)?)?;
    Ok(())
}
