"""A crash is a crash (issue 31): the simulator detects it, says so with the cause, refuses to
fly the wreck, and RESET brings the vehicle back. Against a real lockstep server on loopback."""

from __future__ import annotations

import math
import re

import pytest

from skeye.sim.crash import FAIL_ANGLE_RAD, FAIL_TRIGGER_S, IMPACT_SPEED_M_S, CrashDetector
from tests.sim.conftest import LineClient, sensor_series, vec

# The probe's wind line: a 50 N force (the range's top), redrawn once an hour.
PROBE_WIND = "SET {Type Wind} {Mode random_force} {Params f_max_n=50,tick_s=3600}"


def _crash(messages) -> list:
    return [m for m in messages if m.type == "ERR" and m.get("Command") == "CRASH"]


def _step_until_crash(c: LineClient, limit_s: float, chunk: int = 100) -> tuple[float, object]:
    """Step in chunks until the simulator reports a crash; (sim time of the report, ERR)."""
    t = 0.0
    while t < limit_s:
        msgs = c.step(chunk)
        t += chunk * 0.001
        crashes = _crash(msgs)
        if crashes:
            return t, crashes[0]
    raise AssertionError(f"no ERR {{Command CRASH}} within {limit_s} s of sim time")


def test_the_probe_wind_line_crashes_a_landed_vehicle_and_reset_brings_it_back(
        lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    assert c.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}", "INIT").type == "RES"
    c.step(500)
    assert c.answer(PROBE_WIND, "SET").type == "RES"
    _, err = _step_until_crash(c, 2.0)
    assert err.get("Name") == "R1"
    reason = err.get("Reason") or ""
    assert reason.startswith("crashed: "), reason
    assert "tumbled" in reason or "hard impact" in reason, reason
    # The wreck is not flown: DRIVE is refused with the cause and what to do.
    refused = c.answer("DRIVE {AltitudeVelocity 0.5}", "DRIVE")
    assert refused.type == "ERR" and "crashed" in refused.require("Reason")
    assert "RESET" in refused.require("Reason")
    sta = [m for m in c.step(200) if m.type == "STA"]
    assert sta and not sta[-1].get_bool("Armed")
    # Calm the air, reset: back on the pad, still, and it flies again.
    assert c.answer("SET {Type Wind} {Mode none}", "SET").type == "RES"
    res = c.answer("RESET", "RESET")
    assert res.type == "RES" and res.get("Name") == "R1" and res.get("Status") == "OK", res
    msgs = c.step(500)
    truth = [vec(v) for _, v in sensor_series(msgs, "GroundTruth", "Location")]
    assert math.hypot(truth[-1][0], truth[-1][1]) < 0.05, truth[-1]
    assert not _crash(msgs)
    c.send("DRIVE {AltitudeVelocity 0.5}")
    msgs = c.step(2000)
    truth = [vec(v) for _, v in sensor_series(msgs, "GroundTruth", "Location")]
    assert -truth[-1][2] > 0.4, truth[-1]  # climbing
    assert not _crash(msgs)


def test_a_hard_impact_is_a_crash_and_a_normal_landing_is_not(lockstep_server, client_factory):
    falling = client_factory(lockstep_server)
    landing = client_factory(lockstep_server)
    assert falling.answer("INIT {ClassName hummingbird} {Name F} {Location 0,3,-5}",
                          "INIT").type == "RES"
    assert landing.answer("INIT {ClassName hummingbird} {Name L} {Location 3,0,-2}",
                          "INIT").type == "RES"
    falling.step(300)
    falling.send("DRIVE {RollAngle 0} {PitchAngle 0} {Thrust 0}")  # motors off: a free fall
    landing.send("DRIVE {AltitudeVelocity -1.5}")  # the fastest descent it may command
    landing.answer("PING", "PING")
    _, err = _step_until_crash(falling, 3.0)
    assert err.get("Name") == "F" and "hard impact" in err.require("Reason"), err
    msgs = landing.step(4000)  # touchdown and a second on the ground
    assert not _crash(msgs), _crash(msgs)
    assert [m for m in msgs if m.type == "STA"][-1].get_bool("Landed")


def test_reset_places_the_robot_where_asked_and_needs_a_robot(lockstep_server, client_factory):
    c = client_factory(lockstep_server)
    early = c.answer("RESET", "RESET")
    assert early.type == "ERR" and "needs a robot" in early.require("Reason")
    assert c.answer("INIT {ClassName hummingbird} {Name R1} {Start Pad1}", "INIT").type == "RES"
    c.step(100)
    assert c.answer("RESET {Location 2,1,-3}", "RESET").type == "RES"
    msgs = c.step(1000)
    where = vec(sensor_series(msgs, "GroundTruth", "Location")[-1][1])
    assert abs(where[0] - 2) < 0.1 and abs(where[1] - 1) < 0.1 and abs(where[2] + 3) < 0.2
    sta = [m for m in msgs if m.type == "STA"][-1]
    assert sta.get_bool("Armed") and not sta.get_bool("Landed")  # in the air it hovers
    bad = c.answer("RESET {Start Nowhere}", "RESET")
    assert bad.type == "ERR" and "unknown start pose" in bad.require("Reason")
    assert c.answer("RESET {Start Field1}", "RESET").type == "RES"
    where = vec(sensor_series(c.step(200), "GroundTruth", "Location")[-1][1])
    assert abs(where[0] - 3) < 0.05 and abs(where[1]) < 0.05


