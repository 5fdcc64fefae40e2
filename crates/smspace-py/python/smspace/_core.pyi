"""Type stubs of the extension module ``smspace._core`` (the Rust engine).

Users call the wrappers in ``smspace`` (``smspace.explore``, ``smspace.trace``, ...);
the underscored functions below take the engine's parameter structs as JSON.
"""

from os import PathLike
from typing import Any, Callable, Dict, List, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
#: The library's defaults of every stage's parameters, as JSON: ``metric``, ``period``,
#: ``exploration``, ``kernel``, ``embedding`` (``method``, ``params``), ``knn``.
_DEFAULTS: str

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
Progress = Optional[Callable[[str, int, int], Any]]
Bounds = Tuple[int, int, int, int]
# The engine's description of a metric (smspace._metric_spec): name, period, and the
# JSON of its parameters and of the sets' trace report (each or None).
MetricSpec = Dict[str, Optional[str]]
MotorSpec = Union[str, Tuple[str, float], Tuple[str, float, float]]

class CallbackError(RuntimeError):
    """A callable of a PythonAgent raised, or returned an array of the wrong type,
    shape or values."""

class Agent:
    """A sensorimotor agent: built-in, from a TOML file, or a :class:`PythonAgent`."""

    @staticmethod
    def preset(name: str, **params: Any) -> Agent:
        """The built-in agent ``name`` (``planar-arm``, ``toy-line``,
        ``toy-redundant``, ``chain``) with its ``[agent]`` table's keys as keyword
        arguments."""
    @staticmethod
    def from_toml(path: Union[str, PathLike[str]]) -> Agent:
        """The agent of a TOML file's ``[agent]`` (and ``[environment]``) table."""
    @property
    def name(self) -> str: ...
    @property
    def n_motors(self) -> int: ...
    @property
    def n_sensors(self) -> int: ...
    @property
    def motor_space(self) -> list[Tuple[str, float, float]]:
        """Each motor: ``("periodic", 0.0, period)`` or ``("bounded", low, high)``."""
    @property
    def has_ground_truth(self) -> bool: ...
    def lights(self, env: Any = None) -> F64:
        """The lights of the environment ``env`` names: ``(L, 2)`` or ``(L, 3)``."""
    def sense(self, motors: F64, env: Any = None) -> F64:
        """Sensor values ``(M, K)`` of the motor rows ``(M, N)``."""
    def poses(self, motors: F64) -> F64:
        """The observer's poses ``(M, d)`` of the motor rows ``(M, N)``."""

class PythonAgent(Agent):
    """An agent whose law is Python: ``sense(motors (B, N)) -> (B, K)`` float64,
    called in batches, and optionally ``pose(motors (B, N)) -> (B, d)``, the ground
    truth: ``pose_space="planar"`` ``(x, y, alpha)``, d = 3, or ``"spatial"``
    ``(x, y, z, qw, qx, qy, qz)``, d = 7 (a position and a unit quaternion).
    ``motor_space``: per motor ``"hinge"``, ``("periodic", period)`` or
    ``("bounded", low, high)``; default ``N`` hinges. ``concurrent_sets`` kernel
    sets (1 to 4096) are traced at once by the sensory method, their readings gathered
    into one call of ``sense`` per round: ``sense`` must answer each row independently
    of the others in its batch. ``n_motors`` is 1 to 1000, ``n_sensors`` 1 to 100 000.

    ``thread_safe=False`` (the default): the engine never calls ``sense`` or ``pose``
    from two threads at once, so a simulator with one state (one MuJoCo ``MjData``
    written by ``sense``) is safe as it is written; the engine's other thread goes on
    stepping kernel sets meanwhile. ``thread_safe=True`` lets the engine's threads call
    them concurrently: a promise the user makes, that each call reads only its
    argument and writes only its result, or keeps its state per thread in
    ``threading.local()`` (each engine thread keeps one Python thread state for its
    whole life, so such state lasts from call to call). A wrong promise gives wrong
    readings, not an error.

    Ctrl-C stops a computation within about a second (``KeyboardInterrupt``); one
    blocked inside ``sense`` itself is abandoned and ends when ``sense`` returns."""

    def __init__(
        self,
        sense: Callable[[F64], F64],
        n_motors: int,
        n_sensors: int,
        motor_space: Optional[Sequence[MotorSpec]] = None,
        pose: Optional[Callable[[F64], F64]] = None,
        name: str = "python",
        pose_space: Literal["planar", "spatial"] = "planar",
        concurrent_sets: int = 256,
        thread_safe: bool = False,
    ) -> None: ...

