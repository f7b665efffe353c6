"""MAVSDK's ``get_gps_global_origin`` on a skeye vehicle, unchanged from a PX4 script: the
origin of the local NED frame (GPS_GLOBAL_ORIGIN on request)."""

from __future__ import annotations

import pytest

mavsdk = pytest.importorskip("mavsdk")

from mavsdk import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.plugins.telemetry import Telemetry  # noqa: E402

from tests.mavlink.conftest import free_udp_port, scripted_endpoint  # noqa: E402


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
