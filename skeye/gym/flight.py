"""The in-process world behind the environments: one simulation, its vehicles, their pilots.

How this works: a :class:`Flight` is one :class:`skeye.sim.engine.Simulation` (the world file,
the robot file, the board estimator, the wind: exactly what ``skeye sim`` runs), stepped in
lockstep one control period at a time, with a :class:`~skeye.sim.cameras.CameraSystem` in
lockstep (``skeye sim --image-port ... --camera-profile``) when the task needs the camera. Each
:class:`Vehicle` is one robot in it, seen from the pilot's side (:mod:`skeye.gym.board`): its
snapshot, its airframe, and, with the camera, the pilot's own vision
(:class:`~skeye.pilot.policy.DetectOnlyVision`, i.e. :class:`~skeye.pilot.vision.PadVision`
detecting in lockstep with the configured latency) on an :class:`~skeye.pilot.boards.OnboardBoards`
whose pad controller keeps the newest observation. A single environment flies one vehicle per
flight and makes a new flight per episode (so ``reset(seed=...)`` repeats an episode bit for
bit); the batched vector environment flies N vehicles in one flight and respawns each one
alone when its episode ends.

:class:`FlightSettings` holds what ``gymnasium.make(..., **kwargs)`` may configure; each value is
checked once, and a bad one is a :class:`~skeye.errors.ConfigError` naming it.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from skeye.errors import ConfigError, SkeyeError
from skeye.gym.board import BoardView, InProcessAirframe, InProcessCamera, VisionRobot, wrap_pi
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.pad_track import Pose
from skeye.pilot.policy import DetectOnlyVision, ObservedPad
from skeye.pilot.video_server import CameraFrame
from skeye.pilot.vision import MAX_VISION_LATENCY_S
from skeye.robots.camera_model import PROFILES
from skeye.robots.config import CAMERA_TYPE, RobotConfig, load_robot_config, mount_camera_model
from skeye.robots.params import ESTIMATOR_KINDS
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import TIMESTEP_RANGE_S, Simulation
from skeye.sim.image_server import FrameBuffer
from skeye.sim.sensors import SENSOR_CLASSES, Mount, build_sensor
from skeye.sim.state import BodyState
from skeye.sim.world import WorldDescription, load_world
from skeye.sim.world_model import PadPlacement
from skeye.values import is_number, text
from skeye.vision.calibration import CameraCalibration, load_calibration
from skeye.wire.wind import make_settings, parse_params

NOISE_SUFFIXES = ("sigma", "noise", "walk")
"""``sensor_noise`` scales every sensor parameter whose name ends so (NoiseSigma, BiasWalk...),
and the rotor-driven vibration's amplitudes (VIBRATION_KEYS)."""
VIBRATION_KEYS = ("vibrationrotor", "vibrationbladepass", "vibrationbroadband")
POSE_TYPES = ("INS", "GroundTruth")
"""The readings an observation's pose comes from (:meth:`BoardView.snapshot`: INS, else
GroundTruth); a vehicle is observed from its first one on."""


