"""smspace.mujoco: a MuJoCo model as an agent (skipped where the mujoco package is not
installed), and the example of examples/python/mujoco_arm.py in its small size."""

import importlib.util
import math

import numpy as np
import pytest

# conftest.py asks MuJoCo for headless EGL rendering where it can (the camera's tests).
mujoco = pytest.importorskip(
    "mujoco", reason="the mujoco package is not installed (pip install mujoco): its tests are skipped"
)

import smspace  # noqa: E402
import smspace.mujoco  # noqa: E402

# A small body: a limited hinge, an unlimited hinge, a slide with a range, and a ball
# joint; a rangefinder, a frame position, a joint position and a velocimeter.
JOINTS_XML = """
<mujoco model="joints">
  <compiler angle="radian"/>
  <worldbody>
    <geom name="wall" type="box" pos="4 0 0" size="0.1 4 1"/>
    <body name="a">
      <joint name="limited" type="hinge" axis="0 0 1" range="-1.5 2"/>
      <geom type="capsule" fromto="0 0 0 1 0 0" size="0.05"/>
      <body name="b" pos="1 0 0">
        <joint name="free-hinge" type="hinge" axis="0 1 1"/>
        <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05"/>
        <body name="c" pos="0.5 0 0">
          <joint name="slider" type="slide" axis="1 0 0" range="-0.2 0.4"/>
          <geom type="sphere" size="0.05"/>
          <site name="tip" pos="0.1 0 0" euler="0.3 -0.2 0.5"/>
          <body name="d" pos="0.2 0 0">
            <joint name="ball" type="ball"/>
            <joint name="loose" type="slide" axis="0 0 1"/>
            <geom type="sphere" size="0.03"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <sensor>
    <rangefinder name="range" site="tip"/>
    <framepos name="where" objtype="site" objname="tip"/>
    <jointpos name="angle" joint="limited"/>
    <velocimeter name="speed" site="tip"/>
  </sensor>
</mujoco>
"""

MOVABLE = ["limited", "free-hinge", "slider"]
POSITION_SENSORS = ["range", "where", "angle"]


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(JOINTS_XML)


