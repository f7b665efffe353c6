"""Body-fixed sensors: accelerometer, gyroscope, magnetometer and barometer.

How this works: each reads a ground-truth quantity, expresses it in the sensor frame (the body
frame rotated by the mount) and passes it through :class:`BiasedNoise`: white noise, a constant
bias drawn once at construction, and a bias random walk in sim time. The defaults are MEMS parts
of the AscTec Hummingbird's era; each class docstring gives the numbers and where they come from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np

from skeye.sim.frames import wrap_2pi
from skeye.sim.sensors.base import (
    BiasedNoise,
    Param,
    Reading,
    Sensor,
    Vec3,
    WorldQuery,
)
from skeye.sim.sensors.vibration import MAX_ROTORS, RotorVibration, clip3
from skeye.sim.state import BodyState, Mat3, cross, mat_t_vec, mat_vec
from skeye.sim.vehicle import ground_effect_factor
from skeye.wire.sim import sen_layout
from skeye.wire.sim_format import Layout
from skeye.wire.sim_messages import SenAccelerometer, SenBarometer, SenGyro, SenMagneticCompass

# International Standard Atmosphere, troposphere.
ISA_T0_K: Final = 288.15
ISA_LAPSE_K_M: Final = 0.0065
ISA_EXPONENT: Final = 5.25588  # g0 * M / (R * L)


def _noise_params(
    unit: str, noise: float, bias: float, walk: float, ref: str
) -> tuple[Param, Param, Param]:
    return (
        Param("NoiseSigma", noise, f"white noise per sample, 1 sigma, {unit} ({ref})"),
        Param("BiasSigma", bias, f"constant bias drawn once, 1 sigma, {unit}"),
        Param("BiasWalk", walk, f"bias random walk, {unit} per sqrt(s)"),
    )


def _axis_params(scale: float, misalignment: float, ref: str) -> tuple[Param, Param]:
    return (
        Param("ScaleSigma", scale, f"scale-factor error per axis, drawn once, 1 sigma ({ref})"),
        Param("MisalignmentSigma", misalignment,
              f"cross-axis sensitivity per axis pair, drawn once, 1 sigma, rad ({ref})"),
    )


HOVER_SPEED_RAD_S: Final = 441.7
"""The reference rotor speed of the vibration amplitudes: the Hummingbird's hover (physics.md)."""


def _vibration_params(
    unit: str, rotor: float, blade: float, broadband: float, limit: float, ref: str
) -> tuple[Param, ...]:
    return (
        Param("VibrationRotor", rotor,
              f"vibration line at the rotor frequency, amplitude per rotor per axis at "
              f"VibrationSpeed, {unit} ({ref})"),
        Param("VibrationBladePass", blade,
              f"vibration line at the blade-pass frequency, amplitude per rotor per axis at "
              f"VibrationSpeed, {unit} ({ref})"),
        Param("VibrationBroadband", broadband,
              f"broadband vibration, RMS per axis at VibrationSpeed, {unit} ({ref})"),
        Param("VibrationSpeed", HOVER_SPEED_RAD_S,
              "rotor speed at which the vibration amplitudes are given, rad/s", exclusive=True),
        Param("Blades", 2, "blades per rotor (blade-pass = blades x rotor frequency)", 1,
              integer=True, maximum=8),
        Param("Bandwidth", 330.0, "the sensor's low-pass corner (first order), Hz; 0: none"),
        Param("Range", limit, f"measurement range, +-{unit}: readings clip there; 0: none"),
    )


def _vibration(sensor: Sensor[Any]) -> RotorVibration:
    """The sensor's vibration model; amplitudes whose combined power over the most rotors a
    vehicle may have is not a finite number are refused (they overflowed in the RMS)."""
    p = sensor.params
    rotor, blade, broad = p["VibrationRotor"], p["VibrationBladePass"], p["VibrationBroadband"]
    if not math.isfinite(MAX_ROTORS * (rotor * rotor + blade * blade) / 2.0 + broad * broad):
        key = max(("VibrationRotor", "VibrationBladePass", "VibrationBroadband"), key=p.__getitem__)
        raise sensor._error(key, f"{p[key]:g} is too large: the vibration's RMS over "
                                 f"{MAX_ROTORS} rotors is not a finite number")
    return RotorVibration(sensor.rng, p["VibrationRotor"], p["VibrationBladePass"],
                          p["VibrationBroadband"], p["VibrationSpeed"], int(p["Blades"]),
                          p["Bandwidth"], sensor.normals)


