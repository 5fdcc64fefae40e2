"""A set metric written in Python, registered from outside the package, runs through
every function that builds a metric by name and through the whole pipeline, with no
other change: `smspace.register_metric`."""

import numpy as np
import pytest

import smspace
from conftest import random_sets


def centroids(a, b, scale=1.0):
    """The distance between the two sets' centroids, times `scale`."""
    return scale * float(np.linalg.norm(a.mean(axis=0) - b.mean(axis=0)))


def centroid_matrix(sets, scale=1.0):
    c = sets.mean(axis=1)
    return scale * np.linalg.norm(c[:, None, :] - c[None, :, :], axis=2)


@pytest.fixture(scope="module", autouse=True)
def registered():
    smspace.register_metric(
        "centroids", centroids, summary="between the centroids", is_metric=True
    )


def test_a_registered_metric_is_listed_with_the_built_in_ones():
    names = dict(smspace.metrics())
    assert names["centroids"] == "between the centroids"
    assert {"hausdorff", "curve", "surface"} <= set(names)


def test_distances_and_knn_run_it_pair_by_pair():
    sets = random_sets(12, 9, 3, seed=4)
    d = smspace.distances(sets, metric="centroids", period="none")
    assert np.allclose(d, centroid_matrix(sets), atol=1e-12)
    indices, values = smspace.knn(sets, 3, metric="centroids", period="none")
    expected = np.sort(centroid_matrix(sets) + np.diag([np.inf] * 12), axis=1)[:, :3]
    assert np.allclose(values, expected, atol=1e-12)
    assert indices.shape == (12, 3)


def test_the_pipeline_runs_it_with_its_parameters(tmp_path):
    experiment = tmp_path / "tiny.toml"
    experiment.write_text(
        """
[agent]
kind = "toy-redundant"
[exploration]
n = 40
[kernel]
method = "kinematic"
points = 10
[metric]
metric = "centroids"
period = "none"
[metric.params]
scale = 2.0
[embedding]
method = "mds"
dim = 1
[analysis]
mle_neighbors = 6
[report]
formats = "svg"
sample_configurations = 2
sample_sets = 2
"""
    )
    run = smspace.run(experiment, tmp_path / "run")
    sets = np.load(tmp_path / "run" / "sets.npy")
    assert np.allclose(run.D, centroid_matrix(sets, scale=2.0), atol=1e-9)
    resolved = (tmp_path / "run" / "config.resolved.toml").read_text()
    assert 'metric = "centroids"' in resolved and "scale = 2.0" in resolved


def test_a_failing_or_wrong_callable_is_an_error_naming_the_metric():
    sets = random_sets(4, 5, 2, seed=1)

    def raises(a, b):
        raise RuntimeError("the simulator is gone")

    smspace.register_metric("raises", raises)
    with pytest.raises(ValueError, match="raises metric failed.*the simulator is gone"):
        smspace.distances(sets, metric="raises", period="none")
    smspace.register_metric("negative", lambda a, b: -1.0)
    with pytest.raises(ValueError, match="negative metric failed.*at least 0"):
        smspace.distances(sets, metric="negative", period="none")
    smspace.register_metric("text", lambda a, b: "far")
    with pytest.raises(ValueError, match="text metric failed.*float"):
        smspace.distances(sets, metric="text", period="none")


def test_bad_registrations_are_refused():
    with pytest.raises(ValueError, match="built-in"):
        smspace.register_metric("curve", centroids)
    with pytest.raises(ValueError, match="callable"):
        smspace.register_metric("nothing", 3.0)
    with pytest.raises(ValueError, match="not a metric name"):
        smspace.register_metric("two words", centroids)
    with pytest.raises(ValueError, match="centroids"):
        smspace.distances(random_sets(3, 4, 2, seed=2), metric="centroid", period="none")
