"""Tests of the simulated sensors: accuracy against ground truth, noise, determinism, config."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import ConfigError, LocalProtocolError
from skeye.geo import GeoOrigin, from_degrees_minutes
from skeye.sim.frames import euler_to_quat, quat_to_matrix, wrap_2pi, wrap_pi
from skeye.sim.sensors import (
    DEFAULT_RATES_HZ,
    GPS,
    INS,
    SENSOR_CLASSES,
    Accelerometer,
    Barometer,
    Battery,
    GroundTruth,
    Gyro,
    MagneticCompass,
    Mount,
    OpticalFlow,
    Sensor,
    Sonar,
    build_sensor,
    isa_altitude_m,
    isa_pressure_pa,
)
from skeye.sim.sensors.base import NormalStream, vec3
from skeye.sim.state import BodyState

G = 9.81
ORIGIN = GeoOrigin(39.1339, -77.2167, 120.0)
FIELD_NED_UT = np.array([20.9, -4.0, 46.5])  # mid-Atlantic US: about -11 deg declination
QUIET: dict[str, Any] = {"NoiseSigma": 0.0, "BiasSigma": 0.0, "BiasWalk": 0.0}
IDEAL_AXES: dict[str, Any] = {"ScaleSigma": 0.0, "MisalignmentSigma": 0.0}  # IMU only
IMU_QUIET: dict[str, Any] = {**QUIET, **IDEAL_AXES}


@dataclass
class FlatWorld:
    """Flat ground at NED down = ground_down_m, analytic ray intersection."""

    geo_origin: GeoOrigin | None = ORIGIN
    magnetic_field_ned_ut: np.ndarray = field(default_factory=lambda: FIELD_NED_UT.copy())
    sea_level_pressure_pa: float = 101325.0
    ground_down_m: float = 0.0
    contrast: float = 0.3  # RMS texture contrast of the ground (a textured floor)

    def ray_distance(
        self, origin_ned_m: np.ndarray, direction_ned: np.ndarray, max_range_m: float
    ) -> float | None:
        dz = float(direction_ned[2])
        if dz <= 1e-12 or origin_ned_m[2] > self.ground_down_m:
            return None
        t = (self.ground_down_m - float(origin_ned_m[2])) / dz
        return t if t <= max_range_m else None

    def ray_distances(
        self, origin_ned_m: Any, directions_ned: Any, max_range_m: float
    ) -> list[float | None]:
        return [self.ray_distance(origin_ned_m, d, max_range_m) for d in directions_ned]

    def ray_surface(
        self, origin_ned_m: Any, direction_ned: Any, max_range_m: float
    ) -> tuple[float | None, float]:
        distance = self.ray_distance(origin_ned_m, direction_ned, max_range_m)
        return distance, self.contrast if distance is not None else 0.0


def make_state(
    t: float = 0.0,
    pos: tuple[float, float, float] = (0.0, 0.0, -1.0),
    vel: tuple[float, float, float] = (0.0, 0.0, 0.0),
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0),
    omega: tuple[float, float, float] = (0.0, 0.0, 0.0),
    accel: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> BodyState:
    q = euler_to_quat(*rpy)
    rot = quat_to_matrix(q.tolist())
    a = np.array(accel, dtype=float)
    return BodyState(
        time_s=t,
        pos_ned_m=vec3(pos),
        vel_ned_m_s=vec3(vel),
        quat_ned=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        rpy_rad=vec3(rpy),
        rot_body_to_ned=(vec3(rot[0]), vec3(rot[1]), vec3(rot[2])),
        omega_frd_rad_s=vec3(omega),
        accel_ned_m_s2=vec3(a),
        specific_force_frd_m_s2=vec3(rot.T @ (a - np.array([0.0, 0.0, G]))),
    )


def make(cls: type[Sensor[Any]], seed: int = 1, mount: Mount | None = None,
         **params: object) -> Any:
    return cls(cls.type_name, mount or Mount(), params, np.random.default_rng(seed))


def series(sensor: Sensor[Any], n: int, world: FlatWorld | None = None, **state: Any
           ) -> list[dict[str, Any]]:
    """n readings at the sensor's rate, the vehicle otherwise fixed."""
    w = world or FlatWorld()
    return [dict(sensor.sample(make_state(t=k / sensor.rate_hz, **state), w)) for k in range(n)]


