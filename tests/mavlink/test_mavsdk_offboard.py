"""MAVSDK's offboard with attitude setpoints (``set_attitude``, SET_ATTITUDE_TARGET), which a
skeye vehicle does not fly: ``start`` is refused at once (DENIED) with a STATUSTEXT that says
so and names what is flown, instead of "offboard needs setpoints first"."""

from __future__ import annotations

import threading

import pytest

mavsdk = pytest.importorskip("mavsdk")

from mavsdk import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.plugins.offboard import Attitude, Offboard, OffboardError  # noqa: E402
from mavsdk.plugins.telemetry import Telemetry  # noqa: E402

from tests.mavlink.conftest import free_udp_port, scripted_endpoint  # noqa: E402


def test_offboard_with_attitude_setpoints_is_refused_naming_what_is_flown():
    port = free_udp_port()
    texts: list[str] = []
    heard = threading.Event()

    def on_text(status, _user_data) -> None:
        texts.append(status.text)
        if "DO_SET_MODE" in status.text:
            heard.set()

    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    with scripted_endpoint(f"udpout://127.0.0.1:{port}"), Mavsdk(config) as sdk:
        sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = sdk.first_autopilot(30.0)
        assert system is not None, "no autopilot heard"
        offboard, telemetry = Offboard(system), Telemetry(system)
        telemetry.subscribe_status_text(on_text)
        offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.5))
        with pytest.raises(OffboardError, match="COMMAND_DENIED"):
            offboard.start()
        assert heard.wait(10.0), f"no STATUSTEXT for the refusal; got {texts}"
        assert any("attitude setpoints (SET_ATTITUDE_TARGET) are not flown" in t
                   for t in texts), texts
