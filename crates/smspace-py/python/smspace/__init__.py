"""smspace: a naive sensorimotor agent discovers its own spatial configuration.

The Rust engine of smspace (Laflaquière et al. 2015) from Python, one function per
stage of the pipeline, on NumPy arrays::

    import smspace
    agent = smspace.Agent.preset("planar-arm")            # or Agent.from_toml("arm.toml")
    found = smspace.explore(agent, n=2500, seed=1)        # found.motors, found.poses
    traced = smspace.trace(agent, found.motors, method="kinematic", points=100)
    D = smspace.distances(traced, metric="curve")         # (M, M) ndarray
    Y = smspace.embed(D, method="cca", dim=3, seed=0)     # (M, 3) ndarray
    report = smspace.analyze(D, poses=found.poses[traced.kept])  # dict: betti, ...
    run = smspace.run("experiments/paper-arm.toml", out="runs/x",
                      overrides={"exploration.n": 500})

Arrays come in as float64 arrays of any order or strides (the engine works on its
own copy) and go out as NumPy arrays that own the engine's buffers (no copy). Every
long computation releases the GIL and stops within about a second on Ctrl-C
(``KeyboardInterrupt``). Errors of the engine are raised as ``ValueError``
(``OSError`` for files) with the messages of the ``smspace`` command-line tool; bad
arguments as ``TypeError``/``ValueError`` naming the argument.

Agents written in Python: :class:`PythonAgent` (``sense(motors (B, N)) -> (B, K)``,
called in batches, never from two threads at once unless declared
``thread_safe=True``); a MuJoCo model as an agent: :mod:`smspace.mujoco`
(``smspace.mujoco.agent(model, joints=[...], site="eye")``, needs the ``mujoco``
package). Distance matrices on a Dask cluster: :mod:`smspace.dask`.
"""

from __future__ import annotations

import json
import math
import os
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _core
from ._core import Agent, CallbackError, PythonAgent
from . import mujoco  # MuJoCo models as agents (imports the mujoco package on first use)

__version__: str = _core.__version__

#: The library's defaults of every stage's parameters (the ones ``smspace run`` and the
#: ``smspace`` commands fill in): the functions below take their default arguments
#: from here, so that every door gives the same answer to the same words.
_DEFAULTS: dict = json.loads(_core._DEFAULTS)

__all__ = [
    "Agent",
    "PythonAgent",
    "CallbackError",
    "TraceWarning",
    "Exploration",
    "Traced",
    "Embedded",
    "Run",
    "Invariance",
    "explore",
    "trace",
    "distances",
    "knn",
    "embed",
    "analyze",
    "invariance",
    "run",
    "tile_plan",
    "register_metric",
    "learn",
    "metrics",
]

ProgressArg = Union[None, bool, Callable[[str, int, int], Any]]


# --- arguments ----------------------------------------------------------------------


def _array(value: Any, name: str, ndim: int) -> np.ndarray:
    """``value`` as a float64 array of ``ndim`` dimensions, without a copy when it is
    one already (any order or strides); TypeError/ValueError naming ``name``."""
    array = np.asarray(value)
    if array.dtype != np.float64:
        if array.dtype.kind in "iuf" and array.dtype != np.float16:
            array = array.astype(np.float64)
        else:
            raise TypeError(
                f"{name} must be an array of float64, got dtype {array.dtype}"
            )
    if array.ndim != ndim:
        raise ValueError(
            f"{name} must have {ndim} dimensions, got shape {array.shape}"
        )
    if not array.flags.aligned:
        # Unpickled buffers (Dask, multiprocessing) may be unaligned: the engine reads
        # aligned float64 only, so this one case is copied.
        array = array.copy()
    return array


def _rows(value: Any, name: str) -> np.ndarray:
    """Sensor readings as rows ``(S, K)``: a 2-D array as it is, camera frames
    ``(S, H, W)`` or ``(S, H, W, C)`` flattened per frame (row-major, channels last;
    a view when the frames are contiguous)."""
    array = np.asarray(value)
    if array.ndim in (3, 4):
        if array.shape[0] == 0 or 0 in array.shape[1:]:
            raise ValueError(f"{name}: frames of shape {array.shape} have no pixels")
        array = array.reshape(array.shape[0], -1)
    elif array.ndim != 2:
        raise ValueError(
            f"{name} must be rows (S, K) or camera frames (S, H, W) or (S, H, W, C), "
            f"got shape {array.shape}"
        )
    return _array(array, name, 2)


