"""The Python API keeps the command line's promises under hostile arguments: sizes
beyond the limits are refused before anything is allocated, no result holds NaN or
an infinity, and every bad argument is a clean Python exception (ValueError,
TypeError, OverflowError, OSError), never a crash or an abort of the interpreter.

The seeded battery at the end draws argument combinations from pools of hostile
values; a watchdog (faulthandler) ends the process with a traceback rather than let
a hang go unnoticed."""

import faulthandler
import json
import math
import random
import subprocess
import sys
import types

import numpy as np
import pytest

import smspace
import smspace.dask
from conftest import random_sets

CLEAN = (ValueError, TypeError, OverflowError, OSError)


@pytest.fixture(autouse=True)
def watchdog():
    """No test here may hang: after 120 s the process ends with every thread's stack."""
    faulthandler.dump_traceback_later(120, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


@pytest.fixture(scope="module")
def arm():
    return smspace.Agent.preset("planar-arm")


@pytest.fixture(scope="module")
def small_run(root):
    return root / "experiments" / "paper-toy-redundant.toml"


TINY = {"exploration.n": 12, "kernel.points": 8, "report.formats": "svg"}


# --- sizes are checked before allocation ----------------------------------------------


def test_piece_starts_beyond_the_limit_are_refused(arm):
    motors = smspace.explore(arm, n=2, seed=1).motors
    with pytest.raises(ValueError, match=r"piece_starts.*at most 10000"):
        smspace.trace(arm, motors, piece_starts=10**9)


def test_epochs_beyond_the_limit_are_refused():
    D = smspace.distances(random_sets(6, 4, 2, seed=0), metric="hausdorff", period="none")
    with pytest.raises(ValueError, match=r"epochs.*at most 100000"):
        smspace.embed(D, method="cca", dim=2, epochs=4_000_000_000)
    with pytest.raises(ValueError, match=r"extend_epochs.*at most 100000"):
        smspace.embed(D, method="cca", dim=2, extend_epochs=10**12)


def test_a_tile_plan_of_too_many_tiles_is_refused_at_once():
    with pytest.raises(ValueError, match=r"500000500000 tiles, more than 1000000: use blocks of at least 708"):
        smspace.tile_plan(10**6, 1)
    # The size it names fits.
    assert len(smspace.tile_plan(10**6, 708)) <= smspace.MAX_TILES
    with pytest.raises(TypeError, match="size must be an integer"):
        smspace.tile_plan(10, 2.5)


def test_rayon_num_threads_beyond_four_per_core_is_refused_at_import():
    done = subprocess.run(
        [sys.executable, "-c", "import smspace"],
        env={"RAYON_NUM_THREADS": "100000", "PATH": ""},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode != 0
    assert "RAYON_NUM_THREADS = 100000 is more than 4 threads per core" in done.stderr


# --- no non-finite output, the CLI's checks -------------------------------------------


def test_distances_that_overflow_are_refused_not_returned_as_inf():
    sets = random_sets(6, 5, 3, seed=4) * 1e300
    with pytest.raises(ValueError, match=r"is inf: the sets' coordinates are too large"):
        smspace.distances(sets, metric="hausdorff", period="none")
    with pytest.raises(ValueError, match=r"is inf: the sets' coordinates are too large"):
        smspace.knn(sets, 2, metric="hausdorff", period="none")
    # Periodic coordinates wrap: the same sets give finite distances.
    assert np.isfinite(smspace.distances(sets, metric="hausdorff")).all()


def test_an_environment_without_lights_is_refused(arm):
    motors = smspace.explore(arm, n=2, seed=1).motors
    with pytest.raises(ValueError, match="no lights"):
        smspace.trace(arm, motors, method="sensory", env=np.zeros((0, 2)))
    with pytest.raises(ValueError, match="no lights"):
        smspace.trace(arm, motors, env=np.zeros((0, 2)))


def test_embedding_quality_does_not_depend_on_the_scale(cli, tmp_path):
    sets = random_sets(30, 6, 3, seed=8)
    D = smspace.distances(sets, metric="hausdorff", period="none")
    figures = []
    for scale in [1.0, 1e-200, 1e200]:
        path = tmp_path / f"D{scale:g}.npy"
        np.save(path, D * scale)
        out = tmp_path / f"Y{scale:g}.npy"
        cli("embed", "--distances", path, "--method", "mds", "--dim", "2", "--out", out)
        report = json.loads(out.with_suffix(".embed.json").read_text())
        quality = report["quality"]
        dydx = np.load(out.with_suffix(".dydx.npy"))
        assert np.isfinite(dydx).all()
        figures.append((quality["trustworthiness"], quality["continuity"], quality["kruskal_stress"]))
    for other in figures[1:]:
        np.testing.assert_allclose(other, figures[0], rtol=1e-9)


# --- a distance backend is checked; its failures say so --------------------------------


def _run_with_backend(path, out, backend):
    overrides = [f"{k}={json.dumps(v)}" for k, v in TINY.items()]
    return smspace._core._run(str(path), str(out), overrides, False, None, backend, None, None)


def test_a_backend_returning_the_wrong_shape_fails_at_the_distances_stage(small_run, tmp_path):
    def three_by_three(points, codes, metric, period, pieces=None, params=None):
        return np.zeros((3, 3))

    with pytest.raises(ValueError, match=r"distance backend .* returned a 3 × 3 matrix for \d+ kernel sets"):
        _run_with_backend(small_run, tmp_path / "run", three_by_three)
    assert not (tmp_path / "run" / "D.npy").exists()
    status = json.loads((tmp_path / "run" / "manifest.json").read_text())["status"]
    assert status["state"] == "failed" and status["stage"] == "distances"


def test_a_backend_failure_names_the_backend_not_the_metric_table(small_run, tmp_path):
    def failing(points, codes, metric, period, pieces=None, params=None):
        raise RuntimeError("the cluster is gone")

    with pytest.raises(RuntimeError, match="the cluster is gone"):
        _run_with_backend(small_run, tmp_path / "run", failing)
    status = json.loads((tmp_path / "run" / "manifest.json").read_text())["status"]
    assert "the distance backend" in status["reason"]
    assert "the cluster is gone" in status["reason"]
    assert "[metric.params]" not in status["reason"]


class _Lost:
    """A future whose task was lost with its worker."""

    def __init__(self, error):
        self.error = error

    def result(self):
        raise self.error


def test_a_lost_dask_task_says_that_the_workers_died():
    distributed = pytest.importorskip("distributed")
    killed = getattr(distributed, "KilledWorker", None)
    if killed is None:
        from distributed.scheduler import KilledWorker as killed
    from distributed.client import FutureCancelledError

    try:  # (its arguments differ between versions of distributed)
        worker = types.SimpleNamespace(address="tcp://127.0.0.1:1")
        killed_error = killed("task-1", worker, 3)
    except TypeError:
        killed_error = killed("task-1", "tcp://127.0.0.1:1")
    try:
        cancelled = FutureCancelledError("k", "lost")
    except TypeError:
        cancelled = FutureCancelledError("k")
    for error in [killed_error, cancelled]:
        with pytest.raises(smspace.dask.WorkersDied, match="workers died or were killed"):
            smspace.dask._result(_Lost(error), "the task of tile (0, 5, 0, 5)")
    # The task's own errors pass unchanged.
    with pytest.raises(ValueError, match="its own"):
        smspace.dask._result(_Lost(ValueError("its own")), "a task")


def test_a_run_of_one_set_asks_for_two(small_run, tmp_path):
    with pytest.raises(ValueError, match=r"exploration.*n.*at least 2 sets.*raise exploration.n"):
        smspace.run(small_run, out=tmp_path / "run", overrides={"exploration.n": 1})


def test_an_arm_of_long_links_traces_its_sets():
    big = smspace.Agent.preset("planar-arm", link_lengths=[1e6, 1e6, 1e6])
    found = smspace.explore(big, n=6, seed=2, workspace=None)
    traced = smspace.trace(big, found.motors, points=10, workspace=None)
    assert len(traced) >= 5, traced.report["summary"]


# --- the seeded battery ----------------------------------------------------------------

HUGE = [10**9, 10**12, 2**63, 2**64, -1, -(2**63)]
NUMBERS = [math.nan, math.inf, -math.inf, -1.0, 0.0, 1e308, 1e-320]
WRONG = ["x", None, [1, 2], {"a": 1}, object()]


def _arrays(rng):
    """Hostile arrays: wrong dimensions, empty, non-finite, odd dtypes, huge values."""
    pool = [
        np.zeros((0, 4)),
        np.zeros((0, 3, 2)),
        np.zeros((3, 0, 2)),
        np.zeros((3, 2, 0)),
        np.zeros(5),
        np.zeros((2, 2, 2, 2)),
        np.full((3, 4), np.nan),
        np.full((3, 4), np.inf),
        np.full((4, 3, 2), -np.inf),
        np.array([["a", "b"]]),
        np.zeros((3, 4), dtype=np.complex128),
        np.zeros((3, 4), dtype=np.float16),
        np.ones((3, 3), dtype=bool),
        random_sets(5, 4, 2, seed=rng.randrange(1000)) * 1e300,
        random_sets(5, 4, 2, seed=rng.randrange(1000)) * 1e-300,
        -np.ones((4, 4)),
        np.arange(9.0).reshape(3, 3),
        np.array(5.0),
    ]
    return pool[rng.randrange(len(pool))]


def _value(rng, pools):
    pool = pools[rng.randrange(len(pools))]
    return pool[rng.randrange(len(pool))]


def _cases(arm, rng):
    """One hostile call: a callable of no argument."""
    motors = smspace.explore(arm, n=3, seed=1).motors
    good_sets = random_sets(5, 4, 2, seed=3)
    good_D = smspace.distances(good_sets, metric="hausdorff", period="none")
    pick = rng.randrange(9)
    if pick == 0:
        return lambda: smspace.explore(arm, n=_value(rng, [HUGE, NUMBERS, WRONG]), seed=1)
    if pick == 1:
        key = ["points", "piece_starts", "max_steps", "max_cover_points", "step", "closure_tolerance"][rng.randrange(6)]
        return lambda: smspace.trace(arm, motors, **{key: _value(rng, [HUGE, NUMBERS, WRONG])})
    if pick == 2:
        return lambda: smspace.trace(arm, _arrays(rng), method=["kinematic", "sensory"][rng.randrange(2)])
    if pick == 3:
        env = _arrays(rng) if rng.randrange(2) else _value(rng, [HUGE, NUMBERS, WRONG])
        return lambda: smspace.trace(arm, motors, method="sensory", env=env)
    if pick == 4:
        return lambda: smspace.distances(
            _arrays(rng) if rng.randrange(2) else good_sets,
            metric=["hausdorff", "curve", "surface", "nope"][rng.randrange(4)],
            period=["none", "2pi", "bogus", "2pi,none"][rng.randrange(4)],
            memory_limit_bytes=[None, 1, 2**63][rng.randrange(3)],
        )
    if pick == 5:
        return lambda: smspace.knn(
            _arrays(rng) if rng.randrange(2) else good_sets,
            _value(rng, [HUGE, [0, 1, 4, 5]]),
            metric="hausdorff",
            period="none",
            pivots=[None, 0, 10**12][rng.randrange(3)],
            rows=[None, (0, 10**9), (3, 1), (-1, 2)][rng.randrange(4)],
        )
    if pick == 6:
        key = ["epochs", "dim", "k", "landmarks", "init_landmarks", "alpha_start"][rng.randrange(6)]
        return lambda: smspace.embed(
            _arrays(rng) if rng.randrange(3) == 0 else good_D,
            method=["cca", "mds", "isomap"][rng.randrange(3)],
            **{key: _value(rng, [HUGE, NUMBERS, WRONG])},
        )
    if pick == 7:
        return lambda: smspace.analyze(
            _arrays(rng) if rng.randrange(2) else good_D,
            poses=_arrays(rng) if rng.randrange(2) else None,
            max_points=_value(rng, [HUGE, [0, 1, 3]]),
        )
    return lambda: smspace.tile_plan(_value(rng, [HUGE, NUMBERS, WRONG]), _value(rng, [HUGE, [1, 2]]))


def _check_finite(result):
    """A returned result holds no NaN or infinity."""
    if isinstance(result, np.ndarray) and result.dtype.kind == "f":
        assert np.isfinite(result).all()
    elif isinstance(result, (tuple, list)):
        for item in result:
            _check_finite(item)
    elif hasattr(result, "sets"):
        _check_finite(result.sets)
    elif hasattr(result, "motors"):
        _check_finite(result.motors)


@pytest.mark.parametrize("seed", range(4))
def test_hostile_arguments_give_clean_exceptions(arm, seed):
    rng = random.Random(seed)
    outcomes = {"refused": 0, "returned": 0}
    for _ in range(60):
        call = _cases(arm, rng)
        try:
            result = call()
        except CLEAN:
            outcomes["refused"] += 1
            continue
        outcomes["returned"] += 1
        _check_finite(result)
    # The pools are hostile: calls are refused (and the others returned finite values).
    assert outcomes["refused"] > 0, outcomes


def test_the_old_name_of_sensor_sigma_is_refused_with_the_new_one():
    agent = smspace.Agent.preset("planar-arm")
    found = smspace.explore(agent, n=2, seed=1)
    with pytest.raises(ValueError, match="sensor_sigma = 0.01"):
        smspace.trace(agent, found.motors, method="sensory", env=1, noise=0.01)
