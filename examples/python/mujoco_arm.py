"""A MuJoCo arm with a 2-D lidar for an eye, through every stage of smspace.

The body is the paper's (Laflaquière et al. 2015, section 3.1) written in MJCF: three
links of length 1 turning about vertical hinges from a base at the origin, and a
fourth hinge at the end of the arm that turns the eye. The eye is a fan of 12
rangefinders (a 2-D lidar, 30 degrees apart) on a mast 0.5 above the links, in a
room of walls, pillars and boxes out of the arm's reach, so that every ray hits a
wall or an obstacle and none hits the arm. MuJoCo runs headless: ``mj_kinematics`` and
``mj_sensorPos`` per posture, no dynamics, no rendering.

    pip install mujoco
    python examples/python/mujoco_arm.py                 # 1500 starts
    python examples/python/mujoco_arm.py --sets 60       # a small run (the tests')
    python examples/python/mujoco_arm.py --threads       # one MjData per thread
    python examples/python/mujoco_arm.py --out runs/mj   # save the arrays and reports
    python examples/python/mujoco_arm.py --noise 0.02    # 2 cm of noise on every depth

Stages: ``explore`` in the paper's working space (the eye in the rectangle x from 1 to
2.5, y from -1 to 1), ``trace`` by the sensory method (the lidar's own readings),
``distances`` (curve metric), ``embed`` (CCA, 3-D) and ``analyze`` (Betti numbers,
TwoNN, trustworthiness against the eye's poses). The kernel set of a posture is the
set of postures that put the eye at the same place with the same heading: a circle of
the three arm joints, the eye's hinge compensating; the manifold of these sets is the
eye's space of positions and headings, a plane times a circle (Betti numbers [1, 1],
dimension 3).

**Why a working space.** Explored anywhere in reach, the sets do not form the eye's
disc of positions times a circle. Where the eye is nearer the base than one link
(1 here), the postures that hold it still form two separate loops, and the tracer
follows the one through its start; just outside, the two have merged into one loop.
So the sets near the base fall into two families far (in the curve metric) from the
one-piece sets around them, and the analysis reads a mixture of scales: on the
built-in arm (1500 starts anywhere in reach, kinematic method) Betti numbers [1, 0],
with two H0 bars of 2.6 beside the loop's 1.5. Tracing every piece
(``trace(..., components="all")``) joins them again: one component and one loop
standing 2.3 times above the next bar (below the default gap ratio of 3, so still
read [1, 0]); the sets of an eye kept farther than 1.1 from the base read [1, 2], an
annulus of positions times a circle. A working space farther than one link from the
base that does not circle it, as here, gives the plane times a circle, [1, 1].

**Threads.** ``smspace.mujoco.agent`` shares one ``MjData`` between ``sense`` and
``pose`` by default, and the engine then calls them from one thread at a time; with
``--threads`` every engine thread has its own ``MjData`` and the calls run in
parallel. A callable of your own that writes a shared simulator state must not be
declared ``thread_safe=True``.

The Python API has no report stage for an agent written in Python (the HTML report is
written by ``smspace run`` from an experiment file); ``--out`` saves the stages'
arrays (``motors.npy``, ``poses.npy``, ``sets.npy``, ``D.npy``, ``Y.npy``) and reports
(``trace.json``, ``embedding.json``, ``analysis.json``) instead.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

import smspace
import smspace.mujoco

# The paper's working space: the eye in the rectangle of centre (1.75, 0), depth 1.5
# (x) and width 2 (y).
WORKSPACE = (1.75, 0.0, 1.5, 2.0)
BEAMS = 12


def _rangefinder_sites() -> str:
    """The 12 sites of the lidar, their z axes (the rays) 30 degrees apart in the
    horizontal plane, from -165 to 165 degrees about the eye's heading (its x axis)."""
    sites = []
    for i in range(BEAMS):
        angle = math.radians(-165.0 + 30.0 * i)
        sites.append(
            f'<site name="ray{i}" pos="0 0 0.5" zaxis="{math.cos(angle):.12f} {math.sin(angle):.12f} 0" size="0.01"/>'
        )
    return "\n          ".join(sites)


def _rangefinders() -> str:
    return "\n    ".join(f'<rangefinder name="lidar{i}" site="ray{i}"/>' for i in range(BEAMS))