def assert_mean_close(samples: np.ndarray, truth: np.ndarray, noise: float, bias: float) -> None:
    """Mean within 3 sigma/sqrt(n) of white noise plus a 4-sigma bias bound."""
    n = samples.shape[0]
    err = np.abs(samples.mean(axis=0) - truth)
    assert np.all(err <= 3 * noise / math.sqrt(n) + 4 * bias + 1e-12), (err, noise, bias)


# --- ground truth and battery -----------------------------------------------------------------


def test_ground_truth_copies_state_and_wraps_orientation() -> None:
    gt = make(GroundTruth)
    s = make_state(t=1.5, pos=(1, 2, -3), vel=(0.1, -0.2, 0.3), rpy=(0.1, -0.2, -0.5),
                   omega=(0.01, 0.02, -0.03))
    f = dict(gt.sample(s, FlatWorld()))
    assert list(f) == ["Location", "Orientation", "Velocity", "AngularVelocity"]
    assert f["Location"] == (1.0, 2.0, -3.0)
    assert f["Velocity"] == (0.1, -0.2, 0.3)
    assert f["AngularVelocity"] == (0.01, 0.02, -0.03)
    assert f["Orientation"] == pytest.approx((0.1, 2 * math.pi - 0.2, 2 * math.pi - 0.5))
    assert all(isinstance(v, float) for v in f["Location"])
    assert gt.last is not None and gt.last.time_s == 1.5


def test_battery_reports_engine_values_and_refuses_before_update() -> None:
    bat = make(Battery)
    with pytest.raises(LocalProtocolError, match="before update_battery"):
        bat.sample(make_state(), FlatWorld())
    bat.update_battery(11.4, 8.5, 0.75)
    assert bat.sample(make_state(), FlatWorld()) == [
        ("Voltage", 11.4), ("Current", 8.5), ("Remaining", 0.75)]
    with pytest.raises(LocalProtocolError, match="remaining"):
        bat.update_battery(11.0, 1.0, 1.5)
    with pytest.raises(LocalProtocolError, match="voltage"):
        bat.update_battery(float("nan"), 1.0, 0.5)


# --- IMU -------------------------------------------------------------------------------------


def test_accelerometer_exact_without_noise_and_rotated_by_mount() -> None:
    acc = make(Accelerometer, **IMU_QUIET)
    f = dict(acc.sample(make_state(accel=(1.0, 0.0, 0.0)), FlatWorld()))
    assert f["ProperAcceleration"] == pytest.approx((1.0, 0.0, -G))
    # Mounted yawed +90 deg: body x is the sensor's -y.
    acc = make(Accelerometer, mount=Mount(rpy_rad=(0.0, 0.0, math.pi / 2)), **IMU_QUIET)
    f = dict(acc.sample(make_state(accel=(1.0, 0.0, 0.0)), FlatWorld()))
    assert f["ProperAcceleration"] == pytest.approx((0.0, -1.0, -G), abs=1e-12)
    # Centripetal lever arm: 0.1 m forward, spinning 2 rad/s about z -> -0.4 m/s^2 along x.
    acc = make(Accelerometer, mount=Mount(pos_frd_m=(0.1, 0.0, 0.0)), **IMU_QUIET)
    f = dict(acc.sample(make_state(omega=(0.0, 0.0, 2.0)), FlatWorld()))
    assert f["ProperAcceleration"] == pytest.approx((-0.4, 0.0, -G), abs=1e-12)


def test_accelerometer_noise_statistics() -> None:
    acc = make(Accelerometer, seed=7, **IDEAL_AXES)
    readings = np.array([r["ProperAcceleration"] for r in series(acc, 3000)])
    p = acc.params
    assert_mean_close(readings, np.array([0.0, 0.0, -G]), p["NoiseSigma"],
                      p["BiasSigma"] + p["BiasWalk"] * math.sqrt(30.0))
    assert readings.std(axis=0) == pytest.approx([p["NoiseSigma"]] * 3, rel=0.15)


