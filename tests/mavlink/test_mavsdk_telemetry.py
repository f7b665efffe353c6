"""MAVSDK's ``get_gps_global_origin`` and ``unix_epoch_time`` on a skeye vehicle, unchanged from
a PX4 script: the origin of the local NED frame (GPS_GLOBAL_ORIGIN on request), and the
vehicle's Unix time (SYSTEM_TIME: the host's wall clock)."""

from __future__ import annotations

import threading
import time

import pytest

mavsdk = pytest.importorskip("mavsdk")

from mavsdk import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.plugins.telemetry import Telemetry  # noqa: E402

from tests.mavlink.conftest import free_udp_port, mav_vehicle, scripted_endpoint  # noqa: E402


def test_mavsdk_gets_the_gps_global_origin():
    port = free_udp_port()
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    # The scripted vehicle: landed at its local origin with a GPS fix at 49 N 8 E, 100 m AMSL.
    with scripted_endpoint(f"udpout://127.0.0.1:{port}"), Mavsdk(config) as sdk:
        sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = sdk.first_autopilot(30.0)
        assert system is not None, "no autopilot heard"
        origin = Telemetry(system).get_gps_global_origin()
        assert origin.latitude_deg == pytest.approx(49.0, abs=1e-7)
        assert origin.longitude_deg == pytest.approx(8.0, abs=1e-7)
        assert origin.altitude_m == pytest.approx(100.0, abs=1e-3)


def test_mavsdk_reads_the_unix_epoch_time_of_the_host_clock():
    heard: list[tuple[int, float]] = []
    got = threading.Event()

    def on_time(usec, _user_data) -> None:
        if usec and not got.is_set():
            heard.append((int(usec), time.time()))
            got.set()

    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    with mav_vehicle() as v, Mavsdk(config) as sdk:  # lockstep: sim time runs 4x wall time
        sdk.add_any_connection(f"udpin://127.0.0.1:{v.port}")
        system = sdk.first_autopilot(60.0)
        assert system is not None, "no autopilot heard"
        telemetry = Telemetry(system)
        telemetry.subscribe_unix_epoch_time(on_time)
        assert got.wait(20.0), "no Unix time from the vehicle"
        (usec, wall), = heard
        assert abs(usec / 1e6 - wall) < 1.0
        assert abs(telemetry.unix_epoch_time() / 1e6 - time.time()) < 2.0
