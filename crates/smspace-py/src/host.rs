//! Where the engine runs when it is called from Python, and how it meets the user's
//! callables there.
//!
//! - **One call at a time.** A user's callable (a `sense` that drives a simulator with
//!   one state, a progress function) is called by one thread at a time unless the user
//!   declared it thread-safe: a [`Turnstile`] admits one caller, and a caller waits for
//!   its turn with the interpreter lock released (so the one inside may release it too,
//!   as a simulator's step does, without letting a second call in).
//! - **Threads that keep their interpreter state.** The engine's work runs on a pool of
//!   threads ([`pool`]) that live as long as the process, each of which holds one
//!   interpreter thread state for its whole life ([`host_thread`]); a gathered trace's
//!   rounds run on them too (a Python agent's `host_threads`). A callable's
//!   `threading.local()` (a simulator's data per thread) lasts from one call and one
//!   computation to the next on the same thread, and is never freed while a thread
//!   state is released.
//! - **Ctrl-C.** [`run_interruptible`] runs a computation on that pool while the
//!   calling thread waits with the lock released and checks for signals every
//!   [`POLL`]. On a signal (`KeyboardInterrupt`) it raises [`Interrupt`]s: every later
//!   progress report and callable call of the computation unwinds it instead of
//!   running, so that its threads end at their next report or call; the caller waits
//!   up to [`GRACE`] for them and raises the exception. A computation blocked inside a
//!   user's callable (a `sense` that sleeps or waits for a device) cannot be stopped
//!   from outside: it is abandoned, its result discarded, and it ends when the
//!   callable returns. The engine's threads enter the interpreter only through a gate
//!   ([`attach`]) that `atexit` closes ([`_shutdown_engine`]), waiting for any thread
//!   still inside a callable, as the interpreter waits for its own threads: an engine
//!   thread never meets a finalising interpreter; a run retried at once waits for the abandoned one to release its
//!   folder ([`wait_for_abandoned`]). Outputs are written by renaming complete
//!   temporary files, so an interrupted computation leaves no half-written file.
//! - **A callable that asks to stop.** A callable that raises an exception that is
//!   not an `Exception` (`KeyboardInterrupt`, `SystemExit`) ends the computation at
//!   once ([`stop_with`]), and the call raises that exception as it is.

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
const _: () = assert!(POOL_STACK_BYTES >= smspace::kernel::HOST_STACK_BYTES);

/// The payload with which an interrupted computation unwinds (never a panic message:
/// it is raised by [`resume_unwind`], which does not call the panic hook).
#[derive(Debug)]
pub(crate) struct Interrupted;

/// Whether `error`, raised by a user's callable, asks the program to stop rather than
/// reports a failure: an exception that is not an `Exception` (`KeyboardInterrupt`,
/// `SystemExit`).
pub(crate) fn asks_to_stop(py: Python<'_>, error: &PyErr) -> bool {
    !error.is_instance_of::<pyo3::exceptions::PyException>(py)
}

/// The exception with which a callable asked to stop, kept for the call to raise.
static STOPPING: Mutex<Option<PyErr>> = Mutex::new(None);

/// Raised with [`STOPPING`]: every callable of every computation unwinds at its next
/// call ([`Interrupt::stop_if_raised`]), as after Ctrl-C.
static STOP: AtomicBool = AtomicBool::new(false);

/// Ends the computation at once: keeps `error` (the first of them) for the call to
/// raise as it is ([`run_interruptible`]), and stops every callable at its next call.
/// Never returns.
pub(crate) fn stop_with(error: PyErr) -> ! {
    STOPPING
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .get_or_insert(error);
    STOP.store(true, Ordering::SeqCst);
    resume_unwind(Box::new(Interrupted))
}

/// Unwinds the computation when a callable has asked to stop ([`stop_with`]), for
/// callables that have no [`Interrupt`] of their own (a metric's).
pub(crate) fn stop_if_asked() {
    if STOP.load(Ordering::SeqCst) && !std::thread::panicking() {
        resume_unwind(Box::new(Interrupted));
    }
}

