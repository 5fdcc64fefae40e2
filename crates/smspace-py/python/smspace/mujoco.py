"""A MuJoCo model as a sensorimotor agent (the ``mujoco`` package, headless).

An ``MjModel`` is wrapped as a :class:`smspace.PythonAgent` by names::

    import mujoco, smspace, smspace.mujoco

    model = mujoco.MjModel.from_xml_path("arm.xml")
    agent = smspace.mujoco.agent(model, joints=["shoulder", "elbow", "wrist", "eye"],
                                 sensors=None, site="eye")       # every position sensor
    found = smspace.explore(agent, n=1500, seed=1, workspace=(1.75, 0.0, 1.5, 2.0))
    traced = smspace.trace(agent, found.motors, method="sensory")

- **Motors are joints.** Each named joint is one motor: a hinge with a range
  (``jnt_limited``) is the bounded motor ``("bounded", low, high)`` of its
  ``jnt_range``, an unlimited hinge a periodic one (period ``2π``), and a slide joint
  the bounded motor of its range (a slide joint needs one). Ball and free joints are
  refused (they are not one coordinate). The joints not named keep the model's
  ``qpos0``.
- **Sensors are the model's sensors.** ``sense`` writes a batch of motor rows into
  ``qpos``, one row at a time, runs ``mj_kinematics`` and ``mj_sensorPos`` (no
  dynamics, no rendering; ``mj_comPos``, ``mj_camlight``, ``mj_tendon`` and
  ``mj_transmission`` too when a sensor reads what they compute, ``mj_fwdPosition``
  for the few position sensors that need the whole position stage) and reads the
  named sensors' values out of ``sensordata`` (the ``sensor_dim`` values at
  ``sensor_adr`` each, in the order named). A rangefinder casts its ray (``mj_ray``)
  against the geoms' poses that ``mj_kinematics`` computed, ignoring the body of its
  own site; it needs no collision stage, and reads ``-1`` where the ray hits nothing
  (close the scene with walls so that every ray hits). Sensors of velocity or
  acceleration are refused: the agent senses its posture, and nothing moves.
- **The ground truth is a site's pose**: ``pose_space="planar"`` gives ``(x, y,
  alpha)``, the site's position in the world's ``x``-``y`` plane and the angle of its
  ``x`` axis there (``atan2`` of ``site_xmat``'s ``R[1, 0]`` and ``R[0, 0]``, in
  ``[-π, π)``); ``"spatial"`` gives ``(x, y, z, qw, qx, qy, qz)``, the site's
  position and orientation as a unit quaternion with ``qw ≥ 0``.

- **A camera is a sensor too.** ``camera=NAME`` renders the model's camera of that
  name through ``mujoco.Renderer`` at ``size=(W, H)`` pixels and appends its image to
  the sensors (with ``camera`` given, ``sensors=None`` means no other sensor): ``H W C``
  values a row, row-major, channels last, in ``[0, 1]`` (``color="rgb"``, ``C = 3``) or
  the mean of the three channels (``"grey"``, ``C = 1``), as the built-in camera and
  :func:`smspace.learn` lay frames out. Rendering needs an OpenGL backend: headless,
  ``MUJOCO_GL=egl`` (a GPU or Mesa's EGL) or ``MUJOCO_GL=osmesa``; where none loads, the
  body says so when it is built. The image must fit the model's offscreen buffer
  (``<visual><global offwidth offheight>``, 640 × 480 by default). MuJoCo renders
  with ``<visual><quality offsamples>`` multisampling (4 by default): raise it for an
  image that changes more smoothly with the motors, which the sensory tracer's
  differences need. A camera renders through one OpenGL context, so a body with a
  camera is not threaded (``threads=False``).

**Threads.** One ``MjData`` holds one posture at a time, so its calls must not
interleave. By default (``threads=False``) the agent keeps one ``MjData`` shared by
``sense`` and ``pose`` and is declared not thread-safe: the engine never calls it
concurrently (and a lock inside guards the ``MjData`` as well). With ``threads=True``
every thread that calls the agent gets its own ``MjData`` (kept by the agent, by
thread id, for as long as the agent lives) and the agent is declared thread-safe
(``thread_safe=True``), so that the engine may call it from all its threads at once: MuJoCo releases the GIL in ``mj_kinematics`` and
``mj_sensorPos``, so the rays of several threads are cast in parallel.

Batches are looped row by row in Python (the MuJoCo calls are per posture); reading
the sensors and the poses is vectorised.
"""

