"""`smspace.lerobot`: robot logs in the LeRobot dataset format, read by column names."""

import json

import numpy as np
import pytest

import smspace
import smspace.lerobot

pa = pytest.importorskip("pyarrow", reason="pyarrow is not installed")
import pyarrow.parquet as pq  # noqa: E402


def cart(samples, seed):
    rng = np.random.default_rng(seed)
    motors = rng.uniform(-np.pi, np.pi, size=(samples, 2))
    x = np.sin(motors[:, 0]) + 0.5 * np.sin(motors[:, 1])
    return motors, np.stack([x, 0.5 * x**2], axis=1)


def write_dataset(root, motors, sensors, episodes=2, version="v2.1"):
    """A LeRobot dataset of `episodes` episodes as the LeRobot writer lays it out."""
    (root / "meta").mkdir(parents=True)
    info = {
        "codebase_version": version,
        "robot_type": "cart",
        "total_episodes": episodes,
        "total_frames": len(motors),
        "fps": 30,
        "data_path": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
        "features": {
            "observation.state": {"dtype": "float32", "shape": [2],
                                  "names": {"motors": ["hip", "knee"]}},
            "observation.environment_state": {"dtype": "float32", "shape": [2], "names": None},
            "observation.images.top": {"dtype": "video", "shape": [48, 64, 3],
                                       "names": ["height", "width", "channel"]},
            "timestamp": {"dtype": "float32", "shape": [1], "names": None},
            "frame_index": {"dtype": "int64", "shape": [1], "names": None},
            "episode_index": {"dtype": "int64", "shape": [1], "names": None},
        },
    }
    (root / "meta" / "info.json").write_text(json.dumps(info))
    bounds = np.linspace(0, len(motors), episodes + 1).astype(int)
    for e in range(episodes):
        rows = slice(bounds[e], bounds[e + 1])
        count = bounds[e + 1] - bounds[e]
        table = pa.table({
            "observation.state": pa.array(motors[rows].tolist(), type=pa.list_(pa.float64(), 2)),
            "observation.environment_state": pa.array(sensors[rows].tolist(),
                                                      type=pa.list_(pa.float64(), 2)),
            "timestamp": pa.array(np.arange(count) / 30.0, type=pa.float32()),
            "frame_index": pa.array(np.arange(count), type=pa.int64()),
            "episode_index": pa.array(np.full(count, e), type=pa.int64()),
        })
        path = root / "data" / "chunk-000" / f"episode_{e:06d}.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, path)


def test_a_lerobot_log_is_read_by_column_names_and_learned(tmp_path):
    motors, sensors = cart(12000, seed=2)
    write_dataset(tmp_path / "cart", motors, sensors)
    log = smspace.lerobot.read(tmp_path / "cart", motors="observation.state",
                               sensors="observation.environment_state")
    assert np.array_equal(log.motors, motors) and np.array_equal(log.sensors, sensors)
    assert log.motor_names == ["observation.state[hip]", "observation.state[knee]"]
    assert log.fps == 30.0 and len(log) == 12000
    assert np.array_equal(np.unique(log.episodes), [0, 1])
    # One element by its name, one by its position; one episode.
    one = smspace.lerobot.read(tmp_path / "cart", motors=["observation.state[knee]"],
                               sensors=["observation.environment_state[0]"], episodes=[1])
    assert np.array_equal(one.motors[:, 0], motors[6000:, 1])
    assert np.array_equal(one.sensors[:, 0], sensors[6000:, 0])
    # Learned from the dataset, the sets are those learned from the arrays.
    starts = np.array([[0.3, 0.2], [-0.6, 0.4]])
    from_log = smspace.learn(log.motors, log.sensors, starts, points=30, seed=3)
    direct = smspace.learn(motors, sensors, starts, points=30, seed=3)
    assert np.array_equal(from_log.sets, direct.sets)
    degrees = smspace.lerobot.read(tmp_path / "cart", motors="observation.state",
                                   sensors="observation.environment_state", degrees=True)
    assert np.allclose(degrees.motors, np.deg2rad(motors))


def test_bad_datasets_and_names_are_refused_with_the_fix(tmp_path):
    motors, sensors = cart(200, seed=1)
    root = tmp_path / "cart"
    write_dataset(root, motors, sensors)
    with pytest.raises(FileNotFoundError, match="meta/info.json"):
        smspace.lerobot.read(tmp_path, "observation.state", "observation.environment_state")
    with pytest.raises(ValueError, match="no feature 'action'"):
        smspace.lerobot.read(root, "action", "observation.environment_state")
    with pytest.raises(ValueError, match="no element 'ankle'.*hip"):
        smspace.lerobot.read(root, "observation.state[ankle]", "observation.environment_state")
    with pytest.raises(ValueError, match="has 2 elements"):
        smspace.lerobot.read(root, "observation.state[5]", "observation.environment_state")
    with pytest.raises(ValueError, match="video"):
        smspace.lerobot.read(root, "observation.state", "observation.images.top")
    with pytest.raises(MemoryError, match="max_bytes"):
        smspace.lerobot.read(root, "observation.state", "observation.environment_state",
                             max_bytes=1000)
    bad = sensors.copy()
    bad[150, 1] = np.nan
    write_dataset(tmp_path / "nan", motors, bad)
    with pytest.raises(ValueError, match="episode 1 frame 50 hold a non-finite"):
        smspace.lerobot.read(tmp_path / "nan", "observation.state",
                             "observation.environment_state")
