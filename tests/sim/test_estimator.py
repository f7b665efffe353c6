"""The board's onboard estimator: computed from sensor readings only, and its written-out maths.

The estimator is driven here two ways: with hand-made readings (what a sensor's bias does to
the estimate) and inside the simulator (what losing the optical flow does to a hovering vehicle).
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from skeye.errors import ConfigError, LocalProtocolError
from skeye.geo import GeoOrigin
from skeye.robots.params import EstimatorParams
from skeye.sim.engine import RobotWorldQuery, Simulation
from skeye.sim.estimator import Axis, BoardEstimator
from skeye.sim.sensors import AccelReading, CompassReading, GpsReading, GyroReading
from skeye.sim.world import load_world

G = 9.81


def _still(est: BoardEstimator, seconds: float, accel: tuple[float, float, float],
           gyro: tuple[float, float, float], field: tuple[float, float, float]) -> None:
    """Feed an IMU at 100 Hz and a compass at 20 Hz, as a vehicle standing still."""
    for k in range(round(seconds * 100)):
        t = k * 0.01
        est.observe(AccelReading(t, accel))
        est.observe(GyroReading(t, gyro))
        if k % 5 == 0:
            est.observe(CompassReading(t, 0.0, field))


def test_an_accelerometer_bias_shows_up_as_tilt_in_the_estimate() -> None:
    """Level and still, but the accelerometer reads 0.2 m/s^2 too much along x: the attitude
    filter believes the reading, so the estimated pitch settles at atan(0.2 / g) nose up (the
    estimate comes from the readings, not from the truth)."""
    est = BoardEstimator(EstimatorParams(), (0.0, 0.0, -1.0), (0.0, 0.0, 0.0), 0.0, 163.0)
    _still(est, 60.0, (0.2, 0.0, -G), (0.0, 0.0, 0.0), (20.0, 0.0, 45.0))
    roll, pitch, yaw = est.estimate().rpy_rad
    # An FRD body pitched nose-up by theta feels the specific force g sin(theta) along +x.
    assert pitch == pytest.approx(math.atan2(0.2, G), abs=0.003)
    assert abs(roll) < 0.003 and abs(yaw) < 0.01


def test_a_gyro_bias_is_estimated_and_removed() -> None:
    """A constant 0.01 rad/s roll-rate bias: the Mahony integral learns it; the body rate the
    board flies on returns to zero and the roll estimate stays level."""
    est = BoardEstimator(EstimatorParams(), (0.0, 0.0, -1.0), (0.0, 0.0, 0.0), 0.0, 163.0)
    _still(est, 200.0, (0.0, 0.0, -G), (0.01, 0.0, 0.0), (20.0, 0.0, 45.0))
    out = est.estimate()
    assert est.bias[0] == pytest.approx(0.01, abs=0.001)
    assert abs(out.omega_frd_rad_s[0]) < 0.001
    assert abs(out.rpy_rad[0]) < 0.005


def test_compass_heading_corrects_yaw_against_the_declination() -> None:
    """Started 0.3 rad off in yaw, the compass pulls the estimate to the heading its field
    implies: field along NED north rotated by the 0.1 rad declination, vehicle facing north."""
    dec = 0.1
    est = BoardEstimator(EstimatorParams(), (0.0, 0.0, -1.0), (0.0, 0.0, 0.3), dec, 163.0)
    # The world field points 0.1 rad east of north; a body facing true north sees it at +0.1.
    field = (20.0 * math.cos(dec), 20.0 * math.sin(dec), 45.0)
    _still(est, 120.0, (0.0, 0.0, -G), (0.0, 0.0, 0.0), field)
    assert est.estimate().rpy_rad[2] == pytest.approx(0.0, abs=0.01)


def test_axis_filter_matches_the_matrix_kalman_filter() -> None:
    """The written-out 3-state filter against the textbook matrix form (reference run): the
    same random inputs and measurements give the same states and covariance."""
    rng = np.random.default_rng(4)
    axis = Axis(1.0, 0.04, 0.09, 0.01)
    x = np.array([1.0, 0.0, 0.0])
    p = np.diag([0.04, 0.09, 0.01])
    acc_var, walk_var = 0.35**2, 0.003**2
    for step in range(500):
        dt = 0.01
        acc = float(rng.normal())
        axis.predict(acc, dt, acc_var, walk_var)
        f = np.array([[1.0, dt, 0.0], [0.0, 1.0, -dt], [0.0, 0.0, 1.0]])
        x = np.array([x[0] + x[1] * dt + 0.5 * (acc - x[2]) * dt * dt,
                      x[1] + (acc - x[2]) * dt, x[2]])
        q = acc_var * np.array([[dt**4 / 4, dt**3 / 2, 0.0], [dt**3 / 2, dt**2, 0.0],
                                [0.0, 0.0, 0.0]])
        q[2, 2] = walk_var * dt
        p = f @ p @ f.T + q
        for index, every in ((0, 7), (1, 3)):
            if step % every:
                continue
            z, r = float(rng.normal()), 0.05 + index * 0.01
            (axis.fuse_pos if index == 0 else axis.fuse_vel)(z, r)
            h = np.zeros(3)
            h[index] = 1.0
            s = h @ p @ h + r
            k = p @ h / s
            x = x + k * (z - h @ x)
            p = p - np.outer(k, h @ p)
    assert [axis.p, axis.v, axis.b] == pytest.approx(list(x), rel=1e-9, abs=1e-12)
    mine = [axis.c00, axis.c01, axis.c02, axis.c11, axis.c12, axis.c22]
    ref = [p[0, 0], p[0, 1], p[0, 2], p[1, 1], p[1, 2], p[2, 2]]
    assert mine == pytest.approx(ref, rel=1e-9, abs=1e-15)


def _hover_velocity_error(robot_dirs: tuple[Path, ...], class_name: str) -> float:
    """Hover indoors (no GPS) for 10 s: |estimated - true| horizontal velocity at the end."""
    sim = Simulation(load_world("indoor"), seed=2, robot_dirs=robot_dirs, estimator="onboard")
    robot = sim.spawn(class_name, name="R1", sink=lambda events: None,
                      location_ned_m=(0.0, 0.0, -1.5))
    assert robot.estimator is not None
    sim.step(10000)
    truth = sim.body_state("R1").vel_ned_m_s
    est = robot.estimator.estimate().vel_ned_m_s
    return math.hypot(truth[0] - est[0], truth[1] - est[1])


def test_the_power_up_calibration_takes_the_gyro_bias_and_the_tilt_from_readings() -> None:
    """The board's power-up calibration averages readings taken standing still: the gyro's
    mean becomes its bias estimate (the body rate flown on is then unbiased at once, where
    Mahony's integral needs tens of seconds), and roll and pitch level on the mean specific
    force, whatever the spawn pose said; the heading is kept."""
    est = BoardEstimator(EstimatorParams(), (0.0, 0.0, -1.0), (0.0, 0.0, 0.3), 0.0, 163.0)
    rng = np.random.default_rng(4)
    gyro = [tuple(float(v) for v in (0.004, -0.006, 0.002) + 0.001 * rng.standard_normal(3))
            for _ in range(50)]
    tilt = 0.02  # the accelerometer says: rolled 0.02 rad right
    accel = [(0.0, -G * math.sin(tilt), -G * math.cos(tilt))] * 50
    est.align_at_rest(gyro, accel)  # type: ignore[arg-type]
    assert est.bias == pytest.approx([0.004, -0.006, 0.002], abs=0.0005)
    roll, pitch, yaw = est.estimate().rpy_rad
    assert roll == pytest.approx(tilt, abs=1e-9)
    assert abs(pitch) < 1e-9 and yaw == pytest.approx(0.3, abs=1e-9)
    est.observe(GyroReading(0.0, gyro[0]))
    assert max(abs(w) for w in est.estimate().omega_frd_rad_s) < 0.004


def test_a_vehicle_spawned_on_the_ground_starts_calibrated() -> None:
    """Spawned on its gear, the board calibrates from its own sensors as it powers up: the
    estimated gyro bias is the mean of that gyro's readings at rest (its turn-on bias), not
    zero. A vehicle spawned in the air stands for one whose board calibrated before take-off:
    its gyro bias is found the same way, its attitude stays the spawn pose (the accelerometer
    feels no force at the spawn instant)."""
    sim = Simulation(load_world("pad"), seed=3, estimator="onboard")
    grounded = sim.spawn("hummingbird", name="G", sink=lambda events: None, start="Pad1")
    airborne = sim.spawn("hummingbird", name="A", sink=lambda events: None,
                         location_ned_m=(5.0, 5.0, -2.0))
    assert grounded.estimator is not None and airborne.estimator is not None
    assert max(abs(b) for b in airborne.estimator.bias) > 0.001
    assert airborne.estimator.rpy() == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    gyro = next(s.sensor for s in grounded.sensors + grounded.board_sensors
                if s.board and s.sensor.type_name == "Gyro")
    query = RobotWorldQuery(sim, "G")
    readings = [gyro.read(sim.body_state("G"), query).angular_velocity_rad_s for _ in range(200)]
    mean = np.mean(np.array(readings), axis=0)
    assert np.abs(mean).max() > 0.001  # the part has a turn-on bias to find
    assert np.array(grounded.estimator.bias) == pytest.approx(mean, abs=0.0005)
    # Roll and pitch are the accelerometer's, not the spawn pose's (level on the pad).
    accel = next(s.sensor for s in grounded.sensors + grounded.board_sensors
                 if s.board and s.sensor.type_name == "Accelerometer")
    fx, fy, fz = np.mean(np.array([accel.read(sim.body_state("G"), query).proper_acceleration_m_s2
                                   for _ in range(200)]), axis=0)
    roll, pitch, _ = grounded.estimator.rpy()
    assert roll == pytest.approx(math.atan2(-fy, -fz), abs=0.001)
    assert pitch == pytest.approx(math.atan2(fx, math.hypot(fy, fz)), abs=0.001)
    assert max(abs(roll), abs(pitch)) > 0.001  # the part's errors tilt it off the true level


def test_cutting_the_optical_flow_makes_velocity_drift(tmp_path: Path) -> None:
    """The same vehicle over a floor the flow sensor cannot see (SQUAL 0): without flow (and
    no GPS indoors) the horizontal velocity is integrated accelerometer and drifts."""
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text()
    blind = text.replace('name = "hummingbird"', 'name = "blindflow"').replace(
        'name = "Flow"\n', 'name = "Flow"\nSurfaceQuality = 0\nQualitySigma = 0\n'
    )
    assert blind.count("SurfaceQuality = 0") == 1
    (tmp_path / "blindflow.toml").write_text(blind)
    with_flow = _hover_velocity_error((tmp_path,), "hummingbird")
    without = _hover_velocity_error((tmp_path,), "blindflow")
    assert with_flow < 0.15
    assert without > 0.5 > 3 * with_flow


def test_truth_estimator_is_the_oracle() -> None:
    """``--estimator truth``: no board estimator; the INS is ground truth plus its small error
    processes, and the vehicle holds its spawn point as it did before the onboard estimator."""
    sim = Simulation(load_world("indoor"), seed=2, estimator="truth")
    robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                      location_ned_m=(0.0, 0.0, -1.5))
    assert robot.estimator is None and robot.estimator_kind == "truth"
    sim.step(5000)
    pos = sim.body_state("R1").pos_ned_m
    assert math.hypot(pos[0], pos[1]) < 0.1


def test_estimator_kind_is_checked() -> None:
    with pytest.raises(LocalProtocolError, match="estimator must be one of"):
        Simulation(load_world("pad"), estimator="oracle")
    with pytest.raises(ConfigError, match="kind must be one of"):
        EstimatorParams(kind="kalman")
    with pytest.raises(ConfigError, match="sonar_noise_m"):
        EstimatorParams(sonar_noise_m=-1.0)


def test_a_disarmed_board_holds_its_velocity_estimate_at_zero() -> None:
    """On the ground with the motors off an accelerometer bias would integrate into velocity;
    the board's zero-velocity update (every 0.2 s while disarmed) keeps it near zero."""
    def velocity_after(rest: bool) -> float:
        est = BoardEstimator(EstimatorParams(), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 163.0)
        for k in range(3000):  # 30 s at 100 Hz, 0.1 m/s^2 of bias along x
            t = k * 0.01
            est.observe(AccelReading(t, (0.1, 0.0, -G)))
            est.observe(GyroReading(t, (0.0, 0.0, 0.0)))
            if rest:
                est.at_rest(t)
        vn, ve, _ = est.estimate().vel_ned_m_s
        return math.hypot(vn, ve)

    assert velocity_after(rest=True) < 0.02
    assert velocity_after(rest=False) > 0.1  # the attitude filter takes up most of the bias


def _north(t: float) -> tuple[float, float, float]:
    """Standing still for 5 s, 1 s at 2 m/s^2, then 2 m/s north: (position, velocity,
    acceleration) at ``t``."""
    if t < 5.0:
        return 0.0, 0.0, 0.0
    if t < 6.0:
        return (t - 5.0) ** 2, 2.0 * (t - 5.0), 2.0
    return 1.0 + 2.0 * (t - 6.0), 2.0, 0.0


def _gps_chase(delay_s: float) -> tuple[float, float]:
    """A level vehicle (``_north``) for 25 s; the accelerometer feels the acceleration and
    gravity, the GPS (5 Hz) reports where the vehicle was 0.2 s earlier. The estimator is
    configured with ``delay_s``: (mean, largest) |north error| over the last 10 s. The attitude
    filter's accelerometer correction is off (kp = ki = 0): a level vehicle accelerating would
    read as tilted, and this test is of the translation filter."""
    origin = GeoOrigin(49.0, 8.0, 100.0)
    params = EstimatorParams(gps_delay_s=delay_s, attitude_kp=0.0, attitude_ki=0.0)
    est = BoardEstimator(params, (0.0, 0.0, -10.0), (0.0, 0.0, 0.0), 0.0, 163.0)
    latency = 0.2
    errors = []
    for k in range(2500):
        t = k * 0.01
        est.observe(AccelReading(t, (_north(t)[2], 0.0, -G)))
        est.observe(GyroReading(t, (0.0, 0.0, 0.0)))
        if k % 20 == 0:
            then, speed, _ = _north(t - latency)
            lat, lon, alt = origin.to_geodetic(then, 0.0, -10.0)
            est.observe(GpsReading(t, 1, 9, lat, lon, alt, (speed, 0.0, 0.0)))
        if t >= 15.0:
            errors.append(abs(est.estimate().pos_ned_m[0] - _north(t)[0]))
    return sum(errors) / len(errors), max(errors)


def test_a_late_gps_fix_is_fused_against_the_estimate_of_its_time() -> None:
    """GPS latency (0.2 s): compared with the estimate of 0.2 s ago, the fix keeps the
    estimate on the vehicle; fused as if it were current, it drags the estimate back towards
    where the vehicle was (0.4 m behind at 2 m/s)."""
    mean_compensated, worst_compensated = _gps_chase(0.2)
    mean_naive, _ = _gps_chase(0.0)
    assert worst_compensated < 0.05, worst_compensated
    assert mean_naive > 0.1 > 2 * mean_compensated, (mean_naive, mean_compensated)
