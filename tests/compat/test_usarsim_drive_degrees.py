"""Issue 19, point 2: DRIVE angles are degrees, as USARSim's ``AerialVehicle.uc``.

``setRotationVelocity`` takes deg/s and ``setPitchAngle`` / ``setRollAngle`` degrees (each
converts with ``UnitsConverter.AngleFromDeg``); with ``{Normalized true}`` each is percent of
the vehicle's maximum. A USARSim client sends ``{RotationalVelocity 10}`` meaning 10 deg/s.
"""

from __future__ import annotations

import math

import pytest

from tests.compat.usarsim_client import UsarClient, blocks, sen_lines, unreal_float, wrap_pi


def _orientation(line: list[tuple[str, str]]) -> tuple[float, float, float]:
    assert line[4][0] == "Orientation"  # GroundTruth.GetData: {Name} {Location} {Orientation}
    r, p, y = (unreal_float(v) for v in line[4][1].split(","))
    return r, p, y


def _hover(client: UsarClient) -> None:
    client.send("INIT {ClassName hummingbird} {Location 0,0,-3}")
    assert client.read_line().startswith("RES {Command INIT}")
    client.step(500)


def _measured_yaw_rate_deg_s(client: UsarClient) -> float:
    client.step(1500)  # let the yaw rate settle
    gt = sen_lines(client.step(2000), "GroundTruth")
    t0, t1 = unreal_float(gt[0][0][1]), unreal_float(gt[-1][0][1])
    turned = 0.0
    previous = _orientation(gt[0])[2]
    for line in gt[1:]:  # unwrap the heading (written in [0, 2 pi))
        yaw = _orientation(line)[2]
        turned += wrap_pi(yaw - previous)
        previous = yaw
    return math.degrees(turned) / (t1 - t0)


def test_rotational_velocity_is_deg_per_s(client: UsarClient) -> None:
    _hover(client)
    client.send("DRIVE {RotationalVelocity 10}")  # skeye used to refuse this (10 rad/s)
    assert not [line for line in client.sync() if line.startswith("ERR")]
    client.send("DRIVE {RotationalVelocity 30}")
    # positive: clockwise seen from above (UE yaw), as skeye's heading
    assert _measured_yaw_rate_deg_s(client) == pytest.approx(30.0, abs=3.0)


def test_normalized_rotational_velocity_is_percent_of_the_maximum(client: UsarClient) -> None:
    _hover(client)
    client.send("GETCONF {Type Robot}")
    _, conf = client.read_until("CONF")
    max_yaw_rad_s = unreal_float(dict(blocks(conf))["MaxYawRate"])  # skeye's CONF: rad/s
    client.send("DRIVE {RotationalVelocity -50} {Normalized true}")
    assert _measured_yaw_rate_deg_s(client) == pytest.approx(
        -0.5 * math.degrees(max_yaw_rad_s), abs=4.0)


def test_pitch_and_roll_angles_are_degrees(client: UsarClient) -> None:
    _hover(client)
    # skeye's attitude form needs Thrust (an extension): about the hover fraction.
    client.send("DRIVE {PitchAngle -8} {RollAngle 5} {RotationalVelocity 0} {Thrust 0.3}")
    assert not [line for line in client.sync() if line.startswith("ERR")]
    lines = client.step(600)
    roll, pitch, _ = _orientation(sen_lines(lines, "GroundTruth")[-1])
    assert math.degrees(wrap_pi(pitch)) == pytest.approx(-8.0, abs=1.5)  # nose down
    assert math.degrees(wrap_pi(roll)) == pytest.approx(5.0, abs=1.5)  # right side down


def test_angles_beyond_the_limits_are_refused_in_degrees(client: UsarClient) -> None:
    _hover(client)
    client.send("DRIVE {RotationalVelocity 500}")
    err = [line for line in client.sync() if line.startswith("ERR")]
    assert err and "RotationalVelocity" in err[0]
