"""Several vehicles seen by one MAVLink client: each pilot its own system id (``--mavlink-sysid``),
as PX4's ``MAV_SYS_ID`` (its multi-vehicle SITL gives instance i the id i + 1) and ArduPilot's
``SYSID_THISMAV`` are set per vehicle, so that one ground station tells them apart."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from contextlib import ExitStack

from pymavlink import mavutil

from skeye.pilot.boards import OnboardBoards
from skeye.pilot.mavlink_server import MavlinkServer
from tests.control.conftest import sim_running
from tests.mavlink.conftest import GCS, free_udp_port, mav_vehicle, take_off, wait_for
from tests.pilot.fake_airframe import FakeAirframe

M = mavutil.mavlink


def _pilot(stack: ExitStack, sim: str, name: str, where: list[str], sysid: str, gcs_port: int,
           log: str) -> subprocess.Popen[bytes]:
    err = stack.enter_context(open(log, "w"))
    child = subprocess.Popen(
        [sys.executable, "-m", "skeye.cli", "pilot", "--sim", sim, "--port", "0", "--name", name,
         *where, "--lockstep-rate", "1", "--mavlink-sysid", sysid,
         "--mavlink", f"udpout://127.0.0.1:{gcs_port}"],
        stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL)

    def stop() -> None:
        child.send_signal(signal.SIGINT)
        try:
            child.wait(30)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait(10)

    stack.callback(stop)
    return child


def test_two_pilots_are_two_systems_to_one_ground_station(tmp_path):
    port = free_udp_port()
    with ExitStack() as stack:
        handle = stack.enter_context(sim_running())
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=GCS[0],
                                         source_component=GCS[1])
        stack.callback(gcs.close)
        pilots = [_pilot(stack, handle.address, "R1", ["--start", "Pad1"], "1", port,
                         str(tmp_path / "r1.err")),
                  _pilot(stack, handle.address, "R2", ["--location", "-3,0,0"], "2", port,
                         str(tmp_path / "r2.err"))]
        seen: set[int] = set()
        deadline = time.monotonic() + 90
        while seen != {1, 2}:
            assert time.monotonic() < deadline and all(p.poll() is None for p in pilots), (
                seen, [p.poll() for p in pilots], (tmp_path / "r2.err").read_text())
            msg = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
            if msg is not None and msg.get_srcComponent() == M.MAV_COMP_ID_AUTOPILOT1:
                seen.add(msg.get_srcSystem())
        # a command for system 2 is taken by R2's pilot alone
        gcs.mav.command_long_send(2, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        acks: list[int] = []
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            msg = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=1.0)
            if msg is not None and msg.command == M.MAV_CMD_COMPONENT_ARM_DISARM:
                acks.append(msg.get_srcSystem())
                if msg.get_srcSystem() == 2:
                    assert msg.result == M.MAV_RESULT_ACCEPTED, msg
                    break
        assert acks == [2], acks
    # an id outside MAVLink's 1..255 is refused at start
    bad = subprocess.run([sys.executable, "-m", "skeye.cli", "pilot", "--sim", "127.0.0.1:1",
                          "--mavlink-sysid", "0", "--mavlink", f"udpout://127.0.0.1:{port}"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--mavlink-sysid" in bad.stderr, bad


def test_another_vehicle_heard_on_the_link_keeps_no_ground_link_alive():
    """Vehicles of a fleet hear each other where a router forwards between them (mavlink-router
    sends a message without a target to every endpoint; so does a shared radio net). Another
    vehicle's stream is no ground station: PX4 counts only MAV_TYPE_GCS heartbeats towards its
    data link (COM_DL_LOSS_T), ArduPilot only its own ground station's (SYSID_MYGCS). Here R2's
    1 Hz heartbeat and 20 Hz attitude, arriving on R1's link, kept R1's link-loss timer from
    ever running out, and R1 took R2 for a second ground station."""
    port = free_udp_port()
    with mav_vehicle(uris=[f"udp://127.0.0.1:{port}"]) as v:
        gcs = v.keep(mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}",
                                                source_system=GCS[0], source_component=GCS[1]))
        take_off(gcs)
        gcs.mav.param_set_send(1, 1, b"COM_DL_LOSS_T", 1.0, M.MAV_PARAM_TYPE_REAL32)
        wait_for(gcs, "PARAM_VALUE", lambda m: m.param_id == "COM_DL_LOSS_T")
        timeout_s = v.pilot.boards.settings.link_timeout_s
        assert timeout_s == 1.0
        # R2: a vehicle whose stream reaches R1's link (system 2, landed, on a scripted airframe)
        with MavlinkServer(OnboardBoards(FakeAirframe()), threading.Lock(),
                           [f"udpout://127.0.0.1:{port}"], system_id=2) as r2:
            deadline = time.monotonic() + 60  # a stuck guard
            while r2.received == 0:  # R1 answers the senders it hears: it has heard R2
                assert time.monotonic() < deadline, "R1 never heard R2"
                wait_for(gcs, "ATTITUDE")  # (the ground station's heartbeat goes on meanwhile)
            silent_from_ms = wait_for(gcs, "ATTITUDE").time_boot_ms  # the ground falls silent
            silent_from_s = time.monotonic()
            # The failsafe comes once the link has been silent COM_DL_LOSS_T on the vehicle's
            # clock and on the wall clock both (docs/pilot.md), and is told at once or by the
            # next 1 Hz heartbeat: by the time both clocks are past that, it has been told.
            by_s = timeout_s + 1.0
            while True:
                msg = wait_for(gcs, ["HEARTBEAT", "ATTITUDE"], heartbeat=False)
                if msg.get_type() == "HEARTBEAT" and msg.system_status == M.MAV_STATE_CRITICAL:
                    break
                if msg.get_type() == "ATTITUDE":
                    vehicle_s = (msg.time_boot_ms - silent_from_ms) / 1000.0
                    wall_s = time.monotonic() - silent_from_s
                    assert vehicle_s <= by_s or wall_s <= by_s, (
                        f"no link-loss failsafe {vehicle_s:.1f} s of vehicle time ({wall_s:.1f} s "
                        "of wall time) after the ground station fell silent, with another "
                        "vehicle on the link")
            assert v.pilot.boards.state.name == "FAILSAFE"
            assert (2, 1) not in v.mavlink.vehicle.gcs, v.mavlink.vehicle.gcs