def axis_errors(rng: np.random.Generator, scale_sigma: float, misalignment_sigma: float) -> Mat3:
    """A part's scale-factor and misalignment matrix, drawn once (at turn-on) from its seed.

    ``I + diag(s) + M``: s per axis ~ N(0, scale_sigma), the off-diagonal entries of M
    ~ N(0, misalignment_sigma) (cross-axis sensitivity: the small-angle misalignment of each
    sensing axis toward the other two). Nine normal deviates, row by row.
    """
    d = rng.standard_normal(9).tolist()
    s, m = scale_sigma, misalignment_sigma
    return (
        (1.0 + s * d[0], m * d[1], m * d[2]),
        (m * d[3], 1.0 + s * d[4], m * d[5]),
        (m * d[6], m * d[7], 1.0 + s * d[8]),
    )


_ACCEL_LAYOUT: Final[Layout] = sen_layout(SenAccelerometer)


@dataclass
class AccelReading(Reading):
    proper_acceleration_m_s2: Vec3

    def __init__(self, time_s: float, proper_acceleration_m_s2: Vec3) -> None:
        self.time_s = time_s
        self.proper_acceleration_m_s2 = proper_acceleration_m_s2

    def layout(self) -> Layout:
        return _ACCEL_LAYOUT

    def values(self) -> tuple[object, ...]:
        return self.proper_acceleration_m_s2


class Accelerometer(Sensor[AccelReading]):
    """Specific force (what an accelerometer feels: a - g), sensor frame, m/s^2.

    Model: ``f_body + omega x (omega x r)`` (centripetal lever-arm term for a mount offset r;
    the tangential term needs angular acceleration, which BodyState lacks, and is ignored:
    under 0.1 m/s^2 for r = 5 cm and 2 rad/s^2), rotated into the mount frame, then
    BiasedNoise. Defaults, MPU-6050-class: noise density 400 ug/sqrt(Hz) over a ~50 Hz
    bandwidth gives NoiseSigma 0.03 m/s^2; BiasSigma 0.05 m/s^2 (the turn-on bias: 5 mg
    residual after calibration; the datasheet's uncalibrated zero-g offset is +-50 mg); BiasWalk
    5e-4 m/s^2/sqrt(s). Scale factor and misalignment (:func:`axis_errors`, applied before the
    bias and noise): the MPU-6050 datasheet (PS-MPU-6000A-00 rev 3.4, table 6.2) gives an
    initial calibration tolerance of +-3 % and a cross-axis sensitivity of +-2 %; read as 3-sigma
    limits, ScaleSigma 0.01 and MisalignmentSigma 0.0067. Default rate 100 Hz.

    In-flight vibration (:mod:`.vibration`), added to the specific force before the axis
    errors: lines at the rotor and blade-pass frequencies and broadband content, scaled with
    the rotor speeds squared, each reading the mean over its interval (the part's decimation
    filter; the lines alias through its sidelobes), then clipped at Range (16 g: the MPU-6050's
    widest full scale). The defaults give 1.1 m/s^2 RMS per axis in readings at 200 Hz at the
    Hummingbird's hover speed (2.36 m/s^2 instantaneous): the EuRoC MAV dataset's ADIS16448 on
    an AscTec multirotor in hover carries 0.9-1.3 m/s^2 above 10 Hz at 200 Hz (docs/physics.md,
    "In-flight vibration"); how that splits into lines and broadband is an assumption (two
    thirds of the variance in the two lines, equally, at 200 Hz).
    """

    type_name = "Accelerometer"
    PARAMS = (
        *_noise_params("m/s^2", 0.03, 0.05, 5e-4, "MPU-6050: 400 ug/sqrt(Hz)"),
        *_axis_params(0.01, 0.0067, "MPU-6050: +-3 %, +-2 % cross-axis as 3 sigma"),
        *_vibration_params("m/s^2", 0.568, 1.342, 1.154, 156.9,
                           "EuRoC ADIS16448 in hover: 1.1 m/s^2 RMS per axis at 200 Hz"),
    )

    def _setup(self) -> None:
        p = self.params
        self._noise = BiasedNoise(self.rng, 3, p["NoiseSigma"], p["BiasSigma"], p["BiasWalk"],
                                  self.normals)
        self._axes = axis_errors(self.rng, p["ScaleSigma"], p["MisalignmentSigma"])
        self.vibration = _vibration(self)
        self._range = p["Range"]

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> AccelReading:
        omega = state.omega_frd_rad_s
        cx, cy, cz = cross(omega, cross(omega, self._pos_mount))
        fx, fy, fz = state.specific_force_frd_m_s2
        vx, vy, vz = self.vibration.sample(state.rotor_speed_rad_s, dt_s)
        x, y, z = mat_vec(self._axes, self._body_to_sensor(
            (fx + cx + vx, fy + cy + vy, fz + cz + vz)))
        x, y, z = self._noise.corrupt3(x, y, z, dt_s)
        return AccelReading(state.time_s, clip3(x, y, z, self._range))