@pytest.mark.parametrize("angle_deg", [61.0, 120.0, 180.0, -95.0])
def test_the_attitude_rule_is_px4s(angle_deg):
    """Beyond 60 deg of roll or pitch for 0.3 s, PX4's defaults; not a moment before."""
    for axis in ("roll", "pitch"):
        d = CrashDetector()
        angle = math.radians(angle_deg) if axis == "roll" else math.radians(
            max(-89.0, min(89.0, angle_deg)))
        roll, pitch = (angle, 0.0) if axis == "roll" else (0.0, angle)
        t = 0.0
        assert d.update(t, roll, pitch, (0.0, 0.0, 0.0), False) is None
        while t + 0.004 < FAIL_TRIGGER_S - 1e-6:
            t += 0.004
            assert d.update(t, roll, pitch, (0.0, 0.0, 0.0), False) is None, t
        cause = d.update(FAIL_TRIGGER_S, roll, pitch, (0.0, 0.0, 0.0), False)
        assert cause is not None and axis in cause and "PX4" in cause
        assert d.update(FAIL_TRIGGER_S + 1, roll, pitch, (0.0, 0.0, 0.0), False) is None  # once


def test_the_attitude_timer_restarts_when_the_vehicle_recovers():
    d = CrashDetector()
    beyond = FAIL_ANGLE_RAD + 0.01
    assert d.update(0.0, beyond, 0.0, (0, 0, 0), False) is None
    assert d.update(0.2, 0.0, 0.0, (0, 0, 0), False) is None  # back under control
    assert d.update(0.25, beyond, 0.0, (0, 0, 0), False) is None
    assert d.update(0.5, beyond, 0.0, (0, 0, 0), False) is None  # 0.25 s: not yet
    assert d.update(0.55, beyond, 0.0, (0, 0, 0), False) is not None


def test_the_impact_rule_is_the_drop_speed():
    assert IMPACT_SPEED_M_S == pytest.approx(math.sqrt(2 * 9.80665 * 1.5 * 8 * 0.0254))
    slow, fast = CrashDetector(), CrashDetector()
    for d, v in ((slow, IMPACT_SPEED_M_S - 0.05), (fast, IMPACT_SPEED_M_S + 0.05)):
        assert d.update(0.0, 0.0, 0.0, (0.0, 0.0, v), False) is None  # in the air
    assert slow.update(0.004, 0.0, 0.0, (0.0, 0.0, 0.0), True) is None
    cause = fast.update(0.004, 0.0, 0.0, (0.0, 0.0, 0.0), True)
    assert cause is not None and "hard impact" in cause
    # Staying in contact, however fast it slides, is no new impact.
    still = CrashDetector()
    assert still.update(0.0, 0.0, 0.0, (5.0, 0.0, 0.0), True) is None


def test_two_vehicles_flying_into_each_other_crash_at_their_closing_speed(
        lockstep_server, client_factory):
    """The impact rule takes the speed at which the vehicle meets what it touches: the ground's
    is the vehicle's own, another vehicle's the difference of the two. Two Hummingbirds flying
    at each other at 2 m/s each (each alone below the 2.445 m/s of the rule) meet at about
    4 m/s; they bounced off each other and flew on."""
    a, b = client_factory(lockstep_server), client_factory(lockstep_server)
    assert a.answer("INIT {ClassName hummingbird} {Name A} {Location -4,0,-2}",
                    "INIT").type == "RES"
    assert b.answer("INIT {ClassName hummingbird} {Name B} {Location 4,0,-2} "
                    "{Rotation 0,0,3.14159265}", "INIT").type == "RES"
    a.step(500)
    for c in (a, b):
        c.send("DRIVE {LinearVelocity 2}")  # forward: A north, B (facing south) south
    speeds, crashes = [], []
    for _ in range(40):  # 8 m apart at 4 m/s: they meet within 2 s, 4 s at most
        msgs = a.step(100)
        truth = [m for m in msgs if m.type == "SEN" and m.get("Type") == "GroundTruth"]
        speeds += [math.hypot(*vec(m.get("Velocity"))[:2]) for m in truth  # on its way, its
                   if vec(m.get("Location"))[0] < -0.3]  # rotors (0.27 m) short of the middle
        b.send("PING")  # answered after the lines those steps sent B
        crashes += _crash(msgs) + _crash(b.read_until(
            lambda m: m.type == "RES" and m.get("Command") == "PING")[0])
        if len(crashes) == 2:
            break
    assert max(speeds) < IMPACT_SPEED_M_S  # A alone never flew fast enough to crash
    assert sorted(c.get("Name") for c in crashes) == ["A", "B"], crashes
    for err in crashes:
        impact = float(re.search(r"hard impact at ([0-9.]+) m/s", err.get("Reason")).group(1))
        assert IMPACT_SPEED_M_S < impact <= 2 * max(speeds) + 0.05, err  # (rounded to 0.1)
