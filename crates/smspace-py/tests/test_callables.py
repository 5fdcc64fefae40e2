"""A user's callables as a simulator writes them: one state shared by every call,
per-thread state in threading.local(), a sense that blocks, and Ctrl-C."""

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import smspace


class OneState:
    """A simulator with one state, as a MuJoCo user writes it: each call writes the
    motors into the state, lets other threads run (a call that releases the GIL, as
    mj_kinematics does), then reads the sensors from the state."""

    def __init__(self, sense, pose):
        self.sense_law, self.pose_law = sense, pose
        self.qpos = None

    def _step(self, law, motors):
        out = np.empty((motors.shape[0], law(motors[:1]).shape[1]))
        for i, row in enumerate(motors):
            self.qpos = row.copy()
            time.sleep(0)  # releases the GIL, as a simulator step does
            out[i] = law(self.qpos[None, :])[0]
        return out

    def sense(self, motors):
        return self._step(self.sense_law, motors)

    def pose(self, motors):
        return self._step(self.pose_law, motors)


@pytest.fixture(scope="module")
def arm(numpy_arm_module):
    builtin = smspace.Agent.preset("planar-arm")
    lights = builtin.lights(1)
    found = smspace.explore(builtin, n=10, seed=7)
    return numpy_arm_module.make_sense(lights), numpy_arm_module.pose, found.motors


@pytest.mark.parametrize("method", ["sensory", "kinematic"])
def test_a_stateful_simulator_gives_the_sets_of_a_stateless_one(arm, method):
    sense, pose, motors = arm
    stateless = smspace.PythonAgent(sense=sense, pose=pose, n_motors=4, n_sensors=6,
                                    concurrent_sets=2)
    sim = OneState(sense, pose)
    stateful = smspace.PythonAgent(sense=sim.sense, pose=sim.pose, n_motors=4, n_sensors=6,
                                   concurrent_sets=2)
    expected = smspace.trace(stateless, motors, method=method, points=20, workspace=None)
    got = smspace.trace(stateful, motors, method=method, points=20, workspace=None)
    assert len(expected) >= 8
    assert np.array_equal(got.kept, expected.kept)
    assert np.array_equal(got.sets, expected.sets)


def test_calls_are_never_concurrent_unless_declared_thread_safe(arm):
    sense, pose, motors = arm
    inside, most = [0], [0]
    lock = threading.Lock()

    def counted(m):
        with lock:
            inside[0] += 1
            most[0] = max(most[0], inside[0])
        time.sleep(0.0005)  # releases the GIL while "inside"
        with lock:
            inside[0] -= 1
        return sense(m)

    agent = smspace.PythonAgent(sense=counted, n_motors=4, n_sensors=6, concurrent_sets=2)
    smspace.trace(agent, motors[:4], method="sensory", points=10)
    assert most[0] == 1
    # Declared thread-safe, the two threads of a gathered trace do overlap.
    most[0] = 0
    agent = smspace.PythonAgent(sense=counted, n_motors=4, n_sensors=6, concurrent_sets=2,
                                thread_safe=True)
    smspace.trace(agent, motors[:4], method="sensory", points=10)
    assert most[0] == 2


def test_thread_local_state_lasts_from_call_to_call(arm):
    sense, pose, motors = arm
    local = threading.local()
    made, calls = [], [0]

    def per_thread(m):
        calls[0] += 1
        if not hasattr(local, "state"):
            local.state = object()
            made.append(threading.get_ident())
        time.sleep(0)
        return sense(m)

    agent = smspace.PythonAgent(sense=per_thread, n_motors=4, n_sensors=6, concurrent_sets=4,
                                thread_safe=True)
    traced = smspace.trace(agent, motors, method="sensory", points=20)
    assert len(traced) >= 8
    # One state per engine thread (the two gathering threads of each of the trace's
    # phases: the rank at the starts, the sets), not one per call.
    assert 1 <= len(made) <= 8 and calls[0] > 20 * len(made), (len(made), calls[0])
    # The pool's threads keep theirs too: poses through the kinematic method, twice
    # (the threads of the sensory trace above are the same long-lived threads).
    made.clear()
    local = threading.local()

    def pose_per_thread(m):
        if not hasattr(local, "state"):
            local.state = object()
            made.append(threading.get_ident())
        return pose(m)

    agent = smspace.PythonAgent(sense=sense, pose=pose_per_thread, n_motors=4, n_sensors=6,
                                thread_safe=True)
    smspace.trace(agent, motors, method="kinematic", points=20, workspace=None)
    first = len(made)
    smspace.trace(agent, motors, method="kinematic", points=20, workspace=None)
    assert 1 <= len(made) <= os.cpu_count() * 4
    assert len(made) == first, "a thread of the second trace made its state again"


