//! Where the engine runs when it is called from Python, and how it meets the user's
//! callables there.
//!
//! - **One call at a time.** A user's callable (a `sense` that drives a simulator with
//!   one state, a progress function) is called by one thread at a time unless the user
//!   declared it thread-safe: a [`Turnstile`] admits one caller, and a caller waits for
//!   its turn with the interpreter lock released (so the one inside may release it too,
//!   as a simulator's step does, without letting a second call in).
//! - **Threads that keep their interpreter state.** The engine's work runs on a pool of
//!   threads ([`pool`]) each of which holds one interpreter thread state for its whole
//!   life, as the threads of a gathered trace do ([`host_thread`]): a callable's
//!   `threading.local()` lasts from one call to the next on the same thread.
//! - **Ctrl-C.** [`run_interruptible`] runs a computation on that pool while the
//!   calling thread waits with the lock released and checks for signals every
//!   [`POLL`]. On a signal (`KeyboardInterrupt`) it raises [`Interrupt`]s: every later
//!   progress report and callable call of the computation unwinds it instead of
//!   running, so that its threads end at their next report or call; the caller waits
//!   up to [`GRACE`] for them and raises the exception. A computation blocked inside a
//!   user's callable (a `sense` that sleeps or waits for a device) cannot be stopped
//!   from outside: it is abandoned, its result discarded, and it ends when the
//!   callable returns. Outputs are written by renaming complete temporary files, so an
//!   interrupted computation leaves no half-written file.

use std::any::Any;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Condvar, Mutex, OnceLock, PoisonError};
use std::time::Duration;

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

/// How often a waiting caller checks for signals.
pub(crate) const POLL: Duration = Duration::from_millis(50);

/// How long an interrupted computation is given to end before it is abandoned.
pub(crate) const GRACE: Duration = Duration::from_secs(1);

/// The stack of each pool thread, bytes (reserved; touched only as used). The engine's
/// calls from Python used to run on the interpreter's main thread (8 MiB).
const POOL_STACK_BYTES: usize = 16 << 20;

/// The payload with which an interrupted computation unwinds (never a panic message:
/// it is raised by [`resume_unwind`], which does not call the panic hook).
#[derive(Debug)]
pub(crate) struct Interrupted;

/// A computation's stop flag, shared by the objects that call back into Python.
#[derive(Debug, Clone, Default)]
pub(crate) struct Interrupt(Arc<AtomicBool>);

impl Interrupt {
    /// A flag that is not raised.
    pub(crate) fn new() -> Self {
        Self::default()
    }

    /// Raises the flag.
    pub(crate) fn raise(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether the flag is raised.
    pub(crate) fn raised(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }

    /// Unwinds the computation when the flag is raised.
    pub(crate) fn stop_if_raised(&self) {
        if self.raised() {
            resume_unwind(Box::new(Interrupted));
        }
    }
}

/// Admits one caller at a time.
#[derive(Debug, Default)]
pub(crate) struct Turnstile {
    busy: Mutex<bool>,
    free: Condvar,
}

/// The turn of the caller inside; ends when dropped.
struct Turn<'a>(&'a Turnstile);

impl Drop for Turn<'_> {
    fn drop(&mut self) {
        *self.0.busy.lock().unwrap_or_else(PoisonError::into_inner) = false;
        self.0.free.notify_one();
    }
}

impl Turnstile {
    /// Runs `f` alone: waits for the turn with the interpreter lock released, so that
    /// the caller inside can take it back.
    pub(crate) fn call<T>(&self, py: Python<'_>, f: impl FnOnce() -> T) -> T {
        py.detach(|| {
            let mut busy = self.busy.lock().unwrap_or_else(PoisonError::into_inner);
            while *busy {
                busy = self.free.wait(busy).unwrap_or_else(PoisonError::into_inner);
            }
            *busy = true;
        });
        let _turn = Turn(self);
        f()
    }
}

/// Runs `work`, the whole life of a thread, with one interpreter thread state for all
/// of it (released while `work` runs; taken back by each callback without making a
/// new one).
pub(crate) fn host_thread(work: &mut (dyn FnMut() + Send)) {
    Python::attach(|py| py.detach(work));
}

