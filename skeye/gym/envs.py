"""The Gymnasium environments: one vehicle, one task, the simulation in this process.

How this works: :class:`SkeyeEnv` is a :class:`gymnasium.Env` over a
:class:`~skeye.gym.tasks.Task` and a :class:`~skeye.gym.flight.Flight`. ``reset`` makes a new
flight (a new :class:`~skeye.sim.engine.Simulation` seeded from the environment's generator,
so ``reset(seed=s)`` repeats an episode bit for bit), spawns the vehicle hovering at the task's
start, and lets one control period pass with it holding still (more, until its first pose
reading, where a period is shorter than its INS's), so the first observation carries real
readings. ``step`` hands the action to the vehicle's board as the pilot would
(:func:`skeye.pilot.policy.velocity_setpoint` or :func:`~skeye.pilot.policy.attitude_setpoint`
through the pilot's airframe interface), steps one control period (``1 / control_rate_hz``
of sim time, in lockstep: the camera frames of that period are rendered, and the pilot's
vision has taken the newest), and returns the task's observation, reward and ending.

Keywords of ``gymnasium.make`` (docs/gym.md, "Options"): the :class:`FlightSettings` fields
(robot, robot_dir, world, estimator, wind, wind_params, sensor_noise, control_rate_hz, camera,
camera_name, vision_latency_s, calibration, timestep_s), ``action`` (Hover, GoTo: "velocity"
or "attitude"), ``episode_s``, ``render_mode`` ("rgb_array": the downward camera's newest
frame, where there is a camera), and PadLanding's observation, image_size, start_offset_m,
start_height_m and pad_tolerance_m. A camera or vision setting the environment would ignore
(Hover and GoTo observe no pad detection, and have a camera only to render it) is refused,
as is a render mode it does not offer (:mod:`skeye.gym.options`).

An environment pickles (``pickle``, ``cloudpickle``, ``copy.deepcopy``) as its constructor's
arguments, as Gymnasium's own MuJoCo environments do (:class:`gymnasium.utils.EzPickle`): a
flight holds a live simulation (threads' locks, MuJoCo's buffers), so the copy is a new
environment of the same options, not yet reset; its ``reset(seed=s)`` flies the episode the
original's would. The copy keeps the ``spec`` that ``gymnasium.make`` set
(:class:`SpecPickle`).
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping
from typing import Any, SupportsFloat

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle

from skeye.errors import ConfigError
from skeye.geo import MAX_POSITION_M
from skeye.gym.flight import (
    Flight,
    FlightSettings,
    Vehicle,
    check_pose_source,
    pad_centre,
    prepare,
)
from skeye.gym.options import RENDER_MODE, check_render_mode, check_settings, env_id
from skeye.gym.tasks import (
    PAD_START_HEIGHT_M,
    PAD_START_OFFSET_M,
    PAD_TOLERANCE_M,
    Episode,
    GoTo,
    Hover,
    PadLanding,
    Task,
)
from skeye.pilot.policy import (
    DEFAULT_IMAGE_SIZE,
    ActionLimits,
    attitude_setpoint,
    velocity_setpoint,
)
from skeye.robots.config import RobotConfig
from skeye.values import number, numbers

ACTIONS = ("velocity", "attitude")
ENV_KEYWORDS = ("action", "episode_s", "render_mode")
"""Every environment's own keywords of ``gymnasium.make`` (beside FlightSettings' and its
task's)."""


class EnvironmentClosed(gymnasium.error.ClosedEnvironmentError, gymnasium.error.ResetNeeded):
    """``reset()`` or ``step()`` after ``close()``: Gymnasium's ClosedEnvironmentError (as its
    AsyncVectorEnv raises), and a ResetNeeded, which a ``step()`` after ``close()`` raised
    before (so code catching that still does)."""

    def __init__(self, call: str) -> None:
        super().__init__(f"{call}: the environment was closed (close()); make a new one "
                         f"(gymnasium.make, or copy.deepcopy of this one)")


def action_limits(config: RobotConfig) -> ActionLimits:
    """What an action of 1 means for this robot (its [controller] limits)."""
    c = config.controller
    return ActionLimits(c.max_speed_m_s, c.max_climb_m_s, c.max_yaw_rate_rad_s, c.max_tilt_rad)


def apply_action(vehicle: Vehicle, kind: str, action: Any, limits: ActionLimits) -> None:
    """Fly one action: a velocity or stick set-point through the pilot's airframe interface."""
    if kind == "velocity":
        forward, right, up, yaw_rate = velocity_setpoint(action, limits)
        vehicle.airframe.set_velocity(forward, right, up, yaw_rate, None)
    else:
        roll, pitch, yaw_rate, thrust = attitude_setpoint(action, limits)
        vehicle.airframe.attitude(roll, pitch, yaw_rate, thrust)


def task_origin(task: Task, flight_world: Any) -> tuple[float, float, float]:
    """Where a single environment's episodes are placed: the pad (PadLanding) or the world
    origin."""
    if isinstance(task, PadLanding):
        n, e, d = pad_centre(flight_world)
        return (float(n), float(e), float(d))
    return (0.0, 0.0, 0.0)


