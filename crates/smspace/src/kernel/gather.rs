//! Gathered sensing ([`Calling::Gathered`](crate::agent::Calling::Gathered)): many
//! kernel sets traced in lockstep, their readings answered together.
//!
//! The `C` callers are dealt into [`GROUPS`] groups, one thread each. On its thread,
//! each caller is a coroutine (a stack of its own, `corosensei`) that traces sets one
//! after another. When a set needs readings (the `2N + 1` rows of a finite-difference
//! Jacobian, one row for a residual) or poses, its coroutine posts the rows and
//! suspends. A *round* ends when every coroutine of the group has posted (or run out
//! of sets): the group's thread then calls the agent's
//! [`Agent::sense_batch`](crate::agent::Agent::sense_batch) once with all the posted
//! rows (and the observer's [`Observer::pose_batch`] once with the posted poses'
//! rows), in the order of the callers, and resumes each caller with its rows'
//! answers. Switching between coroutines is a function call, not a wake-up of a
//! thread by the kernel; while one group's call runs (a Python call holds the
//! interpreter lock, one core), the other group's sets step on the other core.
//!
//! Every call of the agent and the observer, and every progress report, is made on
//! the group's own thread stack, never on a coroutine's: an interpreter that checks
//! its stack depth sees an ordinary thread. The groups run on the agent's
//! [`Agent::host_threads`] when it has them (a Python agent: the threads of its host,
//! each with one interpreter thread state for the life of the process, so that the
//! user's per-thread objects outlive every trace), else on threads started for this
//! call. On the host's threads a group holds at most [`MAX_HOSTED_SLOTS`] callers
//! (their scopes nest on the thread's stack): more callers make more groups, which
//! the host's threads run in turn.
//!
//! The readings of a row do not depend on the rows beside it (the `sense_batch`
//! contract), so every set is traced exactly as with direct calls, whatever `C` and
//! however the rows are gathered: the tracer's output is identical (tested).

use std::cell::RefCell;
use std::sync::atomic::{AtomicUsize, Ordering};

use corosensei::stack::DefaultStack;
use corosensei::{CoroutineResult, ScopedCoroutine, ScopedCoroutineRef, Yielder};
use ndarray::{ArrayView2, ArrayViewMut2};

use super::KernelError;
use crate::agent::{Agent, Environment, Observer};

/// How many groups (threads) the callers are dealt into.
pub(super) const GROUPS: usize = 2;

/// The stack of a group's thread, bytes, before the nested scopes of its coroutines.
const GROUP_STACK_BYTES: usize = 2 << 20;

/// The thread stack taken by the scope of one coroutine, bytes (a generous bound).
const SCOPE_STACK_BYTES: usize = 4 << 10;

/// The least stack of each of an agent's [`Agent::host_threads`], bytes: a group of
/// gathered callers (at most 512 on a host thread; more make more groups), with room
/// for the agent's own calls.
pub const HOST_STACK_BYTES: usize = 8 << 20;

/// The most callers of one group on an agent's host threads.
const MAX_HOSTED_SLOTS: usize = (HOST_STACK_BYTES / 2 - GROUP_STACK_BYTES) / SCOPE_STACK_BYTES;

/// The stack of each caller's coroutine, bytes (reserved, touched only as used; the
/// tracer's deepest call chain needs a few tens of kilobytes).
const COROUTINE_STACK_BYTES: usize = 1 << 20;

/// What a caller's coroutine posts to its group's thread.
enum Request {
    /// Sensor readings of these motor rows (row-major, `N` per row).
    Sense(Vec<f64>),
    /// Poses of these motor rows.
    Pose(Vec<f64>),
    /// One item is done (for the progress report); nothing to answer.
    Finished,
}

/// The answer to a request: the readings or poses, row-major.
type Answer = Vec<f64>;