def _closed_codes(closed: Any, sets: int) -> Optional[np.ndarray]:
    """The closed/open code of every set (1: closed loop, 0: open polyline)."""
    if closed is None:
        return None
    if isinstance(closed, str):
        if closed not in ("closed", "open"):
            raise ValueError(f"closed='{closed}' must be 'closed', 'open' or an array")
        return np.full(sets, 1 if closed == "closed" else 0, dtype=np.int64)
    codes = np.asarray(closed)
    if codes.dtype == np.bool_:
        codes = codes.astype(np.int64)
    if codes.dtype.kind not in "iu" or codes.ndim != 1:
        raise TypeError(
            f"closed must be a 1-D integer array of codes (1: closed, 0: open), got dtype {codes.dtype} and shape {codes.shape}"
        )
    codes = codes.astype(np.int64, copy=False)
    return codes if codes.flags.aligned else codes.copy()


class _Tqdm:
    """A progress callable drawing a ``tqdm`` bar per stage."""

    def __init__(self) -> None:
        from tqdm.auto import tqdm

        self._tqdm = tqdm
        self._bar = None
        self._stage = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        if self._bar is None or stage != self._stage or done < self._bar.n:
            if self._bar is not None:
                self._bar.close()
            self._bar = self._tqdm(total=total, desc=stage, leave=False)
            self._stage = stage
        self._bar.update(done - self._bar.n)
        if done >= total and self._bar is not None:
            self._bar.close()
            self._bar = None


def _progress(progress: ProgressArg) -> Optional[Callable[[str, int, int], Any]]:
    """``None``/``False``: silent; ``True``: a ``tqdm`` bar when tqdm is installed (else
    silent); a callable: ``progress(stage, done, total)``."""
    if progress is None or progress is False:
        return None
    if progress is True:
        try:
            return _Tqdm()
        except ImportError:
            return None
    if not callable(progress):
        raise TypeError("progress must be None, True or a callable progress(stage, done, total)")
    return progress


def _params(values: Mapping[str, Any]) -> str:
    """The JSON of the parameters that were given (the others keep the engine's
    defaults, which are the paper's)."""
    given = {k: v for k, v in values.items() if v is not None}
    for key, value in given.items():
        _check_finite_param(key, value)
    return json.dumps(given)


def _check_finite_param(key: str, value: Any) -> None:
    """Refuses a NaN or infinite number given as the keyword argument ``key`` (also
    inside a list), naming the key and the value."""
    values = value if isinstance(value, (list, tuple)) else [value]
    for v in values:
        if isinstance(v, (float, np.floating)) and not math.isfinite(v):
            raise ValueError(f"{key}={value!r}: every number must be finite; give a finite {key}")


# --- results ------------------------------------------------------------------------


@dataclass
class Exploration:
    """Explored motor configurations: ``motors`` (M, N), the observer's ``poses``
    (M, d) (None without a ground truth) and ``probes`` (M, 3) int64 (probe grid
    labels, -1 for babbled rows)."""

    motors: np.ndarray
    poses: Optional[np.ndarray]
    probes: np.ndarray


class TraceWarning(UserWarning):
    """What a trace's summary says a user must know: the sensors are noisy and the
    sets traced from them are blurred, lost or ran back over themselves (the message
    gives the measured noise), or sets miss pieces of their level set."""


@dataclass
class Traced:
    """Kernel sets: ``sets`` (M, P, N), ``kept`` (M,) int64 (the motor row of each set),
    ``closed`` (M,) int64 (1: closed loop, 0: open polyline), ``pieces`` (M, P) int64
    (the piece of every point: 0 for sets of one piece; with ``components="all"`` the
    metrics join no two pieces), the tracing ``report`` (dict: statuses, steps,
    residuals per set; ``sets.trace.json``) and its ``warnings`` (list of str: what
    the summary says a user must know, each raised as a :class:`TraceWarning`)."""

    sets: np.ndarray
    kept: np.ndarray
    closed: np.ndarray
    pieces: np.ndarray
    report: dict = field(repr=False)
    warnings: list = field(default_factory=list, repr=False)
    #: The learned law's report (``sets.law.json``) for sets from :func:`learn`.
    law: Optional[dict] = field(default=None, repr=False)

    def __len__(self) -> int:
        return int(self.sets.shape[0])


@dataclass
class Embedded:
    """An embedding's coordinates ``Y`` (M, d) and its fit ``report`` (dict)."""

    Y: np.ndarray
    report: dict = field(repr=False)


