"""Robot cameras: MuJoCo offscreen rendering, each frame from the state of its own sim time.

How this works: a camera is a sensor in the robot file (``type = "Camera"``) with a mount pose,
a resolution, a horizontal field of view in radians (a float, never rounded: the vertical one
follows from the aspect ratio) and a frame rate. It becomes a MuJoCo ``<camera>`` in the robot's
body. An identity mount looks straight down like every downward sensor (boresight = sensor +z),
with the image's top towards the body's front (sensor +x) and its right towards sensor +y.

:class:`CameraSystem` hooks into the engine. When a camera is due (frame n at the first step
with ``t >= n / rate``), the engine thread snapshots ``qpos`` and hands it to one render thread
that owns the OpenGL context (EGL or OSMesa contexts belong to the thread that made them). The
render thread recomputes kinematics on its own ``MjData``, renders, publishes the frame to the
image server's :class:`FrameBuffer` and hands a :class:`~skeye.sim.readings.CameraFrame` to the
robot's sink (which the control server sends as ``SEN {Type Camera} {Name n} {Frame k}``). In
lockstep mode the engine waits for the render, so frames are exact and
reproducible; in real time it never waits: a snapshot that finds the renderer busy is skipped
(counted in ``skipped``) and the frame numbers show clients what was rendered.
"""

from __future__ import annotations

import logging
import math
import os
import queue
import threading
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from skeye.errors import ConfigError, LocalProtocolError, SkeyeError
from skeye.robots.camera_model import (
    CAMERA_MODEL_KEYS,
    PROFILES,
    CameraModel,
    build_camera_model,
    pinhole,
)
from skeye.robots.config import SensorMount
from skeye.sim import frames
from skeye.sim.gl import GL_BACKEND  # noqa: F401  (before mujoco: picks MUJOCO_GL)
from skeye.sim.image_server import Frame, FrameBuffer
from skeye.sim.lens import Lens, Motion
from skeye.sim.readings import CameraFrame, RobotStopped
from skeye.workers import Worker

log = logging.getLogger(__name__)

_CAMERA_KEYS = {"width", "height", "fov_h_rad", "rate_hz", "near_m", "far_m"} | CAMERA_MODEL_KEYS


@dataclass
class CameraSpec:
    """One mounted camera and its run-time state."""

    name: str
    mount: SensorMount
    width: int = 800
    height: int = 600
    fov_h_rad: float = 1.309
    rate_hz: float = 30.0
    near_m: float = 0.01
    far_m: float = 300.0
    camera_id: int = 0
    model: CameraModel | None = None  # the lens and sensor (skeye.robots.camera_model)
    lens: Lens | None = None  # its image path; None: the ideal pinhole, rendered as is
    rendered: int = 0
    due: int = 0
    type_name: str = field(default="Camera", init=False)

    @classmethod
    def from_mount(cls, mount: SensorMount, owner: str, profile: str | None = None) -> CameraSpec:
        """The camera of one robot-file entry; ``profile`` overrides the entry's (CLI)."""
        params = dict(mount.params)
        unknown = sorted(set(params) - _CAMERA_KEYS)
        where = f"{owner} camera {mount.name!r}"
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {unknown}; known: {sorted(_CAMERA_KEYS)}")
        spec = cls(name=mount.name, mount=mount)
        for key in ("width", "height"):
            if key in params:
                value = params[key]
                if isinstance(value, bool) or not isinstance(value, int) or not 8 <= value <= 8192:
                    raise ConfigError(f"{where}: {key} must be an integer 8..8192, got {value!r}")
                setattr(spec, key, value)
        for key in ("fov_h_rad", "rate_hz", "near_m", "far_m"):
            if key in params:
                value = params[key]
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise ConfigError(f"{where}: {key} must be a number, got {value!r}")
                if not (math.isfinite(value) and value > 0):
                    raise ConfigError(f"{where}: {key} must be positive, got {value!r}")
                setattr(spec, key, float(value))
        check_fov(spec.fov_h_rad, where)
        if spec.near_m >= spec.far_m:
            raise ConfigError(f"{where}: near_m must be < far_m")
        spec.set_model(build_camera_model(params, spec.width, spec.height, spec.fov_h_rad,
                                          where, profile))
        return spec

    def set_model(self, model: CameraModel) -> None:
        """Use this camera model: its pinhole's field of view, and its lens unless ideal."""
        self.model = model
        self.fov_h_rad = model.fov_h_rad
        self.lens = lens_for(model)

    @property
    def render_size(self) -> tuple[int, int]:
        """(height, width) of the MuJoCo render: the lens's wide one, else the image's."""
        if self.lens is not None:
            return (self.lens.render_height, self.lens.render_width)
        return (self.height, self.width)

    @property
    def render_samples(self) -> int:
        """The render's multisampling: the camera model's (its default without one)."""
        return (self.model.msaa_samples if self.model is not None
                else CameraModel.msaa_samples)

    @property
    def fovy_deg(self) -> float:
        """MuJoCo's vertical field of view (degrees, float) from the horizontal one (the
        lens's wide render where the camera model has one)."""
        if self.lens is not None:
            return self.lens.render_fovy_deg
        half_v = math.atan(math.tan(self.fov_h_rad / 2) * self.height / self.width)
        return math.degrees(2 * half_v)

    @property
    def focal_length_px(self) -> float:
        return (self.width / 2) / math.tan(self.fov_h_rad / 2)

    def mjcf(self, robot_name: str) -> str:
        """The ``<camera>`` element inside the robot's body (MuJoCo FLU frame)."""
        r = frames.quat_to_matrix(frames.euler_to_quat(*self.mount.direction_rad))
        image_right = frames.ned_to_mj(r[:, 1])  # sensor +y, FRD -> FLU
        image_up = frames.ned_to_mj(r[:, 0])  # sensor +x
        pos = frames.ned_to_mj(self.mount.position_m)
        axes = " ".join(f"{v:.12g}" for v in (*image_right, *image_up))
        return (
            f'<camera name="{camera_model_name(robot_name, self.name)}" '
            f'pos="{pos[0]:.9g} {pos[1]:.9g} {pos[2]:.9g}" xyaxes="{axes}" '
            f'fovy="{self.fovy_deg:.12g}"/>'
        )

    def conf_fields(self) -> list[tuple[str, object]]:
        return [
            ("Width", self.width),
            ("Height", self.height),
            ("FOV", self.fov_h_rad),
            ("Rate", self.rate_hz),
            ("FocalLength", self.focal_length_px),
            ("CameraId", self.camera_id),
        ]

    def geo_fields(self) -> list[tuple[str, object]]:
        return [
            ("Location", self.mount.position_m),
            ("Orientation", tuple(frames.wrap_2pi(a) for a in self.mount.direction_rad)),
        ]


