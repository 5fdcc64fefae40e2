"""Distance matrices on a Dask cluster (``dask.distributed``).

The matrix of ``M`` kernel sets is cut into triangular tiles: blocks of ``tile`` sets,
block ``a`` against every block ``b >= a``, so that every pair ``{i, j}`` is computed
once (:func:`smspace.tile_plan`). Each tile is one task, which calls the engine's tile
function on the sets of its rows and columns with the GIL released (on all the
worker's cores); the tiles are merged into the matrix, which is the single-machine
matrix bit for bit (inside a tile the pair ``{i, j}`` is the very call the whole
matrix makes). ::

    from dask.distributed import Client
    import smspace, smspace.dask

    client = Client("tcp://scheduler:8786")              # or Client(LocalCluster(...))
    D = smspace.dask.distances(traced, client, metric="curve", tile=500)
    run = smspace.run("experiments/paper-arm.toml", client=client,   # the distance stage there
                      overrides={"scale.path": "dense"})             # (the dense path's tiles)

Memory of one task: its output ``r × c × 8`` bytes (``tile² × 8``: 2 MB for
``tile=500``) plus the sets it reads, ``(r + c) × P × N × 8`` bytes and about as much
again for the engine's prepared copies (the curve metric's segments), plus the whole
``(M, P, N)`` sets array, which is sent once to every worker (``scatter(...,
broadcast=True)``; 8 MB for the paper's 2500 × 100 × 4). The client holds the merged
``M × M × 8`` bytes (50 MB for 2500 sets) and the tiles while they arrive.
"""

from __future__ import annotations

import json
import math
from typing import Any, Callable, Optional, Union

import numpy as np

from . import _DEFAULTS, Traced, _core, _metric_spec, _progress, _sets_args, tile_plan

__all__ = ["distances", "knn", "default_tile", "WorkersDied"]


def default_tile(sets: int, workers: int) -> int:
    """A tile size giving about four tasks per worker (at least 64 sets a side, so
    that a task's work outweighs its scheduling)."""
    blocks = max(1, math.isqrt(8 * max(1, workers)))
    return max(64, math.ceil(sets / blocks))


def _workers(client: Any) -> int:
    try:
        return max(1, len(client.scheduler_info().get("workers", {})))
    except Exception:  # noqa: BLE001 (a client of any kind: count one worker)
        return 1


class WorkersDied(RuntimeError):
    """The Dask cluster lost a task because its workers died (killed, out of memory,
    or the cluster shut down): the computation cannot finish there."""


#: Exception classes (by name, across ``distributed`` versions) that mean the task
#: was lost with its worker rather than failed by itself.
_LOST_TASK = ("KilledWorker", "FutureCancelledError", "CancelledError")


def _result(future: Any, what: str) -> Any:
    """``future.result()``, with a lost task (its workers died) raised as
    :class:`WorkersDied` naming ``what`` and the way out; the task's own errors (the
    engine's ``ValueError``...) pass unchanged."""
    try:
        return future.result()
    except BaseException as error:  # noqa: BLE001 (classified by name below)
        names = {cls.__name__ for cls in type(error).__mro__}
        if not names.intersection(_LOST_TASK):
            raise
        raise WorkersDied(
            f"the Dask cluster lost {what}: its workers died or were killed "
            f"({type(error).__name__}: {error}); nothing was returned. Restart the "
            "workers (or give the client a running cluster) and call again; "
            "smspace.run keeps the stages it finished"
        ) from error


def _aligned(array: np.ndarray) -> np.ndarray:
    """``array``, copied only when its buffer is unaligned (an unpickled one may be)."""
    return array if array.flags.aligned else array.copy()


def _tile_task(
    points: np.ndarray,
    codes: Optional[np.ndarray],
    pieces: Optional[np.ndarray],
    bounds: tuple,
    metric: dict,
) -> np.ndarray:
    """One task: the block ``D[r0:r1, c0:c1]`` (runs on a worker)."""
    from smspace import _core as core

    points = _aligned(points)
    codes = None if codes is None else _aligned(codes)
    pieces = None if pieces is None else _aligned(pieces)
    r0, r1, c0, c1 = bounds

    def part(array: Optional[np.ndarray], start: int, end: int) -> Optional[np.ndarray]:
        return None if array is None else array[start:end]

    return core._distance_tile(
        points[r0:r1],
        part(codes, r0, r1),
        points[c0:c1],
        part(codes, c0, c1),
        bounds,
        metric,
        part(pieces, r0, r1),
        part(pieces, c0, c1),
    )


def _knn_task(
    points: np.ndarray,
    codes: Optional[np.ndarray],
    pieces: Optional[np.ndarray],
    rows: tuple,
    metric: dict,
    k: int,
    pivots: Optional[int],
) -> tuple:
    """One task: the ``k`` nearest sets of the rows ``r0:r1`` (runs on a worker)."""
    from smspace import _core as core

    points = _aligned(points)
    codes = None if codes is None else _aligned(codes)
    pieces = None if pieces is None else _aligned(pieces)
    return core._knn(points, codes, metric, k, pivots, rows, None, pieces)


def _checked_spec(
    spec: dict, points: np.ndarray, codes: Optional[np.ndarray], pieces: Optional[np.ndarray]
) -> dict:
    """``spec`` without its trace report, after the engine's checks (an unknown metric
    or parameter, curve without closures, kernels the metric does not take) on the
    first two sets, before anything is sent to the cluster."""
    if points.shape[0] >= 2:
        _core._distances(points[:2], None if codes is None else codes[:2], spec, None, None,
                         None if pieces is None else pieces[:2])
    return dict(spec, report=None)