@dataclass
class Invariance:
    """The same starts traced in several environments and compared: the ``report``
    (dict, ``invariance.json``: the largest set difference, the Mantel correlations of
    the set metric and of the raw sensors, per pair of environments), the ``rows`` of
    the starts traced in every environment (C,) int64, and per environment the ``(C,
    C)`` matrix of their ``distances`` and their ``sensors`` ``(C, K)``."""

    report: dict = field(repr=False)
    rows: np.ndarray
    distances: list = field(repr=False)
    sensors: list = field(repr=False)


@dataclass
class Run:
    """A finished run folder: ``dir``, its ``report`` (``analysis.json`` as a dict),
    ``manifest`` (``manifest.json``) and its arrays by file stem (``arrays["D"]``,
    ``arrays["sets"]``, ``arrays["Y"]``, ``arrays["motors"]``, ``arrays["poses"]``, ...),
    also as attributes (``run.D``). A run on the landmark path (``[scale]``) writes
    ``D_landmarks`` (every set's distances to the landmarks) instead of ``D``."""

    dir: Path
    report: dict = field(repr=False)
    manifest: dict = field(repr=False)
    arrays: dict = field(repr=False)

    def __getattr__(self, name: str) -> np.ndarray:
        arrays = self.__dict__.get("arrays", {})
        if name in arrays:
            return arrays[name]
        if name.startswith("__"):
            raise AttributeError(name)
        why = f"the run in {self.__dict__.get('dir')} wrote no {name}.npy; its arrays: {', '.join(sorted(arrays))}"
        if name == "D" and "D_landmarks" in arrays:
            why += (
                "; it took the landmark path, which writes D_landmarks (every set's distances"
                " to the landmarks) instead of the M x M matrix: run with"
                " overrides={'scale.path': 'dense'} for D"
            )
        raise AttributeError(why)


# --- stages -------------------------------------------------------------------------


def explore(
    agent: Agent,
    n: int = _DEFAULTS["exploration"]["n"],
    seed: int = _DEFAULTS["exploration"]["seed"],
    *,
    probes: bool = False,
    workspace: Any = "default",
    progress: ProgressArg = None,
    **params: Any,
) -> Exploration:
    """Babbles ``n`` motor configurations (seeded), kept inside the agent's working
    space (``workspace="default"``: the paper's for the arm; ``None``: anywhere;
    ``(cx, cy, depth, width)``), plus the probe grid with ``probes=True``. Other keys of
    the ``[exploration]`` table as keyword arguments (``probe_positions=10``, ...).
    ``progress``: a callable ``(stage, done, total)`` or ``True`` for a tqdm bar."""
    if not isinstance(agent, Agent):
        raise TypeError(f"agent must be a smspace.Agent, got {type(agent).__name__}")
    values = dict(params, n=n, seed=seed, probes="grid" if probes else "none")
    motors, poses, labels = _core._explore(
        agent,
        _params(values),
        _workspace_arg(workspace),
        _progress(progress),
    )
    return Exploration(motors=motors, poses=poses, probes=labels)


def _workspace_arg(workspace: Any) -> Any:
    """``"default"``, ``None`` (spelled ``"none"`` for the engine) or four numbers."""
    return "none" if workspace is None else workspace


