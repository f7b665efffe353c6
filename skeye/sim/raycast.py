"""Ray casts for the robots' range sensors; a bundle of rays skips the robots it cannot reach.

Why: MuJoCo's ``mj_multiRay`` (the sonar's cone: nine rays from one point) first works out the
angular extent, seen from the rays' origin, of every geom within their range: eight corners,
two ``atan2`` each. With ten Hummingbirds the model holds 130 robot geoms and 3 of the pad
world's, so a sonar reading cost about 200 000 instructions, almost all of them on the other
vehicles' arms, rotors and landing gear, which the downward cone never meets. A single ray
(``mj_ray``: the flow sensor's, the barometer's, the ground below the rotors) tests every
geom's bounding sphere, about 100 instructions a robot geom: a quarter of a cast's cost.

How this works: every robot geom is built in geom group :data:`ROBOT_GEOM_GROUP` (2, drawn like
the world's groups 0 and 1 under MuJoCo's default visual options), and the world's geoms are in
other groups. When the model is built, each robot gets a bounding sphere: its body's position
(``xpos``) and the largest distance from it of its geoms' own bounding spheres (``geom_rbound``,
the sphere MuJoCo's ray functions test first). The rays of a cast (one, or a bundle) lie in a
cone about their mean direction; when the sphere of no other robot meets that cone within the
rays' range, MuJoCo is asked about the world's geoms only (``geomgroup`` without group 2), else
about every geom as before.

The two answers are the same to the bit, for every distance the sensors keep (those within
their range): MuJoCo computes each geom's intersection on its own (``mju_rayGeom`` and kin, the
same function with the same arguments in both casts) and keeps the nearest, the first geom on a
tie. A robot geom whose bounding sphere the rays miss within the range has no hit there, so the
nearest hit within the range is the world's either way; a hit beyond the range is reported as
none either way. The spheres carry a margin of a micrometre, and the robot bodies' positions are
MuJoCo's ``xpos``, computed in the same pass as the ``geom_xpos`` its ray functions use. Where
the model does not allow the shortcut (a geom in group 2 that belongs to no robot, a robot with
moving parts, or the casting robot carrying geoms on a child body, which ``bodyexclude`` would
not exclude), every cast asks about every geom. tests/sim/test_raycast.py compares both with
MuJoCo's casts over every geom.

Invariant: :meth:`RayCaster.moved` is called whenever MuJoCo's kinematics change (after each
``mj_step``, ``mj_forward``, or a model rebuild), so the bodies' positions are read again.
"""

from __future__ import annotations

import math
from typing import Any, Final

import numpy as np

from skeye.sim.gl import GL_BACKEND  # noqa: F401  (before mujoco: picks MUJOCO_GL)

# isort: split
import mujoco

ROBOT_GEOM_GROUP: Final = 2
"""MuJoCo geom group of every robot geom; the world's geoms use the other groups."""

_MARGIN_M: Final = 1e-6  # added to every bounding sphere: far above floating-point error


class _Rays:
    """Buffers for a cast of ``n`` rays from one point (MuJoCo's binding wants exact sizes)."""

    def __init__(self, n: int) -> None:
        self.dist: Any = np.zeros(n)
        self.geomid: Any = np.zeros(n, dtype=np.int32)


