"""The robots' ray casts (skeye.sim.raycast) answer as MuJoCo's casts over every geom, to the bit.

The caster leaves the robot geoms out of a cast when the ray cannot meet another robot within
its range; these tests cast many rays among vehicles close together and stacked (rays that hit
other vehicles, rays that pass them, rays that end short of them) and compare each answer with
MuJoCo's ``mj_ray`` / ``mj_multiRay`` over the whole model.
"""

from __future__ import annotations

import mujoco
import numpy as np

from skeye.sim.engine import Simulation
from skeye.sim.raycast import ROBOT_GEOM_GROUP, RayCaster
from skeye.sim.world import load_world

POSITIONS = [(0.0, 0.0, -2.0), (0.0, 0.0, -2.4), (0.35, 0.1, -2.1), (2.0, 0.0, -2.0),
             (-1.0, 1.5, -0.5), (0.0, 0.0, -4.0)]


def _sim() -> Simulation:
    sim = Simulation(load_world("pad"), seed=2)
    for i, pos in enumerate(POSITIONS):
        sim.spawn("hummingbird", name=f"R{i}", sink=lambda events: None, location_ned_m=pos)
    sim.step(30)  # MuJoCo's positions now come from its own steps
    return sim


def _bodies(sim: Simulation) -> list[int]:
    return [mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_BODY, f"robot:R{i}")
            for i in range(len(POSITIONS))]


def _directions(rng: np.random.Generator, origin: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Random directions, and directions at (and just beside) every robot's centre."""
    out = [v / np.linalg.norm(v) for v in rng.standard_normal((40, 3))]
    for c in centres:
        w = c - origin
        if np.linalg.norm(w) > 1e-9:
            for jitter in (0.0, 0.05, 0.2):
                v = w / np.linalg.norm(w) + jitter * rng.standard_normal(3)
                out.append(v / np.linalg.norm(v))
    return np.array(out)


def test_robot_geoms_are_in_the_robot_group_and_the_world_in_others() -> None:
    sim = _sim()
    robots = set(_bodies(sim))
    for g in range(sim.model.ngeom):
        on_robot = int(sim.model.body_rootid[sim.model.geom_bodyid[g]]) in robots
        assert (int(sim.model.geom_group[g]) == ROBOT_GEOM_GROUP) == on_robot


def test_single_rays_match_mujoco_over_every_geom() -> None:
    sim = _sim()
    model, data = sim.model, sim.data
    bodies = _bodies(sim)
    caster = RayCaster()
    caster.rebuild(model, data, bodies)
    centres = np.array([data.xpos[b] for b in bodies])
    rng = np.random.default_rng(7)
    geomid = np.zeros(1, dtype=np.int32)
    hit_robot = hit_world = 0
    for body, centre in zip(bodies, centres, strict=True):
        for u in _directions(rng, centre, centres):
            for max_range in (0.4, 1.0, 6.0, 1e9):
                full = mujoco.mj_ray(model, data, centre, u, None, 1, body, geomid)
                mine = caster.cast(*centre, *u, body, max_range)
                if 0.0 <= full <= max_range:
                    assert mine == full and caster.geom == int(geomid[0])
                    if int(model.geom_group[caster.geom]) == ROBOT_GEOM_GROUP:
                        hit_robot += 1
                    else:
                        hit_world += 1
                else:
                    assert not 0.0 <= mine <= max_range
    assert hit_robot > 20 and hit_world > 20  # both kinds of answer were compared


def test_ray_bundles_match_mujoco_over_every_geom() -> None:
    sim = _sim()
    model, data = sim.model, sim.data
    bodies = _bodies(sim)
    caster = RayCaster()
    caster.rebuild(model, data, bodies)
    centres = np.array([data.xpos[b] for b in bodies])
    rng = np.random.default_rng(8)
    hit_robot = hit_world = 0
    for body, centre in zip(bodies, centres, strict=True):
        directions = _directions(rng, centre, centres)
        for start in range(0, len(directions) - 9, 3):  # bundles of 9, like the sonar's cone
            bundle = directions[start:start + 9]
            for max_range in (0.4, 3.0, 6.0, 100.0):
                dist = np.zeros(9)
                geomid = np.zeros(9, dtype=np.int32)
                mujoco.mj_multiRay(model, data, centre, bundle.reshape(-1), None, 1, body,
                                   geomid, dist, None, 9, max_range)
                mine = caster.cast_many(*centre, bundle.reshape(-1).tolist(), 9, body,
                                        max_range)
                for full, geom, got in zip(dist.tolist(), geomid.tolist(), mine, strict=True):
                    if 0.0 <= full <= max_range:
                        assert got == full
                        if int(model.geom_group[geom]) == ROBOT_GEOM_GROUP:
                            hit_robot += 1
                        else:
                            hit_world += 1
                    else:
                        assert not 0.0 <= got <= max_range
    assert hit_robot > 50 and hit_world > 50  # both kinds of answer were compared


def test_a_cone_sees_the_world_beside_other_robots_and_the_robot_below() -> None:
    """A downward cone from a vehicle hovering 2 m beside the others: the world's geoms alone
    give its answer (MuJoCo asked about those only answers the same); a downward cone from a
    vehicle right above another hits that one, as MuJoCo's cast over every geom does."""
    sim = _sim()
    model, data = sim.model, sim.data
    bodies = _bodies(sim)
    caster = RayCaster()
    caster.rebuild(model, data, bodies)
    down = [0.0, 0.0, -1.0] * 3 + [0.3, 0.0, -0.954, -0.3, 0.0, -0.954, 0.0, 0.3, -0.954]
    dist = np.zeros(6)
    geomid = np.zeros(6, dtype=np.int32)
    world_only = np.array([1, 1, 0, 1, 1, 1], dtype=np.uint8)
    far = bodies[3]  # R3 hovers 2 m beside R0 with nothing below it but the ground
    origin = data.xpos[far]
    mujoco.mj_multiRay(model, data, origin, np.array(down), world_only, 1, far, geomid, dist,
                       None, 6, 6.0)
    assert caster.cast_many(*origin, down, 6, far, 6.0) == dist.tolist()
    assert all(int(model.geom_group[g]) != ROBOT_GEOM_GROUP for g in geomid.tolist())
    above = bodies[1]  # R1 hovers 0.4 m right above R0
    got = caster.cast_many(*data.xpos[above], down, 6, above, 6.0)
    mujoco.mj_multiRay(model, data, data.xpos[above], np.array(down), None, 1, above, geomid,
                       dist, None, 6, 6.0)
    assert got == dist.tolist()
    assert int(model.geom_bodyid[int(geomid[0])]) == bodies[0]  # it hit R0
