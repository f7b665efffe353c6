"""Body-fixed sensors: accelerometer, gyroscope, magnetometer and barometer.

How this works: each reads a ground-truth quantity, expresses it in the sensor frame (the body
frame rotated by the mount) and passes it through :class:`BiasedNoise`: white noise, a constant
bias drawn once at construction, and a bias random walk in sim time. The defaults are MEMS parts
of the AscTec Hummingbird's era; each class docstring gives the numbers and where they come from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skeye.sim.frames import wrap_2pi
from skeye.sim.sensors.base import (
    BiasedNoise,
    Fields,
    Param,
    Reading,
    Sensor,
    Vec3,
    WorldQuery,
    cross3,
    vec3,
)
from skeye.sim.state import BodyState

# International Standard Atmosphere, troposphere.
ISA_T0_K = 288.15
ISA_LAPSE_K_M = 0.0065
ISA_EXPONENT = 5.25588  # g0 * M / (R * L)


def _noise_params(
    unit: str, noise: float, bias: float, walk: float, ref: str
) -> tuple[Param, Param, Param]:
    return (
        Param("NoiseSigma", noise, f"white noise per sample, 1 sigma, {unit} ({ref})"),
        Param("BiasSigma", bias, f"constant bias drawn once, 1 sigma, {unit}"),
        Param("BiasWalk", walk, f"bias random walk, {unit} per sqrt(s)"),
    )


@dataclass(frozen=True)
class AccelReading(Reading):
    proper_acceleration_m_s2: Vec3

    def fields(self) -> Fields:
        return [("ProperAcceleration", self.proper_acceleration_m_s2)]


class Accelerometer(Sensor[AccelReading]):
    """Specific force (what an accelerometer feels: a - g), sensor frame, m/s^2.

    Model: ``f_body + omega x (omega x r)`` (centripetal lever-arm term for a mount offset r;
    the tangential term needs angular acceleration, which BodyState lacks, and is ignored:
    under 0.1 m/s^2 for r = 5 cm and 2 rad/s^2), rotated into the mount frame, then
    BiasedNoise. Defaults, MPU-6050-class: noise density 400 ug/sqrt(Hz) over a ~50 Hz
    bandwidth gives NoiseSigma 0.03 m/s^2; BiasSigma 0.05 m/s^2 (5 mg residual after
    calibration; the datasheet's uncalibrated zero-g offset is +-50 mg); BiasWalk
    5e-4 m/s^2/sqrt(s). Default rate 100 Hz.
    """

    type_name = "Accelerometer"
    PARAMS = _noise_params("m/s^2", 0.03, 0.05, 5e-4, "MPU-6050: 400 ug/sqrt(Hz)")

    def _setup(self) -> None:
        p = self.params
        self._noise = BiasedNoise(self.rng, 3, p["NoiseSigma"], p["BiasSigma"], p["BiasWalk"])

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> AccelReading:
        omega = np.asarray(state.omega_frd_rad_s, dtype=float)
        f_body = np.asarray(state.specific_force_frd_m_s2, dtype=float) + cross3(
            omega, cross3(omega, self._pos_mount)
        )
        f = self._noise.corrupt(self._body_to_sensor(f_body), dt_s)
        return AccelReading(float(state.time_s), vec3(f))


@dataclass(frozen=True)
class GyroReading(Reading):
    angular_velocity_rad_s: Vec3

    def fields(self) -> Fields:
        return [("AngularVelocity", self.angular_velocity_rad_s)]


class Gyro(Sensor[GyroReading]):
    """Angular velocity, sensor frame, rad/s.

    Model: body rates rotated into the mount frame, then BiasedNoise. Defaults, MPU-6050-class:
    total RMS noise 0.05 deg/s at 100 Hz gives NoiseSigma 0.0009 rad/s; BiasSigma 0.005 rad/s
    (0.3 deg/s residual zero-rate offset after a still calibration; uncalibrated it is
    +-20 deg/s); BiasWalk 1e-4 rad/s/sqrt(s). Default rate 100 Hz.
    """

    type_name = "Gyro"
    PARAMS = _noise_params("rad/s", 0.0009, 0.005, 1e-4, "MPU-6050: 0.05 deg/s RMS")

    def _setup(self) -> None:
        p = self.params
        self._noise = BiasedNoise(self.rng, 3, p["NoiseSigma"], p["BiasSigma"], p["BiasWalk"])

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> GyroReading:
        w = self._noise.corrupt(self._body_to_sensor(state.omega_frd_rad_s), dt_s)
        return GyroReading(float(state.time_s), vec3(w))


@dataclass(frozen=True)
class CompassReading(Reading):
    magnetic_angle_rad: float
    field_ut: Vec3

    def fields(self) -> Fields:
        return [("MagneticAngle", self.magnetic_angle_rad), ("Field", self.field_ut)]


class MagneticCompass(Sensor[CompassReading]):
    """Magnetic field (sensor frame, microtesla) and the magnetic heading it implies (rad).

    Model: the world field rotated into the sensor frame, then BiasedNoise. MagneticAngle is
    the heading of the sensor's x axis from magnetic north, in [0, 2 pi): the noisy field is
    tilt-compensated with the sensor's true roll and pitch (what the board does with its
    accelerometer attitude) and the angle read from its horizontal part, so bias and noise show
    up in the heading as they would. Defaults, HMC5883L-class: noise floor 2 mG = 0.2 uT, with
    quantisation at the 1.3 Ga gain NoiseSigma 0.3 uT (about 0.015 rad of heading at a 20 uT
    horizontal field); BiasSigma 1.0 uT (residual hard iron after calibration); BiasWalk
    0.005 uT/sqrt(s) (thermal drift). Default rate 20 Hz.
    """

    type_name = "MagneticCompass"
    PARAMS = _noise_params("uT", 0.3, 1.0, 0.005, "HMC5883L: 2 mG noise floor")

    def _setup(self) -> None:
        p = self.params
        self._noise = BiasedNoise(self.rng, 3, p["NoiseSigma"], p["BiasSigma"], p["BiasWalk"])

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> CompassReading:
        rot = self._rot_sensor_to_ned(state)
        field_true = rot.T @ np.asarray(world.magnetic_field_ned_ut, dtype=float)
        b = self._noise.corrupt(field_true, dt_s)
        roll = math.atan2(rot[2, 1], rot[2, 2])
        pitch = math.asin(max(-1.0, min(1.0, -rot[2, 0])))
        cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
        # Ry(pitch) @ Rx(roll) @ b: the field in the frame that only follows the sensor's yaw.
        by = cr * b[1] - sr * b[2]
        bz = sr * b[1] + cr * b[2]
        bx = cp * b[0] + sp * bz
        heading = wrap_2pi(math.atan2(-by, bx))
        return CompassReading(float(state.time_s), heading, vec3(b))


@dataclass(frozen=True)
class BaroReading(Reading):
    pressure_pa: float
    altitude_m: float

    def fields(self) -> Fields:
        return [("Pressure", self.pressure_pa), ("Altitude", self.altitude_m)]


def isa_pressure_pa(altitude_m: float, sea_level_pa: float) -> float:
    """ISA barometric formula (troposphere): static pressure at a geometric altitude."""
    return sea_level_pa * (1.0 - ISA_LAPSE_K_M * altitude_m / ISA_T0_K) ** ISA_EXPONENT


def isa_altitude_m(pressure_pa: float, sea_level_pa: float) -> float:
    """Inverse of :func:`isa_pressure_pa`."""
    return ISA_T0_K / ISA_LAPSE_K_M * (1.0 - (pressure_pa / sea_level_pa) ** (1.0 / ISA_EXPONENT))


class Barometer(Sensor[BaroReading]):
    """Static pressure (Pa) and the altitude above sea level it implies (m, ISA).

    Model: altitude = world origin altitude (0 without a geodetic origin) minus the sensor's NED
    down; pressure from the ISA barometric formula with the world's sea-level pressure, then
    BiasedNoise; Altitude is computed back from the noisy pressure, so it carries the noise
    (about 8.3 cm per Pa near sea level). Defaults, MS5611-class: RMS noise 0.012 mbar at
    OSR 4096 plus airframe turbulence gives NoiseSigma 1.5 Pa (~12 cm); BiasSigma 10 Pa (the
    datasheet's absolute accuracy is +-150 Pa, normally removed by a ground reference: 10 Pa is
    what is left); BiasWalk 0.1 Pa/sqrt(s) (weather and thermal drift, ~7 cm a minute).
    Default rate 20 Hz.
    """

    type_name = "Barometer"
    PARAMS = _noise_params("Pa", 1.5, 10.0, 0.1, "MS5611: 0.012 mbar RMS at OSR 4096")

    def _setup(self) -> None:
        p = self.params
        self._noise = BiasedNoise(self.rng, 1, p["NoiseSigma"], p["BiasSigma"], p["BiasWalk"])

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> BaroReading:
        origin = world.geo_origin
        base_alt_m = origin.altitude_m if origin is not None else 0.0
        altitude_m = base_alt_m - float(self._pos_ned_m(state)[2])
        p0 = float(world.sea_level_pressure_pa)
        pressure = float(self._noise.corrupt(np.array([isa_pressure_pa(altitude_m, p0)]), dt_s)[0])
        return BaroReading(float(state.time_s), pressure, isa_altitude_m(pressure, p0))
