"""The onboard estimator of the emulated low-level board, fed only by sensor readings.

How this works: the board's sensors (gyro, accelerometer, magnetometer, barometer, sonar,
optical flow, GPS) are sampled by the engine at their own rates; every reading is handed to
:meth:`BoardEstimator.observe`, and the estimator never sees ground truth (it is started at the
spawn pose, as USARSim's INS is: the operator places the vehicle at a known start).

- Attitude: a Mahony complementary filter on SO(3) (Mahony, Hamel, Pflimlin, "Nonlinear
  complementary filters on the special orthogonal group", IEEE TAC 53(5), 2008), the
  complementary-filter class of that era's boards (ArduPilot's DCM is one; AscTec's LL
  firmware is closed, a complementary filter is our assumption): the quaternion is propagated
  with the bias-corrected gyro at each gyro reading; the accelerometer's "up" direction and the
  magnetometer's heading (tilt-compensated with the *estimated* roll and pitch, against the
  local declination the board is configured with) give a correction ``kp * e`` and a gyro
  bias estimate ``-ki * integral(e)``.
- Translation: per NED axis a fixed-size 3-state error-state Kalman filter (position,
  velocity, the accelerometer bias seen along that axis, which also takes up a small tilt
  error times g), written out in scalars. Predicted with the accelerometer's specific force
  rotated into NED plus gravity at each accelerometer reading. Corrected vertically by the
  sonar height (tilt-corrected, over the ground level seen at the first echo) or else the
  barometer (relative to its first reading); horizontally by optical-flow velocity (rates
  de-rotated with the gyro, scaled by the height above ground) and by GPS position and
  velocity when there is a fix (relative to the first fix: the board's home); zero velocity
  while the board is disarmed. Without flow or GPS the horizontal velocity is
  the integrated accelerometer, and it drifts as on a real vehicle.

Readings are fused when they arrive, except GPS: a receiver's fix describes where the vehicle
was ``gps_delay_s`` ago (its latency, which the board is configured with), so it is compared
with the horizontal estimate of that time, kept in a short history (``HISTORY`` entries, one
per ``HISTORY_STEP_S``; the delay is clamped to the history's span), and the correction is
applied to the estimate now and to the history (the delayed-innovation form of an inertial
navigation's GPS fusion). Other sensors' latencies show up as estimate lag. Every noise
parameter is in
:class:`skeye.robots.params.EstimatorParams` (robot file ``[estimator]``), with its source.
Hot path: plain floats, no numpy, no allocation beyond the output estimate.
"""

from __future__ import annotations

import math
from typing import Any, Final

import numpy as np

from skeye.geo import GeoOrigin
from skeye.robots.params import GRAVITY_M_S2, EstimatorParams
from skeye.sim.sensors.base import Mount
from skeye.sim.sensors.inertial import (
    Accelerometer,
    AccelReading,
    Barometer,
    BaroReading,
    CompassReading,
    Gyro,
    GyroReading,
)
from skeye.sim.sensors.navigation import GPS, GpsReading, InsEstimate
from skeye.sim.sensors.ranging import FlowReading, OpticalFlow, Sonar, SonarReading

REST_POS_NOISE_M: Final = 0.01
"""The stationary position's noise while disarmed. PX4 EKF2 fuses a fake position at the last
known one while it has no horizontal aiding (fake_pos_control.cpp): 0.01 m on the ground at
rest (0.5 m on the ground otherwise); skeye's board does it at rest with GPS too (re-anchoring
the receiver, ``_gps``)."""
REST_VEL_NOISE_M_S: Final = 0.2
"""Zero-velocity update noise while disarmed: PX4 EKF2 (zero_velocity_update.cpp)."""
M_PER_PA: Final = 1.0 / (1.225 * GRAVITY_M_S2)
"""Height per pascal near sea level (ISA density 1.225 kg/m^3): 8.3 cm/Pa."""
VARIANCE_HEADROOM: Final = 1e12
"""A sensor-derived noise figure's square times this must be finite (the filter scales its
variances by distances and times)."""
HISTORY: Final = 64  # horizontal estimate history entries (for the GPS delay)
HISTORY_STEP_S: Final = 0.01  # one entry per this much sim time: 0.63 s of history
_PI: Final = math.pi
_TWO_PI: Final = 2.0 * math.pi


