"""Whole-vehicle sensors: ground truth, the onboard INS estimate, GPS and the battery monitor.

How this works: GroundTruth copies the state. INS and GPS add *correlated* errors, advanced in
sim time with exact discretisations (a Wiener process: ``b += s * sqrt(dt) * n``; a first-order
Gauss-Markov process: ``b = a * b + sigma * sqrt(1 - a^2) * n`` with ``a = exp(-dt / tau)``), so
their statistics do not depend on how often they are sampled. The INS estimate is the one the
vehicle's low-level controller flies on; it is called every control period and is kept cheap
(pure-Python floats, normal deviates pre-drawn in blocks from the sensor's Generator).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np

from skeye.errors import LocalProtocolError
from skeye.geo import to_degrees_minutes
from skeye.sim.frames import wrap_2pi
from skeye.sim.sensors.base import Param, Reading, Sensor, Vec3, WorldQuery, vec3
from skeye.sim.state import BodyState
from skeye.wire.sim import sen_layout
from skeye.wire.sim_format import Layout
from skeye.wire.sim_messages import SenBattery, SenGps, SenGroundTruth, SenIns

_TWO_PI: Final = 2.0 * math.pi


def _wrap_rpy_2pi(rpy: Vec3) -> Vec3:
    return (wrap_2pi(rpy[0]), wrap_2pi(rpy[1]), wrap_2pi(rpy[2]))


# --- GroundTruth ---------------------------------------------------------------------------


_GROUND_TRUTH_LAYOUT: Final[Layout] = sen_layout(SenGroundTruth)


@dataclass
class GroundTruthReading(Reading):
    location_ned_m: Vec3
    orientation_rad: Vec3  # roll, pitch, yaw, each in [0, 2 pi)
    velocity_ned_m_s: Vec3
    angular_velocity_frd_rad_s: Vec3

    def __init__(
        self,
        time_s: float,
        location_ned_m: Vec3,
        orientation_rad: Vec3,
        velocity_ned_m_s: Vec3,
        angular_velocity_frd_rad_s: Vec3,
    ) -> None:
        self.time_s = time_s
        self.location_ned_m = location_ned_m
        self.orientation_rad = orientation_rad
        self.velocity_ned_m_s = velocity_ned_m_s
        self.angular_velocity_frd_rad_s = angular_velocity_frd_rad_s

    def layout(self) -> Layout:
        return _GROUND_TRUTH_LAYOUT

    def values(self) -> tuple[object, ...]:
        return (
            *self.location_ned_m,
            *self.orientation_rad,
            *self.velocity_ned_m_s,
            *self.angular_velocity_frd_rad_s,
        )


class GroundTruth(Sensor[GroundTruthReading]):
    """The vehicle's true pose and velocities (body origin; the mount is not applied). No noise.

    Location and Velocity NED (m, m/s), Orientation roll, pitch, yaw wrapped to [0, 2 pi),
    AngularVelocity body p, q, r (rad/s). Default rate 50 Hz.
    """

    type_name = "GroundTruth"

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> GroundTruthReading:
        return GroundTruthReading(
            state.time_s,
            state.pos_ned_m,
            _wrap_rpy_2pi(state.rpy_rad),
            state.vel_ned_m_s,
            state.omega_frd_rad_s,
        )


# --- INS -----------------------------------------------------------------------------------


class InsEstimate:
    """The vehicle's own state estimate. Roll, pitch, yaw in [-pi, pi); NED world, FRD body."""

    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    rpy_rad: Vec3
    omega_frd_rad_s: Vec3
    pos_sigma_ned_m: Vec3 | None  # the estimator's 1-sigma per position axis; None: no covariance

    def __init__(
        self,
        pos_ned_m: Vec3,
        vel_ned_m_s: Vec3,
        rpy_rad: Vec3,
        omega_frd_rad_s: Vec3,
        pos_sigma_ned_m: Vec3 | None = None,
    ) -> None:
        self.pos_ned_m = pos_ned_m
        self.vel_ned_m_s = vel_ned_m_s
        self.rpy_rad = rpy_rad
        self.omega_frd_rad_s = omega_frd_rad_s
        self.pos_sigma_ned_m = pos_sigma_ned_m


