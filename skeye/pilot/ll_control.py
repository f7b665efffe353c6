"""The onboard computer's side of an AscTec LL board, sans-IO: the estimate and the sticks.

How this works: the pilot flies an LL board (real, or ``skeye sim --ll-board``) only through
what the board's serial protocol offers: it polls structures and sends CTRL_INPUT sticks.

- :class:`LLEstimate` turns the polled structures into the ``Snapshot`` the boards fly on. What
  comes from where (docs/onboard.md): attitude, rates, accelerations, magnetic field, the
  velocity estimate (NED) and the fused and barometric heights from IMU_CALCDATA; the motors
  from LL_STATUS (its ``flying`` reads "motors on", as AscTec drivers read it), the battery
  too, and "landed" from a land detector on the thrust output and the vertical speed
  (PX4's tests, below); the GPS fix and the board's best position estimate
  from GPS_DATA_ADVANCED; the serial switch from RC_DATA; pressure from IMU_RAWDATA; thrust
  from CONTROLLER_OUTPUT. The LL board reports no horizontal position, so the pilot keeps its
  own: the velocity integrated (trapezoid) between polls, pulled towards the board's GPS best
  estimate with a time constant of ``GPS_PULL_S`` (a complementary filter: the velocity gives
  the short-term motion the pad hold predicts with, the GPS estimate keeps it from drifting).
  North and east are measured from the start point (the integration's zero; the first fix is
  placed where the estimate was then); down is the board's fused height, negated.
- :class:`StickPilot` turns the pilot's motions into sticks, one CTRL_INPUT per control cycle.
  Velocities (the pad hold, VELOCITY, the boards' GPS-mode sticks) are GPS-mode sticks
  (``ctrl`` 0x2F: full stick = the vehicle's maximum speed, the thrust stick a climb rate around
  its centre, centred sticks hold the position). Positions (take-off, fly-to, turn) and the
  landing are the client-side motions of :mod:`skeye.control.motion` on this estimate, flown
  with the same GPS-mode sticks, and after arriving they hold the target with the same PI, as
  ``sim://``'s motion control does; a hover is centred sticks (the board's own position hold),
  and so is the horizontal part of a take-off (straight up where it is). A landing holds the
  position with the pilot's own PI, as on ``sim://`` (the board's softer P hold let the final
  descent of a pad landing drift 2-6 cm more under E2's disturbance).
  Direct stick input from ground control is passed on in attitude or height mode. The motors
  start with AscTec's gesture (thrust 0, full yaw, held until LL_STATUS says so), before a
  take-off or stick flight; they stop on the ground by the board itself (landed and not asked
  to climb), the pilot leaving it every axis, and with the gesture only if the board has not
  stopped them after ``MOTORS_STOP_WAIT_S``.

Invariants: time is an argument; nothing here blocks or owns a socket; every CTRL_INPUT is in
range (the stick scales clamp).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from skeye.control.motion import (
    DriveCommand,
    GoTo,
    Hold,
    Land,
    Motion,
    MotionConfig,
    NavState,
    Target,
)
from skeye.errors import LinkTimeout, SkeyeError
from skeye.geo import GeoOrigin
from skeye.pilot.airframe import GpsFix, Snapshot, VehicleLimits
from skeye.wire.packet_defs import GPS_FIX_VALID
from skeye.wire.packet_units import (
    STICK_MAX,
    THRUST_MAX,
    ctrl_input_from_si,
    gps_data_advanced_to_si,
    gps_data_to_si,
    imu_calcdata_to_si,
    si_value,
)
from skeye.wire.packets import (
    PD,
    ControllerOutput,
    CtrlBits,
    CtrlInput,
    GpsData,
    GpsDataAdvanced,
    ImuCalcData,
    ImuRawData,
    LlStatus,
    Message,
    RcData,
)

GPS_PULL_S = 30.0
"""Time constant of the pull of the integrated position towards the board's GPS estimate. Long:
that estimate (the board's INS anchored to the running mean of the GPS fixes) moves by
decimetres while the mean settles, which a short pull would fly as if the vehicle had moved."""
SWITCH_CHANNEL = 4  # RC_DATA channel[4]: the serial interface switch (> 2048: enabled)
SWITCH_ON = 2048
GESTURE_THRUST = 0
GESTURE_YAW = -STICK_MAX  # full yaw left
GPS_STICKS = int(CtrlBits.PITCH | CtrlBits.ROLL | CtrlBits.YAW | CtrlBits.THRUST
                 | CtrlBits.GPS_POSITION_CONTROL)
ATTITUDE_STICKS = int(CtrlBits.PITCH | CtrlBits.ROLL | CtrlBits.YAW | CtrlBits.THRUST)
GESTURE_MOTORS_OFF_AFTER_S = 0.5  # landed this long with zero thrust asked: stop the motors
MOTORS_STOP_WAIT_S = 3.0  # on the ground, the board's own stop is awaited this long first
# Landed while the motors run (LL_STATUS ``flying`` reads "motors on", as AscTec drivers read
# it, so it cannot say): PX4's multicopter land detector's tests, thrust low, no vertical
# movement, held for its trigger time (LNDMC_Z_VEL_MAX 0.5 m/s, LNDMC_TRIG_TIME 1 s); "low"
# is under 0.3 of full thrust, skeye's figure, well below a hover (0.48 on the Hummingbird).
LAND_THRUST_MAX = 0.3
LAND_CLIMB_MAX_M_S = 0.5
LAND_TRIGGER_S = 1.0


def _wrap(angle_rad: float) -> float:
    wrapped = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


class LLEstimate:
    """The vehicle state from the LL board's structures (see the module docstring)."""

    def __init__(self) -> None:
        self.frames: dict[PD, Message] = {}
        self.time_s = 0.0
        self.updates = 0
        self.origin: GeoOrigin | None = None
        self._ne: tuple[float, float] = (0.0, 0.0)
        self._origin_ne: tuple[float, float] = (0.0, 0.0)  # the estimate at the first fix
        self._vel_ne: tuple[float, float] | None = None
        self._last_s: float | None = None
        self._gps_s: float | None = None
        self._snap: Snapshot | None = None
        self._quiet_since_s: float | None = None  # motors on, thrust low, not climbing

    @property
    def ready(self) -> bool:
        """LL_STATUS and IMU_CALCDATA have been read at least once."""
        return PD.LL_STATUS in self.frames and PD.IMU_CALCDATA in self.frames

    def update(self, frames: Mapping[PD, Message], time_s: float) -> None:
        """Take one poll's answers, received at ``time_s``."""
        self.frames.update(frames)
        self.time_s = time_s
        self.updates += 1
        imu = frames.get(PD.IMU_CALCDATA)
        if isinstance(imu, ImuCalcData):
            vn, ve, _ = imu_calcdata_to_si(imu).vel_ned_m_s
            if self._last_s is not None and self._vel_ne is not None:
                dt = max(0.0, time_s - self._last_s)
                n, e = self._ne
                self._ne = (n + 0.5 * (vn + self._vel_ne[0]) * dt,
                            e + 0.5 * (ve + self._vel_ne[1]) * dt)
            self._vel_ne = (vn, ve)
            self._last_s = time_s
        adv = frames.get(PD.GPS_DATA_ADVANCED)
        if isinstance(adv, GpsDataAdvanced) and adv.status == GPS_FIX_VALID:
            _, best = gps_data_advanced_to_si(adv)
            if self.origin is None:
                # The first fix: north/east go on from where the integration is (no jump).
                self.origin = GeoOrigin(best.latitude_deg, best.longitude_deg, 0.0)
                self._origin_ne = self._ne
            else:
                gn, ge, _ = self.origin.to_ned(best.latitude_deg, best.longitude_deg, 0.0)
                gn, ge = gn + self._origin_ne[0], ge + self._origin_ne[1]
                since = GPS_PULL_S if self._gps_s is None else time_s - self._gps_s
                k = min(1.0, max(0.0, since) / GPS_PULL_S)
                n, e = self._ne
                self._ne = (n + k * (gn - n), e + k * (ge - e))
            self._gps_s = time_s
        self._snap = None
        self._detect_landing(time_s)

    def _detect_landing(self, time_s: float) -> None:
        status, out = self.ll_status, self._frame(PD.CONTROLLER_OUTPUT, ControllerOutput)
        imu = self._frame(PD.IMU_CALCDATA, ImuCalcData)
        quiet = (status is not None and bool(status.motors_on)
                 and isinstance(out, ControllerOutput) and isinstance(imu, ImuCalcData)
                 and float(si_value(out, "thrust")) < LAND_THRUST_MAX
                 and abs(imu_calcdata_to_si(imu).vel_ned_m_s[2]) < LAND_CLIMB_MAX_M_S)
        if not quiet:
            self._quiet_since_s = None
        elif self._quiet_since_s is None:
            self._quiet_since_s = time_s

    @property
    def landed(self) -> bool:
        """On the ground: the motors off, or the land detector's tests held for its time."""
        status = self.ll_status
        if status is None or not status.motors_on:
            return True
        since = self._quiet_since_s
        return since is not None and self.time_s - since >= LAND_TRIGGER_S - 1e-9

    def _frame(self, pd: PD, cls: type) -> object | None:
        msg = self.frames.get(pd)
        return msg if isinstance(msg, cls) else None

    @property
    def serial_switch(self) -> bool | None:
        """The R/C's serial-interface switch, from RC_DATA (None before RC_DATA was read)."""
        rc = self._frame(PD.RC_DATA, RcData)
        if not isinstance(rc, RcData):
            return None
        return rc.channels_in[SWITCH_CHANNEL] > SWITCH_ON

    @property
    def ll_status(self) -> LlStatus | None:
        msg = self._frame(PD.LL_STATUS, LlStatus)
        return msg if isinstance(msg, LlStatus) else None

    def snapshot(self) -> Snapshot:
        """The latest state as the boards read it.

        Raises:
            LinkTimeout: nothing has been read from the board yet.
        """
        if self._snap is not None:
            return self._snap
        imu = self._frame(PD.IMU_CALCDATA, ImuCalcData)
        status = self.ll_status
        if not isinstance(imu, ImuCalcData) or status is None:
            raise LinkTimeout("the LL board has not answered a poll yet")
        si = imu_calcdata_to_si(imu)
        gps: GpsFix | None = None
        src = self._frame(PD.GPS_DATA_ADVANCED, GpsDataAdvanced) or self._frame(PD.GPS_DATA,
                                                                                GpsData)
        if isinstance(src, (GpsData, GpsDataAdvanced)):
            g = gps_data_to_si(src)
            fix = g.status == GPS_FIX_VALID
            gps = GpsFix(fix, g.num_sv, g.latitude_deg, g.longitude_deg, g.height_m,
                         (g.vel_north_m_s, g.vel_east_m_s, 0.0))
        raw = self._frame(PD.IMU_RAWDATA, ImuRawData)
        out = self._frame(PD.CONTROLLER_OUTPUT, ControllerOutput)
        mx, my, mz = si.mag_field_raw
        n, e = self._ne
        self._snap = Snapshot(
            time_s=self.time_s,
            pos_ned_m=(n, e, -si.height_m),
            rpy_rad=(si.roll_rad, si.pitch_rad, _wrap(si.yaw_rad)),
            vel_ned_m_s=si.vel_ned_m_s,
            rates_frd_rad_s=(si.roll_rate_rad_s, si.pitch_rate_rad_s, si.yaw_rate_rad_s),
            specific_force_frd_m_s2=si.acc_body_frd_m_s2,
            mag_field_frd_ut=(mx / 100.0, my / 100.0, mz / 100.0),
            mag_heading_rad=si.mag_heading_rad,
            baro_pressure_pa=float(raw.pressure) if isinstance(raw, ImuRawData) else 101325.0,
            baro_altitude_m=si.baro_height_m,
            baro_climb_m_s=si.baro_climb_rate_m_s,
            gps=gps,
            battery_v=float(si_value(status, "battery_voltage_1")),
            armed=bool(status.motors_on),
            landed=self.landed,
            thrust_fraction=(float(si_value(out, "thrust"))
                             if isinstance(out, ControllerOutput) else 0.0),
        )
        return self._snap


@dataclass(frozen=True)
class Velocity:
    """Velocity set-points (yaw frame), until ``until_s`` (None: until replaced)."""

    forward_m_s: float
    right_m_s: float
    up_m_s: float
    yaw_rate_rad_s: float
    until_s: float | None


@dataclass(frozen=True)
class Sticks:
    """Direct stick input (ground control's CTRL_INPUT through the pilot's boards)."""

    roll_rad: float
    pitch_rad: float
    yaw_rate_rad_s: float
    thrust_fraction: float
    height_mode: bool


Intent = Motion | Velocity | Sticks | None  # None: hover (or idle on the ground)


class StickPilot:
    """The pilot's motion, as one CTRL_INPUT per control cycle (see the module docstring)."""

    def __init__(self, limits: VehicleLimits, config: MotionConfig | None = None) -> None:
        self.limits = limits
        base = config or MotionConfig()
        self.config = replace(base, max_speed_m_s=limits.max_speed_m_s,
                              max_climb_m_s=limits.max_climb_m_s,
                              max_yaw_rate_rad_s=limits.max_yaw_rate_rad_s)
        self.intent: Intent = None
        self.take_off_target: Target | None = None  # a take-off waiting for the motors
        self.motors_wanted: bool | None = None  # a gesture under way: on (True) or off
        self.error: SkeyeError | None = None  # why the last motion failed
        self._landed_idle_since: float | None = None
        self._off_since: float | None = None  # when the pilot began to stop the motors

    # -- what the boards ask for -----------------------------------------------------------
    @property
    def busy(self) -> bool:
        """A take-off, fly-to, turn or landing under way (a hold or velocity is not)."""
        if self.take_off_target is not None or self.motors_wanted is False:
            return True
        intent = self.intent
        return isinstance(intent, Motion) and not intent.done

    def set(self, intent: Intent) -> None:
        self.intent = intent
        self.take_off_target = None
        self.error = None

    def take_off(self, state: NavState, altitude_m: float, armed: bool) -> None:
        n, e, _ = state.position_ned_m
        target = Target((n, e, -altitude_m), state.yaw_rad)
        self.set(None)
        if armed:
            self._climb(target, state)
        else:
            self.take_off_target = target  # the gesture first
            self.motors_wanted = True

    def _climb(self, target: Target, state: NavState) -> None:
        cfg = self.config
        self.intent = GoTo(target, cfg, name="take_off", start=state,
                           max_climb_m_s=min(cfg.take_off_speed_m_s, cfg.max_climb_m_s))

    def fly_to(self, state: NavState, target_ned_m: tuple[float, float, float],
               speed_m_s: float, yaw_rad: float | None = None) -> None:
        yaw = state.yaw_rad if yaw_rad is None else yaw_rad
        self.set(GoTo(Target(target_ned_m, yaw), self.config, start=state,
                      max_speed_m_s=speed_m_s,
                      max_climb_m_s=min(speed_m_s, self.config.max_climb_m_s)))

    def land(self, state: NavState) -> None:
        self.set(Land(self.config, state))

    # -- one control cycle -----------------------------------------------------------------
    def sticks(self, snap: Snapshot) -> CtrlInput:
        """The CTRL_INPUT for this cycle, from the latest state."""
        now = snap.time_s
        if self.motors_wanted is not None:
            if bool(snap.armed) == self.motors_wanted:
                self.motors_wanted = None
                self._off_since = None
            else:
                return self._motor_sticks(now)
        if isinstance(self.intent, Land) and snap.landed:
            self._motion(self.intent, snap)
            if self.motors_wanted is False:
                return self._motor_sticks(now)
        if self.take_off_target is not None:
            target, self.take_off_target = self.take_off_target, None
            self._climb(target, nav_state(snap))
        intent = self.intent
        if isinstance(intent, Motion):
            command = self._motion(intent, snap)
            if command is not None:
                return self.velocity_sticks(command.forward_m_s, command.right_m_s,
                                            command.up_m_s, command.yaw_rate_rad_s)
            intent = self.intent
        if isinstance(intent, Velocity):
            if intent.until_s is not None and now >= intent.until_s - 1e-9:
                self.intent = None
            else:
                return self.velocity_sticks(intent.forward_m_s, intent.right_m_s,
                                            intent.up_m_s, intent.yaw_rate_rad_s)
        if isinstance(intent, Sticks):
            if not snap.armed and intent.thrust_fraction * THRUST_MAX > 50:
                self.motors_wanted = True  # stick flight needs the motors: the gesture first
                return self._motor_sticks(now)
            if snap.armed and snap.landed and intent.thrust_fraction == 0.0:
                # Ground control stopped the motors (its own gesture): pass that on.
                if self._landed_idle_since is None:
                    self._landed_idle_since = now
                elif now - self._landed_idle_since >= GESTURE_MOTORS_OFF_AFTER_S:
                    self.motors_wanted = False
            else:
                self._landed_idle_since = None
            ctrl = ATTITUDE_STICKS | (int(CtrlBits.HEIGHT_CONTROL) if intent.height_mode else 0)
            return ctrl_input_from_si(intent.roll_rad, intent.pitch_rad, intent.yaw_rate_rad_s,
                                      intent.thrust_fraction, ctrl)
        if snap.landed and not snap.armed:
            return CtrlInput(0, 0, 0, 0, GPS_STICKS)  # idle on the ground: motors stay off
        return self.velocity_sticks(0.0, 0.0, 0.0, 0.0)  # hover: the board holds

    def _motor_sticks(self, now_s: float) -> CtrlInput:
        """Sticks that start (or stop) the motors. Stopping on the ground, the pilot first
        leaves every axis to the board (``ctrl`` 0) for ``MOTORS_STOP_WAIT_S``: landed and not
        asked to climb, the board stops its motors itself (as AscTec's does); only then the
        gesture. The gesture toggles, so sending it while the board stops the motors by itself
        (a cycle before the pilot hears of it) would start them again."""
        if self.motors_wanted is False:
            if self._off_since is None:
                self._off_since = now_s
            if now_s - self._off_since < MOTORS_STOP_WAIT_S:
                return CtrlInput(0, 0, 0, 0, 0)
        return CtrlInput(0, 0, GESTURE_YAW, GESTURE_THRUST, GPS_STICKS)

    def _motion(self, motion: Motion, snap: Snapshot) -> DriveCommand | None:
        """Step a position motion; None once it is done (then the vehicle hovers, or idles
        after a landing). A hold (after a move) never ends by itself."""
        if motion.done and not motion.holds:
            return None
        if isinstance(motion, Land) and snap.landed:
            # Touched down: the motors stop (``_motor_sticks``); the landing is done once
            # LL_STATUS says they are off.
            self.intent = None
            if snap.armed:
                self.motors_wanted = False
                return None
            motion.done = True
            return None
        if isinstance(motion, GoTo) and motion.name == "take_off":
            # Straight up: the board holds the position, the climb is ours; only the height
            # decides the arrival.
            _, _, down = motion.target.position_ned_m
            motion.target = Target((snap.pos_ned_m[0], snap.pos_ned_m[1], down),
                                   motion.target.yaw_rad)
        try:
            command = motion.update(nav_state(snap), snap.landed, snap.armed)
        except SkeyeError as exc:
            self.error = exc
            self.intent = None
            return None
        if motion.done and not motion.holds:
            if isinstance(motion, GoTo):
                # Arrived: hold the target, as sim://'s motion control does after a move (the
                # arrival is within 5 cm; the hold goes on to it).
                hold = Hold(motion.target, self.config)
                hold.name = motion.name
                hold.linear, hold.lateral = motion.linear, motion.lateral
                hold.vertical, hold.angular = motion.vertical, motion.angular
                self.intent = hold
                return self._motion(hold, snap)
            self.intent = None  # landed: idle
            return None
        if motion.name == "take_off":
            # Straight up: centred horizontal sticks, the board holds the position.
            return replace(command, forward_m_s=0.0, right_m_s=0.0)
        return command

    def velocity_sticks(self, forward_m_s: float, right_m_s: float, up_m_s: float,
                        yaw_rate_rad_s: float) -> CtrlInput:
        """GPS-mode sticks for velocities in the yaw frame (clamped to the stick range)."""
        lim = self.limits
        pitch = _count(-forward_m_s / lim.max_speed_m_s * STICK_MAX, STICK_MAX)
        roll = _count(right_m_s / lim.max_speed_m_s * STICK_MAX, STICK_MAX)
        thrust = min(THRUST_MAX, max(0, round(THRUST_MAX / 2 * (1.0 + up_m_s / lim.max_climb_m_s))))
        yaw = ctrl_input_from_si(0.0, 0.0, yaw_rate_rad_s, 0.0).yaw
        return CtrlInput(pitch, roll, yaw, thrust, GPS_STICKS)


def _count(value: float, limit: int) -> int:
    return max(-limit, min(limit, round(value)))


def nav_state(snap: Snapshot) -> NavState:
    return NavState(snap.time_s, snap.pos_ned_m, snap.rpy_rad[2], snap.vel_ned_m_s)
