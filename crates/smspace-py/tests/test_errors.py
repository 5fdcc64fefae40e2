"""Bad input from Python: an exception naming the argument, with the CLI's message;
never a crash."""

import numpy as np
import pytest

import smspace
from conftest import random_sets


def test_wrong_dtype_or_ndim_names_the_argument():
    with pytest.raises(TypeError, match="sets must be an array of float64"):
        smspace.distances(np.array([["a"]]), metric="hausdorff")
    with pytest.raises(ValueError, match=r"sets must have 3 dimensions, got shape \(4, 5\)"):
        smspace.distances(np.zeros((4, 5)), metric="hausdorff")
    with pytest.raises(ValueError, match="D must have 2 dimensions"):
        smspace.embed(np.zeros(3))
    agent = smspace.Agent.preset("planar-arm")
    with pytest.raises(ValueError, match="motors must have 2 dimensions"):
        smspace.trace(agent, np.zeros(4))
    with pytest.raises(TypeError, match="agent must be a smspace.Agent"):
        smspace.trace("planar-arm", np.zeros((1, 4)))


def test_integer_arrays_are_converted():
    sets = random_sets(4, 3, 2, seed=0)
    ints = np.round(sets * 10).astype(np.int32)
    assert np.array_equal(
        smspace.distances(ints, metric="hausdorff"),
        smspace.distances(ints.astype(np.float64), metric="hausdorff"),
    )


def test_nan_is_refused_with_its_place():
    sets = random_sets(4, 3, 2, seed=0)
    sets[2, 1, 0] = np.nan
    with pytest.raises(ValueError, match=r"sets holds a non-finite value \(NaN\)"):
        smspace.distances(sets, metric="hausdorff")
    D = np.zeros((3, 3))
    D[0, 1] = D[1, 0] = np.inf
    with pytest.raises(ValueError, match="D:"):
        smspace.embed(D, method="mds", dim=1)
    with pytest.raises(ValueError, match="motors holds a non-finite value"):
        smspace.trace(smspace.Agent.preset("planar-arm"), np.full((1, 4), np.nan))


def test_engine_errors_carry_the_cli_messages(tmp_path):
    with pytest.raises(ValueError, match="unknown agent 'no-such-arm'; the registered agents are"):
        smspace.Agent.preset("no-such-arm")
    with pytest.raises(ValueError, match="unknown metric 'manhattan'"):
        smspace.distances(random_sets(3, 2, 2, seed=1), metric="manhattan")
    with pytest.raises(ValueError, match="need at least 2 kernel sets"):
        smspace.distances(random_sets(1, 2, 2, seed=1), metric="hausdorff")
    with pytest.raises(ValueError, match="which sets are closed loops"):
        smspace.distances(random_sets(3, 2, 2, seed=1), metric="curve")
    with pytest.raises(ValueError, match="not symmetric|symmetric"):
        smspace.embed(np.array([[0.0, 1.0], [2.0, 0.0]]), method="mds", dim=1)
    with pytest.raises(ValueError, match=r"\[agent\]|link_lengths"):
        smspace.Agent.preset("planar-arm", link_lengths=[-1.0, 1.0])
    with pytest.raises(ValueError, match="unknown field `nn`"):
        smspace.explore(smspace.Agent.preset("planar-arm"), nn=3)
    with pytest.raises(OSError):
        smspace.Agent.from_toml(tmp_path / "missing.toml")
    with pytest.raises(OSError, match="cannot read"):
        smspace.run(tmp_path / "missing.toml", out=tmp_path / "run")
    bad = tmp_path / "bad.toml"
    bad.write_text("[agent]\nkind = \"planar-arm\"\nretina_cells = 0\n")
    with pytest.raises(ValueError, match="retina_cells"):
        smspace.run(bad, out=tmp_path / "run")


def test_from_toml_reads_the_agent_and_its_environment(tmp_path):
    file = tmp_path / "arm.toml"
    file.write_text("[agent]\nkind = \"planar-arm\"\nretina_cells = 8\n[environment]\nseed = 4\n")
    agent = smspace.Agent.from_toml(file)
    assert (agent.n_motors, agent.n_sensors) == (4, 8)
    assert np.array_equal(agent.lights(), agent.lights(4))
    assert not np.array_equal(agent.lights(), agent.lights(5))
