"""Fixtures for the MAVLink tests: a skeye vehicle with its MAVLink endpoint on loopback, and
pymavlink clients of it.

The vehicle runs in this process on a lockstep simulator (``tests.control.conftest``), paced
(``lockstep_rate``) so that a client's wall-clock reactions (MAVSDK's command timeouts, the
ground station heartbeat) stay in step with sim time; its link is ``udpout://`` to a free port
where the client listens, as ``skeye up`` sends to QGroundControl's 14550 and MAVSDK's 14540.
"""

from __future__ import annotations

import math
import re
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from pymavlink import mavutil

from skeye.control.connection import connect
from skeye.pilot.boards import BoardSettings, OnboardBoards
from skeye.pilot.mavlink_server import MavlinkServer
from skeye.pilot.mavlink_vehicle import Settings
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from tests.control.conftest import sim_running
from tests.pilot.fake_airframe import FakeAirframe
from tests.ports import free_port

GCS = (255, 190)  # QGroundControl's system and component ids
SMALL_CAMERA_ROBOT = "mavtest"


def free_udp_port() -> int:
    return free_port(socket.SOCK_DGRAM)


def small_camera_robot(folder: Path) -> Path:
    """A hummingbird with a 320x240 ideal camera at 10 frames/s (cheap to render)."""
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    text = re.sub(r'(?m)^name = "hummingbird"', f'name = "{SMALL_CAMERA_ROBOT}"', text, count=1)
    text = re.sub(r"(?m)^width = 800$", "width = 320", text)
    text = re.sub(r"(?m)^height = 600$", "height = 240", text)
    text = re.sub(r"(?m)^rate_hz = 30$", "rate_hz = 10", text)
    text = re.sub(r'(?m)^profile = "webcam"$', 'profile = "ideal"', text)
    (folder / f"{SMALL_CAMERA_ROBOT}.toml").write_text(text, encoding="utf-8")
    return folder


