//! Set metrics written in Python: `smspace.register_metric(name, distance)` adds a
//! callable `distance(a, b, **params) -> float` (`a`, `b`: the points `(P, N)` of two
//! sets) to the metrics every function of the package builds by name
//! (`smspace.distances`, `knn`, the tiles, and `smspace.run`'s `[metric] metric`, its
//! `[metric.params]` passed as keyword arguments). The engine calls it once per pair,
//! one call at a time unless it is declared thread-safe (as a `PythonAgent`'s
//! callables).
//!
//! **The period.** The callable receives the points as they were traced, never
//! wrapped. A callable that takes a `period` keyword argument (or `**params`) is given
//! the motors' periods, a float64 array `(N,)` (`inf` for a motor that is not
//! periodic), to wrap its differences with; a periodic `period` is refused for one
//! that does not take it, so that a metric never silently ignores the period.
//!
//! **The run cache.** A run reuses its distances only when they are the same
//! computation: the callable's identity (the package hashes a plain function's code,
//! defaults and closure; a `version` given at registration replaces it) is part of the
//! resolved `[metric.params]` table ([`IDENTITY_KEY`]), and so of the stage's key.

use std::sync::{Arc, LazyLock, PoisonError, RwLock};

use ndarray::ArrayView2;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use smspace::metric::{
    CoordinatePeriods, MetricContext, MetricError, MetricRegistry, Period, Periodicity, SetMetric,
};

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

/// The key of the resolved `[metric.params]` table that names the callable's identity
/// (never passed to the callable).
pub(crate) const IDENTITY_KEY: &str = "callable_identity";

/// A metric whose distance is a Python callable.
struct PythonMetric {
    name: String,
    distance: Arc<Py<PyAny>>,
    /// `[metric.params]`, as keyword arguments.
    params: Py<PyDict>,
    /// The period passed as the `period` keyword argument, when the callable takes it.
    period: Option<Periodicity>,
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
        let params = self.params.bind(py);
        let params = match &self.period {
            None => params.clone(),
            Some(period) => {
                let with_period = params.copy().map_err(|e| self.failed(e.to_string()))?;
                let periods = self.periods(period, a.ncols())?.into_pyarray(py);
                with_period
                    .set_item("period", periods)
                    .map_err(|e| self.failed(e.to_string()))?;
                with_period
            }
        };
        let value = self.distance.call(py, args, Some(&params)).map_err(|e| {
            if crate::host::asks_to_stop(py, &e) {
                // KeyboardInterrupt, SystemExit: the call raises it as it is.
                crate::host::stop_with(e);
            }
            self.failed(format!("its callable raised {}", e.value(py)))
        })?;
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

impl PythonMetric {
    /// Each of the `dims` coordinates' period (`inf`: not periodic).
    fn periods(&self, period: &Periodicity, dims: usize) -> Result<Vec<f64>, MetricError> {
        let periods = period
            .for_dims(dims)
            .map_err(|e| self.failed(e.to_string()))?;
        Ok((0..dims).map(|n| periods.radians(n)).collect())
    }
}

/// Whether `period` wraps any coordinate.
fn is_periodic(period: &Periodicity) -> bool {
    !matches!(period.as_uniform(), Some(Period::None))
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
        crate::host::stop_if_asked();
        crate::host::attach(|py| {
            if self.thread_safe {
                self.call(py, a, b)
            } else {
                self.turnstile.call(py, || {
                    // A call may have waited for its turn while another asked to stop.
                    crate::host::stop_if_asked();
                    self.call(py, a, b)
                })
            }
        })
    }

    fn is_metric(&self) -> bool {
        self.is_metric
    }
}

/// `register_metric(name, distance, *, summary, is_metric, thread_safe, takes_period,
/// identity)`: `takes_period` whether the callable takes a `period` keyword argument,
/// `identity` what tells this callable from another registered under the same name
/// (the package's hash of its code, or the user's version).
#[pyfunction]
#[pyo3(signature = (name, distance, *, summary="a metric written in Python", is_metric=false, thread_safe=false, takes_period=false, identity=String::new()))]
#[allow(clippy::too_many_arguments)] // the Python function's keyword arguments
fn register_metric(
    py: Python<'_>,
    name: &str,
    distance: Py<PyAny>,
    summary: &str,
    is_metric: bool,
    thread_safe: bool,
    takes_period: bool,
    identity: String,
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
    let build = move |table: &toml::Table, context: &MetricContext| {
        let invalid = |reason: String| MetricError::InvalidTable {
            metric: entry.clone(),
            reason,
        };
        if table.contains_key("period") {
            return Err(invalid(
                "`period` is not a parameter of a metric: give it as the metric's period ([metric] period, or period=...), and the callable receives it as its `period` keyword argument".to_owned(),
            ));
        }
        if !takes_period && is_periodic(&context.period) {
            return Err(invalid(format!(
                "its callable receives the points as traced, not wrapped, and takes no `period` keyword argument, so the period {} would be ignored; add a `period` argument to the callable (each motor's period, inf where none) and wrap the differences with it, or give the period \"none\"",
                context.period
            )));
        }
        let mut kwargs = table.clone();
        kwargs.remove(IDENTITY_KEY);
        let params = crate::host::attach(|py| -> PyResult<Py<PyDict>> {
            let json = serde_json::to_string(&kwargs).map_err(|e| value_error(e.to_string()))?;
            let loads = py.import("json")?.getattr("loads")?;
            Ok(loads.call1((json,))?.cast_into::<PyDict>()?.unbind())
        })
        .map_err(|e| invalid(e.to_string()))?;
        let metric = PythonMetric {
            name: entry.clone(),
            distance: distance.clone(),
            params,
            period: takes_period.then(|| context.period.clone()),
            is_metric,
            thread_safe,
            turnstile: turnstile.clone(),
        };
        // The identity keys the run cache: another callable is another computation.
        let mut resolved = kwargs;
        resolved.insert(IDENTITY_KEY.to_owned(), identity.clone().into());
        Ok((Box::new(metric) as Box<dyn SetMetric>, resolved))
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