def trace(
    agent: Agent,
    motors: Any,
    method: str = _DEFAULTS["kernel"]["method"],
    points: int = _DEFAULTS["kernel"]["points"],
    *,
    env: Any = None,
    workspace: Any = "default",
    progress: ProgressArg = None,
    **params: Any,
) -> Traced:
    """Traces the kernel set through every motor row ``(M, N)``: ``method="kinematic"``
    (the observer's pose, the paper's) or ``"sensory"`` (the agent's own sensors, in the
    environment ``env``: None the agent's default (seed 1, or its TOML file's
    ``[environment]``), an int seed, or lights ``(L, 2)``; a PythonAgent senses its own
    world). Other keys of the ``[kernel]`` table as keyword arguments (``step=1e-3``,
    ``closure_tolerance=1e-2``, ...). Sets that fail are left out (see ``kept`` and
    ``report``); when fewer than two of two or more rows are kept, it raises ValueError
    naming the count of each status and what it suggests. What the sets' summary says
    a user must know (noisy sensors that blur or turn round the sets, with the measured
    noise; sets that miss pieces of their level set) is raised as a
    :class:`TraceWarning` each, and listed in ``warnings``.

    ``method="learned"`` pays a budget of sensor rows instead (``budget=ROWS``,
    required): the agent is babbled over its motor space (seeded, in batches of
    ``batch`` rows), the law is learned from what it read (the keywords of
    :func:`learn`), the sets are traced on the law, and each is verified against the
    agent at ``verify_points`` points along it (its readings within
    ``verify_tolerance`` of the sensors' spread, plus six deviations of the noise
    measured from two readings of every start, of its start's); sets that fail are left
    out. Rows the agent answers with NaN or infinity
    are counted, named and never learned. No more than ``budget`` rows are read; a
    budget too small to learn from is refused before any is read, with the least that
    works. The result's ``law`` is the law's report, and ``budget`` the rows spent by
    phase (``rows``: ``babble``, ``non_finite``, ``agent_rank``, ``verify``,
    ``total``), the rank of the agent's own slope at 16 starts (``agent_rank``, read
    with ``2N + 2`` rows each; a higher rank than the babbled data show is traced at)
    and each set's
    ``verification``, and ``rounds`` what each babbling round read. The babbling comes in
    ``rounds`` (default 2): the first reads ``first_round`` (default half) of the
    babbled rows over the working space (``workspace``, drawn by the agent's pose: no
    sensor is read for it; None: the whole motor space), each later one around the sets
    traced on the law of the rows read so far, where the babbled rows are sparsest."""
    if not isinstance(agent, Agent):
        raise TypeError(f"agent must be a smspace.Agent, got {type(agent).__name__}")
    motors = _array(motors, "motors", 2)
    if method == "learned":
        return _trace_learned(agent, motors, points, env, workspace, progress, params)
    values = dict(params, method=method, points=points)
    sets, kept, closed, pieces, report = _core._trace(
        agent,
        motors,
        _params(values),
        env,
        _workspace_arg(workspace),
        _progress(progress),
    )
    report = json.loads(report)
    messages = report.pop("warnings", [])
    for message in messages:
        warnings.warn(message, TraceWarning, stacklevel=2)
    return Traced(sets=sets, kept=kept, closed=closed, pieces=pieces, report=report,
                  warnings=messages)


#: The keywords of ``trace(..., method="learned")`` that set the budget's use.
_BUDGET_KEYS = ("budget", "verify_points", "batch", "verify_tolerance", "rounds", "first_round")


def _trace_learned(agent, starts, points, env, workspace, progress, params) -> Traced:
    """``trace(agent, starts, method="learned", budget=ROWS, ...)``."""
    if params.get("budget") is None:
        raise ValueError(
            'method="learned" reads the agent within a budget: give budget=ROWS, the most '
            "sensor rows to read in all (babbling, then verifying the sets)"
        )
    budget = {key: params.pop(key) for key in _BUDGET_KEYS if key in params}
    if "seed" in params:
        budget["seed"] = params["seed"]
    memory = params.pop("memory_limit_bytes", None)
    values = dict(params, points=points)
    sets, kept, closed, pieces, report, law, spent = _core._learn_agent(
        agent, starts, _params(budget), _params(values), env, _workspace_arg(workspace), memory,
        _progress(progress)
    )
    report = json.loads(report)
    law = json.loads(law)
    spent = json.loads(spent)
    messages = list(law.get("warnings", [])) + spent.get("warnings", []) + report.pop("warnings", [])
    for message in messages:
        warnings.warn(message, TraceWarning, stacklevel=3)
    report["budget"] = spent
    return Traced(sets=sets, kept=kept, closed=closed, pieces=pieces, report=report,
                  warnings=messages, law=law)


def learn(
    motors: Any,
    sensors: Any,
    starts: Any,
    *,
    period: str = "2pi",
    method: str = "invariants",
    points: int = _DEFAULTS["kernel"]["points"],
    memory_limit_bytes: Optional[int] = None,
    progress: ProgressArg = None,
    **params: Any,
) -> Traced:
    """Kernel sets from recorded logs, as ``smspace learn``: the law ``ŝ(m)`` learned
    from ``motors`` ``(S, N)`` and ``sensors`` ``(S, K)`` (or lists of them, one pair
    per environment: one law whose sensors are theirs side by side), then the set
    ``ŝ(m) = ŝ(m^i)`` traced through every row of ``starts`` ``(M, N)``. ``period``
    declares the motors: ``"2pi"`` (hinges), ``"none"`` (bounded by the log's range),
    a period, a range ``"LOW:HIGH"``, or a comma-separated list, one per motor.
    ``method`` is the law (``"invariants"``, ``"local-quadratic"``, ``"local-linear"``).
    Other keyword arguments are the law's (``invariants=9``, ``neighbours=60``,
    ``holdout=2000``, ``seed=1``, ...) or the tracing's (``max_steps=3000``,
    ``closure_tolerance=0.03``, ...). Learning is refused before it starts when it
    would need more than ``memory_limit_bytes`` (default 16 GiB). The result is a
    :class:`Traced` whose ``law`` is the law's report (``sets.law.json``: the rank and
    its evidence, the held-out error, the measured noise, repeated samples, the
    warnings, each also raised as a :class:`TraceWarning`). Camera frames may be given
    as they are recorded, ``(S, H, W)`` grey or ``(S, H, W, C)`` colour: each frame is
    one row of ``K = H W C`` sensors, row-major and channels last, as the built-in
    camera writes them."""
    motors = [motors] if not isinstance(motors, (list, tuple)) else list(motors)
    sensors = [sensors] if not isinstance(sensors, (list, tuple)) else list(sensors)
    motors = [_array(m, f"motors[{i}]", 2) for i, m in enumerate(motors)]
    sensors = [_rows(s, f"sensors[{i}]") for i, s in enumerate(sensors)]
    starts = _array(starts, "starts", 2)
    values = dict(params, method=method, points=points)
    sets, kept, closed, pieces, report, law = _core._learn(
        motors, sensors, starts, period, _params(values), memory_limit_bytes, _progress(progress)
    )
    report = json.loads(report)
    law = json.loads(law)
    messages = list(law.get("warnings", [])) + report.pop("warnings", [])
    for message in messages:
        warnings.warn(message, TraceWarning, stacklevel=2)
    return Traced(sets=sets, kept=kept, closed=closed, pieces=pieces, report=report,
                  warnings=messages, law=law)


