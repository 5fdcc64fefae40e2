"""The Python API against the command-line tool on the same inputs: equal arrays."""

import json

import numpy as np
import pytest

import smspace


def test_stages_equal_the_cli(cli, tmp_path):
    agent = smspace.Agent.preset("planar-arm")
    cli("explore", "--agent", "planar-arm", "--n", 30, "--seed", 3, "--out-dir", tmp_path)
    found = smspace.explore(agent, n=30, seed=3)
    assert np.array_equal(found.motors, np.load(tmp_path / "motors.npy"))
    assert np.array_equal(found.poses, np.load(tmp_path / "poses.npy"))
    assert np.array_equal(found.probes, np.load(tmp_path / "probes.npy"))

    cli("trace", "--agent", "planar-arm", "--motors", tmp_path / "motors.npy",
        "--points", 25, "--out", tmp_path / "sets.npy")
    traced = smspace.trace(agent, found.motors, points=25)
    assert np.array_equal(traced.sets, np.load(tmp_path / "sets.npy"))
    assert np.array_equal(traced.kept, np.load(tmp_path / "sets.kept.npy"))
    assert np.array_equal(traced.closed, np.load(tmp_path / "sets.closed.npy"))
    assert traced.report == json.loads((tmp_path / "sets.trace.json").read_text())

    cli("distances", "--sets", tmp_path / "sets.npy", "--metric", "curve", "--out", tmp_path / "D.npy")
    D = smspace.distances(traced, metric="curve")
    assert np.array_equal(D, np.load(tmp_path / "D.npy"))

    cli("embed", "--distances", tmp_path / "D.npy", "--method", "cca", "--dim", 2,
        "--seed", 4, "--out", tmp_path / "Y.npy")
    Y = smspace.embed(D, method="cca", dim=2, seed=4)
    assert np.array_equal(Y, np.load(tmp_path / "Y.npy"))

    poses = found.poses[traced.kept]
    np.save(tmp_path / "poses.npy", poses)
    cli("analyze", "--distances", tmp_path / "D.npy", "--poses", tmp_path / "poses.npy",
        "--out", tmp_path / "analysis.json")
    report = smspace.analyze(D, poses=poses)
    assert report == json.loads((tmp_path / "analysis.json").read_text())


def test_sensory_trace_equals_the_cli(cli, tmp_path):
    agent = smspace.Agent.preset("planar-arm")
    found = smspace.explore(agent, n=12, seed=8)
    np.save(tmp_path / "motors.npy", found.motors)
    cli("trace", "--agent", "planar-arm", "--motors", tmp_path / "motors.npy", "--method", "sensory",
        "--env-seed", 2, "--points", 20, "--out", tmp_path / "sets.npy")
    traced = smspace.trace(agent, found.motors, method="sensory", env=2, points=20)
    assert np.array_equal(traced.sets, np.load(tmp_path / "sets.npy"))
    assert np.array_equal(traced.kept, np.load(tmp_path / "sets.kept.npy"))


def test_point_metric_equals_the_cli(cli, tmp_path):
    sets = np.random.default_rng(1).uniform(-3, 3, size=(9, 7, 3))
    np.save(tmp_path / "sets.npy", sets)
    for metric, period in [("hausdorff", "none"), ("mean-hausdorff", "2pi")]:
        cli("distances", "--sets", tmp_path / "sets.npy", "--metric", metric, "--period", period,
            "--out", tmp_path / "D.npy")
        D = smspace.distances(sets, metric=metric, period=period)
        assert np.array_equal(D, np.load(tmp_path / "D.npy")), metric


