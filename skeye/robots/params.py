"""Parameter dataclasses of a robot class: airframe, battery and low-level controller.

How this works: a robot class file (``skeye/robots/*.toml``, read by :mod:`skeye.robots.config`)
fills these frozen dataclasses from its ``[airframe]``, ``[battery]`` and ``[controller]``
tables through :func:`dataclass_from_mapping`; every value is checked when the dataclass is
built (ConfigError naming the key). The simulator's physics (:mod:`skeye.sim.vehicle`,
:mod:`skeye.sim.controller`) reads them on its hot path, so this module is compiled with the
simulator (``skeye.native.COMPILED_MODULES``); the pilot, ground control and vision read them
too, which is why they live outside ``skeye.sim``. Imports only the standard library and
``skeye.errors``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Final

from skeye.errors import ConfigError

GRAVITY_M_S2: Final = 9.81
FROM_SENSORS: Final = math.nan
"""An ``[estimator]`` setting left to the board's sensors' own figures (the robot derives it)."""
SENSOR_DERIVED: Final = (
    "accel_noise_m_s2", "tilt_noise_rad_s", "baro_noise_m", "sonar_noise_m", "flow_noise_rad_s",
    "gps_pos_noise_m", "gps_vel_noise_m_s", "gps_delay_s",
)
"""The ``[estimator]`` settings that default to the figures of the sensors the board reads."""
ESTIMATOR_KINDS: Final = ("onboard", "truth")
"""``[estimator] kind``: the board's estimator from sensor readings, or the oracle."""


def _check_positive(owner: str, name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{owner}: {name} must be a positive number, got {value!r}")


def dataclass_from_mapping(cls: Any, data: Mapping[str, Any], owner: str) -> Any:
    """Build a parameter dataclass from a TOML table, naming unknown keys and wrong types."""
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ConfigError(f"{owner}: unknown key(s) {unknown}; known keys: {sorted(known)}")
    kwargs: dict[str, Any] = {}
    defaults = {f.name: f.default for f in fields(cls)}
    for key, value in data.items():
        default = defaults.get(key)
        if isinstance(default, float | int) and not isinstance(default, bool):
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"{owner}: {key} must be a number, got {value!r}")
            value = float(value) if isinstance(default, float) else value
        elif isinstance(default, tuple):
            if not isinstance(value, list | tuple) or len(value) != len(default):
                raise ConfigError(
                    f"{owner}: {key} must be a list of {len(default)} numbers, got {value!r}"
                )
            if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
                raise ConfigError(f"{owner}: {key} must hold numbers only, got {value!r}")
            value = tuple(float(v) for v in value)
        kwargs[key] = value
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        raise ConfigError(f"{owner}: {exc}") from None


