"""MAVSDK's parameter calls on a skeye vehicle: every parameter is a REAL32, so
``set_param_int`` on one is refused with a STATUSTEXT and leaves it unchanged (MAVSDK encodes
the integer byte-wise: 30 arrives as the float 4.2e-44, which was once taken as the value)."""

from __future__ import annotations

import threading

import pytest

mavsdk = pytest.importorskip("mavsdk")

from mavsdk import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.plugins.param import Param, ParamError  # noqa: E402
from mavsdk.plugins.telemetry import Telemetry  # noqa: E402

from tests.mavlink.conftest import free_udp_port, scripted_endpoint  # noqa: E402


def test_set_param_int_on_a_float_parameter_is_refused_and_leaves_it_unchanged():
    port = free_udp_port()
    texts: list[str] = []
    heard = threading.Event()

    def on_text(status, _user_data) -> None:
        texts.append(status.text)
        if "REAL32" in status.text:
            heard.set()

    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    with scripted_endpoint(f"udpout://127.0.0.1:{port}"), Mavsdk(config) as sdk:
        sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = sdk.first_autopilot(30.0)
        assert system is not None, "no autopilot heard"
        param, telemetry = Param(system), Telemetry(system)
        telemetry.subscribe_status_text(on_text)
        assert param.get_param_float("COM_DISARM_PRFLT") == pytest.approx(10.0)

        with pytest.raises(ParamError):
            param.set_param_int("COM_DISARM_PRFLT", 30)
        assert param.get_param_float("COM_DISARM_PRFLT") == pytest.approx(10.0)
        assert heard.wait(10.0), f"no STATUSTEXT about the type; got {texts}"
        assert any("COM_DISARM_PRFLT is a REAL32 (float) parameter, not INT32" in t
                   for t in texts), texts

        param.set_param_float("COM_DISARM_PRFLT", 30.0)  # the float call sets it (confirmed)
        assert param.get_param_float("COM_DISARM_PRFLT") == pytest.approx(30.0)