_GYRO_LAYOUT: Final[Layout] = sen_layout(SenGyro)


@dataclass
class GyroReading(Reading):
    angular_velocity_rad_s: Vec3

    def __init__(self, time_s: float, angular_velocity_rad_s: Vec3) -> None:
        self.time_s = time_s
        self.angular_velocity_rad_s = angular_velocity_rad_s

    def layout(self) -> Layout:
        return _GYRO_LAYOUT

    def values(self) -> tuple[object, ...]:
        return self.angular_velocity_rad_s


class Gyro(Sensor[GyroReading]):
    """Angular velocity, sensor frame, rad/s.

    Model: body rates rotated into the mount frame, then BiasedNoise. Defaults, MPU-6050-class:
    total RMS noise 0.05 deg/s at 100 Hz gives NoiseSigma 0.0009 rad/s; BiasSigma 0.005 rad/s
    (0.3 deg/s: the zero-rate offset a client reading this stream sees, the simulator's
    choice, where the uncalibrated part is +-20 deg/s; this is the turn-on bias, drawn once
    from the seed); BiasWalk 1e-4 rad/s/sqrt(s). The board's own power-up calibration
    (skeye.sim.robot.Robot.power_up) averages the turn-on bias away for its estimator, leaving
    the averaging noise and the walk; the stream keeps it. Scale factor and misalignment
    (:func:`axis_errors`): the MPU-6050 datasheet (PS-MPU-6000A-00 rev 3.4, table 6.1) gives a
    sensitivity scale factor tolerance of +-3 % and a cross-axis sensitivity of +-2 %; read as
    3-sigma limits, ScaleSigma 0.01 and MisalignmentSigma 0.0067. Default rate 100 Hz.

    In-flight vibration as the accelerometer's (:mod:`.vibration`): 0.065 rad/s RMS per axis
    in readings at 200 Hz at the Hummingbird's hover speed (EuRoC's ADIS16448 in hover:
    0.06-0.07 rad/s above 10 Hz), clipped at Range (2000 deg/s, the MPU-6050's widest full
    scale). g-sensitivity: a rate error G f with f the specific force the part feels
    (vibration included) and G a 3x3 matrix drawn once, entries N(0, GSensitivity): the
    MPU-6050's linear acceleration sensitivity 0.1 deg/s/g (PS-MPU-6000A-00 rev 3.4, table
    6.1) = 1.78e-4 rad/s per m/s^2.
    """

    type_name = "Gyro"
    PARAMS = (
        *_noise_params("rad/s", 0.0009, 0.005, 1e-4, "MPU-6050: 0.05 deg/s RMS"),
        *_axis_params(0.01, 0.0067, "MPU-6050: +-3 %, +-2 % cross-axis as 3 sigma"),
        *_vibration_params("rad/s", 0.0335, 0.0793, 0.0682, 34.9,
                           "EuRoC ADIS16448 in hover: 0.065 rad/s RMS per axis at 200 Hz"),
        Param("GSensitivity", 1.78e-4,
              "rate error per m/s^2 of specific force, per axis pair, drawn once, 1 sigma, "
              "rad/s/(m/s^2) (MPU-6050: 0.1 deg/s/g)"),
    )

    def _setup(self) -> None:
        p = self.params
        self._noise = BiasedNoise(self.rng, 3, p["NoiseSigma"], p["BiasSigma"], p["BiasWalk"],
                                  self.normals)
        self._axes = axis_errors(self.rng, p["ScaleSigma"], p["MisalignmentSigma"])
        self.vibration = _vibration(self)
        self._range = p["Range"]
        g = p["GSensitivity"]
        self._g_sens: Mat3 | None = None
        if g > 0.0:
            d = self.rng.standard_normal(9).tolist()
            self._g_sens = ((g * d[0], g * d[1], g * d[2]), (g * d[3], g * d[4], g * d[5]),
                            (g * d[6], g * d[7], g * d[8]))
        # The specific force the gyro feels: set by the engine from the accelerometer's
        # vibration when both ride on one board; else the rigid body's.
        self._accel: Accelerometer | None = None

    def share_board(self, accel: Accelerometer) -> None:
        """The accelerometer on the same board: its vibration is what the gyro's
        g-sensitivity feels."""
        self._accel = accel

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> GyroReading:
        wx, wy, wz = state.omega_frd_rad_s
        vx, vy, vz = self.vibration.sample(state.rotor_speed_rad_s, dt_s)
        g = self._g_sens
        if g is not None:
            fx, fy, fz = state.specific_force_frd_m_s2
            accel = self._accel
            if accel is not None and accel.last is not None:
                fx, fy, fz = accel.last.proper_acceleration_m_s2
            gx, gy, gz = mat_vec(g, (fx, fy, fz))
            vx, vy, vz = vx + gx, vy + gy, vz + gz
        x, y, z = mat_vec(self._axes, self._body_to_sensor((wx + vx, wy + vy, wz + vz)))
        x, y, z = self._noise.corrupt3(x, y, z, dt_s)
        return GyroReading(state.time_s, clip3(x, y, z, self._range))