_INS_LAYOUT: Final[Layout] = sen_layout(SenIns, ("Location", "Orientation", "Velocity"))
_INS_SIGMA_LAYOUT: Final[Layout] = sen_layout(SenIns)


@dataclass
class InsReading(Reading):
    location_ned_m: Vec3
    orientation_rad: Vec3  # [0, 2 pi)
    velocity_ned_m_s: Vec3
    position_sigma_ned_m: Vec3 | None  # the board estimator's; None for the oracle

    def __init__(
        self,
        time_s: float,
        location_ned_m: Vec3,
        orientation_rad: Vec3,
        velocity_ned_m_s: Vec3,
        position_sigma_ned_m: Vec3 | None = None,
    ) -> None:
        self.time_s = time_s
        self.location_ned_m = location_ned_m
        self.orientation_rad = orientation_rad
        self.velocity_ned_m_s = velocity_ned_m_s
        self.position_sigma_ned_m = position_sigma_ned_m

    def layout(self) -> Layout:
        return _INS_LAYOUT if self.position_sigma_ned_m is None else _INS_SIGMA_LAYOUT

    def values(self) -> tuple[object, ...]:
        sigma = self.position_sigma_ned_m
        if sigma is None:
            return (*self.location_ned_m, *self.orientation_rad, *self.velocity_ned_m_s)
        return (*self.location_ned_m, *self.orientation_rad, *self.velocity_ned_m_s, *sigma)


_INS_BLOCK_ROWS: Final = 512  # estimate() calls per block of pre-drawn normal deviates (18 each)


