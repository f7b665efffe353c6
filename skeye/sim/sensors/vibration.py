"""Airframe vibration at an IMU, driven by the rotor speeds.

How this works: a spinning rotor shakes the airframe at its rotation frequency (1P: the rotor's
mass and aerodynamic imbalance) and at its blade-pass frequency (blades x the rotation
frequency: each blade's thrust pulse as it passes the arm), plus broadband content (turbulent
wake, motor commutation, frame resonances). :class:`RotorVibration` keeps each rotor's phase,
advanced in sim time with the rotor's speed between readings (trapezoid), and returns, per
reading, on each axis

    sum over rotors i and harmonics h of  A_h (w_i / w_ref)^2 |H(h f_i)| sin(h phi_i + theta)
    + broadband (w_rms / w_ref)^2 N(0, 1)

with ``A_h`` the line amplitude at the reference rotor speed ``w_ref`` (an imbalance force grows
with the speed squared), ``H`` the sensor's first-order low-pass of corner ``Bandwidth`` (its
analog or decimation filter), ``theta`` a phase per rotor, harmonic and axis drawn once from the
sensor's seed, and ``N`` white noise. Nothing is averaged between readings: a line above half the
sample rate folds back (aliases) as it would through a sampled sensor. With the rotors stopped
the vibration is zero.

Invariants: every random draw comes from the Generator given, phases first (once), then one
normal deviate per axis per reading; sim time only. The level at ``w_ref`` per axis is
``sqrt(n_rotors * (A_1^2 + A_2^2) / 2 + broadband^2)`` (:meth:`RotorVibration.rms_at`), which is
what the estimator takes as the sensor's in-flight noise (docs/physics.md).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from skeye.sim.state import Vec3

_TWO_PI: Final = 2.0 * math.pi
MAX_ROTORS: Final = 8


class RotorVibration:
    """The vibration one IMU sees, per reading, from the rotor speeds (see the module doc)."""

    def __init__(
        self,
        rng: np.random.Generator,
        rotor_amp: float,
        blade_amp: float,
        broadband: float,
        ref_speed_rad_s: float,
        blades: int,
        bandwidth_hz: float,
    ) -> None:
        self.rotor_amp = rotor_amp
        self.blade_amp = blade_amp
        self.broadband = broadband
        self.ref_speed_rad_s = ref_speed_rad_s
        self.blades = blades
        self.bandwidth_hz = bandwidth_hz
        self.enabled = rotor_amp > 0.0 or blade_amp > 0.0 or broadband > 0.0
        self.rng = rng
        # theta[rotor][harmonic * 3 + axis], drawn once (the part and its mounting).
        self._theta: list[list[float]] = (
            rng.uniform(0.0, _TWO_PI, (MAX_ROTORS, 6)).tolist() if self.enabled else []
        )
        self._phase = [0.0] * MAX_ROTORS
        self._speeds: tuple[float, ...] = ()

    def rms_at(self, rotors: int, speed_rad_s: float | None = None) -> float:
        """The per-axis RMS of the vibration with ``rotors`` rotors all at ``speed_rad_s``
        (the reference speed when None), before the sensor's filter."""
        s = 1.0 if speed_rad_s is None else (speed_rad_s / self.ref_speed_rad_s) ** 2
        lines = rotors * (self.rotor_amp ** 2 + self.blade_amp ** 2) / 2.0
        return s * math.sqrt(lines + self.broadband ** 2)

    def _gain(self, freq_hz: float) -> float:
        fb = self.bandwidth_hz
        if fb <= 0.0:
            return 1.0
        r = freq_hz / fb
        return 1.0 / math.sqrt(1.0 + r * r)

    def sample(self, speeds: tuple[float, ...], dt_s: float) -> Vec3:
        """The vibration now (sensor axes), after ``dt_s`` of sim time since the last call."""
        if not self.enabled:
            return (0.0, 0.0, 0.0)
        n = min(len(speeds), MAX_ROTORS)
        prev = self._speeds if len(self._speeds) == len(speeds) else speeds
        self._speeds = speeds
        ref = self.ref_speed_rad_s
        blades = float(self.blades)
        x = y = z = 0.0
        mean_sq = 0.0
        for i in range(n):
            w = speeds[i]
            phase = (self._phase[i] + 0.5 * (prev[i] + w) * dt_s) % _TWO_PI
            self._phase[i] = phase
            s = (w / ref) * (w / ref)
            mean_sq += s
            if s <= 0.0:
                continue
            f1 = w / _TWO_PI
            a1 = self.rotor_amp * s * self._gain(f1)
            a2 = self.blade_amp * s * self._gain(blades * f1)
            th = self._theta[i]
            bp = blades * phase
            x += a1 * math.sin(phase + th[0]) + a2 * math.sin(bp + th[3])
            y += a1 * math.sin(phase + th[1]) + a2 * math.sin(bp + th[4])
            z += a1 * math.sin(phase + th[2]) + a2 * math.sin(bp + th[5])
        if self.broadband > 0.0 and mean_sq > 0.0:
            k = self.broadband * mean_sq / n
            dx, dy, dz = self.rng.standard_normal(3).tolist()
            x += k * dx
            y += k * dy
            z += k * dz
        return (x, y, z)


def clip3(x: float, y: float, z: float, limit: float) -> Vec3:
    """Each axis clipped to +-``limit`` (a sensor's measurement range); ``limit`` <= 0: none."""
    if limit <= 0.0:
        return (x, y, z)
    return (
        min(limit, max(-limit, x)),
        min(limit, max(-limit, y)),
        min(limit, max(-limit, z)),
    )
