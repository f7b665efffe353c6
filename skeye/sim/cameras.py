"""Robot cameras: MuJoCo offscreen rendering, each frame from the state of its own sim time.

How this works: a camera is a sensor in the robot file (``type = "Camera"``) with a mount pose,
a resolution, a horizontal field of view in radians (a float, never rounded: the vertical one
follows from the aspect ratio) and a frame rate. It becomes a MuJoCo ``<camera>`` in the robot's
body. An identity mount looks straight down like every downward sensor (boresight = sensor +z),
with the image's top towards the body's front (sensor +x) and its right towards sensor +y.

:class:`CameraSystem` hooks into the engine. When a camera is due (frame n at the first step
with ``t >= n / rate``), the engine thread snapshots ``qpos`` and ``qvel`` (a
:class:`~skeye.sim.render.WorldState`, shared by the cameras due at that step), numbers the
frame and publishes it to the image server's :class:`FrameBuffer` with a
:class:`~skeye.sim.readings.CameraFrame` for the robot's sink (the control server sends it as
``SEN {Type Camera} {Name n} {Frame k}``), at once or after the camera model's capture latency.
The pixels are made by one render thread that owns the OpenGL contexts (EGL or OSMesa contexts
belong to the thread that made them; :mod:`skeye.sim.render`), and only for someone:

* a frame of a camera some image client watches (:meth:`FrameBuffer.wanted`: a client is
  connected that selected it, or has not selected any and it is the first camera, and has not
  said ``SKEYE PRERENDER off``) is queued for rendering when it is taken, so it is ready by its
  delivery;
* any other frame is rendered when its pixels are first asked for (``Frame.rgb``: an image
  client's request, the pilot's vision), from its snapshot: the same pixels, later. A frame
  nobody asks for costs a copy of ``qpos`` and ``qvel``.

In lockstep every watched frame is rendered in order (the engine waits when more than
``LOCKSTEP_BACKLOG`` are queued), so a run is reproducible; in real time the engine never
waits, and a watched frame whose render has not begun when a newer frame of its camera is
published is left unrendered (nobody can ask the buffer for it any more; counted in
``skipped``), unless someone waits for its pixels.
"""

from __future__ import annotations

import logging
import math
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
from skeye.sim.exposure import AutoExposure
from skeye.sim.gl import GL_BACKEND  # noqa: F401  (before mujoco: picks MUJOCO_GL)
from skeye.sim.image_server import Frame, FrameBuffer
from skeye.sim.lens import Lens
from skeye.sim.readings import CameraFrame, RobotStopped
from skeye.sim.render import RENDER_TIMEOUT_S, ShotRenderer, WorldState, camera_index
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
    auto_exposure: AutoExposure | None = None  # its exposure state (with a lens)
    captured: int = 0  # frames taken (their numbers), rendered or not
    # Mixed into the seeds of its pixel noise and latency jitter with the model's noise_seed:
    # the engine gives a spawned robot's cameras (its seed, the spawn's number), skeye.gym
    # (its flight's seed, the vehicle's spawn), so that no two share noise.
    noise_stream: tuple[int, ...] = ()
    rendered: int = 0  # frames rendered
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
        self.auto_exposure = AutoExposure(model) if self.lens is not None else None

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


_LENSES: dict[CameraModel, Lens] = {}


def lens_for(model: CameraModel) -> Lens | None:
    """The model's image path (cached: the maps are computed once per model), or None for a
    perfect pinhole with nothing to add."""
    trivial = not (model.distorted or model.noisy or model.jpeg_quality or model.exposure_s
                   or model.line_time_s or model.cx_px != (model.width - 1) / 2.0
                   or model.cy_px != (model.height - 1) / 2.0 or model.fx_px != model.fy_px
                   or model.vignetting_exponent or model.auto_exposure)
    if trivial:
        return None
    if model not in _LENSES:
        if len(_LENSES) > 32:
            _LENSES.clear()
        _LENSES[model] = Lens(model)
    return _LENSES[model]


def check_fov(fov_h_rad: float, where: str) -> None:
    if not (math.isfinite(fov_h_rad) and 0.01 < fov_h_rad < math.pi - 0.01):
        raise ConfigError(f"{where}: fov_h_rad must be in (0.01, pi - 0.01), got {fov_h_rad!r}")


def camera_model_name(robot: str, camera: str) -> str:
    return f"robot:{robot}:cam:{camera}"


LOCKSTEP_BACKLOG = 2  # in lockstep the engine waits while more watched frames await their render