SHADOW_MAP_PX = 1024  # shadow map size when the world file has shadows off
SHADOW_HALF_SIZE_M = 4.0  # ... covering this half-size around the world origin

_LENSES: dict[CameraModel, Lens] = {}


def lens_for(model: CameraModel) -> Lens | None:
    """The model's image path (cached: the maps are computed once per model), or None for a
    perfect pinhole with nothing to add."""
    trivial = not (model.distorted or model.noisy or model.jpeg_quality or model.exposure_s
                   or model.line_time_s or model.cx_px != (model.width - 1) / 2.0
                   or model.cy_px != (model.height - 1) / 2.0 or model.fx_px != model.fy_px)
    if trivial:
        return None
    if model not in _LENSES:
        if len(_LENSES) > 32:
            _LENSES.clear()
        _LENSES[model] = Lens(model)
    return _LENSES[model]


def camera_motion(mujoco: Any, model: Any, data: Any, cam_id: int) -> Motion:
    """The camera's motion at the state in ``data`` (after mj_kinematics/comPos/comVel), in
    OpenCV camera axes (MuJoCo's camera: x right, y up, looking along -z)."""
    vel = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_CAMERA, cam_id, vel, 1)
    xmat = data.cam_xmat[cam_id].reshape(3, 3)
    down = -xmat[2, :]  # world -z in the camera's axes
    return Motion(
        omega_rad_s=(float(vel[0]), float(-vel[1]), float(-vel[2])),
        velocity_m_s=(float(vel[3]), float(-vel[4]), float(-vel[5])),
        down=(float(down[0]), float(-down[1]), float(-down[2])),
        height_m=float(data.cam_xpos[cam_id][2]),
    )


def check_fov(fov_h_rad: float, where: str) -> None:
    if not (math.isfinite(fov_h_rad) and 0.01 < fov_h_rad < math.pi - 0.01):
        raise ConfigError(f"{where}: fov_h_rad must be in (0.01, pi - 0.01), got {fov_h_rad!r}")


def camera_model_name(robot: str, camera: str) -> str:
    return f"robot:{robot}:cam:{camera}"


@dataclass
class _Job:
    model: Any
    qpos: np.ndarray
    qvel: np.ndarray
    time_s: float
    shots: list[tuple[Any, CameraSpec]]  # (robot, camera)
    done: threading.Event | None