def test_gyro_rotated_and_noise_statistics() -> None:
    gyro = make(Gyro, mount=Mount(rpy_rad=(0.0, 0.0, math.pi / 2)), GSensitivity=0.0,
                **IMU_QUIET)
    f = dict(gyro.sample(make_state(omega=(0.3, 0.0, -0.1)), FlatWorld()))
    assert f["AngularVelocity"] == pytest.approx((0.0, -0.3, -0.1), abs=1e-12)
    gyro = make(Gyro, seed=3, **IDEAL_AXES)
    omega = np.array([0.1, -0.2, 0.05])
    readings = np.array([r["AngularVelocity"]
                         for r in series(gyro, 3000, omega=tuple(omega))])
    p = gyro.params
    assert_mean_close(readings, omega, p["NoiseSigma"],
                      p["BiasSigma"] + p["BiasWalk"] * math.sqrt(30.0))
    assert readings.std(axis=0) == pytest.approx([p["NoiseSigma"]] * 3, rel=0.15)
    # The bias is real: not all three axes' means sit on the truth.
    assert np.max(np.abs(readings.mean(axis=0) - omega)) > 3 * p["NoiseSigma"] / math.sqrt(3000)


# --- compass ----------------------------------------------------------------------------------

DECLINATION = math.atan2(FIELD_NED_UT[1], FIELD_NED_UT[0])


@settings(max_examples=60, deadline=None)
@given(
    roll=st.floats(-0.8, 0.8),
    pitch=st.floats(-0.8, 0.8),
    yaw=st.floats(-math.pi, math.pi),
    mount_yaw=st.sampled_from([0.0, math.pi / 2, -2.0]),
)
def test_compass_heading_is_tilt_compensated(roll: float, pitch: float, yaw: float,
                                             mount_yaw: float) -> None:
    compass = make(MagneticCompass, mount=Mount(rpy_rad=(0.0, 0.0, mount_yaw)), **QUIET)
    s = make_state(rpy=(roll, pitch, yaw))
    f = dict(compass.sample(s, FlatWorld()))
    rot = np.asarray(s.rot_body_to_ned) @ quat_to_matrix(
        euler_to_quat(0.0, 0.0, mount_yaw).tolist())
    assert f["Field"] == pytest.approx(tuple(rot.T @ FIELD_NED_UT), abs=1e-9)
    # The sensor x axis's heading (projected on the horizontal) from magnetic north.
    x_axis = rot[:, 0]
    expected = wrap_2pi(math.atan2(x_axis[1], x_axis[0]) - DECLINATION)
    assert 0.0 <= f["MagneticAngle"] < 2 * math.pi
    assert abs(wrap_pi(f["MagneticAngle"] - expected)) < 1e-9


def test_compass_noise_statistics() -> None:
    compass = make(MagneticCompass, seed=11)
    yaw = 1.0
    readings = series(compass, 2000, rpy=(0.0, 0.0, yaw))
    fields = np.array([r["Field"] for r in readings])
    truth = quat_to_matrix(euler_to_quat(0, 0, yaw).tolist()).T @ FIELD_NED_UT
    p = compass.params
    assert_mean_close(fields, truth, p["NoiseSigma"],
                      p["BiasSigma"] + p["BiasWalk"] * math.sqrt(100.0))
    heading_err = [wrap_pi(r["MagneticAngle"] - (yaw - DECLINATION)) for r in readings]
    horizontal = math.hypot(FIELD_NED_UT[0], FIELD_NED_UT[1])
    assert abs(float(np.mean(heading_err))) < 4 * p["BiasSigma"] / horizontal


# --- barometer --------------------------------------------------------------------------------


def test_isa_formula_round_trip_and_reference_values() -> None:
    assert isa_pressure_pa(0.0, 101325.0) == pytest.approx(101325.0)
    assert isa_pressure_pa(1000.0, 101325.0) == pytest.approx(89874.6, abs=1.0)
    for alt in (-100.0, 0.0, 120.0, 3000.0):
        assert isa_altitude_m(isa_pressure_pa(alt, 100000.0), 100000.0) == pytest.approx(
            alt, abs=1e-6)


