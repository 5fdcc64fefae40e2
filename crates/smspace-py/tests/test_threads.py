"""The engine's threads and the user's callables: per-thread state that lives from one
call to the next, callables that ask to stop (KeyboardInterrupt, SystemExit), Ctrl-C
inside a busy callable and the interpreter's exit after it, the run cache and a
re-registered metric, and the period a Python metric is given.

Each scenario that could crash the interpreter runs in a child process, so that a
crash fails its test instead of ending the test run."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

import smspace


def run_child(source: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """Runs `source` in a new interpreter; its output and exit status."""
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(source), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


# --- per-thread state ---------------------------------------------------------------

PER_THREAD = """
    import sys, threading, weakref
    import numpy as np
    import smspace

    made, freed = [], []

    class Simulator:
        '''A per-thread simulator: MuJoCo's MjData (a C++ object whose destructor
        touches the interpreter's error state) when MuJoCo is installed, else a Python
        object whose finalizer is counted.'''
        def __init__(self):
            made.append(threading.get_ident())
            try:
                import mujoco
                model = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
                self.data = mujoco.MjData(model)
            except ImportError:
                self.data = None
            weakref.finalize(self, freed.append, 1)

    local = threading.local()

    def simulator():
        if not hasattr(local, "sim"):
            local.sim = Simulator()
        return local.sim

    def sense(m):
        simulator()
        return np.stack([np.cos(m[:, 0]) + np.cos(m[:, 0] + m[:, 1]),
                         np.sin(m[:, 0]) + np.sin(m[:, 0] + m[:, 1])], axis=1)

    def pose(m):
        simulator()
        x = np.cos(m[:, 0]) + np.cos(m[:, 0] + m[:, 1])
        y = np.sin(m[:, 0]) + np.sin(m[:, 0] + m[:, 1])
        return np.stack([x, y, m[:, 0] + m[:, 1] + m[:, 2]], axis=1)

    def progress(stage, done, total):
        simulator()

    def distance(a, b):
        simulator()
        return float(np.abs(a.mean(axis=0) - b.mean(axis=0)).sum())

    smspace.register_metric("per-thread", distance)
    agent = smspace.PythonAgent(sense=sense, pose=pose, n_motors=3, n_sensors=2,
                                concurrent_sets=8, thread_safe=sys.argv[1] == "safe")
    starts = np.random.default_rng(1).uniform(-1.0, 1.0, size=(30, 3))
    for round in range(3):
        found = smspace.explore(agent, n=20, seed=round, workspace=None, progress=progress)
        sensory = smspace.trace(agent, starts, method="sensory", workspace=None,
                                points=20, progress=progress)
        kinematic = smspace.trace(agent, found.motors, method="kinematic", points=20,
                                  workspace=None, progress=progress)
        smspace.distances(kinematic.sets[:6], metric="per-thread", period="none",
                          progress=progress)
        assert len(sensory.kept) > 20, sensory.kept
    print(len(made), len(set(made)), len(freed))
"""


@pytest.mark.parametrize("safety", ["one-at-a-time", "safe"])
def test_per_thread_state_lives_from_one_call_to_the_next(safety):
    """A user's per-thread simulator (MuJoCo's MjData where MuJoCo is installed) kept
    in a threading.local: every stage that calls back (explore's poses, both tracing
    methods, progress, a Python metric), three times over, with one object per engine
    thread, never freed between calls, and no crash."""
    done = run_child(PER_THREAD, safety)
    assert done.returncode == 0, done.stderr[-3000:]
    made, threads, freed = map(int, done.stdout.split())
    assert made == threads, "a thread made its simulator twice: its thread state was lost"
    assert freed == 0, f"{freed} per-thread simulators were freed between calls"
    assert threads <= smspace_threads() + 1, f"{threads} threads called back"


def smspace_threads() -> int:
    """The engine's threads in this environment (RAYON_NUM_THREADS, else the cores)."""
    import os

    return int(os.environ.get("RAYON_NUM_THREADS") or os.cpu_count())


# --- callables that ask to stop -----------------------------------------------------


def test_a_metric_that_raises_keyboard_interrupt_raises_it_as_it_is():
    sets = np.random.default_rng(2).uniform(size=(6, 5, 2))
    calls = []

    def interrupted(a, b):
        calls.append(1)
        raise KeyboardInterrupt("stop")

    smspace.register_metric("interrupted", interrupted)
    with pytest.raises(KeyboardInterrupt, match="stop"):
        smspace.distances(sets, metric="interrupted", period="none")
    assert len(calls) <= 2, f"the metric was called {len(calls)} times after it asked to stop"


