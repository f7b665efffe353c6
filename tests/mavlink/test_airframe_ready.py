"""``MavlinkAirframe.start``: the companion takes a flight controller as heard only when a
snapshot can be whole. The controller here is a pymavlink script on UDP, sending the messages
a test chooses (a flight controller that measures no battery voltage is one real case)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav

from skeye.errors import LinkClosed
from skeye.pilot.mavlink_airframe import open_mavlink_airframe
from tests.mavlink.conftest import free_udp_port


def send_telemetry(m: Any, boot_ms: int, status_mv: int | None) -> None:
    """One round of a hovering PX4's telemetry on ``m`` (a pymavlink ``MAVLink``): HEARTBEAT,
    ATTITUDE, LOCAL_POSITION_NED, and SYS_STATUS with ``status_mv`` unless it is None."""
    m.heartbeat_send(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4, 0, 0, mav.MAV_STATE_STANDBY)
    m.attitude_send(boot_ms, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0)
    m.local_position_ned_send(boot_ms, 1.0, 2.0, -0.1, 0.0, 0.0, 0.0)
    if status_mv is not None:
        m.sys_status_send(0, 0, 0, 0, status_mv, -1, -1, 0, 0, 0, 0, 0, 0)


@contextmanager
def scripted_controller(port: int, *, status_mv: int | None) -> Iterator[None]:
    """HEARTBEAT, ATTITUDE and LOCAL_POSITION_NED at 20 Hz to the companion's UDP port, and
    SYS_STATUS with ``status_mv`` unless it is None."""
    link = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1,
                                      source_component=1)
    stop = threading.Event()

    def send() -> None:
        boot_ms = 0
        while not stop.wait(0.05):
            boot_ms += 50
            send_telemetry(link.mav, boot_ms, status_mv)

    thread = threading.Thread(target=send, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(5.0)
        link.close()


def test_a_controller_that_sends_no_status_is_not_taken_and_the_error_says_what_is_missing():
    """The first snapshot said 0.0 V whenever SYS_STATUS had not come yet (a loaded run of the
    backend conformance test saw it)."""
    port = free_udp_port()
    with scripted_controller(port, status_mv=None), \
            pytest.raises(LinkClosed, match="missing SYS_STATUS"):
        open_mavlink_airframe(f"mavlink://udp/127.0.0.1:{port}", wait_s=1.5)


@pytest.mark.parametrize(("status_mv", "battery_v"), [(11_800, 11.8), (65_535, 0.0)])
def test_the_battery_is_the_controllers_and_unknown_when_it_measures_none(status_mv, battery_v):
    """UINT16_MAX is MAVLink's "no voltage measured": it was read as 65.535 V."""
    port = free_udp_port()
    with scripted_controller(port, status_mv=status_mv):
        airframe = open_mavlink_airframe(f"mavlink://udp/127.0.0.1:{port}", wait_s=30.0)
        try:
            snap = airframe.snapshot()
        finally:
            airframe.close()
    assert snap.battery_v == pytest.approx(battery_v)
    assert snap.pos_ned_m == pytest.approx((1.0, 2.0, -0.1)) and snap.rpy_rad[2] == 0.5


def test_the_speed_limits_are_the_robot_files_as_on_the_ll_board():
    """``skeye pilot --airframe mavlink://... --robot airrobot``: the boards check commands
    against the vehicle's limits, which the pilot takes from the robot file on every other
    airframe (the flight envelope too, on this one); the mavlink:// backend kept skeye's
    defaults whatever --robot said, so an AirRobot (2 m/s, climb 2 m/s) was let fly 3 m/s and
    refused a climb over 1.5 m/s."""
    from skeye.pilot.airframe import AirframeOptions, open_airframe
    from skeye.pilot.asctec_ll import vehicle_limits

    port = free_udp_port()
    with scripted_controller(port, status_mv=11_800):
        airframe = open_airframe(f"mavlink://udp/127.0.0.1:{port}",
                                 AirframeOptions(robot="airrobot", timeout_s=30.0))
        try:
            limits = airframe.limits
        finally:
            airframe.close()
    assert limits == vehicle_limits("airrobot")
    assert (limits.max_speed_m_s, limits.max_climb_m_s) == (2.0, 2.0)


def test_a_robot_whose_file_is_not_here_is_refused_before_the_link_opens():
    from skeye.errors import ConfigError
    from skeye.pilot.airframe import AirframeOptions, open_airframe

    port = free_udp_port()
    with pytest.raises(ConfigError, match=r"--robot.*'nosuch'"):  # not LinkClosed after 2 s
        open_airframe(f"mavlink://udp/127.0.0.1:{port}", AirframeOptions(robot="nosuch",
                                                                           timeout_s=2.0))
