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
    MUJOCO_GL=egl python examples/python/mujoco_arm.py --camera 32,24 --sets 60
                                                         # the eye's camera instead

With ``--camera W,H`` the eye sees through a camera on its mast (grey images of W × H
pixels, looking along its heading) instead of the lidar: the same kernel sets, from
``H W`` sensors a row. MuJoCo renders every posture through OpenGL: a GPU's EGL renders
thousands of small frames a second, software EGL far fewer (21 frames/s measured on a
2-core machine without a GPU, while the sensory route reads about 3 500 rows a set),
so on such a machine take few sets or the learned route (``--budget``).

With ``--noise`` the sets are traced from the noisy depths (the tracer measures the
noise and leaves the rays that jump past an obstacle's edge out of the slope), and the
exact sets through the same starts are traced too: the example prints the set error
(``curve`` metric), the measured noise and the sensor rows per set (docs/noise.md).

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
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Optional

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
            <camera name="eye" pos="0 0 0.5" xyaxes="0 -1 0 0 0 1" fovy="70"/>
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


def body(threads: bool = False, camera: Optional[tuple] = None) -> smspace.mujoco.Body:
    """The arm as a body: 4 hinges, 12 rangefinders (or, with ``camera=(W, H)``, the
    eye's camera image instead), the eye site's planar pose."""
    if camera is not None:
        return smspace.mujoco.Body(model(), joints=JOINTS, sensors=None, site="eye",
                                   camera="eye", size=camera, color="grey")
    return smspace.mujoco.Body(model(), joints=JOINTS, sensors=None, site="eye", threads=threads)


# splitmix64's constants: a counter-based generator, vectorised over a batch.
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1, _MIX2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def _mix(x: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser on an array of ``uint64`` (wrapping arithmetic)."""
    x = (x ^ (x >> np.uint64(30))) * _MIX1
    x = (x ^ (x >> np.uint64(27))) * _MIX2
    return x ^ (x >> np.uint64(31))


class NoisyDepths:
    """The lidar's depths plus seeded Gaussian noise of ``sigma`` (metres), as a real
    rangefinder reads them: the same posture never reads the same twice. The noise of
    a reading is a hash of ``seed``, the row's bytes, the row's index among the
    identical rows of the same call and the sensor's column (splitmix64, then
    Box–Muller), so a run is reproducible and independent of the order in which the
    engine's threads call, and a batch costs a few NumPy operations (no Python loop)."""

    def __init__(self, sense, sigma: float, seed: int = 0) -> None:
        self.sense = sense
        self.sigma = float(sigma)
        self.seed = int(seed)

    def __call__(self, motors) -> np.ndarray:
        motors = np.ascontiguousarray(motors, dtype=np.float64)
        out = np.array(self.sense(motors), dtype=np.float64)
        return out + self.sigma * self.gaussian(motors, out.shape[1])

    def gaussian(self, motors: np.ndarray, columns: int) -> np.ndarray:
        """Standard normal draws ``(B, columns)`` for the rows ``motors`` ``(B, N)``."""
        rows = motors.shape[0]
        key = np.full(rows, self.seed, dtype=np.uint64)
        for column in (motors + 0.0).view(np.uint64).T:  # + 0.0: -0.0 reads as 0.0
            key = _mix(key ^ column) + _GOLDEN
        # The index of every row among the identical rows before it in the batch.
        _, group = np.unique(key, return_inverse=True)
        group = group.reshape(-1)
        order = np.argsort(group, kind="stable")
        starts = np.r_[0, np.flatnonzero(np.diff(group[order])) + 1]
        repeat = np.empty(rows, dtype=np.uint64)
        repeat[order] = np.arange(rows) - np.repeat(starts, np.diff(np.r_[starts, rows]))
        cells = _mix(key ^ _mix(repeat + _GOLDEN))[:, None] + _GOLDEN * np.arange(
            1, 2 * columns + 1, dtype=np.uint64)
        uniform = (_mix(cells) >> np.uint64(11)).astype(np.float64) * 2.0**-53
        radius = np.sqrt(-2.0 * np.log1p(-uniform[:, :columns]))
        return radius * np.cos(2.0 * np.pi * uniform[:, columns:])


def run(sets: int = 1500, seed: int = 1, threads: bool = False, points: int = 100, out=None,
        noise: float = 0.0, budget: Optional[int] = None, camera: Optional[tuple] = None) -> dict:
    """Every stage on ``sets`` starts, the depths read with ``noise`` metres of
    Gaussian noise; returns the figures (and saves the arrays and reports into the
    folder ``out`` when given). With ``budget``, the sets are traced on the law
    learned from at most that many sensor rows (``method="learned"``) instead of the
    sensory route. With noise or a budget, the exact sets through the same starts are
    traced too (by the sensory route on the exact depths), and each set's distance to
    its exact one is measured. With ``camera=(W, H)`` the eye sees through its camera
    (grey images) instead of the lidar."""
    arm = body(threads, camera)
    if noise > 0.0:
        arm.sense = NoisyDepths(arm.sense, noise, seed)
    agent = arm.agent(name="lidar-arm" if camera is None else "camera-arm")
    started = time.perf_counter()
    found = smspace.explore(agent, n=sets, seed=seed, workspace=WORKSPACE)
    if budget is None:
        traced = smspace.trace(agent, found.motors, method="sensory", points=points)
    else:
        traced = smspace.trace(agent, found.motors, method="learned", points=points,
                               budget=budget, workspace=WORKSPACE)
    trace_seconds = time.perf_counter() - started
    rows = arm.rows_sensed
    D = smspace.distances(traced, metric="curve")
    embedded = smspace.embed(D, method="cca", dim=3, seed=0, report=True)
    poses = found.poses[traced.kept]
    report = smspace.analyze(D, poses=poses)
    seconds = time.perf_counter() - started
    summary = traced.report["summary"]
    # How far each kept set strays from its start's eye pose (it should hold it still).
    spread = float(np.max(np.abs(
        agent.poses(traced.sets.reshape(-1, 4)).reshape(len(traced), points, 3)[:, :, :2]
        - poses[:, None, :2]
    ))) if len(traced) else float("nan")
    figures = {
        "starts": sets,
        "noise": noise,
        "noise_estimated": summary.get("noise"),
        "traced": len(traced),
        "traced_fraction": len(traced) / sets,
        "statuses": summary["by_status"],
        "warnings": traced.warnings,
        "sensor_rows": rows,
        "sensor_rows_per_start": rows / sets,
        "sensor_rows_per_set": (summary.get("sensor_rows") or {}).get("median"),
        "budget": traced.report.get("budget", {}).get("rows"),
        "eye_position_spread": spread,
        "betti": report["betti"],
        "twonn": report["intrinsic_dimension"]["twonn"],
        "trustworthiness": report["agreement"]["trustworthiness"],
        "continuity": report["agreement"]["continuity"],
        "trace_seconds": trace_seconds,
        "seconds": seconds,
    }
    if noise > 0.0 or budget is not None:
        exact = smspace.trace(body(threads, camera).agent(name="exact"), found.motors,
                              method="sensory", points=points)
        errors = set_errors(traced, exact)
        figures["set_error"] = {
            "compared": len(errors),
            "median": float(np.median(errors)) if len(errors) else float("nan"),
            "p90": float(np.quantile(errors, 0.9, method="closest_observation"))
            if len(errors) else float("nan"),
            "max": float(errors.max()) if len(errors) else float("nan"),
        }
    if out is not None:
        save(Path(out), found, traced, D, embedded, report, figures)
    return figures


def set_errors(traced, exact) -> np.ndarray:
    """The ``curve`` distance (radians) between every set of ``traced`` and the set of
    ``exact`` through the same start (the starts kept in both; a set is read as a
    loop when it closed in both)."""
    row = {int(start): j for j, start in enumerate(exact.kept)}
    errors = []
    for i, start in enumerate(traced.kept):
        j = row.get(int(start))
        if j is None:
            continue
        pair = np.stack([traced.sets[i], exact.sets[j]])
        closed = [min(traced.closed[i], exact.closed[j])] * 2
        errors.append(smspace.distances(pair, metric="curve", closed=closed)[0, 1])
    return np.array(errors)


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
    parser.add_argument("--budget", type=int,
                        help="learn the law from at most this many sensor rows in all and trace "
                             "the sets on it (the learned route) instead of the sensory route")
    parser.add_argument("--camera", metavar="W,H",
                        help="see through the eye's camera (grey, W x H pixels, e.g. 32,24) instead of "
                             "the lidar; MuJoCo renders it through OpenGL (headless: MUJOCO_GL=egl)")
    args = parser.parse_args(argv)
    camera = None
    if args.camera is not None:
        try:
            camera = tuple(int(v) for v in args.camera.split(","))
        except ValueError:
            camera = ()
        if len(camera) != 2 or min(camera) < 1:
            parser.error(f"--camera {args.camera}: give the image's width and height, e.g. 32,24")
    if args.sets < 20:
        parser.error(f"--sets {args.sets}: give at least 20 starts (the analysis needs neighbours)")
    if not math.isfinite(args.noise) or args.noise < 0.0:
        parser.error(f"--noise {args.noise}: give a standard deviation of 0 or more, in metres")
    if args.budget is not None and args.budget <= 0:
        parser.error(f"--budget {args.budget}: give the sensor rows the arm may be read, at least a few thousand")
    figures = run(args.sets, args.seed, args.threads, args.points, args.out, args.noise, args.budget,
                  camera)
    print(f"sets traced: {figures['traced']} of {figures['starts']} "
          f"({100 * figures['traced_fraction']:.1f} %); statuses {figures['statuses']}")
    print(f"sensor rows: {figures['sensor_rows']} ({figures['sensor_rows_per_start']:.0f} per start, "
          f"median {figures['sensor_rows_per_set']} per set); "
          f"eye position spread along the sets: {figures['eye_position_spread']:.1e}")
    if figures["budget"]:
        spent = figures["budget"]
        print(f"learned route: {spent['total']} sensor rows in all ({spent['babble']} babbled, "
              f"{spent['agent_rank']} for the agent's own slope, {spent['verify']} verifying the sets)")
    if figures["noise_estimated"]:
        measured = figures["noise_estimated"]
        print(f"noise: {args.noise} m given, {measured['sigma']:.4g} m measured; position "
              f"uncertainty {measured['position']:.4f} rad (median over {measured['sets']} starts)")
    if "set_error" in figures:
        error = figures["set_error"]
        print(f"set error against the exact sets ({error['compared']} compared, curve metric): "
              f"median {error['median']:.4f} rad, 90th percentile {error['p90']:.4f}, "
              f"largest {error['max']:.4f}")
    print(f"Betti numbers: {figures['betti']}; TwoNN dimension: {figures['twonn']:.2f}; "
          f"trustworthiness: {figures['trustworthiness']:.3f}; continuity: {figures['continuity']:.3f}")
    print(f"time: {figures['trace_seconds']:.1f} s to explore and trace, {figures['seconds']:.1f} s in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