def _closed_curves(m, p, seed):
    """``m`` closed curves of ``p`` points on the 4-torus, wrapped into [-pi, pi)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2.0 * np.pi, p, endpoint=False)
    centres = rng.uniform(-np.pi, np.pi, size=(m, 1, 4))
    radii = rng.uniform(0.2, 0.8, size=(m, 1, 4))
    phases = rng.uniform(0.0, 2.0 * np.pi, size=(m, 1, 4))
    sets = centres + radii * np.cos(t[None, :, None] + phases)
    return np.mod(sets + np.pi, 2.0 * np.pi) - np.pi


def test_the_default_metric_is_the_same_behind_every_door(cli, tmp_path):
    """``smspace distances`` and ``smspace.distances`` given no metric or period compute
    the same matrix from one sets file: the library's default (curve under 2pi), not the
    point metric's."""
    sets = _closed_curves(11, 9, seed=4)
    closed = np.array([1, 0] * 5 + [1], dtype=np.int64)
    np.save(tmp_path / "sets.npy", sets)
    np.save(tmp_path / "sets.closed.npy", closed)
    cli("distances", "--sets", tmp_path / "sets.npy", "--out", tmp_path / "D.npy")
    from_cli = np.load(tmp_path / "D.npy")
    D = smspace.distances(sets, closed=closed)
    assert np.array_equal(D, from_cli)
    assert np.array_equal(D, smspace.distances(sets, metric="curve", period="2pi", closed=closed))
    assert not np.array_equal(D, smspace.distances(sets, metric="hausdorff"))
    indices, distances = smspace.knn(sets, 3, closed=closed)
    cli("distances", "--sets", tmp_path / "sets.npy", "--knn", 3, "--out", tmp_path / "K.npy")
    assert np.array_equal(indices, np.load(tmp_path / "knn_indices.npy"))
    assert np.array_equal(distances, np.load(tmp_path / "knn_distances.npy"))


def test_the_stage_defaults_are_the_same_behind_every_door(cli, tmp_path):
    """The other stages' defaults agree too: exploration (n, seed), tracing (method,
    points) and the embedding (method, dim, seed), each given no argument."""
    agent = smspace.Agent.preset("planar-arm")
    cli("explore", "--agent", "planar-arm", "--out-dir", tmp_path)
    found = smspace.explore(agent)
    assert np.array_equal(found.motors, np.load(tmp_path / "motors.npy"))
    starts = found.motors[:12]
    np.save(tmp_path / "starts.npy", starts)
    cli("trace", "--agent", "planar-arm", "--motors", tmp_path / "starts.npy",
        "--out", tmp_path / "sets.npy")
    traced = smspace.trace(agent, starts)
    assert np.array_equal(traced.sets, np.load(tmp_path / "sets.npy"))
    D = smspace.distances(traced)
    np.save(tmp_path / "D.npy", D)
    cli("embed", "--distances", tmp_path / "D.npy", "--out", tmp_path / "Y.npy")
    assert np.array_equal(smspace.embed(D), np.load(tmp_path / "Y.npy"))


def test_run_equals_the_cli(cli, root, tmp_path):
    experiment = root / "experiments" / "paper-toy-redundant.toml"
    overrides = {"exploration.n": 60, "kernel.points": 12, "report.formats": "svg"}
    sets = [f"{k}={v}" for k, v in overrides.items()]
    cli("run", experiment, "--out", tmp_path / "cli", *[a for s in sets for a in ("--set", s)])
    run = smspace.run(experiment, out=tmp_path / "py", overrides=overrides)
    assert run.dir == tmp_path / "py"
    for name in ["motors", "sets", "D", "Y"]:
        assert np.array_equal(run.arrays[name], np.load(tmp_path / "cli" / f"{name}.npy")), name
    assert run.report == json.loads((tmp_path / "cli" / "analysis.json").read_text())
    assert run.report["betti"][0] == 1
    assert np.array_equal(run.D, run.arrays["D"])
    with pytest.raises(AttributeError, match=r"wrote no nothing\.npy; its arrays: .*\bD\b"):
        run.nothing
    # A second run reuses every stage (and says so through log=).
    lines = []
    again = smspace.run(experiment, out=tmp_path / "py", overrides=overrides, log=lines.append)
    assert np.array_equal(again.D, run.D)
    stages = [line for line in lines if "skipped" not in line]
    assert len(stages) == 6 and all("reused" in line for line in stages), lines