@dataclass(frozen=True)
class FlightSettings:
    """What an environment may configure (docs/gym.md, "Options")."""

    robot: str = "hummingbird"  # a robot class: built-in, or a <name>.toml in robot_dir
    robot_dir: tuple[Path, ...] = ()  # folders of robot files (skeye sim --robot-dir)
    world: str = "pad"  # a built-in world or a world file (skeye sim --world)
    estimator: str | None = "onboard"  # the board's estimator (None: the robot file's)
    wind: str = "none"  # a skeye sim --wind mode
    wind_params: Mapping[str, float] = field(default_factory=dict)  # its --wind-params
    sensor_noise: float = 1.0  # a factor on every sensor's noise, bias and walk parameters
    control_rate_hz: float = 20.0  # actions (and observations) per sim second
    camera: str | None = None  # a camera profile (webcam, ideal), None: no camera rendered
    camera_name: str = "Down"
    vision_latency_s: float = 0.0  # the pilot's --vision-latency-ms, in seconds
    calibration: str | None = None  # a skeye calibrate file ("model": the camera model's own)
    timestep_s: float = 0.001  # the physics step (skeye sim --timestep)

    def __post_init__(self) -> None:
        for name in ("robot", "world", "wind", "camera_name"):
            text(name, getattr(self, name))
        for name in ("estimator", "camera", "calibration"):
            value = getattr(self, name)
            if value is not None:
                text(name, value)
        if not all(isinstance(d, Path) for d in self.robot_dir):
            raise ConfigError(f"robot_dir must be folders (paths), got {self.robot_dir!r}")
        for folder in self.robot_dir:  # as skeye sim --robot-dir: a typo stops it at once
            if not folder.is_dir():
                raise ConfigError(f"robot_dir {str(folder)!r}: "
                                  f"{'not a folder' if folder.exists() else 'no such folder'}")
        if self.calibration == "":
            raise ConfigError("calibration must name a calibration file (skeye calibrate's "
                              "camera.toml), or be \"model\" or None, got ''")
        if self.estimator is not None and self.estimator not in ESTIMATOR_KINDS:
            raise ConfigError(f"estimator must be one of {list(ESTIMATOR_KINDS)}, "
                              f"got {self.estimator!r}")
        if not isinstance(self.wind_params, Mapping) or not all(
                isinstance(k, str) and is_number(v) for k, v in self.wind_params.items()):
            raise ConfigError(f"wind_params must map parameter names to numbers (or be "
                              f"\"k=v,k=v\"), got {self.wind_params!r}")
        for name in ("sensor_noise", "control_rate_hz", "vision_latency_s", "timestep_s"):
            value = getattr(self, name)
            if not is_number(value):
                raise ConfigError(f"{name} must be a number, got {value!r}")
        # The ranges below are finite, so each refuses NaN and the infinities as well.
        low, high = TIMESTEP_RANGE_S
        if not low <= self.timestep_s <= high:
            raise ConfigError(f"timestep_s must be in [{low:g}, {high:g}] s, "
                              f"got {self.timestep_s!r}")
        if not 0.0 <= self.sensor_noise <= 100.0:
            raise ConfigError(f"sensor_noise must be a factor 0..100, got {self.sensor_noise!r}")
        if not 0.5 <= self.control_rate_hz <= 1000.0:
            raise ConfigError(f"control_rate_hz must be 0.5..1000, got {self.control_rate_hz!r}")
        if not 0.0 <= self.vision_latency_s < MAX_VISION_LATENCY_S:
            raise ConfigError(f"vision_latency_s must be in [0, {MAX_VISION_LATENCY_S:g}) s "
                              f"(the pilot refuses later detections), got "
                              f"{self.vision_latency_s!r}")
        if self.camera is not None and self.camera not in PROFILES:
            raise ConfigError(f"camera must be one of {list(PROFILES)}, got {self.camera!r}")
        make_settings(self.wind, dict(self.wind_params))  # names a bad mode or parameter
        period = 1.0 / (self.control_rate_hz * self.timestep_s)
        if abs(period - round(period)) > 1e-6:
            raise ConfigError(f"control_rate_hz {self.control_rate_hz:g} is not a whole number "
                              f"of physics steps of {self.timestep_s:g} s")

    @classmethod
    def from_kwargs(cls, given: Mapping[str, Any], *, where: str,
                    also: Iterable[str] = ()) -> FlightSettings:
        """Settings from ``gymnasium.make`` keywords (wind_params also as ``"k=v,k=v"``);
        ``also``: the environment's own keywords (``where``), named with these when another
        one is refused."""
        unknown = sorted(set(given) - set(cls.__dataclass_fields__), key=str)
        if unknown:
            known = sorted({*cls.__dataclass_fields__, *also})
            raise ConfigError(f"unknown option(s) {unknown} for {where}; known: "
                              f"{', '.join(known)}")
        kwargs = dict(given)
        if isinstance(kwargs.get("wind_params"), str):
            kwargs["wind_params"] = parse_params(kwargs["wind_params"])
        if "robot_dir" in kwargs:
            kwargs["robot_dir"] = folders(kwargs["robot_dir"])
        if isinstance(kwargs.get("calibration"), PurePath):
            kwargs["calibration"] = str(kwargs["calibration"])
        return cls(**kwargs)

    @property
    def period_steps(self) -> int:
        return round(1.0 / (self.control_rate_hz * self.timestep_s))


def folders(value: Any) -> tuple[Path, ...]:
    """``robot_dir``: one folder or several (strings or paths), none for None."""
    if value is None:
        return ()
    items = [value] if isinstance(value, str | PurePath) else value
    if not isinstance(items, list | tuple) or not all(isinstance(d, str | PurePath)
                                                       for d in items):
        raise ConfigError(f"robot_dir must be a folder or a list of folders, got {value!r}")
    return tuple(Path(d) for d in items)


