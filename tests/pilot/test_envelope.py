"""The pilot's flight envelope: absurd targets are refused with RESULT code 3 and a reason, a
full-thrust stick in height mode climbs at the vehicle's maximum rate and stops at the ceiling,
a vehicle moving out of the envelope is stopped; the limits come from the robot file or the
command line, and bad ones are refused with a message naming them."""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from skeye.errors import CommandRejected, ConfigError
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.envelope import FlightEnvelope
from skeye.pilot.server import PilotServer
from skeye.processes import start_skeye, stop_process
from skeye.robots.config import load_robot_config
from skeye.wire.packet_units import nav_status_to_si
from skeye.wire.packets import PD, CtrlBits, NavState, NavStatus, SkeyeMask
from tests.pilot.fake_airframe import FakeAirframe

HEIGHT_MODE = int(CtrlBits(0x0F) | CtrlBits.HEIGHT_CONTROL)
GPS_MODE = int(CtrlBits(0x0F) | CtrlBits.HEIGHT_CONTROL | CtrlBits.GPS_POSITION_CONTROL)


def _refused(call: Callable[[], object], *words: str) -> str:
    with pytest.raises(CommandRejected) as info:
        call()
    assert info.value.code == 3, info.value
    for word in words:
        assert word in info.value.reason, info.value.reason
    return info.value.reason


def _nav(v: Vehicle) -> tuple[float, float, NavState]:
    """(height above the world origin, climb rate, state) from the next NAV_STATUS."""
    msg = v.wait_for(PD.NAV_STATUS, timeout_s=30)
    assert isinstance(msg, NavStatus)
    si = nav_status_to_si(msg)
    return -si.pos_ned_m[2], -si.vel_ned_m_s[2], si.state


def test_envelope_over_real_processes() -> None:
    """``skeye sim`` (lockstep) and ``skeye pilot --ceiling-m 5 --max-radius-m 50``."""
    sim, found = start_skeye(["sim", "--mode", "lockstep", "--port", "0", "--seed", "3"],
                             [r"control protocol on [\d.]+:(\d+)"], "skeye sim")
    try:
        pilot, pfound = start_skeye(
            ["pilot", "--sim", f"127.0.0.1:{found[0].group(1)}", "--port", "0",
             "--lockstep-rate", "2", "--ceiling-m", "5", "--max-radius-m", "50"],
            [r"ground control on (tcp://[\d.]+:\d+); flight envelope: (.*)"], "skeye pilot")
        try:
            line = pfound[0].group(2)
            assert "ceiling 5 m above home, radius 50 m" in line and "--ceiling-m 5" in line
            with Vehicle.open(pfound[0].group(1), timeout_s=10.0) as v:
                v.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
                _refused(lambda: v.take_off(2_147_000.0), "2147.0 km above home", "ceiling 5 m")
                _refused(lambda: v.take_off(6.0), "ceiling 5 m")
                v.take_off(1.0)
                v.wait_state(NavState.HOLDING, timeout_s=120)
                _refused(lambda: v.goto_gps(90.0, 180.0, 2.0), "from home", "radius 50 m")
                _refused(lambda: v.move_by(forward_m=60.0), "from home")
                _refused(lambda: v.move_by(up_m=10.0), "above home")
                _refused(lambda: v.set_velocity(forward_m_s=2.0, duration_s=40.0), "from home")
                v.move_by(forward_m=2.0)  # inside: accepted
                v.wait_state(NavState.HOLDING, timeout_s=120)

                # A full-thrust stick in height mode: the maximum climb rate, not a refusal;
                # held, it climbs to the ceiling and stops there.
                best_climb = 0.0
                height = 0.0
                deadline = time.monotonic() + 120
                while height < 4.9:
                    assert time.monotonic() < deadline, f"no climb to the ceiling ({height} m)"
                    v.ctrl_input(0.0, 0.0, 0.0, 1.0, ctrl=HEIGHT_MODE)
                    height, climb, _ = _nav(v)
                    best_climb = max(best_climb, climb)
                assert best_climb > 0.6  # the robot's climb limit: 0.8 m/s (motion control)
                top = height
                for _ in range(40):  # stick still held: it stays at the ceiling
                    v.ctrl_input(0.0, 0.0, 0.0, 1.0, ctrl=HEIGHT_MODE)
                    height, _, _ = _nav(v)
                    top = max(top, height)
                assert top < 5.0 + 1.0, top  # ceiling 5 m (+ the take-off point's 0.1 m)
                assert height > 4.0
        finally:
            stop_process(pilot)
    finally:
        stop_process(sim)