def _wrap_pi(a: float) -> float:
    return (a + _PI) % _TWO_PI - _PI


class Axis:
    """One NED axis in error-state form: position, velocity and the accelerometer bias seen
    along it, with their 3x3 covariance written out as six scalars."""

    def __init__(self, pos: float, pos_var: float, vel_var: float, bias_var: float) -> None:
        self.p = pos
        self.v = 0.0
        self.b = 0.0
        self.c00, self.c01, self.c02 = pos_var, 0.0, 0.0
        self.c11, self.c12, self.c22 = vel_var, 0.0, bias_var

    def predict(self, acc: float, dt: float, acc_var: float, bias_walk_var: float) -> None:
        """x' = F x with F = [[1, dt, 0], [0, 1, -dt], [0, 0, 1]]; P' = F P F^T + Q."""
        a = acc - self.b
        dt2 = dt * dt
        self.p += self.v * dt + 0.5 * a * dt2
        self.v += a * dt
        c00, c01, c02, c11, c12, c22 = self.c00, self.c01, self.c02, self.c11, self.c12, self.c22
        self.c00 = c00 + 2.0 * dt * c01 + dt2 * c11 + 0.25 * acc_var * dt2 * dt2
        self.c01 = c01 + dt * (c11 - c02) - dt2 * c12 + 0.5 * acc_var * dt2 * dt
        self.c02 = c02 + dt * c12
        self.c11 = c11 - 2.0 * dt * c12 + dt2 * c22 + acc_var * dt2
        self.c12 = c12 - dt * c22
        self.c22 = c22 + bias_walk_var * dt

    def _correct(self, y: float, s: float, k0: float, k1: float, k2: float) -> None:
        """x += K y; P -= K K^T s (K = P h / s for a measurement of one state)."""
        self.p += k0 * y
        self.v += k1 * y
        self.b += k2 * y
        self.c00 -= k0 * k0 * s
        self.c01 -= k0 * k1 * s
        self.c02 -= k0 * k2 * s
        self.c11 -= k1 * k1 * s
        self.c12 -= k1 * k2 * s
        self.c22 -= k2 * k2 * s

    def fuse_pos(self, z: float, var: float) -> None:
        self.fuse_pos_innovation(z - self.p, var)

    def fuse_pos_innovation(self, y: float, var: float) -> tuple[float, float]:
        """Correct with a position innovation ``y``; the (position, velocity) change made."""
        s = self.c00 + var
        k0, k1 = self.c00 / s, self.c01 / s
        self._correct(y, s, k0, k1, self.c02 / s)
        return k0 * y, k1 * y

    def fuse_vel(self, z: float, var: float) -> None:
        self.fuse_vel_innovation(z - self.v, var)

    def fuse_vel_innovation(self, y: float, var: float) -> tuple[float, float]:
        """Correct with a velocity innovation ``y``; the (position, velocity) change made."""
        s = self.c11 + var
        k0, k1 = self.c01 / s, self.c11 / s
        self._correct(y, s, k0, k1, self.c12 / s)
        return k0 * y, k1 * y


