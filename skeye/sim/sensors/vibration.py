"""Airframe vibration at an IMU, driven by the rotor speeds.

How this works: a spinning rotor shakes the airframe at its rotation frequency (1P: the rotor's
mass and aerodynamic imbalance) and at its blade-pass frequency (blades x the rotation
frequency: each blade's thrust pulse as it passes the arm), plus broadband content (turbulent
wake, motor commutation, frame resonances). :class:`RotorVibration` keeps each rotor's phase,
advanced in sim time with the rotor's speed between readings (trapezoid). The vibration at an
instant is, per axis,

    sum over rotors i and harmonics h of  A_h (w_i / w_ref)^2 |H(h f_i)| sin(h phi_i + theta)
    + broadband (w_rms / w_ref)^2 N(0, 1)

with ``A_h`` the line amplitude at the reference rotor speed ``w_ref`` (an imbalance force grows
with the speed squared), ``H`` the sensor's first-order low-pass of corner ``Bandwidth``,
``theta`` a phase per rotor, harmonic and axis drawn once from the sensor's seed, and the
broadband white within ``Bandwidth``.

A reading is the **mean over the interval since the previous reading**: a digital IMU and a
board average their fast internal samples down to the rate they report at (the ADIS16448
averages its 819.2 Hz samples when it decimates; the AscTec LL board reads its gyros at 1 kHz),
so each line is averaged exactly over the interval (its phase moving linearly: the mean of
``sin`` is a difference of cosines over the phase swept) and the broadband's variance falls by
the number of independent samples in it, ``2 Bandwidth x interval``. That averaging is a
boxcar whose sidelobes pass part of every line above half the reading rate: the lines still
alias, as they do through a real decimation filter. A first reading (no interval yet) is the
instant's value. With the rotors stopped the vibration is zero.

Invariants: every random draw comes from the Generator given, phases first (once), then one
normal deviate per axis per reading; sim time only. :meth:`RotorVibration.rms_at` is the
per-axis level of the instantaneous vibration, ``sqrt(n (A_1^2 + A_2^2) / 2 + broadband^2)``;
:meth:`RotorVibration.rms_sampled` what readings at a given rate carry after the averaging,
which is what the estimator takes as the sensor's in-flight noise (docs/physics.md).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from skeye.sim.sensors.base import NormalStream
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
        normals: NormalStream | None = None,
    ) -> None:
        """``normals``: the Generator's :class:`NormalStream` where the sensor has one (the
        broadband's deviates come from it); the phases are drawn from ``rng`` itself, now."""
        self.rotor_amp = rotor_amp
        self.blade_amp = blade_amp
        self.broadband = broadband
        self.ref_speed_rad_s = ref_speed_rad_s
        self.blades = blades
        self.bandwidth_hz = bandwidth_hz
        self.enabled = rotor_amp > 0.0 or blade_amp > 0.0 or broadband > 0.0
        self.rng = rng
        self.normals = normals if normals is not None else NormalStream(rng)
        # theta[rotor][harmonic * 3 + axis], drawn once (the part and its mounting).
        self._theta: list[list[float]] = (
            rng.uniform(0.0, _TWO_PI, (MAX_ROTORS, 6)).tolist() if self.enabled else []
        )
        self._phase = [0.0] * MAX_ROTORS
        self._speeds: tuple[float, ...] = ()

    def rms_at(self, rotors: int, speed_rad_s: float | None = None) -> float:
        """The per-axis RMS of the instantaneous vibration with ``rotors`` rotors all at
        ``speed_rad_s`` (the reference speed when None), before the sensor's filter."""
        s = 1.0 if speed_rad_s is None else (speed_rad_s / self.ref_speed_rad_s) ** 2
        lines = rotors * (self.rotor_amp ** 2 + self.blade_amp ** 2) / 2.0
        return s * math.sqrt(lines + self.broadband ** 2)

    def rms_sampled(self, rotors: int, rate_hz: float, speed_rad_s: float | None = None
                    ) -> float:
        """The per-axis RMS that readings at ``rate_hz`` carry, each averaged over its interval
        and through the sensor's filter, the rotors at ``speed_rad_s`` (default: reference)."""
        w = self.ref_speed_rad_s if speed_rad_s is None else speed_rad_s
        s = (w / self.ref_speed_rad_s) ** 2
        dt = 1.0 / rate_hz
        f1 = w / _TWO_PI
        lines = 0.0
        for amp, freq in ((self.rotor_amp, f1), (self.blade_amp, self.blades * f1)):
            g = self._gain(freq) * _sinc(freq * dt)
            lines += amp * amp * g * g
        broad = self.broadband ** 2 * _broadband_share(self.bandwidth_hz, dt)
        return s * math.sqrt(rotors * lines / 2.0 + broad)

    def _gain(self, freq_hz: float) -> float:
        fb = self.bandwidth_hz
        if fb <= 0.0:
            return 1.0
        r = freq_hz / fb
        return 1.0 / math.sqrt(1.0 + r * r)

    def sample(self, speeds: tuple[float, ...], dt_s: float) -> Vec3:
        """The vibration averaged over the ``dt_s`` of sim time since the last call (sensor
        axes); the instant's value when ``dt_s`` is 0."""
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
            start = self._phase[i]
            swept = 0.5 * (prev[i] + w) * dt_s  # the phase swept over the interval
            end = start + swept
            self._phase[i] = end % _TWO_PI
            s = (w / ref) * (w / ref)
            mean_sq += s
            if s <= 0.0:
                continue
            f1 = w / _TWO_PI
            a1 = self.rotor_amp * s * self._gain(f1)
            a2 = self.blade_amp * s * self._gain(blades * f1)
            th = self._theta[i]
            x += a1 * _mean_sin(start, swept, th[0]) + a2 * _mean_sin(
                blades * start, blades * swept, th[3])
            y += a1 * _mean_sin(start, swept, th[1]) + a2 * _mean_sin(
                blades * start, blades * swept, th[4])
            z += a1 * _mean_sin(start, swept, th[2]) + a2 * _mean_sin(
                blades * start, blades * swept, th[5])
        if self.broadband > 0.0 and mean_sq > 0.0:
            k = self.broadband * mean_sq / n * math.sqrt(
                _broadband_share(self.bandwidth_hz, dt_s))
            d = self.normals.take(3)
            x += k * d[0]
            y += k * d[1]
            z += k * d[2]
        return (x, y, z)