class RayCaster:
    """MuJoCo ray casts (MuJoCo's frame, unit directions) for one model; see the module doc."""

    def __init__(self) -> None:
        self._model: Any = None
        self._data: Any = None
        self._xpos_view: Any = None
        self._xpos: list[float] = []
        self._fresh = False
        self._bodies: list[int] = []  # robot bodies ...
        self._radii: list[float] = []  # ... and their bounding spheres' radii (margin included)
        self._alone: set[int] = set()  # robot bodies whose geoms all sit on the body itself
        self._shortcut = False
        self._world_only: Any = np.array([1, 1, 1, 1, 1, 1], dtype=np.uint8)
        self._world_only[ROBOT_GEOM_GROUP] = 0
        self._pnt: Any = np.zeros(3)  # Any: a buffer of 3 doubles (numpy's stubs say no)
        self._vec: Any = np.zeros(3)
        self._pnt_view: memoryview[float] = self._pnt.data.cast("B").cast("d")
        self._vec_view: memoryview[float] = self._vec.data.cast("B").cast("d")
        self._geomid: Any = np.zeros(1, dtype=np.int32)
        self._many: dict[int, _Rays] = {}
        self.geom = -1
        """The geom that the last :meth:`cast` hit (-1: none)."""

    def rebuild(self, model: Any, data: Any, robot_bodies: list[int]) -> None:
        """Take a newly built model (kinematics computed) and its robots' body ids."""
        self._model, self._data = model, data
        self._xpos_view = data.xpos.reshape(-1)
        self._fresh = False
        root = model.body_rootid.tolist()
        parent = model.geom_bodyid.tolist()
        group = model.geom_group.tolist()
        rbound = model.geom_rbound.tolist()
        joints = model.body_jntnum.tolist()
        geom_xpos = data.geom_xpos.tolist()
        xpos = data.xpos.tolist()
        robots = set(robot_bodies)
        shortcut = True
        for g in range(model.ngeom):
            if min(5, max(0, int(group[g]))) == ROBOT_GEOM_GROUP and root[parent[g]] not in robots:
                shortcut = False  # a geom the world-only cast would leave out unchecked
        self._bodies, self._radii, self._alone = [], [], set()
        for b in robot_bodies:
            radius = 0.0
            alone = True
            for g in range(model.ngeom):
                if root[parent[g]] != b:
                    continue
                if parent[g] != b:
                    alone = False
                    if joints[parent[g]] > 0:
                        radius = math.inf  # a moving part: no fixed sphere holds it
                gx, gy, gz = geom_xpos[g]
                bx, by, bz = xpos[b]
                dx, dy, dz = gx - bx, gy - by, gz - bz
                radius = max(radius, math.sqrt(dx * dx + dy * dy + dz * dz) + float(rbound[g]))
            self._bodies.append(b)
            self._radii.append(radius + _MARGIN_M)
            if alone:
                self._alone.add(b)
        self._shortcut = shortcut

    def bounding_radius(self, body: int) -> float:
        """The bounding sphere's radius of a robot body (m, margin included; ``inf`` for one
        with moving parts, which no fixed sphere holds), about its body position."""
        return self._radii[self._bodies.index(body)]

    def moved(self) -> None:
        """MuJoCo's kinematics changed: read the robots' positions again at the next cast."""
        self._fresh = False

    def _world_suffices(self, px: float, py: float, pz: float, rays: list[float], n: int,
                        exclude_body: int, max_range: float) -> bool:
        """Whether no robot but ``exclude_body`` can be met by any of the ``n`` unit rays
        (``rays``: x, y, z each) from the point within ``max_range``.

        The rays lie in a cone around their mean direction ``a`` whose half-angle ``alpha``
        reaches the farthest of them; a sphere seen under the half-angle ``beta`` in the
        direction ``w`` can meet one of them only if the angle between ``a`` and ``w`` is at
        most ``alpha + beta``, and only if its near side is within ``max_range``."""
        if not self._shortcut or exclude_body not in self._alone:
            return False
        ax = ay = az = 0.0
        for i in range(n):
            ax += rays[3 * i]
            ay += rays[3 * i + 1]
            az += rays[3 * i + 2]
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        if not norm > 1e-6:
            return False  # rays all round: no cone narrower than the whole sphere
        ax, ay, az = ax / norm, ay / norm, az / norm
        cos_alpha = 1.0
        for i in range(n):
            c = ax * rays[3 * i] + ay * rays[3 * i + 1] + az * rays[3 * i + 2]
            if c < cos_alpha:
                cos_alpha = c
        cos_alpha = min(1.0, cos_alpha)
        sin_alpha = math.sqrt(max(0.0, 1.0 - cos_alpha * cos_alpha))
        if not self._fresh:
            self._xpos = self._xpos_view.tolist()
            self._fresh = True
        xpos = self._xpos
        bodies, radii = self._bodies, self._radii
        for k in range(len(bodies)):
            b = bodies[k]
            if b == exclude_body:
                continue
            r = radii[k]
            wx, wy, wz = xpos[3 * b] - px, xpos[3 * b + 1] - py, xpos[3 * b + 2] - pz
            dist = math.sqrt(wx * wx + wy * wy + wz * wz)
            if not dist > r:
                return False  # the point is inside the sphere
            if dist - r > max_range:
                continue  # beyond the rays' reach
            sin_beta = r / dist
            cos_beta = math.sqrt(1.0 - sin_beta * sin_beta)
            # cos(alpha + beta); alpha + beta >= pi/2 leaves a half-space or more: test it all
            cos_sum = cos_alpha * cos_beta - sin_alpha * sin_beta
            if not cos_sum > 0.0:
                return False
            if not (ax * wx + ay * wy + az * wz) / dist < cos_sum - 1e-9:
                return False
        return True

    def cast(self, px: float, py: float, pz: float, ux: float, uy: float, uz: float,
             exclude_body: int, max_range: float) -> float:
        """Distance along one unit ray to the first geom not on ``exclude_body``; -1 when
        nothing is hit (only distances up to ``max_range`` are exact: see the module doc).
        The geom hit is left in :attr:`geom`."""
        pnt, vec = self._pnt_view, self._vec_view
        pnt[0], pnt[1], pnt[2] = px, py, pz
        vec[0], vec[1], vec[2] = ux, uy, uz
        group: Any = None
        if self._world_suffices(px, py, pz, [ux, uy, uz], 1, exclude_body, max_range):
            group = self._world_only
        geomid = self._geomid
        dist = float(mujoco.mj_ray(self._model, self._data, self._pnt, self._vec, group, 1,
                                   exclude_body, geomid))
        self.geom = int(geomid[0])
        return dist

    def cast_many(self, px: float, py: float, pz: float, rays: list[float], n: int,
                  exclude_body: int, max_range: float) -> list[float]:
        """Distances along ``n`` unit rays from one point (``rays``: x, y, z each) to the first
        geom not on ``exclude_body``, -1 where nothing is hit, in one ``mj_multiRay`` call
        (geoms beyond ``max_range`` are left out: only distances up to it are exact, see the
        module doc)."""
        buffers = self._many.get(n)
        if buffers is None:
            buffers = self._many[n] = _Rays(n)
        pnt = self._pnt_view
        pnt[0], pnt[1], pnt[2] = px, py, pz
        group: Any = None
        if self._world_suffices(px, py, pz, rays, n, exclude_body, max_range):
            group = self._world_only
        mujoco.mj_multiRay(self._model, self._data, self._pnt, np.array(rays), group, 1,
                           exclude_body, buffers.geomid, buffers.dist, None, n, max_range)
        out: list[float] = buffers.dist.tolist()
        return out