from __future__ import annotations

import math
import os
import threading
from typing import Any, Callable, List, Optional, Sequence, Tuple, Union

import numpy as np

from ._core import PythonAgent

__all__ = ["Body", "agent"]

ModelArg = Union["Any", str, "os.PathLike[str]"]


def _mujoco() -> Any:
    """The ``mujoco`` package, or an ImportError saying how to install it."""
    try:
        import mujoco
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError(
            "smspace.mujoco needs the mujoco package: pip install mujoco"
        ) from error
    return mujoco


def _load(model: ModelArg) -> Any:
    """An ``MjModel`` as given, or loaded from an MJCF (``.xml``) or ``.mjb`` file."""
    mujoco = _mujoco()
    if isinstance(model, mujoco.MjModel):
        return model
    if isinstance(model, (str, os.PathLike)):
        path = os.fspath(model)
        if not os.path.exists(path):
            raise ValueError(f"model file {path!r} does not exist")
        if path.endswith(".mjb"):
            return mujoco.MjModel.from_binary_path(path)
        return mujoco.MjModel.from_xml_path(path)
    raise TypeError(
        f"model must be a mujoco.MjModel or the path of an MJCF or .mjb file, got {type(model).__name__}"
    )


def _names(model: Any, kind: str, count: int) -> List[str]:
    """The names of the model's objects of ``kind`` (``joint``, ``sensor``, ``site``),
    in id order (an unnamed one as ``#id``)."""
    mujoco = _mujoco()
    obj = getattr(mujoco.mjtObj, f"mjOBJ_{kind.upper()}")
    return [mujoco.mj_id2name(model, obj, i) or f"#{i}" for i in range(count)]


def _lookup(model: Any, kind: str, name: str, count: int) -> int:
    """The id of the ``kind`` object ``name``; a ValueError naming it and the
    available names when the model has none of that name."""
    mujoco = _mujoco()
    if not isinstance(name, str):
        raise TypeError(f"a {kind} is named by a string, got {name!r}")
    obj = getattr(mujoco.mjtObj, f"mjOBJ_{kind.upper()}")
    found = mujoco.mj_name2id(model, obj, name)
    if found < 0:
        available = ", ".join(repr(n) for n in _names(model, kind, count)) or "none"
        raise ValueError(
            f"the model has no {kind} named {name!r}; its {kind}s are: {available}"
        )
    return int(found)


# Position sensors and the computation they read beyond mj_kinematics.
_NEEDS_COM = ("mjSENS_SUBTREECOM",)
_NEEDS_CAMLIGHT = ("mjSENS_CAMPROJECTION",)
_NEEDS_TENDON = ("mjSENS_TENDONPOS",)
_NEEDS_TRANSMISSION = ("mjSENS_ACTUATORPOS",)
_KINEMATIC = (
    "mjSENS_RANGEFINDER",
    "mjSENS_MAGNETOMETER",
    "mjSENS_JOINTPOS",
    "mjSENS_BALLQUAT",
    "mjSENS_FRAMEPOS",
    "mjSENS_FRAMEQUAT",
    "mjSENS_FRAMEXAXIS",
    "mjSENS_FRAMEYAXIS",
    "mjSENS_FRAMEZAXIS",
    "mjSENS_INSIDESITE",
    "mjSENS_GEOMDIST",
    "mjSENS_GEOMNORMAL",
    "mjSENS_GEOMFROMTO",
)


def _types(mujoco: Any, names: Sequence[str]) -> set:
    """The sensor type codes of ``names`` that this MuJoCo version has."""
    return {int(getattr(mujoco.mjtSensor, n)) for n in names if hasattr(mujoco.mjtSensor, n)}