class SpecPickle(EzPickle):
    """:class:`gymnasium.utils.EzPickle` that also keeps the ``spec`` ``gymnasium.make`` (or
    ``make_vec``) set on the environment after building it: a copy built from the
    constructor's arguments alone would read None (its id, its ``max_episode_steps``)."""

    def __getstate__(self) -> dict[str, Any]:
        return {**super().__getstate__(), "spec": getattr(self, "spec", None)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        super().__setstate__(state)
        self.spec = state.get("spec")


class SkeyeEnv(gymnasium.Env[Any, np.ndarray], SpecPickle):
    """One vehicle flying one task (see the module docstring). Each subclass records its own
    constructor's arguments for pickling (``EzPickle.__init__``) after this one's."""

    # The class's render modes are the most any instance offers: Gymnasium's make reads them
    # before building it (and asks for "rgb_array" when given "human"); each instance's own say
    # whether its camera makes them real (skeye.gym.options).
    metadata: dict[str, Any] = {"render_modes": [RENDER_MODE], "render_fps": 20}  # noqa: RUF012

    def __init__(self, task: Task, *, action: str = "velocity", episode_s: float | None = None,
                 render_mode: str | None = None, **settings: Any) -> None:
        EzPickle.__init__(self, task, action=action, episode_s=episode_s,
                          render_mode=render_mode, **settings)
        if action not in ACTIONS:
            raise ConfigError(f"action must be one of {list(ACTIONS)}, got {action!r}")
        if task.needs_camera and action != "velocity":
            raise ConfigError(f"{task.name} flies velocity set-points only")
        if task.needs_camera:
            settings.setdefault("camera", "webcam")
        # A bad value is named as such first; then a good one that would do nothing here.
        self.settings = FlightSettings.from_kwargs(
            settings, where=env_id(task), also=(*ENV_KEYWORDS, *task.keywords))
        check_settings(task, settings, renders=render_mode is not None)
        if task.needs_camera and self.settings.camera is None:
            raise ConfigError(f"{task.name} needs the camera: camera must be webcam or ideal")
        check_render_mode(task, render_mode, self.settings.camera is not None)
        if episode_s is not None:
            if not number("episode_s", episode_s) > 0:
                raise ConfigError(f"episode_s must be > 0, got {episode_s!r}")
            task.episode_s = float(episode_s)
        self.task = task
        self.action_kind = action
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.settings.control_rate_hz,
                         "render_modes": [RENDER_MODE] if self.settings.camera else []}
        self.setup = prepare(self.settings)  # the robot, world and camera, checked now
        # the observation's pose comes from its INS or GroundTruth: one is refused without
        self._pose_steps = check_pose_source(self.setup)
        self.limits = action_limits(self.setup.config)
        self.origin = task_origin(task, self.setup.world)
        self.observation_space = task.observation_space()
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self.flight: Flight | None = None
        self.vehicle: Vehicle | None = None
        self.episode: Episode | None = None
        self._release: weakref.finalize | None = None  # closes the flight if we are dropped
        self._closed = False
        self._started_s = 0.0
        # why the episode ended ("terminated", "truncated", a step() cut short by an
        # exception), "" while it runs
        self._ended = ""

    # -- gymnasium ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        """A new episode; ``options`` may fix ``start_ned_m``, ``yaw_rad`` and (Hover, GoTo)
        ``target_ned_m`` instead of drawing them."""
        if self._closed:  # a new flight now would outlive the user's close()
            raise EnvironmentClosed("reset()")
        super().reset(seed=seed)
        self._close_flight()
        episode = self.task.start(self.np_random, self.origin)
        override_start(episode, options, target_fixed=self.task.target_fixed)
        self.task.prime(episode)  # the progress counted from the start and target given
        flight = Flight(self.setup, int(self.np_random.integers(2**31)),
                        vision=self.task.needs_camera)  # Hover, GoTo: a camera to render only
        try:
            vehicle = flight.spawn("R1", episode.start_ned_m, episode.yaw_rad)
            if not vehicle.robot.spawn_airborne:  # it would stand there: a crash at once
                n, e, d = episode.start_ned_m
                raise ConfigError(
                    f"the start ({n:g}, {e:g}, {d:g}) m NED is not in the air: it is at or "
                    f"below the ground or an object there (down is positive), where the "
                    f"vehicle stands on its gear; an episode starts flying, so start_ned_m "
                    f"must be above what is below it")
            vehicle.airframe.hover()
            flight.step_until_reporting(vehicle, self._pose_steps)
        except BaseException:
            flight.close()
            raise
        self.flight, self.vehicle, self.episode = flight, vehicle, episode
        self._release = flight.closed_with(self)
        self._started_s = flight.time_s
        self._ended = ""
        return self._observe(), self._info()

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        flight, vehicle, episode = self.flight, self.vehicle, self.episode
        if self._closed:
            raise EnvironmentClosed("step()")
        if flight is None or vehicle is None or episode is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        if self._ended:  # a crashed vehicle would fly on, its episode judged afresh
            raise gymnasium.error.ResetNeeded(
                f"the episode is over ({self._ended}): call reset() before step()")
        if vehicle.alive:  # a refused action raises here, before anything is flown
            apply_action(vehicle, self.action_kind, action, self.limits)
        try:
            flight.step()
        except BaseException as exc:  # the period half flown, unjudged: no step goes on from it
            self._ended = f"the last step() was cut short by {type(exc).__name__}"
            raise
        reward, terminated = self.task.judge(vehicle, episode)
        truncated = not terminated and flight.seconds_since(self._started_s) >= (
            self.task.episode_s - 1e-9)
        self._ended = "terminated" if terminated else "truncated" if truncated else ""
        return self._observe(), float(reward), terminated, truncated, self._info()

    def render(self) -> np.ndarray | None:
        if self.render_mode != RENDER_MODE or self.flight is None:
            return None
        cameras = self.flight.cameras
        if cameras is None:
            return None
        frame = cameras.buffer.latest(f"R1/{self.settings.camera_name}")
        if frame is None:  # the first frame is still on its way (the capture latency)
            width, height = self.setup.camera_size
            return np.zeros((height, width, 3), dtype=np.uint8)
        return np.array(frame.rgb)

    def close(self) -> None:
        """End the flight (its threads, the simulation); idempotent. A closed environment
        refuses ``reset()`` and ``step()`` (:class:`EnvironmentClosed`)."""
        self._close_flight()
        self._closed = True
        super().close()

    # -- helpers -----------------------------------------------------------------------------
    def _observe(self) -> Any:
        assert self.flight is not None and self.vehicle is not None and self.episode is not None
        snap = self.vehicle.airframe.snapshot()
        return self.task.observe(self.vehicle, snap, self.episode)

    def _info(self) -> dict[str, Any]:
        assert self.flight is not None and self.episode is not None
        return {"sim_time_s": self.flight.seconds_since(self._started_s), **self.episode.info}

    def _close_flight(self) -> None:
        if self._release is not None:
            self._release()  # closes the flight, once
        self._release = None
        self.flight = self.vehicle = self.episode = None


def override_start(episode: Episode, options: Any, target_fixed: bool = False) -> None:
    """``reset(options=...)``: a fixed start, heading or target instead of the drawn ones
    (``target_fixed``: the task's target is not an option, as PadLanding's pad)."""
    if options is None:
        return
    if not isinstance(options, Mapping):
        raise ConfigError(f"reset options must be a dict, got {options!r}")
    known = ("start_ned_m", "yaw_rad") if target_fixed else (
        "start_ned_m", "yaw_rad", "target_ned_m")
    unknown = sorted(set(options) - set(known), key=str)
    if unknown:
        raise ConfigError(f"unknown reset option(s) {unknown}; known: {', '.join(known)}")
    for key in ("start_ned_m", "target_ned_m"):
        if key in options:
            value = numbers(key, options[key], 3, "three finite numbers (north, east, down m)")
            if max(abs(v) for v in value) > MAX_POSITION_M:
                raise ConfigError(f"{key} must be within {MAX_POSITION_M:g} m of the origin "
                                  f"(the simulator's limit), got {options[key]!r}")
            setattr(episode, key, value)
    if "yaw_rad" in options:
        episode.yaw_rad = number("yaw_rad", options["yaw_rad"])


class HoverEnv(SkeyeEnv):
    """``skeye/Hover-v0``: hold a point (:class:`skeye.gym.tasks.Hover`)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(Hover(), **kwargs)
        EzPickle.__init__(self, **kwargs)


