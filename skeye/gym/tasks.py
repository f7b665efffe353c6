"""The tasks: where an episode starts, what the policy observes, the reward and the end.

How this works: a :class:`Task` is the part of an environment that is not the simulation. It
draws the start (and target) of an episode from the environment's seeded generator, around an
``origin`` (the world origin for one vehicle; each vehicle's own cell in the batched vector
environment), builds the observation from the pilot's snapshot (:mod:`skeye.pilot.policy`:
the same numbers ``skeye pilot --policy`` gives a policy), and judges each step on ground
truth (the reward and the end may use what the vehicle cannot know; the observation never
does). docs/gym.md tabulates every space, reward and ending.

- :class:`Hover` (``skeye/Hover-v0``): hold a point 1.5 m above the origin from a start up to
  0.5 m from it north and east each (0.3 m vertically). Reward per step
  ``1 - min(|e|, 1 m)/1 m`` (e: true distance to the point).
- :class:`GoTo` (``skeye/GoTo-v0``): fly from 1.5 m above the origin to a target up to 4 m away
  north and east each (5.7 m horizontally) and 1-3 m high. Reward per step: the progress
  ``d_prev - d`` (m) plus 0.1 within 0.2 m of the target.
- :class:`PadLanding` (``skeye/PadLanding-v0``): from 1.5-2.5 m above a point within
  ``start_offset_m`` of the pad, land on it; the observation has the pilot's pad detection (or
  the camera image). Reward per step: the progress of ``horizontal distance + 0.5 height``
  towards the pad; at touchdown +10 within ``pad_tolerance_m`` of the pad centre (success),
  else -10.

Every task ends (terminated) with -10 on a crash: the vehicle stopped by the physics, found
crashed by the simulator (:mod:`skeye.sim.crash`: a hard impact; its motors stop and its
set-points are refused), tilted beyond 60 degrees, left its area, or (Hover, GoTo) touched
the ground; and is truncated at its ``episode_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium import spaces

from skeye.errors import ConfigError
from skeye.gym.flight import Vehicle
from skeye.pilot.airframe import Snapshot
from skeye.pilot.policy import (
    DEFAULT_IMAGE_SIZE,
    OBSERVATIONS,
    PAD_HIGH,
    PAD_LOW,
    STATE_HIGH,
    STATE_LOW,
    policy_observation,
    state_vector,
)
from skeye.sim.state import BodyState
from skeye.values import number, numbers

Vec3 = tuple[float, float, float]
CRASH_REWARD = -10.0
SUCCESS_REWARD = 10.0
PAD_TOLERANCE_M = 0.15  # PadLanding's success: touchdown this close to the pad centre
PAD_START_OFFSET_M = 0.4  # PadLanding's start: at most this far from above the pad centre
PAD_START_HEIGHT_M = (1.5, 2.5)  # PadLanding's start: this high above the pad (from, to)
MAX_TILT_RAD = math.radians(60.0)
CEILING_M = 10.0
TARGET_FIELDS = ("target_north_m", "target_east_m", "target_down_m")
"""Hover and GoTo: the target minus the onboard position estimate, NED."""


@dataclass
class Episode:
    """One vehicle's episode: its start, target and running figures."""

    start_ned_m: Vec3
    yaw_rad: float
    target_ned_m: Vec3  # Hover/GoTo: the point; PadLanding: the pad centre on its surface
    last_distance_m: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)


TARGET_HIGH = np.full(3, 2e5, dtype=np.float32)


def _box(*bounds: tuple[np.ndarray, np.ndarray]) -> spaces.Box:
    low = np.concatenate([b[0] for b in bounds]).astype(np.float32)
    high = np.concatenate([b[1] for b in bounds]).astype(np.float32)
    return spaces.Box(low, high, dtype=np.float32)


def tilt_rad(truth: BodyState) -> float:
    """The angle between the body's down axis and the world's."""
    r22 = truth.rot_body_to_ned[2][2]
    return math.acos(max(-1.0, min(1.0, r22)))


