"""In-flight vibration (skeye.sim.sensors.vibration), gyro g-sensitivity, the compass's motor
field, and the estimator's settings derived from the sensors' figures."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from skeye.robots.params import EstimatorParams
from skeye.sim.engine import Simulation
from skeye.sim.estimator import from_sensor_figures
from skeye.sim.sensors import (
    GPS,
    Accelerometer,
    Barometer,
    Gyro,
    MagneticCompass,
    OpticalFlow,
    Sonar,
)
from skeye.sim.sensors.inertial import HOVER_SPEED_RAD_S
from skeye.sim.world import load_world
from tests.sim.test_sensors import IMU_QUIET, FlatWorld, make, make_state

HOVER = (HOVER_SPEED_RAD_S,) * 4


def readings(sensor: Any, rate_hz: float, seconds: float, speeds: tuple[float, ...],
             **state: Any) -> np.ndarray:
    """The sensor's vector readings at ``rate_hz`` for ``seconds``, rotors at ``speeds``."""
    out = []
    for k in range(round(rate_hz * seconds)):
        st = make_state(t=k / rate_hz, **state)
        st.rotor_speed_rad_s = speeds  # type: ignore[assignment]
        reading = sensor.read(st, FlatWorld())
        out.append(getattr(reading, "proper_acceleration_m_s2", None)
                   or reading.angular_velocity_rad_s)
    return np.array(out)


def test_no_vibration_with_the_rotors_stopped() -> None:
    acc = make(Accelerometer, **IMU_QUIET)
    values = readings(acc, 100.0, 1.0, (0.0,) * 4)
    assert np.allclose(values, [0.0, 0.0, -9.81])


@pytest.mark.parametrize("cls", [Accelerometer, Gyro])
def test_hover_vibration_has_its_stated_level(cls: Any) -> None:
    quiet: dict[str, Any] = {**IMU_QUIET, "GSensitivity": 0.0} if cls is Gyro else IMU_QUIET
    # Four rotors at one speed: their lines add with the phases drawn for the part, so one
    # part's level varies; the stated level is the mean square over parts (seeds).
    variances = []
    for seed in range(24):
        values = readings(make(cls, seed=seed, **quiet), 1000.0, 1.0, HOVER)
        variances.append(values.var(axis=0).mean())
    expected = make(cls, **quiet).vibration.rms_sampled(4, 1000.0)
    assert math.sqrt(np.mean(variances)) == pytest.approx(expected, rel=0.12)
    # twice the speed, four times the vibration (an imbalance force grows with w^2)
    fast = [readings(make(cls, seed=seed, **quiet), 1000.0, 1.0, tuple(2 * w for w in HOVER))
            .var(axis=0).mean() for seed in range(24)]
    vib = make(cls, **quiet).vibration
    ratio = vib.rms_sampled(4, 1000.0, 2 * HOVER_SPEED_RAD_S) / vib.rms_sampled(4, 1000.0)
    assert 3.0 < ratio < 4.0  # w^2, less what the sensor's filter takes off the faster lines
    assert math.sqrt(np.mean(fast) / np.mean(variances)) == pytest.approx(ratio, rel=0.15)


def _peak_hz(x: np.ndarray, rate_hz: float) -> float:
    spectrum = np.abs(np.fft.rfft(x - x.mean()))
    return float(np.fft.rfftfreq(len(x), 1.0 / rate_hz)[int(np.argmax(spectrum))])


def test_the_rotor_line_aliases_at_the_sample_rate() -> None:
    f1 = HOVER_SPEED_RAD_S / (2 * math.pi)  # 70.3 Hz
    only_1p: dict[str, Any] = {**IMU_QUIET, "VibrationBladePass": 0.0, "VibrationBroadband": 0.0}
    fast = readings(make(Accelerometer, **only_1p), 1000.0, 4.0, HOVER)
    assert _peak_hz(fast[:, 0], 1000.0) == pytest.approx(f1, abs=0.5)
    slow = readings(make(Accelerometer, **only_1p), 50.0, 20.0, HOVER)
    assert _peak_hz(slow[:, 0], 50.0) == pytest.approx(abs(f1 - 50.0), abs=0.2)  # 20.3 Hz


def test_readings_clip_at_the_range() -> None:
    acc = make(Accelerometer, Range=10.0, **IMU_QUIET)
    values = readings(acc, 200.0, 2.0, HOVER)
    assert values.max() <= 10.0 and values.min() >= -10.0
    assert np.sum(values[:, 2] == -10.0) > 10  # -9.81 plus vibration reaches the range