class BoardEstimator:
    """Attitude (Mahony) + per-axis position/velocity Kalman filters, on sensor readings only."""

    def __init__(
        self,
        params: EstimatorParams,
        pos_ned_m: tuple[float, float, float],
        rpy_rad: tuple[float, float, float],
        declination_rad: float,
        flow_counts_per_rad: float,
    ) -> None:
        self.p = params if params.derived else with_default_sensors(params)
        self.declination_rad = declination_rad
        self.flow_counts_per_rad = flow_counts_per_rad
        self.q0, self.q1, self.q2, self.q3 = 1.0, 0.0, 0.0, 0.0
        self._set_rpy(rpy_rad[0], rpy_rad[1], rpy_rad[2])
        self.bias = [0.0, 0.0, 0.0]  # estimated gyro bias, rad/s
        self.err = [0.0, 0.0, 0.0]  # pending attitude correction (body), from accel + mag
        self.omega = [0.0, 0.0, 0.0]  # last bias-corrected gyro reading, rad/s
        self.gyro_t: float | None = None
        self.acc_t: float | None = None
        self.flow_t: float | None = None
        bias_var = params.accel_bias_init_m_s2 * params.accel_bias_init_m_s2
        self.axes = [
            Axis(pos_ned_m[0], 0.01, 0.01, bias_var),
            Axis(pos_ned_m[1], 0.01, 0.01, bias_var),
            Axis(pos_ned_m[2], 0.01, 0.01, bias_var),
        ]
        self.ground_d: float | None = None  # NED down of the ground seen at the first echo
        self.sonar_agl_m: float | None = None  # last valid sonar height above ground
        self.sonar_t = -math.inf
        self.baro_offset: float | None = None  # baro altitude + down, set at the first reading
        self.home: GeoOrigin | None = None
        self.home_ned: tuple[float, float] = (0.0, 0.0)
        self.gps_t = -math.inf
        self.rest_t = -math.inf  # last stationary update
        self.rest_seen_t = -math.inf  # last tick the board was at rest (disarmed)
        self.rest_pos: tuple[float, float] | None = None  # where the vehicle came to rest
        # Height above the baro's first reading on pressure alone (with the accelerometer):
        # what the AscTec LL board's height mode holds.
        self.press = Axis(pos_ned_m[2], 0.01, 0.01, bias_var)
        self.sonar_half_beam_rad = 0.0  # the sonar's beam half-angle (from its figures)
        self.flow_used = 0
        # History of the horizontal estimate (ring buffer): time, north/east position, velocity.
        self.hist_t = [-math.inf] * HISTORY
        self.hist_n = [0.0] * HISTORY
        self.hist_e = [0.0] * HISTORY
        self.hist_vn = [0.0] * HISTORY
        self.hist_ve = [0.0] * HISTORY
        self.hist_i = 0  # next slot
        self.mag_yaw_err = 0.0  # compass heading minus estimated yaw, times compass_gain
        self._est: InsEstimate | None = None

    # -- attitude ------------------------------------------------------------------------
    def _set_rpy(self, roll: float, pitch: float, yaw: float) -> None:
        cr, sr = math.cos(roll / 2), math.sin(roll / 2)
        cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
        cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
        self.q0 = cr * cp * cy + sr * sp * sy
        self.q1 = sr * cp * cy - cr * sp * sy
        self.q2 = cr * sp * cy + sr * cp * sy
        self.q3 = cr * cp * sy - sr * sp * cy
        self._est = None

    def align_at_rest(
        self,
        gyro_rad_s: list[tuple[float, float, float]],
        specific_force_m_s2: list[tuple[float, float, float]],
    ) -> None:
        """The board's power-up calibration, from gyro and accelerometer readings taken while
        the vehicle stood still: the gyro bias is their mean (ArduPilot's start-up gyro
        calibration, INS_GYR_CAL), roll and pitch are levelled on the mean specific force
        (PX4 EKF2's initial tilt alignment); the heading is kept."""
        if gyro_rad_s:
            n = float(len(gyro_rad_s))
            self.bias = [sum(w[i] for w in gyro_rad_s) / n for i in range(3)]
        if specific_force_m_s2:
            n = float(len(specific_force_m_s2))
            fx, fy, fz = (sum(f[i] for f in specific_force_m_s2) / n for i in range(3))
            norm = math.sqrt(fx * fx + fy * fy + fz * fz)
            if 0.5 * GRAVITY_M_S2 < norm < 1.5 * GRAVITY_M_S2:
                _, _, yaw = self.rpy()
                self._set_rpy(math.atan2(-fy, -fz), math.atan2(fx, math.sqrt(fy * fy + fz * fz)),
                              yaw)

    def rot(self) -> tuple[float, float, float, float, float, float, float, float, float]:
        """The body-to-NED rotation, row major."""
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        return (
            1 - 2 * (q2 * q2 + q3 * q3), 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2),
            2 * (q1 * q2 + q0 * q3), 1 - 2 * (q1 * q1 + q3 * q3), 2 * (q2 * q3 - q0 * q1),
            2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), 1 - 2 * (q1 * q1 + q2 * q2),
        )

    def rpy(self) -> tuple[float, float, float]:
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        roll = math.atan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2))
        s = 2 * (q0 * q2 - q3 * q1)
        pitch = math.asin(s if -1.0 < s < 1.0 else (1.0 if s > 0 else -1.0))
        yaw = math.atan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2 * q2 + q3 * q3))
        return roll, pitch, yaw

    def _gyro(self, t: float, w: tuple[float, float, float]) -> None:
        b, e, p = self.bias, self.err, self.p
        last = self.gyro_t
        self.gyro_t = t
        wx, wy, wz = w[0] - b[0], w[1] - b[1], w[2] - b[2]
        self.omega = [wx, wy, wz]
        if last is None or t <= last:
            return
        dt = t - last
        # Bias from the integral of the error (Mahony's passive filter: b_dot = -ki e).
        ki = p.attitude_ki
        b[0] = b[0] - ki * e[0] * dt  # not -=: a list item's -= is a generic call in mypyc
        b[1] = b[1] - ki * e[1] * dt
        b[2] = b[2] - ki * e[2] * dt
        kp = p.attitude_kp
        wx += kp * e[0]
        wy += kp * e[1]
        wz += kp * e[2]
        q0, q1, q2, q3 = self.q0, self.q1, self.q2, self.q3
        h = 0.5 * dt
        n0 = q0 + h * (-q1 * wx - q2 * wy - q3 * wz)
        n1 = q1 + h * (q0 * wx + q2 * wz - q3 * wy)
        n2 = q2 + h * (q0 * wy - q1 * wz + q3 * wx)
        n3 = q3 + h * (q0 * wz + q1 * wy - q2 * wx)
        norm = 1.0 / math.sqrt(n0 * n0 + n1 * n1 + n2 * n2 + n3 * n3)
        self.q0, self.q1, self.q2, self.q3 = n0 * norm, n1 * norm, n2 * norm, n3 * norm

    def _accel(self, t: float, f: tuple[float, float, float]) -> None:
        fx, fy, fz = f
        r = self.rot()
        # Translation: specific force to NED, plus gravity.
        last = self.acc_t
        self.acc_t = t
        if last is not None and t > last:
            dt = t - last
            var = self.p.accel_noise_m_s2 * self.p.accel_noise_m_s2
            walk = self.p.accel_bias_walk_m_s3 * self.p.accel_bias_walk_m_s3
            # A horizontal bias state also carries g times the attitude's tilt error, which
            # wanders as the gyro's noise integrates (EKF2's tilt states, driven by
            # EKF2_GYR_NOISE); vertically a tilt error is second order.
            tilt = GRAVITY_M_S2 * self.p.tilt_noise_rad_s
            walk_h = walk + tilt * tilt
            ax = self.axes
            ax[0].predict(r[0] * fx + r[1] * fy + r[2] * fz, dt, var, walk_h)
            ax[1].predict(r[3] * fx + r[4] * fy + r[5] * fz, dt, var, walk_h)
            a_down = r[6] * fx + r[7] * fy + r[8] * fz + GRAVITY_M_S2
            ax[2].predict(a_down, dt, var, walk)
            self.press.predict(a_down, dt, var, walk)
            last_i = (self.hist_i - 1) % HISTORY
            if t - self.hist_t[last_i] >= HISTORY_STEP_S - 1e-9:
                i = self.hist_i
                self.hist_t[i] = t
                self.hist_n[i], self.hist_e[i] = ax[0].p, ax[1].p
                self.hist_vn[i], self.hist_ve[i] = ax[0].v, ax[1].v
                self.hist_i = (i + 1) % HISTORY
        # Attitude: measured up (the specific force at rest is -g, i.e. up) against the
        # estimated up (NED -z in the body frame).
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        if norm < 0.5 * GRAVITY_M_S2 or norm > 1.5 * GRAVITY_M_S2:
            return  # not near 1 g: the direction says little about the tilt
        mx, my, mz = fx / norm, fy / norm, fz / norm
        ux, uy, uz = -r[6], -r[7], -r[8]
        e = self.err
        e[0] = my * uz - mz * uy
        e[1] = mz * ux - mx * uz
        e[2] = mx * uy - my * ux
        self._mag_err_into(e)

    def _mag_err_into(self, e: list[float]) -> None:
        m = self.mag_yaw_err
        if m == 0.0:
            return
        r = self.rot()
        # A yaw error about NED down, expressed in the body frame (R^T (0, 0, m)).
        e[0] = e[0] + r[6] * m  # not +=: a list item's += is a generic call in mypyc
        e[1] = e[1] + r[7] * m
        e[2] = e[2] + r[8] * m

    def _compass(self, field: tuple[float, float, float]) -> None:
        bx, by, bz = field
        if bx * bx + by * by + bz * bz <= 0.0:
            return
        roll, pitch, _ = self.rpy()
        cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
        hy = cr * by - sr * bz
        hz = sr * by + cr * bz
        hx = cp * bx + sp * hz
        heading = math.atan2(-hy, hx) + self.declination_rad  # true heading of the body x axis
        _, _, yaw = self.rpy()
        self.mag_yaw_err = self.p.compass_gain * _wrap_pi(heading - yaw)

    # -- height, velocity, position ------------------------------------------------------
    def _sonar(self, r: SonarReading) -> None:
        if not r.echo:
            self.sonar_agl_m = None
            return
        rot = self.rot()
        # Over flat ground the nearest echo of a cone comes from the ray nearest the vertical:
        # straight down while the tilt is within the beam's half-angle, else from its edge.
        tilt = math.acos(max(-1.0, min(1.0, rot[8])))
        agl = r.range_m * math.cos(max(0.0, tilt - self.sonar_half_beam_rad))
        down = self.axes[2]
        if self.ground_d is None:
            self.ground_d = down.p + agl
        self.sonar_agl_m = agl
        self.sonar_t = r.time_s
        down.fuse_pos(self.ground_d - agl, self.p.sonar_noise_m * self.p.sonar_noise_m)

    def _baro(self, r: BaroReading) -> None:
        down = self.axes[2]
        if self.baro_offset is None:
            self.baro_offset = r.altitude_m + down.p
            self.press.p = down.p
            return
        var = self.p.baro_noise_m * self.p.baro_noise_m
        self.press.fuse_pos(self.baro_offset - r.altitude_m, var)
        if r.time_s - self.sonar_t < 0.5:
            return  # the sonar is the height reference while it has an echo
        down.fuse_pos(self.baro_offset - r.altitude_m, var)

    def pressure_down(self) -> tuple[float, float]:
        """The pressure-altitude height (NED down, m) and its rate (m/s): what the AscTec LL
        board's height mode holds (barometer and accelerometer, never the sonar)."""
        return self.press.p, self.press.v

    def height_above_ground_m(self) -> float | None:
        """The height over the ground the flow looks at: sonar-aided, None when unknown."""
        if self.ground_d is None:
            return None
        return self.ground_d - self.axes[2].p

    def _flow(self, r: FlowReading) -> None:
        last = self.flow_t
        self.flow_t = r.time_s
        if last is None or r.time_s <= last or r.quality < self.p.flow_min_quality:
            return
        h = self.height_above_ground_m()
        if h is None or h < self.p.flow_min_height_m or r.time_s - self.sonar_t > 1.0:
            return
        dt = r.time_s - last
        rot = self.rot()
        tilt = rot[8]
        if tilt < 0.7:
            return
        dist = h / tilt
        k = 1.0 / (self.flow_counts_per_rad * dt)
        w = self.omega
        # The sensor sees (v_x / r + w_y, v_y / r - w_x): de-rotate, then scale by the range.
        vbx = (r.delta_counts[0] * k - w[1]) * dist
        vby = (r.delta_counts[1] * k + w[0]) * dist
        ax = self.axes
        vn, ve, vd = ax[0].v, ax[1].v, ax[2].v
        vbz = rot[2] * vn + rot[5] * ve + rot[8] * vd
        var = (self.p.flow_noise_rad_s * dist) ** 2
        ax[0].fuse_vel(rot[0] * vbx + rot[1] * vby + rot[2] * vbz, var)
        ax[1].fuse_vel(rot[3] * vbx + rot[4] * vby + rot[5] * vbz, var)
        self.flow_used += 1

    def _gps(self, r: GpsReading) -> None:
        lat, lon, alt, vel = r.latitude_deg, r.longitude_deg, r.altitude_m, r.velocity_ned_m_s
        if r.fix == 0 or lat is None or lon is None or alt is None or vel is None:
            return
        ax = self.axes
        home = self.home
        # The estimate when the fix was taken, against the fix; the corrections apply now and
        # to every history entry (so the next fix is not compared with uncorrected states).
        then_n, then_e, then_vn, then_ve = self._history_at(r.time_s - self.p.gps_delay_s)
        if home is None:  # the first fix is home, where the estimate was when it was taken
            home = self.home = GeoOrigin(lat, lon, alt)
            self.home_ned = (then_n, then_e)
        n, e, _ = home.to_ned(lat, lon, alt)
        if self.resting(r.time_s):
            # Standing still, any motion of the fix is the receiver's own error: the board
            # re-anchors home to the stationary estimate (the fix's offset moves with the
            # error), so the estimate stays put and nothing jumps when the motors start.
            self.home_ned = (then_n - n, then_e - e)
        pv = self.p.gps_pos_noise_m * self.p.gps_pos_noise_m
        vv = self.p.gps_vel_noise_m_s * self.p.gps_vel_noise_m_s
        dpn, dvn = ax[0].fuse_pos_innovation(self.home_ned[0] + n - then_n, pv)
        dpe, dve = ax[1].fuse_pos_innovation(self.home_ned[1] + e - then_e, pv)
        a, b = ax[0].fuse_vel_innovation(vel[0] - (then_vn + dvn), vv)
        dpn, dvn = dpn + a, dvn + b
        a, b = ax[1].fuse_vel_innovation(vel[1] - (then_ve + dve), vv)
        dpe, dve = dpe + a, dve + b
        for i in range(HISTORY):
            self.hist_n[i] = self.hist_n[i] + dpn  # not +=: generic in mypyc on list items
            self.hist_e[i] = self.hist_e[i] + dpe
            self.hist_vn[i] = self.hist_vn[i] + dvn
            self.hist_ve[i] = self.hist_ve[i] + dve
        self.gps_t = r.time_s

    def _history_at(self, t: float) -> tuple[float, float, float, float]:
        """The horizontal estimate (north, east, v north, v east) at time ``t``, interpolated
        in the history; the newest entry for a time after it, the oldest for one before it."""
        ax = self.axes
        newest = (self.hist_i - 1) % HISTORY
        if t >= self.hist_t[newest]:
            return ax[0].p, ax[1].p, ax[0].v, ax[1].v
        later = newest
        for k in range(1, HISTORY):
            i = (newest - k) % HISTORY
            ti = self.hist_t[i]
            if ti == -math.inf:
                break
            if ti <= t:
                t1 = self.hist_t[later]
                w = (t - ti) / (t1 - ti) if t1 > ti else 0.0
                return (self.hist_n[i] + w * (self.hist_n[later] - self.hist_n[i]),
                        self.hist_e[i] + w * (self.hist_e[later] - self.hist_e[i]),
                        self.hist_vn[i] + w * (self.hist_vn[later] - self.hist_vn[i]),
                        self.hist_ve[i] + w * (self.hist_ve[later] - self.hist_ve[i]))
            later = i
        return (self.hist_n[later], self.hist_e[later], self.hist_vn[later],
                self.hist_ve[later])

    def resting(self, time_s: float) -> bool:
        """Whether the board was at rest (disarmed) within the last 0.1 s."""
        return time_s - self.rest_seen_t < 0.1

    def at_rest(self, time_s: float) -> None:
        """The board is disarmed (motors off), so at rest. Every 0.2 s: zero velocity with
        0.2 m/s noise (PX4 EKF2's zero-velocity update, zero_velocity_update.cpp) and the
        horizontal position where it came to rest with 0.01 m noise (EKF2's fake-position
        fusion at rest on the ground, fake_pos_control.cpp, which EKF2 uses only without
        horizontal aiding; here also with GPS, which meanwhile re-anchors to it, ``_gps``).
        So a parked vehicle's estimate does not wander with the receiver's error."""
        if not self.resting(time_s):
            self.rest_pos = None
        self.rest_seen_t = time_s
        if time_s - self.rest_t < 0.2:
            return
        self.rest_t = time_s
        self._est = None
        ax = self.axes
        if self.rest_pos is None:
            self.rest_pos = (ax[0].p, ax[1].p)
        vel_var = REST_VEL_NOISE_M_S * REST_VEL_NOISE_M_S
        pos_var = REST_POS_NOISE_M * REST_POS_NOISE_M
        for axis in ax:
            axis.fuse_vel(0.0, vel_var)
        self.press.fuse_vel(0.0, vel_var)
        ax[0].fuse_pos(self.rest_pos[0], pos_var)
        ax[1].fuse_pos(self.rest_pos[1], pos_var)

    def has_gps_fix(self, time_s: float) -> bool:
        """Whether a GPS fix was fused within the last second."""
        return time_s - self.gps_t < 1.0

    # -- in and out ----------------------------------------------------------------------
    def observe(self, reading: object) -> None:
        """Fuse one sensor reading (any type; the ones the board has no use for are ignored)."""
        self._est = None
        if isinstance(reading, GyroReading):
            self._gyro(reading.time_s, reading.angular_velocity_rad_s)
        elif isinstance(reading, AccelReading):
            self._accel(reading.time_s, reading.proper_acceleration_m_s2)
        elif isinstance(reading, CompassReading):
            self._compass(reading.field_ut)
        elif isinstance(reading, BaroReading):
            self._baro(reading)
        elif isinstance(reading, SonarReading):
            self._sonar(reading)
        elif isinstance(reading, FlowReading):
            self._flow(reading)
        elif isinstance(reading, GpsReading):
            self._gps(reading)

    def estimate(self) -> InsEstimate:
        """The estimate now (cached until the next reading)."""
        est = self._est
        if est is None:
            ax = self.axes
            w = self.omega
            est = self._est = InsEstimate(
                (ax[0].p, ax[1].p, ax[2].p),
                (ax[0].v, ax[1].v, ax[2].v),
                self.rpy(),
                (w[0], w[1], w[2]),
                (math.sqrt(max(0.0, ax[0].c00)), math.sqrt(max(0.0, ax[1].c00)),
                 math.sqrt(max(0.0, ax[2].c00))),
            )
        return est


