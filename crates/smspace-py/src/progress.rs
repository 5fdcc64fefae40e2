//! Progress of a long computation, reported to an optional Python callable
//! `progress(stage: str, done: int, total: int)` (the package's `progress=` argument;
//! `progress=True` passes a `tqdm` bar's updater when `tqdm` is installed).
//!
//! The computation runs with the GIL released on the library's threads; the callable
//! is called with the GIL taken, at most every [`INTERVAL`] and at the start and end of
//! each stage, by one thread at a time. An exception it raises is kept and raised when
//! the computation ends. After Ctrl-C, the next report unwinds the computation
//! ([`crate::host::run_interruptible`]): reports come at least once per set, row block
//! or epoch, so an interrupted computation ends within a fraction of a second.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use pyo3::prelude::*;
use smspace::progress::Progress;

use crate::host::{Interrupt, Turnstile};

/// The shortest time between two calls of the callable.
const INTERVAL: Duration = Duration::from_millis(100);

/// A [`Progress`] that calls a Python callable (or nothing).
pub(crate) struct PyProgress {
    callback: Option<Py<PyAny>>,
    stage: Mutex<String>,
    total: AtomicU64,
    done: AtomicU64,
    last_call: Mutex<Instant>,
    error: Mutex<Option<PyErr>>,
    /// Admits one call of the callable at a time.
    turnstile: Turnstile,
    /// The computation's stop flag.
    interrupt: Interrupt,
}

impl PyProgress {
    /// Reports to `callback` (`None`: silent).
    pub(crate) fn new(callback: Option<Py<PyAny>>) -> Self {
        Self {
            callback,
            stage: Mutex::new(String::new()),
            total: AtomicU64::new(0),
            done: AtomicU64::new(0),
            last_call: Mutex::new(Instant::now()),
            error: Mutex::new(None),
            turnstile: Turnstile::default(),
            interrupt: Interrupt::new(),
        }
    }

    /// The computation's stop flag (raised on Ctrl-C).
    pub(crate) fn interrupt(&self) -> Interrupt {
        self.interrupt.clone()
    }

    /// Unwinds the computation when its stop flag is raised (never while unwinding).
    fn stop_if_interrupted(&self) {
        if !std::thread::panicking() {
            self.interrupt.stop_if_raised();
        }
    }

    /// Calls the callable with the current counts.
    fn call(&self) {
        let Some(callback) = &self.callback else {
            return;
        };
        let stage = self.stage.lock().map(|s| s.clone()).unwrap_or_default();
        let (done, total) = (
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        );
        if self.error.lock().map_or(true, |e| e.is_some()) {
            return;
        }
        // No lock is held while the GIL is taken.
        let called = crate::host::attach(|py| {
            self.turnstile
                .call(py, || callback.call1(py, (stage, done.min(total), total)))
        });
        if let Err(e) = called {
            if crate::host::attach(|py| crate::host::asks_to_stop(py, &e)) {
                crate::host::stop_with(e);
            }
            if let Ok(mut error) = self.error.lock() {
                error.get_or_insert(e);
            }
        }
    }

    /// The exception the callable raised, if any.
    pub(crate) fn check(&self) -> PyResult<()> {
        match self.error.lock().ok().and_then(|mut e| e.take()) {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

impl Progress for PyProgress {
    fn start(&self, stage: &str, total: u64) {
        self.stop_if_interrupted();
        if let Ok(mut s) = self.stage.lock() {
            *s = stage.to_owned();
        }
        self.total.store(total, Ordering::Relaxed);
        self.done.store(0, Ordering::Relaxed);
        self.call();
    }

    fn advance(&self, done: u64) {
        self.stop_if_interrupted();
        self.done.fetch_add(done, Ordering::Relaxed);
        if self.callback.is_none() {
            return;
        }
        let due = match self.last_call.try_lock() {
            Ok(mut last) if last.elapsed() >= INTERVAL => {
                *last = Instant::now();
                true
            }
            _ => false,
        };
        if due {
            self.call();
        }
    }

    fn finish(&self) {
        self.stop_if_interrupted();
        self.done
            .store(self.total.load(Ordering::Relaxed), Ordering::Relaxed);
        self.call();
    }
}