def test_barometer_exact_without_noise_and_statistics() -> None:
    baro = make(Barometer, **QUIET)
    f = dict(baro.sample(make_state(pos=(0, 0, -10.0)), FlatWorld()))
    assert f["Altitude"] == pytest.approx(130.0, abs=1e-6)
    assert f["Pressure"] == pytest.approx(isa_pressure_pa(130.0, 101325.0))
    f = dict(baro.sample(make_state(pos=(0, 0, -10.0)), FlatWorld(geo_origin=None)))
    assert f["Altitude"] == pytest.approx(10.0, abs=1e-6)  # indoors: origin at 0 m

    baro = make(Barometer, seed=5)
    readings = series(baro, 2000, pos=(0.0, 0.0, -2.0))
    p = baro.params
    pressures = np.array([[r["Pressure"]] for r in readings])
    assert_mean_close(pressures, np.array([isa_pressure_pa(122.0, 101325.0)]),
                      p["NoiseSigma"], p["BiasSigma"] + p["BiasWalk"] * 10.0)
    altitudes = np.array([r["Altitude"] for r in readings])
    assert abs(altitudes.mean() - 122.0) < 0.09 * (4 * p["BiasSigma"] + 1.0)
    assert altitudes.std() == pytest.approx(p["NoiseSigma"] * 0.083, rel=0.2)


def test_barometer_saturates_at_the_ms5611_range() -> None:
    """The modelled MS5611 measures 10 to 1200 mbar (its datasheet's operating range): beyond
    it the reading stays at the end of the range, as a real sensor's does. Above about 44 km
    the ISA formula's base goes negative, and the reading was a complex number."""
    baro = make(Barometer, **QUIET)
    for down_m in (-50_000.0, -30_000.0):
        f = dict(baro.sample(make_state(pos=(0, 0, down_m)), FlatWorld(geo_origin=None)))
        assert f["Pressure"] == 1000.0, (down_m, f)
        assert f["Altitude"] == isa_altitude_m(1000.0, 101325.0), (down_m, f)
    # Reachable from a world file: the highest sea-level pressure it takes, below sea level.
    low = FlatWorld(geo_origin=GeoOrigin(31.5, 35.5, -430.0), sea_level_pressure_pa=120000.0)
    f = dict(baro.sample(make_state(pos=(0, 0, -1.0)), low))
    assert isa_pressure_pa(429.0, 120000.0) < 120000.0 < isa_pressure_pa(-429.0, 120000.0)
    assert f["Pressure"] == 120000.0 and f["Altitude"] == 0.0, f
    # Inside the range the reading is the formula's, untouched.
    f = dict(baro.sample(make_state(pos=(0, 0, -20_000.0)), FlatWorld(geo_origin=None)))
    assert f["Pressure"] == isa_pressure_pa(20_000.0, 101325.0) > 1000.0


# --- GPS --------------------------------------------------------------------------------------


def test_gps_indoors_has_no_fix_and_no_position() -> None:
    gps = make(GPS)
    assert gps.sample(make_state(), FlatWorld(geo_origin=None)) == [
        ("Fix", 0), ("Satellites", 0)]


