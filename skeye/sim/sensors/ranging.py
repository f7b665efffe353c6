"""Sensors that look at the world: the ultrasonic rangefinder and the optical-flow sensor.

How this works: both look along their mount frame's +z axis (an identity mount looks straight
down) and ask the world for ray distances. The sonar casts a small cone of rays and keeps the
nearest echo, one ranging per RangingTime, in whole centimetres; the flow sensor casts one ray
for the distance to the surface and its texture contrast (its SQUAL) and turns the sensor's
velocity and rotation into image motion, accumulated as integer counts between readings
(fractions carried over, so nothing is lost to rounding).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from skeye.sim.sensors.base import Param, Reading, Sensor, WorldQuery
from skeye.sim.state import BodyState, Vec3, cross, mat_t_vec, mat_vec
from skeye.wire.sim import sen_layout
from skeye.wire.sim_format import Layout
from skeye.wire.sim_messages import SenOpticalFlow, SenSonar

SQUAL_MAX: Final = 169  # ADNS-3080: SQUAL register maximum
DELTA_MIN, DELTA_MAX = -128, 127  # ADNS-3080: 8-bit signed Delta_X / Delta_Y registers
_COUNTS_LIMIT: Final = 1e9  # far beyond the registers' range: any larger term saturates them


def _saturate(counts: float) -> float:
    """``counts`` within +-1e9 (an overflowed +-inf too; never NaN here: finite factors)."""
    return min(_COUNTS_LIMIT, max(-_COUNTS_LIMIT, counts))


_SONAR_LAYOUT: Final[Layout] = sen_layout(SenSonar)


@dataclass
class SonarReading(Reading):
    range_m: float
    echo: bool  # False when nothing was within MaxRange (Range is then MaxRange)

    def __init__(self, time_s: float, range_m: float, echo: bool) -> None:
        self.time_s = time_s
        self.range_m = range_m
        self.echo = echo

    def layout(self) -> Layout:
        return _SONAR_LAYOUT

    def values(self) -> tuple[object, ...]:
        return (self.range_m,)


class Sonar(Sensor[SonarReading]):
    """An SRF10-class ultrasonic rangefinder with a cone-shaped beam, downward by default.

    Model: one ray along the boresight and BeamRays rays on a cone at half the BeamAngle; the
    nearest hit is the echo (slant distance, as time of flight measures it). Range = echo +
    white noise, clamped to [MinRange, MaxRange] and rounded to whole centimetres (the SRF10's
    result registers in its centimetre mode); MaxRange when no echo. Defaults: MinRange
    0.06 m, MaxRange 6.0 m (the SRF10's rated 6 m), BeamAngle 1.257 rad (72 deg: Devantech's
    SRF10 beam width at the -6 dB points, robot-electronics.co.uk "Ultrasonic Rangers FAQ"),
    BeamRays 8, NoiseSigma 0.0175 m (Devantech: "We quote 3-4cm" accuracy, read as 2 sigma of
    3.5 cm), rate 15 Hz.

    Ranging time (Devantech SRF10 technical specification: a ranging takes 65 ms at the
    default range setting): a ranging starts at a reading when none is in progress, measures
    the geometry of that moment, and its result is released at the first reading at least
    RangingTime later; until then every reading repeats the last released result. The first
    reading carries a ranging of its own moment: the sensor has been ranging since the board
    powered up (its power-up calibration precedes the first reading), so a vehicle standing
    on the ground reports the ground from its first line, not the "no echo" MaxRange.
    RangingTime 0 gives the ranging of the reading itself.

    Missed and multiple echoes: each ranging independently misses its echo with probability
    MissProbability (reported as no echo, MaxRange) or, with probability MultiEchoProbability,
    reports the second echo (sound that went ground - vehicle - ground: twice the range; a
    miss when that is beyond MaxRange). The SRF10 specification gives no rates for either:
    MissProbability 0.02 is an assumption (an occasional ranging lost to rotor noise and soft
    ground, an order of magnitude, not a measured figure); MultiEchoProbability defaults to 0.
    """

    type_name = "Sonar"
    PARAMS = (
        Param("MaxRange", 6.0, "longest range reported, m", exclusive=True),
        Param("MinRange", 0.06, "shortest range reported, m"),
        Param("BeamAngle", 1.257, "full cone angle of the beam, rad (SRF10: 72 deg at -6 dB)",
              maximum=math.pi,
              exclusive=True),
        Param("BeamRays", 8, "rays on the cone besides the centre ray", integer=True, maximum=64),
        Param("NoiseSigma", 0.0175, "white noise on the range, m (SRF10: 3-4 cm as 2 sigma)"),
        Param("RangingTime", 0.065, "time from the start of a ranging to its result, s "
              "(SRF10: 65 ms)", maximum=10.0),
        Param("MissProbability", 0.02, "chance that a ranging misses its echo (assumption)",
              maximum=1.0),
        Param("MultiEchoProbability", 0.0, "chance that a ranging reports the second echo",
              maximum=1.0),
    )

    def _check(self) -> None:
        p = self.params
        lo, hi = p["MinRange"], p["MaxRange"]
        if not hi > lo:
            raise self._error("MaxRange", f"must be > MinRange ({lo:g}), got {hi:g}")
        if p["BeamAngle"] >= math.pi:
            raise self._error("BeamAngle", f"must be < pi, got {p['BeamAngle']:g}")
        if p["MissProbability"] + p["MultiEchoProbability"] > 1.0:
            raise self._error(
                "MultiEchoProbability",
                f"plus MissProbability ({p['MissProbability']:g}) must be <= 1, "
                f"got {p['MultiEchoProbability']:g}",
            )

    def _setup(self) -> None:
        half = self.params["BeamAngle"] / 2.0
        rays = [(0.0, 0.0, 1.0)]
        count = int(self.params["BeamRays"])
        for k in range(count):
            phi = 2.0 * math.pi * k / count
            rays.append((math.sin(half) * math.cos(phi), math.sin(half) * math.sin(phi),
                         math.cos(half)))
        self._rays_sensor: list[Vec3] = rays  # unit vectors, sensor frame
        self._pending_start_s: float | None = None  # start of the ranging in progress
        self._pending: tuple[float, bool] = (self.params["MaxRange"], False)
        self._released: tuple[float, bool] = (self.params["MaxRange"], False)
        self._ranged = False  # whether a ranging was released yet

    def _ranging(self, state: BodyState, world: WorldQuery) -> tuple[float, bool]:
        """One ranging of the present geometry: (range in whole cm as m, echo heard)."""
        p = self.params
        lo, hi = p["MinRange"], p["MaxRange"]
        origin = self._pos_ned_m(state)
        rot = self._rot_sensor_to_ned(state)
        hits = world.ray_distances(origin, [mat_vec(rot, r) for r in self._rays_sensor], hi)
        echoes = [h for h in hits if h is not None]
        nearest = min(echoes) if echoes else None
        if nearest is None:
            return (hi, False)
        u = float(self.rng.random())
        miss = p["MissProbability"]
        if u < miss:
            return (hi, False)
        if u < miss + p["MultiEchoProbability"]:
            nearest = 2.0 * nearest
            if nearest > hi:
                return (hi, False)
        measured = nearest + p["NoiseSigma"] * float(self.rng.standard_normal())
        clamped = min(hi, max(lo, measured))
        return (round(clamped * 100.0) / 100.0, True)

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> SonarReading:
        t = state.time_s
        ranging_s = self.params["RangingTime"]
        if ranging_s <= 0.0:
            range_m, echo = self._ranging(state, world)
            return SonarReading(t, range_m, echo)
        start = self._pending_start_s
        if start is not None and t >= start + ranging_s - 1e-9:
            self._released = self._pending
            start = None
        if start is None:
            self._pending = self._ranging(state, world)
            self._pending_start_s = t
            if not self._ranged:  # the first reading: a ranging is ready (see the class)
                self._released = self._pending
                self._ranged = True
        range_m, echo = self._released
        return SonarReading(t, range_m, echo)


_FLOW_LAYOUT: Final[Layout] = sen_layout(SenOpticalFlow)


@dataclass
class FlowReading(Reading):
    delta_counts: tuple[int, int]
    quality: int
    distance_m: float | None  # the surface distance along the boresight, None if none seen

    def __init__(
        self,
        time_s: float,
        delta_counts: tuple[int, int],
        quality: int,
        distance_m: float | None,
    ) -> None:
        self.time_s = time_s
        self.delta_counts = delta_counts
        self.quality = quality
        self.distance_m = distance_m

    def layout(self) -> Layout:
        return _FLOW_LAYOUT

    def values(self) -> tuple[object, ...]:
        return (*self.delta_counts, self.quality)


class OpticalFlow(Sensor[FlowReading]):
    """An ADNS-3080-class optical mouse sensor behind a lens, looking down (mount +z).

    Delta (dx, dy) is the sensor's own motion over the surface in counts since the previous
    reading, as a mouse reports it: positive dx when the sensor moves along its +x. The raw
    sensor sees rotation too (no compensation): with v the sensor's velocity in its frame,
    w its angular velocity and r the surface distance along the boresight, the rate in rad/s is
    ``(v_x / r + w_y, v_y / r - w_x)``, so a nose-up pitch rate adds to forward motion. Counts
    per radian = Pixels * CountsPerPixel / (2 tan(FieldOfView / 2)): the ADNS-3080's 30 px
    array, 1.1 counts per pixel at 400 cpi and the 8 mm lens' 0.2025 rad (11.6 deg) field of
    view as in ArduPilot's ADNS-3080 driver, about 163 counts/rad. The rate is integrated with
    the trapezoid rule between readings (the first reading covers one nominal period), white
    noise NoiseSigma 0.5 counts is added, fractions carry to the next reading, and each
    reading saturates at the 8-bit registers' [-128, 127].

    Quality (SQUAL, 0..169) from the texture and the distance actually under the sensor: the
    boresight ray returns the distance and the RMS luminance contrast c of the surface it hits
    (``WorldQuery.ray_surface``: each surface's texture measured once when the world is built,
    :mod:`skeye.sim.surface_contrast`). SQUAL = SurfaceQuality (100) x min(1, c /
    ReferenceContrast) x the distance factor, plus QualitySigma 3 white noise, rounded and
    clipped. The distance factor is 1 in [MinRange 0.3 m, MaxRange 5.0 m] (the lens' focus and
    texture limits), falls linearly to 0 at distance 0 below (defocus) and to 0 at twice
    MaxRange above. ReferenceContrast 0.1 is the simulator's choice, not a datasheet figure (the
    ADNS-3080 datasheet gives SQUAL only as a count of features, up to 169): a surface of at
    least that contrast tracks as well as a textured floor. A plain surface (c = 0) gives
    SQUAL 0, and with Quality 0 the sensor sees nothing: Delta is (0, 0), a dropout. Lighting
    is not modelled (the sensor's own LED lights what it sees). Default rate 50 Hz.
    """

    type_name = "OpticalFlow"
    PARAMS = (
        Param("Pixels", 30, "pixels across the sensor array", 1, integer=True),
        Param("CountsPerPixel", 1.1, "counts per pixel of image motion (1.1 at 400 cpi)",
              exclusive=True),
        Param("FieldOfView", 0.202458, "lens field of view across the array, rad",
              exclusive=True, maximum=math.pi),
        Param("MinRange", 0.3, "nearest surface in focus, m"),
        Param("MaxRange", 5.0, "farthest surface with usable texture, m", exclusive=True),
        Param("SurfaceQuality", 100, "SQUAL over a textured surface in range", 0, integer=True,
              maximum=SQUAL_MAX),
        Param("ReferenceContrast", 0.1, "RMS surface contrast that gives SurfaceQuality",
              exclusive=True),
        Param("QualitySigma", 3.0, "white noise on SQUAL"),
        Param("NoiseSigma", 0.5, "white noise per reading on each Delta, counts"),
    )

    def _check(self) -> None:
        p = self.params
        if not p["MaxRange"] > p["MinRange"]:
            raise self._error(
                "MaxRange", f"must be > MinRange ({p['MinRange']:g}), got {p['MaxRange']:g}"
            )
        if p["FieldOfView"] >= math.pi:
            raise self._error("FieldOfView", f"must be < pi, got {p['FieldOfView']:g}")

    def _setup(self) -> None:
        p = self.params
        self.counts_per_rad = p["Pixels"] * p["CountsPerPixel"] / (
            2.0 * math.tan(p["FieldOfView"] / 2.0)
        )
        # Pixels or CountsPerPixel 1e308 gave infinite counts per radian: the first reading
        # raised OverflowError in round() and stopped the engine for every client.
        if not math.isfinite(self.counts_per_rad):
            key = "Pixels" if p["Pixels"] >= p["CountsPerPixel"] else "CountsPerPixel"
            raise self._error(key, f"{p[key]:g} is too large: Pixels x CountsPerPixel / "
                                   "(2 tan(FieldOfView / 2)) is not a finite number of counts "
                                   "per radian")
        self._prev_rate: tuple[float, float] | None = None
        self._carry = [0.0, 0.0]

    def _quality(self, distance_m: float | None, contrast: float) -> int:
        p = self.params
        if distance_m is None or contrast <= 0.0:
            return 0
        lo, hi = p["MinRange"], p["MaxRange"]
        if distance_m < lo:
            scale = distance_m / lo
        elif distance_m > hi:
            scale = max(0.0, 2.0 - distance_m / hi)
        else:
            scale = 1.0
        scale *= min(1.0, contrast / p["ReferenceContrast"])
        if scale <= 0.0:
            return 0
        q = p["SurfaceQuality"] * scale + p["QualitySigma"] * self.normals.take(1)[0]
        return round(min(float(SQUAL_MAX), max(0.0, q)))  # clipped first: q may be inf

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> FlowReading:
        p = self.params
        t = state.time_s
        rot_bn = state.rot_body_to_ned
        rot_sn = self._rot_sensor_to_ned(state)
        origin = self._pos_ned_m(state)
        boresight = (rot_sn[0][2], rot_sn[1][2], rot_sn[2][2])
        distance, contrast = world.ray_surface(origin, boresight, 2.0 * p["MaxRange"])
        quality = self._quality(distance, contrast)
        if quality == 0 or distance is None or distance <= 0.0:
            self._prev_rate = None
            self._carry = [0.0, 0.0]
            return FlowReading(t, (0, 0), quality, distance)
        omega_b = state.omega_frd_rad_s
        lx, ly, lz = mat_vec(rot_bn, cross(omega_b, self._pos_mount))
        vx, vy, vz = state.vel_ned_m_s
        v = mat_t_vec(rot_sn, (vx + lx, vy + ly, vz + lz))
        w = self._body_to_sensor(omega_b)
        rate = (v[0] / distance + w[1], v[1] / distance - w[0])
        prev = self._prev_rate
        if prev is None:
            prev, dt_s = rate, 1.0 / self.rate_hz
        self._prev_rate = rate
        noise = self.normals.take(2)
        delta: list[int] = []
        for axis in range(2):
            # Each term saturated far beyond the registers' range first: a huge NoiseSigma (or
            # counts per radian times a fast rate) overflowed to inf, and round(inf) raised
            # OverflowError, which stopped the engine for every client.
            total = (
                self._carry[axis]
                + _saturate(self.counts_per_rad * dt_s * 0.5 * (prev[axis] + rate[axis]))
                + _saturate(p["NoiseSigma"] * noise[axis])
            )
            counts = round(total)
            if counts > DELTA_MAX or counts < DELTA_MIN:
                counts = min(DELTA_MAX, max(DELTA_MIN, counts))
                self._carry[axis] = 0.0
            else:
                self._carry[axis] = total - counts
            delta.append(int(counts))
        return FlowReading(t, (delta[0], delta[1]), quality, distance)
