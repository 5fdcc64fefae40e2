"""Benchmarks of the Python package (issue 17), on the paper's 2500 arm sets.

    python examples/python/benchmark.py [--cli PATH] [--repeat 3] [--only matrix,agent,dask]
    python examples/python/benchmark.py --only numba --sets sets.npy [--cli PATH] [--repeat 3]
        [--numba-fold wrapped|remainder]

1. matrix: ``smspace.distances`` (curve metric) from Python against the same matrix in
   Rust alone (the ``smspace distances`` command, whose own reported time excludes
   nothing but process start; it also reads the sets and writes D.npy), interleaved.
2. agent: sensory tracing of the 2500 babbled starts with the NumPy arm of
   ``planar_arm.py`` (a PythonAgent) against the built-in arm, both from Python.
3. dask: ``smspace.dask.distances`` on a LocalCluster of 2 worker processes against
   ``smspace.distances`` in this process.
4. numba: the ``hausdorff`` matrix of the sets in ``--sets`` (an (M, P, N) ``.npy`` of
   angles, period 2π) by the ``smspace distances`` command (``--threads 2``, its own
   reported time) against a parallel brute force in Numba (every pair, every point
   against every point in ``float64``, rows spread over 2 threads), interleaved; it
   prints both times, the ratio, ``SMSPACE_SIMD`` (the level cap the command ran
   under), the CPU times of both (less disturbed than wall times by other work on the
   machine) and the largest difference between the two matrices. The brute force folds
   a difference ``u`` to ``min(r, 2π − r)`` with ``r = |u|`` (angles wrapped, as smspace
   takes them), or with ``--numba-fold remainder`` ``r = |u| mod 2π`` (any angles).
   Needs ``pip install numba``, not the wheel.

Build the wheel (and the command) with ``--release`` for meaningful numbers.
"""

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def timed(f):
    start = time.perf_counter()
    value = f()
    return time.perf_counter() - start, value


def paper_sets():
    import smspace

    agent = smspace.Agent.preset("planar-arm")
    found = smspace.explore(agent, n=2500, seed=1)
    seconds, traced = timed(lambda: smspace.trace(agent, found.motors))
    print(f"traced {len(traced)} kinematic sets in {seconds:.2f} s")
    return agent, found, traced


def bench_matrix(traced, cli, repeat):
    import smspace

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
    import planar_arm
    import smspace

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

    import smspace
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


def numba_hausdorff_matrix(remainder):
    """The brute-force Hausdorff matrix with period 2π, compiled by Numba (parallel rows).
    A coordinate difference ``u`` folds to ``min(r, 2π − r)`` with ``r = |u|`` (angles
    wrapped into one period, as smspace takes them) or, with ``remainder``, with
    ``r = |u| mod 2π`` (any angles, as smspace's reference does)."""
    import numba

    if remainder:
        @numba.njit(inline="always")
        def fold(u, tau):
            r = abs(u) % tau
            return min(r, tau - r)
    else:
        @numba.njit(inline="always")
        def fold(u, tau):
            r = abs(u)
            return min(r, tau - r)

    @numba.njit(parallel=True, cache=False)
    def matrix(sets):
        m, p, n = sets.shape
        tau = 2.0 * np.pi
        out = np.zeros((m, m))
        for i in numba.prange(m):
            row = np.empty(p)
            col = np.empty(p)
            for j in range(i + 1, m):
                row[:] = np.inf
                col[:] = np.inf
                for a in range(p):
                    for b in range(p):
                        d2 = 0.0
                        for k in range(n):
                            w = fold(sets[i, a, k] - sets[j, b, k], tau)
                            d2 += w * w
                        if d2 < row[a]:
                            row[a] = d2
                        if d2 < col[b]:
                            col[b] = d2
                d = np.sqrt(max(row.max(), col.max()))
                out[i, j] = d
                out[j, i] = d
        return out

    return matrix


def bench_numba(sets_path, cli, repeat, remainder):
    import numba

    numba.set_num_threads(2)
    sets = np.load(sets_path)
    matrix = numba_hausdorff_matrix(remainder)
    matrix(sets[:3])  # compile
    rust, brute, rust_cpu, brute_cpu = [], [], [], []
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "D.npy"
        for _ in range(repeat):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            done = subprocess.run(
                [cli, "distances", "--sets", sets_path, "--metric", "hausdorff", "--threads", "2",
                 "--out", out],
                capture_output=True, text=True, check=True,
            )
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            rust.append(float(re.search(r"in ([0-9.]+) s", done.stderr).group(1)))
            rust_cpu.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
            cpu = time.process_time()
            seconds, E = timed(lambda: matrix(sets))
            brute_cpu.append(time.process_time() - cpu)
            brute.append(seconds)
        D = np.load(out)
    m = len(sets)
    pairs = m * (m - 1) // 2
    r, b = min(rust), min(brute)
    print(f"hausdorff matrix of {m} sets ({pairs} pairs), 2 threads: smspace {r:.3f} s "
          f"({pairs / r / 1e6:.2f} M pairs/s; runs {fmt(rust)}; SMSPACE_SIMD={os.environ.get('SMSPACE_SIMD', 'default')}), "
          f"Numba brute force ({'remainder' if remainder else 'wrapped'} fold) {b:.2f} s (runs {fmt(brute)}): {b / r:.0f}x; "
          f"CPU time (both threads) smspace {fmt(rust_cpu)} s, Numba {fmt(brute_cpu)} s: "
          f"{min(brute_cpu) / min(rust_cpu):.0f}x; largest difference {np.abs(D - E).max():.1e}")


def fmt(values):
    return ", ".join(f"{v:.2f}" for v in values)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cli", default=os.environ.get("SMSPACE_CLI", "smspace"))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--only", default="matrix,agent,dask")
    parser.add_argument("--sets", help="an (M, P, N) .npy of angles for the numba comparison")
    parser.add_argument("--numba-fold", choices=["wrapped", "remainder"], default="wrapped",
                        help="how the Numba brute force folds a difference (see numba_hausdorff_matrix)")
    args = parser.parse_args()
    which = set(args.only.split(","))
    if "numba" in which:
        if args.sets is None:
            parser.error("--only numba needs --sets PATH (an (M, P, N) .npy of angles)")
        bench_numba(args.sets, args.cli, args.repeat, args.numba_fold == "remainder")
        which.discard("numba")
    if not which:
        return
    agent, found, traced = paper_sets()
    if "matrix" in which:
        bench_matrix(traced, args.cli, args.repeat)
    if "agent" in which:
        bench_agent(agent, found, args.repeat)
    if "dask" in which:
        bench_dask(traced, args.repeat)


if __name__ == "__main__":
    main()
