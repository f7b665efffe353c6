"""Wind and disturbances acting on the vehicles.

How this works: a wind model gives, at each board tick, the air velocity (NED, m/s) that drag
acts against and an extra force on the centre of mass (NED, N). Modes:

- ``none``: still air.
- ``constant``: a steady wind ``speed_m_s`` from a direction (``from_deg``, meteorological:
  the direction the wind comes from, clockwise from north).
- ``turbulence``: the constant wind plus Dryden-style gusts: each axis is white noise shaped by
  a first-order filter with time constant L/V (length scales L_u = L_v = 30 m, L_w = 10 m,
  V = max(mean speed, 1 m/s)), with standard deviations ``sigma_m_s`` horizontally and half that
  vertically. Seeded. These scale lengths have no source: they are not MIL-F-8785C's
  low-altitude values at 10 m, which are L_u = L_v = 67 m and L_w = 10 m (``dryden_profile``;
  sigma_w = 0.53 sigma_u there); the ``dryden`` mode follows the specification.
- ``dryden``: low-altitude atmospheric turbulence as MIL-F-8785C (and MIL-HDBK-1797) define it
  for flight below 1000 ft: a mean wind from ``w20_m_s``, the wind speed 20 ft (6.1 m) above the
  ground, scaled to the model height by the specification's logarithmic profile
  ``W(h) = W20 ln(h / z0) / ln(20 / z0)`` (z0 = 0.15 ft), plus Dryden gusts with the
  specification's low-altitude intensities and scale lengths, h in feet:
  ``sigma_w = 0.1 W20``, ``sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4``,
  ``L_w = h``, ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``. The longitudinal gust (along the
  mean wind) is Dryden's first-order form, the lateral and vertical ones its second-order
  form ``(1 + sqrt(3) T s) / (1 + T s)^2`` with ``T = L / V``, V the mean wind speed the
  frozen turbulence passes the hovering vehicle at (at least 1 m/s). The specification's
  low-altitude forms hold from 10 ft up; below, the 10 ft values apply (as MathWorks' Dryden
  blocks do). ``height_m`` is the height the model is evaluated at. Seeded.
- ``random_force``: the paper's disturbance (docs/experiments.md): a horizontal force on the centre
  of mass whose direction is uniform in the plane and magnitude uniform in [0, f_max_n],
  redrawn every ``tick_s`` (default 1/30 s). Seeded.

Parameters come from ``SET {Type Wind} {Mode m} {Params k=v,k=v}`` or the command line, as a
:class:`skeye.wire.wind.WindSettings`; bad keys or values raise ConfigError naming them. Every
parameter has a physical range (``skeye.wire.wind.PARAM_RANGES``), checked before a setting is
accepted: a value outside it (a 1e-320 s redraw period, a 1e6 m/s wind) would overflow the model
or blow every vehicle out of the world.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from skeye.wire.wind import WindSettings  # the protocol's SET {Type Wind}, checked there

FT: Final = 0.3048  # m per foot
DRYDEN_Z0_FT: Final = 0.15  # MIL-F-8785C wind-shear roughness (category C flight phases)


class WindModel:
    """Air velocity and disturbance force over time, for one world (shared by all vehicles)."""

    def __init__(self, settings: WindSettings, rng: np.random.Generator) -> None:
        self.settings = settings
        self.rng = rng
        self._gust = [0.0, 0.0, 0.0]
        self._force = (0.0, 0.0, 0.0)
        self._next_draw_s = 0.0
        s = dict(settings.params)
        speed = s.get("speed_m_s", 0.0)
        frm = math.radians(s.get("from_deg", 0.0))
        if settings.mode == "dryden":
            speed = dryden_profile(s["w20_m_s"], s["height_m"])[0]
        # Wind blowing *from* frm moves air towards frm + pi.
        self._mean = (-speed * math.cos(frm), -speed * math.sin(frm), 0.0)
        self._dryden = [0.0, 0.0, 0.0, 0.0, 0.0]  # u, then (x1, x2) for v and for w
        # What every board tick uses, worked out once (the settings never change).
        self._params = s
        self._mean_speed = max(1.0, math.hypot(self._mean[0], self._mean[1]))
        self._profile = (dryden_profile(s["w20_m_s"], s["height_m"]) if settings.mode == "dryden"
                         else (0.0, 0.0, 0.0, 0.0, 0.0))
        self._from_rad = frm

    def advance(self, time_s: float, dt_s: float) -> None:
        """Advance the random processes to ``time_s`` (called once per board tick)."""
        mode = self.settings.mode
        if mode == "turbulence":
            sigma = self._params["sigma_m_s"]
            v = self._mean_speed
            for axis, (length, sig) in enumerate(((30.0, sigma), (30.0, sigma), (10.0, sigma / 2))):
                a = math.exp(-dt_s * v / length)
                self._gust[axis] = a * self._gust[axis] + sig * math.sqrt(1 - a * a) * float(
                    self.rng.standard_normal()
                )
        elif mode == "dryden":
            self._advance_dryden(dt_s)
        elif mode == "random_force" and time_s + 1e-12 >= self._next_draw_s:
            s = dict(self.settings.params)
            direction = float(self.rng.uniform(0.0, 2.0 * math.pi))
            magnitude = float(self.rng.uniform(0.0, s["f_max_n"]))
            self._force = (magnitude * math.cos(direction), magnitude * math.sin(direction), 0.0)
            tick = s["tick_s"]
            self._next_draw_s = (math.floor(time_s / tick + 1e-9) + 1) * tick

    def _advance_dryden(self, dt_s: float) -> None:
        """Dryden's shaping filters one step: u exactly (first order), v and w (second order)
        by Euler-Maruyama (dt << T: 4 ms against T >= 1 s), each driven by white noise of
        intensity sigma^2 T so its output variance is sigma^2."""
        mean, sig_u, sig_w, l_u, l_w = self._profile
        if sig_w <= 0.0 or dt_s <= 0.0:
            return
        v = max(1.0, mean)
        x = self._dryden
        n: list[float] = self.rng.standard_normal(3).tolist()  # typed: native arithmetic
        t_u = l_u / v
        a = math.exp(-dt_s / t_u)
        x[0] = a * x[0] + sig_u * math.sqrt(1.0 - a * a) * n[0]
        for k, (sig, length) in enumerate(((sig_u, l_u), (sig_w, l_w))):
            t = length / v
            i = 1 + 2 * k
            x1, x2 = x[i], x[i + 1]
            x[i] = x1 - dt_s / t * x1 + sig * math.sqrt(dt_s / t) * n[1 + k]
            x[i + 1] = x2 + dt_s / t * (x1 - x2)
        root3 = math.sqrt(3.0)
        gust_v = root3 * x[1] + (1.0 - root3) * x[2]
        gust_w = root3 * x[3] + (1.0 - root3) * x[4]
        # Along the mean wind (towards where it blows), across it, and up (NED: -down).
        frm = self._from_rad
        cu, su = -math.cos(frm), -math.sin(frm)
        self._gust = [cu * x[0] - su * gust_v, su * x[0] + cu * gust_v, -gust_w]

    def air_velocity_ned(self) -> tuple[float, float, float]:
        m, g = self._mean, self._gust
        return m[0] + g[0], m[1] + g[1], m[2] + g[2]

    def force_ned(self) -> tuple[float, float, float]:
        return self._force


def dryden_profile(w20_m_s: float, height_m: float) -> tuple[float, float, float, float, float]:
    """MIL-F-8785C low altitude at ``height_m`` (10 ft at the least): the mean wind (m/s),
    sigma_u = sigma_v and sigma_w (m/s), L_u = L_v and L_w (m), from the wind at 20 ft."""
    h_ft = max(10.0, height_m / FT)
    k = 0.177 + 0.000823 * h_ft
    sig_w = 0.1 * w20_m_s
    mean = w20_m_s * math.log(h_ft / DRYDEN_Z0_FT) / math.log(20.0 / DRYDEN_Z0_FT)
    return mean, sig_w / k ** 0.4, sig_w, h_ft / k ** 1.2 * FT, h_ft * FT
