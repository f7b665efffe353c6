"""Coordinate frames: the one place where MuJoCo's z-up frames meet the protocol's NED/FRD.

How this works: skeye builds its MuJoCo world as NWU (x north, y west, z up) and its robot
bodies as FLU (x forward, y left, z up). The protocol and everything above it use USARSim's NED
world (x north, y east, z down) and FRD body frames. Both pairs differ by a rotation of pi about
x, so a vector converts by negating y and z, and a quaternion (w, x, y, z; body to world) by
negating its y and z parts. These functions are their own inverses. Nothing outside this module
may flip a sign to change frames.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from skeye.sim.state import BodyState, Mat3

Vec3 = Sequence[float] | np.ndarray


def ned_to_mj(v: Vec3) -> np.ndarray:
    """A world vector NED -> MuJoCo NWU (or body FRD -> FLU)."""
    return np.array((v[0], -v[1], -v[2]), dtype=float)


def quat_ned_to_mj(q: Vec3) -> np.ndarray:
    """Body(FRD)->world(NED) quaternion (w,x,y,z) -> MuJoCo body(FLU)->world(NWU)."""
    return np.array((q[0], q[1], -q[2], -q[3]), dtype=float)


def euler_to_quat(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """(roll, pitch, yaw) rad, ZYX order -> quaternion (w,x,y,z)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array(
        (
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        )
    )


def quat_to_matrix(q: Vec3) -> np.ndarray:
    """Quaternion (w,x,y,z) -> 3x3 rotation matrix (body to world)."""
    w, x, y, z = q
    return np.array(
        (
            (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
        )
    )


def wrap_2pi(angle_rad: float) -> float:
    """Wrap to [0, 2 pi), as USARSim writes orientations."""
    if -2.0 * math.pi < angle_rad < 2.0 * math.pi:
        a = angle_rad  # what fmod gives there, exactly, without its call (not compiled to C)
    else:
        a = math.fmod(angle_rad, 2.0 * math.pi)
    if a < 0.0:
        a += 2.0 * math.pi
    if a >= 2.0 * math.pi:  # fmod of a tiny negative number can round up to 2 pi
        a = 0.0
    return a


def wrap_pi(angle_rad: float) -> float:
    """Wrap to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def free_joint_state(
    time_s: float,
    qpos: list[float],
    qvel: list[float],
    qacc: list[float],
    rotor_speed_rad_s: list[float] | None = None,
    qpos_adr: int = 0,
    qvel_adr: int = 0,
) -> BodyState:
    """A MuJoCo free joint's (qpos[7], qvel[6], qacc[3], from ``qpos_adr`` and ``qvel_adr`` in
    the lists: the whole model's ``tolist()`` will do) -> the body's state in NED/FRD.

    Plain floats: this runs every board tick of every robot. MuJoCo's free-joint linear
    velocity is in the world frame and its angular velocity in the body frame. The specific
    force is ``R^T (a - g)`` with g = +9.81 m/s^2 down (what an accelerometer feels).
    """
    a, b = qpos_adr, qvel_adr
    w, x, y, z = qpos[a + 3], qpos[a + 4], -qpos[a + 5], -qpos[a + 6]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    r00, r01, r02 = 1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)
    r10, r11, r12 = 2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)
    r20, r21, r22 = 2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)
    s = -r20
    pitch = math.asin(1.0 if s > 1.0 else -1.0 if s < -1.0 else s)
    ax, ay, az = qacc[b], -qacc[b + 1], -qacc[b + 2]
    gz = az - 9.81
    speeds = rotor_speed_rad_s if rotor_speed_rad_s is not None else [0.0, 0.0, 0.0, 0.0]
    return BodyState(
        time_s,
        (qpos[a], -qpos[a + 1], -qpos[a + 2]),
        (qvel[b], -qvel[b + 1], -qvel[b + 2]),
        (w, x, y, z),
        (math.atan2(r21, r22), pitch, math.atan2(r10, r00)),
        ((r00, r01, r02), (r10, r11, r12), (r20, r21, r22)),
        (qvel[b + 3], -qvel[b + 4], -qvel[b + 5]),
        (ax, ay, az),
        (
            r00 * ax + r10 * ay + r20 * gz,
            r01 * ax + r11 * ay + r21 * gz,
            r02 * ax + r12 * ay + r22 * gz,
        ),
        (speeds[0], speeds[1], speeds[2], speeds[3]),
    )


def quat_to_rows(q: Sequence[float]) -> Mat3:
    """Quaternion (w,x,y,z) -> rotation matrix (body to world) as rows of plain floats."""
    w, x, y, z = q
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


def ned_to_mj_floats(v: Sequence[float]) -> tuple[float, float, float]:
    """:func:`ned_to_mj` as a tuple of plain floats (for hot paths that fill MuJoCo buffers)."""
    return (v[0], -v[1], -v[2])


def ned_wrench_to_mj(
    force_ned: Sequence[float], torque_ned: Sequence[float]
) -> tuple[float, float, float, float, float, float]:
    """A world-frame force and torque in NED -> MuJoCo's xfrc_applied layout (NWU)."""
    return (
        force_ned[0],
        -force_ned[1],
        -force_ned[2],
        torque_ned[0],
        -torque_ned[1],
        -torque_ned[2],
    )


def put_ned_wrench_mj(
    out: memoryview[float], index: int, force_ned: tuple[float, float, float],
    torque_ned: tuple[float, float, float],
) -> None:
    """:func:`ned_wrench_to_mj` written into ``out[index:index + 6]`` (a flat float view of
    MuJoCo's ``xfrc_applied``): the engine's hot path, without a tuple or numpy's conversion."""
    out[index] = force_ned[0]
    out[index + 1] = -force_ned[1]
    out[index + 2] = -force_ned[2]
    out[index + 3] = torque_ned[0]
    out[index + 4] = -torque_ned[1]
    out[index + 5] = -torque_ned[2]
