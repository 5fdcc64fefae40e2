"""Agents written in Python: the NumPy arm of examples/python against the built-in
arm, batched calls, and callables that fail."""

import numpy as np
import pytest

import smspace


@pytest.fixture(scope="module")
def arms(numpy_arm_module):
    builtin = smspace.Agent.preset("planar-arm")
    lights = builtin.lights(1)
    return builtin, numpy_arm_module.numpy_arm(lights), lights


def test_the_numpy_arm_senses_as_the_builtin_arm(arms):
    builtin, agent, _ = arms
    motors = np.random.default_rng(0).uniform(-np.pi, np.pi, size=(50, 4))
    np.testing.assert_allclose(agent.sense(motors), builtin.sense(motors, env=1), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(agent.poses(motors), builtin.poses(motors), rtol=0, atol=1e-14)
    assert (agent.name, agent.n_motors, agent.n_sensors) == ("numpy-arm", 4, 6)
    assert agent.motor_space == [("periodic", 0.0, 2 * np.pi)] * 4


def test_sensory_kernel_sets_match_the_builtin_arm(arms):
    builtin, agent, _ = arms
    found = smspace.explore(builtin, n=8, seed=2)
    ours = smspace.trace(agent, found.motors, method="sensory", points=30)
    theirs = smspace.trace(builtin, found.motors, method="sensory", env=1, points=30)
    assert len(ours) >= 6
    assert np.array_equal(ours.kept, theirs.kept)
    assert np.array_equal(ours.closed, theirs.closed)
    np.testing.assert_allclose(ours.sets, theirs.sets, rtol=0, atol=1e-8)
    D_ours, D_theirs = smspace.distances(ours), smspace.distances(theirs)
    np.testing.assert_allclose(D_ours, D_theirs, rtol=0, atol=1e-8)


def test_kinematic_tracing_with_a_python_pose(arms):
    builtin, agent, _ = arms
    found = smspace.explore(agent, n=5, seed=4, workspace=(1.75, 0.0, 1.5, 2.0))
    ours = smspace.trace(agent, found.motors, points=20, workspace=None)
    theirs = smspace.trace(builtin, found.motors, points=20, workspace=None)
    assert np.array_equal(ours.kept, theirs.kept)
    np.testing.assert_allclose(ours.sets, theirs.sets, rtol=0, atol=1e-7)


def test_the_tracer_asks_for_a_jacobian_in_one_batch(arms, numpy_arm_module):
    _, _, lights = arms
    sense = numpy_arm_module.make_sense(lights)
    batches = []

    def counted(motors):
        batches.append(motors.shape[0])
        return sense(motors)

    agent = smspace.PythonAgent(sense=counted, n_motors=4, n_sensors=6)
    start = np.array([[0.3, 0.4, -0.5, 0.2]])
    traced = smspace.trace(agent, start, method="sensory", points=10,
                           jacobian="finite-differences")
    assert len(traced) == 1
    # The 2N + 1 = 9 readings of each finite-difference linearisation come in one call.
    assert max(batches) == 9 and batches.count(9) > 10


def test_concurrent_sets_gather_many_sets_into_one_call(arms, numpy_arm_module):
    builtin, _, lights = arms
    sense = numpy_arm_module.make_sense(lights)
    found = smspace.explore(builtin, n=12, seed=3)

    def traced_with(concurrent_sets):
        batches = []

        def counted(motors):
            batches.append(motors.shape[0])
            return sense(motors)

        agent = smspace.PythonAgent(
            sense=counted, n_motors=4, n_sensors=6, pose=numpy_arm_module.pose,
            concurrent_sets=concurrent_sets,
        )
        traced = smspace.trace(agent, found.motors, method="sensory", points=20,
                               jacobian="finite-differences")
        return traced, batches

    alone, alone_batches = traced_with(1)
    together, together_batches = traced_with(12)
    # The same sets bit for bit, in far fewer calls: the 12 sets are traced at once in
    # two groups of 6, whose rounds carry the rows of several sets at once: 5 or 6
    # Jacobians of 9 rows in the largest call, as the sets' requests line up in rounds.
    assert np.array_equal(alone.kept, together.kept)
    assert np.array_equal(alone.sets, together.sets)
    assert max(alone_batches) == 9
    assert max(together_batches) in (5 * 9, 6 * 9)
    assert 2 * len(together_batches) < len(alone_batches)


def test_concurrent_sets_is_checked():
    for bad in (0, 5000):
        with pytest.raises(ValueError, match=f"concurrent_sets = {bad} must be 1 to 4096"):
            smspace.PythonAgent(sense=abs, n_motors=2, n_sensors=3, concurrent_sets=bad)


def test_the_whole_pipeline_runs_on_a_python_agent(arms):
    _, agent, _ = arms
    found = smspace.explore(agent, n=30, seed=1, workspace=(1.75, 0.0, 1.5, 2.0))
    traced = smspace.trace(agent, found.motors, method="sensory", points=20)
    D = smspace.distances(traced)
    Y = smspace.embed(D, method="mds", dim=3)
    report = smspace.analyze(D, poses=found.poses[traced.kept])
    assert Y.shape == (len(traced), 3) and report["agreement"]["spearman"] > 0.5


def test_a_raising_callable_is_raised_naming_it():
    def broken(motors):
        raise ZeroDivisionError("no light")

    agent = smspace.PythonAgent(sense=broken, n_motors=2, n_sensors=3)
    with pytest.raises(smspace.CallbackError, match="the sense callable of the python agent raised") as raised:
        smspace.trace(agent, np.zeros((3, 2)), method="sensory")
    assert isinstance(raised.value.__cause__, ZeroDivisionError)
    # The agent can be used again once the error was raised.
    with pytest.raises(smspace.CallbackError):
        agent.sense(np.zeros((1, 2)))


@pytest.mark.parametrize(
    "answer, match",
    [
        (lambda m: np.zeros((m.shape[0], 2)), r"shape \(\d+, 3\).*shape \(\d+, 2\)"),
        (lambda m: np.zeros((m.shape[0], 3), dtype=np.float32), "dtype float32"),
        (lambda m: [[0.0, 0.0, 0.0]] * m.shape[0], "type list"),
        (lambda m: np.full((m.shape[0], 3), np.nan), "returned NaN"),
    ],
)
def test_a_wrong_answer_is_an_error_naming_the_callable(answer, match):
    agent = smspace.PythonAgent(sense=answer, n_motors=2, n_sensors=3, name="sim")
    with pytest.raises(smspace.CallbackError, match="the sense callable of the sim agent"):
        agent.sense(np.zeros((4, 2)))
    with pytest.raises(smspace.CallbackError, match=match):
        smspace.trace(agent, np.zeros((2, 2)), method="sensory")


def test_bad_constructor_arguments():
    with pytest.raises(TypeError, match="sense must be callable"):
        smspace.PythonAgent(sense=3, n_motors=2, n_sensors=3)
    with pytest.raises(TypeError, match=r"motor_space\[1\]"):
        smspace.PythonAgent(sense=abs, n_motors=2, n_sensors=3, motor_space=["hinge", ("twisty", 1.0)])
    with pytest.raises(ValueError, match="motor_space"):
        smspace.PythonAgent(sense=abs, n_motors=3, n_sensors=3, motor_space=["hinge"])
    with pytest.raises(ValueError, match="kinematic|ground truth"):
        agent = smspace.PythonAgent(sense=lambda m: m, n_motors=2, n_sensors=2)
        smspace.trace(agent, np.zeros((1, 2)))


def test_bounded_motors_of_a_python_agent():
    # The redundant toy (section 2.3): s depends on m1 + m2 only; bounded motors.
    def sense(m):
        x = m.sum(axis=1)
        return np.stack([np.exp(-(x - 0.5) ** 2), np.exp(-(x + 0.5) ** 2)], axis=1)

    agent = smspace.PythonAgent(sense=sense, n_motors=2, n_sensors=2,
                                motor_space=[("bounded", -1.0, 1.0)] * 2)
    traced = smspace.trace(agent, np.array([[0.2, 0.1], [-0.3, 0.5]]), method="sensory", points=9)
    sums = traced.sets.sum(axis=2)
    np.testing.assert_allclose(sums, [[0.3] * 9, [0.2] * 9], atol=1e-6)
    assert list(traced.closed) == [0, 0]


def test_a_spatial_pose_of_a_python_agent(root):
    # The 3-D arm of experiments/arm-3d.toml seen through Python callables: its poses
    # (x, y, z, qw, qx, qy, qz) and its kinematic kernel sets are the chain's.
    chain = smspace.Agent.from_toml(root / "experiments" / "arm-3d.toml")
    agent = smspace.PythonAgent(
        sense=lambda m: chain.sense(m),
        n_motors=chain.n_motors,
        n_sensors=chain.n_sensors,
        pose=lambda m: chain.poses(m),
        pose_space="spatial",
    )
    motors = np.random.default_rng(3).uniform(-np.pi, np.pi, size=(4, chain.n_motors))
    assert agent.poses(motors).shape == (4, 7)
    np.testing.assert_array_equal(agent.poses(motors), chain.poses(motors))
    ours = smspace.trace(agent, motors, points=20, workspace=None)
    theirs = smspace.trace(chain, motors, points=20, workspace=None)
    assert len(theirs) >= 3
    assert np.array_equal(ours.kept, theirs.kept)
    np.testing.assert_allclose(ours.sets, theirs.sets, rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match="pose_space 'sideways'"):
        smspace.PythonAgent(sense=abs, n_motors=2, n_sensors=3, pose_space="sideways")