# The room: walls 3.5 to 6 from the base (the arm reaches 3), three pillars and two
# boxes between the reach and the walls, all 1 high (the rays run at height 0.5).
ARM_XML = f"""
<mujoco model="lidar-arm">
  <compiler angle="radian"/>
  <default>
    <geom rgba="0.7 0.7 0.7 1"/>
  </default>
  <worldbody>
    <geom name="wall-east" type="box" pos="6 0 0.5" size="0.1 6 0.5"/>
    <geom name="wall-west" type="box" pos="-4 0 0.5" size="0.1 6 0.5"/>
    <geom name="wall-north" type="box" pos="1 5 0.5" size="5 0.1 0.5"/>
    <geom name="wall-south" type="box" pos="1 -4.5 0.5" size="5 0.1 0.5"/>
    <geom name="pillar-1" type="cylinder" pos="4.3 2.2 0.5" size="0.35 0.5"/>
    <geom name="pillar-2" type="cylinder" pos="3.8 -2.6 0.5" size="0.25 0.5"/>
    <geom name="pillar-3" type="cylinder" pos="-1.5 3.6 0.5" size="0.3 0.5"/>
    <geom name="box-1" type="box" pos="5.0 -0.4 0.5" size="0.4 0.6 0.5" euler="0 0 0.4"/>
    <geom name="box-2" type="box" pos="-2.9 -2.2 0.5" size="0.5 0.3 0.5" euler="0 0 -0.3"/>
    <geom name="base" type="cylinder" pos="0 0 -0.05" size="0.12 0.05"/>
    <body name="link1">
      <joint name="shoulder" type="hinge" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 1 0 0" size="0.04"/>
      <body name="link2" pos="1 0 0">
        <joint name="elbow" type="hinge" axis="0 0 1"/>
        <geom type="capsule" fromto="0 0 0 1 0 0" size="0.04"/>
        <body name="link3" pos="1 0 0">
          <joint name="wrist" type="hinge" axis="0 0 1"/>
          <geom type="capsule" fromto="0 0 0 1 0 0" size="0.04"/>
          <body name="eye" pos="1 0 0">
            <joint name="eye" type="hinge" axis="0 0 1"/>
            <geom type="cylinder" fromto="0 0 0 0 0 0.45" size="0.02"/>
            <geom type="sphere" pos="0 0 0.5" size="0.06" rgba="0.2 0.4 0.9 1"/>
            <site name="eye" pos="0 0 0.5" size="0.02"/>
          {_rangefinder_sites()}
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <sensor>
    {_rangefinders()}
  </sensor>
</mujoco>
"""

JOINTS = ["shoulder", "elbow", "wrist", "eye"]


def model():
    """The arm and its room as an ``MjModel``."""
    import mujoco

    return mujoco.MjModel.from_xml_string(ARM_XML)


def body(threads: bool = False) -> smspace.mujoco.Body:
    """The arm as a body: 4 hinges, 12 rangefinders, the eye site's planar pose."""
    return smspace.mujoco.Body(model(), joints=JOINTS, sensors=None, site="eye", threads=threads)


class NoisyDepths:
    """The lidar's depths plus seeded Gaussian noise of ``sigma`` (metres), as a real
    rangefinder reads them: the same posture never reads the same twice. The noise of
    a row is drawn from a generator seeded by ``seed``, the row's bytes and the row's
    index among the identical rows of the same call, so a run is reproducible and
    independent of the order in which the engine's threads call."""

    def __init__(self, sense, sigma: float, seed: int = 0) -> None:
        self.sense = sense
        self.sigma = float(sigma)
        self.seed = int(seed)

    def __call__(self, motors) -> np.ndarray:
        motors = np.asarray(motors, dtype=np.float64)
        out = np.array(self.sense(motors), dtype=np.float64)
        seen: dict = {}
        for i, row in enumerate(motors):
            key = row.tobytes()
            repeat = seen.get(key, 0)
            seen[key] = repeat + 1
            row_hash = int.from_bytes(hashlib.blake2b(key, digest_size=8).digest(), "little")
            rng = np.random.default_rng([self.seed, row_hash, repeat])
            out[i] += self.sigma * rng.standard_normal(out.shape[1])
        return out


