"""Flight physics acceptance tests, against a real lockstep server on a loopback port."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from skeye.robots.config import load_robot_config
from tests.sim.conftest import LineClient, running_sim, sensor_series, vec

G = 9.81


def spawn_airborne(client: LineClient, altitude_m: float, cls: str = "hummingbird") -> None:
    res = client.answer(
        f"INIT {{ClassName {cls}}} {{Name R1}} {{Location 0,0,{-altitude_m}}}", "INIT"
    )
    assert res.type == "RES", res


def test_hover_thrust_equals_weight(lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    spawn_airborne(c, 3.0)
    c.step(3000)
    msgs = c.step(2000)
    thrust = [float(v) for _, v in sensor_series(msgs, "Motors", "Thrust")]
    weight = load_robot_config("hummingbird").airframe.mass_kg * G
    assert len(thrust) >= 40
    assert abs(np.mean(thrust) / weight - 1.0) < 0.01


def test_free_fall_matches_g(lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    spawn_airborne(c, 40.0)
    c.step(500)
    c.send("DRIVE {RollAngle 0} {PitchAngle 0} {Thrust 0}")
    c.step(400)  # motors spin down (tau_down 25 ms)
    msgs = c.step(600)
    series = sensor_series(msgs, "GroundTruth", "Velocity")
    t = np.array([s[0] for s in series])
    vd = np.array([vec(s[1])[2] for s in series])
    # dv/dt = g - k v|v| with the documented quadratic air drag; motors are stopped.
    airframe = load_robot_config("hummingbird").airframe
    k = 0.5 * 1.225 * airframe.drag_area_m2 / airframe.mass_kg
    accel = np.diff(vd) / np.diff(t)
    v_mid = 0.5 * (vd[1:] + vd[:-1])
    g_measured = np.mean(accel + k * v_mid * np.abs(v_mid))
    assert abs(g_measured / G - 1.0) < 0.01, g_measured
    assert vd[-1] > 5.0  # it really fell
    # Nearly weightless: the accelerometer feels only the drag (upwards, body -z).
    acc = [vec(v) for _, v in sensor_series(msgs, "Accelerometer", "ProperAcceleration")]
    expected = -np.mean(k * v_mid**2)
    assert abs(np.mean([a[2] for a in acc]) - expected) < 0.15


def test_motor_step_follows_time_constant(tmp_path: Path, client_factory):
    text = (Path(__file__).parents[2] / "skeye/robots/hummingbird.toml").read_text()
    text = text.replace('name = "hummingbird"', 'name = "fastmotors"', 1)
    text = re.sub(r'(type = "Motors"\nname = "Motors"\nrate_hz = )\d+', r"\g<1>250", text)
    assert "rate_hz = 250" in text
    (tmp_path / "fastmotors.toml").write_text(text)
    with running_sim(robot_dirs=(tmp_path,)) as server:
        c = client_factory(server)
        spawn_airborne(c, 5.0, cls="fastmotors")
        before = c.step(2000)
        c.send("DRIVE {RollAngle 0} {PitchAngle 0} {RotationalVelocity 0} {Thrust 0.5}")
        msgs = c.step(60)
    w_before = np.mean(vec(sensor_series(before, "Motors", "Speeds")[-1][1]))
    series = sensor_series(msgs, "Motors", "Speeds")
    t = np.array([s[0] for s in series])
    w = np.array([np.mean(vec(s[1])) for s in series])
    airframe = load_robot_config("hummingbird").airframe
    w_target = math.sqrt(0.5 * airframe.max_thrust_n / 4 / airframe.kf)
    remaining = (w_target - w) / (w_target - w_before)  # exp(-(t - t0) / tau)
    mask = remaining > 0.05
    slope = np.polyfit(t[mask], np.log(remaining[mask]), 1)[0]
    tau = -1.0 / slope
    assert abs(tau / airframe.tau_up_s - 1.0) < 0.05, tau


def test_drive_forward_reaches_speed(truth_server, client_factory):
    """The velocity loop's response (5 % of the set-point): on the oracle estimator, since
    with the onboard one the flow estimate's own error is in the true speed."""
    c = client_factory(truth_server)
    spawn_airborne(c, 2.0)
    c.step(1000)
    c.send("DRIVE {LinearVelocity 0.5}")
    msgs = c.step(4000)
    t0 = msgs[0] and float(msgs[0].require("Time"))
    series = sensor_series(msgs, "GroundTruth", "Velocity")
    reached = [t for t, v in series if abs(math.hypot(*vec(v)[:2]) - 0.5) < 0.025]
    assert reached, "never within 5 % of 0.5 m/s"
    assert reached[0] - t0 < 2.0
    late = [math.hypot(*vec(v)[:2]) for t, v in series if t - t0 > 2.0]
    assert all(abs(s - 0.5) < 0.025 for s in late), max(late)