_COMPASS_LAYOUT: Final[Layout] = sen_layout(SenMagneticCompass)


@dataclass
class CompassReading(Reading):
    magnetic_angle_rad: float
    field_ut: Vec3

    def __init__(self, time_s: float, magnetic_angle_rad: float, field_ut: Vec3) -> None:
        self.time_s = time_s
        self.magnetic_angle_rad = magnetic_angle_rad
        self.field_ut = field_ut

    def layout(self) -> Layout:
        return _COMPASS_LAYOUT

    def values(self) -> tuple[object, ...]:
        return (self.magnetic_angle_rad, *self.field_ut)


class MagneticCompass(Sensor[CompassReading]):
    """Magnetic field (sensor frame, microtesla) and the magnetic heading it implies (rad).

    Model: the world field rotated into the sensor frame, then BiasedNoise. MagneticAngle is
    the heading of the sensor's x axis from magnetic north, in [0, 2 pi): the noisy field is
    tilt-compensated with the sensor's true roll and pitch (what the board does with its
    accelerometer attitude) and the angle read from its horizontal part, so bias and noise show
    up in the heading as they would. Defaults, HMC5883L-class: NoiseSigma 0.2 uT (about 0.01
    rad of heading at a 20 uT horizontal field): the datasheet's noise floor, 2 mG = 0.2 uT,
    which is also its effective resolution, the larger of that and the 0.92 mG LSb at the
    1.3 Ga gain (Configuration Register B) (was 0.3 uT, a margin without a source); BiasSigma
    1.0 uT (residual hard iron after calibration); BiasWalk 0.005 uT/sqrt(s) (thermal drift).
    Default rate 20 Hz.

    Motor currents: the currents to the motors make a field of their own at the board, fixed
    in the body frame and growing with the current. The current follows the shaft power, so the
    rotor speeds cubed: the field is MotorField x sum(w_i^3) / (n MotorSpeed^3) (MotorField at
    every rotor at MotorSpeed, the Hummingbird's hover), along a body-frame direction drawn once
    from the seed. MotorField 2.2 uT is an assumption at the edge of what ArduPilot's compass /
    motor calibration (compassmot) calls acceptable, 30 % of the earth's field (about 50 uT) at
    full throttle: the rotors' top speed at a full pack's open-circuit voltage draws
    (838 / 441.7)^3 = 6.8 times the hover current, so 15 uT there and 2.2 uT in hover. (Under
    the voltage sag of full throttle the top speed is about 775 rad/s, 5.4 times the hover
    current, 11.9 uT: MotorField was set on the open-circuit figure and is kept.) A board
    compensates it only when it has been calibrated for it (compassmot); the simulated board
    has not.
    """

    type_name = "MagneticCompass"
    PARAMS = (
        *_noise_params("uT", 0.2, 1.0, 0.005, "HMC5883L: 2 mG noise floor"),
        Param("MotorField", 2.2, "field of the motor currents at MotorSpeed, uT (assumption: "
              "ArduPilot compassmot's 30 % of the earth field at full throttle)"),
        Param("MotorSpeed", HOVER_SPEED_RAD_S, "rotor speed at which MotorField is given, rad/s",
              exclusive=True),
    )

    def _setup(self) -> None:
        p = self.params
        self._noise = BiasedNoise(self.rng, 3, p["NoiseSigma"], p["BiasSigma"], p["BiasWalk"],
                                  self.normals)
        u = self.rng.standard_normal(3).tolist()
        norm = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]) or 1.0
        k = p["MotorField"] / norm
        self._motor_dir: Vec3 = (k * u[0], k * u[1], k * u[2])

    def motor_field_ut(self, speeds: tuple[float, ...]) -> float:
        """The magnitude of the motor currents' field at these rotor speeds, uT."""
        if not speeds:
            return 0.0
        ref = self.params["MotorSpeed"]
        total = 0.0
        for w in speeds:
            r = w / ref
            total += r * r * r
        return self.params["MotorField"] * total / len(speeds)

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> CompassReading:
        rot = self._rot_sensor_to_ned(state)
        fx, fy, fz = world.magnetic_field_ned_ut
        mx, my, mz = mat_t_vec(rot, (float(fx), float(fy), float(fz)))
        scale = self.motor_field_ut(state.rotor_speed_rad_s) / max(self.params["MotorField"],
                                                                  1e-12)
        if scale > 0.0:
            dx, dy, dz = self._body_to_sensor(self._motor_dir)
            mx, my, mz = mx + scale * dx, my + scale * dy, mz + scale * dz
        b = self._noise.corrupt3(mx, my, mz, dt_s)
        r20, r21, r22 = rot[2]
        roll = math.atan2(r21, r22)
        pitch = math.asin(max(-1.0, min(1.0, -r20)))
        cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
        # Ry(pitch) @ Rx(roll) @ b: the field in the frame that only follows the sensor's yaw.
        by = cr * b[1] - sr * b[2]
        bz = sr * b[1] + cr * b[2]
        bx = cp * b[0] + sp * bz
        heading = wrap_2pi(math.atan2(-by, bx))
        return CompassReading(state.time_s, heading, b)