def run(sets: int = 1500, seed: int = 1, threads: bool = False, points: int = 100, out=None,
        noise: float = 0.0) -> dict:
    """Every stage on ``sets`` starts, the depths read with ``noise`` metres of
    Gaussian noise; returns the figures (and saves the arrays and reports into the
    folder ``out`` when given)."""
    arm = body(threads)
    if noise > 0.0:
        arm.sense = NoisyDepths(arm.sense, noise, seed)
    agent = arm.agent(name="lidar-arm")
    started = time.perf_counter()
    found = smspace.explore(agent, n=sets, seed=seed, workspace=WORKSPACE)
    traced = smspace.trace(agent, found.motors, method="sensory", points=points)
    trace_seconds = time.perf_counter() - started
    rows = arm.rows_sensed
    D = smspace.distances(traced, metric="curve")
    embedded = smspace.embed(D, method="cca", dim=3, seed=0, report=True)
    poses = found.poses[traced.kept]
    report = smspace.analyze(D, poses=poses)
    seconds = time.perf_counter() - started
    statuses = traced.report.get("summary", {}).get("by_status") if isinstance(traced.report, dict) else None
    # How far each kept set strays from its start's eye pose (it should hold it still).
    spread = float(np.max(np.abs(
        agent.poses(traced.sets.reshape(-1, 4)).reshape(len(traced), points, 3)[:, :, :2]
        - poses[:, None, :2]
    ))) if len(traced) else float("nan")
    figures = {
        "starts": sets,
        "noise": noise,
        "noise_estimated": (traced.report.get("summary", {}).get("noise")
                            if isinstance(traced.report, dict) else None),
        "traced": len(traced),
        "traced_fraction": len(traced) / sets,
        "statuses": statuses,
        "sensor_rows": rows,
        "sensor_rows_per_start": rows / sets,
        "eye_position_spread": spread,
        "betti": report["betti"],
        "twonn": report["intrinsic_dimension"]["twonn"],
        "trustworthiness": report["agreement"]["trustworthiness"],
        "continuity": report["agreement"]["continuity"],
        "trace_seconds": trace_seconds,
        "seconds": seconds,
    }
    if out is not None:
        save(Path(out), found, traced, D, embedded, report, figures)
    return figures


def save(folder: Path, found, traced, D, embedded, report, figures) -> None:
    """The arrays and reports of every stage into ``folder`` (each file written to a
    temporary name and renamed into place)."""
    folder.mkdir(parents=True, exist_ok=True)

    def write(name: str, writer) -> None:
        temporary = folder / f".{name}.tmp"
        with open(temporary, "wb") as file:
            writer(file)
        os.replace(temporary, folder / name)

    arrays = {
        "motors.npy": found.motors,
        "poses.npy": found.poses,
        "sets.npy": traced.sets,
        "sets.closed.npy": traced.closed,
        "kept.npy": traced.kept,
        "D.npy": D,
        "Y.npy": embedded.Y,
    }
    for name, array in arrays.items():
        write(name, lambda file, a=array: np.save(file, a))
    for name, value in (
        ("trace.json", traced.report),
        ("embedding.json", embedded.report),
        ("analysis.json", report),
        ("figures.json", figures),
    ):
        write(name, lambda file, v=value: file.write(json.dumps(v, indent=1).encode()))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--sets", type=int, default=int(os.environ.get("SMSPACE_MUJOCO_SETS", 1500)),
        help="starts explored and traced (default 1500, or $SMSPACE_MUJOCO_SETS)",
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--points", type=int, default=100, help="points per kernel set")
    parser.add_argument("--threads", action="store_true", help="one MjData per engine thread")
    parser.add_argument("--out", type=Path, help="a folder for the arrays and reports")
    parser.add_argument("--noise", type=float, default=0.0,
                        help="standard deviation of Gaussian noise on every depth, metres (default 0)")
    args = parser.parse_args(argv)
    if args.sets < 20:
        parser.error(f"--sets {args.sets}: give at least 20 starts (the analysis needs neighbours)")
    if not math.isfinite(args.noise) or args.noise < 0.0:
        parser.error(f"--noise {args.noise}: give a standard deviation of 0 or more, in metres")
    figures = run(args.sets, args.seed, args.threads, args.points, args.out, args.noise)
    print(f"sets traced: {figures['traced']} of {figures['starts']} "
          f"({100 * figures['traced_fraction']:.1f} %); statuses {figures['statuses']}")
    print(f"sensor rows: {figures['sensor_rows']} ({figures['sensor_rows_per_start']:.0f} per start); "
          f"eye position spread along the sets: {figures['eye_position_spread']:.1e}")
    print(f"Betti numbers: {figures['betti']}; TwoNN dimension: {figures['twonn']:.2f}; "
          f"trustworthiness: {figures['trustworthiness']:.3f}; continuity: {figures['continuity']:.3f}")
    print(f"time: {figures['trace_seconds']:.1f} s to explore and trace, {figures['seconds']:.1f} s in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
