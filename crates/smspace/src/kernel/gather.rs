//! Gathered sensing ([`Calling::Gathered`]): many kernel sets traced at once, their
//! readings answered together.
//!
//! Each of `C` caller threads traces sets one after another. When a set needs readings
//! (the `2N + 1` rows of a finite-difference Jacobian, one row for a residual), its
//! thread posts the rows and waits. A *round* ends when every caller still tracing has
//! posted: the last one to post (or the last one to leave, when a caller runs out of
//! sets while the others wait) calls the agent's [`Agent::sense_batch`] once with all
//! the posted rows, in the callers' order of posting, and hands each caller its rows'
//! readings. A round is answered as soon as its last request arrives, with one call
//! in flight per rendezvous; the callers are dealt into two rendezvous, so that one's
//! call overlaps the other's stepping. A waiting caller is parked on its own flag and
//! woken alone when its readings are written.
//!
//! The readings of a row do not depend on the rows beside it (the `sense_batch`
//! contract), so every set is traced exactly as with direct calls, whatever `C` and
//! whatever the order of posting: the tracer's output is identical (tested).
//!
//! A caller that panics leaves on unwinding, so the others are never stranded; a
//! panic in the agent's call is caught, the round is answered with NaN (its sets then
//! fail), and the panic goes on in the calling thread.

use std::panic::{self, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, OnceLock, PoisonError};
use std::thread::{self, Thread};

use ndarray::{ArrayView2, ArrayViewMut2};

use crate::agent::{Agent, Environment};

/// The rendezvous of `C` callers (see the module docs).
///
/// A caller waits parked on its own flag, not on a shared lock: the round's answerer
/// writes each caller's readings into its slot and wakes that caller alone, so a round
/// of `C` callers costs `C` wake-ups and no contention.
pub(super) struct Gather<'a> {
    agent: &'a dyn Agent,
    environment: &'a Environment,
    rounds: Mutex<Rounds>,
    slots: Vec<Slot>,
    /// How many calls of the agent were made.
    calls: AtomicUsize,
}

/// Who is in the current round.
struct Rounds {
    /// Callers that have not left.
    live: usize,
    /// The callers with a posted request, in the order they posted.
    posted: Vec<usize>,
}

/// One caller's place: its request, whether it is answered, and its thread.
struct Slot {
    request: Mutex<Request>,
    answered: AtomicBool,
    thread: OnceLock<Thread>,
}

/// One caller's rows and, once its round is answered, their readings.
#[derive(Default)]
struct Request {
    motors: Vec<f64>,
    rows: usize,
    readings: Vec<f64>,
}

/// Locks `mutex`, whatever a panicking holder left (every holder leaves it consistent).
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

impl<'a> Gather<'a> {
    /// A rendezvous for `callers` callers of `agent` in `environment`: every caller
    /// counts as live from the start, and leaves when its [`Caller`] is dropped.
    pub(super) fn new(agent: &'a dyn Agent, environment: &'a Environment, callers: usize) -> Self {
        Self {
            agent,
            environment,
            rounds: Mutex::new(Rounds {
                live: callers,
                posted: Vec::with_capacity(callers),
            }),
            slots: (0..callers)
                .map(|_| Slot {
                    request: Mutex::new(Request::default()),
                    answered: AtomicBool::new(false),
                    thread: OnceLock::new(),
                })
                .collect(),
            calls: AtomicUsize::new(0),
        }
    }

    /// The handle of caller `slot` (below the `callers` given to [`Gather::new`]), to
    /// be used on the calling thread only.
    pub(super) fn caller(&self, slot: usize) -> Caller<'_, 'a> {
        // A slot serves one thread: a second handle keeps the first thread.
        let _ = self.slots[slot].thread.set(thread::current());
        Caller { gather: self, slot }
    }

    /// How many times the agent was called.
    #[cfg(test)]
    pub(super) fn calls(&self) -> usize {
        self.calls.load(Ordering::Relaxed)
    }