@pytest.mark.parametrize("n_motors, n_sensors, bad", [(10**9, 3, "n_motors = 1000000000"),
                                                      (2, 10**9, "n_sensors = 1000000000"),
                                                      (0, 3, "n_motors = 0"), (2, 0, "n_sensors = 0")])
def test_sizes_of_a_python_agent_are_checked_before_allocation(n_motors, n_sensors, bad):
    with pytest.raises(ValueError, match=f"{bad} must be 1 to"):
        smspace.PythonAgent(sense=abs, n_motors=n_motors, n_sensors=n_sensors)


INTERRUPTED = textwrap.dedent(
    """
    import sys, time, numpy as np, smspace
    kind = sys.argv[1]
    if kind == "builtin":
        agent = smspace.Agent.preset("planar-arm")
        found = smspace.explore(agent, n=3000, seed=1)
        call = lambda: smspace.trace(agent, found.motors, method="sensory", env=1)
    elif kind == "slow":
        def sense(m):
            time.sleep(0.01)
            return np.cos(m) @ np.ones((m.shape[1], 3))
        agent = smspace.PythonAgent(sense=sense, n_motors=4, n_sensors=3)
        # Three equal sensors: 3-D kernels, covered at a step whose covering is not
        # refused up front as too large.
        call = lambda: smspace.trace(agent, np.zeros((500, 4)) + 0.1, method="sensory",
                                     cover_step=0.5)
    else:  # a sense that blocks
        def sense(m):
            time.sleep(3600)
        agent = smspace.PythonAgent(sense=sense, n_motors=4, n_sensors=3)
        call = lambda: smspace.trace(agent, np.zeros((5, 4)), method="sensory")
    print("started", flush=True)
    try:
        call()
        print("finished", flush=True)
    except KeyboardInterrupt:
        print("interrupted", time.monotonic(), flush=True)
        sys.exit(3)
    """
)


@pytest.mark.parametrize("kind", ["builtin", "slow", "blocking"])
def test_ctrl_c_stops_a_call_within_a_second(kind, tmp_path):
    script = tmp_path / "interrupted.py"
    script.write_text(INTERRUPTED)
    child = subprocess.Popen([sys.executable, str(script), kind], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "started"
        time.sleep(1.5)
        sent = time.monotonic()
        child.send_signal(signal.SIGINT)
        line = child.stdout.readline()
        if kind == "blocking":
            # The interpreter waits at exit for the engine's thread, which sleeps in
            # the callable for an hour; Ctrl-C again exits without waiting.
            time.sleep(1.5)
            child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=30)
    finally:
        child.kill()
    assert child.returncode == 3, (line, out, err)
    if kind == "blocking":
        assert "waiting for a computation interrupted inside a Python callable" in err, err
    else:
        assert "Fatal Python error" not in err and "waiting for" not in err, err
    stopped = float(line.split()[1])
    assert stopped - sent < 1.5, f"KeyboardInterrupt came {stopped - sent:.2f} s after SIGINT"


def test_a_python_agent_with_three_dimensional_kernels_fails_fast_as_cover_budget():
    """Three equal sensors of four motors: kernels of dimension 3, whose covering at the
    default step is forecast far beyond the budget. Every set fails at once as
    cover-budget, having read only its start and its Jacobian's rank, not after hours."""
    rows = []

    def sense(m):
        rows.append(m.shape[0])
        return np.cos(m) @ np.ones((m.shape[1], 3))

    agent = smspace.PythonAgent(sense=sense, n_motors=4, n_sensors=3)
    starts = np.random.default_rng(3).uniform(-1.0, 1.0, size=(20, 4))
    with pytest.raises(ValueError, match="cover-budget"):
        smspace.trace(agent, starts, method="sensory")
    assert sum(rows) <= 20 * (4 + 1) * 3, f"{sum(rows)} sensor rows read for 20 starts"