class CameraSystem:
    """Renders every robot camera into a FrameBuffer. Attach before robots are spawned."""

    def __init__(self, sim: Any, buffer: FrameBuffer, *, synchronous: bool,
                 profile: str | None = None) -> None:
        """``profile``: the camera model profile every camera uses (``skeye sim
        --camera-profile``), over the robot files' own; None keeps theirs."""
        if profile is not None and profile not in PROFILES:
            raise ConfigError(f"unknown camera profile {profile!r}; known: {list(PROFILES)}")
        self.profile = profile
        self.sim = sim
        self.buffer = buffer
        self.synchronous = synchronous
        self.skipped = 0
        self.error: str | None = None
        self._next_id = 1
        self._known: dict[str, int] = {}
        self._jobs: queue.Queue[_Job | None] = queue.Queue(maxsize=1)
        self._ready = threading.Event()
        self._stop = threading.Event()
        sim.xml_extras.append(self._xml)
        sim.rebuild_hooks.append(self._on_rebuild)
        sim.step_hooks.append(self._on_step)
        sim.event_sources.append(self._next_event_step)
        self._reported = False
        # Frames waiting out their capture latency: (delivery sim time, seq, robot, cam, frame)
        self._pending: list[tuple[float, int, Any, CameraSpec, Frame]] = []
        self._pending_lock = threading.Lock()
        self._seq = 0
        self._last_delivery: dict[str, float] = {}
        self._worker = Worker(self._render_loop, "skeye-render", on_error=self._render_died)
        self._worker.start()

    def _render_died(self, exc: BaseException) -> None:
        """The render thread itself failed: record why and release a waiting engine."""
        self.error = f"camera rendering stopped: {type(exc).__name__}: {exc}"
        while True:
            try:
                job = self._jobs.get_nowait()
            except queue.Empty:
                return
            if job is not None and job.done is not None:
                job.done.set()

    def close(self, timeout_s: float = 5.0) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        try:
            self._jobs.put(None, timeout=timeout_s)
        except queue.Full:
            pass
        self._worker.join(timeout_s)

    def __enter__(self) -> CameraSystem:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- engine side (engine thread) -----------------------------------------------------
    def _xml(self, robot: Any) -> str:
        if self.profile is not None:
            for cam in robot.cameras:
                if cam.model is not None and cam.model.profile != self.profile:
                    fov = dict(cam.mount.params).get("fov_h_rad", 1.309)
                    cam.set_model(build_camera_model(
                        dict(cam.mount.params), cam.width, cam.height, float(fov),
                        f"camera {cam.name!r}", self.profile))
        return "\n".join(cam.mjcf(robot.name) for cam in robot.cameras)

    def _on_rebuild(self, sim: Any) -> None:
        current = {}
        for robot in sim.robots.values():
            for cam in robot.cameras:
                key = f"{robot.name}/{cam.name}"
                if not cam.camera_id:
                    cam.camera_id = self._next_id
                    self._next_id += 1
                current[key] = cam.camera_id
                if self._known.get(key) != cam.camera_id:
                    # New, or a new robot under a gone one's name: its own slot and id.
                    if key in self._known:
                        self.buffer.remove_camera(key)
                    self._last_delivery.pop(key, None)
                    self.buffer.register_camera(key, cam.camera_id)
                    # The first frame comes at the robot's first step (from its spawn state),
                    # then on the camera's grid of sim times k / rate.
                    cam.due = math.floor(sim.time_s * cam.rate_hz + 1e-9)
        for key in set(self._known) - set(current):
            self.buffer.remove_camera(key)
            self._last_delivery.pop(key, None)
        self._known = current
        with self._pending_lock:  # frames of cameras that went wait for nobody
            self._pending = [p for p in self._pending if self._is_current(p[4])]
        for robot in sim.robots.values():
            for cam in robot.cameras:
                cam_id = _camera_index(sim.model, camera_model_name(robot.name, cam.name))
                sim.model.cam_fovy[cam_id] = cam.fovy_deg
        # Absolute near/far clip planes: MuJoCo scales them by the model's extent.
        cams = [c for r in sim.robots.values() for c in r.cameras]
        if cams:
            extent = float(sim.model.stat.extent)
            sim.model.vis.map.znear = min(c.near_m for c in cams) / extent
            sim.model.vis.map.zfar = max(c.far_m for c in cams) / extent
            # The lens's wide renders must fit the offscreen buffer (read at context creation).
            # Only the lens's margin grows it: a camera larger than the buffer still fails.
            glob = sim.model.vis.global_
            fits = [c for c in cams if c.width <= glob.offwidth and c.height <= glob.offheight]
            if fits:
                glob.offwidth = max(int(glob.offwidth), max(c.render_size[1] for c in fits))
                glob.offheight = max(int(glob.offheight), max(c.render_size[0] for c in fits))
            if any(c.model is not None and c.model.shadows for c in cams):
                # A camera model with shadows: the world's lights cast them (the vehicle
                # shadows the pad), with a shadow map if the world had none.
                sim.model.light_castshadow[:] = 1
                if int(sim.model.vis.quality.shadowsize) == 0:
                    # A 1024-pixel map over +-4 m around the directional light's position
                    # (above the world origin, where the pad is): sharp rotor shadows, and a
                    # cheaper pass in software GL than a map spanning the whole world.
                    sim.model.vis.quality.shadowsize = SHADOW_MAP_PX
                    sim.model.vis.map.shadowclip = SHADOW_HALF_SIZE_M / extent

    def _next_event_step(self, sim: Any) -> int:
        """The step index whose end reaches the next camera's due time or frame delivery."""
        best = sim.steps + 1_000_000
        with self._pending_lock:
            for entry in self._pending:
                best = min(best, math.ceil((entry[0] - 1e-9) / sim.dt) - 1)
        for robot in sim.robots.values():
            for cam in robot.cameras:
                end_step = math.ceil((cam.due / cam.rate_hz - 1e-9) / sim.dt)
                best = min(best, end_step - 1)
        return max(best, sim.steps)

    def _on_step(self, sim: Any) -> None:
        if self.error is not None:
            if not self._reported:  # realtime: the render thread failed since the last step
                self._reported = True
                self._report_error()
            return
        t = sim.time_s
        self._deliver_due(t)
        shots = []
        for robot in sim.robots.values():
            for cam in robot.cameras:
                if t + 1e-9 >= cam.due / cam.rate_hz:
                    cam.due += 1
                    while t + 1e-9 >= cam.due / cam.rate_hz:  # never fall behind the clock
                        cam.due += 1
                    shots.append((robot, cam))
        if not shots:
            return
        job = _Job(sim.model, sim.data.qpos.copy(), sim.data.qvel.copy(), t, shots,
                   threading.Event() if self.synchronous else None)
        if self.synchronous:
            self._jobs.put(job)
            assert job.done is not None
            if not job.done.wait(60.0):
                raise SkeyeError("camera rendering timed out (60 s)")
            if self.error is not None:
                self._reported = True
                self._report_error()
        else:
            try:
                self._jobs.put_nowait(job)
            except queue.Full:
                self.skipped += len(shots)

    def _deliver_due(self, t: float) -> None:
        """Publish the frames whose capture latency has passed by sim time ``t``."""
        with self._pending_lock:
            due = [p for p in self._pending if p[0] <= t + 1e-9]
            if not due:
                return
            self._pending = [p for p in self._pending if p[0] > t + 1e-9]
        for _, _, robot, cam, frame in sorted(due, key=lambda p: (p[0], p[1])):
            self._publish(robot, cam, frame, lockstep=True)

    def _is_current(self, frame: Frame) -> bool:
        """True while the camera that took ``frame`` still exists (not a gone robot's camera,
        nor one of a robot since spawned under the same name)."""
        return self._known.get(frame.camera) == frame.camera_id

    def _publish(self, robot: Any, cam: CameraSpec, frame: Frame, *, lockstep: bool) -> None:
        if not self._is_current(frame):
            return  # its robot went while the frame was rendered or waited out its latency
        self.buffer.publish(frame)
        shot = CameraFrame(frame.sim_time_s, cam.name, frame.number)
        if lockstep:  # in order, with the step's lines
            self.sim.emit(robot, [shot])
        else:
            robot.sink([shot])

    def _delivery_time(self, cam: CameraSpec, key: str, capture_s: float, number: int) -> float:
        """Capture time + latency +- jitter (seeded by the camera model's noise seed and the
        frame number), never before the camera's previous frame."""
        model = cam.model
        assert model is not None
        jitter = 0.0
        if model.latency_jitter_s > 0:
            rng = np.random.default_rng((model.noise_seed, 1, number))
            jitter = float(rng.uniform(-model.latency_jitter_s, model.latency_jitter_s))
        when = max(capture_s + model.latency_s + jitter, self._last_delivery.get(key, 0.0))
        self._last_delivery[key] = when
        return when

    def _report_error(self) -> None:
        log.error("telling the camera robots' clients: %s", self.error)
        # One line, no braces: the reason must never make the ERR line itself unformattable.
        reason = " ".join((self.error or "rendering failed").replace("{", "(")
                          .replace("}", ")").split())[:400]
        for robot in self.sim.robots.values():
            if robot.cameras:
                robot.sink([RobotStopped(robot.name, "CAMERA", reason)])

    # -- render thread -------------------------------------------------------------------
    def _render_loop(self) -> None:
        import mujoco

        model = None
        data = None
        renderers: dict[tuple[int, int, int], Any] = {}
        try:
            while not self._stop.is_set():
                job = self._jobs.get()
                if job is None:
                    break
                try:
                    if job.model is not model:
                        for r in renderers.values():
                            r.close()
                        renderers = {}
                        model = job.model
                        data = mujoco.MjData(model)
                    assert data is not None
                    data.qpos[:] = job.qpos
                    data.qvel[:] = job.qvel
                    mujoco.mj_kinematics(model, data)
                    mujoco.mj_comPos(model, data)
                    mujoco.mj_comVel(model, data)
                    mujoco.mj_camlight(model, data)
                    for robot, cam in job.shots:
                        spec = (*cam.render_size, cam.render_samples)
                        if spec not in renderers:
                            renderers[spec] = _make_renderer(mujoco, model, *spec)
                        renderer = renderers[spec]
                        name = camera_model_name(robot.name, cam.name)
                        shadows = cam.model is not None and cam.model.shadows
                        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = int(shadows)
                        renderer.update_scene(data, camera=name)
                        rgb = renderer.render()
                        cam.rendered += 1
                        if cam.lens is not None:
                            motion = camera_motion(mujoco, model, data,
                                                   _camera_index(model, name))
                            rgb = cam.lens.apply(rgb, motion, cam.rendered)
                        key = f"{robot.name}/{cam.name}"
                        frame = Frame(key, cam.camera_id, cam.rendered, job.time_s, rgb)
                        if cam.model is not None and cam.model.latency_s > 0:
                            when = self._delivery_time(cam, key, job.time_s, cam.rendered)
                            with self._pending_lock:
                                self._seq += 1
                                self._pending.append((when, self._seq, robot, cam, frame))
                        else:
                            self._publish(robot, cam, frame, lockstep=job.done is not None)
                except SkeyeError as exc:
                    self.error = str(exc)
                    log.error("%s", exc)
                except Exception as exc:  # a GL failure must reach the clients, not kill us
                    self.error = f"camera rendering failed: {type(exc).__name__}: {exc}"
                    log.exception("camera rendering failed")
                finally:
                    if job.done is not None:
                        job.done.set()
        finally:
            for r in renderers.values():
                r.close()


