"""The physical state of one vehicle at one instant, in the protocol's frames (NED world, FRD body).

Sensors and the low-level controller see only this (and their own configuration); they never
touch MuJoCo. The engine fills it from MuJoCo through :mod:`skeye.sim.frames`.

Everything is plain Python floats in tuples, not numpy arrays: a state is built every board
tick of every robot, and on 3-vectors float arithmetic is several times faster than numpy's
per-call overhead (``np.asarray(state.pos_ned_m)`` still gives an array where one is wanted).
"""

from __future__ import annotations

from dataclasses import dataclass

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]
"""A 3x3 matrix as three rows."""

IDENTITY3: Mat3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(slots=True)
class BodyState:
    """Ground truth of one vehicle. Quaternions are (w, x, y, z), body FRD to world NED."""

    time_s: float = 0.0
    pos_ned_m: Vec3 = (0.0, 0.0, 0.0)
    vel_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    quat_ned: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    rpy_rad: Vec3 = (0.0, 0.0, 0.0)
    rot_body_to_ned: Mat3 = IDENTITY3
    omega_frd_rad_s: Vec3 = (0.0, 0.0, 0.0)
    accel_ned_m_s2: Vec3 = (0.0, 0.0, 0.0)
    # Specific force (what an accelerometer measures): (a - g) in the body frame, m/s^2.
    specific_force_frd_m_s2: Vec3 = (0.0, 0.0, -9.81)
    # Rotor speeds (rad/s), for telemetry.
    rotor_speed_rad_s: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    # Written out, not generated: one state is made per event, and mypyc compiles a written
    # __init__ while a dataclass's generated one stays interpreted.
    def __init__(
        self,
        time_s: float = 0.0,
        pos_ned_m: Vec3 = (0.0, 0.0, 0.0),
        vel_ned_m_s: Vec3 = (0.0, 0.0, 0.0),
        quat_ned: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
        rpy_rad: Vec3 = (0.0, 0.0, 0.0),
        rot_body_to_ned: Mat3 = IDENTITY3,
        omega_frd_rad_s: Vec3 = (0.0, 0.0, 0.0),
        accel_ned_m_s2: Vec3 = (0.0, 0.0, 0.0),
        specific_force_frd_m_s2: Vec3 = (0.0, 0.0, -9.81),
        rotor_speed_rad_s: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
    ) -> None:
        self.time_s = time_s
        self.pos_ned_m = pos_ned_m
        self.vel_ned_m_s = vel_ned_m_s
        self.quat_ned = quat_ned
        self.rpy_rad = rpy_rad
        self.rot_body_to_ned = rot_body_to_ned
        self.omega_frd_rad_s = omega_frd_rad_s
        self.accel_ned_m_s2 = accel_ned_m_s2
        self.specific_force_frd_m_s2 = specific_force_frd_m_s2
        self.rotor_speed_rad_s = rotor_speed_rad_s


def mat_vec(m: Mat3, v: Vec3) -> Vec3:
    """``m @ v`` on plain floats."""
    r0, r1, r2 = m
    x, y, z = v
    return (
        r0[0] * x + r0[1] * y + r0[2] * z,
        r1[0] * x + r1[1] * y + r1[2] * z,
        r2[0] * x + r2[1] * y + r2[2] * z,
    )


def mat_t_vec(m: Mat3, v: Vec3) -> Vec3:
    """``m.T @ v`` on plain floats."""
    r0, r1, r2 = m
    x, y, z = v
    return (
        r0[0] * x + r1[0] * y + r2[0] * z,
        r0[1] * x + r1[1] * y + r2[1] * z,
        r0[2] * x + r1[2] * y + r2[2] * z,
    )


def mat_mul(a: Mat3, b: Mat3) -> Mat3:
    """``a @ b`` on plain floats."""
    (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = b
    rows = []
    for a0, a1, a2 in a:
        rows.append((
            a0 * b00 + a1 * b10 + a2 * b20,
            a0 * b01 + a1 * b11 + a2 * b21,
            a0 * b02 + a1 * b12 + a2 * b22,
        ))
    return (rows[0], rows[1], rows[2])


def transpose(m: Mat3) -> Mat3:
    (a, b, c), (d, e, f), (g, h, i) = m
    return ((a, d, g), (b, e, h), (c, f, i))


def cross(a: Vec3, b: Vec3) -> Vec3:
    """The cross product of two 3-vectors, plain floats."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