def test_metric_parameters_reach_the_metric_behind_both_doors(cli, tmp_path):
    """``params=`` of :func:`smspace.distances` and :func:`smspace.knn` is the metric's
    ``[metric.params]`` table, as ``smspace distances --param`` sets it: the same
    matrix from the same words, and the same refusals."""
    rng = np.random.default_rng(5)
    grid = np.stack(np.meshgrid(np.arange(5), np.arange(5), indexing="ij"), -1).reshape(-1, 2) * 0.3
    sets = np.empty((7, 25, 3))
    for s in range(7):
        sets[s, :, :2] = grid + rng.uniform(-0.05, 0.05, size=(25, 2))
        sets[s, :, 2] = np.sin(0.4 * s) + 0.02 * rng.standard_normal(25)
    np.save(tmp_path / "planes.npy", sets)
    cli("distances", "--sets", tmp_path / "planes.npy", "--metric", "surface", "--period", "none",
        "--param", "radius_scale=0.5", "--param", "neighbours=6", "--out", tmp_path / "D.npy")
    params = {"radius_scale": 0.5, "neighbours": 6}
    D = smspace.distances(sets, metric="surface", period="none", params=params)
    assert np.array_equal(D, np.load(tmp_path / "D.npy"))
    assert not np.array_equal(D, smspace.distances(sets, metric="surface", period="none"))
    indices, near = smspace.knn(sets, 2, metric="surface", period="none", params=params)
    assert np.array_equal(near[:, 0], np.sort(D + np.diag(np.full(7, np.inf)), axis=1)[:, 0])
    with pytest.raises(ValueError, match="dimension"):
        smspace.distances(sets, metric="hausdorff", period="none", params={"dimension": 2})
    with pytest.raises(ValueError, match="radius_scale"):
        smspace.distances(sets, metric="surface", period="none", params={"radius_scale": -1.0})
    with pytest.raises(TypeError, match="dict"):
        smspace.distances(sets, metric="surface", period="none", params=[("radius_scale", 1.0)])


def test_invariance_equals_the_cli(cli, tmp_path):
    """``smspace.invariance`` and ``smspace invariance`` on the same starts and
    environments: the same report and arrays; bad input refused."""
    x = -2.0 + 0.35 * np.arange(12)
    motors = np.stack([0.6 * x, 0.4 * x], axis=1)
    np.save(tmp_path / "motors.npy", motors)
    cli("invariance", "--agent", "toy-redundant", "--motors", tmp_path / "motors.npy",
        "--env-seeds", "1,2,3", "--points", 20, "--metric", "hausdorff", "--period", "motors",
        "--out", tmp_path / "invariance.json")
    agent = smspace.Agent.preset("toy-redundant")
    found = smspace.invariance(agent, motors, [1, 2, 3], points=20, metric="hausdorff",
                               period="motors")
    assert found.report == json.loads((tmp_path / "invariance.json").read_text())
    for e in range(3):
        assert np.array_equal(found.distances[e], np.load(tmp_path / f"invariance-D-{e + 1}.npy"))
        assert np.array_equal(found.sensors[e], np.load(tmp_path / f"invariance-sensors-{e + 1}.npy"))
    assert found.report["max_set_distance_relative"] < 1e-6
    assert len(found.rows) == found.report["common_sets"]
    five = smspace.invariance(agent, motors, [1, 2], points=20, starts=5)
    assert five.report["starts"] == 5
    with pytest.raises(ValueError, match="at least two"):
        smspace.invariance(agent, motors, [1])
    with pytest.raises(ValueError, match="starts=0"):
        smspace.invariance(agent, motors, [1, 2], starts=0)
    with pytest.raises(ValueError, match="period"):
        smspace.invariance(agent, motors, [1, 2], period="2pi,none,none")
    python_agent = smspace.PythonAgent(sense=lambda m: np.sin(m), n_motors=2, n_sensors=2)
    with pytest.raises(ValueError, match="own world"):
        smspace.invariance(python_agent, motors, [1, 2])
