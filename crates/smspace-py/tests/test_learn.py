"""`smspace.learn`: kernel sets from recorded logs, as `smspace learn` computes them."""

import numpy as np
import pytest

import smspace


def cart_log(samples: int, seed: int):
    """A log of two hinges whose two sensors read x = sin m1 + sin(m2)/2 (and x²): the
    kernels are the curves x = const."""
    rng = np.random.default_rng(seed)
    motors = rng.uniform(-np.pi, np.pi, size=(samples, 2))
    x = np.sin(motors[:, 0]) + 0.5 * np.sin(motors[:, 1])
    return motors, np.stack([x, 0.5 * x**2], axis=1)


def test_sets_learned_from_a_log_hold_the_law():
    motors, sensors = cart_log(20000, seed=1)
    starts = np.array([[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2], [1.0, 2.0]])
    traced = smspace.learn(motors, sensors, starts, points=40)
    assert len(traced) >= 3, traced.report
    assert traced.law["rank"] == 1, traced.law
    x = lambda p: np.sin(p[..., 0]) + 0.5 * np.sin(p[..., 1])
    for set_points, row in zip(traced.sets, traced.kept):
        error = np.abs(x(set_points) - x(starts[row]))
        assert np.median(error) < 0.05, (row, np.median(error))


def test_two_logs_are_one_law_and_the_cli_agrees(cli, tmp_path):
    motors, sensors = cart_log(12000, seed=2)
    starts = np.array([[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2]])
    halves = (motors[:6000], motors[6000:]), (sensors[:6000], sensors[6000:])
    traced = smspace.learn(list(halves[0]), list(halves[1]), starts, points=30, seed=3)
    for i in range(2):
        np.save(tmp_path / f"m{i}.npy", halves[0][i])
        np.save(tmp_path / f"s{i}.npy", halves[1][i])
    np.save(tmp_path / "starts.npy", starts)
    cli("learn", "--motors", tmp_path / "m0.npy", "--sensors", tmp_path / "s0.npy",
        "--motors", tmp_path / "m1.npy", "--sensors", tmp_path / "s1.npy",
        "--starts", tmp_path / "starts.npy", "--points", 30, "--seed", 3,
        "--out", tmp_path / "sets.npy")
    assert np.array_equal(np.load(tmp_path / "sets.npy"), traced.sets)
    assert np.array_equal(np.load(tmp_path / "sets.kept.npy"), traced.kept)


def test_bad_logs_and_arguments_are_named():
    motors, sensors = cart_log(500, seed=4)
    starts = np.zeros((2, 2))
    with pytest.raises(ValueError, match="give one pair per log"):
        smspace.learn([motors, motors], [sensors], starts)
    with pytest.raises(ValueError, match="starts has 3 columns"):
        smspace.learn(motors, sensors, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="unknown field `no_such_key`"):
        smspace.learn(motors, sensors, starts, no_such_key=1)
    with pytest.raises(ValueError, match="period"):
        smspace.learn(motors, sensors, starts, period="sideways")
    bad = sensors.copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match="sensors"):
        smspace.learn(motors, bad, starts)
    with pytest.raises(ValueError, match="rows|samples"):
        smspace.learn(motors, sensors[:100], starts)


def test_a_python_agent_is_learned_within_a_budget_of_sensor_rows():
    read = [0]

    def sense(m):
        read[0] += m.shape[0]
        x = np.sin(m[:, 0]) + 0.5 * np.sin(m[:, 1])
        return np.stack([x, 0.5 * x**2], axis=1)

    agent = smspace.PythonAgent(sense=sense, n_motors=2, n_sensors=2)
    starts = np.array([[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2], [1.0, 2.0]])
    traced = smspace.trace(agent, starts, method="learned", budget=20000, points=40)
    spent = traced.report["budget"]["rows"]
    assert read[0] == spent["total"] <= 20000
    assert spent["babble"] + spent["agent_rank"] + spent["verify"] == spent["total"]
    # The agent's own slope at the 4 starts, 2N + 2 rows each: rank 1, as the law's.
    assert spent["agent_rank"] == 4 * 6
    assert traced.report["budget"]["agent_rank"]["rank"] == 1
    assert traced.law["rank_choice"]["agent"] == 1
    assert len(traced) >= 3 and traced.law["rank"] == 1
    x = lambda p: np.sin(p[..., 0]) + 0.5 * np.sin(p[..., 1])
    for set_points, row in zip(traced.sets, traced.kept):
        assert np.median(np.abs(x(set_points) - x(starts[row]))) < 0.05
    with pytest.raises(ValueError, match="budget=ROWS"):
        smspace.trace(agent, starts, method="learned")
    read[0] = 0
    with pytest.raises(ValueError, match="at least"):
        smspace.trace(agent, starts, method="learned", budget=1000)
    assert read[0] == 0, "a budget refused up front read the agent"