def test_hover_holds_height(lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    spawn_airborne(c, 1.5)
    msgs = c.step(20000)
    alts = [-vec(v)[2] for _, v in sensor_series(msgs, "GroundTruth", "Location")]
    # The board holds its sonar-aided height estimate (onboard estimator), not the true
    # height: a few centimetres, not the 2 cm the oracle estimator held.
    assert max(abs(a - 1.5) for a in alts) < 0.08


def test_take_off_from_pad_and_land(lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    assert c.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}", "INIT").type == "RES"
    msgs = c.step(500)
    sta = [m for m in msgs if m.type == "STA"]
    assert sta[-1].get_bool("Landed") and not sta[-1].get_bool("Armed")
    c.send("DRIVE {AltitudeVelocity 0.5}")
    c.step(3000)
    c.send("DRIVE {AltitudeVelocity 0}")
    msgs = c.step(2000)
    alt = -vec(sensor_series(msgs, "GroundTruth", "Location")[-1][1])[2]
    assert 1.0 < alt < 2.0
    assert not [m for m in msgs if m.type == "STA"][-1].get_bool("Landed")
    c.send("DRIVE {AltitudeVelocity -0.5}")
    msgs = c.step(8000)
    sta = [m for m in msgs if m.type == "STA"][-1]
    assert sta.get_bool("Landed") and not sta.get_bool("Armed")


def test_sonar_beyond_range_reports_max(lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    spawn_airborne(c, 9.0)
    msgs = c.step(1000)
    ranges = [float(v) for _, v in sensor_series(msgs, "Sonar", "Range")]
    assert ranges and all(r == 6.0 for r in ranges)


def test_sensors_agree_with_ground_truth(lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    spawn_airborne(c, 1.2)
    c.step(1000)
    msgs = c.step(5000)
    loc = np.array([vec(v) for _, v in sensor_series(msgs, "GroundTruth", "Location")])
    truth = loc.mean(axis=0)
    acc = np.array([vec(v) for _, v in sensor_series(msgs, "Accelerometer", "ProperAcceleration")])
    assert np.allclose(acc.mean(axis=0), (0, 0, -G), atol=0.15)
    gyro = np.array([vec(v) for _, v in sensor_series(msgs, "Gyro", "AngularVelocity")])
    assert np.allclose(gyro.mean(axis=0), 0, atol=0.02)
    sonar = np.array([float(v) for _, v in sensor_series(msgs, "Sonar", "Range")])
    sonar_true = -truth[2] - 0.001 - 0.03  # above the pad surface, from the sonar's mount
    assert abs(np.median(sonar) - sonar_true) < 0.05
    ins = np.array([vec(v) for _, v in sensor_series(msgs, "INS", "Location")])
    # The onboard estimate: height from the sonar, horizontal position GPS-aided (the GPS's
    # own wander since the first fix, 2.12 m sigma with a 300 s correlation time: 0.17 m per
    # square-root second).
    assert abs(ins.mean(axis=0)[2] - truth[2]) < 0.1
    assert math.hypot(*(ins.mean(axis=0)[:2] - truth[:2])) < 1.5
    baro = np.array([float(v) for _, v in sensor_series(msgs, "Barometer", "Altitude")])
    origin_alt = lockstep_server.runner.sim.world.geo_origin.altitude_m
    assert abs(baro.mean() - (origin_alt - truth[2])) < 1.0
    lat = np.array([float(v) for _, v in sensor_series(msgs, "GPS", "LatitudeDeg")])
    lon = np.array([float(v) for _, v in sensor_series(msgs, "GPS", "LongitudeDeg")])
    origin = lockstep_server.runner.sim.world.geo_origin
    n, e, _ = origin.to_ned(lat.mean(), lon.mean(), origin.altitude_m)
    assert math.hypot(n - truth[0], e - truth[1]) < 6.0
    heading = np.array(
        [float(v) for _, v in sensor_series(msgs, "MagneticCompass", "MagneticAngle")]
    )
    assert heading.size > 10
    flow = np.array([vec(v) for _, v in sensor_series(msgs, "OpticalFlow", "Delta")])
    assert np.abs(flow.mean(axis=0)).max() < 5.0  # hovering: little image motion


def _stream(seed: int) -> bytes:
    with running_sim(seed=seed) as server:
        c = LineClient(server.port)
        c.expect("NFO")
        spawn_airborne(c, 1.0)
        c.step(500)
        c.send("DRIVE {LinearVelocity 0.4} {LateralVelocity -0.2}")
        c.step(1500)
        c.close()
        return bytes(c.raw)


def test_lockstep_is_deterministic():
    a, b, other = _stream(5), _stream(5), _stream(6)
    assert a == b
    assert a != other


def test_hover_endurance_estimate(lockstep_server, client_factory):
    """STA {Battery} (remaining life, s) on a full battery at hover: about 20 minutes."""
    c = client_factory(lockstep_server)
    spawn_airborne(c, 2.0)
    msgs = c.step(10000)
    remaining = float([m for m in msgs if m.type == "STA"][-1].require("Battery"))
    assert abs(remaining / 1200.0 - 1.0) < 0.2, remaining


def test_robot_conf_lists_mounted_sensors(lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    spawn_airborne(c, 1.0)
    c.send("GETCONF {Type Robot}")
    conf = c.expect("CONF")
    sensors = conf.require("Sensors").split(",")
    assert "Sonar:Down" in sensors and "GroundTruth:GroundTruth" in sensors
    assert conf.get_float("Mass") == 0.68


def test_hover_until_the_battery_is_empty():
    """The documented endurance (about 20 minutes of hover, docs/physics.md), flown for real:
    1.2 M physics steps in-process with nothing streamed."""
    from skeye.sim.engine import Simulation
    from skeye.sim.world import load_world

    sim = Simulation(load_world("pad"), seed=1)
    robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                      location_ned_m=(0.0, 0.0, -2.0))
    robot.sensors = []  # the battery is the question; no stream to format
    while robot.flight.armed and sim.time_s < 1800:
        sim.step(10000)
        if robot.flight.armed:
            assert abs(-sim.body_state("R1").pos_ned_m[2] - 2.0) < 0.1  # still hovering
    assert not robot.flight.armed and robot.battery.empty
    assert abs(sim.time_s / 1200.0 - 1.0) < 0.2, sim.time_s


def test_full_throttle_tops_out_at_the_speed_the_sagging_battery_allows():
    """A brushless motor's top speed is its Kv times the voltage it gets, so a rotor at full
    throttle turns at the airframe's top speed (838 rad/s, a full battery) times the battery's
    voltage under load over its full voltage. Full throttle draws about 31 A (5.6 hover
    currents), which sags a fresh 3-cell pack by about 0.95 V (0.03 ohm), so the rotors top out
    near 775 rad/s (20.5 N of thrust in all, where the cap without sag gives 24.0 N).
    The old cap, min(1, V / V_full + 0.15), gave the whole 838 rad/s down to 85 % of the full
    voltage."""
    from skeye.sim.engine import Simulation
    from skeye.sim.vehicle import cell_open_circuit_v
    from skeye.sim.world import load_world

    sim = Simulation(load_world("pad"), seed=1)
    robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                      location_ned_m=(0.0, 0.0, -20.0))
    robot.sensors = []
    robot.drive(attitude=True, roll_rad=0.0, pitch_rad=0.0, thrust=1.0)
    sim.step(round(0.3 / sim.dt))  # 24 spin-up time constants (12.5 ms)
    airframe = load_robot_config("hummingbird").airframe
    full_v = 3 * cell_open_circuit_v(1.0)
    loaded_v = robot.battery.voltage_v
    assert loaded_v < 0.95 * full_v, loaded_v  # full throttle's sag
    top = airframe.max_rotor_speed_rad_s * loaded_v / full_v
    speeds = sim.body_state("R1").rotor_speed_rad_s
    # The cap follows the voltage of the tick before: within 0.1 % of it.
    assert speeds == pytest.approx([top] * 4, rel=1e-3), (speeds, top)