def _scatter(client: Any, *arrays: Optional[np.ndarray]) -> tuple:
    """Each array sent once to every worker (None stays None)."""
    futures = []
    for array in arrays:
        if array is None:
            futures.append(None)
            continue
        # Unique keys (hash=False): a content key shared with an earlier call could be
        # released by it while this one still needs it.
        [future] = client.scatter([np.ascontiguousarray(array)], broadcast=True, hash=False)
        futures.append(future)
    return tuple(futures)


def distances(
    sets: Union[Traced, np.ndarray],
    client: Any,
    metric: str = _DEFAULTS["metric"],
    period: str = _DEFAULTS["period"],
    *,
    params: Optional[dict] = None,
    tile: Optional[int] = None,
    knn: Optional[int] = None,
    closed: Any = None,
    pieces: Any = None,
    progress: Any = None,
) -> Any:
    """The ``(M, M)`` matrix of :func:`smspace.distances`, computed in triangular tiles
    of ``tile`` sets a side (default :func:`default_tile`) on ``client``'s cluster;
    equal to the local matrix bit for bit. With ``knn=K``: :func:`knn` instead."""
    if knn is not None:
        return globals()["knn"](
            sets,
            client,
            knn,
            metric=metric,
            period=period,
            params=params,
            rows=tile,
            closed=closed,
            pieces=pieces,
            progress=progress,
        )
    from distributed import as_completed

    points, codes, pieces = _sets_args(sets, closed, pieces)
    spec = _checked_spec(_metric_spec(metric, period, params, sets), points, codes, pieces)
    m = points.shape[0]
    size = tile or default_tile(m, _workers(client))
    plan = tile_plan(m, size)
    points_future, codes_future, pieces_future = _scatter(client, points, codes, pieces)
    futures = {
        client.submit(
            _tile_task,
            points_future,
            codes_future,
            pieces_future,
            bounds,
            spec,
            pure=False,
        ): bounds
        for bounds in plan
    }
    report = _progress(progress)
    total = sum(
        (r1 - r0) * (c1 - c0) if r0 != c0 else (r1 - r0) * (r1 - r0 - 1) // 2
        for r0, r1, c0, c1 in plan
    )
    done = 0
    if report is not None:
        report("distances", 0, total)
    tiles = []
    for future in as_completed(futures):
        bounds = futures[future]
        tiles.append((bounds, _aligned(_result(future, f"the task of tile {bounds}"))))
        r0, r1, c0, c1 = bounds
        done += (r1 - r0) * (c1 - c0) if r0 != c0 else (r1 - r0) * (r1 - r0 - 1) // 2
        if report is not None:
            report("distances", done, total)
    return _core._merge_tiles(m, tiles)


def knn(
    sets: Union[Traced, np.ndarray],
    client: Any,
    k: int,
    metric: str = _DEFAULTS["metric"],
    period: str = _DEFAULTS["period"],
    *,
    params: Optional[dict] = None,
    rows: Optional[int] = None,
    pivots: Optional[int] = None,
    closed: Any = None,
    pieces: Any = None,
    progress: Any = None,
) -> tuple:
    """The ``k`` nearest sets of every set, as :func:`smspace.knn`, in tasks of
    ``rows`` query rows each (every task reads all the sets, sent once per worker):
    ``(indices (M, k) int64, distances (M, k))``, equal to the local search."""
    points, codes, pieces = _sets_args(sets, closed, pieces)
    spec = _checked_spec(_metric_spec(metric, period, params, sets), points, codes, pieces)
    m = points.shape[0]
    size = rows or default_tile(m, _workers(client))
    blocks = [(start, min(start + size, m)) for start in range(0, m, size)]
    points_future, codes_future, pieces_future = _scatter(client, points, codes, pieces)
    futures = [
        client.submit(
            _knn_task,
            points_future,
            codes_future,
            pieces_future,
            block,
            spec,
            int(k),
            pivots,
            pure=False,
        )
        for block in blocks
    ]
    report = _progress(progress)
    parts = []
    for index, future in enumerate(futures):
        parts.append(_result(future, f"the task of rows {blocks[index]}"))
        if report is not None:
            report("knn", blocks[index][1], m)
    # (np.concatenate copies into fresh, aligned arrays.)
    indices = np.concatenate([p[0] for p in parts], axis=0)
    found = np.concatenate([p[1] for p in parts], axis=0)
    return indices, found


def _stage_backend(client: Any, tile: Optional[int]) -> Callable[..., np.ndarray]:
    """The pipeline's distance stage on ``client`` (``smspace.run(..., client=)``):
    called by the engine with the traced sets, their closed/open codes, the metric's
    name, the period, the piece of every point (or None) and the metric's parameters
    (the JSON of the ``[metric.params]`` table)."""

    def compute(
        points: np.ndarray,
        codes: Optional[np.ndarray],
        metric: str,
        period: str,
        pieces: Optional[np.ndarray] = None,
        params: Optional[str] = None,
    ) -> np.ndarray:
        table = None if params is None else json.loads(params)
        return distances(points, client, metric, period, params=table, tile=tile, closed=codes,
                         pieces=pieces)

    return compute