class INS(Sensor[InsReading]):
    """The onboard estimate, as the board reports it.

    By default the robot attaches its board estimator (:mod:`skeye.sim.estimator`, fed only by
    sensor readings) as :attr:`board` and the INS reports that estimator's output. With
    ``--estimator truth`` (robot file ``[estimator] kind = "truth"``) it is the oracle below:
    ground truth plus error processes, what skeye flew on before it had a board estimator.

    Oracle error model (per axis, all in sim time; defaults chosen so a vehicle standing still for a
    minute drifts a few centimetres, as a well-tuned MEMS INS with flow/baro aiding does):

    - position: a random walk from zero at power-up, PosWalk 0.004 m/sqrt(s) horizontally
      (1 sigma per axis after 60 s: 3.1 cm; a horizontal drift beyond 15 cm has probability
      < 1e-4) and AltWalk 0.003 m/sqrt(s) vertically (2.3 cm after 60 s), plus white noise
      PosNoise 0.003 m;
    - velocity: white noise VelNoise 0.01 m/s (no bias: the velocity loop stays unbiased);
    - attitude: white noise AttNoise 0.001 rad plus a first-order Gauss-Markov bias with time
      constant AttBiasTime 100 s and stationary sigma AttBiasSigma 0.005 rad (0.3 deg, the
      static accuracy class of a MEMS AHRS such as a VN-100's 0.5 deg) for roll and pitch and
      YawBiasSigma 0.01 rad for yaw; the bias starts drawn from its stationary distribution;
    - body rates: white noise RateNoise 0.001 rad/s plus a constant bias RateBiasSigma
      0.0005 rad/s (a calibrated gyro).

    SEN fields: Location, Orientation (wrapped to [0, 2 pi)) and, as extensions, Velocity and
    (from the board estimator, not the oracle) PositionSigma, its 1-sigma per axis.
    Default rate 50 Hz. :meth:`estimate_now` is what the low-level controller calls each
    period; :meth:`read` reports the estimate at the sample's time (the same one when the
    controller already asked at that time, so the drift advances once per instant).
    """

    type_name = "INS"
    PARAMS = (
        Param("PosWalk", 0.004, "horizontal position random walk, m/sqrt(s)"),
        Param("AltWalk", 0.003, "vertical position random walk, m/sqrt(s)"),
        Param("PosNoise", 0.003, "position white noise, m"),
        Param("VelNoise", 0.01, "velocity white noise, m/s"),
        Param("AttNoise", 0.001, "attitude white noise, rad"),
        Param("AttBiasSigma", 0.005, "roll/pitch Gauss-Markov bias, stationary sigma, rad"),
        Param("YawBiasSigma", 0.01, "yaw Gauss-Markov bias, stationary sigma, rad"),
        Param("AttBiasTime", 100.0, "attitude bias correlation time, s", exclusive=True),
        Param("RateNoise", 0.001, "body-rate white noise, rad/s"),
        Param("RateBiasSigma", 0.0005, "constant body-rate bias, 1 sigma, rad/s"),
    )

    def _setup(self) -> None:
        p = self.params
        att0 = self.rng.standard_normal(3)
        self._att_bias = [
            float(att0[0]) * p["AttBiasSigma"],
            float(att0[1]) * p["AttBiasSigma"],
            float(att0[2]) * p["YawBiasSigma"],
        ]
        rate0 = self.rng.standard_normal(3) * p["RateBiasSigma"]
        self._rate_bias: list[float] = [float(v) for v in rate0]
        self._pos_bias = [0.0, 0.0, 0.0]
        self._rows: list[list[float]] = []
        self._row_i = 0
        self._row_scale = np.array(
            [1.0] * 6 + [p["PosNoise"]] * 3 + [p["VelNoise"]] * 3 + [p["AttNoise"]] * 3
            + [p["RateNoise"]] * 3
        )
        self._dt_s = -1.0  # dt for which the coefficients below were computed
        self._k_pos = self._k_alt = self._a_att = self._k_rp = self._k_yaw = 0.0
        self._est: InsEstimate | None = None
        self._est_time_s: float | None = None
        # The board's estimator (skeye.sim.estimator) when it runs on sensor readings: the
        # stream then reports its output; None with ``--estimator truth`` (the oracle above).
        self.board: Any = None

    def _set_dt(self, dt_s: float) -> None:
        p = self.params
        root = math.sqrt(dt_s)
        self._k_pos = p["PosWalk"] * root
        self._k_alt = p["AltWalk"] * root
        a = math.exp(-dt_s / p["AttBiasTime"])
        shrink = math.sqrt(max(0.0, 1.0 - a * a))
        self._a_att = a
        self._k_rp = p["AttBiasSigma"] * shrink
        self._k_yaw = p["YawBiasSigma"] * shrink
        self._dt_s = dt_s

    @property
    def pos_bias_ned_m(self) -> Vec3:
        """The current position drift (estimate minus truth, before white noise)."""
        b = self._pos_bias
        return (b[0], b[1], b[2])

    def estimate(self, state: BodyState, dt_s: float) -> InsEstimate:
        """Advance the error processes by ``dt_s`` of sim time and return the estimate now."""
        if not dt_s >= 0.0 or dt_s == math.inf:
            raise LocalProtocolError(f"INS {self.name!r}: dt_s must be finite and >= 0, got {dt_s}")
        if abs(dt_s - self._dt_s) > 1e-12:  # steps * dt differences wobble in the last bit
            self._set_dt(dt_s)
        rows = self._rows
        i = self._row_i
        if i >= len(rows):
            rows = self._rows = (
                self.rng.standard_normal((_INS_BLOCK_ROWS, 18)) * self._row_scale
            ).tolist()
            i = 0
        self._row_i = i + 1
        # Six unit deviates for the drift processes, then twelve white noises already scaled.
        (d0, d1, d2, d3, d4, d5, np0, np1, np2, nv0, nv1, nv2,
         na0, na1, na2, nw0, nw1, nw2) = rows[i]
        pb, ab, rb = self._pos_bias, self._att_bias, self._rate_bias
        k_pos, a, k_rp = self._k_pos, self._a_att, self._k_rp
        pb0 = pb[0] = pb[0] + k_pos * d0
        pb1 = pb[1] = pb[1] + k_pos * d1
        pb2 = pb[2] = pb[2] + self._k_alt * d2
        ab0 = ab[0] = a * ab[0] + k_rp * d3
        ab1 = ab[1] = a * ab[1] + k_rp * d4
        ab2 = ab[2] = a * ab[2] + self._k_yaw * d5
        px, py, pz = state.pos_ned_m
        vx, vy, vz = state.vel_ned_m_s
        roll, pitch, yaw = state.rpy_rad
        wx, wy, wz = state.omega_frd_rad_s
        est = InsEstimate(
            (px + pb0 + np0, py + pb1 + np1, pz + pb2 + np2),
            (vx + nv0, vy + nv1, vz + nv2),
            (roll + ab0 + na0, pitch + ab1 + na1, (yaw + ab2 + na2 + math.pi) % _TWO_PI - math.pi),
            (wx + rb[0] + nw0, wy + rb[1] + nw1, wz + rb[2] + nw2),
        )
        self._est = est
        self._est_time_s = state.time_s
        return est

    def estimate_now(self, state: BodyState) -> InsEstimate:
        """The estimate at ``state.time_s``: advanced by the sim time since the last one, or
        the same one again at the same time (the board and the SEN stream share it)."""
        t = state.time_s
        est = self._est
        if est is not None and self._est_time_s == t:
            return est
        last = self._est_time_s
        return self.estimate(state, t - last if last is not None and t > last else 0.0)

    def read(self, state: BodyState, world: WorldQuery) -> InsReading:
        """The estimate at ``state.time_s`` as a reading: the board estimator's output, or
        with ``--estimator truth`` the oracle's (see :meth:`estimate_now`)."""
        board = self.board
        est = board.estimate() if board is not None else self.estimate_now(state)
        t = state.time_s
        self._last_time_s = t
        reading = InsReading(t, est.pos_ned_m, _wrap_rpy_2pi(est.rpy_rad), est.vel_ned_m_s,
                             est.pos_sigma_ned_m)
        self.last = reading
        return reading

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> InsReading:
        raise AssertionError("INS overrides read()")  # pragma: no cover