def scale_noise(config: RobotConfig, factor: float) -> RobotConfig:
    """The robot with every mounted sensor's noise, bias and walk parameters (names ending in
    Sigma, Noise, Walk) and vibration amplitudes times ``factor``; 1 leaves it as it is."""
    if factor == 1.0:
        return config
    mounts = []
    for mount in config.sensors:
        cls = SENSOR_CLASSES.get(mount.type_name.lower())
        if cls is None:
            mounts.append(mount)
            continue
        given = {k.replace("_", "").lower(): (k, v) for k, v in mount.params}
        params = dict(mount.params)
        for param in cls.all_params():
            norm = param.key.lower()
            if not (norm.endswith(NOISE_SUFFIXES) or norm in VIBRATION_KEYS):
                continue
            key, value = given.get(norm, (param.key, param.default))
            params[key] = float(value) * factor
        mounts.append(replace(mount, params=tuple(params.items())))
    return replace(config, sensors=tuple(mounts))


class Vehicle:
    """One robot of a flight as the pilot sees it (see the module docstring)."""

    def __init__(self, flight: Flight, name: str, location_ned_m: tuple[float, float, float],
                 yaw_rad: float) -> None:
        self.flight = flight
        self.name = name
        sim = flight.sim
        self.view = BoardView(flight.config)
        self.robot = sim.spawn(flight.config.class_name, config=flight.config, name=name,
                               sink=self.view.sink, location_ned_m=location_ned_m,
                               rotation_rpy_rad=(0.0, 0.0, yaw_rad))
        # The robot's status as it stands now (the STA a client finds at spawn): flying.
        self.view.sink([self.robot.status(sim.time_s)])
        # Its camera's pixel noise and latency jitter its own: drawn from the flight's seed and
        # this spawn, not only the camera model's noise_seed and the frame number (every
        # vehicle of a world, and every episode whatever its seed, drew the same noise).
        flight.spawns += 1
        for cam in self.robot.cameras:
            cam.noise_stream = (flight.seed, flight.spawns)
        self.airframe = InProcessAirframe(sim, name, self.view)
        self.spawn_pose = Pose(sim.time_s, *location_ned_m, 0.0, 0.0, wrap_pi(yaw_rad))
        # Home: where the vehicle would stand on the ground below its spawn point, as the
        # pilot's home is the estimate at take-off. The ground is looked for at any depth, as
        # the simulator's spawn looks for it (a start may be up to 1e5 m high).
        below = sim.ray_distance(name, location_ned_m, (0.0, 0.0, 1.0), math.inf)
        ground_down_m = location_ned_m[2] + (below if below is not None else 0.0)
        self.home_ned_m = (location_ned_m[0], location_ned_m[1],
                           ground_down_m - flight.config.airframe.gear_height_m)
        self.vision: DetectOnlyVision | None = None
        self.pad: ObservedPad | None = None
        self.boards: OnboardBoards | None = None
        self._frame: CameraFrame | None = None

    def start_vision(self) -> None:
        """The pilot's vision on this vehicle (after its first readings: the boards start
        from a snapshot)."""
        flight = self.flight
        if flight.cameras is None or self.vision is not None:
            return
        self.pad = ObservedPad()
        self.boards = OnboardBoards(self.airframe, pad=self.pad)
        key = f"{self.name}/{flight.settings.camera_name}"
        robot = VisionRobot(InProcessCamera(flight.cameras.buffer, key), self.view)
        self.vision = DetectOnlyVision(
            self.boards, robot, flight.lock, fov_h_rad=flight.fov_h_rad, lockstep=True,
            calibration=flight.calibration, latency_s=flight.settings.vision_latency_s,
        )
        # The pilot's pose history reaches back to its start; this vision starts a control
        # period after the spawn, so the estimate's poses of that period go in first (else the
        # first frames, captured before, would have no pose to be placed with): the board's
        # estimate at power-up is the spawn pose, then the INS readings.
        self.vision.history.add(self.spawn_pose)
        for ins in self.view.ins_readings:
            n, e, d = ins.location_ned_m
            roll, pitch, yaw = (wrap_pi(a) for a in ins.orientation_rad)
            self.vision.history.add(Pose(ins.time_s, n, e, d, roll, pitch, yaw))
        self.vision.attach_video(self._on_frame)
        self.vision.start()

    def _on_frame(self, frame: CameraFrame) -> None:
        self._frame = frame  # what the vision looked at, as the pilot's video port gets it

    def frame_bgr(self) -> np.ndarray | None:
        """The newest camera frame the vision looked at (BGR), None before the first."""
        return None if self._frame is None else self._frame.bgr

    def close(self) -> None:
        if self.vision is not None:
            self.vision.close()
            self.vision = None

    def truth(self) -> BodyState:
        """Ground truth (for rewards and termination only: never in an observation)."""
        return self.flight.sim.body_state(self.name)

    @property
    def alive(self) -> bool:
        return self.name in self.flight.sim.robots

    @property
    def reporting(self) -> bool:
        """Whether its first pose reading has come (its snapshot, its vision, can start)."""
        return any(t in self.view.latest for t in POSE_TYPES)


