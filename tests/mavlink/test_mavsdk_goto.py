"""MAVSDK's ``goto_location`` with a yaw: the vehicle flies to the point and keeps its heading
(its moves carry no yaw), and says so with a STATUSTEXT instead of dropping the yaw silently."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

mavsdk = pytest.importorskip("mavsdk")

from mavsdk import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.plugins.action import Action  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, Telemetry  # noqa: E402

from tests.mavlink.conftest import mav_vehicle  # noqa: E402

METRES_PER_DEG_LAT = 111_320.0


def until(pred: Callable[[], bool], what: str, timeout_s: float = 30.0) -> None:
    """Wait for a condition of the vehicle's telemetry; the timeout is a stuck guard only."""
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def test_goto_location_with_a_yaw_flies_there_and_says_the_yaw_is_not_flown():
    texts: list[str] = []
    heard = threading.Event()

    def on_text(status, _user_data) -> None:
        texts.append(status.text)
        if "yaw (p4)" in status.text:
            heard.set()

    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    with mav_vehicle() as vehicle, Mavsdk(config) as sdk:
        sdk.add_any_connection(f"udpin://127.0.0.1:{vehicle.port}")
        system = sdk.first_autopilot(30.0)
        assert system is not None, "no autopilot heard"
        telemetry, action = Telemetry(system), Action(system)
        telemetry.subscribe_status_text(on_text)
        until(lambda: (h := telemetry.health()).is_global_position_ok
              and h.is_home_position_ok, "a position")
        action.set_takeoff_altitude(1.5)
        action.arm()
        action.takeoff()
        until(lambda: telemetry.in_air() and telemetry.flight_mode() == FlightMode.HOLD
              and telemetry.position().relative_altitude_m > 1.3, "the take-off")
        heading = telemetry.heading().heading_deg
        here = telemetry.position()
        lat = here.latitude_deg + 1.0 / METRES_PER_DEG_LAT

        yaw = (heading + 90.0) % 360.0
        action.goto_location(lat, here.longitude_deg, here.absolute_altitude_m, yaw)
        assert heard.wait(10.0), f"no STATUSTEXT about the yaw; got {texts}"
        assert any("is not flown: the heading is kept" in t for t in texts), texts
        until(lambda: abs(telemetry.position().latitude_deg - lat) * METRES_PER_DEG_LAT < 0.3,
              "the go-to point 1 m north")
        turned = (telemetry.heading().heading_deg - heading + 180.0) % 360.0 - 180.0
        assert abs(turned) < 5.0