def test_a_vehicle_moving_out_of_the_envelope_is_stopped() -> None:
    air = FakeAirframe()
    settings = BoardSettings(envelope=FlightEnvelope(ceiling_m=10.0, max_radius_m=20.0))
    with PilotServer(air, port=0, settings=settings) as pilot:
        with Vehicle.open(pilot.address) as v:
            v.stream(0, int(SkeyeMask.NAV_STATUS), 0.02)
            v.take_off(1.0)
            air.finish(landed=False, armed=True, pos_ned_m=(0.0, 0.0, -1.0))
            v.wait_state(NavState.HOLDING, timeout_s=10)
            v.set_velocity(forward_m_s=2.0)  # open-ended: accepted
            v.wait_state(NavState.FLYING, timeout_s=10)
            air.finish(pos_ned_m=(19.0, 0.0, -1.0), vel_ned_m_s=(2.0, 0.0, 0.0))
            time.sleep(0.3)  # inside: nothing happens
            assert pilot.boards.state is NavState.FLYING
            air.finish(pos_ned_m=(20.5, 0.0, -1.0), vel_ned_m_s=(2.0, 0.0, 0.0))
            v.wait_state(NavState.HOLDING, timeout_s=10)
            assert air.names()[-1] == "hover" and pilot.boards.envelope_stops == 1
            assert "radius 20 m" in pilot.boards.envelope_reason
            # Beyond the edge, coming back is allowed; going further is refused.
            air.finish(vel_ned_m_s=(0.0, 0.0, 0.0))
            _refused(lambda: v.move_by(forward_m=5.0, frame="world"), "from home")
            v.move_by(forward_m=-5.0, frame="world")
            assert air.calls[-1][0] == "fly_to" and math.isclose(air.calls[-1][1][0], 15.5)
            # Sticks at the edge: the outward part is removed, not refused.
            # Height mode: sticks are angles; a tilt outward (pitch forward = north) is levelled.
            v.ctrl_input(0.0, -0.3, 0.0, 0.5, ctrl=HEIGHT_MODE)
            name, (roll, pitch, _yaw, thrust) = air.calls[-1]
            assert name == "attitude" and air.height_mode
            assert abs(pitch) < 1e-9 and abs(roll) < 1e-9 and abs(thrust - 0.5) < 0.01
            v.ctrl_input(0.3, -0.3, 0.0, 0.5, ctrl=HEIGHT_MODE)  # east is along the edge: kept
            name, (roll, pitch, _yaw, _thrust) = air.calls[-1]
            assert name == "attitude" and abs(pitch) < 1e-9 and abs(roll - 0.3) < 1e-3
            # GPS mode: sticks are velocities; the outward one is removed.
            v.ctrl_input(0.0, -0.3, 0.0, 0.5, ctrl=GPS_MODE)
            name, (fwd, _right, up, _yaw) = air.calls[-1]
            assert name == "set_velocity" and abs(fwd) < 1e-9 and abs(up) < 0.01
            assert air.gps_mode  # the LL board's GPS mode (DRIVE {BoardMode gps})


def test_envelope_values_are_checked() -> None:
    with pytest.raises(ConfigError, match="ceiling_m must be a positive finite number"):
        FlightEnvelope(ceiling_m=-1.0)
    with pytest.raises(ConfigError, match="max_radius_m must be a positive finite number"):
        FlightEnvelope(max_radius_m=math.inf)
    assert load_robot_config("hummingbird").envelope == FlightEnvelope(120.0, 500.0)


def test_robot_file_envelope_and_bad_values(tmp_path: Path) -> None:
    from importlib import resources

    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    good = text.replace('name = "hummingbird"', 'name = "lowcap"').replace(
        "ceiling_m = 120.0", "ceiling_m = 30.0")
    (tmp_path / "lowcap.toml").write_text(good, encoding="utf-8")
    assert load_robot_config("lowcap", (tmp_path,)).envelope.ceiling_m == 30.0
    bad = good.replace('name = "lowcap"', 'name = "badcap"').replace(
        "ceiling_m = 30.0", "ceiling_m = -3.0")
    (tmp_path / "badcap.toml").write_text(bad, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"badcap.toml \[envelope\].*ceiling_m"):
        load_robot_config("badcap", (tmp_path,))
    typo = good.replace('name = "lowcap"', 'name = "typo"').replace("ceiling_m", "celing_m")
    (tmp_path / "typo.toml").write_text(typo, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"unknown key.*celing_m"):
        load_robot_config("typo", (tmp_path,))
    # The pilot reads the class's envelope from --robot-dir, and refuses a bad value at once.
    from skeye.pilot import cli as pilot_cli

    args = _pilot_args("--robot", "lowcap", "--robot-dir", str(tmp_path))
    envelope, source = pilot_cli.flight_envelope(args)
    assert envelope.ceiling_m == 30.0 and "lowcap.toml" in source
    out = subprocess.run(
        [sys.executable, "-m", "skeye.cli", "pilot", "--max-radius-m", "0", "--port", "0"],
        capture_output=True, text=True, timeout=60,
    )
    assert out.returncode == 2 and "max_radius_m must be a positive" in out.stdout + out.stderr


def _pilot_args(*argv: str) -> argparse.Namespace:

    from skeye.pilot import cli as pilot_cli

    p = argparse.ArgumentParser()
    sub = p.add_subparsers()
    pilot_cli.register(sub)
    return p.parse_args(["pilot", *argv])


def test_the_onboard_computers_velocities_pass_inside_the_envelope_untouched() -> None:
    """Inside the envelope, the pad modes' and a policy's set-points reach the airframe as they
    were computed: the limit's heading-frame round trip changed their last bits (0.3 forward at
    yaw 0.3 rad came out 0.29999999999999993), and with them every pad flight's figures."""
    from skeye.pilot.boards import OnboardBoards

    air = FakeAirframe()
    air.finish(landed=False, armed=True, pos_ned_m=(1.0, 1.0, -1.0), rpy_rad=(0.0, 0.0, 0.3))
    boards = OnboardBoards(air, BoardSettings())
    boards.fly_velocity(0.3, -0.7, 0.1)
    assert air.calls[-1] == ("set_velocity", (0.3, -0.7, 0.1, 0.0))
