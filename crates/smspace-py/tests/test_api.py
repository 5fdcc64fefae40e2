"""The stage API: SciPy's directed Hausdorff, layouts and strides, tiles, kNN,
progress, and the GIL released during a computation."""

import json
import threading
import time

import numpy as np
import pytest
from scipy.spatial.distance import directed_hausdorff

import smspace
from conftest import random_sets


def test_point_hausdorff_equals_scipy():
    sets = random_sets(7, 11, 3, seed=2)
    D = smspace.distances(sets, metric="hausdorff", period="none")
    for i in range(len(sets)):
        for j in range(len(sets)):
            expected = max(directed_hausdorff(sets[i], sets[j])[0],
                           directed_hausdorff(sets[j], sets[i])[0])
            assert D[i, j] == pytest.approx(expected, rel=1e-12, abs=1e-15)


def test_surface_metric_measures_sampled_planes_by_their_gap():
    # Planes z = h sampled by a 6 x 6 grid, each shifted in the plane by at most a fifth
    # of a step: the surface metric (points against tangent disks) is |h_i - h_j|, the
    # point metric is not.
    m = 6
    heights = np.sin(0.37 * np.arange(m))
    grid = np.stack(np.meshgrid(np.arange(6), np.arange(6), indexing="ij"), -1).reshape(-1, 2) * 0.3
    sets = np.empty((m, 36, 3))
    for s in range(m):
        shift = 0.06 * np.cos(1.7 * s)
        sets[s, :, 0] = grid[:, 0] + shift
        sets[s, :, 1] = grid[:, 1] - shift
        sets[s, :, 2] = heights[s]
    d = smspace.distances(sets, metric="surface", period="none")
    np.testing.assert_allclose(d, np.abs(heights[:, None] - heights[None, :]), atol=1e-12)
    points = smspace.distances(sets, metric="hausdorff", period="none")
    assert (points - d).max() > 0.01


def test_any_layout_or_strides_gives_the_same_results(arm_sets):
    D = smspace.distances(arm_sets)
    fortran = np.asfortranarray(arm_sets.sets)
    assert np.array_equal(smspace.distances(fortran, closed=arm_sets.closed), D)
    # A stepped view (every other set, reversed points): read in place.
    stepped = arm_sets.sets[::2]
    assert not stepped.flags.c_contiguous
    assert np.array_equal(
        smspace.distances(stepped, closed=arm_sets.closed[::2]), D[::2, ::2]
    )
    Y = smspace.embed(D, method="mds", dim=2)
    assert np.array_equal(smspace.embed(np.asfortranarray(D), method="mds", dim=2), Y)
    assert np.array_equal(smspace.embed(D.T, method="mds", dim=2), Y)


def test_outputs_are_writable_arrays_that_own_their_data(arm_sets):
    D = smspace.distances(arm_sets)
    assert D.dtype == np.float64 and D.flags.c_contiguous and D.flags.writeable
    assert arm_sets.sets.flags.writeable and arm_sets.kept.dtype == np.int64


def test_tiles_merge_into_the_matrix_bit_for_bit(arm_sets):
    D = smspace.distances(arm_sets)
    points, codes = arm_sets.sets, arm_sets.closed
    m = len(points)
    plan = smspace.tile_plan(m, 7)
    pairs = set()
    for r0, r1, c0, c1 in plan:
        pairs.update((i, j) for i in range(r0, r1) for j in range(c0, c1) if i < j)
    assert len(pairs) == m * (m - 1) // 2
    tiles = [
        (b, smspace._core._distance_tile(points[b[0]:b[1]], codes[b[0]:b[1]],
                                         points[b[2]:b[3]], codes[b[2]:b[3]], b,
                                         smspace._metric_spec("curve", "2pi")))
        for b in plan
    ]
    assert np.array_equal(smspace._core._merge_tiles(m, tiles), D)
    with pytest.raises(ValueError, match="no tile holds the pair"):
        smspace._core._merge_tiles(m, tiles[1:])