def from_sensor_figures(
    params: EstimatorParams,
    accel: Accelerometer,
    gyro: Gyro,
    baro: Barometer,
    sonar: Sonar,
    flow: OpticalFlow,
    gps: GPS,
    rotors: int = 4,
) -> EstimatorParams:
    """The estimator's settings with every one left to the sensors (NaN) filled in from the
    figures of the sensors the board reads: the filter is told what its sensors deliver
    (docs/physics.md, "Onboard estimator"). A setting the robot file gave is kept.

    - accel_noise_m_s2: the accelerometer's white noise and the in-flight vibration its readings
      carry at its rate and the vibration's reference rotor speed (hover), per axis,
      root-sum-square;
    - tilt_noise_rad_s: the gyro's angle random walk, its noise and vibration per reading
      times sqrt(1 / rate) (rad/sqrt(s): how the tilt error of integrating it wanders);
    - baro_noise_m: the barometer's white noise (Pa) at 8.3 cm/Pa;
    - sonar_noise_m: the sonar's noise and its whole-centimetre rounding (1 cm / sqrt(12));
    - flow_noise_rad_s: the flow sensor's count noise per reading over counts-per-radian and
      its period, with the gyro's (its rates are de-rotated with the gyro);
    - gps_pos_noise_m, gps_vel_noise_m_s, gps_delay_s: the receiver's HorizontalSigma,
      VelocitySigma and Latency.
    """
    a, g, b, s, f, r = (accel.params, gyro.params, baro.params, sonar.params, flow.params,
                        gps.params)
    gyro_total = math.hypot(g["NoiseSigma"], gyro.vibration.rms_sampled(rotors, gyro.rate_hz))
    flow_rate = f["NoiseSigma"] / (flow.counts_per_rad / flow.rate_hz)
    derived = {
        "accel_noise_m_s2": math.hypot(a["NoiseSigma"],
                                       accel.vibration.rms_sampled(rotors, accel.rate_hz)),
        "tilt_noise_rad_s": gyro_total * math.sqrt(1.0 / gyro.rate_hz),
        "baro_noise_m": b["NoiseSigma"] * M_PER_PA,
        "sonar_noise_m": math.hypot(s["NoiseSigma"], 0.01 / math.sqrt(12.0)),
        "flow_noise_rad_s": math.hypot(flow_rate, gyro_total),
        "gps_pos_noise_m": r["HorizontalSigma"],
        "gps_vel_noise_m_s": r["VelocitySigma"],
        "gps_delay_s": r["Latency"],
    }

    vibration = ("NoiseSigma", "VibrationRotor", "VibrationBladePass", "VibrationBroadband")
    sources: dict[str, tuple[Any, tuple[str, ...]]] = {
        "accel_noise_m_s2": (accel, vibration),
        "tilt_noise_rad_s": (gyro, vibration),
        "baro_noise_m": (baro, ("NoiseSigma",)),
        "sonar_noise_m": (sonar, ("NoiseSigma",)),
        "flow_noise_rad_s": (flow, ("NoiseSigma",)) if flow_rate >= gyro_total
        else (gyro, vibration),
        "gps_pos_noise_m": (gps, ("HorizontalSigma",)),
        "gps_vel_noise_m_s": (gps, ("VelocitySigma",)),
        "gps_delay_s": (gps, ("Latency",)),
    }

    def pick(name: str) -> float:
        value = float(getattr(params, name))
        if not math.isnan(value):
            return value
        value = derived[name]
        # The filter squares it (a variance) and scales it by distances and times: a sensor
        # noise of 1e308 made INIT refuse "estimator: flow_noise_rad_s ... got inf" (no file,
        # no sensor key), or loaded and raised OverflowError in the filter (the engine stopped
        # for every client) or sent STEP's ERR "PositionSigma: inf" at every step.
        if not math.isfinite(value * value * VARIANCE_HEADROOM):
            sensor, keys = sources[name]
            key = max(keys, key=lambda k: float(sensor.params[k]))
            raise sensor._error(key, f"{sensor.params[key]:g} is too large: the board's "
                                     f"estimator's {name} from it, {value:g}, squared is not a "
                                     "finite number with room to spare")
        return value

    # Built field by field (not dataclasses.replace): mypyc compiles both dataclasses.
    return EstimatorParams(
        kind=params.kind,
        attitude_kp=params.attitude_kp,
        attitude_ki=params.attitude_ki,
        compass_gain=params.compass_gain,
        accel_noise_m_s2=pick("accel_noise_m_s2"),
        accel_bias_init_m_s2=params.accel_bias_init_m_s2,
        accel_bias_walk_m_s3=params.accel_bias_walk_m_s3,
        baro_noise_m=pick("baro_noise_m"),
        sonar_noise_m=pick("sonar_noise_m"),
        flow_noise_rad_s=pick("flow_noise_rad_s"),
        flow_min_quality=params.flow_min_quality,
        flow_min_height_m=params.flow_min_height_m,
        gps_pos_noise_m=pick("gps_pos_noise_m"),
        gps_vel_noise_m_s=pick("gps_vel_noise_m_s"),
        gps_delay_s=pick("gps_delay_s"),
        tilt_noise_rad_s=pick("tilt_noise_rad_s"),
    )


SENSOR_BUILDERS: Final[dict[str, Any]] = {
    "Accelerometer": Accelerometer, "Gyro": Gyro, "Barometer": Barometer, "Sonar": Sonar,
    "OpticalFlow": OpticalFlow, "GPS": GPS,
}
"""The board's sensor classes, for :func:`with_default_sensors`."""


def with_default_sensors(params: EstimatorParams) -> EstimatorParams:
    """:func:`from_sensor_figures` for a board with every sensor at its class defaults (an
    estimator built on its own, outside a robot)."""
    rng = np.random.default_rng(0)
    mount = Mount()

    def make(type_name: str) -> Any:
        return SENSOR_BUILDERS[type_name](type_name, mount, {}, rng)

    return from_sensor_figures(params, make("Accelerometer"), make("Gyro"), make("Barometer"),
                               make("Sonar"), make("OpticalFlow"), make("GPS"))