def _explore(
    agent: Agent, params: str, workspace: Any = None, progress: Any = None
) -> Tuple[F64, Optional[F64], I64]: ...
def _trace(
    agent: Agent,
    motors: F64,
    params: str,
    env: Any = None,
    workspace: Any = None,
    progress: Progress = None,
) -> Tuple[npt.NDArray[np.float64], I64, I64, I64, str]: ...
def _distances(
    sets: npt.NDArray[np.float64],
    closed: Optional[I64],
    metric: MetricSpec,
    memory_limit_bytes: Optional[int] = None,
    progress: Progress = None,
    pieces: Optional[I64] = None,
) -> F64: ...
def _distance_tile(
    rows: npt.NDArray[np.float64],
    rows_closed: Optional[I64],
    cols: npt.NDArray[np.float64],
    cols_closed: Optional[I64],
    tile: Bounds,
    metric: MetricSpec,
    rows_pieces: Optional[I64] = None,
    cols_pieces: Optional[I64] = None,
) -> F64: ...
def register_metric(
    name: str,
    distance: Callable[..., float],
    *,
    summary: str = ...,
    is_metric: bool = ...,
    thread_safe: bool = ...,
    takes_period: bool = ...,
    identity: str = ...,
) -> None: ...
def _shutdown_engine() -> None: ...
def _learn_agent(
    agent: Agent,
    starts: F64,
    budget: str,
    params: str,
    env: Any = ...,
    memory_limit_bytes: Optional[int] = ...,
    progress: Optional[Callable[[str, int, int], Any]] = ...,
) -> Tuple[F64, I64, I64, I64, str, str, str]: ...
def _learn(
    motors: Sequence[F64],
    sensors: Sequence[F64],
    starts: F64,
    period: str,
    params: str,
    memory_limit_bytes: Optional[int] = ...,
    progress: Optional[Callable[[str, int, int], Any]] = ...,
) -> Tuple[F64, I64, I64, I64, str, str]: ...
def metrics() -> List[Tuple[str, str]]: ...
def _merge_tiles(m: int, tiles: Sequence[Tuple[Bounds, F64]]) -> F64: ...
def _knn(
    sets: npt.NDArray[np.float64],
    closed: Optional[I64],
    metric: MetricSpec,
    k: int,
    pivots: Optional[int],
    rows: Tuple[int, int],
    progress: Progress = None,
    pieces: Optional[I64] = None,
) -> Tuple[I64, F64]: ...
def _invariance(
    agent: Agent,
    motors: F64,
    params: str,
    envs: Sequence[Any],
    metric: MetricSpec,
    workspace: Any = None,
    progress: Progress = None,
) -> Tuple[str, I64, List[F64], List[F64]]: ...
def _embed(distances: F64, params: str, progress: Progress = None) -> Tuple[F64, str]: ...
def _analyze(
    distances: F64,
    poses: Optional[F64],
    params: str,
    progress: Progress = None,
    representation: Optional[F64] = None,
) -> str: ...
def _run(
    path: Union[str, PathLike[str]],
    out: Optional[Union[str, PathLike[str]]] = None,
    overrides: Sequence[str] = ...,
    force: bool = False,
    max_memory: Optional[int] = None,
    distances: Optional[Callable[..., F64]] = None,
    log: Optional[Callable[[str], Any]] = None,
    progress: Progress = None,
) -> Tuple[str, str]: ...