def _sets_args(sets: Any, closed: Any, pieces: Any = None) -> tuple:
    """``(points, closed codes or None, pieces or None)`` of a :class:`Traced` or an
    array."""
    if isinstance(sets, Traced):
        codes = sets.closed if closed is None else _closed_codes(closed, len(sets))
        pieces = sets.pieces if pieces is None else pieces
        return _array(sets.sets, "sets", 3), codes, _pieces(pieces)
    points = _array(sets, "sets", 3)
    return points, _closed_codes(closed, points.shape[0]), _pieces(pieces)


def _metric_spec(metric: str, period: str, params: Optional[dict] = None, sets: Any = None) -> dict:
    """The engine's description of a metric: its name, the period of the motor
    coordinates, its parameters (the ``[metric.params]`` table of an experiment, as a
    dict) and, when ``sets`` comes from :func:`trace`, its trace report (the kernels'
    shape, which a parameter such as the surface metric's ``dimension`` follows)."""
    if params is not None and not isinstance(params, dict):
        raise TypeError(f"params must be a dict of the metric's parameters, got {type(params).__name__}")
    report = sets.report if isinstance(sets, Traced) else None
    return {
        "name": str(metric),
        "period": str(period),
        "params": None if params is None else json.dumps(params),
        "report": None if report is None else json.dumps(report),
    }


def _pieces(pieces: Any) -> Optional[np.ndarray]:
    """The piece of every point, ``(M, P)`` int64, or None; None too when every set is
    one piece (the engine's default)."""
    if pieces is None:
        return None
    array = np.asarray(pieces)
    if array.ndim != 2 or not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f"pieces must be an (M, P) integer array, got {array.dtype} of shape {array.shape}")
    if not array.any():
        return None
    return np.ascontiguousarray(array, dtype=np.int64)


def distances(
    sets: Union[Traced, np.ndarray],
    metric: str = _DEFAULTS["metric"],
    period: str = _DEFAULTS["period"],
    *,
    params: Optional[dict] = None,
    closed: Any = None,
    pieces: Any = None,
    knn: Optional[int] = None,
    memory_limit_bytes: Optional[int] = None,
    progress: ProgressArg = None,
) -> Any:
    """The ``(M, M)`` matrix of ``metric`` between the kernel sets (``"curve"``, the
    default of every door: the Hausdorff distance between the sets read as polylines;
    ``"hausdorff"``, ``"mean-hausdorff"``: between the sampled points; ``"surface"``:
    from the points of one set to the tangent disks of the other's, for kernels of
    dimension 2 sampled by points, see the README), each motor
    coordinate periodic ``"2pi"`` or not (``"none"``). ``sets`` is the result of
    :func:`trace` or an array ``(M, P, N)`` (then ``closed=`` says which sets are
    closed loops for ``curve``: an array of 1/0 or ``"closed"``/``"open"``, and
    ``pieces=`` the piece of every point, (M, P), for sets traced with
    ``components="all"``). ``params`` sets the metric's own parameters, as the
    ``[metric.params]`` table of an experiment and ``smspace distances --param`` do
    (e.g. ``{"dimension": 2}``). ``memory_limit_bytes`` defaults to the memory
    available. With ``knn=K``, the ``K`` nearest sets of every set instead:
    ``(indices, distances)``, each ``(M, K)``."""
    if knn is not None:
        return globals()["knn"](
            sets, knn, metric=metric, period=period, params=params, closed=closed,
            pieces=pieces, progress=progress,
        )
    spec = _metric_spec(metric, period, params, sets)
    points, codes, pieces = _sets_args(sets, closed, pieces)
    return _core._distances(points, codes, spec, memory_limit_bytes, _progress(progress), pieces)