_BARO_LAYOUT: Final[Layout] = sen_layout(SenBarometer)


@dataclass
class BaroReading(Reading):
    pressure_pa: float
    altitude_m: float

    def __init__(self, time_s: float, pressure_pa: float, altitude_m: float) -> None:
        self.time_s = time_s
        self.pressure_pa = pressure_pa
        self.altitude_m = altitude_m

    def layout(self) -> Layout:
        return _BARO_LAYOUT

    def values(self) -> tuple[object, ...]:
        return (self.pressure_pa, self.altitude_m)


def isa_pressure_pa(altitude_m: float, sea_level_pa: float) -> float:
    """ISA barometric formula (troposphere): static pressure at a geometric altitude. Its
    base reaches 0 at T0 / L, 44.3 km, where the formula's pressure is 0; above, 0 (the
    power of a negative base would be a complex number)."""
    base = 1.0 - ISA_LAPSE_K_M * altitude_m / ISA_T0_K
    return sea_level_pa * base**ISA_EXPONENT if base > 0.0 else 0.0


def isa_altitude_m(pressure_pa: float, sea_level_pa: float) -> float:
    """Inverse of :func:`isa_pressure_pa`."""
    return ISA_T0_K / ISA_LAPSE_K_M * (1.0 - (pressure_pa / sea_level_pa) ** (1.0 / ISA_EXPONENT))