def _mean_sin(start: float, swept: float, theta: float) -> float:
    """The mean of sin(phase + theta) as the phase moves linearly from ``start`` by ``swept``."""
    if abs(swept) < 1e-9:
        return math.sin(start + theta)
    return (math.cos(start + theta) - math.cos(start + swept + theta)) / swept


def _sinc(x: float) -> float:
    """|sin(pi x) / (pi x)|: a line's gain through a boxcar average over x of its periods."""
    if abs(x) < 1e-12:
        return 1.0
    return abs(math.sin(math.pi * x) / (math.pi * x))


def _broadband_share(bandwidth_hz: float, dt_s: float) -> float:
    """The share of white noise (band-limited to ``bandwidth_hz``) left after averaging over
    ``dt_s``: one over the independent samples in it, 2 B dt (1 for a single instant)."""
    if dt_s <= 0.0 or bandwidth_hz <= 0.0:
        return 1.0
    return min(1.0, 1.0 / (2.0 * bandwidth_hz * dt_s))


def clip3(x: float, y: float, z: float, limit: float) -> Vec3:
    """Each axis clipped to +-``limit`` (a sensor's measurement range); ``limit`` <= 0: none."""
    if limit <= 0.0:
        return (x, y, z)
    return (
        min(limit, max(-limit, x)),
        min(limit, max(-limit, y)),
        min(limit, max(-limit, z)),
    )