class Task:
    """The base: see the module docstring. ``area_m``: farthest from the target before the
    episode ends as a crash; ``target_fixed``: the target is not a reset option (the pad)."""

    name = ""
    episode_s = 10.0
    area_m = 3.0
    needs_camera = False
    target_fixed = False
    keywords: tuple[str, ...] = ()  # its own keywords of gymnasium.make (PadLanding's)

    @property
    def reach_m(self) -> float:
        """The farthest horizontally from its cell's centre that an episode still runs: its
        area around the target, the target being at the centre (Hover's point, the pad)."""
        return self.area_m

    def observation_space(self) -> spaces.Space[Any]:
        return _box((STATE_LOW, STATE_HIGH), (-TARGET_HIGH, TARGET_HIGH))

    def start(self, rng: np.random.Generator, origin: Vec3) -> Episode:
        """A new episode drawn around ``origin``, primed (:meth:`prime`)."""
        raise NotImplementedError

    def potential(self, pos: Vec3, episode: Episode) -> float:
        """What the progress reward counts down (GoTo, PadLanding): the distance to the
        target."""
        return math.dist(pos, episode.target_ned_m)

    def prime(self, episode: Episode) -> None:
        """Count the progress from the episode's start: after drawing it, and again after
        ``reset(options=...)`` replaced its start or target."""
        episode.last_distance_m = self.potential(episode.start_ned_m, episode)

    def observe(self, vehicle: Vehicle, snap: Snapshot, episode: Episode) -> Any:
        """State + target offset from the estimate (Hover, GoTo)."""
        n, e, d = snap.pos_ned_m
        t = episode.target_ned_m
        offset = np.array((t[0] - n, t[1] - e, t[2] - d), dtype=np.float32)
        return np.concatenate((state_vector(snap, vehicle.home_ned_m),
                               np.clip(offset, -TARGET_HIGH, TARGET_HIGH)))

    def distance_m(self, truth: BodyState, episode: Episode) -> float:
        p, t = truth.pos_ned_m, episode.target_ned_m
        return math.dist(p, t)

    def crashed(self, vehicle: Vehicle, truth: BodyState | None, episode: Episode) -> str:
        """Why the episode ends as a crash ('' when it does not). Records the step's
        ``distance_m`` in the episode's info first (a crash's info gives the distance of the
        step that ended it, not of the step before; none where the physics stopped the
        vehicle, whose position is then unknown)."""
        if truth is None:
            episode.info.pop("distance_m", None)
            return f"stopped: {vehicle.view.stopped or 'removed'}"
        distance = episode.info["distance_m"] = self.distance_m(truth, episode)
        if vehicle.robot.flight.crashed:  # the simulator's detector: motors off, DRIVE refused
            return f"crashed: {vehicle.robot.flight.crashed}"
        if tilt_rad(truth) > MAX_TILT_RAD:
            return "tilted beyond 60 degrees"
        if distance > self.area_m:
            return f"left the area ({self.area_m:g} m)"
        if truth.pos_ned_m[2] < episode.target_ned_m[2] - CEILING_M:
            return f"climbed {CEILING_M:g} m above the target"
        return ""

    def judge(self, vehicle: Vehicle, episode: Episode) -> tuple[float, bool]:
        """(reward, terminated) of the step just made."""
        truth = vehicle.truth() if vehicle.alive else None
        crash = self.crashed(vehicle, truth, episode)
        if not crash and vehicle.robot.flight.landed:
            crash = "touched the ground"
        if crash:
            episode.info.update(crash=crash, success=False)
            return CRASH_REWARD, True
        assert truth is not None
        return self.step_reward(truth, episode), False

    def step_reward(self, truth: BodyState, episode: Episode) -> float:
        raise NotImplementedError


class Hover(Task):
    name = "Hover"
    episode_s = 10.0
    area_m = 3.0

    def start(self, rng: np.random.Generator, origin: Vec3) -> Episode:
        target = (origin[0], origin[1], origin[2] - 1.5)
        offset = rng.uniform((-0.5, -0.5, -0.3), (0.5, 0.5, 0.3))
        start = (target[0] + offset[0], target[1] + offset[1], target[2] + offset[2])
        return Episode(start, float(rng.uniform(-math.pi, math.pi)), target)

    def step_reward(self, truth: BodyState, episode: Episode) -> float:
        d = self.distance_m(truth, episode)
        episode.info["distance_m"] = d
        return 1.0 - min(d, 1.0)


class GoTo(Task):
    name = "GoTo"
    episode_s = 15.0
    area_m = 8.0

    target_box_m = 4.0  # the target is drawn this far north and east of the centre at most

    @property
    def reach_m(self) -> float:
        """The area around a target that can be ``target_box_m`` north and east of the
        centre: the target's farthest corner is that times sqrt(2) away."""
        return self.area_m + math.sqrt(2.0) * self.target_box_m

    def start(self, rng: np.random.Generator, origin: Vec3) -> Episode:
        jitter = rng.uniform((-0.2, -0.2, -0.2), (0.2, 0.2, 0.2))
        start = (origin[0] + jitter[0], origin[1] + jitter[1], origin[2] - 1.5 + jitter[2])
        dn, de = rng.uniform(-self.target_box_m, self.target_box_m, size=2)
        target = (origin[0] + float(dn), origin[1] + float(de),
                  origin[2] - float(rng.uniform(1.0, 3.0)))
        episode = Episode(start, float(rng.uniform(-math.pi, math.pi)), target)
        self.prime(episode)
        return episode

    def step_reward(self, truth: BodyState, episode: Episode) -> float:
        d = self.distance_m(truth, episode)
        progress = episode.last_distance_m - d
        episode.last_distance_m = d
        episode.info["distance_m"] = d
        return progress + (0.1 if d < 0.2 else 0.0)