def _camera_index(model: Any, name: str) -> int:
    import mujoco

    idx = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name)
    if idx < 0:
        raise LocalProtocolError(f"no camera {name} in the model")
    return int(idx)


def _make_renderer(mujoco: Any, model: Any, height: int, width: int, samples: int) -> Any:
    """A renderer of this size with ``samples``-fold multisampling (MuJoCo reads the model's
    ``offsamples`` when it makes the GL context; the model's own value is put back)."""
    backend = os.environ.get("MUJOCO_GL", "?")
    quality = model.vis.quality
    before = int(quality.offsamples)
    quality.offsamples = samples
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:
        raise SkeyeError(
            f"cannot render camera images with MUJOCO_GL={backend}: {exc}. Install an OpenGL "
            "backend: Mesa's EGL (apt-get install libegl1 libgl1-mesa-dri) for MUJOCO_GL=egl, "
            "or OSMesa (apt-get install libosmesa6) for MUJOCO_GL=osmesa, or run with a display "
            "(MUJOCO_GL=glfw)"
        ) from exc
    finally:
        quality.offsamples = before
    flags = renderer.scene.flags
    flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
    flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
    flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
    return renderer


def set_camera_fov(sim: Any, robot_name: str, camera: str, fov_h_rad: float) -> None:
    """``SET {Type Camera} {Name n} {Opcode FOV} {Params rad}``: a float, never rounded."""
    robot = sim.robots.get(robot_name)
    if robot is None:
        raise LocalProtocolError(f"robot {robot_name} no longer exists")
    for cam in robot.cameras:
        if cam.name.lower() == camera.lower():
            check_fov(fov_h_rad, f"camera {camera!r}")
            cam.fov_h_rad = fov_h_rad
            if cam.model is not None:  # a zoom: the same lens model, a new focal length
                cam.set_model(replace(cam.model, **pinhole(cam.width, cam.height, fov_h_rad)))
            index = _camera_index(sim.model, camera_model_name(robot_name, cam.name))
            sim.model.cam_fovy[index] = cam.fovy_deg
            return
    raise LocalProtocolError(f"robot {robot_name} has no camera named {camera!r}")