def test_knn_equals_the_sorted_matrix(arm_sets):
    D = smspace.distances(arm_sets)
    indices, found = smspace.distances(arm_sets, knn=4)
    assert indices.shape == (len(D), 4) and indices.dtype == np.int64
    for i, row in enumerate(D):
        nearest = np.sort(np.delete(row, i))[:4]
        np.testing.assert_allclose(found[i], nearest, rtol=1e-12, atol=0)
        np.testing.assert_allclose(row[indices[i]], found[i], rtol=1e-12, atol=0)
        assert i not in indices[i]


def test_progress_reaches_the_total(arm_sets):
    calls = []
    smspace.distances(arm_sets, progress=lambda stage, done, total: calls.append((stage, done, total)))
    assert calls and calls[-1][1] == calls[-1][2] > 0
    assert all(done <= total for _, done, total in calls)


def test_explore_reports_progress():
    calls = []
    arm = smspace.Agent.preset("planar-arm")
    smspace.explore(arm, n=3000, seed=1, progress=lambda stage, done, total: calls.append((stage, done, total)))
    assert calls[0] == ("explore", 0, 3000)
    assert calls[-1] == ("explore", 3000, 3000)
    assert all(done <= total for _, done, total in calls)


def test_a_raising_progress_callback_is_raised(arm_sets):
    def broken(stage, done, total):
        raise KeyError("stop")

    with pytest.raises(KeyError, match="stop"):
        smspace.distances(arm_sets, progress=broken)


def test_the_gil_is_released_while_a_matrix_is_computed():
    sets = random_sets(500, 40, 4, seed=3)
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    thread = threading.Thread(target=count)
    thread.start()
    time.sleep(0.02)
    start = time.perf_counter()
    smspace.distances(sets, metric="hausdorff")
    end = time.perf_counter()
    stop.set()
    thread.join()
    during = [t for t in ticks if start < t < end]
    # Held, the GIL would let the thread tick at most once or twice at the edges.
    assert end - start > 0.05, "the matrix was too quick to tell"
    assert len(during) >= 10, (len(during), end - start)


def test_analyze_gives_the_loop_as_a_circular_coordinate():
    rng = np.random.default_rng(3)
    alpha = rng.uniform(-np.pi, np.pi, 150)
    D = 2.0 * np.abs(np.sin(0.5 * (alpha[:, None] - alpha[None, :])))
    poses = np.column_stack([np.zeros(150), np.zeros(150), alpha])
    report = smspace.analyze(D, poses, circle_values=True)
    assert "values" not in smspace.analyze(D, poses)["circle"]
    circle = report["circle"]
    assert circle["classes"] == 1
    values = np.asarray(circle["values"])
    assert values.shape == (150,) and values.dtype == np.float64
    assert np.all((values >= 0.0) & (values < 2.0 * np.pi))
    json.dumps(report)  # the report stays plain JSON
    assert circle["agreement"]["alpha"]["circular_correlation"] > 0.99
    off = smspace.analyze(D, circle_landmarks=0)
    assert "circle" not in off
    with pytest.raises(ValueError, match="circle_scale"):
        smspace.analyze(D, circle_scale=2.0)
    # Positions read off a representation by one affine map.
    grid = np.column_stack([np.arange(150) % 15, np.arange(150) // 15, alpha]).astype(float)
    H = np.column_stack([2.0 * grid[:, 0] + 1.0, grid[:, 1] - grid[:, 0]])
    fitted = smspace.analyze(D, grid, representation=H, circle_landmarks=0)["affine"]
    assert fitted["metric_error"] < 1e-9 and abs(fitted["r_squared"] - 1.0) < 1e-9
    with pytest.raises(ValueError, match="needs poses"):
        smspace.analyze(D, representation=H)
    with pytest.raises(ValueError, match="3 rows"):
        smspace.analyze(D, grid, representation=H[:3])
    # The positions alone (a sensor of fixed orientation): the same fit.
    alone = smspace.analyze(D, grid[:, :2], representation=H, circle_landmarks=0)
    assert alone["affine"] == fitted
    assert list(alone["agreement"]["coordinates"]) == ["x", "y"]


def test_analyze_and_embed_reports(arm_sets):
    D = smspace.distances(arm_sets)
    fit = smspace.embed(D, method="isomap", dim=2, k=6, report=True)
    assert fit.Y.shape == (len(D), 2) and fit.report["method"] == "isomap"
    report = smspace.analyze(D)
    assert report["agreement"] is None and len(report["betti"]) >= 1
