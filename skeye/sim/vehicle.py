"""Quadrotor flight physics: rotors, motors, drag, ground effect and the battery.

How this works: every board tick (an integer number of physics steps) the vehicle model turns
four rotor-speed commands into a body wrench. Each motor follows its command with a first-order
lag whose time constant depends on direction (spin-up faster than spin-down), integrated exactly
over the tick, and saturates at the motor's maximum speed (scaled by battery voltage). Rotor i
gives thrust ``kf*w^2`` along body -z and a reaction torque ``s_i * c * kf*w^2`` about body z
(c = moment constant in metres, s_i = -1 for rotors spinning clockwise seen from above). Rotor
drag (RotorS) is ``-sum(w) * c_rd * v_perp`` with v_perp the air-relative velocity in the rotor
plane; air drag is quadratic in the air-relative velocity. Ground effect multiplies thrust by
Cheeseman-Bennett's ``1 / (1 - (R / 4z)^2)``, capped, with z the rotor height above what is
below. Everything here is in the protocol's frames: NED world, FRD body, SI units.

Invariants: speeds are in [0, w_max]; thrust is never negative; the battery's charge only
decreases; all parameters are validated on construction (ConfigError naming the key).
"""

from __future__ import annotations

import math
from typing import Final

from skeye.robots.params import AirframeParams, BatteryParams

AIR_DENSITY_KG_M3: Final = 1.225

# '+' layout in FRD: front, right, back, left. Spin sign s_i: reaction torque about body z.
ROTOR_XY_UNIT = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))
ROTOR_SPIN = (-1.0, 1.0, -1.0, 1.0)


# Resting cell voltage against state of charge (typical LiPo discharge curve).
_OCV_SOC: tuple[float, ...] = (0.0, 0.05, 0.10, 0.20, 0.40, 0.60, 0.80, 0.90, 1.0)
_OCV_V: tuple[float, ...] = (3.30, 3.55, 3.65, 3.73, 3.80, 3.87, 3.98, 4.08, 4.20)


def cutoff_state_of_charge(cell_v: float) -> float:
    """The state of charge at which a cell rests at ``cell_v`` (the discharge curve inverted;
    0 at or below its 0 % voltage, 3.30 V)."""
    knots, volts = _OCV_SOC, _OCV_V
    if cell_v <= volts[0]:
        return 0.0
    i = 1
    while i < len(volts) - 1 and volts[i] < cell_v:
        i += 1
    v0, v1 = volts[i - 1], volts[i]
    return knots[i - 1] + (knots[i] - knots[i - 1]) * (cell_v - v0) / (v1 - v0)


def cell_open_circuit_v(soc: float) -> float:
    """Resting voltage of one LiPo cell at a state of charge in [0, 1]."""
    soc = min(1.0, max(0.0, soc))
    knots, volts = _OCV_SOC, _OCV_V  # one global lookup each (a board tick calls this)
    i = 1  # the first knot at or above soc (bisect_left), at least 1
    while i < len(knots) - 1 and knots[i] < soc:
        i += 1
    s0, s1 = knots[i - 1], knots[i]
    v0, v1 = volts[i - 1], volts[i]
    return v0 + (v1 - v0) * (soc - s0) / (s1 - s0)


class Battery:
    """Charge bookkeeping with voltage sag: V = cells * OCV(soc) - I * R.

    Remaining life (the protocol's ``STA {Battery}``) is the charge left divided by a current
    that is never below the hover current: the recent average current (a 2 s filter) while the
    vehicle draws more than hover (a climb), else the hover current. The filter starts at the
    hover current, so the figure is sensible from the first status line: the time the vehicle
    could still hover, as USARSim's ``Battery.ExpectedLifeTime`` starts from the rated life
    (its ``averageDischarge`` starts at ``maxEnergy / batteryLife``) rather than from nothing.
    The figure never rises: when the draw falls back to hover after a climb, or to the
    avionics at touchdown, it holds until the estimate comes down to it (USARSim's discharges
    at a steady rate, so its figure only counts down; a client shows "minutes left").

    Args:
        params: the battery's parameters.
        hover_shaft_power_w: the rotors' shaft power in hover (``RotorModel.hover_power_w``);
            0 leaves only the avionics as the floor.
    """

    def __init__(self, params: BatteryParams, hover_shaft_power_w: float = 0.0) -> None:
        self.params = params
        self.capacity_c = params.capacity_mah * 3.6  # coulombs
        self.charge_c = self.capacity_c
        # The charge at which it counts as empty: where the resting cell voltage reaches
        # cutoff_cell_v (0 for the default 3.3 V, the curve's 0 %); the motors stop there.
        self.cutoff_c = self.capacity_c * cutoff_state_of_charge(params.cutoff_cell_v)
        self.current_a = 0.0
        self.voltage_v = params.cells * cell_open_circuit_v(1.0)
        self.hover_current_a = self._current_for(
            hover_shaft_power_w / params.efficiency + params.avionics_power_w, self.voltage_v
        )
        self._avg_current_a = self.hover_current_a
        self._life_s = self._estimate_s()

    def _current_for(self, electrical_w: float, ocv: float) -> float:
        """The current that delivers this electrical power: P = I * (OCV - I R), smaller root;
        past the maximum-power point, the current at that point."""
        r = self.params.internal_resistance_ohm
        disc = ocv * ocv - 4.0 * r * electrical_w
        if disc > 0.0:
            return (ocv - math.sqrt(disc)) / (2.0 * r)
        return ocv / (2.0 * r)

    @property
    def state_of_charge(self) -> float:
        return self.charge_c / self.capacity_c

    @property
    def empty(self) -> bool:
        return self.charge_c <= self.cutoff_c

    def draw(self, shaft_power_w: float, dt_s: float) -> None:
        """Draw the electrical power that this shaft power needs for dt seconds."""
        p = self.params
        electrical_w = shaft_power_w / p.efficiency + p.avionics_power_w
        ocv = p.cells * cell_open_circuit_v(self.state_of_charge)
        current = self._current_for(electrical_w, ocv)
        if self.empty:
            current = 0.0
        self.current_a = current
        self.voltage_v = max(0.0, ocv - current * p.internal_resistance_ohm)
        self.charge_c = max(0.0, self.charge_c - current * dt_s)
        # Smoothed current for the remaining-life estimate (time constant 2 s).
        k = min(1.0, dt_s / 2.0)
        self._avg_current_a += k * (current - self._avg_current_a)
        estimate = self._estimate_s()
        if estimate < self._life_s:
            self._life_s = estimate

    def _estimate_s(self) -> float:
        """Life left (s) at the recent average current, never above the hover time."""
        if self.empty:
            return 0.0
        current = max(max(self._avg_current_a, self.hover_current_a),
                      self.params.avionics_power_w / max(self.voltage_v, 1.0))
        return (self.charge_c - self.cutoff_c) / current

    @property
    def remaining_s(self) -> float:
        """Remaining life (s): the lowest estimate so far (it never rises; see the class)."""
        return self._life_s