def test_a_given_rank_is_used_reported_and_checked():
    motors, sensors = cart_log(20000, seed=1)
    starts = np.array([[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2], [1.0, 2.0]])
    traced = smspace.learn(motors, sensors, starts, points=40, rank=1)
    assert traced.law["rank"] == 1 and traced.law["rank_source"] == "given", traced.law
    choice = traced.law["rank_choice"]
    assert choice["given"] == 1 and choice["estimate"] == 1, choice
    assert "given" in choice["reason"], choice
    estimated = smspace.learn(motors, sensors, starts, points=40)
    assert "given" not in estimated.law["rank_choice"], estimated.law
    assert np.array_equal(estimated.sets, traced.sets)
    for bad in (0, 2):
        with pytest.raises(ValueError, match=f"rank.*{bad}|{bad}.*rank"):
            smspace.learn(motors, sensors, starts, rank=bad)
    with pytest.raises(ValueError, match="1..=1 for 2 motors"):
        smspace.learn(motors, sensors, starts, rank=2)


def test_a_given_rank_reaches_the_law_learned_within_a_budget():
    def sense(m):
        x = np.sin(m[:, 0]) + 0.5 * np.sin(m[:, 1])
        return np.stack([x, 0.5 * x**2], axis=1)

    agent = smspace.PythonAgent(sense=sense, n_motors=2, n_sensors=2)
    starts = np.array([[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2], [1.0, 2.0]])
    traced = smspace.trace(agent, starts, method="learned", budget=20000, points=40, rank=1)
    assert traced.law["rank_source"] == "given", traced.law
    assert traced.law["rank_choice"]["given"] == 1
    with pytest.raises(ValueError, match="rank"):
        smspace.trace(agent, starts, method="learned", budget=20000, rank=2)


def test_the_first_round_of_babbling_stays_in_the_working_space():
    read = []

    def x_of(m):
        return np.sin(m[:, 0]) + 0.5 * np.sin(m[:, 1])

    def sense(m):
        read.append(np.array(m))
        x = x_of(m)
        return np.stack([x, 0.5 * x**2], axis=1)

    def pose(m):
        return np.stack([x_of(m), np.zeros(len(m)), np.zeros(len(m))], axis=1)

    agent = smspace.PythonAgent(sense=sense, n_motors=2, n_sensors=2, pose=pose)
    starts = np.array([[0.3, 0.2], [0.6, -0.4], [0.2, 0.5]])
    traced = smspace.trace(agent, starts, method="learned", budget=20000, points=40,
                           workspace=(0.5, 0.0, 1.0, 1.0))
    rounds = traced.report["budget"]["rounds"]
    first = np.concatenate(read)[: rounds[0]["rows"]]
    assert len(first) == rounds[0]["rows"] > 0
    # The poses drawn in the box x ∈ [0, 1] (a few 1e-9 of slack for the pose's rounding).
    assert np.all((x_of(first) >= -1e-9) & (x_of(first) <= 1 + 1e-9)), x_of(first).min()
    # Without a working space, the first round covers the motor space.
    read.clear()
    anywhere = smspace.trace(agent, starts, method="learned", budget=20000, points=40,
                             workspace=None)
    first = np.concatenate(read)[: anywhere.report["budget"]["rounds"][0]["rows"]]
    assert x_of(first).min() < -1.0
    assert len(traced) >= 2 and len(anywhere) >= 2


def test_camera_frames_are_learned_as_rows_of_pixels():
    motors, sensors = cart_log(20000, seed=2)
    x = sensors[:, 0]
    # A 3 × 4 grey "camera" whose pixels are smooth functions of x: frames (S, H, W).
    rows, cols = np.meshgrid(np.arange(3), np.arange(4), indexing="ij")
    frames = np.sin(x[:, None, None] * (1 + 0.3 * cols) + 0.5 * rows)
    starts = np.array([[0.3, 0.2], [-0.6, 0.4], [0.1, -0.2]])
    from_frames = smspace.learn(motors, frames, starts, points=30)
    from_rows = smspace.learn(motors, frames.reshape(len(frames), -1), starts, points=30)
    assert from_frames.law["rank"] == 1
    assert np.array_equal(from_frames.sets, from_rows.sets)
    # Colour frames (S, H, W, C) are rows of H W C sensors, channels last.
    colour = np.stack([frames, 0.5 * frames, frames**2], axis=-1)
    assert len(smspace.learn(motors, colour, starts, points=30)) >= 2
    with pytest.raises(ValueError, match="no pixels"):
        smspace.learn(motors, frames[:, :0], starts)
    with pytest.raises(ValueError, match=r"camera frames \(S, H, W\)"):
        smspace.learn(motors, x, starts)