/// A caller's coroutine.
type Coroutine<'c> = ScopedCoroutine<'c, Answer, Request, (), DefaultStack>;
/// A caller's coroutine within its scope.
type Running<'s> = ScopedCoroutineRef<'s, Answer, Request, (), DefaultStack>;

/// One caller: the handle through which its coroutine asks its group for readings.
pub(super) struct Caller<'y> {
    yielder: &'y Yielder<Answer, Request>,
}

impl Caller<'_> {
    /// Writes the readings of the motor rows `(B, N)` into `sensors` `(B, K)`, in this
    /// caller's next round.
    pub(super) fn sense_batch(&self, motors: ArrayView2<'_, f64>, sensors: ArrayViewMut2<'_, f64>) {
        let answer = self
            .yielder
            .suspend(Request::Sense(motors.iter().copied().collect()));
        assign(sensors, &answer);
    }

    /// Writes the observer's poses of the motor rows `(B, N)` into `poses` `(B, d)`, in
    /// this caller's next round.
    pub(super) fn pose_batch(&self, motors: ArrayView2<'_, f64>, poses: ArrayViewMut2<'_, f64>) {
        let answer = self
            .yielder
            .suspend(Request::Pose(motors.iter().copied().collect()));
        assign(poses, &answer);
    }
}

fn assign(mut out: ArrayViewMut2<'_, f64>, answer: &[f64]) {
    for (o, &v) in out.iter_mut().zip(answer) {
        *o = v;
    }
}

/// `work(caller, state, i)` for every `i` below `count`, on `callers` coroutines (at
/// most `count`, at least 1) dealt into [`GROUPS`] threads that gather their requests
/// to `agent` in `environment` (and to `observer`), each coroutine with its own
/// `state` from `init`; `done` is called after each item, on a group's thread. The
/// results come in the order of `i`. Each coroutine takes the next `i` when it is done
/// with one, so the callers stay busy until the last items.
#[allow(clippy::too_many_arguments)] // the two calls' inputs, then the work's parts
pub(super) fn map_gathered<S, T: Send>(
    agent: &dyn Agent,
    environment: &Environment,
    observer: Option<&dyn Observer>,
    callers: usize,
    count: usize,
    init: impl Fn() -> S + Sync,
    work: impl Fn(&Caller<'_>, &mut S, usize) -> T + Sync,
    done: &(dyn Fn() + Sync),
) -> Result<Vec<T>, KernelError> {
    let callers = callers.clamp(1, count.max(1));
    let next = AtomicUsize::new(0);
    let group = Group {
        agent,
        environment,
        observer,
        next: &next,
        count,
    };
    let run = |slots: usize| group.run(slots, &init, &work, done);
    let parts = match agent.host_threads() {
        Some(pool) => on_host(pool, callers, &run),
        None => on_own_threads(callers, &run)?,
    };
    let mut results = Vec::with_capacity(count);
    for part in parts {
        results.extend(part?);
    }
    results.sort_by_key(|(i, _)| *i);
    Ok(results.into_iter().map(|(_, t)| t).collect())
}

/// The callers of each group when `callers` are dealt into `groups`.
fn slots(callers: usize, groups: usize) -> impl Iterator<Item = usize> {
    (0..groups).map(move |g| (callers - g).div_ceil(groups))
}

/// Runs the groups on the agent's long-lived `pool`, [`GROUPS`] of them or more so that
/// none holds over [`MAX_HOSTED_SLOTS`] callers; the calling thread waits (or, on one
/// of the pool's threads, runs groups itself).
fn on_host<T: Send>(
    pool: &rayon::ThreadPool,
    callers: usize,
    run: &(dyn Fn(usize) -> Part<T> + Sync),
) -> Vec<Part<T>> {
    let groups = callers.min(GROUPS).max(callers.div_ceil(MAX_HOSTED_SLOTS));
    let mut parts: Vec<Option<Part<T>>> = (0..groups).map(|_| None).collect();
    pool.scope(|scope| {
        for (part, slots) in parts.iter_mut().zip(slots(callers, groups)) {
            scope.spawn(move |_| *part = Some(run(slots)));
        }
    });
    parts
        .into_iter()
        .map(|part| part.expect("a scope's tasks have run when it returns"))
        .collect()
}

/// Runs the groups on [`GROUPS`] threads started for this call.
fn on_own_threads<T: Send>(
    callers: usize,
    run: &(dyn Fn(usize) -> Part<T> + Sync),
) -> Result<Vec<Part<T>>, KernelError> {
    let groups = callers.min(GROUPS);
    std::thread::scope(|scope| {
        let handles: Vec<_> = slots(callers, groups)
            .map(|slots| {
                // The coroutines' scopes nest, a few frames each.
                let bytes = GROUP_STACK_BYTES + slots * SCOPE_STACK_BYTES;
                std::thread::Builder::new()
                    .stack_size(bytes)
                    .spawn_scoped(scope, move || run(slots))
                    .map_err(|source| KernelError::CoroutineStack { bytes, source })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                Ok(h?
                    .join()
                    .unwrap_or_else(|payload| std::panic::resume_unwind(payload)))
            })
            .collect()
    })
}

/// One group's results: its items' indices and outputs.
type Part<T> = Result<Vec<(usize, T)>, KernelError>;

/// What the groups share.
struct Group<'a> {
    agent: &'a dyn Agent,
    environment: &'a Environment,
    observer: Option<&'a dyn Observer>,
    next: &'a AtomicUsize,
    count: usize,
}