class GoToEnv(SkeyeEnv):
    """``skeye/GoTo-v0``: fly to a target (:class:`skeye.gym.tasks.GoTo`)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(GoTo(), **kwargs)
        EzPickle.__init__(self, **kwargs)


class PadLandingEnv(SkeyeEnv):
    """``skeye/PadLanding-v0``: land on the pad (:class:`skeye.gym.tasks.PadLanding`); the
    paper's disturbance (``wind="random_force"``, F_max 0.3 N, as ``skeye validate``'s E2)
    unless told otherwise."""

    def __init__(self, *, observation: str = "pad",
                 image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE,
                 start_offset_m: float = PAD_START_OFFSET_M,
                 start_height_m: tuple[float, float] = PAD_START_HEIGHT_M,
                 pad_tolerance_m: float = PAD_TOLERANCE_M,
                 **kwargs: Any) -> None:
        kwargs.setdefault("wind", "random_force")
        task = PadLanding(observation, image_size, start_offset_m, start_height_m,
                          pad_tolerance_m)
        super().__init__(task, **kwargs)
        EzPickle.__init__(self, observation=observation, image_size=image_size,
                          start_offset_m=start_offset_m, start_height_m=start_height_m,
                          pad_tolerance_m=pad_tolerance_m, **kwargs)
