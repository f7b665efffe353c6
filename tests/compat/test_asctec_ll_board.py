"""AscTec programs written elsewhere against the simulator's emulated LL board (issue 29).

``skeye sim --ll-board`` presents a robot as the AscTec low-level board on a line. The clients
here were written from AscTec's SDK and the open-source drivers, not from skeye's codec: the
SDK-style TCP client of the pilot's conformance tests (tests/compat/asctec_client.py), unchanged,
and a serial client that reads the pseudo-terminal as the ROS AscTec drivers read their port
(tests/compat/asctec_driver_client.py). These programs grant no sim time, so the board drives
the lockstep clock itself (``rate=``). Waits are on sim time and the board's own answers.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from contextlib import ExitStack

import pytest

from skeye.hil.cli import parse_ll_board, start_ll_board
from skeye.hil.ll_server import LLBoardServer
from skeye.processes import start_skeye, stop_process
from tests.compat.asctec_client import AscTecClient
from tests.compat.asctec_driver_client import POLL_BITS, SerialDriverClient
from tests.compat.test_asctec_packets import ATTITUDE_MODE, STICK_DEG, THRUST, YAW_STICK_DEG_S
from tests.sim.conftest import running_sim


@pytest.fixture
def board() -> Iterator[tuple[AscTecClient, object, LLBoardServer]]:
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=11))
        ll = start_ll_board(stack, parse_ll_board("R1=tcp:0,rate=2"),
                            f"127.0.0.1:{server.port}")
        client = AscTecClient(int(ll.line.address.rsplit(":", 1)[1]))
        stack.callback(client.close)
        yield client, server, ll


def _truth(server) -> tuple[float, tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """Sim time, roll/pitch/yaw, NED velocity and body rates of R1, from the simulator."""
    def read(sim):
        b = sim.body_state("R1")
        return (sim.time_s, tuple(float(v) for v in b.rpy_rad),
                tuple(float(v) for v in b.vel_ned_m_s),
                tuple(float(v) for v in b.omega_frd_rad_s))
    return server.runner.call(read)


def _motors_on(client: AscTecClient) -> None:
    for _ in range(100_000):
        client.ctrl_input(0, 0, -2047, 0, ATTITUDE_MODE)
        if client.ll_status()[7]:  # motors_on
            return
    raise AssertionError("the stick gesture never started the motors")


def _fly(client: AscTecClient, server, seconds: float, pitch: int, roll: int, yaw: int) -> None:
    start = _truth(server)[0]
    while _truth(server)[0] - start < seconds:
        client.ctrl_input(pitch, roll, yaw, THRUST, ATTITUDE_MODE)


def test_rc_data_and_ll_status_of_the_board_at_rest(board) -> None:
    client, _server, ll = board
    client.ctrl_input(100, -200, 300, 40, ATTITUDE_MODE)  # motors off: only shown
    channels = client.rc_data()[:8]
    assert channels[:4] == (2048 + 100, 2048 - 200, 40, 2048 + 300)
    assert channels[4] > 2048  # the serial interface switch is on
    status = client.ll_status()
    assert status[0] > 9000 and status[3] > 0 and status[6] == 0 and status[7] == 0
    ll.board.set_serial_switch(False)  # the safety pilot takes the vehicle back
    assert client.rc_data()[4] < 2048


def test_a_stick_manoeuvre_reads_back_with_the_sdk_signs_and_scales(board) -> None:
    client, server, _ll = board
    _motors_on(client)
    _fly(client, server, 1.5, 0, 600, 0)  # roll right 15 deg
    imu = client.imu_calcdata()
    _, rpy, vel, _ = _truth(server)
    assert imu[1] / 1000 == pytest.approx(600 * STICK_DEG, abs=2.0)
    assert abs(imu[0]) / 1000 < 2.0
    assert rpy[0] > 0.2 and vel[1] > 0.2  # leaning right, going east
    _fly(client, server, 1.5, -600, 0, 0)  # stick forward: nose down, north
    imu = client.imu_calcdata()
    _, rpy, vel, _ = _truth(server)
    assert imu[0] / 1000 == pytest.approx(-600 * STICK_DEG, abs=2.0)
    assert rpy[1] < -0.2 and vel[0] > 0.2
    yaw_before = client.imu_calcdata()[2]
    _fly(client, server, 1.0, 0, 0, 500)  # clockwise 60 deg/s
    imu = client.imu_calcdata()
    assert imu[5] / 64.8 == pytest.approx(500 * YAW_STICK_DEG_S, rel=0.15)
    assert _truth(server)[3][2] > 0.5
    assert 20_000 < (imu[2] - yaw_before) % 360_000 < 120_000


def test_the_ros_drivers_way_of_reading_the_pseudo_terminal() -> None:
    """``skeye sim --ll-board R1=pty`` as a process; a client that opens the printed device,
    sets it up with termios and reads exactly what it asked for, as the ROS drivers do."""
    sim, found = start_skeye(
        ["sim", "--mode", "lockstep", "--port", "0", "--seed", "2", "--ll-board",
         "R1=pty,rate=1"],
        [r"R1 plays an AscTec LL board on (/dev/pts/\d+)"], "skeye sim")
    try:
        client = SerialDriverClient(found[0].group(1))
        try:
            every = 0
            for bit in POLL_BITS:
                every |= bit
            packets = client.get_packets(every)  # all eight structures, back to back
            assert sorted(packets) == [0x01, 0x02, 0x03, 0x11, 0x15, 0x21, 0x23, 0x29]
            battery_mv, _, _, cpu_load = struct.unpack_from("<4h", packets[0x02])
            assert battery_mv > 9000 and cpu_load > 0
            for _ in range(20):  # the poll/command cycle the drivers run
                assert client.send_control(0, 0, 0, 0, ATTITUDE_MODE) == 0x17
                assert sorted(client.get_packets(0x0001 | 0x0004)) == [0x02, 0x03]
        finally:
            client.close()
    finally:
        stop_process(sim)