# --- GPS -----------------------------------------------------------------------------------


@dataclass
class GpsReading(Reading):
    fix: int
    satellites: int
    latitude_deg: float | None = None
    longitude_deg: float | None = None
    altitude_m: float | None = None
    velocity_ned_m_s: Vec3 | None = None

    def __init__(
        self,
        time_s: float,
        fix: int,
        satellites: int,
        latitude_deg: float | None = None,
        longitude_deg: float | None = None,
        altitude_m: float | None = None,
        velocity_ned_m_s: Vec3 | None = None,
    ) -> None:
        self.time_s = time_s
        self.fix = fix
        self.satellites = satellites
        self.latitude_deg = latitude_deg
        self.longitude_deg = longitude_deg
        self.altitude_m = altitude_m
        self.velocity_ned_m_s = velocity_ned_m_s

    def _has_fix(self) -> bool:
        return not (
            self.fix == 0
            or self.latitude_deg is None
            or self.longitude_deg is None
            or self.altitude_m is None
            or self.velocity_ned_m_s is None
        )

    def layout(self) -> Layout:
        return _GPS_FIX_LAYOUT if self._has_fix() else _GPS_NO_FIX_LAYOUT

    def values(self) -> tuple[object, ...]:
        if not self._has_fix():
            return (self.fix, self.satellites)
        assert self.latitude_deg is not None and self.longitude_deg is not None
        assert self.velocity_ned_m_s is not None
        return (
            to_degrees_minutes(self.latitude_deg, "N", "S"),
            to_degrees_minutes(self.longitude_deg, "E", "W"),
            self.latitude_deg,
            self.longitude_deg,
            self.altitude_m,
            *self.velocity_ned_m_s,
            self.fix,  # USARSim's GPSSensor ends every line with {Fix} {Satellites}
            self.satellites,
        )


_GPS_NO_FIX_LAYOUT: Final[Layout] = sen_layout(SenGps, ("Fix", "Satellites"))
_GPS_FIX_LAYOUT: Final[Layout] = sen_layout(SenGps)