@pytest.fixture(scope="module")
def example(root):
    """examples/python/mujoco_arm.py, imported."""
    path = root / "examples" / "python" / "mujoco_arm.py"
    spec = importlib.util.spec_from_file_location("mujoco_arm", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def postures(count, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([
        rng.uniform(-1.5, 2.0, count), rng.uniform(-math.pi, math.pi, count), rng.uniform(-0.2, 0.4, count)
    ])


@pytest.mark.parametrize(
    "arguments, message",
    [
        (dict(joints=["limited", "elbow"]), r"no joint named 'elbow'; its joints are: 'limited', 'free-hinge', 'slider', 'ball', 'loose'"),
        (dict(joints=MOVABLE, sensors=["range", "lidar"]), r"no sensor named 'lidar'; its sensors are: 'range', 'where', 'angle', 'speed'"),
        (dict(joints=MOVABLE, sensors=POSITION_SENSORS, site="eye"), r"no site named 'eye'; its sites are: 'tip'"),
        (dict(joints=["ball"]), r"the joint 'ball' is a ball joint"),
        (dict(joints=["loose"]), r"the slide joint 'loose' has no range"),
        (dict(joints=MOVABLE, sensors=["speed"]), r"the sensor 'speed' measures velocity"),
        (dict(joints=["limited", "limited"]), r"names a joint twice"),
    ],
)
def test_a_name_the_model_lacks_is_a_clear_error(model, arguments, message):
    with pytest.raises(ValueError, match=message):
        smspace.mujoco.agent(model, **arguments)


def test_joints_are_motors_and_ranges_bound_them(model):
    agent = smspace.mujoco.agent(model, joints=MOVABLE, sensors=POSITION_SENSORS, site="tip")
    assert agent.n_motors == 3
    assert agent.n_sensors == 1 + 3 + 1
    assert agent.motor_space == [
        ("bounded", -1.5, 2.0),
        ("periodic", 0.0, 2 * math.pi),
        ("bounded", -0.2, 0.4),
    ]
    assert agent.name == "mujoco:joints"
    body = smspace.mujoco.Body(model, joints=MOVABLE, sensors=None, site="tip", pose_space="spatial")
    # Every hinge and slide joint by default (the ball joint is not one coordinate).
    with pytest.raises(ValueError, match="'loose' has no range"):
        smspace.mujoco.Body(model)
    # Every position sensor by default (the velocimeter is left out).
    assert body.sensors == POSITION_SENSORS
    assert body.columns == [("range", 0), ("where", 0), ("where", 1), ("where", 2), ("angle", 0)]


def test_sensors_and_pose_are_mujocos(model):
    agent = smspace.mujoco.agent(model, joints=MOVABLE, sensors=POSITION_SENSORS, site="tip")
    spatial = smspace.mujoco.agent(model, joints=MOVABLE, sensors=POSITION_SENSORS, site="tip", pose_space="spatial")
    motors = postures(40)
    sensed, planar, poses = agent.sense(motors), agent.poses(motors), spatial.poses(motors)
    data = mujoco.MjData(model)
    site = model.site("tip").id
    for i, row in enumerate(motors):
        data.qpos[:] = model.qpos0
        data.qpos[[model.joint(j).qposadr[0] for j in MOVABLE]] = row
        mujoco.mj_forward(model, data)
        np.testing.assert_allclose(sensed[i], data.sensordata[:5], rtol=0, atol=1e-12)
        xpos, xmat = data.site_xpos[site], data.site_xmat[site].reshape(3, 3)
        np.testing.assert_allclose(planar[i, :2], xpos[:2], rtol=0, atol=1e-12)
        assert planar[i, 2] == pytest.approx(math.atan2(xmat[1, 0], xmat[0, 0]), abs=1e-12)
        assert -math.pi <= planar[i, 2] < math.pi
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, data.site_xmat[site])
        quat *= np.sign(quat[0]) or 1.0
        np.testing.assert_allclose(poses[i], np.concatenate([xpos, quat]), rtol=0, atol=1e-12)
        assert poses[i, 3] >= 0


def test_the_rays_and_the_eye_of_the_example(example):
    body = example.body()
    assert body.joints == ["shoulder", "elbow", "wrist", "eye"]
    assert body.n_sensors == 12
    motors = np.random.default_rng(3).uniform(-math.pi, math.pi, size=(200, 4))
    readings = body.sense(motors)
    # The room is closed and the obstacles are out of reach: every ray hits.
    assert readings.min() > 0
    # The eye is at the end of three links of length 1, heading along the angles' sum.
    angles = np.cumsum(motors[:, :3], axis=1)
    poses = body.pose(motors)
    np.testing.assert_allclose(poses[:, 0], np.cos(angles).sum(axis=1), atol=1e-12)
    np.testing.assert_allclose(poses[:, 1], np.sin(angles).sum(axis=1), atol=1e-12)
    heading = np.angle(np.exp(1j * (motors.sum(axis=1) - poses[:, 2])))
    np.testing.assert_allclose(heading, 0.0, atol=1e-12)
    # Sensing depends on the eye's pose only (no ray hits the arm): the last two
    # links swapped (the same two vectors, summed in the other order) and the eye's
    # hinge turned to keep the heading leave the eye where it was.
    q1, q2, q3, q4 = motors.T
    swapped = np.column_stack([q1, q2 + q3, -q3, q4 + q3])
    np.testing.assert_allclose(body.pose(swapped), poses, atol=1e-12)
    np.testing.assert_allclose(body.sense(swapped), readings, rtol=0, atol=1e-9)
    assert body.rows_sensed == 400


def test_a_shared_mjdata_and_one_per_thread_trace_the_same_sets(example):
    shared, threaded = example.body(threads=False), example.body(threads=True)
    found = smspace.explore(shared.agent(), n=8, seed=4, workspace=example.WORKSPACE)
    one = smspace.trace(shared.agent(), found.motors, method="sensory", points=30)
    many = smspace.trace(threaded.agent(), found.motors, method="sensory", points=30)
    assert len(one) >= 7
    assert np.array_equal(one.kept, many.kept)
    assert np.array_equal(one.sets, many.sets)
    # Each set holds the eye still: the kinematic and the sensory sets agree.
    poses = shared.pose(one.sets.reshape(-1, 4)).reshape(len(one), 30, 3)
    assert np.abs(poses - poses[:, :1]).max() < 1e-6


def test_the_example_runs_in_its_small_size(example, tmp_path):
    figures = example.run(sets=60, points=50, out=tmp_path)
    assert figures["traced_fraction"] >= 0.9, figures
    assert figures["eye_position_spread"] < 1e-6
    assert figures["betti"][0] == 1
    assert figures["sensor_rows_per_start"] > 0
    assert (tmp_path / "analysis.json").exists() and (tmp_path / "D.npy").exists()
    assert np.load(tmp_path / "D.npy").shape == (figures["traced"],) * 2


def test_the_examples_noise_is_seeded_and_gaussian(example):
    motors = np.random.default_rng(5).uniform(-math.pi, math.pi, size=(400, 4))
    motors[200:300] = motors[7]  # 101 identical rows
    noise = example.NoisyDepths(lambda m: np.zeros((len(m), 12)), sigma=0.02, seed=3)
    once, again = noise(motors), noise(motors)
    np.testing.assert_array_equal(once, again)
    # Identical rows of one batch read differently; the same row alone reads as the
    # first of them, and the order of the rows changes nothing but which repeat is which.
    assert len(np.unique(once[200:300, 0])) == 100
    np.testing.assert_array_equal(noise(motors[7:8])[0], once[7])
    order = np.random.default_rng(6).permutation(400)
    shuffled = np.empty_like(once)
    shuffled[order] = noise(motors[order])
    np.testing.assert_array_equal(np.delete(shuffled, np.r_[7, 200:300], 0), np.delete(once, np.r_[7, 200:300], 0))
    np.testing.assert_array_equal(np.sort(shuffled[np.r_[7, 200:300]], 0), np.sort(once[np.r_[7, 200:300]], 0))
    # Another seed, other draws; the draws are standard normal times sigma.
    assert not np.array_equal(example.NoisyDepths(noise.sense, 0.02, seed=4)(motors), once)
    draws = example.NoisyDepths(noise.sense, 1.0, seed=8)(np.random.default_rng(9).normal(size=(5000, 4)))
    assert abs(draws.mean()) < 0.02 and abs(draws.std() - 1.0) < 0.02
    assert abs(np.mean(np.abs(draws) < 1.0) - 0.6827) < 0.01


def test_noisy_depths_trace_near_the_exact_sets(example):
    # The rays pass the edges of the room's obstacles as the arm moves: the tracer
    # leaves the sensors that jump out of the slope where they jump (0 of 20 sets
    # were traced at 1 cm of noise before it did).
    exact = example.body()
    noisy = example.body()
    noisy.sense = example.NoisyDepths(noisy.sense, 0.01, seed=1)
    found = smspace.explore(exact.agent(), n=3, seed=2, workspace=example.WORKSPACE)
    truth = smspace.trace(exact.agent(), found.motors, method="sensory", points=30)
    traced = smspace.trace(noisy.agent(), found.motors, method="sensory", points=30)
    assert len(traced) >= 2, traced.report["summary"]
    noise = traced.report["summary"]["noise"]
    assert noise["sigma"] == pytest.approx(0.01, rel=0.1)
    assert any(s["noise"].get("discontinuous") for s in traced.report["sets"])
    errors = example.set_errors(traced, truth)
    assert len(errors) >= 2 and errors.max() < 0.01, errors


def test_what_a_trace_warns_of_is_raised_and_named_in_the_error(example):
    # Sets that miss pieces of their level set (the arm anywhere in reach): a warning.
    arm = smspace.Agent.preset("planar-arm")
    found = smspace.explore(arm, n=40, seed=1, workspace=None)
    with pytest.warns(smspace.TraceWarning, match="sets miss pieces of their level set"):
        traced = smspace.trace(arm, found.motors, method="kinematic", points=30, workspace=None)
    assert any("miss pieces" in w for w in traced.warnings)
    # Depths read with 3 m of noise: no set is kept, and the error gives the measured
    # noise as well as the statuses.
    body = example.body()
    body.sense = example.NoisyDepths(body.sense, 3.0, seed=1)
    found = smspace.explore(example.body().agent(), n=2, seed=2, workspace=example.WORKSPACE)
    with pytest.raises(ValueError, match=r"only 0 of 2 sets(.|\n)*the sensors are noisy \(σ = 2\.9"):
        smspace.trace(body.agent(), found.motors, method="sensory", points=20)


# A two-hinge arm carrying a camera inside a room of coloured walls.
CAMERA_XML = """
<mujoco model="camera-arm">
  <visual><quality offsamples="8"/></visual>
  <worldbody>
    <light pos="0 0 4" dir="0 0 -1" directional="true"/>
    <geom type="box" pos="3 0 0" size="0.1 3 2" rgba="0.9 0.2 0.2 1"/>
    <geom type="box" pos="-3 0 0" size="0.1 3 2" rgba="0.2 0.9 0.2 1"/>
    <geom type="box" pos="0 3 0" size="3 0.1 2" rgba="0.2 0.2 0.9 1"/>
    <geom type="box" pos="0 -3 0" size="3 0.1 2" rgba="0.9 0.9 0.2 1"/>
    <body name="upper">
      <joint name="shoulder" type="hinge" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 1 0 0" size="0.05"/>
      <body name="lower" pos="1 0 0">
        <joint name="eye" type="hinge" axis="0 0 1"/>
        <geom type="sphere" size="0.04"/>
        <site name="lens" pos="0.1 0 0"/>
        <camera name="eye" pos="0.1 0 0" xyaxes="0 -1 0 0 0 1" fovy="60"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.fixture(scope="module")
def camera_body():
    model = mujoco.MjModel.from_xml_string(CAMERA_XML)
    try:
        return smspace.mujoco.Body(model, ["shoulder", "eye"], None, "lens", camera="eye", size=(32, 24))
    except RuntimeError as error:
        pytest.skip(f"no OpenGL backend for MuJoCo's renderer here: {error}")


def test_a_mujoco_camera_is_read_as_rows_of_pixels(camera_body):
    body = camera_body
    assert body.image_shape == (24, 32, 3) and body.n_sensors == 24 * 32 * 3
    rows = np.array([[0.0, 0.0], [0.0, 0.5], [1.0, -2.0], [0.0, 0.0]])
    images = body.sense(rows)
    assert images.shape == (4, 24 * 32 * 3)
    assert np.all((images >= 0.0) & (images <= 1.0))
    # Deterministic, and a turn of the camera changes what it sees.
    assert np.array_equal(images[0], images[3])
    assert np.abs(images[0] - images[1]).max() > 0.1
    # Looking along +x at the red wall; turned by pi, at the green one.
    frame = images[0].reshape(24, 32, 3)
    turned = body.sense(np.array([[0.0, math.pi]]))[0].reshape(24, 32, 3)
    assert frame[12, 16, 0] > frame[12, 16, 1] and turned[12, 16, 1] > turned[12, 16, 0]
    agent = body.agent()
    assert agent.n_sensors == 24 * 32 * 3
    model = body.model
    grey = smspace.mujoco.Body(model, ["shoulder", "eye"], camera="eye", size=(16, 12), color="grey")
    assert grey.image_shape == (12, 16, 1) and grey.sense(rows[:1]).shape == (1, 192)


def test_a_mujoco_camera_refuses_what_it_cannot_render(camera_body):
    model = camera_body.model
    with pytest.raises(ValueError, match="no camera named 'nose'.*'eye'"):
        smspace.mujoco.Body(model, ["shoulder", "eye"], camera="nose")
    with pytest.raises(ValueError, match="offscreen buffer"):
        smspace.mujoco.Body(model, ["shoulder", "eye"], camera="eye", size=(4000, 30))
    with pytest.raises(ValueError, match="threads=False"):
        smspace.mujoco.Body(model, ["shoulder", "eye"], camera="eye", threads=True)
    with pytest.raises(ValueError, match="'rgb' or 'grey'"):
        smspace.mujoco.Body(model, ["shoulder", "eye"], camera="eye", color="depth")