def test_gps_fields_formats_and_error_statistics() -> None:
    gps = make(GPS, seed=2, FixTime=0.0)  # acquisition: tests/sim/test_sensor_imperfections.py
    n = 15000  # 3000 s at 5 Hz: 10 correlation times of 300 s
    readings = series(gps, n, pos=(3.0, -4.0, -1.0), vel=(0.5, 0.0, 0.0))
    first = readings[0]
    # USARSim's GPSSensor order: Latitude, Longitude first, Fix, Satellites last
    assert list(first) == ["Latitude", "Longitude", "LatitudeDeg", "LongitudeDeg", "Altitude",
                           "VelocityNED", "Fix", "Satellites"]
    assert first["Latitude"].endswith(",N") and first["Longitude"].endswith(",W")
    assert from_degrees_minutes(first["Latitude"]) == pytest.approx(first["LatitudeDeg"],
                                                                    abs=2e-6)
    assert from_degrees_minutes(first["Longitude"]) == pytest.approx(first["LongitudeDeg"],
                                                                     abs=2e-6)
    assert all(r["Fix"] == 1 and 9 <= r["Satellites"] <= 12 for r in readings)
    assert len({r["Satellites"] for r in readings}) > 1
    ned = np.array([ORIGIN.to_ned(r["LatitudeDeg"], r["LongitudeDeg"], r["Altitude"])
                    for r in readings])
    err = ned - np.array([3.0, -4.0, -1.0])
    p = gps.params
    rms = np.sqrt((err**2).mean(axis=0))
    sigma = np.array([p["HorizontalSigma"], p["HorizontalSigma"], p["VerticalSigma"]])
    assert np.all(rms > 0.5 * sigma) and np.all(rms < 1.6 * sigma), rms
    # Correlated: consecutive errors 0.2 s apart are nearly the same, and the error moves
    # slowly, as a static receiver's does: sigma sqrt(2 (1 - exp(-1 s / 300 s))) = 0.17 m in a
    # second per axis (sigma 2.12 m), where a 30 s process moved 0.54 m.
    lag1 = np.corrcoef(err[:-1, 0], err[1:, 0])[0, 1]
    assert lag1 > 0.95
    step_1s = np.sqrt((np.diff(err[::5, :2], axis=0) ** 2).mean())
    expected = p["HorizontalSigma"] * math.sqrt(2.0 * (1.0 - math.exp(-1.0 / 300.0)))
    assert 0.7 * expected < step_1s < 1.3 * expected, (step_1s, expected)
    vel = np.array([r["VelocityNED"] for r in readings])
    assert_mean_close(vel, np.array([0.5, 0.0, 0.0]), p["VelocitySigma"], 0.0)


# --- sonar ------------------------------------------------------------------------------------


def test_sonar_ranges_clamps_and_cone() -> None:
    world = FlatWorld()
    quiet = make(Sonar, NoiseSigma=0.0, RangingTime=0.0, BeamAngle=0.6, MissProbability=0.0)
    assert quiet.sample(make_state(pos=(0, 0, -2.0)), world) == [("Range", pytest.approx(2.0))]
    assert quiet.sample(make_state(pos=(0, 0, -10.0)), world) == [("Range", 6.0)]
    assert quiet.last is not None and not quiet.last.echo
    assert quiet.sample(make_state(pos=(0, 0, -0.03)), world) == [("Range", 0.06)]
    # Pitched 0.5 rad: the nearest ray of the cone is 0.3 rad off the boresight.
    f = dict(quiet.sample(make_state(pos=(0, 0, -1.0), rpy=(0.0, 0.5, 0.0)), world))
    assert f["Range"] == round(100.0 / math.cos(0.5 - 0.3)) / 100.0  # whole centimetres
    # Rolled 2 rad: even the nearest cone ray (1.7 rad off the vertical) points up: no echo.
    assert quiet.sample(make_state(pos=(0, 0, -1.0), rpy=(2.0, 0.0, 0.0)), world) == [
        ("Range", 6.0)]
    # Mount offset moves the sensor: 0.05 m below the body origin.
    low = make(Sonar, mount=Mount(pos_frd_m=(0.0, 0.0, 0.05)), NoiseSigma=0.0,
               RangingTime=0.0)
    assert dict(low.sample(make_state(pos=(0, 0, -1.0)), world))["Range"] == pytest.approx(0.95)


def test_sonar_noise_statistics() -> None:
    sonar = make(Sonar, seed=4, RangingTime=0.0, MissProbability=0.0)
    sigma = sonar.params["NoiseSigma"]
    ranges = np.array([[r["Range"]] for r in series(sonar, 1500, pos=(0.0, 0.0, -1.5))])
    assert_mean_close(ranges, np.array([1.5]), sigma, 0.0)
    # whole centimetres add 1 cm / sqrt(12) of rounding
    expected = math.hypot(sigma, 0.01 / math.sqrt(12.0))
    assert float(ranges.std()) == pytest.approx(expected, rel=0.15)



# --- optical flow -----------------------------------------------------------------------------


def flow_sum(flow: OpticalFlow, n: int, **state: Any) -> tuple[np.ndarray, list[int]]:
    readings = series(flow, n, **state)
    return np.array([r["Delta"] for r in readings]).sum(axis=0), [r["Quality"] for r in readings]