class GPS(Sensor[GpsReading]):
    """A u-blox-class GPS receiver at the mount position.

    Without a geodetic origin (indoors) it reports ``{Fix 0} {Satellites 0}`` and nothing else.
    Otherwise its position error is a first-order Gauss-Markov process per axis (correlated, the
    way multipath and atmosphere errors wander): HorizontalSigma 2.12 m per axis (the u-blox
    LEA-6 data sheet's 2.5 m CEP horizontal accuracy; CEP = 1.18 sigma for a circular normal
    error), VerticalSigma 3.0 m (assumption: the data sheet gives no vertical figure),
    CorrelationTime 300 s, started from its stationary distribution. The correlation
    time is that of measured static receivers: a consumer receiver's horizontal error about
    1.5 m sigma over a 700 s recording, changing on "the order of several hundred seconds"
    (docs/physics.md, GPS row); so the error moves about 2.12 sqrt(2 / 300) = 0.17 m in a second,
    not the 0.39 m of a 30 s process. Velocity: white
    noise VelocitySigma 0.085 m/s per axis (the u-blox 6 engine's 0.1 m/s velocity accuracy,
    read as the median of the horizontal error as the 2.5 m CEP is the position's:
    0.1 / sqrt(2 ln 2); docs/physics.md, GPS row). Satellites: an integer random walk in
    [MinSatellites 9, MaxSatellites 12], one step with probability 0.05 per reading.
    Latitude/Longitude are written in USARSim's ``39,8.0341,N`` form plus decimal degrees.
    Default rate 5 Hz (the NEO-6M's maximum).

    Fix acquisition and latency: until FixTime after the first reading the receiver has no
    fix (``{Fix 0} {Satellites 0}``); default 1 s, the u-blox LEA-6 datasheet's hot-start
    time to first fix (26 s for a cold start: set FixTime 26). Each position and velocity is
    that of Latency earlier (0.2 s: one measurement epoch at the 5 Hz rate, the solution being
    reported an epoch after its measurements; the LEA-6 datasheet gives no latency figure),
    interpolated linearly between the receiver's own past readings
    (the oldest one before there is enough history).
    """

    type_name = "GPS"
    PARAMS = (
        Param("HorizontalSigma", 2.12,
              "horizontal position error, stationary sigma per axis, m (LEA-6: 2.5 m CEP)"),
        Param("VerticalSigma", 3.0, "vertical position error, stationary sigma, m"),
        Param("CorrelationTime", 300.0, "position error correlation time, s",
              exclusive=True),
        Param("VelocitySigma", 0.085,
              "velocity white noise per axis, m/s (u-blox 6: 0.1 m/s, a horizontal median)"),
        Param("MinSatellites", 9, "fewest satellites reported with a fix", 4, integer=True,
              maximum=32),
        Param("MaxSatellites", 12, "most satellites reported", 4, integer=True, maximum=32),
        Param("FixTime", 1.0, "time to first fix from the first reading, s (LEA-6 hot start)"),
        Param("Latency", 0.2, "age of the reported position and velocity, s", maximum=10.0),
    )

    def _check(self) -> None:
        lo, hi = self.params["MinSatellites"], self.params["MaxSatellites"]
        if hi < lo:
            raise self._error("MaxSatellites", f"must be >= MinSatellites ({lo:g}), got {hi:g}")

    def _setup(self) -> None:
        p = self.params
        self._sigma = np.array([p["HorizontalSigma"], p["HorizontalSigma"], p["VerticalSigma"]])
        self._error_ned_m: np.ndarray = self.rng.standard_normal(3) * self._sigma
        lo, hi = int(p["MinSatellites"]), int(p["MaxSatellites"])
        self._satellites = int(self.rng.integers(lo, hi + 1))
        self._start_s: float | None = None
        # (time, position NED, velocity NED) of past readings, oldest first.
        self._history: list[tuple[float, Vec3, Vec3]] = []

    def _delayed(self, t: float, pos: Vec3, vel: Vec3) -> tuple[Vec3, Vec3]:
        """Position and velocity of Latency ago, from the history (which this extends)."""
        hist = self._history
        hist.append((t, pos, vel))
        target = t - self.params["Latency"]
        while len(hist) > 2 and hist[1][0] <= target:
            del hist[0]
        t0, p0, v0 = hist[0]
        if target <= t0 or len(hist) == 1:
            return p0, v0
        t1, p1, v1 = hist[1]
        a = (target - t0) / (t1 - t0) if t1 > t0 else 1.0
        a = min(1.0, a)
        return (
            (p0[0] + a * (p1[0] - p0[0]), p0[1] + a * (p1[1] - p0[1]), p0[2] + a * (p1[2] - p0[2])),
            (v0[0] + a * (v1[0] - v0[0]), v0[1] + a * (v1[1] - v0[1]), v0[2] + a * (v1[2] - v0[2])),
        )

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> GpsReading:
        t = float(state.time_s)
        origin = world.geo_origin
        if origin is None:
            return GpsReading(t, 0, 0)
        pos, vel_true = self._delayed(t, self._pos_ned_m(state), vec3(state.vel_ned_m_s))
        if self._start_s is None:
            self._start_s = t
        if t < self._start_s + self.params["FixTime"] - 1e-9:
            return GpsReading(t, 0, 0)
        if dt_s > 0.0:
            a = math.exp(-dt_s / self.params["CorrelationTime"])
            self._error_ned_m = a * self._error_ned_m + self._sigma * math.sqrt(
                1.0 - a * a
            ) * self.rng.standard_normal(3)
        if self.rng.random() < 0.05:
            lo, hi = int(self.params["MinSatellites"]), int(self.params["MaxSatellites"])
            step = 1 if self.rng.random() < 0.5 else -1
            self._satellites = min(hi, max(lo, self._satellites + step))
        n, e, d = vec3(np.add(pos, self._error_ned_m))
        lat, lon, alt = origin.to_geodetic(n, e, d)
        vel = np.asarray(vel_true, dtype=float) + self.params[
            "VelocitySigma"
        ] * self.rng.standard_normal(3)
        return GpsReading(t, 1, self._satellites, lat, lon, alt, vec3(vel))


