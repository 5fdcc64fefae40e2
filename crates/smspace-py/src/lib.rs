//! `smspace._core`: the Python bindings of smspace, wrapped by the
//! `smspace` package (`python/smspace/__init__.py`, which the user imports).
//!
//! Every function here is one stage of the library on NumPy arrays: arrays come in as
//! views of any order and strides (copied only where the library needs to own them, as
//! a [`DistanceMatrix`] does), arrays go out moved into NumPy without a copy, and every
//! long computation runs with the GIL released ([`Python::detach`]). Errors of the
//! library are raised as `ValueError`, or `OSError` when a file is involved, with the
//! command-line tool's message ([`to_py_err`]). Parameters travel as the JSON of the
//! library's serde parameter structs (the same keys as the experiment's tables), so
//! an unknown or invalid key is reported as the experiment reader reports it.

mod agent;
mod host;
mod learn;
mod metric;
mod progress;
mod run;
mod stages;

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;

pub use agent::{Agent, PythonAgent};

/// The message of an error and of its sources, as the command-line tool prints it
/// (`error: outer: inner`).
pub(crate) fn message(error: &(dyn std::error::Error + 'static)) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(inner) = source {
        let line = inner.to_string();
        if !text.contains(&line) {
            text.push_str(": ");
            text.push_str(&line);
        }
        source = inner.source();
    }
    text
}

/// A library error as a Python exception: `OSError` when a file could not be read or
/// written (an [`smspace::io::IoError`], a [`std::io::Error`] or an unreadable
/// experiment file among its causes),
/// `ValueError` otherwise.
pub(crate) fn to_py_err<E: std::error::Error + 'static>(error: E) -> PyErr {
    let mut is_io = false;
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(&error);
    while let Some(e) = cause {
        let unreadable = matches!(
            e.downcast_ref::<smspace_pipeline::config::ConfigError>(),
            Some(smspace_pipeline::config::ConfigError::Read { .. })
        );
        // `smspace::Error` (and a stage's error) wraps its modules' errors transparently (its source is the
        // inner error's source), so its variants are matched as well.
        let wrapped = matches!(
            e.downcast_ref::<smspace::Error>(),
            Some(smspace::Error::Io(_))
        ) || matches!(
            e.downcast_ref::<smspace_pipeline::Error>(),
            Some(
                smspace_pipeline::Error::Core(smspace::Error::Io(_))
                    | smspace_pipeline::Error::Config(
                        smspace_pipeline::config::ConfigError::Read { .. }
                    )
            )
        );
        is_io |=
            unreadable || wrapped || e.is::<smspace::io::IoError>() || e.is::<std::io::Error>();
        cause = e.source();
    }
    let text = message(&error);
    if is_io {
        PyOSError::new_err(text)
    } else {
        PyValueError::new_err(text)
    }
}

/// A `ValueError` with `text`.
pub(crate) fn value_error(text: impl Into<String>) -> PyErr {
    PyValueError::new_err(text.into())
}

/// Reads the JSON of a parameter struct (`what` names it in the error).
pub(crate) fn from_json<T: serde::de::DeserializeOwned>(json: &str, what: &str) -> PyResult<T> {
    serde_json::from_str(json).map_err(|e| value_error(format!("invalid {what}: {e}")))
}

/// The extension module.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // The worker pool reads RAYON_NUM_THREADS when it first starts: a count beyond the
    // command line's limit is refused here, before any thread starts.
    smspace::threads::check_variable().map_err(to_py_err)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<Agent>()?;
    m.add_class::<PythonAgent>()?;
    stages::register(m)?;
    run::register(m)?;
    metric::register(m)?;
    learn::register(m)?;
    // The interpreter waits for the engine's computations (one abandoned after Ctrl-C
    // ends when the user's callable it is in returns) before it shuts down.
    m.add_function(wrap_pyfunction!(host::_shutdown_engine, m)?)?;
    let wait = m.getattr("_shutdown_engine")?;
    m.py().import("atexit")?.call_method1("register", (wait,))?;
    Ok(())
}
