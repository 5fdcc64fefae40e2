"""Robot logs in the LeRobot dataset format, as logs for :func:`smspace.learn`.

A LeRobot dataset (``codebase_version`` v2.x or v3.0) is a folder with
``meta/info.json``, which describes every *feature* (a column: its ``dtype``, its
``shape`` and, for vectors, the ``names`` of its elements), and parquet tables under
``data/`` with one row per frame (``episode_index``, ``frame_index``, ``timestamp`` and
one column per feature; a vector feature is a list column). ::

    import smspace, smspace.lerobot
    log = smspace.lerobot.read("so100_dataset",
                               motors="observation.state",
                               sensors=["observation.environment_state"])
    traced = smspace.learn(log.motors, log.sensors, starts)

Columns are chosen by name: ``"observation.state"`` takes every element of the feature,
``"observation.state[shoulder_pan]"`` one element by its name in ``info.json`` and
``"observation.state[0]"`` one by position. Motors must be in radians for
``period="2pi"`` (the default of :func:`smspace.learn`; LeRobot's SO-100 arms log
degrees: pass ``degrees=True``). Frames stored in the table as images (``dtype``
``"image"``, PNG bytes) are decoded with Pillow and become ``H W C`` sensors a frame,
as :func:`smspace.learn` reads camera frames; features stored as videos (``dtype``
``"video"``, MP4 files) are not decoded here: decode them with the video library of
your choice and pass the frames as ``(S, H, W[, C])`` arrays.

Reading needs ``pyarrow`` (``pip install pyarrow``). A row with a non-finite value is
refused with its file, episode and frame; the arrays' size is checked against
``max_bytes`` before they are allocated.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, List, Optional, Sequence, Union

import numpy as np

__all__ = ["RobotLog", "read", "features"]

_SPEC = re.compile(r"^(?P<feature>[^\[\]]+?)(\[(?P<element>[^\[\]]+)\])?$")


@dataclass
class RobotLog:
    """A log read from a LeRobot dataset: ``motors`` ``(S, N)``, ``sensors`` ``(S, K)``
    (float64), and for every row its ``episodes`` and ``frames`` index; the names of the
    columns chosen (``feature[element]``) and the dataset's ``fps``."""

    motors: np.ndarray
    sensors: np.ndarray
    episodes: np.ndarray
    frames: np.ndarray
    motor_names: List[str] = field(default_factory=list)
    sensor_names: List[str] = field(default_factory=list)
    fps: Optional[float] = None

    def __len__(self) -> int:
        return len(self.motors)


def _pyarrow():
    try:
        import pyarrow.parquet as pq
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError(
            "smspace.lerobot reads parquet tables with pyarrow: pip install pyarrow"
        ) from error
    return pq


def _info(root: Path) -> dict:
    path = root / "meta" / "info.json"
    if not path.is_file():
        raise FileNotFoundError(
            f"{path} not found: a LeRobot dataset has meta/info.json (is {root} the dataset's folder?)"
        )
    try:
        info = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path} is not JSON: {error}") from error
    if not isinstance(info.get("features"), dict):
        raise ValueError(f"{path} has no 'features' table")
    return info


def features(root: Union[str, Path]) -> dict:
    """The dataset's features as ``info.json`` gives them: name → ``dtype``, ``shape``,
    ``names``."""
    return _info(Path(root))["features"]


def _element_names(feature: dict) -> Optional[List[str]]:
    names = feature.get("names")
    if isinstance(names, dict):
        # {"motors": [...]} or {"axes": [...]}: the one list.
        lists = [v for v in names.values() if isinstance(v, list)]
        names = lists[0] if len(lists) == 1 else None
    if isinstance(names, list) and all(isinstance(n, str) for n in names):
        return names
    return None


@dataclass
class _Column:
    feature: str
    dtype: str
    positions: Optional[List[int]]  # None: every element
    names: List[str]  # of the elements taken
    width: int  # of the whole feature


def _columns(specs: Union[str, Sequence[str]], info: dict, what: str) -> List[_Column]:
    if isinstance(specs, str):
        specs = [specs]
    if not specs:
        raise ValueError(f"{what}: no column named; give a feature, e.g. 'observation.state'")
    table = info["features"]
    out = []
    for spec in specs:
        match = _SPEC.match(spec.strip())
        if match is None:
            raise ValueError(f"{what}: {spec!r} is not 'feature' or 'feature[element]'")
        name, element = match.group("feature"), match.group("element")
        if name not in table:
            raise ValueError(
                f"{what}: no feature {name!r} in the dataset; it has {sorted(table)}"
            )
        feature = table[name]
        dtype = str(feature.get("dtype", ""))
        if dtype == "video":
            raise ValueError(
                f"{what}: {name!r} is stored as video files, which this reader does not decode; "
                "decode the frames and pass them as an (S, H, W[, C]) array"
            )
        shape = [int(s) for s in feature.get("shape", [1])]
        width = int(np.prod(shape)) if shape else 1
        names = _element_names(feature) if dtype != "image" else None
        if element is None:
            labels = (
                [f"{name}[{n}]" for n in names]
                if names is not None and len(names) == width
                else [f"{name}[{i}]" for i in range(width)]
            )
            out.append(_Column(name, dtype, None, labels, width))
            continue
        if dtype == "image":
            raise ValueError(f"{what}: {spec!r}: an image feature is taken whole")
        if element.isdigit():
            position = int(element)
            if position >= width:
                raise ValueError(
                    f"{what}: {spec!r}: {name!r} has {width} elements (0 to {width - 1})"
                )
        elif names is not None and element in names:
            position = names.index(element)
        else:
            raise ValueError(
                f"{what}: {spec!r}: {name!r} has no element {element!r}; its names are {names}"
            )
        out.append(_Column(name, dtype, [position], [f"{name}[{element}]"], width))
    return out