class Barometer(Sensor[BaroReading]):
    """Static pressure (Pa) and the altitude above sea level it implies (m, ISA).

    Model: altitude = world origin altitude (0 without a geodetic origin) minus the sensor's NED
    down; pressure from the ISA barometric formula with the world's sea-level pressure, then
    BiasedNoise, then the sensor's range; Altitude is computed back from that pressure, so it
    carries the noise (about 8.3 cm per Pa near sea level). Defaults, MS5611-class: RMS noise
    0.012 mbar at OSR 4096 plus airframe turbulence gives NoiseSigma 1.5 Pa (~12 cm);
    BiasSigma 10 Pa (the datasheet's absolute accuracy is +-150 Pa, normally removed by a
    ground reference: 10 Pa is what is left); BiasWalk 0.1 Pa/sqrt(s) (weather and thermal
    drift, ~7 cm a minute). Default rate 20 Hz.

    Range: the MS5611-01BA03's operating range is 10 to 1200 mbar (its datasheet), so
    MinPressure 1000 Pa and MaxPressure 120000 Pa: a pressure beyond is read as the end of
    the range (as its 24-bit ADC's reading stays there), and the Altitude is the one that
    pressure implies (about 26 km by this formula at 1000 Pa; 1200 mbar is reached only
    below sea level under a high sea-level pressure, as a world file may set). Inside the
    range the reading is the noisy pressure itself, to the bit.

    Rotor wash in ground effect: near the ground the rotors' wake stagnates on it and raises
    the pressure around the vehicle, so the barometer reads low (a known effect: flight
    controllers' estimators ignore the baro near the ground for it). Model: the same
    Cheeseman-Bennett ground-effect gain k(h) the vehicle's thrust gets
    (:func:`skeye.sim.vehicle.ground_effect_factor`, h the sensor's height above the surface
    below, one ray), read as a ground cushion: the extra thrust (k - 1) T is that extra
    pressure over the rotor disks, ``dP = (k - 1) * sum(kf w_i^2) / (n pi R^2)``, added to the
    static pressure. RotorThrustCoefficient (kf) and RotorRadius (R) are the airframe's (the
    robot file sets them; kf 0, the default, is a barometer with no rotors). Above 4 R the
    effect is 0; for the Hummingbird at hover it is 3.5 Pa (about 0.3 m) at h = R and 13 Pa
    (about 1.1 m) at the 1.25 cap. The free-air prop wash over the static port depends on the
    airframe's ducting and is not modelled.
    """

    type_name = "Barometer"
    PARAMS = (
        *_noise_params("Pa", 1.5, 10.0, 0.1, "MS5611: 0.012 mbar RMS at OSR 4096"),
        Param("RotorThrustCoefficient", 0.0,
              "airframe's thrust per rotor / (rad/s)^2, N s^2 (0: no rotor wash)"),
        Param("RotorRadius", 0.1, "airframe's rotor radius, m", exclusive=True),
        Param("MinPressure", 1000.0, "range, low end, Pa: readings clip there "
              "(MS5611: 10 mbar)"),
        Param("MaxPressure", 120000.0, "range, high end, Pa: readings clip there "
              "(MS5611: 1200 mbar)", exclusive=True),
    )

    def _setup(self) -> None:
        p = self.params
        self._noise = BiasedNoise(self.rng, 1, p["NoiseSigma"], p["BiasSigma"], p["BiasWalk"],
                                  self.normals)
        self._min_pa, self._max_pa = p["MinPressure"], p["MaxPressure"]
        if not self._min_pa < self._max_pa:
            raise self._error("MinPressure", f"{self._min_pa:g} must be below MaxPressure "
                              f"{self._max_pa:g}")

    def rotor_wash_pa(self, state: BodyState, world: WorldQuery) -> float:
        """The ground-cushion overpressure at the sensor (Pa), 0 without rotors or ground."""
        kf, radius = self.params["RotorThrustCoefficient"], self.params["RotorRadius"]
        speeds = state.rotor_speed_rad_s
        if kf <= 0.0 or not speeds:
            return 0.0
        height = world.ray_distance(self._pos_ned_m(state), (0.0, 0.0, 1.0), 4.0 * radius)
        gain = ground_effect_factor(height, radius)
        if gain <= 1.0:
            return 0.0
        thrust = 0.0
        for w in speeds:
            thrust += kf * w * w
        return (gain - 1.0) * thrust / (len(speeds) * math.pi * radius * radius)

    def _read(self, state: BodyState, world: WorldQuery, dt_s: float) -> BaroReading:
        origin = world.geo_origin
        base_alt_m = origin.altitude_m if origin is not None else 0.0
        altitude_m = base_alt_m - self._pos_ned_m(state)[2]
        p0 = float(world.sea_level_pressure_pa)
        static = isa_pressure_pa(altitude_m, p0) + self.rotor_wash_pa(state, world)
        pressure = self._noise.corrupt((static,), dt_s)[0]
        if pressure < self._min_pa:  # beyond the sensor's range: it reads the end of it
            pressure = self._min_pa
        elif pressure > self._max_pa:
            pressure = self._max_pa
        return BaroReading(state.time_s, pressure, isa_altitude_m(pressure, p0))
