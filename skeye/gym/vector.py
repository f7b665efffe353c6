"""The batched vector environment: N vehicles in one simulated world, stepped together.

How this works: :class:`SkeyeVectorEnv` is a :class:`gymnasium.vector.VectorEnv` whose N
sub-environments are N vehicles of one :class:`~skeye.gym.flight.Flight` (one
:class:`~skeye.sim.engine.Simulation`, one MuJoCo world: one ``step`` call advances them all,
and one render job draws every camera). Each vehicle has its own cell of the world
(``spacing_m`` apart on a square grid, its own landing pad for PadLanding: far enough apart
that no camera sees a neighbour), its own task episode, observation and reward, computed as
the single environment computes them (:mod:`skeye.gym.tasks`). A vehicle whose episode ended
is taken out of the world and spawned again at its next start at the next ``step`` (Gymnasium's
next-step autoreset: that step returns its first observation, reward 0, not terminated); the
others fly on undisturbed, their state carried across the world's rebuild exactly.

``reset(seed=s)`` makes a new world seeded from ``s``: the same seed and actions give the same
batch of episodes, bit for bit. The keywords are the single environment's
(:mod:`skeye.gym.envs`) plus ``spacing_m`` and ``max_episode_steps`` (which
``gymnasium.make`` turns into a ``TimeLimit`` wrapper, and ``make_vec`` hands to a vector entry
point: each vehicle's episode is truncated after that many steps); it renders nothing, so it
offers no render mode and Hover and GoTo take no camera (:mod:`skeye.gym.options`). It
pickles as its constructor's arguments, as the single environment does (``EzPickle``, keeping
the ``spec`` ``make_vec`` set): a new world of the same options, not yet reset.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from numbers import Integral
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.utils import EzPickle
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

from skeye.errors import ConfigError, InvalidArgument
from skeye.geo import MAX_POSITION_M
from skeye.gym.envs import (
    ACTIONS,
    ENV_KEYWORDS,
    EnvironmentClosed,
    SpecPickle,
    action_limits,
    apply_action,
    override_start,
)
from skeye.gym.flight import (
    Flight,
    FlightSettings,
    Setup,
    Vehicle,
    check_pose_source,
    prepare,
)
from skeye.gym.options import check_render_mode, check_settings, env_id
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
from skeye.pilot.policy import DEFAULT_IMAGE_SIZE, action_values
from skeye.sim.world import WorldDescription
from skeye.sim.world_model import Box
from skeye.values import number

MAX_NUM_ENVS = 256
"""The most vehicles one batched environment flies."""
DEFAULT_SPACING_M = 10.0
"""Between vehicles' cells, at least (a task whose reach needs more gets its minimum,
:func:`min_spacing_m`): PadLanding's area is 3 m and the webcam sees about 1.5 m around
itself from 2.5 m up, so 10 m keeps every neighbour out of every view."""
CELL_CLEARANCE_M = 2.0
"""Between two vehicles of neighbouring cells, each as far towards the other as its episode
runs (its task's ``reach_m``): two Hummingbirds side by side need 0.54 m centre to centre
(the simulator refuses a spawn closer: docs/protocols/simulator.md, INIT), and the rest,
1.46 m, is for the travel past its reach: a vehicle is judged after every control step and
taken out at the next, so it is never more than one control period past it; two flying at
each other have 0.73 m each in that period, 14.6 m/s at the default 20 Hz (the velocity
action's limit is 3 m/s). At a much slower ``control_rate_hz`` a fast vehicle can go further;
should one stand where a neighbour respawns, ``step`` raises the simulator's refusal, which
names both."""
CELL_REACH_M = 100.0
"""How far from its cell's centre an episode may take a vehicle (each task's area, target and
ceiling are well within): the farthest cell stays this far inside the simulator's limit."""


def min_spacing_m(task: Task) -> float:
    """The closest two cells may be for ``task``: each vehicle's reach and the clearance
    between them (``CELL_CLEARANCE_M``), so that no vehicle flies into a neighbour, nor is
    respawned where one flies (the simulator would refuse the spawn)."""
    return 2.0 * task.reach_m + CELL_CLEARANCE_M


def vehicle_count(value: Any) -> int:
    """``num_envs``: a whole number 1..MAX_NUM_ENVS of any integer type (numpy's too, as
    Gymnasium's sync and async modes take it), not a bool."""
    count = int(value) if isinstance(value, Integral) and not isinstance(value, bool) else 0
    if not 1 <= count <= MAX_NUM_ENVS:
        raise ConfigError(f"num_envs must be a whole number 1..{MAX_NUM_ENVS}, got {value!r}")
    return count


def grid(num: int, spacing_m: float) -> list[tuple[float, float]]:
    """``num`` (north, east) points on a square grid centred on the origin."""
    side = math.ceil(math.sqrt(num))
    half = (side - 1) / 2.0
    return [((i // side - half) * spacing_m, (i % side - half) * spacing_m) for i in range(num)]


def box_distance_m(point_ne_m: tuple[float, float], box: Box) -> float:
    """Horizontal distance from a (north, east) point to a box's footprint (0 inside it)."""
    dn, de = point_ne_m[0] - box.center_ned_m[0], point_ne_m[1] - box.center_ned_m[1]
    c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    along, across = c * dn + s * de, -s * dn + c * de  # in the box's own north and east
    return math.hypot(max(abs(along) - box.size_m[0] / 2.0, 0.0),
                      max(abs(across) - box.size_m[1] / 2.0, 0.0))


def check_cells_clear(world: WorldDescription, cells: list[tuple[float, float]],
                      reach_m: float) -> None:
    """Refuse a cell whose episodes would reach one of the world's boxes (a wall, a building,
    a ceiling): the cells copy the world's pad, not its obstacles, so a box near a cell's
    centre is where no episode of the single environment meets one, and every episode of that
    vehicle would end flying into it (or start inside it). A cell at the origin is the world's
    own scene, the one the single environment flies, and is not checked."""
    clear_m = reach_m + CELL_CLEARANCE_M / 2.0  # the vehicle's size and a period's flight
    for i, (north, east) in enumerate(cells):
        if north == 0.0 and east == 0.0:
            continue
        for box in world.boxes:
            distance = box_distance_m((north, east), box)
            if distance < clear_m:
                raise ConfigError(
                    f"vehicle {i}'s cell, centred at ({north:g}, {east:g}) m NED, is "
                    f"{distance:.2f} m from box {box.name!r} of world {world.name!r}: its "
                    f"episodes run up to {reach_m:g} m from the centre, and need "
                    f"{clear_m:g} m clear of any box (the cells copy the world's pad, not its "
                    f"obstacles); use a world without boxes there (pad), other num_envs or "
                    f"spacing_m, or vectorization_mode='sync' or 'async'")


def check_period(setup: Setup) -> None:
    """A respawned vehicle is observed one control period after its spawn: refuse a period
    that may pass without its first pose reading (shorter than its INS's)."""
    needed = check_pose_source(setup)
    settings = setup.settings
    if settings.period_steps < needed:
        fastest_hz = 1.0 / (needed * settings.timestep_s)
        raise ConfigError(
            f"control_rate_hz {settings.control_rate_hz:g} is faster than robot "
            f"{setup.config.class_name}'s INS ({fastest_hz:g} Hz): the batched environment "
            f"observes a respawned vehicle one control period after its spawn, which may be "
            f"before its first reading; use control_rate_hz <= {fastest_hz:g}, or "
            f"vectorization_mode='sync' or 'async'")


class SkeyeVectorEnv(VectorEnv[Any, Any, Any], SpecPickle):
    """N vehicles flying one task in one world (see the module docstring). Each subclass
    records its own constructor's arguments for pickling after this one's."""

    metadata: dict[str, Any] = {  # noqa: RUF012  (Gymnasium's class attribute)
        "autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, task_factory: Callable[[], Task], num_envs: int, *,
                 spacing_m: float | None = None, action: str = "velocity",
                 episode_s: float | None = None, render_mode: Any = None,
                 max_episode_steps: int | None = None, **settings: Any) -> None:
        EzPickle.__init__(self, task_factory, num_envs, spacing_m=spacing_m, action=action,
                          episode_s=episode_s, render_mode=render_mode,
                          max_episode_steps=max_episode_steps, **settings)
        num_envs = vehicle_count(num_envs)
        if max_episode_steps == -1 and not isinstance(max_episode_steps, bool):
            max_episode_steps = None  # gymnasium.make's "no TimeLimit"
        if max_episode_steps is not None and (
                isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, int)
                or max_episode_steps < 1):
            raise ConfigError(f"max_episode_steps must be a whole number >= 1 (or None or -1: "
                              f"no limit), got {max_episode_steps!r}")
        if action not in ACTIONS:
            raise ConfigError(f"action must be one of {list(ACTIONS)}, got {action!r}")
        self.tasks = [task_factory() for _ in range(num_envs)]
        task = self.tasks[0]
        closest = min_spacing_m(task)
        if spacing_m is None:
            spacing_m = max(DEFAULT_SPACING_M, closest)
        elif not (number("spacing_m", spacing_m) >= closest):
            raise ConfigError(
                f"spacing_m must be >= {closest:g} m for {task.name}, got {spacing_m!r}: its "
                f"episodes run up to {task.reach_m:g} m from their cell's centre, and two "
                f"vehicles of neighbouring cells need {CELL_CLEARANCE_M:g} m between them")
        self.spacing_m = float(spacing_m)
        if task.needs_camera:
            settings.setdefault("camera", "webcam")
            if action != "velocity":
                raise ConfigError(f"{task.name} flies velocity set-points only")
        if episode_s is not None:
            if not number("episode_s", episode_s) > 0:
                raise ConfigError(f"episode_s must be > 0, got {episode_s!r}")
            for t in self.tasks:
                t.episode_s = float(episode_s)
        self.settings = FlightSettings.from_kwargs(
            settings, where=env_id(task, vector=True),
            also=(*ENV_KEYWORDS, *task.keywords, "num_envs", "spacing_m", "max_episode_steps"))
        check_settings(task, settings, renders=False, vector=True)
        check_render_mode(task, render_mode, False, vector=True)
        cells = grid(num_envs, spacing_m)
        farthest = max(max(abs(n), abs(e)) for n, e in cells)
        if farthest > MAX_POSITION_M - CELL_REACH_M:
            raise ConfigError(f"spacing_m {spacing_m:g} puts {num_envs} vehicles up to "
                              f"{farthest:g} m from the origin: the simulator's limit is "
                              f"{MAX_POSITION_M:g} m")
        self.setup = prepare(self.settings, tuple(cells) if task.needs_camera else None)
        check_period(self.setup)
        check_cells_clear(self.setup.world, cells, task.reach_m)
        if task.needs_camera:
            pads = self.setup.world.pads
            self.origins = [(p.position_ned_m[0], p.position_ned_m[1], p.surface_down_m)
                            for p in pads]
        else:
            self.origins = [(n, e, 0.0) for n, e in cells]
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.action_kind = action
        self.limits = action_limits(self.setup.config)
        self.single_observation_space = task.observation_space()
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.flight: Flight | None = None
        self._release: weakref.finalize | None = None  # closes the flight if we are dropped
        self.vehicles: list[Vehicle | None] = [None] * num_envs
        self.episodes: list[Episode | None] = [None] * num_envs
        self._started_s = np.zeros(num_envs)
        self._steps = np.zeros(num_envs, dtype=np.int64)  # each vehicle's steps this episode
        self._autoreset = np.zeros(num_envs, dtype=bool)
        self._cut_short = ""  # why the last step() or reset() stopped half-way, "" if none did

    def _name(self, i: int) -> str:
        return f"V{i}"

    def _start(self, i: int, options: dict[str, Any] | None = None) -> None:
        """Spawn vehicle ``i`` at a new episode's start (taking out the old one)."""
        assert self.flight is not None
        if self.vehicles[i] is not None:
            self.flight.remove(self._name(i))
        episode = self.tasks[i].start(self.np_random, self.origins[i])
        override_start(episode, options)
        self.tasks[i].prime(episode)
        vehicle = self.flight.spawn(self._name(i), episode.start_ned_m, episode.yaw_rad)
        vehicle.airframe.hover()
        self.vehicles[i], self.episodes[i] = vehicle, episode

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
            raise ConfigError(
                f"the batched vector environment's vehicles fly in one world, seeded by one "
                f"number: seed must be a whole number or None, got {seed!r} (a seed per "
                f"environment: vectorization_mode='sync' or 'async')")
        if isinstance(options, dict) and "reset_mask" in options:
            raise ConfigError(
                f"the batched vector environment offers no partial reset "
                f"(options['reset_mask'], got {options['reset_mask']!r}): a vehicle whose "
                f"episode ended is respawned at the next step (next-step autoreset), and reset() "
                f"starts every vehicle afresh; for partial resets, use vectorization_mode='sync' "
                f"or 'async'")
        if options:
            raise ConfigError(
                f"the batched vector environment takes no reset options (each vehicle starts "
                f"in its own cell, spacing_m apart), got {options!r}; to fix the starts, use "
                f"vectorization_mode='sync' or 'async'")
        if self.closed:  # a new world now would outlive close(), which then does nothing
            raise EnvironmentClosed("reset()")
        super().reset(seed=seed)
        self._close_flight()
        self._cut_short = "the last reset() did not finish"  # until it does (below)
        self.flight = Flight(self.setup, int(self.np_random.integers(2**31)),
                             vision=self.tasks[0].needs_camera)
        self._release = self.flight.closed_with(self)
        for i in range(self.num_envs):
            self._start(i)
        self.flight.step()
        self._started_s[:] = self.flight.time_s
        self._steps[:] = 0
        self._autoreset[:] = False
        self._cut_short = ""
        infos: dict[str, Any] = {}
        for i in range(self.num_envs):
            infos = self._add_info(infos, self._info(i), i)
        return self._observations(), infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        flight = self.flight
        if self.closed:
            raise EnvironmentClosed("step()")
        if flight is None:  # as the single environment, and Gymnasium's own vector ones
            raise ResetNeeded("call reset() before step()")
        try:
            shape: Any = np.shape(actions)
        except ValueError:  # ragged rows
            shape = "ragged"
        if shape != (self.num_envs, 4):  # (no silent reshaping of a flat batch)
            raise InvalidArgument(f"the actions are one row of 4 per vehicle, shape "
                                  f"({self.num_envs}, 4), got {shape}")
        for i, row in enumerate(actions):  # every row checked before any vehicle is touched
            try:
                action_values(row)
            except InvalidArgument as exc:  # which of the num_envs rows it was
                raise InvalidArgument(f"vehicle {i} (row {i} of the actions): {exc}") from None
        if self._cut_short:
            raise ResetNeeded(f"{self._cut_short}: call reset() before step()")
        restarted = self._autoreset.copy()
        try:
            for i in range(self.num_envs):
                if restarted[i]:
                    self._start(i)
                    continue
                vehicle = self.vehicles[i]
                assert vehicle is not None
                if vehicle.alive:
                    apply_action(vehicle, self.action_kind, actions[i], self.limits)
            flight.step()
        except BaseException as exc:  # half flown, unjudged: no step goes on from there
            self._cut_short = f"the last step() was cut short by {type(exc).__name__}"
            raise
        rewards = np.zeros(self.num_envs, dtype=np.float64)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        infos: dict[str, Any] = {}
        for i in range(self.num_envs):
            vehicle, episode = self.vehicles[i], self.episodes[i]
            assert vehicle is not None and episode is not None
            if restarted[i]:
                self._started_s[i] = flight.time_s
                self._steps[i] = 0
            else:
                reward, term = self.tasks[i].judge(vehicle, episode)
                rewards[i], terminated[i] = reward, term
                self._steps[i] += 1
                truncated[i] = not term and flight.seconds_since(self._started_s[i]) >= (
                    self.tasks[i].episode_s - 1e-9)
                if self.max_episode_steps is not None:  # as gymnasium.make's TimeLimit
                    truncated[i] |= self._steps[i] >= self.max_episode_steps
            infos = self._add_info(infos, self._info(i), i)
        self._autoreset = terminated | truncated
        return self._observations(), rewards, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        self._close_flight()

    # -- helpers -----------------------------------------------------------------------------
    def _observations(self) -> Any:
        items = []
        for i in range(self.num_envs):
            vehicle, episode = self.vehicles[i], self.episodes[i]
            assert vehicle is not None and episode is not None
            items.append(self.tasks[i].observe(vehicle, vehicle.airframe.snapshot(), episode))
        out: Any = create_empty_array(self.single_observation_space, self.num_envs)
        return concatenate(self.single_observation_space, items, out)

    def _info(self, i: int) -> dict[str, Any]:
        assert self.flight is not None
        episode = self.episodes[i]
        assert episode is not None
        return {"sim_time_s": self.flight.seconds_since(self._started_s[i]), **episode.info}

    def _close_flight(self) -> None:
        if self._release is not None:
            self._release()  # closes the flight, once
        self._release = None
        self.flight = None
        self.vehicles = [None] * self.num_envs
        self.episodes = [None] * self.num_envs


class HoverVectorEnv(SkeyeVectorEnv):
    """``skeye/Hover-v0`` batched (``gymnasium.make_vec(..., vectorization_mode=
    "vector_entry_point")``)."""

    def __init__(self, num_envs: int = 1, **kwargs: Any) -> None:
        super().__init__(Hover, num_envs, **kwargs)
        EzPickle.__init__(self, num_envs, **kwargs)


class GoToVectorEnv(SkeyeVectorEnv):
    """``skeye/GoTo-v0`` batched."""

    def __init__(self, num_envs: int = 1, **kwargs: Any) -> None:
        super().__init__(GoTo, num_envs, **kwargs)
        EzPickle.__init__(self, num_envs, **kwargs)


class PadLandingVectorEnv(SkeyeVectorEnv):
    """``skeye/PadLanding-v0`` batched: one pad per vehicle."""

    def __init__(self, num_envs: int = 1, *, observation: str = "pad",
                 image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE,
                 start_offset_m: float = PAD_START_OFFSET_M,
                 start_height_m: tuple[float, float] = PAD_START_HEIGHT_M,
                 pad_tolerance_m: float = PAD_TOLERANCE_M, **kwargs: Any) -> None:
        kwargs.setdefault("wind", "random_force")

        def task() -> Task:
            return PadLanding(observation, image_size, start_offset_m, start_height_m,
                              pad_tolerance_m)

        super().__init__(task, num_envs, **kwargs)
        EzPickle.__init__(self, num_envs, observation=observation, image_size=image_size,
                          start_offset_m=start_offset_m, start_height_m=start_height_m,
                          pad_tolerance_m=pad_tolerance_m, **kwargs)