    /// Posts caller `slot`'s rows, waits for its round, and writes the readings.
    fn sense_batch(
        &self,
        slot: usize,
        motors: ArrayView2<'_, f64>,
        mut sensors: ArrayViewMut2<'_, f64>,
    ) {
        let place = &self.slots[slot];
        {
            let mut request = lock(&place.request);
            request.motors.clear();
            request.motors.extend(motors.iter());
            request.rows = motors.nrows();
        }
        place.answered.store(false, Ordering::Release);
        let round = {
            let mut rounds = lock(&self.rounds);
            rounds.posted.push(slot);
            (rounds.posted.len() == rounds.live).then(|| std::mem::take(&mut rounds.posted))
        };
        if let Some(posted) = round {
            self.answer(&posted);
        }
        while !place.answered.load(Ordering::Acquire) {
            thread::park();
        }
        let request = lock(&place.request);
        for (out, &v) in sensors.iter_mut().zip(&request.readings) {
            *out = v;
        }
    }

    /// Caller `slot` leaves; if the others all wait, their round is answered now.
    fn leave(&self) {
        let round = {
            let mut rounds = lock(&self.rounds);
            rounds.live -= 1;
            (!rounds.posted.is_empty() && rounds.posted.len() == rounds.live)
                .then(|| std::mem::take(&mut rounds.posted))
        };
        if let Some(posted) = round {
            self.answer(&posted);
        }
    }

    /// Answers the `posted` requests with one call of the agent and wakes their
    /// callers; a panic of the agent answers NaN, then goes on.
    fn answer(&self, posted: &[usize]) {
        let (n, k) = (self.agent.motor_dim(), self.agent.sensor_dim());
        let mut motors = Vec::new();
        for &slot in posted {
            motors.extend_from_slice(&lock(&self.slots[slot].request).motors);
        }
        let rows = motors.len() / n;
        let mut readings = vec![0.0; rows * k];
        let call = panic::catch_unwind(AssertUnwindSafe(|| {
            let motors = ArrayView2::from_shape((rows, n), &motors).expect("rows × N motors");
            let sensors =
                ArrayViewMut2::from_shape((rows, k), &mut readings).expect("rows × K readings");
            self.agent.sense_batch(self.environment, motors, sensors);
        }));
        self.calls.fetch_add(1, Ordering::Relaxed);
        if call.is_err() {
            readings.fill(f64::NAN);
        }
        let mut offset = 0;
        for &slot in posted {
            let place = &self.slots[slot];
            {
                let mut request = lock(&place.request);
                let length = request.rows * k;
                request.readings.clear();
                request
                    .readings
                    .extend_from_slice(&readings[offset..offset + length]);
                offset += length;
            }
            place.answered.store(true, Ordering::Release);
            if let Some(thread) = place.thread.get() {
                thread.unpark();
            }
        }
        if let Err(payload) = call {
            panic::resume_unwind(payload);
        }
    }
}

/// How many independent rendezvous the callers are dealt into: while one group's
/// round is in the agent's call (a Python call holds the interpreter lock, one core),
/// the other group's sets step on the other cores.
const GROUPS: usize = 2;

/// `work(caller, state, i)` for every `i` below `count`, on `callers` threads (at most
/// `count`, at least 1) dealt into [`GROUPS`] rendezvous ([`Gather`]s) of `agent` in
/// `environment`, each thread with its own `state` from `init`; the results in the
/// order of `i`. Each thread takes the next `i` when it is done with one, so the
/// threads stay busy until the last items.
pub(super) fn map_gathered<S, T: Send>(
    agent: &dyn Agent,
    environment: &Environment,
    callers: usize,
    count: usize,
    init: impl Fn() -> S + Sync,
    work: impl Fn(&Caller<'_, '_>, &mut S, usize) -> T + Sync,
) -> Vec<T> {
    let threads = callers.clamp(1, count.max(1));
    let groups = threads.min(GROUPS);
    let gathers: Vec<Gather<'_>> = (0..groups)
        .map(|g| Gather::new(agent, environment, (threads - g).div_ceil(groups)))
        .collect();
    let next = AtomicUsize::new(0);
    let mut done: Vec<(usize, T)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let (gather, next, init, work) = (&gathers[t % groups], &next, &init, &work);
                scope.spawn(move || {
                    let caller = gather.caller(t / groups);
                    let mut state = init();
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= count {
                            return done;
                        }
                        done.push((i, work(&caller, &mut state, i)));
                    }
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| {
                h.join()
                    .unwrap_or_else(|payload| panic::resume_unwind(payload))
            })
            .collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, t)| t).collect()
}

/// One caller of a [`Gather`]: its sensing goes through the rendezvous, and dropping
/// it (also on unwinding) leaves.
pub(super) struct Caller<'g, 'a> {
    gather: &'g Gather<'a>,
    slot: usize,
}