def test_optical_flow_counts_follow_velocity_height_and_rotation() -> None:
    k = make(OpticalFlow).counts_per_rad
    assert k == pytest.approx(30 * 1.1 / (2 * math.tan(0.202458 / 2)))
    n, dt = 500, 1 / 50.0  # 10 s
    totals = {}
    for v, h in ((0.5, 1.0), (1.0, 1.0), (1.0, 2.0)):
        total, quality = flow_sum(make(OpticalFlow, seed=9), n, pos=(0, 0, -h), vel=(v, 0, 0))
        totals[(v, h)] = total
        assert total[0] == pytest.approx(k * v / h * n * dt, abs=3 * 0.5 * math.sqrt(n) + 1)
        assert abs(total[1]) < 3 * 0.5 * math.sqrt(n) + 1
        assert 85 <= np.mean(quality) <= 115
    assert totals[(1.0, 1.0)][0] > totals[(0.5, 1.0)][0] > 0
    assert totals[(1.0, 2.0)][0] < totals[(1.0, 1.0)][0]
    # Sideways motion gives dy; a nose-up pitch rate reads as forward motion (no compensation).
    total, _ = flow_sum(make(OpticalFlow), n, pos=(0, 0, -1.0), vel=(0, 0.4, 0))
    assert total[1] == pytest.approx(k * 0.4 * n * dt, abs=40)
    total, _ = flow_sum(make(OpticalFlow), n, pos=(0, 0, -1.0), omega=(0, 0.2, 0))
    assert total[0] == pytest.approx(k * 0.2 * n * dt, abs=40)


def test_optical_flow_quality_range_and_saturation() -> None:
    _, q_low = flow_sum(make(OpticalFlow), 50, pos=(0, 0, -0.1))
    _, q_ok = flow_sum(make(OpticalFlow), 50, pos=(0, 0, -1.0))
    assert np.mean(q_low) < 0.5 * np.mean(q_ok)
    total, q_far = flow_sum(make(OpticalFlow), 50, pos=(0, 0, -20.0), vel=(1, 0, 0))
    assert q_far == [0] * 50 and list(total) == [0, 0]
    assert all(0 <= q <= 169 for q in q_low + q_ok)
    fast = series(make(OpticalFlow), 5, pos=(0, 0, -0.5), vel=(30.0, 0, 0))
    assert [r["Delta"][0] for r in fast] == [127] * 5


# --- INS --------------------------------------------------------------------------------------


def run_ins(seed: int, duration_s: float, dt_s: float, **params: Any) -> tuple[INS, Any]:
    ins = make(INS, seed=seed, **params)
    s = make_state(pos=(1.0, 2.0, -1.0), rpy=(0.0, 0.0, 3.0))
    est = None
    for k in range(1, round(duration_s / dt_s) + 1):
        s.time_s = k * dt_s
        est = ins.estimate(s, dt_s)
    return ins, est


def test_ins_drift_over_a_minute_is_small_but_nonzero() -> None:
    for seed in range(8):
        _, est = run_ins(seed, 60.0, 0.001 if seed == 0 else 0.02)
        drift = np.array(est.pos_ned_m) - np.array([1.0, 2.0, -1.0])
        horizontal = math.hypot(drift[0], drift[1])
        assert 1e-4 < horizontal < 0.15, horizontal  # documented: 3.1 cm/axis 1 sigma
        assert abs(drift[2]) < 0.12
        assert abs(est.rpy_rad[0]) < 5 * (0.005 + 0.001)
        assert abs(wrap_pi(est.rpy_rad[2] - 3.0)) < 5 * (0.01 + 0.001)
        assert -math.pi <= est.rpy_rad[2] < math.pi
        assert np.max(np.abs(est.vel_ned_m_s)) < 5 * 0.01
        assert np.max(np.abs(est.omega_frd_rad_s)) < 5 * (0.001 + 0.0005)