@dataclass(frozen=True)
class Setup:
    """The loaded, checked parts of a flight, made once per environment: the robot (its noise
    scaled), the world (its pads placed), and the camera's field of view and calibration."""

    settings: FlightSettings
    config: RobotConfig
    world: WorldDescription
    fov_h_rad: float = 0.0
    calibration: CameraCalibration | None = None
    camera_size: tuple[int, int] = (0, 0)  # (width, height) of the camera's frames


def prepare(settings: FlightSettings,
            pads_ned_m: tuple[tuple[float, float], ...] | None = None) -> Setup:
    """Load and check everything a flight needs (ConfigError names what is wrong).
    ``pads_ned_m``: the world's first pad copied to each (north, east) point."""
    world = load_world(settings.world)
    if pads_ned_m is not None:
        world = with_pads(world, pads_ned_m)
    config = scale_noise(load_robot_config(settings.robot, settings.robot_dir, allow_paths=True),
                         settings.sensor_noise)
    if settings.camera is None:
        return Setup(settings, config, world)
    mount = next((m for m in config.sensors if m.type_name.lower() == CAMERA_TYPE
                  and m.name.lower() == settings.camera_name.lower()), None)
    if mount is None:
        raise ConfigError(f"robot {config.class_name} has no camera named "
                          f"{settings.camera_name!r}")
    model = mount_camera_model(config, mount, settings.camera)
    calibration = None
    if settings.calibration is not None and settings.calibration != "model":
        calibration = load_calibration(Path(settings.calibration))
        if (calibration.width_px, calibration.height_px) != (model.width, model.height):
            raise ConfigError(f"calibration is for {calibration.width_px}x"
                              f"{calibration.height_px} images, the camera gives "
                              f"{model.width}x{model.height}")
    elif settings.camera != "ideal" or settings.calibration == "model":
        # The camera model's own intrinsics: what a perfect `skeye calibrate` finds.
        calibration = CameraCalibration(model.width, model.height, model.fx_px, model.fy_px,
                                        model.cx_px, model.cy_px, model.dist_coeffs)
    return Setup(settings, config, world, model.fov_h_rad, calibration,
                 (model.width, model.height))