impl Caller<'_, '_> {
    /// Writes the readings of the motor rows `(B, N)` into `sensors` `(B, K)`, in this
    /// caller's next round.
    pub(super) fn sense_batch(&self, motors: ArrayView2<'_, f64>, sensors: ArrayViewMut2<'_, f64>) {
        self.gather.sense_batch(self.slot, motors, sensors);
    }
}

impl Drop for Caller<'_, '_> {
    fn drop(&mut self) {
        self.gather.leave();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    /// `s = (m1 + 2 m2, m1 m2)`, counting its calls and the largest batch.
    #[derive(Debug, Default)]
    struct Counting {
        calls: AtomicUsize,
        largest: AtomicUsize,
    }

    impl Agent for Counting {
        fn motor_dim(&self) -> usize {
            2
        }
        fn sensor_dim(&self) -> usize {
            2
        }
        fn sense(&self, _: &Environment, m: &[f64], s: &mut [f64]) {
            s[0] = m[0] + 2.0 * m[1];
            s[1] = m[0] * m[1];
        }
        fn name(&self) -> &str {
            "counting"
        }
        fn sense_batch(
            &self,
            e: &Environment,
            m: ArrayView2<'_, f64>,
            mut s: ArrayViewMut2<'_, f64>,
        ) {
            self.calls.fetch_add(1, Ordering::Relaxed);
            self.largest.fetch_max(m.nrows(), Ordering::Relaxed);
            for (row, mut out) in m.outer_iter().zip(s.outer_iter_mut()) {
                let mut v = [0.0; 2];
                self.sense(e, &[row[0], row[1]], &mut v);
                out[0] = v[0];
                out[1] = v[1];
            }
        }
    }

    #[test]
    fn every_caller_gets_its_own_rows_and_rounds_are_gathered() {
        let agent = Counting::default();
        let environment = Environment::from_lights(Vec::new());
        let callers = 6;
        let gather = Gather::new(&agent, &environment, callers);
        // Caller c makes c + 1 requests of c + 1 rows each: callers leave at different
        // rounds, so the last rounds are answered by leaving callers too.
        std::thread::scope(|scope| {
            for c in 0..callers {
                let gather = &gather;
                scope.spawn(move || {
                    let caller = gather.caller(c);
                    for round in 0..=c {
                        let rows = c + 1;
                        let motors = ndarray::Array2::from_shape_fn((rows, 2), |(i, j)| {
                            (c * 100 + round * 10 + i) as f64 + j as f64 * 0.5
                        });
                        let mut sensors = ndarray::Array2::zeros((rows, 2));
                        caller.sense_batch(motors.view(), sensors.view_mut());
                        for (m, s) in motors.outer_iter().zip(sensors.outer_iter()) {
                            assert_eq!(s[0], m[0] + 2.0 * m[1]);
                            assert_eq!(s[1], m[0] * m[1]);
                        }
                    }
                });
            }
        });
        // Round r holds every caller with more than r requests: 6 rounds, the first
        // of all 21 rows.
        assert_eq!(agent.calls.load(Ordering::Relaxed), callers);
        assert_eq!(gather.calls(), callers);
        assert_eq!(agent.largest.load(Ordering::Relaxed), 21);
    }

    #[test]
    fn a_panicking_agent_strands_no_caller() {
        #[derive(Debug)]
        struct Failing;
        impl Agent for Failing {
            fn motor_dim(&self) -> usize {
                1
            }
            fn sensor_dim(&self) -> usize {
                1
            }
            fn sense(&self, _: &Environment, _: &[f64], _: &mut [f64]) {
                panic!("the simulator crashed");
            }
            fn name(&self) -> &str {
                "failing"
            }
        }
        let environment = Environment::from_lights(Vec::new());
        let gather = Gather::new(&Failing, &environment, 3);
        let outcome = panic::catch_unwind(AssertUnwindSafe(|| {
            std::thread::scope(|scope| {
                for c in 0..3 {
                    let gather = &gather;
                    scope.spawn(move || {
                        let caller = gather.caller(c);
                        let mut s = ndarray::Array2::zeros((1, 1));
                        caller.sense_batch(ndarray::array![[1.0]].view(), s.view_mut());
                        assert!(s[[0, 0]].is_nan(), "a failed round reads NaN");
                    });
                }
            });
        }));
        assert!(outcome.is_err(), "the agent's panic goes on");
        assert_eq!(gather.calls(), 1);
    }
}
