"""Distance matrices on a Dask cluster: a LocalCluster of 2 worker processes on the
loopback interface, equal to the local matrix bit for bit."""

import numpy as np
import pytest

import smspace
import smspace.dask

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
        dashboard_address=None,
    )
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


def test_tiles_on_the_cluster_equal_the_local_matrix(client, arm_sets):
    local = smspace.distances(arm_sets)
    for tile in [7, 16, 40, None]:
        remote = smspace.dask.distances(arm_sets, client, metric="curve", tile=tile)
        assert np.array_equal(remote, local), tile
    sets = np.random.default_rng(1).normal(size=(23, 9, 3))
    assert np.array_equal(
        smspace.dask.distances(sets, client, metric="hausdorff", period="none", tile=5),
        smspace.distances(sets, metric="hausdorff", period="none"),
    )


def test_knn_on_the_cluster_equals_the_local_search(client, arm_sets):
    local = smspace.distances(arm_sets, knn=3)
    remote = smspace.dask.distances(arm_sets, client, knn=3, tile=9)
    assert np.array_equal(remote[0], local[0]) and np.array_equal(remote[1], local[1])


def test_run_computes_the_distance_stage_on_the_cluster(client, root, tmp_path):
    experiment = root / "experiments" / "paper-toy-redundant.toml"
    overrides = {"exploration.n": 50, "kernel.points": 10, "report.formats": "svg"}
    here = smspace.run(experiment, out=tmp_path / "here", overrides=overrides)
    there = smspace.run(experiment, out=tmp_path / "there", overrides=overrides, client=client, tile=12)
    assert np.array_equal(here.D, there.D)
    assert here.report == there.report


def test_the_landmark_path_is_refused_on_the_cluster(client, root, tmp_path):
    # The landmark path computes in this process: a client is refused, not ignored.
    experiment = root / "experiments" / "paper-toy-redundant.toml"
    overrides = {"exploration.n": 50, "kernel.points": 10, "scale.path": "landmarks"}
    with pytest.raises(ValueError, match=r"scale parameter path = landmarks: .*computes in this process, not on the Dask cluster"):
        smspace.run(experiment, out=tmp_path / "there", overrides=overrides, client=client)


def test_errors_on_the_cluster_are_raised(client):
    with pytest.raises(ValueError, match="which sets are closed loops"):
        smspace.dask.distances(np.zeros((3, 2, 2)), client, metric="curve")


def test_pieces_travel_to_the_cluster(client):
    # Retina within one link of the base: kernels of two pieces (issue 14); the curve
    # metric joins no two pieces, locally and on the cluster alike.
    arm = smspace.Agent.preset("planar-arm")
    found = smspace.explore(arm, n=12, seed=3, workspace=(0.9, 0.0, 1.2, 1.6))
    traced = smspace.trace(arm, found.motors, points=40, components="all", workspace=None)
    assert traced.pieces.shape == traced.sets.shape[:2]
    assert traced.pieces.max() >= 1
    local = smspace.distances(traced)
    joined = smspace.distances(traced.sets, closed=traced.closed)
    assert not np.array_equal(local, joined)
    assert np.array_equal(smspace.dask.distances(traced, client, tile=5), local)
    indices, found_d = smspace.dask.distances(traced, client, knn=2, tile=5)
    local_knn = smspace.distances(traced, knn=2)
    assert np.array_equal(indices, local_knn[0]) and np.array_equal(found_d, local_knn[1])
