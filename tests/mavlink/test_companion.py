"""The pilot as the companion computer of a MAVLink flight controller (``--airframe mavlink://``):
the flight controller is skeye's own MAVLink vehicle (a pilot on the simulated robot with
``--mavlink udp://``), the companion a second pilot whose airframe is ``MavlinkAirframe``, with the
pad vision on a camera source by URI (the simulator's image server, ``sim://``), opened as
``skeye pilot --airframe mavlink://... --camera URI`` opens it. Ground control talks to the
companion over its packet port, exactly as to any pilot. Real time: the flight controller keeps
its own clock, and the companion puts it on its own, the clock its camera's frames carry."""

from __future__ import annotations

import math
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from skeye.control.connection import connect
from skeye.link.vehicle import Vehicle
from skeye.pilot.boards import BoardSettings
from skeye.pilot.cli import camera_fov_rad, camera_vision_factory, open_camera_for
from skeye.pilot.mavlink_airframe import MavlinkAirframe, open_mavlink_airframe
from skeye.pilot.mavlink_server import MavlinkServer
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.wire.packets import NavState, PadAction, SkeyeMask
from tests.control.conftest import sim_running
from tests.mavlink.conftest import SMALL_CAMERA_ROBOT, free_udp_port, small_camera_robot


@dataclass
class Companion:
    robot: Any
    controller: PilotServer  # the flight controller: skeye's MAVLink vehicle
    endpoint: MavlinkServer
    airframe: MavlinkAirframe
    camera: Any  # the companion's camera source (sim://, on the airframe's clock)
    companion: PilotServer


@pytest.fixture
def companion(tmp_path: Path) -> Iterator[Companion]:
    with ExitStack() as stack:
        # The oracle estimator: the test checks where the pad landing put the vehicle.
        handle = stack.enter_context(sim_running(
            mode="realtime", images=True, robot_dirs=(small_camera_robot(tmp_path),),
            estimator="truth"))
        sim = stack.enter_context(connect(handle.address, images=handle.images))
        robot = sim.spawn(SMALL_CAMERA_ROBOT, start="Pad1")
        mc = robot.motion_config
        airframe = SimAirframe(sim, robot)
        settings = BoardSettings(max_speed_m_s=mc.max_speed_m_s, default_speed_m_s=1.0,
                                 max_climb_m_s=mc.max_climb_m_s)
        controller = stack.enter_context(PilotServer(airframe, port=0, settings=settings))
        port = free_udp_port()
        endpoint = stack.enter_context(MavlinkServer(controller.boards, controller.lock,
                                                     [f"udp://127.0.0.1:{port}"]))
        mavlink_airframe = open_mavlink_airframe(f"mavlink://udpout/127.0.0.1:{port}")
        stack.callback(mavlink_airframe.close)
        fov = camera_fov_rad(sim)
        camera = open_camera_for(f"sim://{handle.images}/{robot.name}/Down?fov_rad={fov!r}",
                                 mavlink_airframe, "companion", None, 5.0)
        stack.callback(camera.close)
        pilot = stack.enter_context(PilotServer(
            mavlink_airframe, port=0, settings=settings,
            vision=camera_vision_factory(camera, camera.fov_h_rad)))
        pilot.boards.pad.add_listener(mavlink_airframe.landing_target)
        yield Companion(robot, controller, endpoint, mavlink_airframe, camera, pilot)


def test_the_pilot_lands_on_the_pad_through_a_mavlink_flight_controller(companion):
    c = companion
    with Vehicle.open(c.companion.address, timeout_s=10.0) as v:
        v.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
        v.take_off(1.5)
        v.wait_state(NavState.HOLDING, timeout_s=60)
        assert c.endpoint.vehicle.mode.name == "HOLD"
        v.move_by(forward_m=0.3)
        v.wait_state(NavState.FLYING, timeout_s=30)
        v.wait_state(NavState.HOLDING, timeout_s=60)
        assert c.endpoint.vehicle.mode.name == "OFFBOARD"  # the companion flies offboard
        north, east, down = c.robot.ground_truth.latest.position_ned_m
        assert math.hypot(north - 0.3, east) < 0.12 and -down == pytest.approx(1.5, abs=0.2)
        v.pad_mode(PadAction.LAND)
        v.wait_state(NavState.LANDED, timeout_s=120)
    north, east, down = c.robot.ground_truth.latest.position_ned_m
    assert math.hypot(north, east) < 0.08, (north, east)  # the pad's centre is the origin
    assert c.controller.boards.state is NavState.LANDED
    # Its detections reached the flight controller as LANDING_TARGET.
    assert c.airframe.landing_targets > 10
    assert c.endpoint.vehicle.landing_targets_in == c.airframe.landing_targets
    assert c.airframe.refusals == [] and c.endpoint.errors == 0


def test_snapshots_and_camera_frames_are_on_the_companions_clock(companion):
    """The controller's boot time is put on this computer's monotonic clock (the airframe's
    clock is not the simulator's), the clock a camera source stamps its frames with: a frame
    and a snapshot of one moment carry one time, so each detection becomes due."""
    c = companion
    deadline = time.monotonic() + 10.0
    while c.camera.latest is None and time.monotonic() < deadline:
        c.airframe.check()
        time.sleep(0.05)
    frame, snap = c.camera.latest, c.airframe.snapshot()
    now = time.monotonic()
    assert frame is not None, "no frame from the image server"
    assert c.airframe.lost is None
    # On one clock (on the boot clock they were some 79 000 s apart). A snapshot is never
    # ahead of its receipt, and a controller not lost was heard within lost_after_s; the
    # latest message's own delay is allowed as much again (a loaded machine made a fixed
    # 0.5 s fail: 0.59 s).
    bound_s = 2 * c.airframe.lost_after_s
    assert 0.0 <= now - snap.time_s < bound_s, (now, snap.time_s)
    assert abs(frame.time_s - snap.time_s) < bound_s, (frame.time_s, snap.time_s)


def _pilot(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "skeye.cli", "pilot", *args],
                          capture_output=True, text=True, timeout=120)


def test_skeye_pilot_airframe_refuses_bad_uris_and_silent_controllers():
    bad = _pilot("--airframe", "mavlink://bogus/1.2.3.4:5")
    assert bad.returncode == 2 and "unknown MAVLink link kind 'bogus'" in bad.stderr
    # the URI named once ("mavlink://bogus/1.2.3.4:5: mavlink://bogus/1.2.3.4:5: ..." before)
    assert bad.stderr == ("skeye pilot: error: mavlink://bogus/1.2.3.4:5: unknown MAVLink link "
                          "kind 'bogus' (udp, udpout, tcp, serial)\n"), bad.stderr
    port = free_udp_port()
    silent = _pilot("--airframe", f"mavlink://udp/127.0.0.1:{port}", "--timeout", "1",
                    "--port", "0")
    assert silent.returncode == 4 and "no flight controller on udp://127.0.0.1" in silent.stderr