/// The engine's computations from Python: how many run, and how many of them were
/// abandoned by their caller after Ctrl-C (a run retried at once waits for those).
#[derive(Debug, Default)]
struct Flights {
    running: usize,
    abandoned: usize,
}

static FLIGHTS: (Mutex<Flights>, Condvar) = (
    Mutex::new(Flights {
        running: 0,
        abandoned: 0,
    }),
    Condvar::new(),
);

/// One computation in flight; counted out when dropped (when it ends, however).
struct InFlight(Arc<AtomicBool>);

impl InFlight {
    fn enter() -> Self {
        FLIGHTS
            .0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .running += 1;
        Self(Arc::default())
    }

    /// A handle with which the caller marks the computation abandoned.
    fn abandon_handle(&self) -> Arc<AtomicBool> {
        self.0.clone()
    }

    /// Marks the computation of `handle` abandoned (unless it has ended).
    fn abandon(handle: &AtomicBool) {
        let mut flights = FLIGHTS.0.lock().unwrap_or_else(PoisonError::into_inner);
        if !handle.swap(true, Ordering::SeqCst) {
            flights.abandoned += 1;
        }
    }

    /// Whether no abandoned computation runs after waiting up to `timeout`.
    fn wait_abandoned(timeout: Duration) -> bool {
        let flights = FLIGHTS.0.lock().unwrap_or_else(PoisonError::into_inner);
        let (flights, _) = FLIGHTS
            .1
            .wait_timeout_while(flights, timeout, |f| f.abandoned > 0)
            .unwrap_or_else(PoisonError::into_inner);
        flights.abandoned == 0
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        let mut flights = FLIGHTS.0.lock().unwrap_or_else(PoisonError::into_inner);
        flights.running = flights.running.saturating_sub(1);
        // Marked ended under the lock, so that a late abandon counts nothing.
        if self.0.swap(true, Ordering::SeqCst) {
            flights.abandoned = flights.abandoned.saturating_sub(1);
        }
        FLIGHTS.1.notify_all();
    }
}

/// The gate through which the engine's threads enter the interpreter ([`attach`]):
/// whether the interpreter is shutting down, and how many threads are inside it.
static GATE: (Mutex<Gate>, Condvar) = (
    Mutex::new(Gate {
        closed: false,
        inside: 0,
    }),
    Condvar::new(),
);

#[derive(Debug)]
struct Gate {
    closed: bool,
    inside: usize,
}

/// The thread inside the interpreter through the gate; leaves it when dropped.
struct Inside;

impl Drop for Inside {
    fn drop(&mut self) {
        let mut gate = GATE.0.lock().unwrap_or_else(PoisonError::into_inner);
        gate.inside = gate.inside.saturating_sub(1);
        GATE.1.notify_all();
    }
}

