"""Several vehicles seen by one MAVLink client: each pilot its own system id (``--mavlink-sysid``),
as PX4's ``MAV_SYS_ID`` (its multi-vehicle SITL gives instance i the id i + 1) and ArduPilot's
``SYSID_THISMAV`` are set per vehicle, so that one ground station tells them apart."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from contextlib import ExitStack

from pymavlink import mavutil

from tests.control.conftest import sim_running
from tests.mavlink.conftest import GCS, free_udp_port

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