def _data_files(root: Path, info: dict) -> List[Path]:
    files = sorted((root / "data").glob("**/*.parquet"))
    if not files:
        raise FileNotFoundError(
            f"no parquet table under {root / 'data'}: the dataset has no frames"
        )
    return files


def _decode_images(values: Sequence[Any], name: str, path: Path) -> np.ndarray:
    try:
        from PIL import Image
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError(
            f"{name} holds images (PNG in {path}): decoding them needs Pillow (pip install pillow)"
        ) from error
    import io

    frames = []
    for value in values:
        data = value.get("bytes") if isinstance(value, dict) else value
        if data is None:
            raise ValueError(f"{path}: an image of {name} has no bytes (stored as a path?)")
        frame = np.asarray(Image.open(io.BytesIO(data)), dtype=np.float64)
        frames.append(frame.reshape(-1))
    return np.stack(frames) if frames else np.empty((0, 0))


def _block(table: Any, column: _Column, path: Path) -> np.ndarray:
    if column.feature not in table.column_names:
        raise ValueError(
            f"{path} has no column {column.feature!r} although meta/info.json lists it"
        )
    values = table.column(column.feature).to_pylist()
    if column.dtype == "image":
        block = _decode_images(values, column.feature, path)
    else:
        block = np.asarray(
            [v if isinstance(v, (list, tuple)) else [v] for v in values], dtype=np.float64
        )
        if block.ndim != 2:
            raise ValueError(
                f"{path}: the rows of {column.feature!r} do not all have {column.width} elements"
            )
    if block.shape[1] != column.width:
        raise ValueError(
            f"{path}: {column.feature!r} has {block.shape[1]} values a row, "
            f"meta/info.json says {column.width}"
        )
    return block if column.positions is None else block[:, column.positions]


def read(
    root: Union[str, Path],
    motors: Union[str, Sequence[str]],
    sensors: Union[str, Sequence[str]],
    *,
    episodes: Optional[Iterable[int]] = None,
    degrees: bool = False,
    max_bytes: int = 16 << 30,
) -> RobotLog:
    """The log of the dataset at ``root``: the ``motors`` and ``sensors`` columns (a
    feature name, ``feature[element]`` or a list of them; module docs) of every frame,
    or of the ``episodes`` given. ``degrees=True`` converts the motors to radians. The
    rows are in the order of the tables (episode, then frame)."""
    root = Path(root)
    info = _info(root)
    pq = _pyarrow()
    motor_columns = _columns(motors, info, "motors")
    sensor_columns = _columns(sensors, info, "sensors")
    wanted = None if episodes is None else {int(e) for e in episodes}
    files = _data_files(root, info)
    # The size, from the tables' metadata, before anything is read.
    rows = sum(pq.ParquetFile(path).metadata.num_rows for path in files)
    width = sum(len(c.names) for c in motor_columns + sensor_columns)
    if rows * width * 8 > max_bytes:
        raise MemoryError(
            f"{root}: {rows} frames × {width} values is {rows * width * 8} bytes, more than "
            f"max_bytes = {max_bytes}; read fewer episodes or columns, or raise max_bytes"
        )
    parts_m, parts_s, parts_e, parts_f = [], [], [], []
    needed = ["episode_index", "frame_index"] + sorted(
        {c.feature for c in motor_columns + sensor_columns}
    )
    for path in files:
        present = set(pq.ParquetFile(path).schema_arrow.names)
        for key in needed:
            if key not in present:
                raise ValueError(
                    f"{path} has no column {key!r}"
                    + ("" if key.endswith("_index") else " although meta/info.json lists it")
                    + ("" if not key.endswith("_index") else ": not a LeRobot data table")
                )
        # Only the columns asked for (a table may hold images that are not).
        table = pq.read_table(path, columns=needed)
        episode = np.asarray(table.column("episode_index").to_pylist(), dtype=np.int64)
        frame = np.asarray(table.column("frame_index").to_pylist(), dtype=np.int64)
        keep = np.ones(len(episode), dtype=bool) if wanted is None else np.isin(episode, list(wanted))
        if not keep.any():
            continue
        if not keep.all():
            table = table.filter(keep)
            episode, frame = episode[keep], frame[keep]
        m = np.hstack([_block(table, c, path) for c in motor_columns])
        s = np.hstack([_block(table, c, path) for c in sensor_columns])
        for what, block in (("motors", m), ("sensors", s)):
            bad = np.flatnonzero(~np.isfinite(block).all(axis=1))
            if bad.size:
                r = bad[0]
                raise ValueError(
                    f"{path}: the {what} of episode {episode[r]} frame {frame[r]} hold a "
                    f"non-finite value ({bad.size} such rows); drop those frames first"
                )
        parts_m.append(m)
        parts_s.append(s)
        parts_e.append(episode)
        parts_f.append(frame)
    if not parts_m:
        raise ValueError(f"{root}: no frame of the episodes {sorted(wanted or [])}")
    motors_array = np.vstack(parts_m)
    if degrees:
        motors_array = np.deg2rad(motors_array)
    return RobotLog(
        motors=np.ascontiguousarray(motors_array),
        sensors=np.ascontiguousarray(np.vstack(parts_s)),
        episodes=np.concatenate(parts_e),
        frames=np.concatenate(parts_f),
        motor_names=[n for c in motor_columns for n in c.names],
        sensor_names=[n for c in sensor_columns for n in c.names],
        fps=float(info["fps"]) if isinstance(info.get("fps"), (int, float)) else None,
    )