def test_an_agent_and_a_progress_callable_that_raise_keyboard_interrupt_raise_it():
    def sense(m):
        raise KeyboardInterrupt("from sense")

    agent = smspace.PythonAgent(sense=sense, n_motors=2, n_sensors=1)
    with pytest.raises(KeyboardInterrupt, match="from sense"):
        smspace.trace(agent, np.zeros((4, 2)) + 0.3, method="sensory", workspace=None)

    arm = smspace.Agent.preset("planar-arm")

    def progress(stage, done, total):
        raise SystemExit(7)

    with pytest.raises(SystemExit):
        smspace.explore(arm, n=50, progress=progress)
    # An ordinary exception is still a failure of the callable, named as such.
    with pytest.raises(smspace.CallbackError, match="raised"):
        smspace.trace(
            smspace.PythonAgent(sense=lambda m: 1 / 0, n_motors=2, n_sensors=1),
            np.zeros((2, 2)),
            method="sensory",
            workspace=None,
        )


# --- Ctrl-C inside a busy callable, then the interpreter's exit ----------------------

BUSY = """
    import os, signal, sys, threading, time
    import numpy as np
    import smspace

    kind, out, signals = sys.argv[1], sys.argv[2], int(sys.argv[3])

    def busy(seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            sum(range(1000))

    if kind == "metric":
        def distance(a, b):
            busy(2.0)
            return 1.0
        smspace.register_metric("busy", distance)
        call = lambda: smspace.distances(np.zeros((3, 4, 2)), metric="busy", period="none")
    else:
        def sense(m):
            busy(2.0)
            return np.cos(m)
        agent = smspace.PythonAgent(sense=sense, n_motors=2, n_sensors=2)
        call = lambda: smspace.trace(agent, np.zeros((3, 2)) + 0.2, method="sensory",
                                     workspace=None)

    def interrupt():
        for _ in range(signals):
            time.sleep(0.5)
            os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt, daemon=True).start()
    # A file the script writes and closes only at exit: lost if the exit aborts.
    kept = open(out, "w")
    kept.write("the user's data\\n" * 1000)
    try:
        call()
        print("finished")
    except KeyboardInterrupt:
        print("interrupted", flush=True)
"""


@pytest.mark.parametrize("kind", ["metric", "agent"])
@pytest.mark.parametrize("signals", [1, 2])
def test_the_interpreter_exits_cleanly_after_ctrl_c_inside_a_busy_callable(
    kind, signals, tmp_path
):
    """Ctrl-C (once, or twice: the computation abandoned) while a callable computes for
    2 s; the script goes on and ends normally. The interpreter waits for the engine's
    thread before it shuts down: exit 0, no fatal error, the script's file intact."""
    out = tmp_path / "kept.txt"
    done = run_child(BUSY, kind, str(out), str(signals))
    assert "Fatal Python error" not in done.stderr, done.stderr[-3000:]
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "interrupted"
    assert out.read_text() == "the user's data\n" * 1000


RETRY = """
    import os, signal, sys, threading, time
    from pathlib import Path
    import numpy as np
    import smspace

    experiment, folder = sys.argv[1], sys.argv[2]
    first = [True]

    def progress(stage, done, total):
        if first[0]:
            first[0] = False
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.5)  # inside the callable: the run is abandoned

    try:
        smspace.run(experiment, folder, progress=progress)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
    smspace.run(experiment, folder)
    print("retried")
"""


def test_a_run_retried_at_once_after_ctrl_c_finds_its_folder_free(tmp_path):
    experiment = tmp_path / "tiny.toml"
    experiment.write_text(TINY_EXPERIMENT.replace("centroid-cache", "hausdorff"))
    done = run_child(RETRY, str(experiment), str(tmp_path / "run"))
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split() == ["interrupted", "retried"]


TINY_EXPERIMENT = """
[agent]
kind = "toy-redundant"
[exploration]
n = 40
[kernel]
method = "kinematic"
points = 10
[metric]
metric = "centroid-cache"
period = "none"
[embedding]
method = "mds"
dim = 1
[analysis]
mle_neighbors = 6
[report]
formats = "svg"
sample_configurations = 2
sample_sets = 2
"""


