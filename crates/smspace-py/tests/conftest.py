"""Shared fixtures: the command-line tool (to compare with), the repository's files,
and the NumPy arm of examples/python."""

import ctypes.util
import importlib.util
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]

# Headless rendering for the MuJoCo camera's tests: EGL where its library is installed.
# MuJoCo chooses its OpenGL backend when it is first imported, so this is set before any
# test module imports it; without EGL those tests skip and say why.
if "MUJOCO_GL" not in os.environ and ctypes.util.find_library("EGL"):
    os.environ["MUJOCO_GL"] = "egl"


def _cli() -> str:
    """The `smspace` binary: $SMSPACE_CLI (scripts/test sets it to the one `cargo test`
    built), else one on the PATH."""
    found = os.environ.get("SMSPACE_CLI") or shutil.which("smspace")
    if not found or not Path(found).exists():
        if os.environ.get("SMSPACE_REQUIRE_CLI"):
            raise RuntimeError("SMSPACE_CLI does not name the smspace binary")
        pytest.skip("the smspace command-line tool is not built (set SMSPACE_CLI)")
    return found


@pytest.fixture(scope="session")
def cli():
    """Runs `smspace ARGS...`, failing the test with its stderr on a non-zero exit."""
    binary = _cli()

    def run(*args):
        done = subprocess.run(
            [binary, *map(str, args)], capture_output=True, text=True, cwd=ROOT
        )
        assert done.returncode == 0, done.stderr
        return done

    return run


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def numpy_arm_module():
    """examples/python/planar_arm.py, imported."""
    path = ROOT / "examples" / "python" / "planar_arm.py"
    spec = importlib.util.spec_from_file_location("planar_arm", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def arm_sets():
    """Kinematic kernel sets of 40 babbled arm configurations (20 points each)."""
    import smspace

    agent = smspace.Agent.preset("planar-arm")
    found = smspace.explore(agent, n=40, seed=5)
    return smspace.trace(agent, found.motors, points=20)


def random_sets(m, p, n, seed):
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=(m, p, n))
