"""The vehicle's own low-level controller (the AscTec "LL" board's job), emulated.

How this works: a cascade run every board tick on the vehicle's *own estimate* (the INS), never
on ground truth, so an estimate that drifts makes the vehicle drift as a real one does.

- Attitude mode (``DRIVE {RollAngle} {PitchAngle} {RotationalVelocity} {Thrust}``): angle
  set-points -> P angle loop -> rate set-points -> PI rate loop -> body torques; collective
  thrust is ``Thrust * max_thrust`` straight from the stick, as on the real board.
- Height mode (the AscTec LL board's height control; ``Command.height_mode`` with attitude):
  angles as in attitude mode; the thrust stick is a climb rate around its centre,
  ``(Thrust - 0.5) * 2 * max_climb``, and at the centre the height estimate is held.
- Velocity mode (USARSim's aerial ``DRIVE``; the skeye extension board's flow-based velocity
  hold): forward/lateral velocity in the yaw-following frame -> PI velocity loop on the
  *estimated* velocity (optical flow indoors, so it drifts as flow drifts) -> acceleration ->
  tilt set-points (limited to ``max_tilt_rad``); vertical: PI on climb rate, and when the climb
  command is zero a P loop holds the height estimate where the command went to zero (height
  hold). Yaw rate goes straight to the rate loop.
- GPS mode (the AscTec LL board's GPS position hold; ``Command.gps_mode``): velocity mode
  while the estimator has a GPS fix; with the horizontal sticks centred (zero forward and
  lateral velocity) a P loop (``position_gain``) holds the position estimate where they were
  centred.
- Per axis (USARSim's ``AerialVehicle.Drive``: each DRIVE field sets its own axis, the others
  keep theirs): the pitch axis flies either an angle or a forward velocity, the roll axis an
  angle or a right velocity, the vertical axis the thrust stick or a climb rate. The two
  modes above are the cases where every axis is of one form; a mixed set-point flies each
  axis as its form says (an angle axis with the velocity loop of the other axis, a climb rate
  with angles: the height-hold loop above).
- Mixer: total thrust and torques -> per-rotor thrust for the '+' layout -> rotor speed
  commands (sqrt(f/kf)); roll/pitch keep priority over yaw when a rotor would saturate.

Integrators are clamped (anti-windup). Every limit is a parameter (ControllerParams).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from skeye.robots.params import GRAVITY_M_S2, AirframeParams, ControllerParams


@dataclass
class Command:
    """The current set-point, per axis: the pitch axis flies ``pitch_rad`` when ``pitch_angle``
    is set, else ``forward_m_s``; the roll axis ``roll_rad`` when ``roll_angle``, else
    ``right_m_s``; the vertical axis ``thrust`` when ``thrust_vertical``, else ``up_m_s``.
    Velocity mode when none is set, attitude mode (:attr:`attitude`) when all three are."""

    pitch_angle: bool = False
    roll_angle: bool = False
    thrust_vertical: bool = False
    forward_m_s: float = 0.0
    right_m_s: float = 0.0
    up_m_s: float = 0.0
    yaw_rate_rad_s: float = 0.0
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    thrust: float = 0.0  # 0..1 of max thrust
    gps_mode: bool = False  # GPS mode: centred sticks hold the position while there is a fix
    height_mode: bool = False  # with attitude: thrust stick = climb rate, height held at 0.5

    @property
    def attitude(self) -> bool:
        """Every axis in the attitude form (angles and the thrust stick): attitude mode."""
        return self.pitch_angle and self.roll_angle and self.thrust_vertical

    @property
    def velocity(self) -> bool:
        """Every axis in the velocity form: velocity mode."""
        return not (self.pitch_angle or self.roll_angle or self.thrust_vertical)


def _clamp(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


class LowLevelController:
    """Stateful cascade; ``update`` is the hot path and works on floats."""

    def __init__(self, airframe: AirframeParams, params: ControllerParams, tick_s: float) -> None:
        self.a = airframe
        self.p = params
        self.dt = tick_s
        self.reset()

    def reset(self, hold_altitude_m: float | None = None) -> None:
        self.rate_int = [0.0, 0.0, 0.0]
        self.vel_int = [0.0, 0.0]
        self.climb_int = 0.0
        self.hold_altitude_m = hold_altitude_m
        self.hold_north_m: float | None = None
        self.hold_east_m: float | None = None

    def reset_axes(self, pitch: bool, roll: bool, vertical: bool) -> None:
        """Forget the state of the axes that changed form: a pitch or roll axis's velocity
        integrator and the GPS hold point, the vertical axis's climb integrator and height
        hold (taken anew where the climb command is next zero)."""
        if pitch:
            self.vel_int[0] = 0.0
        if roll:
            self.vel_int[1] = 0.0
        if pitch or roll:
            self.hold_north_m = self.hold_east_m = None
        if vertical:
            self.climb_int = 0.0
            self.hold_altitude_m = None

    def update(
        self,
        cmd: Command,
        rpy: tuple[float, float, float],
        omega: tuple[float, float, float],
        vel_ned: tuple[float, float, float],
        pos_ned: tuple[float, float, float],
        max_rotor_speed_rad_s: float,
        gps_hold: bool = False,
    ) -> list[float]:
        """One tick: estimate + command -> four rotor speed commands (rad/s).

        ``gps_hold``: the estimator has a GPS fix, so centred sticks hold the position.

        Hot path (every board tick of every robot): written out on plain floats.
        """
        p, a, dt = self.p, self.a, self.dt
        roll, pitch, yaw = rpy
        altitude_m = -pos_ned[2]
        if cmd.attitude:
            lim = p.max_tilt_rad * 1.6
            roll_sp = _clamp(cmd.roll_rad, -lim, lim)
            pitch_sp = _clamp(cmd.pitch_rad, -lim, lim)
            if cmd.height_mode:
                # Height mode: the thrust stick is a climb rate around its centre (0.5).
                up = (_clamp(cmd.thrust, 0.0, 1.0) - 0.5) * 2.0 * p.max_climb_m_s
                thrust = self._vertical(up, altitude_m, vel_ned[2], roll, pitch)
            else:
                thrust = _clamp(cmd.thrust, 0.0, 1.0) * a.max_thrust_n
                self.hold_altitude_m = None
        elif not cmd.velocity:
            roll_sp, pitch_sp, thrust = self._mixed(cmd, yaw, vel_ned, altitude_m, roll, pitch)
        else:
            cy, sy = math.cos(yaw), math.sin(yaw)
            vn, ve, vd = vel_ned
            vmax, amax, ki = p.max_speed_m_s, p.max_accel_m_s2, p.velocity_integral_gain
            kv = p.velocity_gain
            vel_int = self.vel_int
            fwd_sp = _clamp(cmd.forward_m_s, -vmax, vmax)
            right_sp = _clamp(cmd.right_m_s, -vmax, vmax)
            hold_n, hold_e = self.hold_north_m, self.hold_east_m
            if cmd.gps_mode and gps_hold and fwd_sp == 0.0 and right_sp == 0.0:
                # GPS mode, sticks centred: position hold -> velocity set-point (NED -> yaw frame).
                if hold_n is None or hold_e is None:
                    hold_n = self.hold_north_m = pos_ned[0]
                    hold_e = self.hold_east_m = pos_ned[1]
                kp = p.position_gain
                sp_n = _clamp(kp * (hold_n - pos_ned[0]), -vmax, vmax)
                sp_e = _clamp(kp * (hold_e - pos_ned[1]), -vmax, vmax)
                fwd_sp = cy * sp_n + sy * sp_e
                right_sp = -sy * sp_n + cy * sp_e
            else:
                self.hold_north_m = self.hold_east_m = None
            # Horizontal velocity loop -> accelerations in the yaw frame (forward, right).
            err = fwd_sp - (cy * vn + sy * ve)
            i0 = vel_int[0] = _clamp(vel_int[0] + err * dt, -1.0, 1.0)
            acc_fwd = _clamp(kv * err + ki * i0, -amax, amax)
            err = right_sp - (-sy * vn + cy * ve)
            i1 = vel_int[1] = _clamp(vel_int[1] + err * dt, -1.0, 1.0)
            acc_right = _clamp(kv * err + ki * i1, -amax, amax)
            tilt_max = p.max_tilt_rad
            pitch_sp = _clamp(-math.atan2(acc_fwd, GRAVITY_M_S2), -tilt_max, tilt_max)
            roll_sp = _clamp(
                math.atan2(acc_right * math.cos(pitch_sp), GRAVITY_M_S2), -tilt_max, tilt_max
            )
            thrust = self._vertical(cmd.up_m_s, altitude_m, vd, roll, pitch)
        yaw_rate_sp = _clamp(cmd.yaw_rate_rad_s, -p.max_yaw_rate_rad_s, p.max_yaw_rate_rad_s)
        # Angle loop -> body rate set-points (Euler-rate approximation, fine for small tilt),
        # then the PI rate loop (P only on yaw) -> body torques.
        rate_int = self.rate_int
        kr, kri, ka = p.rate_gain, p.rate_integral_gain, p.angle_gain
        ixx, iyy, izz = a.inertia_kg_m2
        err = ka * (roll_sp - roll) - omega[0]
        r0 = rate_int[0] = _clamp(rate_int[0] + err * dt, -0.5, 0.5)
        tau_x = ixx * (kr * err + kri * r0)
        err = ka * (pitch_sp - pitch) - omega[1]
        r1 = rate_int[1] = _clamp(rate_int[1] + err * dt, -0.5, 0.5)
        tau_y = iyy * (kr * err + kri * r1)
        err = yaw_rate_sp - omega[2]
        rate_int[2] = _clamp(rate_int[2] + err * dt, -0.5, 0.5)
        tau_z = izz * (p.yaw_rate_gain * err)
        return self.mix(thrust, [tau_x, tau_y, tau_z], max_rotor_speed_rad_s)

    def _mixed(
        self,
        cmd: Command,
        yaw: float,
        vel_ned: tuple[float, float, float],
        altitude_m: float,
        roll: float,
        pitch: float,
    ) -> tuple[float, float, float]:
        """A set-point whose axes are of both forms: (roll and pitch set-points, thrust N).

        An angle axis flies its angle (its velocity integrator rests at 0); a velocity axis
        the velocity loop of velocity mode; the vertical axis the thrust stick (height mode:
        a climb rate around its centre) or the climb-rate loop with its height hold. No GPS
        position hold: that needs both horizontal axes on velocities."""
        p, a, dt = self.p, self.a, self.dt
        lim = p.max_tilt_rad * 1.6
        tilt_max = p.max_tilt_rad
        cy, sy = math.cos(yaw), math.sin(yaw)
        vn, ve, vd = vel_ned
        vmax, amax = p.max_speed_m_s, p.max_accel_m_s2
        kv, ki = p.velocity_gain, p.velocity_integral_gain
        vel_int = self.vel_int
        self.hold_north_m = self.hold_east_m = None
        if cmd.pitch_angle:
            pitch_sp = _clamp(cmd.pitch_rad, -lim, lim)
            vel_int[0] = 0.0
        else:
            err = _clamp(cmd.forward_m_s, -vmax, vmax) - (cy * vn + sy * ve)
            i0 = vel_int[0] = _clamp(vel_int[0] + err * dt, -1.0, 1.0)
            acc_fwd = _clamp(kv * err + ki * i0, -amax, amax)
            pitch_sp = _clamp(-math.atan2(acc_fwd, GRAVITY_M_S2), -tilt_max, tilt_max)
        if cmd.roll_angle:
            roll_sp = _clamp(cmd.roll_rad, -lim, lim)
            vel_int[1] = 0.0
        else:
            err = _clamp(cmd.right_m_s, -vmax, vmax) - (-sy * vn + cy * ve)
            i1 = vel_int[1] = _clamp(vel_int[1] + err * dt, -1.0, 1.0)
            acc_right = _clamp(kv * err + ki * i1, -amax, amax)
            roll_sp = _clamp(
                math.atan2(acc_right * math.cos(pitch_sp), GRAVITY_M_S2), -tilt_max, tilt_max
            )
        if not cmd.thrust_vertical:
            thrust = self._vertical(cmd.up_m_s, altitude_m, vd, roll, pitch)
        elif cmd.height_mode:
            up = (_clamp(cmd.thrust, 0.0, 1.0) - 0.5) * 2.0 * p.max_climb_m_s
            thrust = self._vertical(up, altitude_m, vd, roll, pitch)
        else:
            thrust = _clamp(cmd.thrust, 0.0, 1.0) * a.max_thrust_n
            self.hold_altitude_m = None
        return roll_sp, pitch_sp, thrust

    def _vertical(
        self, up_m_s: float, altitude_m: float, vd: float, roll: float, pitch: float
    ) -> float:
        """Climb-rate PI, with height hold while the climb command is zero -> thrust (N)."""
        p, a, dt = self.p, self.a, self.dt
        climb_max = p.max_climb_m_s
        up_cmd = _clamp(up_m_s, -climb_max, climb_max)
        if up_cmd == 0.0:
            if self.hold_altitude_m is None:
                self.hold_altitude_m = altitude_m
            up_cmd = _clamp(
                p.height_gain * (self.hold_altitude_m - altitude_m), -climb_max, climb_max
            )
        else:
            self.hold_altitude_m = None
        err = up_cmd + vd
        self.climb_int = _clamp(self.climb_int + err * dt, -2.0, 2.0)
        a_up = _clamp(
            p.climb_gain * err + p.climb_integral_gain * self.climb_int,
            -GRAVITY_M_S2 * 0.8,
            p.max_accel_m_s2 * 2,
        )
        tilt = math.cos(roll) * math.cos(pitch)
        return a.mass_kg * (GRAVITY_M_S2 + a_up) / (tilt if tilt > 0.5 else 0.5)

    def mix(
        self, thrust_n: float, torque: list[float], max_rotor_speed_rad_s: float
    ) -> list[float]:
        """Total thrust and body torques -> rotor speed commands ('+' layout, FRD)."""
        a = self.a
        f_max = a.kf * max_rotor_speed_rad_s**2
        thrust_n = _clamp(thrust_n, 0.0, 4.0 * f_max)
        base = thrust_n / 4.0
        tx = torque[0] / (2.0 * a.arm_m)
        ty = torque[1] / (2.0 * a.arm_m)
        tz = torque[2] / (4.0 * a.moment_constant_m)
        # Roll/pitch first: limit them to what fits around the collective, then yaw.
        head = min(base, f_max - base)
        scale = 1.0
        rp = max(abs(tx), abs(ty))
        if rp > head and rp > 0:
            scale = head / rp
        tx, ty = tx * scale, ty * scale
        room = max(0.0, head - max(abs(tx), abs(ty)))
        tz = _clamp(tz, -room, room)
        kf = a.kf
        f0, f1, f2, f3 = base + ty - tz, base - tx + tz, base - ty - tz, base + tx + tz
        return [
            math.sqrt(f0 / kf) if f0 > 0.0 else 0.0,
            math.sqrt(f1 / kf) if f1 > 0.0 else 0.0,
            math.sqrt(f2 / kf) if f2 > 0.0 else 0.0,
            math.sqrt(f3 / kf) if f3 > 0.0 else 0.0,
        ]