@dataclass
class MavVehicle:
    """A pilot with its MAVLink endpoint, and where a client listens for it."""

    port: int
    pilot: PilotServer
    robot: Any
    mavlink: MavlinkServer
    sim: Any
    clients: list[Any] = field(default_factory=list)  # closed with the vehicle

    def client(self, source: tuple[int, int] = GCS) -> Any:
        """A pymavlink connection on the port the vehicle sends to (closed with the vehicle)."""
        return self.keep(mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{self.port}", source_system=source[0], source_component=source[1]))

    def keep(self, conn: Any) -> Any:
        """Close ``conn`` (a pymavlink connection) when the vehicle goes."""
        self.clients.append(conn)
        return conn

    def truth(self) -> tuple[float, float, float]:
        reading = self.robot.ground_truth.latest
        assert reading is not None
        return tuple(reading.position_ned_m)


@contextmanager
def mav_vehicle(*, rate: float = 4.0, images: bool = False, robot_dir: Path | None = None,
                estimator: str | None = None, uris: list[str] | None = None,
                start: str = "Pad1") -> Iterator[MavVehicle]:
    """A lockstep simulator, the pilot on it and its MAVLink endpoint (udpout to a free port);
    the robot at the pad world's start pose ``start``."""
    with ExitStack() as stack:
        handle = stack.enter_context(sim_running(
            images=images, robot_dirs=(robot_dir,) if robot_dir else (), estimator=estimator))
        sim = stack.enter_context(connect(handle.address, images=handle.images))
        robot = sim.spawn(SMALL_CAMERA_ROBOT if robot_dir else "hummingbird", start=start)
        airframe = SimAirframe(sim, robot)
        mc = robot.motion_config
        settings = BoardSettings(max_speed_m_s=mc.max_speed_m_s,
                                 default_speed_m_s=min(1.0, mc.max_speed_m_s),
                                 max_climb_m_s=mc.max_climb_m_s,
                                 max_yaw_rate_rad_s=mc.max_yaw_rate_rad_s)
        vision = None
        if images:
            from skeye.pilot.cli import pad_vision_factory

            vision = pad_vision_factory(sim, robot)
        pilot = stack.enter_context(PilotServer(
            airframe, port=0, settings=settings, lockstep=True, lockstep_rate=rate,
            tick_s=1.0 / mc.control_rate_hz, vision=vision))
        port = free_udp_port()
        server = stack.enter_context(MavlinkServer(
            pilot.boards, pilot.lock, uris or [f"udpout://127.0.0.1:{port}"],
            settings=Settings(pad_vision=images)))
        vehicle = MavVehicle(port, pilot, robot, server, sim)
        try:
            yield vehicle
        finally:
            for conn in vehicle.clients:
                conn.close()


@contextmanager
def scripted_endpoint(uri: str) -> Iterator[MavlinkServer]:
    """The MAVLink endpoint on the boards over a scripted airframe (``FakeAirframe``: landed,
    a GPS fix at 49 N 8 E): no simulator, for what needs only the endpoint's answers."""
    boards = OnboardBoards(FakeAirframe())
    with MavlinkServer(boards, threading.Lock(), [uri]) as server:
        yield server


def wait_for(conn: Any, kinds: str | list[str], pred: Callable[[Any], bool] = lambda m: True,
             timeout_s: float = 60.0, heartbeat: bool = True) -> Any:
    """The next message of ``kinds`` from the vehicle for which ``pred`` holds; sends the ground
    station's heartbeat every second meanwhile (the vehicle's link-loss timer needs it).
    ``timeout_s`` is a stuck guard only."""
    deadline = time.monotonic() + timeout_s
    next_hb = 0.0
    while True:
        now = time.monotonic()
        if heartbeat and now >= next_hb:
            conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS,
                                    mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            next_hb = now + 1.0
        assert now < deadline, f"no {kinds} as expected within {timeout_s} s"
        msg = conn.recv_match(type=kinds, blocking=True, timeout=0.2)
        if msg is not None and msg.get_srcSystem() == 1 and pred(msg):
            return msg


def statustext(conn: Any, timeout_s: float = 20.0) -> str:
    """The next STATUSTEXT's whole text (MAVLink 2 sends a long one in 50-byte chunks)."""
    first = wait_for(conn, "STATUSTEXT", timeout_s=timeout_s)
    text = first.text
    if first.id == 0:
        return str(text)
    while len(text.encode()) % 50 == 0:
        more = wait_for(conn, "STATUSTEXT", lambda m: m.id == first.id, timeout_s)
        text += more.text
        if len(more.text.encode()) < 50:
            break
    return str(text)


def command(conn: Any, cmd: int, *params: float, timeout_s: float = 20.0) -> tuple[int, str]:
    """COMMAND_LONG to the vehicle; returns its COMMAND_ACK result and any STATUSTEXT after it."""
    p = [*params, *([0.0] * (7 - len(params)))]
    conn.mav.command_long_send(1, 1, cmd, 0, *p)
    ack = wait_for(conn, "COMMAND_ACK", lambda m: m.command == cmd, timeout_s)
    text = ""
    if ack.result != mavutil.mavlink.MAV_RESULT_ACCEPTED:
        text = statustext(conn, timeout_s)
    return int(ack.result), text


def take_off(conn: Any) -> None:
    """Arm and take off (to MIS_TAKEOFF_ALT); returns once the vehicle hovers in Hold (PX4's
    LOITER, system status ACTIVE)."""
    m = mavutil.mavlink
    assert command(conn, m.MAV_CMD_COMPONENT_ARM_DISARM, 1)[0] == m.MAV_RESULT_ACCEPTED
    assert command(conn, m.MAV_CMD_NAV_TAKEOFF, *[0.0] * 6, math.nan)[0] == 0
    wait_for(conn, "HEARTBEAT", lambda h: mavutil.mode_string_v10(h) == "LOITER"
             and h.system_status == m.MAV_STATE_ACTIVE)


def upload_mission(conn: Any, items: list[tuple[int, int, float]]) -> int:
    """Waypoints (latitude, longitude in degE7; altitude above home in m) by the mission
    protocol, from the ground station's side; returns the MISSION_ACK's type."""
    m = mavutil.mavlink
    conn.mav.mission_count_send(1, 1, len(items), m.MAV_MISSION_TYPE_MISSION)
    while True:
        msg = wait_for(conn, ["MISSION_REQUEST_INT", "MISSION_ACK"])
        if msg.get_type() == "MISSION_ACK":
            return int(msg.type)
        lat, lon, alt = items[msg.seq]
        conn.mav.mission_item_int_send(
            1, 1, msg.seq, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, m.MAV_CMD_NAV_WAYPOINT,
            int(msg.seq == 0), 1, 0, 0.5, 0, math.nan, lat, lon, alt, m.MAV_MISSION_TYPE_MISSION)


@contextmanager
def ground_station(server: MavlinkServer) -> Iterator[Any]:
    """A pymavlink ground station (255/190) on a scripted endpoint's UDP link, closed after."""
    port = int(server.addresses[0].rsplit(":", 1)[1])
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=GCS[0],
                                      source_component=GCS[1])
    try:
        yield conn
    finally:
        conn.close()


@contextmanager
def two_ground_stations(server: MavlinkServer) -> Iterator[tuple[Any, Any]]:
    """Two pymavlink ground stations (255/190 and 254/190) on a scripted endpoint's UDP link,
    closed after."""
    port = int(server.addresses[0].rsplit(":", 1)[1])
    first, second = (mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}",
                                                source_system=src[0], source_component=src[1])
                     for src in (GCS, (254, 190)))
    try:
        yield first, second
    finally:
        first.close()
        second.close()