def test_gyro_g_sensitivity_follows_the_specific_force() -> None:
    k = 1e-3
    errors = []
    for seed in range(200):
        gyro = make(Gyro, seed=seed, GSensitivity=k, **IMU_QUIET)
        errors.append(readings(gyro, 100.0, 0.02, (0.0,) * 4)[0])
    # at rest the part feels 1 g: each axis's error is k g N(0, 1) per entry of G
    assert np.std(errors) == pytest.approx(k * 9.81, rel=0.2)


def test_compass_feels_the_motor_currents() -> None:
    quiet: dict[str, Any] = {"NoiseSigma": 0.0, "BiasSigma": 0.0, "BiasWalk": 0.0}
    compass = make(MagneticCompass, seed=2, **quiet)
    still = make_state()
    base = np.array(compass.read(still, FlatWorld()).field_ut)
    hover = make_state(t=0.05)
    hover.rotor_speed_rad_s = HOVER  # type: ignore[assignment]
    moved = np.array(compass.read(hover, FlatWorld()).field_ut)
    assert np.linalg.norm(moved - base) == pytest.approx(compass.params["MotorField"], rel=1e-6)
    full = make_state(t=0.1)
    full.rotor_speed_rad_s = (2 * HOVER_SPEED_RAD_S,) * 4  # type: ignore[assignment]
    far = np.array(compass.read(full, FlatWorld()).field_ut)
    assert np.linalg.norm(far - base) == pytest.approx(8 * compass.params["MotorField"],
                                                       rel=1e-6)  # current ~ w^3


def test_estimator_settings_come_from_the_sensors() -> None:
    sensors = [make(cls) for cls in (Accelerometer, Gyro, Barometer, Sonar, OpticalFlow, GPS)]
    acc, gyro, baro, sonar, flow, gps = sensors
    p = from_sensor_figures(EstimatorParams(), acc, gyro, baro, sonar, flow, gps)  # type: ignore[arg-type]
    assert p.derived
    assert p.accel_noise_m_s2 == pytest.approx(
        math.hypot(acc.params["NoiseSigma"], acc.vibration.rms_sampled(4, acc.rate_hz)))
    assert p.gps_pos_noise_m == gps.params["HorizontalSigma"] == pytest.approx(2.5 / 1.18, 0.01)
    assert p.baro_noise_m == pytest.approx(baro.params["NoiseSigma"] / (1.225 * 9.81))
    assert p.gps_delay_s == gps.params["Latency"]
    # a figure the robot file gives is kept
    given = from_sensor_figures(EstimatorParams(baro_noise_m=3.5), *sensors)  # type: ignore[arg-type]
    assert given.baro_noise_m == 3.5
    # and the robot's board uses its own sensors' figures
    sim = Simulation(load_world("pad"), seed=1)
    robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None, start="Pad1")
    assert robot.estimator is not None and robot.estimator.p.derived
    board_gyro = next(s.sensor for s in robot.sensors if s.sensor.type_name == "Gyro")
    assert robot.estimator.p.tilt_noise_rad_s == pytest.approx(
        math.hypot(board_gyro.params["NoiseSigma"],
                   board_gyro.vibration.rms_sampled(4, board_gyro.rate_hz))
        / math.sqrt(board_gyro.rate_hz))


def test_deriving_keeps_every_other_setting() -> None:
    from dataclasses import fields

    from skeye.robots.params import SENSOR_DERIVED

    sensors = [make(cls) for cls in (Accelerometer, Gyro, Barometer, Sonar, OpticalFlow, GPS)]
    given = EstimatorParams(kind="truth", attitude_kp=0.3, attitude_ki=0.02, compass_gain=0.5,
                            accel_bias_init_m_s2=0.1, accel_bias_walk_m_s3=0.004,
                            flow_min_quality=5.0, flow_min_height_m=0.2)
    derived = from_sensor_figures(given, *sensors)  # type: ignore[arg-type]
    for f in fields(EstimatorParams):
        if f.name not in SENSOR_DERIVED:
            assert getattr(derived, f.name) == getattr(given, f.name), f.name


@pytest.mark.parametrize("rate_hz", [50.0, 200.0])
def test_readings_average_their_interval(rate_hz: float) -> None:
    # the level readings carry at a rate is the stated one (averaged over each interval)
    variances = [readings(make(Accelerometer, seed=seed, **IMU_QUIET), rate_hz, 20.0, HOVER)
                 .var(axis=0).mean() for seed in range(12)]
    expected = make(Accelerometer, **IMU_QUIET).vibration.rms_sampled(4, rate_hz)
    assert math.sqrt(np.mean(variances)) == pytest.approx(expected, rel=0.12)
    # EuRoC's 200 Hz level in hover: 1.1 m/s^2 per axis
    assert make(Accelerometer).vibration.rms_sampled(4, 200.0) == pytest.approx(1.1, rel=0.01)
    assert make(Gyro).vibration.rms_sampled(4, 200.0) == pytest.approx(0.065, rel=0.01)
