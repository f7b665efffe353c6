"""The physical state of one vehicle at one instant, in the protocol's frames (NED world, FRD body).

Sensors and the low-level controller see only this (and their own configuration); they never
touch MuJoCo. The engine fills it from MuJoCo through :mod:`skeye.sim.frames`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class BodyState:
    """Ground truth of one vehicle. Quaternions are (w, x, y, z), body FRD to world NED."""

    time_s: float = 0.0
    pos_ned_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    vel_ned_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    quat_ned: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    rpy_rad: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rot_body_to_ned: np.ndarray = field(default_factory=lambda: np.eye(3))
    omega_frd_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_ned_m_s2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # Specific force (what an accelerometer measures): (a - g) in the body frame, m/s^2.
    specific_force_frd_m_s2: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    # Mechanical power drawn by the rotors and rotor speeds (rad/s), for battery and telemetry.
    rotor_speed_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(4))