class Body:
    """A MuJoCo model read as a sensorimotor body: its motors (``joints``), its
    sensors (``sensors``) and the pose of its ``site``, with the functions that an
    agent calls (:meth:`sense`, :meth:`pose`). :func:`agent` builds one and wraps it
    as a :class:`smspace.PythonAgent`; build one directly to inspect the mapping.

    ``model``: an ``MjModel`` or the path of an MJCF (``.xml``) or ``.mjb`` file.
    ``joints``: the names of the joints that are the motors, in order (None: every
    hinge and slide joint of the model, in id order). ``sensors``: the names of the
    sensors read, in order (None: every position sensor, in id order). ``site``: the name of the site whose
    pose is the ground truth (None: no ground truth). ``pose_space``: ``"planar"``
    ``(x, y, alpha)`` or ``"spatial"`` ``(x, y, z, qw, qx, qy, qz)``. ``threads``:
    one ``MjData`` per calling thread (True) or one shared behind a lock (False).
    ``camera``: the name of a camera whose image is read too, at ``size=(W, H)``, in
    ``color="rgb"`` or ``"grey"`` (module docs).

    A name the model lacks is a ValueError naming it and listing the model's names of
    that kind; a joint that is not one coordinate (ball, free), a slide joint without
    a range or a sensor of velocity or acceleration is a ValueError naming it.
    """

    def __init__(
        self,
        model: ModelArg,
        joints: Optional[Sequence[str]] = None,
        sensors: Optional[Sequence[str]] = None,
        site: Optional[str] = None,
        *,
        pose_space: str = "planar",
        threads: bool = False,
        camera: Optional[str] = None,
        size: Tuple[int, int] = (32, 24),
        color: str = "rgb",
    ) -> None:
        mujoco = _mujoco()
        self.model = _load(model)
        self.camera = camera
        self._camera = None if camera is None else self._camera_check(camera, size, color, threads)
        self.size = (int(size[0]), int(size[1]))
        self.color = color
        if pose_space not in ("planar", "spatial"):
            raise ValueError(
                f"pose_space {pose_space!r} must be 'planar' (x, y, alpha) or 'spatial' (x, y, z, qw, qx, qy, qz)"
            )
        self.pose_space = pose_space
        self.threads = bool(threads)
        self.joints, self.motor_space, self._qpos = self._motors(mujoco, joints)
        if camera is not None and sensors is None:
            self.sensors, self.columns, self._sensor_columns = [], [], np.empty(0, dtype=np.intp)
            self._sensor_ids = []
        else:
            self.sensors, self.columns, self._sensor_columns = self._sensor_map(mujoco, sensors)
        self.site = site
        self._site = None if site is None else _lookup(self.model, "site", site, self.model.nsite)
        self._steps = self._computation(mujoco)
        self._shared = None if self.threads else mujoco.MjData(self.model)
        self._renderer = None if camera is None else self._make_renderer(mujoco)
        self._lock = threading.Lock()
        # One MjData per calling thread, kept by the body (not in a threading.local,
        # whose values are freed with the thread's Python state: an engine thread may
        # hold one only while it calls) and freed with it.
        self._per_thread: dict = {}
        self._count_lock = threading.Lock()
        self.rows_sensed = 0
        """The motor rows :meth:`sense` has answered so far (every call counted)."""

    # --- the mapping ------------------------------------------------------------

    def _motors(self, mujoco: Any, joints: Optional[Sequence[str]]) -> Tuple[List[str], list, np.ndarray]:
        """The joints' names, motor space and ``qpos`` addresses."""
        model = self.model
        hinge, slide = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
        if joints is None:
            ids = [j for j in range(model.njnt) if int(model.jnt_type[j]) in (hinge, slide)]
            if not ids:
                raise ValueError("the model has no hinge or slide joint to be a motor")
        else:
            if isinstance(joints, str):
                raise TypeError(f"joints must be a list of joint names, got the string {joints!r}")
            ids = [_lookup(model, "joint", name, model.njnt) for name in joints]
            if not ids:
                raise ValueError("joints names no joint: an agent needs at least one motor")
            if len(set(ids)) != len(ids):
                raise ValueError(f"joints names a joint twice: {list(joints)}")
        names = _names(model, "joint", model.njnt)
        space = []
        for j in ids:
            kind = int(model.jnt_type[j])
            low, high = (float(v) for v in model.jnt_range[j])
            limited = bool(model.jnt_limited[j])
            if kind == hinge:
                space.append(("bounded", low, high) if limited else ("periodic", 2 * math.pi))
            elif kind == slide:
                if not limited:
                    raise ValueError(
                        f"the slide joint {names[j]!r} has no range: a slide motor is bounded, give it limited=\"true\" and a range"
                    )
                space.append(("bounded", low, high))
            else:
                raise ValueError(
                    f"the joint {names[j]!r} is a {'ball' if kind == int(mujoco.mjtJoint.mjJNT_BALL) else 'free'} joint: a motor is one hinge or slide coordinate"
                )
        qpos = np.array([int(model.jnt_qposadr[j]) for j in ids], dtype=np.intp)
        return [names[j] for j in ids], space, qpos

    def _sensor_map(self, mujoco: Any, sensors: Optional[Sequence[str]]) -> Tuple[List[str], List[Tuple[str, int]], np.ndarray]:
        """The sensors' names, the ``(sensor, component)`` of every column, and the
        columns' indices in ``sensordata``."""
        model = self.model
        position = int(mujoco.mjtStage.mjSTAGE_POS)
        if sensors is None:
            ids = [s for s in range(model.nsensor) if int(model.sensor_needstage[s]) <= position]
            if not ids:
                raise ValueError("the model has no position sensor: add sensors (e.g. rangefinders) to its <sensor> section")
        else:
            if isinstance(sensors, str):
                raise TypeError(f"sensors must be a list of sensor names or None, got the string {sensors!r}")
            ids = [_lookup(model, "sensor", name, model.nsensor) for name in sensors]
            if not ids:
                raise ValueError("sensors names no sensor: give None for every position sensor of the model")
        names = _names(model, "sensor", model.nsensor)
        columns, index = [], []
        for s in ids:
            if int(model.sensor_needstage[s]) > position:
                raise ValueError(
                    f"the sensor {names[s]!r} measures velocity or acceleration: the agent senses postures only (position sensors such as rangefinders, frame and joint positions)"
                )
            adr, dim = int(model.sensor_adr[s]), int(model.sensor_dim[s])
            columns.extend((names[s], c) for c in range(dim))
            index.extend(range(adr, adr + dim))
        self._sensor_ids = ids
        return [names[s] for s in ids], columns, np.array(index, dtype=np.intp)

    def _camera_check(self, camera: str, size: Any, color: str, threads: bool) -> int:
        """The camera's id, after the checks of its arguments."""
        model = self.model
        if color not in ("rgb", "grey"):
            raise ValueError(f"color {color!r} must be 'rgb' or 'grey'")
        try:
            width, height = (int(v) for v in size)
        except (TypeError, ValueError):
            raise ValueError(f"size must be (W, H) in pixels, got {size!r}") from None
        if width < 1 or height < 1:
            raise ValueError(f"size (W, H) = {size!r} must be at least one pixel each way")
        offwidth, offheight = int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
        if width > offwidth or height > offheight:
            raise ValueError(
                f"size (W, H) = ({width}, {height}) does not fit the model's offscreen buffer "
                f"{offwidth} x {offheight}: raise <visual><global offwidth offheight> in the model"
            )
        if threads:
            raise ValueError(
                "a camera renders through one OpenGL context: build the body with threads=False"
            )
        return _lookup(model, "camera", camera, model.ncam)

    def _make_renderer(self, mujoco: Any) -> Any:
        """The camera's renderer, or a RuntimeError saying why there is none."""
        width, height = self.size
        try:
            return mujoco.Renderer(self.model, height, width)
        except Exception as error:  # the backends fail in many ways
            backend = os.environ.get("MUJOCO_GL", "the default")
            raise RuntimeError(
                f"MuJoCo cannot render the camera {self.camera!r} here: no OpenGL context "
                f"with MUJOCO_GL={backend} ({type(error).__name__}: {error}); headless, set "
                "MUJOCO_GL=egl (a GPU or Mesa's EGL) or MUJOCO_GL=osmesa before importing mujoco"
            ) from error

    @property
    def image_shape(self) -> Optional[Tuple[int, int, int]]:
        """``(H, W, C)`` of the camera's image, or None without a camera."""
        if self.camera is None:
            return None
        width, height = self.size
        return (height, width, 3 if self.color == "rgb" else 1)

    def _computation(self, mujoco: Any) -> List[Callable[[Any, Any], None]]:
        """The MuJoCo calls that put one posture's sensors in ``sensordata`` (and the
        cameras' frames, for a body with a camera)."""
        if not self._sensor_ids:
            return [mujoco.mj_kinematics, mujoco.mj_camlight]
        model = self.model
        chosen = {int(model.sensor_type[s]) for s in self._sensor_ids}
        known = set().union(
            *(_types(mujoco, group) for group in (_KINEMATIC, _NEEDS_COM, _NEEDS_CAMLIGHT, _NEEDS_TENDON, _NEEDS_TRANSMISSION))
        )
        if chosen - known:
            # Sensors that read the whole position stage (limits, plugins, user sensors).
            return [mujoco.mj_fwdPosition, mujoco.mj_sensorPos]
        steps = [mujoco.mj_kinematics]
        cameras = {int(mujoco.mjtObj.mjOBJ_CAMERA), int(mujoco.mjtObj.mjOBJ_LIGHT)}
        if chosen & _types(mujoco, _NEEDS_COM):
            steps.append(mujoco.mj_comPos)
        if chosen & _types(mujoco, _NEEDS_CAMLIGHT) or any(
            int(model.sensor_objtype[s]) in cameras or int(model.sensor_reftype[s]) in cameras
            for s in self._sensor_ids
        ):
            steps.append(mujoco.mj_camlight)
        if chosen & (_types(mujoco, _NEEDS_TENDON) | _types(mujoco, _NEEDS_TRANSMISSION)):
            steps.append(mujoco.mj_tendon)
        if chosen & _types(mujoco, _NEEDS_TRANSMISSION):
            steps.append(mujoco.mj_transmission)
        if self.camera is not None and mujoco.mj_camlight not in steps:
            steps.append(mujoco.mj_camlight)
        steps.append(mujoco.mj_sensorPos)
        return steps

    # --- the calls ----------------------------------------------------------------

    @property
    def n_motors(self) -> int:
        """``N``: the number of joints."""
        return len(self.joints)

    @property
    def n_sensors(self) -> int:
        """``K``: the number of sensor values (a sensor of dimension 3 gives 3, a
        camera ``H W C``)."""
        shape = self.image_shape
        return len(self.columns) + (0 if shape is None else shape[0] * shape[1] * shape[2])

    @property
    def pose_dim(self) -> int:
        """``d``: 3 for ``planar``, 7 for ``spatial``."""
        return 3 if self.pose_space == "planar" else 7

    def _data(self) -> Any:
        """This thread's ``MjData`` (``threads=True``), else the shared one."""
        if self._shared is not None:
            return self._shared
        thread = threading.get_ident()
        data = self._per_thread.get(thread)
        if data is None:
            data = _mujoco().MjData(self.model)
            with self._count_lock:
                self._per_thread[thread] = data
        return data

    def _posture(self, data: Any, row: np.ndarray) -> None:
        """Puts the motor row in ``qpos`` and computes what the sensors read."""
        data.qpos[self._qpos] = row
        for step in self._steps:
            step(self.model, data)

    def _rows(self, motors: Any) -> np.ndarray:
        motors = np.asarray(motors, dtype=np.float64)
        if motors.ndim != 2 or motors.shape[1] != self.n_motors:
            raise ValueError(f"motors must have shape (B, {self.n_motors}), got {motors.shape}")
        return motors

    def sense(self, motors: Any) -> np.ndarray:
        """The sensor values ``(B, K)`` of the motor rows ``(B, N)``."""
        motors = self._rows(motors)
        with self._count_lock:
            self.rows_sensed += motors.shape[0]
        out = np.empty((motors.shape[0], self.n_sensors))
        if self._shared is not None:
            with self._lock:
                self._sense_into(self._shared, motors, out)
        else:
            self._sense_into(self._data(), motors, out)
        return out

    def _sense_into(self, data: Any, motors: np.ndarray, out: np.ndarray) -> None:
        columns = self._sensor_columns
        k = len(columns)
        for i, row in enumerate(motors):
            self._posture(data, row)
            np.take(data.sensordata, columns, out=out[i, :k])
            if self._renderer is not None:
                self._renderer.update_scene(data, camera=self._camera)
                image = self._renderer.render()
                if self.color == "grey":
                    image = image.mean(axis=2)
                out[i, k:] = np.ravel(image) / 255.0

    def pose(self, motors: Any) -> np.ndarray:
        """The site's poses ``(B, 3)`` (planar) or ``(B, 7)`` (spatial) of the motor
        rows ``(B, N)``."""
        if self._site is None:
            raise ValueError("this body has no site: give site= to have a ground truth")
        motors = self._rows(motors)
        if self._shared is not None:
            with self._lock:
                xpos, xmat = self._frames(self._shared, motors)
        else:
            xpos, xmat = self._frames(self._data(), motors)
        return _planar(xpos, xmat) if self.pose_space == "planar" else _spatial(xpos, xmat)

    def _frames(self, data: Any, motors: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """The site's positions ``(B, 3)`` and rotation matrices ``(B, 9)``."""
        mujoco = _mujoco()
        xpos = np.empty((motors.shape[0], 3))
        xmat = np.empty((motors.shape[0], 9))
        site = self._site
        for i, row in enumerate(motors):
            data.qpos[self._qpos] = row
            mujoco.mj_kinematics(self.model, data)
            xpos[i] = data.site_xpos[site]
            xmat[i] = data.site_xmat[site]
        return xpos, xmat

    def agent(self, name: Optional[str] = None, concurrent_sets: int = 256) -> PythonAgent:
        """This body as a :class:`smspace.PythonAgent` (see :func:`agent`):
        thread-safe when it was built with ``threads=True``."""
        if name is None:
            # The model's name opens the names buffer (MJCF's <mujoco model=...>).
            model_name = bytes(self.model.names).split(b"\0", 1)[0].decode() or "model"
            name = f"mujoco:{model_name}"
        arguments = dict(
            sense=self.sense,
            n_motors=self.n_motors,
            n_sensors=self.n_sensors,
            motor_space=self.motor_space,
            pose=None if self._site is None else self.pose,
            name=name,
            pose_space=self.pose_space,
            concurrent_sets=concurrent_sets,
        )
        return PythonAgent(**arguments, thread_safe=self.threads)

    def __repr__(self) -> str:
        camera = "" if self.camera is None else f", camera={self.camera!r} {self.size} {self.color}"
        return (
            f"smspace.mujoco.Body(joints={self.joints}, sensors={len(self.sensors)} ({self.n_sensors} values), "
            f"site={self.site!r}, pose_space={self.pose_space!r}, threads={self.threads}{camera})"
        )


def _planar(xpos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    """``(x, y, alpha)``: the position in the plane and the angle of the ``x`` axis,
    in ``[-π, π)``."""
    alpha = np.arctan2(xmat[:, 3], xmat[:, 0])
    alpha = np.where(alpha >= math.pi, alpha - 2 * math.pi, alpha)
    return np.column_stack([xpos[:, 0], xpos[:, 1], alpha])


def _spatial(xpos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    """``(x, y, z, qw, qx, qy, qz)`` with ``qw ≥ 0``."""
    mujoco = _mujoco()
    quats = np.empty((xpos.shape[0], 4))
    for i in range(xpos.shape[0]):
        mujoco.mju_mat2Quat(quats[i], xmat[i])
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    quats[quats[:, 0] < 0] *= -1.0
    return np.column_stack([xpos, quats])


def agent(
    model: ModelArg,
    joints: Optional[Sequence[str]] = None,
    sensors: Optional[Sequence[str]] = None,
    site: Optional[str] = None,
    *,
    pose_space: str = "planar",
    threads: bool = False,
    name: Optional[str] = None,
    concurrent_sets: int = 256,
    camera: Optional[str] = None,
    size: Tuple[int, int] = (32, 24),
    color: str = "rgb",
) -> PythonAgent:
    """A :class:`smspace.PythonAgent` whose body is the MuJoCo ``model``: its motors
    are the named ``joints`` (None: every hinge and slide joint), its sensors the
    named ``sensors`` (None: every position sensor; ``K`` = the sum of their
    dimensions), its
    ground truth the pose of ``site`` (None: none; ``pose_space="planar"`` ``(x, y,
    alpha)`` or ``"spatial"`` ``(x, y, z, qw, qx, qy, qz)``). A hinge with a range is
    a bounded motor, one without a periodic motor.

    ``threads=False`` (the default): one ``MjData``, shared by ``sense`` and ``pose``;
    the agent is not thread-safe and the engine calls it from one thread at a time.
    ``threads=True``: one ``MjData`` per calling thread, and the agent is thread-safe
    (the engine may call it from all its threads at once). ``name``: the agent's name
    in messages (default ``mujoco:<model name>``); ``concurrent_sets``: as for
    :class:`smspace.PythonAgent`. See :class:`Body` for the mapping and the errors
    (a missing joint, sensor or site is a ValueError naming it and listing the
    model's names); ``Body(...).agent()`` is the same agent with its body at hand
    (e.g. to read :attr:`Body.rows_sensed`). ``camera``: the name of a camera whose
    image, ``size=(W, H)`` pixels in ``color="rgb"`` or ``"grey"``, is read as ``H W C``
    more sensors (module docs; it needs an OpenGL backend, e.g. ``MUJOCO_GL=egl``)."""
    body = Body(
        model, joints, sensors, site, pose_space=pose_space, threads=threads,
        camera=camera, size=size, color=color,
    )
    return body.agent(name=name, concurrent_sets=concurrent_sets)