class RotorModel:
    """Four motors with first-order lag and the wrench they produce.

    Hot path: called every board tick, so it works on plain floats.
    """

    def __init__(self, airframe: AirframeParams, tick_s: float) -> None:
        self.p = airframe
        self.tick_s = tick_s
        self.alpha_up = 1.0 - math.exp(-tick_s / airframe.tau_up_s)
        self.alpha_down = 1.0 - math.exp(-tick_s / airframe.tau_down_s)
        self.speed_rad_s = [0.0, 0.0, 0.0, 0.0]
        self.command_rad_s = [0.0, 0.0, 0.0, 0.0]

    def set_speeds(self, speed_rad_s: float) -> None:
        """Start with every rotor at this speed (a vehicle spawned hovering)."""
        self.speed_rad_s = [speed_rad_s] * 4
        self.command_rad_s = [speed_rad_s] * 4

    def advance(self, commands_rad_s: list[float], max_speed_rad_s: float) -> None:
        """Advance the motors one tick towards the (saturated) commands."""
        speeds = self.speed_rad_s
        up, down = self.alpha_up, self.alpha_down
        for i in range(4):
            c = commands_rad_s[i]
            if c < 0.0:
                c = 0.0
            elif c > max_speed_rad_s:
                c = max_speed_rad_s
            self.command_rad_s[i] = c
            w = speeds[i]
            speeds[i] = w + (c - w) * (up if c > w else down)

    def wrench(
        self,
        vel_air_body: tuple[float, float, float],
        ground_effect: float,
    ) -> tuple[float, float, float, float, float, float, float]:
        """Body force (FRD, N), body torque (FRD, N m) and shaft power (W)."""
        p = self.p
        kf, arm, c = p.kf, p.arm_m, p.moment_constant_m
        w0, w1, w2, w3 = self.speed_rad_s
        f0, f1, f2, f3 = kf * w0 * w0, kf * w1 * w1, kf * w2 * w2, kf * w3 * w3
        thrust = (f0 + f1 + f2 + f3) * ground_effect
        tau_x = arm * (f3 - f1) * ground_effect
        tau_y = arm * (f0 - f2) * ground_effect
        tau_z = c * (-f0 + f1 - f2 + f3)
        w_sum = w0 + w1 + w2 + w3
        vx, vy, vz = vel_air_body
        k_rd = p.rotor_drag * w_sum
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        k_air = 0.5 * AIR_DENSITY_KG_M3 * p.drag_area_m2 * speed
        fx = -k_rd * vx - k_air * vx
        fy = -k_rd * vy - k_air * vy
        fz = -thrust - k_air * vz
        power = c * (f0 * w0 + f1 * w1 + f2 * w2 + f3 * w3)
        return fx, fy, fz, tau_x, tau_y, tau_z, power

    @staticmethod
    def hover_power_w(airframe: AirframeParams) -> float:
        """Shaft power (W) of four equal rotors holding the airframe's weight out of ground
        effect: the sum of c * kf * w^3 that :meth:`wrench` reports, at the hover speed."""
        w = airframe.hover_speed_rad_s
        return 4.0 * airframe.moment_constant_m * airframe.kf * w * w * w

    def total_thrust_n(self) -> float:
        kf = self.p.kf
        return sum(kf * w * w for w in self.speed_rad_s)


def ground_effect_factor(rotor_height_m: float | None, rotor_radius_m: float) -> float:
    """Cheeseman-Bennett thrust ratio in ground effect, capped at 1.25 very close to the ground."""
    if rotor_height_m is None or rotor_height_m > 4.0 * rotor_radius_m:
        return 1.0
    z = max(rotor_height_m, 0.01)
    ratio = rotor_radius_m / (4.0 * z)
    if ratio >= 0.447:  # 1 / (1 - 0.2) = 1.25
        return 1.25
    return 1.0 / (1.0 - ratio * ratio)