def knn(
    sets: Union[Traced, np.ndarray],
    k: int,
    metric: str = _DEFAULTS["metric"],
    period: str = _DEFAULTS["period"],
    *,
    params: Optional[dict] = None,
    closed: Any = None,
    pieces: Any = None,
    rows: Optional[tuple] = None,
    pivots: Optional[int] = None,
    progress: ProgressArg = None,
) -> tuple:
    """The ``k`` nearest sets of every set (or of ``rows=(i0, i1)``) under ``metric``
    (with its ``params``, as :func:`distances`): ``(indices (R, k) int64, distances
    (R, k))``, nearest first, without the matrix."""
    spec = _metric_spec(metric, period, params, sets)
    points, codes, pieces = _sets_args(sets, closed, pieces)
    rows = (0, points.shape[0]) if rows is None else tuple(rows)
    return _core._knn(points, codes, spec, int(k), pivots, rows, _progress(progress), pieces)


def embed(
    D: Any,
    method: str = _DEFAULTS["embedding"]["method"],
    dim: int = _DEFAULTS["embedding"]["params"]["dim"],
    seed: int = _DEFAULTS["embedding"]["params"]["seed"],
    *,
    report: bool = False,
    progress: ProgressArg = None,
    **params: Any,
) -> Union[np.ndarray, Embedded]:
    """Coordinates ``(M, dim)`` of the points whose distances are ``D`` (``"cca"``, the
    paper's; ``"isomap"``; ``"mds"``), seeded. Other keys of the ``[embedding]`` table
    as keyword arguments (``epochs=50``, ``k=10``, ...). With ``report=True``, an
    :class:`Embedded` with the fit's diagnostics."""
    D = _array(D, "D", 2)
    values = dict(params, method=method, dim=dim, seed=seed)
    Y, fit = _core._embed(D, _params(values), _progress(progress))
    return Embedded(Y=Y, report=json.loads(fit)) if report else Y


def analyze(
    D: Any,
    poses: Any = None,
    *,
    representation: Any = None,
    circle_values: bool = False,
    progress: ProgressArg = None,
    **params: Any,
) -> dict:
    """Betti numbers and persistence, intrinsic dimension (TwoNN, MLE) and, with the
    ``poses`` of the sets ((M, 3) ``(x, y, alpha)`` of a planar agent, (M, 7) of a 3-D
    one, or (M, 2) ``(x, y)`` of a sensor whose orientation is fixed), the agreement of the learned neighbourhoods
    with them; a dict equal to ``analysis.json`` (plain JSON values). When the manifold
    has a loop, ``report["circle"]["agreement"]`` is its circular coordinate's circular
    correlation with the poses' angles; with ``circle_values=True``,
    ``report["circle"]["values"]`` is the coordinate of every set (a list of ``M``
    radians, as ``circle.npy``: ``np.asarray`` it). With a ``representation`` (M, q) of the same
    sets (an embedding ``Y``), ``report["affine"]`` says how well one affine map reads
    the positions (x, y) of ``poses`` off it (``r_squared``, ``metric_error``,
    ``topology_error_positions``, ``topology_error_representation``). Other keys of
    the ``[analysis]`` table as keyword arguments (``max_points=1000``,
    ``circle_landmarks=0``, ...)."""
    D = _array(D, "D", 2)
    poses = None if poses is None else _array(poses, "poses", 2)
    representation = None if representation is None else _array(representation, "representation", 2)
    report = json.loads(
        _core._analyze(D, poses, _params(params), _progress(progress), representation)
    )
    if not circle_values and isinstance(report.get("circle"), dict):
        report["circle"].pop("values", None)
    return report