@dataclass(frozen=True)
class AirframeParams:
    """Rigid body, rotors and drag. Defaults: RotorS' published AscTec Hummingbird set."""

    mass_kg: float = 0.68
    inertia_kg_m2: tuple[float, float, float] = (0.007, 0.007, 0.012)
    arm_m: float = 0.17
    rotor_radius_m: float = 0.1
    kf: float = 8.54858e-06  # thrust constant, N / (rad/s)^2
    moment_constant_m: float = 0.016  # reaction torque / thrust
    tau_up_s: float = 0.0125
    tau_down_s: float = 0.025
    max_rotor_speed_rad_s: float = 838.0
    rotor_drag: float = 8.06e-05  # N / (rad/s) / (m/s), per rotor
    drag_area_m2: float = 0.01  # Cd * A for quadratic air drag
    body_size_m: tuple[float, float, float] = (0.12, 0.12, 0.06)
    gear_height_m: float = 0.08  # body origin above the ground when landed

    def __post_init__(self) -> None:
        owner = "airframe"
        for name in (
            "mass_kg",
            "arm_m",
            "rotor_radius_m",
            "kf",
            "moment_constant_m",
            "tau_up_s",
            "tau_down_s",
            "max_rotor_speed_rad_s",
            "gear_height_m",
        ):
            _check_positive(owner, name, getattr(self, name))
        for name in ("rotor_drag", "drag_area_m2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(f"{owner}: {name} must be >= 0, got {value!r}")
        for i, v in enumerate(self.inertia_kg_m2):
            _check_positive(owner, f"inertia_kg_m2[{i}]", v)
        for i, v in enumerate(self.body_size_m):
            _check_positive(owner, f"body_size_m[{i}]", v)
        # Principal moments of a real body obey the triangle inequality (each is a sum of two
        # of the mass's second moments); MuJoCo refuses to compile a body that breaks it.
        for i in range(3):
            ia = self.inertia_kg_m2[i]
            others = self.inertia_kg_m2[(i + 1) % 3] + self.inertia_kg_m2[(i + 2) % 3]
            if ia > others * (1.0 + 1e-9):
                raise ConfigError(
                    f"{owner}: inertia_kg_m2 {list(self.inertia_kg_m2)} is no rigid body's: "
                    f"inertia_kg_m2[{i}] = {ia!r} exceeds the sum of the other two ({others!r}); "
                    "each principal moment must be at most the sum of the other two"
                )
        half_height = self.body_size_m[2] / 2.0
        if self.gear_height_m < half_height:
            raise ConfigError(
                f"{owner}: gear_height_m {self.gear_height_m!r} is less than half the hull's "
                f"height (body_size_m[2] / 2 = {half_height!r}): standing on its gear the hull "
                "would reach into the ground; gear_height_m must be at least body_size_m[2] / 2"
            )
        # 4 kf w^2 in floats: kf = 1e300 gave inf, max_rotor_speed_rad_s = 1e200 raised
        # OverflowError (from "**") out of the robot file's loading, naming no file or key.
        thrust = 4.0 * self.kf * self.max_rotor_speed_rad_s * self.max_rotor_speed_rad_s
        if not math.isfinite(thrust):
            raise ConfigError(
                f"{owner}: the rotors' max thrust 4 * kf * max_rotor_speed_rad_s^2 (kf "
                f"{self.kf!r}, max_rotor_speed_rad_s {self.max_rotor_speed_rad_s!r}) is not a "
                "finite number of newtons"
            )
        if thrust <= self.mass_kg * GRAVITY_M_S2:
            raise ConfigError(
                f"{owner}: the rotors cannot lift the vehicle (max thrust "
                f"{thrust:.4g} N <= weight {self.mass_kg * GRAVITY_M_S2:.4g} N)"
            )

    @property
    def max_thrust_n(self) -> float:
        return 4.0 * self.kf * self.max_rotor_speed_rad_s**2

    @property
    def hover_speed_rad_s(self) -> float:
        return math.sqrt(self.mass_kg * GRAVITY_M_S2 / (4.0 * self.kf))


FULL_CELL_V = 4.2  # a full LiPo cell at rest (skeye.sim.vehicle's discharge curve starts there)


@dataclass(frozen=True)
class BatteryParams:
    """3-cell LiPo. Endurance follows from the power drawn; see docs/physics.md."""

    cells: int = 3
    capacity_mah: float = 2100.0
    internal_resistance_ohm: float = 0.03
    efficiency: float = 0.70  # rotor shaft power / electrical power (motors, ESCs)
    avionics_power_w: float = 3.0
    cutoff_cell_v: float = 3.3  # resting cell voltage at which it counts as empty (3.3: 0 %)

    def __post_init__(self) -> None:
        if not isinstance(self.cells, int) or not 1 <= self.cells <= 12:
            raise ConfigError(f"battery: cells must be an integer 1..12, got {self.cells!r}")
        for name in ("capacity_mah", "internal_resistance_ohm", "efficiency", "cutoff_cell_v"):
            _check_positive("battery", name, getattr(self, name))
        if self.efficiency > 1.0:
            raise ConfigError(f"battery: efficiency must be <= 1, got {self.efficiency}")
        if self.cutoff_cell_v >= FULL_CELL_V:
            raise ConfigError(f"battery: cutoff_cell_v must be below a full cell's "
                              f"{FULL_CELL_V:g} V (else the battery is empty from the start), "
                              f"got {self.cutoff_cell_v}")
        power = self.avionics_power_w
        if not (isinstance(power, int | float) and math.isfinite(power) and power >= 0):
            raise ConfigError(f"battery: avionics_power_w must be a number >= 0, got {power!r}")


@dataclass(frozen=True)
class ControllerParams:
    """Gains and limits of the low-level controller."""

    max_tilt_rad: float = 0.44  # ~25 deg
    max_speed_m_s: float = 3.0
    max_climb_m_s: float = 1.5
    max_yaw_rate_rad_s: float = 1.745  # 100 deg/s
    angle_gain: float = 7.0  # 1/s
    rate_gain: float = 22.0  # 1/s
    rate_integral_gain: float = 15.0  # 1/s^2
    yaw_rate_gain: float = 8.0
    velocity_gain: float = 2.8  # (m/s^2)/(m/s)
    velocity_integral_gain: float = 0.8
    climb_gain: float = 5.0
    climb_integral_gain: float = 3.0
    height_gain: float = 1.8  # (m/s)/m
    max_accel_m_s2: float = 4.0
    position_gain: float = 0.95  # (m/s)/m, GPS position hold; PX4's MPC_XY_P default

    def __post_init__(self) -> None:
        for name, value in ((f.name, getattr(self, f.name)) for f in fields(self)):
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"controller: {name} must be a positive number, got {value!r}")
        if self.max_tilt_rad >= math.pi / 2:
            raise ConfigError(f"controller: max_tilt_rad must be < pi/2, got {self.max_tilt_rad}")