class _Shot:
    """One frame of one camera: the snapshot it is rendered from. It is rendered at once when
    someone watches the camera (FrameBuffer.wanted), else when its pixels are first asked for
    (the frame's PixelSource)."""

    def __init__(self, system: CameraSystem, robot: Any, cam: CameraSpec, key: str, number: int,
                 state: WorldState) -> None:
        self.system = system
        self.robot = robot
        self.cam = cam
        self.key = key
        self.number = number
        self.state = state
        self.done = threading.Event()
        self.result: tuple[np.ndarray, bytes | None] | None = None
        self.error: str | None = None
        self.queued = False
        self.eager = False
        self.waiters = 0

    def pixels(self) -> tuple[np.ndarray, bytes | None]:
        if not self.done.is_set():
            self.system._request(self, eager=False)
            try:
                if not self.done.wait(RENDER_TIMEOUT_S):
                    raise SkeyeError(f"camera {self.key} frame {self.number}: not rendered "
                                     f"within {RENDER_TIMEOUT_S:g} s")
            finally:
                with self.system._lock:
                    self.waiters -= 1
        if self.error is not None:
            raise SkeyeError(self.error)
        assert self.result is not None
        return self.result


class CameraSystem:
    """Renders every robot camera into a FrameBuffer. Attach before robots are spawned."""

    def __init__(self, sim: Any, buffer: FrameBuffer, *, synchronous: bool,
                 profile: str | None = None) -> None:
        """``profile``: the camera model profile every camera uses (``skeye sim
        --camera-profile``), over the robot files' own; None keeps theirs. ``synchronous``
        (lockstep): every watched frame is rendered, the engine waiting when they pile up;
        otherwise (real time) a watched frame whose render has not begun when a newer one is
        published is left unrendered unless someone waits for it (counted in ``skipped``)."""
        if profile is not None and profile not in PROFILES:
            raise ConfigError(f"unknown camera profile {profile!r}; known: {list(PROFILES)}")
        self.profile = profile
        self.sim = sim
        self.buffer = buffer
        self.synchronous = synchronous
        self.skipped = 0  # watched frames left unrendered (real time: a newer one was out)
        self.rendered = 0  # frames rendered, all cameras
        self.error: str | None = None
        self.renderer_description: str | None = None  # the OpenGL renderer, once probed
        self._described = threading.Event()
        self._next_id = 1
        for robot in sim.robots.values():  # robots there before the cameras: not being spawned
            for cam in robot.cameras:
                if not cam.camera_id:
                    cam.camera_id = self._next_id
                    self._next_id += 1
        self._known: dict[str, int] = {}
        self._queue: queue.Queue[_Shot | None] = queue.Queue()
        self._lock = threading.Condition()
        self._backlog = 0  # eager shots queued and not rendered
        self._newest_published: dict[str, int] = {}  # by camera: the newest frame out
        self._stop = threading.Event()
        self._reported = False
        # Frames waiting out their capture latency: (delivery sim time, seq, robot, cam, frame)
        self._pending: list[tuple[float, int, Any, CameraSpec, Frame]] = []
        self._pending_lock = threading.Lock()
        self._seq = 0
        self._last_delivery: dict[str, float] = {}
        # Last: a real-time engine already running calls the hooks from the next step on
        sim.xml_extras.append(self._xml)
        sim.rebuild_hooks.append(self._on_rebuild)
        sim.step_hooks.append(self._on_step)
        sim.event_sources.append(self._next_event_step)
        self._worker = Worker(self._render_loop, "skeye-render", on_error=self._render_died)
        self._worker.start()

    @property
    def pending_renders(self) -> int:
        """Frames rendered ahead for a watching client (PRERENDER on) that are queued and not
        yet rendered."""
        with self._lock:
            return self._backlog

    def describe_renderer(self, timeout_s: float = 30.0) -> str:
        """The OpenGL renderer the cameras render on (probed when the render thread starts)."""
        self._described.wait(timeout_s)
        return self.renderer_description or "unknown (the render thread did not say)"

    def _render_died(self, exc: BaseException) -> None:
        """The render thread itself failed: record why and release every waiting shot."""
        self.error = f"camera rendering stopped: {type(exc).__name__}: {exc}"
        self._described.set()
        self._fail_queued(self.error)

    def _fail_queued(self, reason: str) -> None:
        while True:
            try:
                shot = self._queue.get_nowait()
            except queue.Empty:
                return
            if shot is not None and not shot.done.is_set():
                shot.error = reason
                shot.done.set()
                self._finished(shot)

    def close(self, timeout_s: float = 5.0) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        self._queue.put(None)
        self._worker.join(timeout_s)
        self._fail_queued("the simulator's cameras were closed")

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
                        f"{robot.config.source} camera {cam.name!r}", self.profile))
        return "\n".join(cam.mjcf(robot.name) for cam in robot.cameras)

    def _on_rebuild(self, sim: Any) -> None:
        """Register the robots' cameras with the image server after the world was rebuilt.

        Raises:
            ConfigError: a camera of a robot being spawned cannot be rendered (larger than the
                offscreen buffer): the engine takes the robot out again, and its INIT is refused
                with this reason; the other robots and their cameras go on.
        """
        spawned = {id(c) for r in sim.robots.values() for c in r.cameras if not c.camera_id}
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
                    self._newest_published.pop(key, None)
                    self.buffer.register_camera(key, cam.camera_id)
                    # The first frame comes at the robot's first step (from its spawn state),
                    # then on the camera's grid of sim times k / rate.
                    cam.due = math.floor(sim.time_s * cam.rate_hz + 1e-9)
        for key in set(self._known) - set(current):
            self.buffer.remove_camera(key)
            self._last_delivery.pop(key, None)
            self._newest_published.pop(key, None)
        self._known = current
        with self._pending_lock:  # frames of cameras that went wait for nobody
            self._pending = [p for p in self._pending if self._is_current(p[4])]
        for robot in sim.robots.values():
            for cam in robot.cameras:
                cam_id = camera_index(sim.model, camera_model_name(robot.name, cam.name))
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
            # A camera that cannot be rendered is said at once, not when a frame is first asked
            # for (frames are rendered only for someone).
            for robot in sim.robots.values():
                for cam in robot.cameras:
                    if cam.width <= glob.offwidth and cam.height <= glob.offheight:
                        continue
                    why = (f"camera {robot.name}/{cam.name}: a {cam.width}x{cam.height} image "
                           f"does not fit the offscreen buffer (framebuffer width "
                           f"{glob.offwidth}, height {glob.offheight}); use a smaller camera")
                    if id(cam) in spawned:
                        raise ConfigError(why)  # the robot being spawned: refused alone
                    if self.error is None:  # there before the cameras were (in-process use)
                        self.error = why
                        log.error("%s", self.error)

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
            if not self._reported:  # the render thread failed since the last step
                self._reported = True
                self._report_error()
            return
        t = sim.time_s
        self._deliver_due(t)
        state: WorldState | None = None
        for robot in sim.robots.values():
            for cam in robot.cameras:
                if t + 1e-9 < cam.due / cam.rate_hz:
                    continue
                cam.due += 1
                while t + 1e-9 >= cam.due / cam.rate_hz:  # never fall behind the clock
                    cam.due += 1
                if state is None:  # one snapshot for every camera due at this step
                    state = WorldState(sim.model, sim.data.qpos.copy(), sim.data.qvel.copy(), t)
                self._capture(robot, cam, state)
        if self.synchronous and state is not None:
            self._wait_backlog()

    def _capture(self, robot: Any, cam: CameraSpec, state: WorldState) -> None:
        """Number a frame of ``cam`` at ``state``, start its render if it is watched, and
        publish it now or after its capture latency."""
        key = f"{robot.name}/{cam.name}"
        cam.captured += 1
        shot = _Shot(self, robot, cam, key, cam.captured, state)
        model = cam.model
        frame = Frame(key, cam.camera_id, cam.captured, state.time_s, source=shot,
                      width=cam.width, height=cam.height,
                      jpeg_quality=model.jpeg_quality if model is not None else 0)
        if self.buffer.wanted(key):
            self._request(shot, eager=True)
        if model is not None and model.latency_s > 0:
            when = self._delivery_time(cam, key, state.time_s, cam.captured)
            with self._pending_lock:
                self._seq += 1
                self._pending.append((when, self._seq, robot, cam, frame))
        else:
            self._publish(robot, cam, frame)

    def _wait_backlog(self) -> None:
        """Lockstep: hold the engine while more watched frames wait for their render than
        LOCKSTEP_BACKLOG (every one is rendered, in order: a run stays reproducible)."""
        with self._lock:
            if not self._lock.wait_for(
                lambda: self._backlog <= LOCKSTEP_BACKLOG or self.error is not None
                or self._stop.is_set(), RENDER_TIMEOUT_S):
                raise SkeyeError(f"camera rendering timed out ({RENDER_TIMEOUT_S:g} s)")
        if self.error is not None and not self._reported:
            self._reported = True
            self._report_error()

    def _deliver_due(self, t: float) -> None:
        """Publish the frames whose capture latency has passed by sim time ``t``."""
        with self._pending_lock:
            due = [p for p in self._pending if p[0] <= t + 1e-9]
            if not due:
                return
            self._pending = [p for p in self._pending if p[0] > t + 1e-9]
        for _, _, robot, cam, frame in sorted(due, key=lambda p: (p[0], p[1])):
            self._publish(robot, cam, frame)

    def _is_current(self, frame: Frame) -> bool:
        """True while the camera that took ``frame`` still exists (not a gone robot's camera,
        nor one of a robot since spawned under the same name)."""
        return self._known.get(frame.camera) == frame.camera_id

    def _publish(self, robot: Any, cam: CameraSpec, frame: Frame) -> None:
        if not self._is_current(frame):
            return  # its robot went while the frame waited out its latency
        self.buffer.publish(frame)
        with self._lock:
            self._newest_published[frame.camera] = frame.number
        self.sim.emit(robot, [CameraFrame(frame.sim_time_s, cam.name, frame.number)])

    def _delivery_time(self, cam: CameraSpec, key: str, capture_s: float, number: int) -> float:
        """Capture time + latency +- jitter (seeded by the camera model's noise seed and the
        frame number), never before the camera's previous frame."""
        model = cam.model
        assert model is not None
        jitter = 0.0
        if model.latency_jitter_s > 0:
            rng = np.random.default_rng((model.noise_seed, 1, *cam.noise_stream, number))
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

    # -- any thread ------------------------------------------------------------------------
    def _request(self, shot: _Shot, *, eager: bool) -> None:
        """Queue ``shot`` for the render thread (once); a waiter counts itself in."""
        with self._lock:
            if not eager:
                shot.waiters += 1
            if self._stop.is_set() or self.error is not None:
                shot.error = self.error or "the simulator's cameras were closed"
                shot.done.set()
                return
            if eager:
                shot.eager = True
            if shot.queued or shot.done.is_set():
                return
            shot.queued = True
            if eager:
                self._backlog += 1
        self._queue.put(shot)

    def _finished(self, shot: _Shot) -> None:
        with self._lock:
            if shot.eager:
                shot.eager = False
                self._backlog -= 1
            self._lock.notify_all()

    # -- render thread -------------------------------------------------------------------
    def _render_loop(self) -> None:
        renderer = ShotRenderer()
        try:
            try:
                self.renderer_description = renderer.describe()
                log.info("camera renderer: %s", self.renderer_description)
            except Exception as exc:  # reported again, with advice, at the first frame
                log.warning("camera renderer: cannot make an OpenGL context: %s", exc)
            finally:
                self._described.set()
            while not self._stop.is_set():
                shot = self._queue.get()
                if shot is None:
                    break
                with self._lock:
                    shot.queued = False
                    skip = (not self.synchronous and shot.waiters == 0
                            and self._newest_published.get(shot.key, 0) > shot.number)
                if shot.done.is_set():
                    continue
                if skip:  # real time: a newer frame is out, nobody will ask for this one
                    self.skipped += 1
                    self._finished(shot)
                    continue
                try:
                    name = camera_model_name(shot.robot.name, shot.cam.name)
                    rgb, jpeg, _ = renderer.render(shot.state, name, shot.cam, shot.number)
                    shot.result = (rgb, jpeg)
                    shot.cam.rendered += 1
                    self.rendered += 1
                except SkeyeError as exc:
                    shot.error = self.error = str(exc)
                    log.error("%s", exc)
                except Exception as exc:  # a GL failure must reach the clients, not kill us
                    shot.error = self.error = (f"camera rendering failed: {type(exc).__name__}: "
                                               f"{exc}")
                    log.exception("camera rendering failed")
                finally:
                    shot.done.set()
                    self._finished(shot)
        finally:
            renderer.close()


def set_camera_fov(sim: Any, robot_name: str, camera: str, fov_h_rad: float) -> None:
    """``SET {Type Camera} {Name n} {Opcode FOV} {Params rad}``: a float, never rounded."""
    robot = sim.robots.get(robot_name)
    if robot is None:
        raise LocalProtocolError(f"robot {robot_name} no longer exists")
    for cam in robot.cameras:
        if cam.name.lower() == camera.lower():
            check_fov(fov_h_rad, f"camera {camera!r}")
            # The model holds the robot's cameras only while images are served (the camera
            # system adds them); without, the camera keeps the field of view for when they are
            # (the camera system sets the model's from it at every rebuild).
            import mujoco

            index = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_CAMERA,
                                      camera_model_name(robot_name, cam.name))
            cam.fov_h_rad = fov_h_rad
            if cam.model is not None:  # a zoom: the same lens model, a new focal length
                cam.set_model(replace(cam.model, **pinhole(cam.width, cam.height, fov_h_rad)))
            if index >= 0:
                sim.model.cam_fovy[index] = cam.fovy_deg
            return
    raise LocalProtocolError(f"robot {robot_name} has no camera named {camera!r}")