/// The number of threads of the engine's pool: `RAYON_NUM_THREADS` when it is a
/// positive number within the limit of [`smspace::threads`] (the module refuses one
/// beyond it when it is imported), else the cores.
pub(crate) fn pool_threads() -> usize {
    smspace::threads::check_variable()
        .ok()
        .flatten()
        .unwrap_or_else(smspace::threads::cores)
}

/// The engine's thread pool (made at its first use), whose threads each hold one
/// interpreter thread state for their whole life.
pub(crate) fn pool() -> PyResult<&'static rayon::ThreadPool> {
    static POOL: OnceLock<Result<rayon::ThreadPool, String>> = OnceLock::new();
    POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(pool_threads())
            .thread_name(|i| format!("smspace-{i}"))
            .stack_size(POOL_STACK_BYTES)
            .spawn_handler(|thread| {
                let mut builder = std::thread::Builder::new();
                if let Some(name) = thread.name() {
                    builder = builder.name(name.to_owned());
                }
                if let Some(bytes) = thread.stack_size() {
                    builder = builder.stack_size(bytes);
                }
                let mut thread = Some(thread);
                builder.spawn(move || {
                    host_thread(&mut || {
                        if let Some(thread) = thread.take() {
                            thread.run();
                        }
                    })
                })?;
                Ok(())
            })
            .build()
            .map_err(|e| e.to_string())
    })
    .as_ref()
    .map_err(|e| PyRuntimeError::new_err(format!("cannot start the engine's threads: {e}")))
}

/// Runs `work` on the engine's pool while this thread waits with the interpreter lock
/// released, checking for signals every [`POLL`]. A signal's exception (Ctrl-C's
/// `KeyboardInterrupt`) raises every flag of `interrupts`, waits up to [`GRACE`] for
/// the computation to end, and is returned; the computation is abandoned if it has
/// not ended by then (it is blocked inside a user's callable).
pub(crate) fn run_interruptible<T: Send + 'static>(
    py: Python<'_>,
    interrupts: &[Interrupt],
    work: impl FnOnce() -> T + Send + 'static,
) -> PyResult<T> {
    // Made without the GIL: each new thread takes it once, to make its thread state.
    let pool = py.detach(pool)?;
    if pool.current_thread_index().is_some() {
        // Called from a callable the engine runs (a `sense` that calls smspace): the
        // pool's own thread does the work, as waiting on it for a free thread could
        // wait for ever.
        return catch_unwind(AssertUnwindSafe(work)).map_err(unwound);
    }
    let (sender, receiver) = mpsc::channel::<Result<T, Box<dyn Any + Send>>>();
    pool.spawn(move || {
        let _ = sender.send(catch_unwind(AssertUnwindSafe(work)));
    });
    // Only this thread receives; the lock makes the receiver shareable with `detach`.
    let receiver = Mutex::new(receiver);
    let wait = |timeout| {
        py.detach(|| {
            receiver
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .recv_timeout(timeout)
        })
    };
    loop {
        match wait(POLL) {
            Ok(Ok(value)) => return Ok(value),
            Ok(Err(payload)) => return Err(unwound(payload)),
            Err(RecvTimeoutError::Disconnected) => {
                return Err(PyRuntimeError::new_err(
                    "the engine's computation ended without a result",
                ))
            }
            Err(RecvTimeoutError::Timeout) => {}
        }
        if let Err(signal) = py.check_signals() {
            interrupts.iter().for_each(Interrupt::raise);
            let _ = wait(GRACE);
            return Err(signal);
        }
    }
}

/// The exception for a computation that unwound: an interrupt's (only after a signal,
/// which [`run_interruptible`] returns itself), or a bug's panic, raised again.
fn unwound(payload: Box<dyn Any + Send>) -> PyErr {
    if payload.is::<Interrupted>() {
        return pyo3::exceptions::PyKeyboardInterrupt::new_err("the computation was interrupted");
    }
    resume_unwind(payload)
}