def invariance(
    agent: Agent,
    motors: Any,
    envs: Sequence[Any],
    points: int = _DEFAULTS["kernel"]["points"],
    *,
    metric: str = _DEFAULTS["metric"],
    period: str = _DEFAULTS["period"],
    params: Optional[dict] = None,
    starts: Optional[int] = None,
    workspace: Any = "default",
    progress: ProgressArg = None,
    **kernel: Any,
) -> Invariance:
    """Traces the starts ``motors`` (M, N) (the first ``starts`` rows, default all)
    with the sensory method in every environment of ``envs`` (at least two; each an int
    seed or lights ``(L, 2)``/``(L, 3)``, as ``env`` of :func:`trace`) and compares the
    sets: they should not depend on the environment (paper section 3.3), while the raw
    sensor values do. ``metric``, ``period`` (``"motors"``: the agent's own) and
    ``params`` as in :func:`distances`; other keys of the ``[kernel]`` table as keyword
    arguments. The same numbers and arrays as ``smspace invariance`` writes."""
    if not isinstance(agent, Agent):
        raise TypeError(f"agent must be a smspace.Agent, got {type(agent).__name__}")
    motors = _array(motors, "motors", 2)
    envs = list(envs)
    if len(envs) < 2:
        raise ValueError(f"envs has {len(envs)} environment(s); give at least two to compare, e.g. envs=[1, 2, 3]")
    if starts is not None:
        if int(starts) < 1:
            raise ValueError(f"starts={starts}: give at least one start (or None to trace every row)")
        motors = motors[: int(starts)]
    values = dict(kernel, points=points)
    report, rows, matrices, sensors = _core._invariance(
        agent,
        motors,
        _params(values),
        envs,
        _metric_spec(metric, period, params),
        _workspace_arg(workspace),
        _progress(progress),
    )
    return Invariance(report=json.loads(report), rows=rows, distances=list(matrices),
                      sensors=list(sensors))


def _toml_value(value: Any) -> str:
    """A Python value as the TOML text of ``--set stage.key=value``."""
    if isinstance(value, (bool, int, float, str, list, tuple)):
        return json.dumps(list(value) if isinstance(value, tuple) else value)
    raise TypeError(f"override value {value!r} must be a bool, number, string or list")


def run(
    path: Union[str, os.PathLike],
    out: Union[None, str, os.PathLike] = None,
    overrides: Optional[Mapping[str, Any]] = None,
    *,
    force: bool = False,
    max_memory: Optional[int] = None,
    client: Any = None,
    tile: Optional[int] = None,
    log: Union[None, bool, Callable[[str], Any]] = None,
    progress: ProgressArg = None,
) -> Run:
    """Runs the experiment file ``path`` into ``out`` (default ``runs/<name>``, as
    ``smspace run``), with ``overrides`` as ``{"stage.key": value}`` (``--set``);
    unchanged stages are reused from the folder's cache unless ``force``. With a Dask
    ``client``, the distance stage runs on its cluster in tiles (:mod:`smspace.dask`;
    the matrix is the same, bit for bit); the landmark path of large runs
    (``[scale]``) computes in this process only, and is refused with a client
    (``scale.path = "dense"`` puts the whole matrix on the cluster). ``log=True`` prints one line per stage to
    stderr (or give a callable). Returns the run folder's arrays and reports."""
    sets = [f"{k}={_toml_value(v)}" for k, v in (overrides or {}).items()]
    if log is True:
        log = lambda line: print(line, file=sys.stderr)  # noqa: E731
    backend = None
    if client is not None:
        from . import dask as _dask

        backend = _dask._stage_backend(client, tile)
    directory, report = _core._run(
        os.fspath(path),
        None if out is None else os.fspath(out),
        sets,
        force,
        max_memory,
        backend,
        log or None,
        _progress(progress),
    )
    return _load_run(Path(directory), json.loads(report))


def _load_run(directory: Path, report: dict) -> Run:
    arrays = {}
    for file in sorted(directory.glob("*.npy")):
        arrays[file.name[: -len(".npy")].replace(".", "_")] = np.load(file)
    manifest_file = directory / "manifest.json"
    manifest = json.loads(manifest_file.read_text()) if manifest_file.exists() else {}
    return Run(dir=directory, report=report, manifest=manifest, arrays=arrays)


#: Most tiles :func:`tile_plan` lists (each is one task of a cluster).
MAX_TILES = 1_000_000


