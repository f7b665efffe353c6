"""MAVSDK (the PyPI ``mavsdk`` package: the C++ MAVSDK library) flies a skeye vehicle unchanged:
``skeye sim`` and ``skeye pilot --mavlink udpout://...`` as child processes, MAVSDK listening
where the pilot sends (as on ``skeye up``'s 14540), and the script a MAVSDK user writes for a
PX4 vehicle: connect, wait for a position, arm, take off to 2 m, go to a point 5 m away, upload
and fly a 3-waypoint mission, return to launch, land, disarm."""

from __future__ import annotations

import math
import subprocess
from collections.abc import Iterator

import pytest

mavsdk = pytest.importorskip("mavsdk")

from mavsdk.plugins.action import Action  # noqa: E402
from mavsdk.plugins.mission import Mission, MissionItem, MissionPlan  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, LandedState, Telemetry  # noqa: E402

from skeye.processes import start_skeye, stop_processes  # noqa: E402
from tests.mavlink.conftest import free_udp_port  # noqa: E402
from tests.mavlink.mavsdk_client import METRES_PER_DEG_LAT, ground_station, until  # noqa: E402


@pytest.fixture
def skeye_vehicle() -> Iterator[int]:
    """``skeye sim`` (lockstep) and ``skeye pilot --mavlink udpout://127.0.0.1:PORT``; the port."""
    port = free_udp_port()
    children: list[subprocess.Popen[str]] = []
    try:
        sim, found = start_skeye(["sim", "--mode", "lockstep", "--port", "0"],
                                 [r"control protocol on [\d.]+:(\d+)"], "skeye sim")
        children.append(sim)
        pilot, _ = start_skeye(
            ["pilot", "--sim", f"127.0.0.1:{found[0].group(1)}", "--port", "0",
             "--lockstep-rate", "4", "--mavlink", f"udpout://127.0.0.1:{port}"],
            [r"MAVLink on udpout://127\.0\.0\.1:\d+"], "skeye pilot")
        children.append(pilot)
        yield port
    finally:
        stop_processes(list(reversed(children)), 10.0)


def test_mavsdk_flies_a_skeye_vehicle(skeye_vehicle):
    with ground_station(skeye_vehicle) as system:
        telemetry, action, mission = Telemetry(system), Action(system), Mission(system)
        until(lambda: (h := telemetry.health()).is_global_position_ok
              and h.is_home_position_ok, "a position")
        action.set_takeoff_altitude(2.0)
        action.set_return_to_launch_altitude(2.0)
        assert action.get_takeoff_altitude() == pytest.approx(2.0)

        action.arm()
        until(telemetry.armed, "armed")
        action.takeoff()
        until(lambda: telemetry.flight_mode() == FlightMode.TAKEOFF, "the take-off mode")
        until(lambda: telemetry.in_air() and telemetry.flight_mode() == FlightMode.HOLD
              and telemetry.position().relative_altitude_m > 1.8, "the take-off")
        here = telemetry.position()
        assert here.relative_altitude_m == pytest.approx(2.0, abs=0.25)

        lat = here.latitude_deg + 5.0 / METRES_PER_DEG_LAT
        action.goto_location(lat, here.longitude_deg, here.absolute_altitude_m, math.nan)
        until(lambda: abs(telemetry.position().latitude_deg - lat) * METRES_PER_DEG_LAT < 0.3
              and abs(telemetry.position().longitude_deg - here.longitude_deg)
              * METRES_PER_DEG_LAT < 0.3, "the go-to point 5 m north")

        step = 2.0 / METRES_PER_DEG_LAT
        items = [MissionItem(lat + step * k, here.longitude_deg + step * (k % 2), 2.5, 1.0,
                             False, math.nan, math.nan, MissionItem.CameraAction.NONE,
                             math.nan, math.nan, 0.5, math.nan, math.nan,
                             MissionItem.VehicleAction.NONE)
                 for k in (1, 2, 3)]
        mission.upload_mission(MissionPlan(items))
        mission.start_mission()
        until(lambda: telemetry.flight_mode() == FlightMode.MISSION, "mission mode")
        until(mission.is_mission_finished, "the mission's end")
        progress = mission.mission_progress()
        assert (progress.current, progress.total) == (3, 3)
        end = telemetry.position()
        assert abs(end.latitude_deg - (lat + 3 * step)) * METRES_PER_DEG_LAT < 0.5

        action.return_to_launch()
        until(lambda: telemetry.flight_mode() == FlightMode.RETURN_TO_LAUNCH, "return mode")
        until(lambda: telemetry.landed_state() == LandedState.ON_GROUND, "the landing")
        home = telemetry.home()
        down = telemetry.position()
        assert abs(down.latitude_deg - home.latitude_deg) * METRES_PER_DEG_LAT < 0.5
        assert abs(down.longitude_deg - home.longitude_deg) * METRES_PER_DEG_LAT < 0.5
        action.disarm()
        until(lambda: not telemetry.armed(), "disarmed")
