"""The simulation engine: one MuJoCo world, the robots in it, the clock.

How this works: :class:`Simulation` owns the MuJoCo model and data and is used from exactly one
thread (under the server, the :class:`~skeye.sim.runner.SimulationRunner`'s). The world is
rebuilt from its description whenever a robot comes or goes, carrying every surviving robot's
state over, so spawning is exact and deterministic. Each physics step (1 kHz by default):
robots whose board tick is due read their ground truth, run their board and set their wrench
(``xfrc_applied``, converted to MuJoCo's frame through :mod:`skeye.sim.frames`); MuJoCo steps;
sensors that are due are sampled. The engine writes no wire text: the typed readings
(:mod:`skeye.sim.readings`) of one ``step()`` call go to each robot's sink in one call when it
ends (the control server's sink turns them into protocol lines; an in-process user keeps
them). Sim time is ``steps * timestep`` exactly.

In-process use: :class:`Simulation` can be stepped directly, without the server, the runner or
any socket (benchmarks, tests, learning environments). Spawn a robot with a sink that keeps the
readings (``sink=events.extend``) and call :meth:`Simulation.step`; see :mod:`skeye.sim.readings`.
Under the simulator process, :class:`skeye.sim.runner.SimulationRunner` owns the one thread that
steps it and paces the clock.
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from skeye.sim.gl import GL_BACKEND  # noqa: F401  (before mujoco: picks MUJOCO_GL)

# isort: split
import mujoco
import numpy as np

from skeye.errors import LocalProtocolError, PhysicsError
from skeye.geo import MAX_POSITION_M
from skeye.robots.config import RobotConfig, load_robot_config
from skeye.robots.params import ESTIMATOR_KINDS
from skeye.sim import frames
from skeye.sim.limits import TIMESTEP_RANGE_S
from skeye.sim.raycast import ROBOT_GEOM_GROUP, RayCaster
from skeye.sim.readings import Event, ReadingSink, RobotCrashed, RobotStopped, SensorSample
from skeye.sim.robot import (
    MAX_RATE_RAD_S,
    MAX_SPEED_M_S,
    Robot,
    ScheduledSensor,
    check_state,
)
from skeye.sim.state import BodyState
from skeye.sim.surface_contrast import geom_contrasts
from skeye.sim.wind import WindModel
from skeye.sim.world import WorldDescription, build_mjcf
from skeye.sim.world import start_pose_list as world_start_poses
from skeye.wire.sim_messages import MAX_ROBOT_NAME_CHARS
from skeye.wire.wind import WindSettings, make_settings

log = logging.getLogger(__name__)

FLUSH_EVENTS = 10_000
"""Events queued during one step() call are handed to their sinks at its end, or once this many
wait: a lockstep STEP may ask for 10 000 000 steps, hours of a robot's stream (about 500 bytes
an event, 300 events a sim second for a Hummingbird: 1.5 GB) that would otherwise all wait in
memory for its end. 10 000 events are a few MB, some 30 s of one Hummingbird's stream."""


@dataclass
class _Slot:
    """Where a robot lives in the compiled model."""

    body_id: int
    qpos_adr: int
    qvel_adr: int


class RobotWorldQuery:
    """What a robot's sensors may ask of the world (see skeye.sim.sensors.WorldQuery)."""

    def __init__(self, sim: Simulation, robot_name: str) -> None:
        self._sim = sim
        self._robot = robot_name
        self.geo_origin = sim.world.geo_origin
        self.magnetic_field_ned_ut = np.asarray(sim.world.magnetic_field_ned_ut, dtype=float)
        self.sea_level_pressure_pa = sim.world.sea_level_pressure_pa

    def ray_distance(
        self, origin_ned_m: Any, direction_ned: Any, max_range_m: float
    ) -> float | None:
        return self._sim.ray_distance(self._robot, origin_ned_m, direction_ned, max_range_m)

    def ray_distances(
        self, origin_ned_m: Any, directions_ned: Any, max_range_m: float
    ) -> list[float | None]:
        return self._sim.ray_distances(self._robot, origin_ned_m, directions_ned, max_range_m)

    def ray_surface(
        self, origin_ned_m: Any, direction_ned: Any, max_range_m: float
    ) -> tuple[float | None, float]:
        return self._sim.ray_surface(self._robot, origin_ned_m, direction_ned, max_range_m)


