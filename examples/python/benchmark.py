"""Benchmarks of the Python package (issue 17), on the paper's 2500 arm sets.

    python examples/python/benchmark.py [--cli PATH] [--repeat 3] [--only matrix,agent,dask]

1. matrix: ``smspace.distances`` (curve metric) from Python against the same matrix in
   Rust alone (the ``smspace distances`` command, whose own reported time excludes
   nothing but process start; it also reads the sets and writes D.npy), interleaved.
2. agent: sensory tracing of the 2500 babbled starts with the NumPy arm of
   ``planar_arm.py`` (a PythonAgent) against the built-in arm, both from Python.
3. dask: ``smspace.dask.distances`` on a LocalCluster of 2 worker processes against
   ``smspace.distances`` in this process.

Build the wheel with ``--release`` for meaningful numbers.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import smspace

sys.path.insert(0, str(Path(__file__).resolve().parent))
import planar_arm  # noqa: E402


def timed(f):
    start = time.perf_counter()
    value = f()
    return time.perf_counter() - start, value


def paper_sets():
    agent = smspace.Agent.preset("planar-arm")
    found = smspace.explore(agent, n=2500, seed=1)
    seconds, traced = timed(lambda: smspace.trace(agent, found.motors))
    print(f"traced {len(traced)} kinematic sets in {seconds:.2f} s")
    return agent, found, traced


def bench_matrix(traced, cli, repeat):
    with tempfile.TemporaryDirectory() as folder:
        sets = Path(folder) / "sets.npy"
        np.save(sets, traced.sets)
        np.save(Path(folder) / "sets.closed.npy", traced.closed)
        python, rust = [], []
        for _ in range(repeat):
            seconds, D = timed(lambda: smspace.distances(traced, metric="curve"))
            python.append(seconds)
            done = subprocess.run(
                [cli, "distances", "--sets", sets, "--metric", "curve", "--out", Path(folder) / "D.npy"],
                capture_output=True, text=True, check=True,
            )
            rust.append(float(re.search(r"in ([0-9.]+) s", done.stderr).group(1)))
        same = np.array_equal(D, np.load(Path(folder) / "D.npy"))
    p, r = min(python), min(rust)
    print(f"matrix {len(traced)} x {len(traced)} curve: Python {p:.3f} s (runs {fmt(python)}), "
          f"Rust CLI {r:.3f} s (runs {fmt(rust)}): {100 * (p / r - 1):+.1f} %; equal: {same}")


def bench_agent(agent, found, repeat):
    numpy_agent = planar_arm.numpy_arm(agent.lights(1))
    rust, python = [], []
    for _ in range(repeat):
        seconds, theirs = timed(lambda: smspace.trace(agent, found.motors, method="sensory", env=1))
        rust.append(seconds)
        seconds, ours = timed(lambda: smspace.trace(numpy_agent, found.motors, method="sensory"))
        python.append(seconds)
    gap = np.abs(ours.sets - theirs.sets).max() if np.array_equal(ours.kept, theirs.kept) else float("nan")
    print(f"sensory tracing of {len(found.motors)} starts: built-in arm {min(rust):.2f} s (runs {fmt(rust)}), "
          f"NumPy PythonAgent {min(python):.2f} s (runs {fmt(python)}): {min(python) / min(rust):.1f}x; "
          f"kept {len(ours)} and {len(theirs)}, largest set difference {gap:.1e}")


def bench_dask(traced, repeat):
    from distributed import Client, LocalCluster

    import smspace.dask

    threads = os.environ.get("SMSPACE_DASK_RAYON_THREADS")
    env = {"RAYON_NUM_THREADS": threads} if threads else {}
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, env=env) as cluster, Client(cluster) as client:
        smspace.dask.distances(traced, client, tile=200)  # warm the workers
        local, remote = [], []
        for _ in range(repeat):
            seconds, D = timed(lambda: smspace.distances(traced))
            local.append(seconds)
            seconds, E = timed(lambda: smspace.dask.distances(traced, client))
            remote.append(seconds)
    print(f"dask, 2 local workers (RAYON_NUM_THREADS={threads or 'default'}): {min(remote):.3f} s "
          f"(runs {fmt(remote)}) against one process {min(local):.3f} s (runs {fmt(local)}): "
          f"{100 * (min(remote) / min(local) - 1):+.1f} %; equal: {np.array_equal(D, E)}")


def fmt(values):
    return ", ".join(f"{v:.2f}" for v in values)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cli", default=os.environ.get("SMSPACE_CLI", "smspace"))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--only", default="matrix,agent,dask")
    args = parser.parse_args()
    which = set(args.only.split(","))
    agent, found, traced = paper_sets()
    if "matrix" in which:
        bench_matrix(traced, args.cli, args.repeat)
    if "agent" in which:
        bench_agent(agent, found, args.repeat)
    if "dask" in which:
        bench_dask(traced, args.repeat)


if __name__ == "__main__":
    main()