def test_ins_drift_statistics_do_not_depend_on_call_rate() -> None:
    walk = 0.004
    expected_var = walk**2 * 60.0
    for dt_s in (0.02, 1.0):
        drifts = np.array([run_ins(100 + seed, 60.0, dt_s)[0].pos_bias_ned_m[:2]
                           for seed in range(60)]).ravel()
        assert float(np.mean(drifts**2)) / expected_var == pytest.approx(1.0, abs=0.4), dt_s


def test_ins_sample_reports_the_controller_estimate() -> None:
    ins = make(INS, seed=3)
    world = FlatWorld()
    s = make_state(t=0.5, pos=(1.0, 2.0, -3.0), vel=(0.1, 0, 0), rpy=(0.0, 0.0, -0.4))
    est = ins.estimate(s, 0.001)
    f = dict(ins.sample(s, world))
    assert list(f) == ["Location", "Orientation", "Velocity"]
    assert f["Location"] == est.pos_ned_m and f["Velocity"] == est.vel_ned_m_s
    assert f["Orientation"] == tuple(wrap_2pi(a) for a in est.rpy_rad)
    # Sampled alone (no controller calls), the drift still advances with sim time.
    ins2 = make(INS, seed=3)
    for k in range(601):
        ins2.sample(make_state(t=k * 0.1), world)
    assert ins2.pos_bias_ned_m != (0.0, 0.0, 0.0)
    with pytest.raises(LocalProtocolError, match="dt_s"):
        ins.estimate(s, -0.001)


def test_ins_estimate_timing(capsys: pytest.CaptureFixture[str]) -> None:
    ins = make(INS)
    s = make_state()
    n = 20000
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(n):
            ins.estimate(s, 0.001)
        best = min(best, (time.perf_counter() - t0) / n)
    with capsys.disabled():
        print(f"\nINS.estimate: {best * 1e6:.2f} us per call (best of 3 x {n})")


# --- determinism ------------------------------------------------------------------------------

NOISY = [c for c in SENSOR_CLASSES.values() if c not in (GroundTruth, Battery)]


def trajectory_readings(sensor: Sensor[Any]) -> list[Any]:
    world = FlatWorld()
    out = []
    for k in range(40):
        t = k / sensor.rate_hz
        s = make_state(t=t, pos=(0.1 * t, 0.0, -1.0 - 0.05 * t), vel=(0.3, 0.1, -0.05),
                       rpy=(0.05, -0.03, 0.2 * t), omega=(0.01, 0.02, 0.2))
        out.append(sensor.sample(s, world))
    return out


@pytest.mark.parametrize("cls", list(SENSOR_CLASSES.values()), ids=lambda c: c.type_name)
def test_same_seed_same_readings_different_seed_different(cls: type[Sensor[Any]]) -> None:
    def build(seed: int) -> Sensor[Any]:
        sensor = make(cls, seed=seed)
        if isinstance(sensor, Battery):
            sensor.update_battery(12.0, 5.0, 0.9)
        return sensor

    assert trajectory_readings(build(42)) == trajectory_readings(build(42))
    if cls in NOISY:
        assert trajectory_readings(build(42)) != trajectory_readings(build(43))


# --- configuration ----------------------------------------------------------------------------


def test_defaults_rates_and_conf_geo_fields() -> None:
    for key, cls in SENSOR_CLASSES.items():
        assert key == cls.type_name.lower()
        assert make(cls).rate_hz == DEFAULT_RATES_HZ[key]
    sonar = build_sensor("sonar", "Down", Mount((0.0, 0.0, 0.05), (0.0, -0.1, 0.0)),
                         {"max_range": 4, "rate_hz": 10}, np.random.default_rng(0))
    assert isinstance(sonar, Sonar) and sonar.rate_hz == 10.0
    assert sonar.conf_fields()[:4] == [("Rate", 10.0), ("MaxRange", 4.0), ("MinRange", 0.06),
                                       ("BeamAngle", 1.257)]
    geo = dict(sonar.geo_fields())
    assert geo["Location"] == (0.0, 0.0, 0.05)
    assert geo["Orientation"] == pytest.approx((0.0, 2 * math.pi - 0.1, 0.0))


