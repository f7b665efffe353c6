"""Single MAVSDK calls on a skeye vehicle, unchanged from a script for a PX4 vehicle, where a
compatibility probe (2026-11-26) found skeye answering wrongly or not at all:

- ``param.set_param_int`` on a parameter: every parameter is a REAL32, so it is refused with a
  STATUSTEXT and leaves the value unchanged (MAVSDK encodes the integer byte-wise: 30 arrives
  as the float 4.2e-44, which was once taken as the value);
- ``offboard.set_attitude`` then ``start``: attitude setpoints are not flown, and the refusal
  (DENIED) says so and names what is, instead of "offboard needs setpoints first";
- ``action.goto_location`` with a yaw: the vehicle flies there keeping its heading (its moves
  carry no yaw) and says so, instead of dropping the yaw silently;
- ``telemetry.get_gps_global_origin`` (GPS_GLOBAL_ORIGIN on request) and
  ``telemetry.unix_epoch_time`` (SYSTEM_TIME: the host's wall clock).
"""

from __future__ import annotations

import threading
import time

import pytest

mavsdk = pytest.importorskip("mavsdk")

from mavsdk.plugins.action import Action  # noqa: E402
from mavsdk.plugins.offboard import Attitude, Offboard, OffboardError  # noqa: E402
from mavsdk.plugins.param import Param, ParamError  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, Telemetry  # noqa: E402

from tests.mavlink.conftest import free_udp_port, mav_vehicle, scripted_endpoint  # noqa: E402
from tests.mavlink.mavsdk_client import (  # noqa: E402
    METRES_PER_DEG_LAT,
    StatusTexts,
    ground_station,
    until,
)


def test_set_param_int_on_a_float_parameter_is_refused_and_leaves_it_unchanged():
    port = free_udp_port()
    with scripted_endpoint(f"udpout://127.0.0.1:{port}"), ground_station(port) as system:
        param = Param(system)
        texts = StatusTexts(Telemetry(system))
        assert param.get_param_float("COM_DISARM_PRFLT") == pytest.approx(10.0)

        with pytest.raises(ParamError):
            param.set_param_int("COM_DISARM_PRFLT", 30)
        assert param.get_param_float("COM_DISARM_PRFLT") == pytest.approx(10.0)
        texts.wait_for("COM_DISARM_PRFLT is a REAL32 (float) parameter, not INT32")

        param.set_param_float("COM_DISARM_PRFLT", 30.0)  # the float call sets it (confirmed)
        assert param.get_param_float("COM_DISARM_PRFLT") == pytest.approx(30.0)


def test_offboard_with_attitude_setpoints_is_refused_naming_what_is_flown():
    port = free_udp_port()
    with scripted_endpoint(f"udpout://127.0.0.1:{port}"), ground_station(port) as system:
        offboard = Offboard(system)
        texts = StatusTexts(Telemetry(system))
        offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.5))
        # The refusal's STATUSTEXT comes with its COMMAND_ACK. One busy suite run (load 5-6)
        # got no text at all from MAVSDK in 10 s, the ack's DENIED having come; the cause was
        # not established (MAVSDK's subscription set up after the text came is one guess). So
        # the request is made again, past the vehicle's 2 s limit on a repeated notice to one
        # station, until the text is seen (5 tries: a vehicle that never says it still fails).
        text = None
        for _ in range(5):
            with pytest.raises(OffboardError, match="COMMAND_DENIED"):
                offboard.start()
            text = texts.seen("attitude setpoints (SET_ATTITUDE_TARGET) are not flown", 3.0)
            if text is not None:
                break
        assert text is not None, texts.texts


def test_goto_location_with_a_yaw_flies_there_and_says_the_yaw_is_not_flown():
    with mav_vehicle() as vehicle, ground_station(vehicle.port) as system:
        telemetry, action = Telemetry(system), Action(system)
        texts = StatusTexts(telemetry)
        until(lambda: (h := telemetry.health()).is_global_position_ok
              and h.is_home_position_ok, "a position", timeout_s=30.0)
        action.set_takeoff_altitude(1.5)
        action.arm()
        action.takeoff()
        until(lambda: telemetry.in_air() and telemetry.flight_mode() == FlightMode.HOLD
              and telemetry.position().relative_altitude_m > 1.3, "the take-off",
              timeout_s=30.0)
        heading = telemetry.heading().heading_deg
        here = telemetry.position()
        lat = here.latitude_deg + 1.0 / METRES_PER_DEG_LAT

        yaw = (heading + 90.0) % 360.0
        action.goto_location(lat, here.longitude_deg, here.absolute_altitude_m, yaw)
        texts.wait_for("is not flown: the heading is kept")
        until(lambda: abs(telemetry.position().latitude_deg - lat) * METRES_PER_DEG_LAT < 0.3,
              "the go-to point 1 m north", timeout_s=30.0)
        turned = (telemetry.heading().heading_deg - heading + 180.0) % 360.0 - 180.0
        assert abs(turned) < 5.0


def test_mavsdk_gets_the_gps_global_origin():
    port = free_udp_port()
    # The scripted vehicle: landed at its local origin with a GPS fix at 49 N 8 E, 100 m AMSL.
    with scripted_endpoint(f"udpout://127.0.0.1:{port}"), ground_station(port) as system:
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

    with mav_vehicle() as v, ground_station(v.port) as system:  # lockstep: sim time runs 4x
        telemetry = Telemetry(system)
        telemetry.subscribe_unix_epoch_time(on_time)
        assert got.wait(20.0), "no Unix time from the vehicle"
        (usec, wall), = heard
        assert abs(usec / 1e6 - wall) < 1.0
        assert abs(telemetry.unix_epoch_time() / 1e6 - time.time()) < 2.0