class Flight:
    """One in-process simulation with its vehicles (see the module docstring)."""

    def __init__(self, setup: Setup, seed: int, *, vision: bool = True) -> None:
        """``vision``: each vehicle runs the pilot's pad detector on its camera (a task that
        observes it: PadLanding); without, a camera is only rendered, each frame when its
        pixels are asked for (``render()``)."""
        import threading

        settings = setup.settings
        self.setup = setup
        self.settings = settings
        self.seed = seed
        self.vision = vision
        self.spawns = 0  # vehicles spawned so far, each its own camera noise (Vehicle)
        self.world = setup.world
        self.config = setup.config
        self.fov_h_rad = setup.fov_h_rad
        self.calibration = setup.calibration
        self.sim = Simulation(setup.world, seed=seed, timestep_s=settings.timestep_s,
                              wind=make_settings(settings.wind, dict(settings.wind_params)),
                              robot_dirs=settings.robot_dir, estimator=settings.estimator)
        self.lock = threading.Lock()
        self.vehicles: dict[str, Vehicle] = {}
        self.cameras: CameraSystem | None = None
        if settings.camera is not None:
            self.cameras = CameraSystem(self.sim, FrameBuffer(), synchronous=True,
                                        profile=settings.camera)

    def spawn(self, name: str, location_ned_m: tuple[float, float, float],
              yaw_rad: float) -> Vehicle:
        vehicle = Vehicle(self, name, location_ned_m, yaw_rad)
        self.vehicles[name] = vehicle
        return vehicle

    def remove(self, name: str) -> None:
        vehicle = self.vehicles.pop(name, None)
        if vehicle is not None:
            vehicle.close()
        self.sim.remove(name)

    def step(self) -> None:
        """One control period of sim time, then each vehicle's vision takes its frame (its
        vision starts with its first pose reading), where the flight has vision."""
        self.sim.step(self.settings.period_steps)
        if self.cameras is None or not self.vision:
            return
        for vehicle in self.vehicles.values():
            if vehicle.alive:
                if vehicle.vision is None and vehicle.reporting:
                    vehicle.start_vision()
                if vehicle.vision is not None:
                    vehicle.vision.step()

    def step_until_reporting(self, vehicle: Vehicle, pose_steps: int) -> None:
        """Control periods, as :meth:`step`, until ``vehicle`` has its first pose reading, as the
        pilot's spawn waits for the first readings: one period, unless a period is shorter than
        its pose sensor's (sensors report on the simulation's clock, so one comes within
        ``pose_steps``, that sensor's period: :func:`check_pose_source`).
        """
        last_step = self.sim.steps + pose_steps + self.settings.period_steps
        self.step()
        while not vehicle.reporting:
            if self.sim.steps > last_step:  # a bug: the schedule promises a reading by now
                raise SkeyeError(f"no {' or '.join(POSE_TYPES)} reading from "
                                 f"{vehicle.name} {pose_steps} steps after its spawn")
            self.step()

    @property
    def time_s(self) -> float:
        return self.sim.time_s

    def seconds_since(self, start_s: float) -> float:
        """Sim time since ``start_s`` (an earlier :attr:`time_s`), rounded to the nanosecond:
        both are whole physics steps times ``dt``, so their difference is a whole number of
        steps, and the rounding drops the float noise of that product (150 steps of 1 ms read
        0.15, not 0.15000000000000002)."""
        return round(self.sim.time_s - start_s, 9)

    def close(self) -> None:
        """Stop its threads (each vision's worker, the render thread, which frees its OpenGL
        contexts on its way out); idempotent."""
        for vehicle in self.vehicles.values():
            vehicle.close()
        if self.cameras is not None:
            self.cameras.close()

    def closed_with(self, owner: object) -> weakref.finalize:
        """Close this flight when ``owner`` (the environment flying it) is garbage-collected,
        or at interpreter exit, unless the returned finalizer was called before (the owner's
        ``close()`` or next ``reset()`` calls it: it closes the flight once, then does nothing).

        An environment dropped without ``close()`` would otherwise keep its flight for the
        process's life: its render and vision threads hold the flight (their bound methods
        reach the simulation, the vehicles, MuJoCo's model and the OpenGL contexts), so
        nothing of it is ever collected, and each thread goes on waking. The threads never
        reach ``owner``, so it is collected and the finalizer runs (a
        :class:`weakref.finalize`, not ``__del__``: it runs once, holds no reference to the
        owner, and runs at exit for an owner still alive).
        """
        return weakref.finalize(owner, self.close)


def check_pose_source(setup: Setup) -> int:
    """The physics steps between the pose readings of the vehicle (:func:`pose_period_steps`).

    Raises:
        ConfigError: the robot mounts neither an INS nor GroundTruth.
    """
    steps = pose_period_steps(setup)
    if steps is None:
        raise ConfigError(f"robot {setup.config.class_name} mounts no INS nor GroundTruth: the "
                          f"observation's pose comes from one")
    return steps


def pose_period_steps(setup: Setup) -> int | None:
    """The physics steps between the pose readings of a vehicle (:data:`POSE_TYPES`, the
    mounts :class:`BoardView` reads: the faster one), None if it mounts neither. Sensors report
    on the simulation's clock, so any stretch of this many steps after a spawn holds one."""
    names = BoardView(setup.config).names
    periods = []
    for mount in setup.config.sensors:
        type_name = next((t for t in POSE_TYPES if t.lower() == mount.type_name.lower()), None)
        if type_name is None or names.get(type_name) != mount.name:
            continue
        sensor = build_sensor(mount.type_name, mount.name, Mount(), dict(mount.params),
                              np.random.default_rng(0))
        periods.append(max(1, round(1.0 / (sensor.rate_hz * setup.settings.timestep_s))))
    return min(periods, default=None)


def with_pads(world: WorldDescription,
              pads_ned_m: tuple[tuple[float, float], ...]) -> WorldDescription:
    """The world with its first pad copied to each (north, east) point (none kept elsewhere)."""
    if not world.pads:
        raise ConfigError(f"world {world.name!r} has no landing pad")
    first = world.pads[0]
    pads = tuple(
        PadPlacement(f"{first.name}_{i}", first.pad, (n, e, first.position_ned_m[2]),
                     first.yaw_rad)
        for i, (n, e) in enumerate(pads_ned_m)
    )
    return replace(world, pads=pads)


def pad_centre(world: WorldDescription, index: int = 0) -> np.ndarray:
    """A pad's centre (NED, on its surface)."""
    if len(world.pads) <= index:
        raise ConfigError(f"world {world.name!r} has no landing pad {index}")
    pad = world.pads[index]
    n, e, _ = pad.position_ned_m
    return np.array((n, e, pad.surface_down_m))