@pytest.mark.parametrize(
    ("cls", "params", "message"),
    [
        (Sonar, {"MaxRange": 0.01},
         "sensor 'Down' (Sonar): MaxRange must be > MinRange (0.06), got 0.01"),
        (Sonar, {"Range": 3.0}, "sensor 'Down' (Sonar): Range is not a parameter of Sonar"),
        (Sonar, {"Rate": -1.0}, "sensor 'Down' (Sonar): Rate must be > 0, got -1.0"),
        (Sonar, {"NoiseSigma": "0.1"}, "sensor 'Down' (Sonar): NoiseSigma must be a number"),
        (Sonar, {"NoiseSigma": True}, "sensor 'Down' (Sonar): NoiseSigma must be a number"),
        (Sonar, {"BeamRays": 2.5}, "sensor 'Down' (Sonar): BeamRays must be an integer"),
        (Sonar, {"BeamAngle": 4.0}, "sensor 'Down' (Sonar): BeamAngle must be <= 3.14159"),
        (Sonar, {"maxrange": 5.0, "max_range": 4.0}, "sensor 'Down' (Sonar): max_range is given"),
        (Gyro, {"BiasSigma": -0.1}, "sensor 'Down' (Gyro): BiasSigma must be >= 0, got -0.1"),
        (Gyro, {"NoiseSigma": float("nan")}, "sensor 'Down' (Gyro): NoiseSigma must be finite"),
        (GPS, {"MinSatellites": 12, "MaxSatellites": 9},
         "sensor 'Down' (GPS): MaxSatellites must be >= MinSatellites (12), got 9"),
        (OpticalFlow, {"MinRange": 6.0},
         "sensor 'Down' (OpticalFlow): MaxRange must be > MinRange (6), got 5"),
        (INS, {"AttBiasTime": 0}, "sensor 'Down' (INS): AttBiasTime must be > 0"),
    ],
)
def test_config_errors_name_sensor_and_key(cls: type[Sensor[Any]], params: dict[str, object],
                                           message: str) -> None:
    with pytest.raises(ConfigError) as exc:
        cls("Down", Mount(), params, np.random.default_rng(0))
    assert str(exc.value).startswith(message), str(exc.value)


def test_unknown_type_and_bad_mount() -> None:
    with pytest.raises(ConfigError, match=r"unknown sensor type 'Lidar'.*Sonar.*OpticalFlow"):
        build_sensor("Lidar", "L", Mount(), {}, np.random.default_rng(0))
    with pytest.raises(ConfigError, match=r"sensor 'S' \(Sonar\): Position"):
        build_sensor("Sonar", "S", Mount(pos_frd_m=(0.0, math.inf, 0.0)), {},
                     np.random.default_rng(0))


@settings(max_examples=150, deadline=None)
@given(
    type_key=st.sampled_from(sorted(SENSOR_CLASSES)),
    params=st.dictionaries(
        st.sampled_from(["Rate", "NoiseSigma", "MaxRange", "MinRange", "BeamRays", "Pixels",
                         "PosWalk", "MinSatellites", "bogus"]),
        st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 50),
                  st.booleans(), st.text(max_size=3), st.none()),
        max_size=4,
    ),
)
def test_any_parameters_build_a_sensor_or_raise_config_error(type_key: str,
                                                             params: dict[str, object]) -> None:
    try:
        sensor = build_sensor(type_key, "X", Mount(), params, np.random.default_rng(0))
    except ConfigError as exc:
        assert "sensor 'X'" in str(exc)
        return
    assert sensor.rate_hz > 0
    if isinstance(sensor, Battery):
        sensor.update_battery(12.0, 1.0, 0.5)
    fields = sensor.sample(make_state(pos=(0, 0, -1.0)), FlatWorld())
    assert fields and all(isinstance(k, str) for k, _ in fields)


@given(st.lists(st.integers(1, 3000), min_size=1, max_size=12), st.integers(0, 2**32))
@settings(max_examples=25, deadline=None)
def test_a_normal_stream_hands_out_the_generators_own_sequence(sizes: list[int], seed: int):
    """Requests of any size, across the stream's block boundaries, give the same numbers as
    drawing each request from the Generator when it is made."""
    stream = NormalStream(np.random.default_rng(seed))
    direct = np.random.default_rng(seed)
    for k in sizes:
        assert stream.take(k) == direct.standard_normal(k).tolist()