# --- the run cache and a re-registered metric ---------------------------------------


def test_a_re_registered_metric_is_another_computation_for_the_run_cache(tmp_path):
    experiment = tmp_path / "tiny.toml"
    experiment.write_text(TINY_EXPERIMENT)
    folder = tmp_path / "run"

    def centroids(a, b):
        return float(np.linalg.norm(a.mean(axis=0) - b.mean(axis=0)))

    def doubled(a, b):
        return 2.0 * float(np.linalg.norm(a.mean(axis=0) - b.mean(axis=0)))

    smspace.register_metric("centroid-cache", centroids)
    first = smspace.run(experiment, folder).D
    smspace.register_metric("centroid-cache", doubled)
    second = smspace.run(experiment, folder).D
    assert np.allclose(second, 2.0 * first), "the distances of the earlier callable were reused"
    # The same function registered again is the same computation: reused.
    smspace.register_metric("centroid-cache", doubled)
    stamp = (folder / "D.npy").stat().st_mtime_ns
    assert np.array_equal(smspace.run(experiment, folder).D, second)
    assert (folder / "D.npy").stat().st_mtime_ns == stamp, "an unchanged metric was recomputed"
    # A version given by the user replaces the identity.
    smspace.register_metric("centroid-cache", centroids, version="v1")
    assert np.allclose(smspace.run(experiment, folder).D, first)
    resolved = (folder / "config.resolved.toml").read_text()
    assert 'callable_identity = "version:v1"' in resolved


def test_a_closure_over_another_value_is_another_computation():
    from smspace import _callable_identity

    def scaled(scale):
        return lambda a, b: scale * float(np.abs(a - b).max())

    assert _callable_identity(scaled(1.0)) == _callable_identity(scaled(1.0))
    assert _callable_identity(scaled(1.0)) != _callable_identity(scaled(2.0))

    class Metric:
        def __call__(self, a, b):
            return 0.0

    instance = Metric()
    assert _callable_identity(instance) != _callable_identity(instance)


# --- the period and a Python metric -------------------------------------------------


def test_a_python_metric_is_given_the_period_or_refuses_it():
    rng = np.random.default_rng(5)
    sets = rng.uniform(-3.0, 3.0, size=(5, 4, 2))

    def unwrapped(a, b):
        return float(np.abs(a.mean(axis=0) - b.mean(axis=0)).sum())

    smspace.register_metric("unwrapped", unwrapped)
    with pytest.raises(ValueError, match="period"):
        smspace.distances(sets, metric="unwrapped", period="2pi")
    assert smspace.distances(sets, metric="unwrapped", period="none").shape == (5, 5)

    seen = []

    def wrapped(a, b, period):
        seen.append(period.copy())
        d = a[:, None, :] - b[None, :, :]
        finite = np.isfinite(period)
        d[..., finite] = (d[..., finite] + period[finite] / 2) % period[finite] - period[finite] / 2
        return float(np.abs(d).max())

    smspace.register_metric("wrapped", wrapped)
    hinge = smspace.distances(sets, metric="wrapped", period="2pi")
    assert np.allclose(seen[-1], [2 * np.pi, 2 * np.pi])
    assert hinge.max() <= np.pi + 1e-12
    free = smspace.distances(sets, metric="wrapped", period="none")
    assert np.all(np.isinf(seen[-1]))
    assert free.max() > np.pi, "the period changed nothing: it was not applied"
    smspace.distances(sets, metric="wrapped", period="2pi,none")
    assert seen[-1][0] == 2 * np.pi and np.isinf(seen[-1][1])


def test_a_nan_keyword_argument_is_named():
    arm = smspace.Agent.preset("planar-arm")
    with pytest.raises(ValueError, match="step=nan"):
        smspace.trace(arm, np.zeros((2, 4)), step=float("nan"))
    with pytest.raises(ValueError, match="tolerance"):
        smspace.embed(np.ones((3, 3)) - np.eye(3), method="mds", tolerance=float("inf"))


def test_a_run_folder_that_holds_its_experiment_is_refused(tmp_path):
    experiment = tmp_path / "tiny.toml"
    experiment.write_text(TINY_EXPERIMENT.replace("centroid-cache", "hausdorff"))
    before = experiment.read_bytes()
    with pytest.raises(ValueError, match="tiny.toml"):
        smspace.run(experiment, tmp_path)
    assert experiment.read_bytes() == before