@dataclass(frozen=True)
class EstimatorParams:
    """The board's estimator (skeye.sim.estimator): which one, and its noise parameters.

    ``kind = "onboard"`` (the default) estimates from the simulated sensor readings only;
    ``"truth"`` is the oracle: ground truth plus the INS sensor's small error processes, for
    users who want the navigation out of the way (``skeye sim --estimator onboard|truth``
    overrides the robot file). Sources of the
    defaults (docs/physics.md, "Onboard estimator"):

    - attitude_kp 0.2 rad/s: ArduPilot's DCM complementary filter, AHRS_RP_P default 0.2;
      attitude_ki = kp^2 / 4 = 0.01 rad/s^2: the critically damped bias loop of Mahony's filter
      (error dynamics s^2 + kp s + ki); compass_gain 1.0: ArduPilot's AHRS_YAW_P default
      equals AHRS_RP_P (0.2);
    - accel_bias_init_m_s2 0.2, accel_bias_walk_m_s3 0.003, flow_min_quality 1,
      flow_min_height_m 0.1: PX4 EKF2's defaults EKF2_ABIAS_INIT, EKF2_ACC_B_NOISE,
      EKF2_OF_QMIN, EKF2_MIN_RNG;
    - the measurement noises (accel_noise_m_s2, tilt_noise_rad_s, baro_noise_m, sonar_noise_m,
      flow_noise_rad_s, gps_pos_noise_m, gps_vel_noise_m_s) and gps_delay_s default to NaN,
      "from the board's sensors": the robot derives each from the parameters of the sensor
      the board reads (:func:`skeye.sim.estimator.from_sensor_figures`, docs/physics.md), so
      the filter is told what its sensors deliver, one source of truth; a number in the robot
      file's ``[estimator]`` table overrides it.
    """

    kind: str = "onboard"
    attitude_kp: float = 0.2
    attitude_ki: float = 0.01
    compass_gain: float = 1.0
    accel_noise_m_s2: float = FROM_SENSORS
    accel_bias_init_m_s2: float = 0.2
    accel_bias_walk_m_s3: float = 0.003
    baro_noise_m: float = FROM_SENSORS
    sonar_noise_m: float = FROM_SENSORS
    flow_noise_rad_s: float = FROM_SENSORS
    flow_min_quality: float = 1.0
    flow_min_height_m: float = 0.1
    gps_pos_noise_m: float = FROM_SENSORS
    gps_vel_noise_m_s: float = FROM_SENSORS
    gps_delay_s: float = FROM_SENSORS
    tilt_noise_rad_s: float = FROM_SENSORS

    def __post_init__(self) -> None:
        if self.kind not in ESTIMATOR_KINDS:
            raise ConfigError(
                f"estimator: kind must be one of {list(ESTIMATOR_KINDS)}, got {self.kind!r}"
            )
        for f in fields(self):
            if f.name == "kind":
                continue
            value = getattr(self, f.name)
            if f.name in SENSOR_DERIVED and math.isnan(value):
                continue  # from the board's sensors (the robot fills it in)
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(f"estimator: {f.name} must be a number >= 0, got {value!r}")

    @property
    def derived(self) -> bool:
        """Whether every sensor-derived setting has its value (none is still NaN)."""
        return not any(math.isnan(getattr(self, name)) for name in SENSOR_DERIVED)