def register_metric(
    name: str,
    distance: Callable[..., float],
    *,
    summary: str = "a metric written in Python",
    is_metric: bool = False,
    thread_safe: bool = False,
    version: Optional[str] = None,
) -> None:
    """Adds the set metric ``name`` to those every function builds by name:
    :func:`distances`, :func:`knn`, the Dask tiles, and :func:`run`'s
    ``[metric] metric = "name"``, whose ``[metric.params]`` table is passed to
    ``distance`` as keyword arguments. ``distance(a, b, **params)`` takes the points of
    two sets, float64 arrays ``(P, N)``, and returns their distance: a finite float of
    at least 0. ``is_metric=True`` promises the triangle inequality (the nearest-
    neighbour search then prunes with it). The engine calls ``distance`` once per pair,
    one call at a time unless ``thread_safe=True`` (then from several threads at once:
    the callable must not share unguarded state). A built-in name cannot be replaced;
    registering a name again replaces the earlier callable.

    The points reach ``distance`` as they were traced, never wrapped. A callable that
    takes a ``period`` keyword argument is given each motor's period (a float64 array
    ``(N,)``, ``inf`` where a motor is not periodic) to wrap its differences with; for
    one that does not, any period but ``"none"`` is refused, so that the period is never
    silently ignored.

    :func:`run` reuses the distances in a run folder only when they are the same
    computation: a plain function is known by a hash of its code, defaults and closure
    (a change to a global it reads is not seen: give ``version``); any other callable
    (an object with ``__call__``, a ``functools.partial``) by its registration, so its
    distances are reused only within the process that registered it. ``version``, when
    given, replaces that identity: the same version is the same computation.

    A ``KeyboardInterrupt`` (or ``SystemExit``) that ``distance`` raises ends the
    computation and is raised as it is."""
    if version is not None and not isinstance(version, str):
        raise TypeError(f"register_metric: version must be a string, not {type(version).__name__}")
    identity = f"version:{version}" if version is not None else _callable_identity(distance)
    _core.register_metric(
        name,
        distance,
        summary=summary,
        is_metric=is_metric,
        thread_safe=thread_safe,
        takes_period=_takes_keyword(distance, "period"),
        identity=identity,
    )


#: Registrations of callables that cannot be hashed, in this process.
_registrations = [0]


def _callable_identity(distance: Callable[..., float]) -> str:
    """What tells ``distance`` from another callable: a hash of a plain function's code,
    defaults and closure, or for any other callable (or one whose closure cannot be
    pickled) this process and the registration's count."""
    import hashlib
    import marshal
    import pickle

    code = getattr(distance, "__code__", None)
    if code is not None:
        try:
            closure = tuple(c.cell_contents for c in (distance.__closure__ or ()))
            digest = hashlib.sha256(marshal.dumps(code))
            digest.update(pickle.dumps((distance.__defaults__, distance.__kwdefaults__, closure)))
            return f"code:{digest.hexdigest()}"
        except Exception:
            pass
    _registrations[0] += 1
    import time

    return f"registration:{os.getpid()}:{time.time_ns()}:{_registrations[0]}"


def _takes_keyword(function: Callable[..., Any], keyword: str) -> bool:
    """Whether ``function`` accepts the keyword argument ``keyword`` (by name, or
    through ``**kwargs``)."""
    import inspect

    try:
        parameters = inspect.signature(function).parameters.values()
    except (TypeError, ValueError):
        return False
    return any(
        (p.name == keyword and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))
        or p.kind == p.VAR_KEYWORD
        for p in parameters
    )


def metrics() -> list:
    """The set metrics registered now, built-in and from :func:`register_metric`:
    ``[(name, summary)]`` in name order."""
    return _core.metrics()


def tile_plan(sets: int, size: int) -> list:
    """The triangular tiles ``(r0, r1, c0, c1)`` of a matrix of ``sets`` sets in blocks
    of ``size``: every pair ``{i, j}`` in exactly one tile (block ``a`` against every
    block ``b >= a``). At most :data:`MAX_TILES` tiles: a plan with more is refused
    (ValueError naming a size that fits) before any tile is made."""
    for name, value in (("sets", sets), ("size", size)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"tile_plan: {name} must be an integer, got {type(value).__name__}")
    sets, size = int(sets), int(size)
    if sets < 2 or size < 1:
        raise ValueError(f"a tile plan needs at least 2 sets and a size of at least 1, got {sets} and {size}")
    count = -(-sets // size)
    tiles = count * (count + 1) // 2
    if tiles > MAX_TILES:
        # The smallest size whose plan fits: b blocks give b(b + 1)/2 tiles.
        most_blocks = (math.isqrt(8 * MAX_TILES + 1) - 1) // 2
        fits = -(-sets // most_blocks)
        raise ValueError(
            f"a tile plan of {sets} sets in blocks of {size} has {tiles} tiles, more than "
            f"{MAX_TILES}: use blocks of at least {fits} sets (tile={fits})"
        )
    blocks = [(start, min(start + size, sets)) for start in range(0, sets, size)]
    return [
        (a0, a1, b0, b1)
        for i, (a0, a1) in enumerate(blocks)
        for (b0, b1) in blocks[i:]
    ]