/// Runs `f` with the interpreter lock, on one of the engine's threads: every call of a
/// user's callable (and every other use of the interpreter) from the engine's threads
/// goes through here. Once the interpreter is shutting down ([`_shutdown_engine`]) it
/// unwinds the computation instead, so that no engine thread enters a finalising
/// interpreter.
pub(crate) fn attach<R>(f: impl FnOnce(Python<'_>) -> R) -> R {
    {
        let mut gate = GATE.0.lock().unwrap_or_else(PoisonError::into_inner);
        if gate.closed {
            drop(gate);
            resume_unwind(Box::new(Interrupted));
        }
        gate.inside += 1;
    }
    let _inside = Inside;
    Python::attach(f)
}

/// `_shutdown_engine()`, registered with `atexit` when the package is imported: closes
/// the gate of [`attach`] (every later callable call of a computation still running
/// unwinds it instead) and waits, with the interpreter lock released, until no engine
/// thread is inside the interpreter (one left inside a busy callable after Ctrl-C
/// returns from it), so that the interpreter never shuts down under an engine thread
/// running Python; computations that call no Python are not waited for. It says so on
/// standard error when it waits; a signal while it waits (Ctrl-C again) ends the wait.
#[pyfunction]
pub(crate) fn _shutdown_engine(py: Python<'_>) -> PyResult<()> {
    let quiet = |timeout| {
        py.detach(|| {
            let mut gate = GATE.0.lock().unwrap_or_else(PoisonError::into_inner);
            gate.closed = true;
            let (gate, _) = GATE
                .1
                .wait_timeout_while(gate, timeout, |g| g.inside > 0)
                .unwrap_or_else(PoisonError::into_inner);
            gate.inside == 0
        })
    };
    if quiet(GRACE) {
        return Ok(());
    }
    let stderr = py.import("sys")?.getattr("stderr")?;
    stderr.call_method1(
        "write",
        ("smspace: waiting for a computation interrupted inside a Python callable to return before the interpreter exits (Ctrl-C again to exit without waiting)\n",),
    )?;
    while !quiet(POLL) {
        py.check_signals()?;
    }
    Ok(())
}

/// Waits up to `timeout`, with the interpreter lock released, for the computations
/// abandoned after Ctrl-C to end (at their next callable call or report): a run
/// retried at once after an interrupted one finds its folder's lock released.
pub(crate) fn wait_for_abandoned(py: Python<'_>, timeout: Duration) -> PyResult<()> {
    let deadline = std::time::Instant::now() + timeout;
    while !py.detach(|| InFlight::wait_abandoned(POLL)) {
        py.check_signals()?;
        if std::time::Instant::now() >= deadline {
            break;
        }
    }
    Ok(())
}

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

    /// Whether the flag is raised, or a callable asked to stop ([`stop_with`]).
    pub(crate) fn raised(&self) -> bool {
        self.0.load(Ordering::SeqCst) || STOP.load(Ordering::SeqCst)
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
fn host_thread(work: &mut (dyn FnMut() + Send)) {
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
/// the computation to end (at its next progress report or callable call), and is
/// returned; a computation that has not ended by then (it is blocked inside a user's
/// callable), or a second signal, abandons it: it ends when that callable returns, and
/// the interpreter waits for it at exit ([`_shutdown_engine`]).
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
    // A new computation from Python: a stop asked of an earlier one is over.
    STOP.store(false, Ordering::SeqCst);
    STOPPING
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .take();
    let (sender, receiver) = mpsc::channel::<Result<T, Box<dyn Any + Send>>>();
    let flight = InFlight::enter();
    let abandon = flight.abandon_handle();
    pool.spawn(move || {
        let _flight = flight;
        let _ = sender.send(catch_unwind(AssertUnwindSafe(work)));
    });
    // Only this thread receives; the lock makes the receiver shareable with `detach`.
    let receiver = Mutex::new(receiver);
    let wait = || {
        py.detach(|| {
            receiver
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .recv_timeout(POLL)
        })
    };
    let mut signal: Option<(PyErr, std::time::Instant)> = None;
    loop {
        let ended = match wait() {
            Ok(Ok(value)) => Ok(value),
            Ok(Err(payload)) => Err(unwound(payload)),
            Err(RecvTimeoutError::Disconnected) => Err(PyRuntimeError::new_err(
                "the engine's computation ended without a result",
            )),
            Err(RecvTimeoutError::Timeout) => {
                let again = py.check_signals().err();
                match (signal.take(), again) {
                    (None, Some(raised)) => {
                        interrupts.iter().for_each(Interrupt::raise);
                        signal = Some((raised, std::time::Instant::now()));
                    }
                    (Some((first, _)), Some(_)) => {
                        InFlight::abandon(&abandon);
                        return Err(first);
                    }
                    (Some((first, since)), None) if since.elapsed() >= GRACE => {
                        InFlight::abandon(&abandon);
                        return Err(first);
                    }
                    (waiting, None) => signal = waiting,
                }
                continue;
            }
        };
        return match signal {
            Some((signal, _)) => Err(signal),
            None => ended,
        };
    }
}

/// The exception for a computation that unwound: an interrupt's (the exception a
/// callable raised to stop it, or `KeyboardInterrupt`), or a bug's panic, raised
/// again.
fn unwound(payload: Box<dyn Any + Send>) -> PyErr {
    if payload.is::<Interrupted>() {
        let asked = STOPPING
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        return asked.unwrap_or_else(|| {
            pyo3::exceptions::PyKeyboardInterrupt::new_err("the computation was interrupted")
        });
    }
    resume_unwind(payload)
}