impl Group<'_> {
    /// Runs `slots` coroutines on this thread until the items are done.
    fn run<S, T>(
        &self,
        slots: usize,
        init: &(impl Fn() -> S + Sync),
        work: &(impl Fn(&Caller<'_>, &mut S, usize) -> T + Sync),
        done: &(dyn Fn() + Sync),
    ) -> Part<T> {
        let results = RefCell::new(Vec::new());
        let mut coroutines: Vec<Coroutine<'_>> = Vec::with_capacity(slots);
        for _ in 0..slots {
            let stack = DefaultStack::new(COROUTINE_STACK_BYTES).map_err(|source| {
                KernelError::CoroutineStack {
                    bytes: COROUTINE_STACK_BYTES,
                    source,
                }
            })?;
            let (results, next, count) = (&results, self.next, self.count);
            coroutines.push(ScopedCoroutine::with_stack(
                stack,
                move |yielder: &Yielder<Answer, Request>, _: Answer| {
                    let caller = Caller { yielder };
                    let mut state = init();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= count {
                            return;
                        }
                        let t = work(&caller, &mut state, i);
                        results.borrow_mut().push((i, t));
                        yielder.suspend(Request::Finished);
                    }
                },
            ));
        }
        in_scope(coroutines, Vec::new(), &mut |running| {
            self.rounds(running, done)
        });
        Ok(results.into_inner())
    }

    /// Resumes every caller with its answer until it posts again, and answers each
    /// round with one call, until every caller has returned.
    fn rounds(&self, running: &mut [Running<'_>], done: &(dyn Fn() + Sync)) {
        let mut answers: Vec<Option<Answer>> = running.iter().map(|_| Some(Vec::new())).collect();
        loop {
            let mut sense = Posted::default();
            let mut pose = Posted::default();
            for (slot, coroutine) in running.iter_mut().enumerate() {
                let Some(mut answer) = answers[slot].take() else {
                    continue;
                };
                loop {
                    match coroutine.as_mut().resume(answer) {
                        CoroutineResult::Yield(Request::Finished) => {
                            done();
                            answer = Vec::new();
                        }
                        CoroutineResult::Yield(Request::Sense(rows)) => {
                            sense.post(slot, rows);
                            break;
                        }
                        CoroutineResult::Yield(Request::Pose(rows)) => {
                            pose.post(slot, rows);
                            break;
                        }
                        CoroutineResult::Return(()) => break,
                    }
                }
            }
            if sense.slots.is_empty() && pose.slots.is_empty() {
                return;
            }
            let n = self.agent.motor_dim();
            sense.answer(n, self.agent.sensor_dim(), &mut answers, |m, s| {
                self.agent.sense_batch(self.environment, m, s)
            });
            let d = self.observer.map_or(0, |o| o.pose_space().dim());
            pose.answer(n, d, &mut answers, |m, mut p| match self.observer {
                Some(observer) => observer.pose_batch(m, p),
                None => p.fill(f64::NAN),
            });
        }
    }
}

/// The requests of one kind in a round: the callers, in order, and their rows.
#[derive(Default)]
struct Posted {
    slots: Vec<(usize, usize)>,
    rows: Vec<f64>,
}

impl Posted {
    fn post(&mut self, slot: usize, rows: Vec<f64>) {
        self.slots.push((slot, rows.len()));
        self.rows.extend_from_slice(&rows);
    }

    /// One call `f(motors (R, n), out (R, width))` for all the posted rows, each
    /// caller's part of `out` into its answer.
    fn answer(
        self,
        n: usize,
        width: usize,
        answers: &mut [Option<Answer>],
        f: impl FnOnce(ArrayView2<'_, f64>, ArrayViewMut2<'_, f64>),
    ) {
        if self.slots.is_empty() {
            return;
        }
        let rows = self.rows.len() / n;
        let mut out = vec![0.0; rows * width];
        f(
            ArrayView2::from_shape((rows, n), &self.rows).expect("rows × N motors"),
            ArrayViewMut2::from_shape((rows, width), &mut out).expect("rows × width answers"),
        );
        let mut offset = 0;
        for (slot, values) in self.slots {
            let length = values / n * width;
            answers[slot] = Some(out[offset..offset + length].to_vec());
            offset += length;
        }
    }
}

/// Enters the scope of every coroutine (one inside the other), then runs `f` on them
/// all: a scoped coroutine runs only within its scope.
fn in_scope<'c>(
    mut pending: Vec<Coroutine<'c>>,
    running: Vec<Running<'_>>,
    f: &mut dyn FnMut(&mut [Running<'_>]),
) {
    match pending.pop() {
        None => {
            let mut running = running;
            running.reverse();
            f(&mut running);
        }
        Some(coroutine) => coroutine.scope(move |entered| {
            let mut running: Vec<Running<'_>> = running;
            running.push(entered);
            in_scope(pending, running, f);
        }),
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
    fn every_item_gets_its_own_rows_and_rounds_are_gathered() {
        let agent = Counting::default();
        let environment = Environment::from_lights(Vec::new());
        let finished = AtomicUsize::new(0);
        // Item i makes i % 4 + 1 requests of i % 3 + 1 rows each.
        let requests = |i: usize| i % 4 + 1;
        let work = |caller: &Caller<'_>, calls: &mut usize, i: usize| {
            let rows = i % 3 + 1;
            for round in 0..requests(i) {
                let motors = ndarray::Array2::from_shape_fn((rows, 2), |(r, j)| {
                    (i * 100 + round * 10 + r) as f64 + j as f64 * 0.5
                });
                let mut sensors = ndarray::Array2::zeros((rows, 2));
                caller.sense_batch(motors.view(), sensors.view_mut());
                for (m, s) in motors.outer_iter().zip(sensors.outer_iter()) {
                    assert_eq!(s[0], m[0] + 2.0 * m[1]);
                    assert_eq!(s[1], m[0] * m[1]);
                }
                *calls += 1;
            }
            (i, *calls)
        };
        let done = || {
            finished.fetch_add(1, Ordering::Relaxed);
        };
        let results = map_gathered(&agent, &environment, None, 6, 30, || 0, work, &done).unwrap();
        assert_eq!(results.len(), 30);
        assert!(results.iter().enumerate().all(|(i, &(j, _))| i == j));
        assert_eq!(finished.load(Ordering::Relaxed), 30);
        let asked: usize = (0..30).map(requests).sum();
        let calls = agent.calls.load(Ordering::Relaxed);
        // Two groups of 3 callers: each round of a group answers up to 3 requests.
        assert!(
            3 * calls >= asked && 2 * calls < asked,
            "{calls} calls for {asked}"
        );
        // One caller per item: every request alone.
        let alone = Counting::default();
        map_gathered(&alone, &environment, None, 1, 30, || 0, work, &done).unwrap();
        assert_eq!(alone.calls.load(Ordering::Relaxed), asked);
        assert_eq!(alone.largest.load(Ordering::Relaxed), 3);
    }

    /// [`Counting`] on long-lived host threads, recording the threads it is called on.
    #[derive(Debug)]
    struct Hosted {
        law: Counting,
        pool: rayon::ThreadPool,
        threads: std::sync::Mutex<std::collections::BTreeSet<String>>,
    }

    impl Hosted {
        fn new(threads: usize) -> Self {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(|i| format!("host-{i}"))
                .stack_size(HOST_STACK_BYTES)
                .build()
                .unwrap();
            Self {
                law: Counting::default(),
                pool,
                threads: Default::default(),
            }
        }
    }

    impl Agent for Hosted {
        fn motor_dim(&self) -> usize {
            2
        }
        fn sensor_dim(&self) -> usize {
            2
        }
        fn sense(&self, e: &Environment, m: &[f64], s: &mut [f64]) {
            self.law.sense(e, m, s)
        }
        fn name(&self) -> &str {
            "hosted"
        }
        fn sense_batch(&self, e: &Environment, m: ArrayView2<'_, f64>, s: ArrayViewMut2<'_, f64>) {
            let name = std::thread::current()
                .name()
                .unwrap_or("unnamed")
                .to_owned();
            self.threads.lock().unwrap().insert(name);
            self.law.sense_batch(e, m, s)
        }
        fn host_threads(&self) -> Option<&rayon::ThreadPool> {
            Some(&self.pool)
        }
    }

    #[test]
    fn an_agent_with_host_threads_is_called_only_on_them() {
        let environment = Environment::from_lights(Vec::new());
        let work = |caller: &Caller<'_>, _: &mut (), i: usize| {
            let motors = ndarray::array![[i as f64, 0.5]];
            let mut sensors = ndarray::Array2::zeros((1, 2));
            caller.sense_batch(motors.view(), sensors.view_mut());
            sensors[[0, 0]]
        };
        let expected: Vec<f64> = (0..1200).map(|i| i as f64 + 1.0).collect();
        // More callers than one group holds on a host thread: more groups, in turn.
        for (threads, callers) in [(1, 3), (2, 7), (2, 1200)] {
            let agent = Hosted::new(threads);
            let results = map_gathered(
                &agent,
                &environment,
                None,
                callers,
                1200,
                || (),
                work,
                &|| {},
            )
            .unwrap();
            assert_eq!(results, expected, "{threads} threads, {callers} callers");
            let seen = agent.threads.lock().unwrap().clone();
            assert!(
                !seen.is_empty() && seen.iter().all(|t| t.starts_with("host-")),
                "called on {seen:?}"
            );
            if callers > MAX_HOSTED_SLOTS {
                let groups = callers.div_ceil(MAX_HOSTED_SLOTS);
                assert!(agent.law.calls.load(Ordering::Relaxed) >= groups);
            }
        }
    }

    #[test]
    fn a_panicking_agent_panics_the_caller() {
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
        let work = |caller: &Caller<'_>, _: &mut (), _: usize| {
            let mut s = ndarray::Array2::zeros((1, 1));
            caller.sense_batch(ndarray::array![[1.0]].view(), s.view_mut());
        };
        let outcome = std::panic::catch_unwind(|| {
            map_gathered(&Failing, &environment, None, 4, 8, || (), work, &|| {})
        });
        assert!(outcome.is_err(), "the agent's panic goes on");
    }
}