# --- Battery -------------------------------------------------------------------------------


_BATTERY_LAYOUT: Final[Layout] = sen_layout(SenBattery)


@dataclass
class BatteryReading(Reading):
    voltage_v: float
    current_a: float
    remaining: float  # fraction of capacity, 0..1

    def __init__(self, time_s: float, voltage_v: float, current_a: float, remaining: float) -> None:
        self.time_s = time_s
        self.voltage_v = voltage_v
        self.current_a = current_a
        self.remaining = remaining

    def layout(self) -> Layout:
        return _BATTERY_LAYOUT

    def values(self) -> tuple[object, ...]:
        return (self.voltage_v, self.current_a, self.remaining)


class Battery(Sensor[BatteryReading]):
    """The battery monitor: Voltage (V), Current (A), Remaining (fraction 0..1). No noise.

    The engine's battery model calls :meth:`update_battery` each step; the sensor reports the
    latest values. Sampling before the first update is an engine bug (LocalProtocolError).
    Default rate 1 Hz.
    """

    type_name = "Battery"

    def _setup(self) -> None:
        self.voltage_v: float | None = None
        self.current_a: float | None = None
        self.remaining: float | None = None

    def update_battery(self, voltage_v: float, current_a: float, remaining: float) -> None:
        """Set the values the next reading reports."""
        if not (math.isfinite(voltage_v) and voltage_v >= 0.0):
            raise LocalProtocolError(f"battery {self.name!r}: voltage {voltage_v} V is invalid")
        if not math.isfinite(current_a):
            raise LocalProtocolError(f"battery {self.name!r}: current {current_a} A is invalid")
        if not 0.0 <= remaining <= 1.0:
            raise LocalProtocolError(
                f"battery {self.name!r}: remaining {remaining} is outside [0, 1]"
            )
        self.voltage_v, self.current_a, self.remaining = (
            float(voltage_v), float(current_a), float(remaining)
        )

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> BatteryReading:
        if self.voltage_v is None or self.current_a is None or self.remaining is None:
            raise LocalProtocolError(
                f"battery {self.name!r} sampled before update_battery() was called"
            )
        return BatteryReading(float(state.time_s), self.voltage_v, self.current_a, self.remaining)
