"""Sensor imperfections from datasheets (issue 17): each one shown against ground truth."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from skeye.sim.engine import RobotWorldQuery, Simulation
from skeye.sim.sensors import (
    GPS,
    Accelerometer,
    Barometer,
    Gyro,
    MagneticCompass,
    OpticalFlow,
    Sonar,
)
from skeye.sim.world import load_world
from tests.sim.test_sensors import ORIGIN, FlatWorld, make, make_state, series


def test_sonar_reports_whole_centimetres_and_a_new_ranging_every_65_ms() -> None:
    sonar = make(Sonar, seed=5)
    world = FlatWorld()
    rate_hz = 1000.0  # sampled far faster than it ranges
    changes: list[float] = []
    last: float | None = None
    for k in range(2000):
        t = k / rate_hz
        height = 1.0 + 0.5 * t  # climbing: every ranging differs
        r = dict(sonar.sample(make_state(t=t, pos=(0.0, 0.0, -height)), world))["Range"]
        assert r == round(r * 100.0) / 100.0  # whole centimetres
        if last is not None and r != last:
            changes.append(t)
        last = r
    gaps = np.diff(changes)
    assert gaps.min() >= 0.065 - 1e-9
    assert np.median(gaps) == pytest.approx(0.065, abs=1.5 / rate_hz)
    # A reading lags its geometry by up to two rangings: the last one started 65 ms before.
    assert sonar.last is not None
    height_then = 1.0 + 0.5 * (1.999 - 0.065)
    assert sonar.last.range_m == pytest.approx(height_then, abs=0.05)


def test_sonar_missed_and_multiple_echoes_at_the_configured_rates() -> None:
    miss, multi, n = 0.1, 0.05, 4000
    sonar = make(Sonar, seed=11, NoiseSigma=0.0, RangingTime=0.0, MissProbability=miss,
                 MultiEchoProbability=multi)
    world = FlatWorld()
    ranges = [dict(sonar.sample(make_state(t=k / 15.0, pos=(0.0, 0.0, -1.5)), world))["Range"]
              for k in range(n)]
    counts = {v: ranges.count(v) for v in set(ranges)}
    assert set(counts) == {1.5, 3.0, 6.0}  # the echo, the second echo, no echo (MaxRange)
    for value, p in ((6.0, miss), (3.0, multi)):
        sd = math.sqrt(p * (1.0 - p) / n)
        assert abs(counts[value] / n - p) < 4.0 * sd, (value, counts)
    # Same seed, same readings.
    again = make(Sonar, seed=11, NoiseSigma=0.0, RangingTime=0.0, MissProbability=miss,
                 MultiEchoProbability=multi)
    assert [dict(again.sample(make_state(t=k / 15.0, pos=(0.0, 0.0, -1.5)), world))["Range"]
            for k in range(n)] == ranges
    # A second echo beyond MaxRange is no echo.
    far = make(Sonar, seed=1, NoiseSigma=0.0, RangingTime=0.0, MissProbability=0.0,
               MultiEchoProbability=1.0)
    assert far.sample(make_state(pos=(0.0, 0.0, -4.0)), world) == [("Range", 6.0)]
    assert far.last is not None and not far.last.echo


def imu_mean(cls: type[Any], seed: int, n: int, **state: Any) -> np.ndarray:
    sensor = make(cls, seed=seed, NoiseSigma=0.0, BiasWalk=0.0)
    key = "AngularVelocity" if cls is Gyro else "ProperAcceleration"
    readings = np.array([dict(sensor.sample(make_state(t=k / 100.0, **state), FlatWorld()))[key]
                         for k in range(n)])
    assert np.all(readings == readings[0])  # turn-on errors are constant within a run
    return readings[0]


@pytest.mark.parametrize("cls", [Gyro, Accelerometer])
def test_imu_turn_on_bias_differs_per_seed_and_is_constant_in_a_run(cls: type[Any]) -> None:
    # At rest (noise and bias walk off) every reading is the same: truth through the turn-on
    # scale/misalignment plus the turn-on bias; another seed is another part.
    zero = imu_mean(cls, 1, 200)
    other = imu_mean(cls, 2, 200)
    assert np.all(np.abs(zero - other) > 1e-6)
    assert np.all(zero == imu_mean(cls, 1, 50))  # same seed, same turn-on errors


def test_imu_scale_factor_and_misalignment_follow_the_datasheet_spread() -> None:
    # Rotating at 2 rad/s about z: x and y see the misalignment, z the scale error.
    omega = 2.0
    rows = np.array([imu_mean(Gyro, seed, 1, omega=(0.0, 0.0, omega)) for seed in range(300)])
    p = make(Gyro).params
    bias = p["BiasSigma"]
    z_scale = (rows[:, 2] - omega) / omega
    xy = rows[:, :2] / omega
    assert z_scale.std() == pytest.approx(math.hypot(p["ScaleSigma"], bias / omega), rel=0.2)
    assert xy.std() == pytest.approx(math.hypot(p["MisalignmentSigma"], bias / omega), rel=0.2)
    # Switched off, a still bias-free gyro reads the rate exactly.
    ideal = make(Gyro, NoiseSigma=0.0, BiasSigma=0.0, BiasWalk=0.0, ScaleSigma=0.0,
                 MisalignmentSigma=0.0, GSensitivity=0.0)
    assert dict(ideal.sample(make_state(omega=(0.0, 0.0, omega)), FlatWorld()))[
        "AngularVelocity"] == (0.0, 0.0, omega)


def test_gps_has_no_fix_before_acquisition_and_lags_by_its_latency() -> None:
    gps = make(GPS, seed=3, HorizontalSigma=0.0, VerticalSigma=0.0, VelocitySigma=0.0,
               FixTime=2.0)
    speed = 1.0
    fixes: list[tuple[float, float]] = []
    for k in range(50):  # 10 s at 5 Hz, flying north at 1 m/s
        t = k / 5.0
        f = dict(gps.sample(make_state(t=t, pos=(speed * t, 0.0, -1.0), vel=(speed, 0, 0)),
                            FlatWorld()))
        if t < 2.0:
            assert f == {"Fix": 0, "Satellites": 0}
            continue
        assert f["Fix"] == 1
        north = ORIGIN.to_ned(f["LatitudeDeg"], f["LongitudeDeg"], f["Altitude"])[0]
        fixes.append((t, float(north)))
    lags = [t - north / speed for t, north in fixes]
    assert lags == pytest.approx([0.2] * len(lags), abs=1e-3)


def test_gps_velocity_error_has_the_u_blox_6_accuracy() -> None:
    """The LEA-6's u-blox 6 engine is rated 0.1 m/s velocity accuracy (NEO-6 data sheet
    GPS.G6-HW-09005), read as the median of the horizontal error, as its 2.5 m CEP is the
    position's: the readings' horizontal velocity error has that median (the M8's 0.05 m/s,
    the default until 2026-11-28, gave 0.059 m/s)."""
    gps = make(GPS, seed=4, FixTime=0.0)
    n, velocity = 6000, np.array([1.0, -0.5, 0.0])
    errors = []
    for k in range(n):  # 20 minutes at 5 Hz, flying at a constant velocity
        t = k / 5.0
        f = dict(gps.sample(make_state(t=t, pos=tuple(velocity * t + [0.0, 0.0, -2.0]),
                                       vel=tuple(velocity)), FlatWorld()))
        errors.append(np.array(f["VelocityNED"]) - velocity)
    err = np.array(errors)
    horizontal = np.hypot(err[:, 0], err[:, 1])
    # The sample median's standard error for a Rayleigh error: about 1.1 % at this n.
    assert float(np.median(horizontal)) == pytest.approx(0.1, rel=0.05)
    per_axis = 0.1 / math.sqrt(2.0 * math.log(2.0))  # 0.085 m/s: a Rayleigh median of 0.1
    assert err.std(axis=0) == pytest.approx([per_axis] * 3, rel=0.05)


def test_compass_white_noise_is_the_hmc5883l_noise_floor() -> None:
    """Honeywell HMC5883L data sheet: noise floor 2 mG (0.2 uT), also its effective resolution
    at the default 1.3 Ga gain (0.92 mG LSb). With the bias walk off, the readings at a fixed
    attitude scatter by that per axis (the default was 0.3 uT until 2026-11-28)."""
    compass = make(MagneticCompass, seed=6, BiasWalk=0.0)
    fields = np.array([r["Field"] for r in series(compass, 6000, rpy=(0.0, 0.0, 0.4))])
    noise_floor_ut = 2.0 * 0.1  # 2 mG, 0.1 uT per mG
    # The sample standard deviation's standard error: 1/sqrt(2n), about 0.9 % at this n.
    assert fields.std(axis=0) == pytest.approx([noise_floor_ut] * 3, rel=0.05)


def test_baro_reads_low_in_ground_effect_from_the_rotor_wash() -> None:
    kf, radius, hover_w = 8.54858e-6, 0.1, 441.7  # the Hummingbird (docs/physics.md)
    baro = make(Barometer, NoiseSigma=0.0, BiasSigma=0.0, BiasWalk=0.0,
                RotorThrustCoefficient=kf, RotorRadius=radius)
    world = FlatWorld()
    rotors = (hover_w,) * 4

    def altitude_error(height: float, speeds: tuple[float, ...]) -> float:
        state = make_state(pos=(0.0, 0.0, -height))
        state.rotor_speed_rad_s = (speeds[0], speeds[1], speeds[2], speeds[3])
        f = dict(baro.sample(state, world))
        return float(f["Altitude"]) - (ORIGIN.altitude_m + height)

    assert altitude_error(2.0, rotors) == pytest.approx(0.0, abs=1e-6)  # above 4 R: none
    assert altitude_error(0.1, (0.0,) * 4) == pytest.approx(0.0, abs=1e-6)  # motors off
    disk_loading = 4 * kf * hover_w**2 / (4 * math.pi * radius**2)
    gain = 1.0 / (1.0 - (radius / (4 * 0.1)) ** 2)
    assert baro.rotor_wash_pa(make_state(pos=(0.0, 0.0, -0.1)), world) == 0.0  # no rotor speeds
    low = altitude_error(0.1, rotors)
    assert low == pytest.approx(-(gain - 1.0) * disk_loading * 0.0832, rel=0.05)
    assert low < altitude_error(0.2, rotors) < altitude_error(0.35, rotors) < 0.0


def test_flow_quality_follows_the_texture_and_drops_out_over_a_plain_surface() -> None:
    textured, plain = FlatWorld(contrast=0.3), FlatWorld(contrast=0.0)
    flow = make(OpticalFlow, seed=4)
    moving: dict[str, Any] = {"pos": (0.0, 0.0, -1.0), "vel": (0.5, 0.0, 0.0)}
    over_texture = [dict(flow.sample(make_state(t=k / 50.0, **moving), textured))
                    for k in range(100)]
    over_plain = [dict(flow.sample(make_state(t=2.0 + k / 50.0, **moving), plain))
                  for k in range(100)]
    assert min(r["Quality"] for r in over_texture) > 80
    total = sum(r["Delta"][0] for r in over_texture)  # 0.5 rad/s for 2 s
    assert total == pytest.approx(flow.counts_per_rad * 1.0, rel=0.05)
    assert all(r["Quality"] == 0 and r["Delta"] == (0, 0) for r in over_plain)
    # Faint texture: quality in proportion to the contrast below ReferenceContrast.
    faint = make(OpticalFlow, seed=4, QualitySigma=0.0)
    q = dict(faint.sample(make_state(**moving), FlatWorld(contrast=0.05)))["Quality"]
    assert q == round(100 * 0.05 / faint.params["ReferenceContrast"])


def test_flow_quality_from_the_real_world_surface_under_the_sensor(tmp_path: Path) -> None:
    # A plain ground (texture "none") with the textured pad at the origin: one vehicle hovers
    # over the pad, one over the plain ground; the engine's ray tells which surface is under.
    world_file = tmp_path / "plain.toml"
    world_file.write_text(
        'name = "plain"\n[ground]\nsize_m = 30.0\ntexture = "none"\n'
        '[[pads]]\nname = "pad1"\npad = "skeye-4"\nposition_ned_m = [0.0, 0.0, 0.0]\n'
        'yaw_rad = 0.0\n'
    )
    sim = Simulation(load_world(world_file), seed=2)
    quality: dict[str, list[int]] = {}
    for name, north in (("OverPad", 0.0), ("OverPlain", 10.0)):
        robot = sim.spawn("hummingbird", name=name, sink=lambda events: None,
                          location_ned_m=(north, 0.0, -1.0))
        flow = next(s.sensor for s in robot.sensors if isinstance(s.sensor, OpticalFlow))
        query = RobotWorldQuery(sim, name)
        quality[name] = [flow.read(sim.body_state(name), query).quality for _ in range(20)]
    assert min(quality["OverPad"]) > 80, quality
    assert quality["OverPlain"] == [0] * 20


def test_the_pad_collider_shows_the_pad_texture_to_the_flow_sensor() -> None:
    """The pad's collision box and its textured sheet share the top face: a ray may report
    either, and both must read as the pad (a plain box read SQUAL 0 over the pad's middle)."""
    from skeye.sim.surface_contrast import geom_contrasts
    from skeye.sim.world import load_world

    contrasts = geom_contrasts(load_world("pad"))
    assert contrasts["pad:pad1:collider"] == contrasts["pad:pad1"] > 0.5