class Simulation:
    """A MuJoCo world with robots. Not thread-safe: use it from the runner's thread."""

    def __init__(
        self,
        world: WorldDescription,
        *,
        seed: int = 0,
        timestep_s: float = 0.001,
        wind: WindSettings | None = None,
        offscreen_size: tuple[int, int] = (800, 600),
        robot_dirs: tuple[Path, ...] = (),
        estimator: str | None = None,
    ) -> None:
        """``estimator``: every robot's board estimator ("onboard" or "truth"), overriding the
        robot files' ``[estimator] kind`` (``skeye sim --estimator``); None keeps them."""
        if estimator is not None and estimator not in ESTIMATOR_KINDS:
            raise LocalProtocolError(
                f"estimator must be one of {list(ESTIMATOR_KINDS)}, got {estimator!r}"
            )
        self.estimator = estimator
        low, high = TIMESTEP_RANGE_S
        if not (math.isfinite(timestep_s) and low <= timestep_s <= high):
            raise LocalProtocolError(
                f"physics step must be in [{low:g}, {high:g}] s, got {timestep_s}")
        self.world = world
        self.seed = seed
        self.dt = timestep_s
        self.steps = 0
        self.offscreen_size = offscreen_size
        self.robot_dirs = tuple(Path(p) for p in robot_dirs)
        self.robots: dict[str, Robot] = {}
        self._spawned = 0
        self._resets = 0
        self._slots: dict[str, _Slot] = {}
        # MuJoCo's velocities (qvel, as a list) at the last step a board ticked: what two
        # robots that touch now met at (see _closing_speed); None after a rebuild or a start.
        self._tick_qvel: list[float] | None = None
        self._queries: dict[str, RobotWorldQuery] = {}
        self.wind = WindModel(wind or make_settings("none"), np.random.default_rng([seed, 7]))
        self.step_hooks: list[Callable[[Simulation], None]] = []
        # Each step hook names, through an event source, the next step it needs to see.
        self.event_sources: list[Callable[[Simulation], int]] = []
        self._pending: dict[int, tuple[Robot, list[Event]]] = {}
        self._pending_events = 0
        self._periods: list[int] = []
        self.rebuild_hooks: list[Callable[[Simulation], None]] = []
        self.xml_extras: list[Callable[[Robot], str]] = []
        self._rays = RayCaster()
        # RMS texture contrast of each geom, by id (skeye.sim.surface_contrast), for flow sensors.
        self._contrast_by_name = geom_contrasts(world)
        self._geom_contrast: list[float] = []
        self.model: Any = None
        self.data: Any = None
        # Views of MjData's arrays (each attribute access on MjData makes a new view).
        self._qpos: Any = None
        self._qvel: Any = None
        self._qacc: Any = None
        self._xfrc: Any = None
        self._xfrc_flat: memoryview[float] = memoryview(b"").cast("d")
        self._rebuild()

    # -- model ---------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        return self.steps * self.dt

    def _robot_xml(self, robot: Robot) -> str:
        a = robot.config.airframe
        pos = frames.ned_to_mj(robot.spawn_pos_ned_m)
        quat = frames.quat_ned_to_mj(frames.euler_to_quat(*robot.spawn_rpy_rad))
        ixx, iyy, izz = a.inertia_kg_m2
        bx, by, bz = (s / 2 for s in a.body_size_m)
        arm, rr, gear = a.arm_m, a.rotor_radius_m, a.gear_height_m
        n = f"robot:{robot.name}"
        parts = [
            f'<body name="{n}" pos="{pos[0]:.9g} {pos[1]:.9g} {pos[2]:.9g}" '
            f'quat="{quat[0]:.9g} {quat[1]:.9g} {quat[2]:.9g} {quat[3]:.9g}">',
            f'<freejoint name="{n}:joint"/>',
            f'<inertial pos="0 0 0" mass="{a.mass_kg:.9g}" '
            f'diaginertia="{ixx:.9g} {iyy:.9g} {izz:.9g}"/>',
            f'<geom name="{n}:hull" type="box" size="{bx:.6g} {by:.6g} {bz:.6g}" '
            f'rgba="0.15 0.15 0.18 1" mass="0" condim="3" group="{ROBOT_GEOM_GROUP}"/>',
        ]
        for i, (ux, uy) in enumerate(
            ((1, 0), (0, -1), (-1, 0), (0, 1))
        ):  # FLU: front,right,back,left
            x, y = ux * arm, uy * arm
            parts.append(
                f'<geom name="{n}:arm{i}" type="capsule" fromto="0 0 0 {x:.6g} {y:.6g} 0" '
                f'size="0.008" rgba="0.2 0.2 0.25 1" mass="0" contype="0" conaffinity="0" '
                f'group="{ROBOT_GEOM_GROUP}"/>'
            )
            color = "0.9 0.3 0.2 0.6" if i == 0 else "0.3 0.3 0.35 0.6"
            parts.append(
                f'<geom name="{n}:rotor{i}" type="cylinder" pos="{x:.6g} {y:.6g} 0.02" '
                f'size="{rr:.6g} 0.003" rgba="{color}" mass="0" contype="0" conaffinity="0" '
                f'group="{ROBOT_GEOM_GROUP}"/>'
            )
        for gx, gy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            parts.append(
                f'<geom name="{n}:gear{gx}{gy}" type="sphere" size="0.012" '
                f'pos="{gx * bx:.6g} {gy * by:.6g} {-(gear - 0.012):.6g}" rgba="0.1 0.1 0.1 1" '
                f'mass="0" friction="1.0 0.01 0.001" group="{ROBOT_GEOM_GROUP}"/>'
            )
        parts.extend(self.robot_xml_extras(robot))
        parts.append("</body>")
        return "\n".join(parts)

    def robot_xml_extras(self, robot: Robot) -> list[str]:
        """Extra MJCF inside a robot's body (cameras add themselves here)."""
        return [extra(robot) for extra in self.xml_extras]

    def _rebuild(self) -> None:
        saved: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        if self.data is not None:
            for name, slot in self._slots.items():
                if name in self.robots:
                    saved[name] = (
                        self.data.qpos[slot.qpos_adr : slot.qpos_adr + 7].copy(),
                        self.data.qvel[slot.qvel_adr : slot.qvel_adr + 6].copy(),
                        self.data.xfrc_applied[slot.body_id].copy(),
                    )
        robots_xml = "\n".join(self._robot_xml(r) for r in self.robots.values())
        xml, assets = build_mjcf(
            self.world,
            robots_xml=robots_xml,
            timestep_s=self.dt,
            offscreen_size=self.offscreen_size,
        )
        self.model = mujoco.MjModel.from_xml_string(xml, assets)
        self.data = mujoco.MjData(self.model)
        contrast_by_name = self._contrast_by_name
        self._geom_contrast = [
            contrast_by_name.get(
                mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_GEOM, i) or "", 0.0
            )
            for i in range(self.model.ngeom)
        ]
        self.data.time = self.time_s
        d = self.data
        self._qpos, self._qvel, self._qacc, self._xfrc = d.qpos, d.qvel, d.qacc, d.xfrc_applied
        self._tick_qvel = None  # its addresses are the old model's
        self._xfrc_flat = memoryview(d.xfrc_applied).cast("B").cast("d")
        self._slots = {}
        for name in self.robots:
            body_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, f"robot:{name}")
            joint_id = self.model.body_jntadr[body_id]
            slot = _Slot(
                body_id, int(self.model.jnt_qposadr[joint_id]), int(self.model.jnt_dofadr[joint_id])
            )
            self._slots[name] = slot
            if name in saved:
                # The wrench too: the board sets it only on its ticks.
                qpos, qvel, wrench = saved[name]
                self.data.qpos[slot.qpos_adr : slot.qpos_adr + 7] = qpos
                self.data.qvel[slot.qvel_adr : slot.qvel_adr + 6] = qvel
                self.data.xfrc_applied[body_id] = wrench
        mujoco.mj_forward(self.model, self.data)
        self._rays.rebuild(self.model, self.data,
                           [slot.body_id for slot in self._slots.values()])
        self._update_schedule()
        for hook in self.rebuild_hooks:
            hook(self)

    # -- robots --------------------------------------------------------------------------
    def spawn(
        self,
        class_name: str,
        *,
        sink: ReadingSink,
        name: str | None = None,
        location_ned_m: tuple[float, float, float] | None = None,
        rotation_rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0),
        start: str | None = None,
        config: RobotConfig | None = None,
    ) -> Robot:
        """Add a robot. On a start pose (or a location at or below the ground) it stands on its
        landing gear; a location in the air spawns it hovering, motors running. A location
        below the ground (down > 0: every world's ground plane is at down 0) stands it on the
        surface straight above (the ground, or what stands on it there, such as a pad): it is
        never spawned inside the ground, which would launch it. ``sink`` takes the robot's
        readings (:mod:`skeye.sim.readings`) after each :meth:`step` call."""
        config = config or load_robot_config(class_name, self.robot_dirs, allow_paths=False)
        number = self._spawned + 1  # counted once spawned: a refused INIT takes no number
        while not name and f"R{number}" in self.robots:  # a client named its robot so
            number += 1
        name = name or f"R{number}"
        if name in self.robots:
            raise LocalProtocolError(f"a robot named {name!r} already exists")
        if len(name) > MAX_ROBOT_NAME_CHARS:
            raise LocalProtocolError(f"robot name of {len(name)} characters: at most "
                                     f"{MAX_ROBOT_NAME_CHARS} characters")
        if not name.replace("_", "").replace("-", "").isalnum():
            raise LocalProtocolError(f"robot name {name!r} may hold only letters, digits, - and _")
        pos, rpy, airborne = self._spawn_pose(config, start, location_ned_m, rotation_rpy_rad)
        rng = np.random.default_rng([self.seed, 1000 + number])
        robot = Robot(
            name,
            config,
            physics_step_s=self.dt,
            rng=rng,
            sink=sink,
            spawn_pos_ned_m=(pos[0], pos[1], pos[2]),
            spawn_rpy_rad=(rpy[0], rpy[1], rpy[2]),
            airborne=airborne,
            estimator=self.estimator,
            declination_rad=self._declination_rad(),
        )
        robot.flight.landed_since_s = self.time_s
        for cam in robot.cameras:  # its pixel noise and latency jitter: this seed, this spawn
            cam.noise_stream = (self.seed, number)
        self.robots[name] = robot
        self._queries[name] = RobotWorldQuery(self, name)
        try:
            self._rebuild()
            self._refuse_occupied(name, pos, self.data)
        except Exception:
            del self.robots[name]
            del self._queries[name]
            self._rebuild()
            raise
        self._spawned = number
        self._start_robot(name, robot, pos, airborne)
        return robot

    def _spawn_pose(
        self,
        config: RobotConfig,
        start: str | None,
        location_ned_m: tuple[float, float, float] | None,
        rotation_rpy_rad: tuple[float, float, float],
        exclude_body: int = -1,
    ) -> tuple[tuple[float, float, float], tuple[float, float, float], bool]:
        """Where a robot of ``config`` spawns: (position NED, roll/pitch/yaw, airborne). On a
        start pose, or a location at or below the ground (``exclude_body``: the robot's own
        body, when it is already in the world), it stands on its gear."""
        gear = config.airframe.gear_height_m
        if start is not None:
            poses = {p.lower(): v for p, v in self.world.start_poses.items()}
            if start.lower() not in poses:
                raise LocalProtocolError(
                    f"unknown start pose {start!r}; known: {', '.join(self.world.start_poses)}"
                )
            pose = poses[start.lower()]
            gn, ge, gd = (float(v) for v in pose.position_ned_m)
            rr, rp, ry = (float(v) for v in pose.rpy_rad)
            return (gn, ge, gd - gear), (rr, rp, ry), False
        if location_ned_m is None:
            raise LocalProtocolError("INIT needs {Location x,y,z} or {Start name}")
        ln, le, ld = (float(v) for v in location_ned_m)
        rr, rp, ry = (float(v) for v in rotation_rpy_rad)
        if ld > 0.0:  # below the ground: onto the surface above, 1 cm over it
            ld = self._surface_down(ln, le) - 0.01
        below = self._cast(ln, le, ld, 0.0, 0.0, 1.0, exclude_body, math.inf)
        if below is not None and below < gear + 0.02:
            return (ln, le, ld + below - gear), (rr, rp, ry), False
        return (ln, le, ld), (rr, rp, ry), True

    def _refuse_occupied(self, name: str, pos: tuple[float, float, float], data: Any) -> None:
        """Refuse to put robot ``name`` at ``pos`` (NED) where another robot stands: where a
        part of it would be inside a part of another robot, the two would be spawned inside
        each other. USARSim's spawn fails there too (Unreal's ``Spawn`` returns None where
        the new actor's collision meets another's). ``data``: MuJoCo's data with the robot at
        ``pos``, its kinematics computed.

        The robots' bounding spheres (:class:`~skeye.sim.raycast.RayCaster`'s: the body
        position and the farthest reach of its geoms, the rotor tips for a quadrotor) find the
        robots that may be in the way; of those, every pair of geoms (hull, arms, rotor disks,
        landing gear) is asked MuJoCo's signed distance (``mj_geomDistance``): one below 0 is
        two parts inside each other. Robots merely near (stacked 0.4 m apart, rotor disks
        side by side) are no obstacle: their spheres overlap, their parts do not.

        Raises:
            LocalProtocolError: naming the nearest robot in the way, its distance (centre to
                centre) and the two parts found inside each other.
        """
        rays, model = self._rays, self.model
        body = self._slots[name].body_id
        radius = rays.bounding_radius(body)
        px, py, pz = (float(v) for v in data.xpos[body])
        roots = model.geom_bodyid.tolist()
        root_of = model.body_rootid.tolist()
        mine = [g for g in range(model.ngeom) if root_of[roots[g]] == body]
        found: tuple[float, str, int, int] | None = None
        for other, slot in self._slots.items():
            if other == name:
                continue
            ox, oy, oz = (float(v) for v in data.xpos[slot.body_id])
            dist = math.sqrt((ox - px) ** 2 + (oy - py) ** 2 + (oz - pz) ** 2)
            if not dist < radius + rays.bounding_radius(slot.body_id):
                continue  # too far for any part to meet (an unbounded sphere: checked)
            if found is not None and dist >= found[0]:
                continue
            theirs = [g for g in range(model.ngeom) if root_of[roots[g]] == slot.body_id]
            clash = next(((g1, g2) for g1 in mine for g2 in theirs
                          if mujoco.mj_geomDistance(model, data, g1, g2, 0.0, None) < 0.0),
                         None)
            if clash is not None:
                found = (dist, other, clash[0], clash[1])
        if found is not None:
            dist, other, g1, g2 = found
            n, e, d = pos

            def part(geom: int) -> str:
                return (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, geom) or
                        f"geom {geom}").rpartition(":")[2]

            raise LocalProtocolError(
                f"{n:g},{e:g},{d:g} is taken: robot {other} is {dist:.2f} m away there "
                f"(centre to centre), and this robot's {part(g1)} would be inside its "
                f"{part(g2)}; choose a place clear of it")

    def _start_robot(self, name: str, robot: Robot, pos: tuple[float, float, float],
                     airborne: bool) -> None:
        """A robot just placed at its spawn pose: still, its board calibrated, its first tick."""
        slot = self._slots[name]
        if airborne:
            robot.controller.reset(hold_altitude_m=-pos[2])
        self.data.qvel[slot.qvel_adr : slot.qvel_adr + 6] = 0.0
        self._tick_qvel = None  # its velocity is set to rest: no earlier flight to meet with
        # The board's power-up calibration. In the air the vehicle stands for one that took off
        # earlier, so its board calibrated on the ground before; its readings at the spawn
        # instant (no motion yet) give the gyro bias, while the accelerometer, free of any
        # force there, says nothing and the spawn attitude is kept.
        robot.power_up(self.body_state(name), self._queries[name])
        # The board's first tick now, so the wrench is set from the first step on.
        self._board_tick(name, robot, self.body_state(name), self._bodies_in_contact(),
                         self._qvel.tolist())

    def reset_robot(
        self,
        name: str,
        *,
        start: str | None = None,
        location_ned_m: tuple[float, float, float] | None = None,
        rotation_rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> Robot:
        """Respawn a robot where it was spawned (or at ``start`` / ``location_ned_m``): a fresh
        board (motors, battery, estimator, crash detector) and a still body at that pose. It
        keeps its name, sink and cameras (their ids and frame numbers go on), so its clients
        carry on. The world is not rebuilt.

        Raises:
            LocalProtocolError: no such robot, or an unknown start pose.
        """
        old = self.robots.get(name)
        if old is None:
            raise LocalProtocolError(f"no robot named {name!r}")
        slot = self._slots[name]
        if start is None and location_ned_m is None:
            pos, rpy, airborne = old.spawn_pos_ned_m, old.spawn_rpy_rad, old.spawn_airborne
        else:
            pos, rpy, airborne = self._spawn_pose(old.config, start, location_ned_m,
                                                  rotation_rpy_rad, slot.body_id)
        # Its parts at the new pose, on a copy: a refused RESET leaves the world untouched.
        there = copy.copy(self.data)
        a = slot.qpos_adr
        there.qpos[a : a + 3] = frames.ned_to_mj(pos)
        there.qpos[a + 3 : a + 7] = frames.quat_ned_to_mj(frames.euler_to_quat(*rpy))
        mujoco.mj_kinematics(self.model, there)
        self._refuse_occupied(name, pos, there)
        self._resets += 1
        robot = Robot(
            name,
            old.config,
            physics_step_s=self.dt,
            rng=np.random.default_rng([self.seed, 5000 + self._resets]),
            sink=old.sink,
            spawn_pos_ned_m=pos,
            spawn_rpy_rad=rpy,
            airborne=airborne,
            estimator=self.estimator,
            declination_rad=self._declination_rad(),
        )
        robot.cameras = old.cameras
        robot.flight.landed_since_s = self.time_s
        self.robots[name] = robot
        self._update_schedule()  # the new board's sensors fall due on the engine's schedule
        d = self.data
        a = slot.qpos_adr
        d.qpos[a : a + 3] = frames.ned_to_mj(pos)
        d.qpos[a + 3 : a + 7] = frames.quat_ned_to_mj(frames.euler_to_quat(*rpy))
        d.qacc[slot.qvel_adr : slot.qvel_adr + 6] = 0.0
        d.xfrc_applied[slot.body_id] = 0.0
        mujoco.mj_forward(self.model, d)
        self._rays.moved()  # the robot jumped: the ray casts read the positions again
        self._start_robot(name, robot, pos, airborne)
        log.info("robot %s reset at %s (%s)", name, tuple(round(v, 3) for v in pos),
                 "in the air" if airborne else "on the ground")
        return robot

    def _declination_rad(self) -> float:
        """The world field's declination: what the board is configured with (a real one takes
        it from a table by position, as ArduPilot's COMPASS_AUTODEC does)."""
        fn, fe, _ = (float(v) for v in self.world.magnetic_field_ned_ut)
        return math.atan2(fe, fn) if fn * fn + fe * fe > 0.0 else 0.0

    def remove(self, name: str) -> None:
        if self.robots.pop(name, None) is not None:
            self._queries.pop(name, None)
            self._rebuild()

    def _surface_down(self, north_m: float, east_m: float) -> float:
        """NED down of the surface at a point: the ground (down 0) or, where something stands
        on the ground there (a pad, a box), its top. Found from below, where only what stands
        on the ground is in the way: a ray cast up from under the ground meets that thing's
        underside (the ground plane is not hit from below); a ray cast down from over its
        bounding sphere then meets its top."""
        start_down = 1.0  # below every collider's underside (a pad's reaches 2 cm down)
        hit = self._cast(north_m, east_m, start_down, 0.0, 0.0, -1.0, -1, math.inf)
        if hit is None or start_down - hit < -0.05:
            return 0.0  # nothing there, or only something well above the ground (a ceiling)
        geom = self._rays.geom
        top_z = float(self.data.geom_xpos[geom][2]) + float(self.model.geom_rbound[geom])
        above_down = -(top_z + 0.05)
        top = self._cast(north_m, east_m, above_down, 0.0, 0.0, 1.0, -1, math.inf)
        return 0.0 if top is None else above_down + top

    def ray_distance(
        self, robot_name: str, origin_ned_m: Any, direction_ned: Any, max_range_m: float
    ) -> float | None:
        """First hit along a ray from a NED point, ignoring the robot itself."""
        ox, oy, oz = origin_ned_m
        dx, dy, dz = direction_ned
        return self._cast(float(ox), float(oy), float(oz), float(dx), float(dy), float(dz),
                          self._slots[robot_name].body_id, max_range_m)

    def ray_surface(
        self, robot_name: str, origin_ned_m: Any, direction_ned: Any, max_range_m: float
    ) -> tuple[float | None, float]:
        """:meth:`ray_distance` and the texture contrast of the surface hit (0 when none)."""
        dist = self.ray_distance(robot_name, origin_ned_m, direction_ned, max_range_m)
        if dist is None:
            return None, 0.0
        return dist, self._geom_contrast[self._rays.geom]

    def _cast(self, north_m: float, east_m: float, down_m: float, dn: float, de: float,
              dd: float, exclude_body: int, max_range_m: float) -> float | None:
        """One MuJoCo ray from a NED point along a NED direction (metres out); None when
        nothing is hit within range. The geom hit is ``self._rays.geom``."""
        norm = math.sqrt(dn * dn + de * de + dd * dd)
        if norm == 0.0:
            return None
        dist = self._rays.cast(north_m, -east_m, -down_m, dn / norm, -de / norm, -dd / norm,
                               exclude_body, max_range_m)
        if dist < 0 or dist > max_range_m:
            return None
        return dist

    def ray_distances(
        self, robot_name: str, origin_ned_m: Any, directions_ned: Any, max_range_m: float
    ) -> list[float | None]:
        """:meth:`ray_distance` for several rays from one point, in one MuJoCo call."""
        n = len(directions_ned)
        if n == 0:
            return []
        rays: list[float] = []
        for direction in directions_ned:
            dx, dy, dz = direction
            x, y, z = float(dx), -float(dy), -float(dz)
            norm = math.sqrt(x * x + y * y + z * z)
            if norm == 0.0:
                raise LocalProtocolError("a ray direction must not be zero")
            rays.append(x / norm)
            rays.append(y / norm)
            rays.append(z / norm)
        ox, oy, oz = origin_ned_m
        dist = self._rays.cast_many(float(ox), -float(oy), -float(oz), rays, n,
                                    self._slots[robot_name].body_id, max_range_m)
        return [d if 0.0 <= d <= max_range_m else None for d in dist]

    def body_state(self, name: str) -> BodyState:
        """Ground truth of a robot in NED/FRD."""
        slot = self._slots[name]
        d = self.data
        a, b = slot.qpos_adr, slot.qvel_adr
        return frames.free_joint_state(
            self.steps * self.dt,
            d.qpos[a : a + 7].tolist(),
            d.qvel[b : b + 6].tolist(),
            d.qacc[b : b + 3].tolist(),
            self.robots[name].rotors.speed_rad_s,
        )

    def _bodies_in_contact(self) -> dict[int, set[int]]:
        """The bodies that touch something now (MuJoCo's contacts of the last step), each with
        the root bodies of what it touches (0, the world body, for the ground and what stands
        on it; a robot's own body for a robot)."""
        d, m = self.data, self.model
        bodies: dict[int, set[int]] = {}
        for i in range(d.ncon):
            c = d.contact[i]
            b1, b2 = int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])
            bodies.setdefault(b1, set()).add(int(m.body_rootid[b2]))
            bodies.setdefault(b2, set()).add(int(m.body_rootid[b1]))
        return bodies

    def _closing_speed(self, name: str, touched: set[int], qvel: list[float],
                       before: list[float] | None) -> float:
        """The fastest robot ``name`` meets another robot it touches now (m/s): the speed of
        the one relative to the other, now (``qvel``) and at the last step a board ticked
        before (``before``, None when there is none since the last rebuild or start), the
        larger. 0 when it touches no robot: the ground and what stands on it are still, and the
        vehicle's own speed is its speed on them."""
        if len(touched) == 1 and 0 in touched:
            return 0.0  # the world alone (the usual contact: standing on the ground)
        a = self._slots[name].qvel_adr
        fastest = 0.0
        for other_name, other in self._slots.items():
            if other_name == name or other.body_id not in touched:
                continue
            o = other.qvel_adr
            for v in (qvel, before):
                if v is not None:
                    dx, dy, dz = v[a] - v[o], v[a + 1] - v[o + 1], v[a + 2] - v[o + 2]
                    fastest = max(fastest, math.sqrt(dx * dx + dy * dy + dz * dz))
        return fastest

    # -- stepping ------------------------------------------------------------------------
    def step(self, count: int = 1, stop: Callable[[], bool] | None = None) -> None:
        """Advance ``count`` physics steps, emitting every message those steps produce.

        Steps after which nothing is due but physics (no board tick, no sensor, status or
        camera) run as one ``mj_step(nstep=k)`` call: the same arithmetic, without Python in
        the loop. The lines the steps produce go to each client in one write at the end, or,
        in a long call, each time ``FLUSH_EVENTS`` of them wait (what waits in memory is
        bounded however many steps are asked for). ``stop``, asked before each such call,
        ends the stepping early when it returns True (the control server's: the client that
        asked for a lockstep STEP went away); the steps taken so far stand, and their lines go
        out as ever.
        """
        target = self.steps + count
        try:
            self._check_states()
            while self.steps < target:
                if stop is not None and stop():
                    break
                if self._pending_events >= FLUSH_EVENTS:
                    self.flush()
                # The quiet steps and the one after which something is due: one MuJoCo call.
                self._step_to_event(min(self._next_event_step(), target - 1) - self.steps + 1)
        finally:
            self._rays.moved()  # whoever holds the data next may move it
            self.flush()

    def _check_states(self) -> None:
        """Stop every robot whose state went bad between steps (a task can write MuJoCo's
        state), before MuJoCo sees it: its own NaN guard would reset the whole world.

        The same test as :func:`check_state` on the robot's :class:`BodyState`, on MuJoCo's
        joint values directly (the frame change only flips signs, which the bounds ignore)."""
        qpos, qvel = self._qpos.tolist(), self._qvel.tolist()
        for name in list(self.robots):
            slot = self._slots[name]
            a, b = slot.qpos_adr, slot.qvel_adr
            px, py, pz = qpos[a], qpos[a + 1], qpos[a + 2]
            vx, vy, vz = qvel[b], qvel[b + 1], qvel[b + 2]
            wx, wy, wz = qvel[b + 3], qvel[b + 4], qvel[b + 5]
            total = px + py + pz + vx + vy + vz + wx + wy + wz
            if (math.isfinite(total) and max(max(abs(px), abs(py)), abs(pz)) <= MAX_POSITION_M
                    and vx * vx + vy * vy + vz * vz <= MAX_SPEED_M_S**2
                    and wx * wx + wy * wy + wz * wz <= MAX_RATE_RAD_S**2):
                continue
            try:
                check_state(name, self.body_state(name))
            except PhysicsError as exc:
                self._park(name)
                self._stop_robot(name, str(exc))

    def _update_schedule(self) -> None:
        """Collect the distinct periods (in steps) at which robots have work: board ticks,
        sensors, status. Called whenever robots come or go."""
        periods: set[int] = set()
        for robot in self.robots.values():
            periods.add(robot.board_decimation)
            periods.add(robot.status_period_steps)
            periods.update(s.period_steps for s in robot.sensors)
            # The robot's own sensing periods: between their multiples an event has nothing
            # but the board for it (see _step_to_event).
            sensing = {robot.status_period_steps}
            sensing.update(s.period_steps for s in robot.sensors)
            sensing.update(s.period_steps for s in robot.board_sensors)
            robot.sensing_periods = sorted(sensing)
            robot.next_sensing_step = 0
        self._periods = sorted(periods)

    def _next_event_step(self) -> int:
        """The first step index >= now whose :meth:`_step_to_event` has work to do after it.

        Work that falls due when the step count reaches a multiple of ``p`` is done at the end
        of the step with index ``k`` where ``(k + 1) % p == 0``.
        """
        now = self.steps
        after = now + 1
        best = now + 1_000_000
        for p in self._periods:
            k = -(-after // p) * p - 1
            if k < best:
                best = k
                if k == now:
                    return now
        for source in self.event_sources:
            k = source(self)
            if k < best:
                best = k
        return best if best > now else now

    def emit(self, robot: Robot, events: list[Event]) -> None:
        """Queue events for a robot's sink; handed over when the current step() call ends (or
        ``FLUSH_EVENTS`` wait)."""
        self._pending_events += len(events)
        entry = self._pending.get(id(robot))
        if entry is None:
            self._pending[id(robot)] = (robot, list(events))
        else:
            entry[1].extend(events)

    def flush(self) -> None:
        """Hand every robot's queued events to its sink (one call per robot).

        A robot whose events its sink cannot encode (a reading that is not a finite number: a
        robot file's sensor noise of 1e308 made a compass read -inf) is stopped, and the
        other robots' events go out: the encoder's LocalProtocolError used to end the flush,
        so the robots after it lost their lines and every STEP of every client answered ERR
        from then on.
        """
        pending, self._pending = self._pending, {}
        self._pending_events = 0
        unsendable: list[tuple[str, str]] = []
        for robot, events in pending.values():
            if events:
                try:
                    robot.sink(events)
                except LocalProtocolError as exc:
                    unsendable.append((robot.name, str(exc)))
        for name, reason in unsendable:
            self._stop_robot(name, f"a reading could not be sent: {reason}")
        if unsendable:
            self.flush()  # the stops' own news

    def _step_to_event(self, count: int = 1) -> None:
        """``count`` physics steps, then whatever falls due at the new step count, robot by
        robot: sensors are sampled (and status reported) from the state now, then the board
        ticks on that same state and sets the wrench MuJoCo applies until its next tick."""
        mujoco.mj_step(self.model, self.data, count)
        self._rays.moved()
        self.steps = step = self.steps + count
        failed: list[tuple[str, str]] = []
        wind_advanced = False
        joints: tuple[list[float], list[float], list[float]] | None = None
        contacts: dict[int, set[int]] | None = None  # read once, for all robots that tick
        t = step * self.dt
        for name, robot in self.robots.items():
            board = step % robot.board_decimation == 0
            due: list[ScheduledSensor] = []
            hidden: list[ScheduledSensor] = []
            status = False
            if step >= robot.next_sensing_step:  # else no sensor nor status is due now
                due = [sched for sched in robot.sensors if step % sched.period_steps == 0]
                hidden = [sched for sched in robot.board_sensors
                          if step % sched.period_steps == 0]
                status = step % robot.status_period_steps == 0
                following = step + 1_000_000
                for p in robot.sensing_periods:
                    k = (step // p + 1) * p
                    if k < following:
                        following = k
                robot.next_sensing_step = following
            if not (board or due or status or hidden):
                continue
            if joints is None:  # one read of MuJoCo's arrays for all robots this step
                joints = (self._qpos.tolist(), self._qvel.tolist(), self._qacc.tolist())
            slot = self._slots[name]
            state = frames.free_joint_state(t, joints[0], joints[1], joints[2],
                                            robot.rotors.speed_rad_s, slot.qpos_adr,
                                            slot.qvel_adr)
            # One robot's arithmetic fault stops that robot, not the engine: a robot file's
            # [estimator] attitude_kp = 1e308 drove its board's attitude filter to NaN, and a
            # ZeroDivisionError out of its next gyro reading ended the simulation for every
            # client ("the simulation engine failed").
            if due or status or hidden:
                try:
                    self._emit_readings(robot, state, due, status, hidden)
                except ArithmeticError as exc:
                    failed.append((name, f"its board failed: {type(exc).__name__}: {exc}"))
                    self._park(name)
                    continue
            if board:
                if not wind_advanced:
                    self.wind.advance(state.time_s, robot.tick_s)
                    wind_advanced = True
                if contacts is None:
                    contacts = self._bodies_in_contact()
                try:
                    self._board_tick(name, robot, state, contacts, joints[1])
                except PhysicsError as exc:
                    failed.append((name, str(exc)))
                    self._park(name)
                except ArithmeticError as exc:
                    failed.append((name, f"its board failed: {type(exc).__name__}: {exc}"))
                    self._park(name)
        if contacts is not None and joints is not None:  # a board ticked: its velocities
            self._tick_qvel = joints[1]
        for name, reason in failed:
            self._stop_robot(name, reason)
        for hook in self.step_hooks:
            hook(self)

    def _board_tick(self, name: str, robot: Robot, state: BodyState,
                    contacts: dict[int, set[int]], qvel: list[float]) -> None:
        """Run one robot's board on ``state`` and set the wrench on its body (``contacts``:
        the bodies touching something now, with what they touch; ``qvel``: MuJoCo's
        velocities now, for :meth:`_closing_speed`)."""
        check_state(name, state)
        slot = self._slots[name]
        touched = contacts.get(slot.body_id)
        closing = (0.0 if touched is None
                   else self._closing_speed(name, touched, qvel, self._tick_qvel))
        if self.steps % (10 * robot.board_decimation) == 0 or robot.ground_distance_m is None:
            pn, pe, pd = state.pos_ned_m
            ground = self._cast(pn, pe, pd, 0.0, 0.0, 1.0, slot.body_id, 10.0)
        else:
            ground = robot.ground_distance_m
        force, torque = robot.board_tick(
            state, ground, touched is not None, self.wind.air_velocity_ned(), closing
        )
        wf = self.wind.force_ned()
        frames.put_ned_wrench_mj(
            self._xfrc_flat, 6 * slot.body_id,
            (force[0] + wf[0], force[1] + wf[1], force[2] + wf[2]), torque,
        )
        if robot.crash_news is not None:
            cause = robot.crash_news
            robot.crash_news = None
            log.warning("robot %s crashed at %.3f s: %s", name, state.time_s, cause)
            self.emit(robot, [RobotCrashed(name, state.time_s, cause)])

    def _park(self, name: str) -> None:
        """Park a failed body far above the world with finite state and no force, so MuJoCo's
        own NaN guard (which resets the whole MjData) never fires for one robot's fault."""
        slot = self._slots[name]
        d = self.data
        a, b = slot.qpos_adr, slot.qvel_adr
        d.qpos[a : a + 7] = (0.0, 0.0, 1.0e4, 1.0, 0.0, 0.0, 0.0)
        d.qvel[b : b + 6] = 0.0
        d.qacc[b : b + 6] = 0.0
        d.xfrc_applied[slot.body_id] = 0.0

    def _stop_robot(self, name: str, reason: str) -> None:
        robot = self.robots.get(name)
        if robot is None:
            return
        log.error("stopping robot %s: %s", name, reason)
        robot.flight.failed = reason
        robot.flight.armed = False
        self.emit(robot, [RobotStopped(name, "PHYSICS", f"robot stopped: {reason}")])
        self.remove(name)

    def _emit_readings(
        self,
        robot: Robot,
        state: BodyState,
        due: list[ScheduledSensor],
        status: bool,
        hidden: list[ScheduledSensor],
    ) -> None:
        """Readings of the due sensors, then the status if due, for one robot; the board's
        sensors' readings also go to its estimator (``hidden``: the board's only, unstreamed)."""
        events: list[Event] = []
        query = self._queries[robot.name]
        for sched in hidden:
            robot.observe(sched.read(state, query))
        # The board's sensors first, so an INS reading at this instant reports the estimate
        # the board flies on now; the events keep the sensors' order.
        samples: list[SensorSample | None] = [None] * len(due)
        for board_first in (True, False):
            for i in range(len(due)):
                sched = due[i]
                if sched.board != board_first:
                    continue
                if sched.type_name == "Battery":
                    sched.sensor.update_battery(
                        robot.battery.voltage_v,
                        robot.battery.current_a,
                        robot.battery.state_of_charge,
                    )
                reading = sched.read(state, query)
                if board_first:
                    robot.observe(reading)
                samples[i] = SensorSample(sched.type_name, sched.name, reading)
        for done in samples:
            if done is not None:
                events.append(done)
        if status:
            events.append(robot.status(state.time_s))
        self.emit(robot, events)

    def set_wind(self, settings: WindSettings) -> None:
        self.wind = WindModel(settings, np.random.default_rng([self.seed, 7, self.steps]))

    def start_poses(
        self,
    ) -> list[tuple[str, tuple[float, float, float], tuple[float, float, float]]]:
        return world_start_poses(self.world)