class PadLanding(Task):
    """See the module docstring; ``observation``: ``"pad"`` or ``"image"``."""

    name = "PadLanding"
    episode_s = 30.0
    area_m = 3.0
    needs_camera = True
    target_fixed = True
    keywords = ("observation", "image_size", "start_offset_m", "start_height_m",
                "pad_tolerance_m")

    def __init__(self, observation: str = "pad", image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE,
                 start_offset_m: float = PAD_START_OFFSET_M,
                 start_height_m: tuple[float, float] = PAD_START_HEIGHT_M,
                 pad_tolerance_m: float = PAD_TOLERANCE_M) -> None:
        if observation not in OBSERVATIONS:
            raise ConfigError(f"observation must be one of {list(OBSERVATIONS)}, "
                              f"got {observation!r}")
        size_rule = "(width, height), whole numbers 8..2048 each"
        w, h = numbers("image_size", image_size, 2, size_rule)
        if not (w.is_integer() and h.is_integer() and 8 <= w <= 2048 and 8 <= h <= 2048):
            raise ConfigError(f"image_size must be {size_rule}, got {image_size!r}")
        height_rule = "(low, high) within 0.5..10 m"
        low, high = numbers("start_height_m", start_height_m, 2, height_rule)
        if not (0.5 <= low <= high <= 10.0):
            raise ConfigError(f"start_height_m must be {height_rule}, got {start_height_m!r}")
        checked = {}
        for name, value, top in (("start_offset_m", start_offset_m, 2.0),
                                 ("pad_tolerance_m", pad_tolerance_m, 1.0)):
            checked[name] = number(name, value)
            if not 0.0 <= checked[name] <= top:
                raise ConfigError(f"{name} must be 0..{top:g} m, got {value!r}")
        self.observation = observation
        self.image_size = (int(w), int(h))
        self.start_offset_m = checked["start_offset_m"]
        self.start_height_m = (low, high)
        self.pad_tolerance_m = checked["pad_tolerance_m"]

    def observation_space(self) -> spaces.Space[Any]:
        state = _box((STATE_LOW, STATE_HIGH), (PAD_LOW, PAD_HIGH))
        if self.observation == "pad":
            return state
        w, h = self.image_size
        return spaces.Dict({"state": state,
                            "image": spaces.Box(0, 255, shape=(h, w, 1), dtype=np.uint8)})

    def start(self, rng: np.random.Generator, origin: Vec3) -> Episode:
        radius = self.start_offset_m * math.sqrt(float(rng.uniform()))
        bearing = float(rng.uniform(-math.pi, math.pi))
        height = float(rng.uniform(*self.start_height_m))
        start = (origin[0] + radius * math.cos(bearing), origin[1] + radius * math.sin(bearing),
                 origin[2] - height)
        episode = Episode(start, float(rng.uniform(-math.pi, math.pi)), origin)
        self.prime(episode)
        # in every info, so an episode truncated (here or by Gymnasium's TimeLimit) says so
        episode.info["success"] = False
        return episode

    def potential(self, pos: Vec3, episode: Episode) -> float:
        """Horizontal distance to the pad centre plus half the height above it."""
        t = episode.target_ned_m
        return math.hypot(pos[0] - t[0], pos[1] - t[1]) + 0.5 * max(0.0, t[2] - pos[2])

    def distance_m(self, truth: BodyState, episode: Episode) -> float:
        p, t = truth.pos_ned_m, episode.target_ned_m
        return math.hypot(p[0] - t[0], p[1] - t[1])

    def observe(self, vehicle: Vehicle, snap: Snapshot, episode: Episode) -> Any:
        pad = vehicle.pad.latest if vehicle.pad is not None else None
        image = None
        if self.observation == "image":
            image = vehicle.frame_bgr()
        return policy_observation(self.observation, snap, vehicle.home_ned_m, pad, image,
                                  self.image_size)

    def judge(self, vehicle: Vehicle, episode: Episode) -> tuple[float, bool]:
        truth = vehicle.truth() if vehicle.alive else None
        crash = self.crashed(vehicle, truth, episode)
        if crash:
            episode.info.update(crash=crash, success=False)
            return CRASH_REWARD, True
        assert truth is not None
        error = self.distance_m(truth, episode)
        episode.info["distance_m"] = error
        if vehicle.robot.flight.landed:  # touchdown: on the pad, or not
            success = error <= self.pad_tolerance_m
            episode.info.update(success=success, touchdown_error_m=error)
            return (SUCCESS_REWARD if success else CRASH_REWARD), True
        potential = self.potential(truth.pos_ned_m, episode)
        progress = episode.last_distance_m - potential
        episode.last_distance_m = potential
        return progress, False
