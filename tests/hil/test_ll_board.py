"""The emulated LL board, sans-IO (skeye.hil.ll_board) and its ``--ll-board`` spec, on a
scripted airframe: what it answers on its line, its serial timeout and the R/C switch."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import ConfigError
from skeye.hil.cli import LLBoardSpec, parse_ll_board
from skeye.hil.ll_board import LLBoard, LLSettings
from skeye.wire.packets import (
    PD,
    Ack,
    Clock,
    CommandStreamParser,
    CtrlInput,
    Hold,
    LlStatus,
    NavState,
    Poll,
    PollMask,
    RcData,
    Result,
    ResultCode,
    TakeOff,
    encode,
)
from tests.pilot.fake_airframe import FakeAirframe

GPS_STICKS = 0x2F  # pitch, roll, yaw, thrust from the serial input, GPS mode
GESTURE = CtrlInput(0, 0, -2047, 0, GPS_STICKS)


def send(board: LLBoard, data: bytes, now_s: float) -> list:
    out = []
    for event in CommandStreamParser().feed(data):
        out += board.handle(event, now_s)
    return out


def flying(board: LLBoard, air: FakeAirframe) -> float:
    """Motors on by the gesture, then climbing sticks: the board flies; returns the time."""
    t = 0.0
    for _ in range(25):
        assert send(board, encode(GESTURE), t) == [Ack(PD.CTRL_INPUT)]
        board.tick(t)
        t += 0.05
    assert board.boards.motors_on
    assert send(board, encode(CtrlInput(0, 0, 0, 3000, GPS_STICKS)), t) == [Ack(PD.CTRL_INPUT)]
    assert board.boards.state is NavState.MANUAL and air.gps_mode  # the sticks fly it
    return t


def test_every_intact_command_is_acknowledged_even_when_the_board_ignores_it():
    air = FakeAirframe()
    board = LLBoard(air)
    # Sticks before the motors run: acknowledged, not flown (LL_STATUS says motors off).
    assert send(board, encode(CtrlInput(0, 0, 0, 3000, GPS_STICKS)), 0.0) == [Ack(PD.CTRL_INPUT)]
    assert "set_velocity" not in air.names()
    (status,) = send(board, encode(Poll(int(PollMask.LL_STATUS))), 0.0)
    assert isinstance(status, LlStatus) and status.motors_on == 0


def test_an_intact_command_with_a_field_out_of_range_is_acknowledged_not_flown():
    """A CTRL_INPUT whose checksum holds but whose pitch is 3000 (the range is +-2047) was
    counted as a checksum error and never acknowledged, though every intact command is."""
    from skeye.wire.crc import command_checksum
    from skeye.wire.packets import LAYOUTS

    air = FakeAirframe()
    board = LLBoard(air)
    t = flying(board, air)
    flown = len(air.calls)
    layout = LAYOUTS[CtrlInput]
    fields = (3000, 0, 0, 3000, GPS_STICKS)
    packet = layout.prefix + layout.packer.pack(*fields, command_checksum(*fields))
    assert send(board, packet, t) == [Ack(PD.CTRL_INPUT)]
    assert len(air.calls) == flown  # not flown
    assert board.ignored["a field out of range"] == 1
    (status,) = send(board, encode(Poll(int(PollMask.LL_STATUS))), t)
    assert status.chksum_error == 0


def test_bad_checksums_garbage_and_unknown_letters_are_counted_never_answered():
    board = LLBoard(FakeAirframe())
    bad = bytearray(encode(CtrlInput(1, 2, 3, 4, 0x0F)))
    bad[-1] ^= 0xFF
    assert send(board, bytes(bad) + b"\x00garbage>*>zz", 0.0) == []
    (status,) = send(board, encode(Poll(int(PollMask.LL_STATUS))), 0.0)
    assert status.chksum_error >= 1


def test_skeye_commands_get_a_result_naming_the_board_and_clock_is_left_to_the_line():
    board = LLBoard(FakeAirframe())
    (reply,) = send(board, encode(TakeOff(1000)), 0.0)
    assert isinstance(reply, Result) and reply.code is ResultCode.BAD_VALUE
    assert "AscTec commands only" in reply.reason and board.refused_skeye == 1
    assert send(board, encode(Clock(5000)), 0.0) == []  # answered once the time is reached


def test_a_silent_line_starts_wait_and_land_and_sticks_end_it():
    air = FakeAirframe()
    board = LLBoard(air, LLSettings(serial_timeout_s=0.5, wait_before_landing_s=5.0))
    t = flying(board, air)
    board.tick(t + 0.4)
    assert board.boards.state is NavState.MANUAL  # within the timeout
    board.tick(t + 0.6)
    assert board.boards.state is NavState.FAILSAFE and board.emergencies == 1
    assert air.names()[-1] == "hover"  # waits where it is ...
    board.tick(t + 5.5)
    assert board.boards.state is NavState.FAILSAFE
    board.tick(t + 5.7)
    assert board.boards.state is NavState.LANDING and air.names()[-1] == "land"  # ... then lands
    assert board.in_emergency
    # The serial input comes back: the procedure ends and the sticks fly again.
    send(board, encode(CtrlInput(0, 0, 0, 2048, GPS_STICKS)), t + 6.0)
    assert board.boards.state is NavState.MANUAL and not board.in_emergency
    assert air.names()[-2:] == ["hover", "set_velocity"]


def test_the_safety_pilots_switch_takes_the_vehicle_from_the_serial_line():
    air = FakeAirframe()
    board = LLBoard(air)
    t = flying(board, air)
    board.set_serial_switch(False)
    assert air.names()[-1] == "hover"
    calls = len(air.calls)
    assert send(board, encode(CtrlInput(900, 0, 0, 3000, GPS_STICKS)), t) == [Ack(PD.CTRL_INPUT)]
    assert len(air.calls) == calls and board.ignored["serial switch off"] == 1
    (rc,) = send(board, encode(Poll(int(PollMask.RC_DATA))), t)
    assert isinstance(rc, RcData) and rc.channels_in[4] == 0
    board.set_serial_switch(True)
    (rc,) = send(board, encode(Poll(int(PollMask.RC_DATA))), t)
    assert rc.channels_in[4] > 2048


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_arbitrary_bytes_never_break_the_board(data):
    board = LLBoard(FakeAirframe())
    for m in send(board, data, 0.0):
        encode(m)
    assert [type(m) for m in send(board, encode(Poll(0x0001)), 0.0)] == [LlStatus]


@pytest.mark.parametrize(("text", "spec"), [
    ("R1=pty", LLBoardSpec("R1", "pty")),
    ("R2=tcp:7100,robot=airrobot,start=Pad2", LLBoardSpec("R2", "tcp", port=7100,
                                                          robot="airrobot", start="Pad2")),
    ("R1=serial:/dev/ttyUSB0,baud=115200", LLBoardSpec("R1", "serial", device="/dev/ttyUSB0",
                                                       baud=115200)),
    ("R1=pty,rate=2,serial_timeout=1.5", LLBoardSpec("R1", "pty", rate=2.0,
                                                     serial_timeout_s=1.5)),
])
def test_ll_board_specs(text, spec):
    assert parse_ll_board(text) == spec


@pytest.mark.parametrize(("text", "words"), [
    ("pty", "expected NAME=pty"),
    ("R1=udp:1", "must be pty, tcp:PORT or serial:DEVICE"),
    ("R1=tcp:x", "tcp needs a port"),
    ("R1=tcp:70000", "not 0..65535"),
    ("R1=serial:ttyUSB0", "device path"),
    ("R1=pty,baud=9600", "baud=9600 is for a serial line"),
    ("R1=pty,colour=red", "unknown option 'colour'"),
    ("R1=pty,rate=0", "rate must be"),
    ("R1=pty,serial_timeout=-1", "serial_timeout must be"),
    ("R1=pty:/dev/x", "pty takes no address"),
    # An option given twice: until 2026-11-28 the last was taken without a word (the rule
    # for a URI's options, skeye/uris.py query_of)
    ("R1=pty,serial_timeout=1,serial_timeout=2", "option 'serial_timeout' is given twice"),
    ("R1=pty,start=Pad1,start=Field1", "option 'start' is given twice"),
    ("R1=serial:/dev/ttyUSB0,baud=9600,baud=57600", "option 'baud' is given twice"),
])
def test_bad_ll_board_specs_are_named(text, words):
    with pytest.raises(ConfigError, match=words):
        parse_ll_board(text)


def test_hold_is_not_an_ll_command():
    board = LLBoard(FakeAirframe())
    (reply,) = send(board, encode(Hold()), 0.0)
    assert isinstance(reply, Result) and reply.command_pd == PD.HOLD


def test_ll_board_tcp_ports_are_checked_with_the_simulators_before_anything_starts(capsys):
    import socket

    from skeye.cli import main

    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        for argv, words in (
            (["--ll-board", "R1=tcp:7100", "--ll-board", "R2=tcp:7100"],
             "port 7100 is given to both LL board R1's line (--ll-board R1=tcp:PORT) and LL "
             "board R2's line; move one with --ll-board R2=tcp:PORT"),
            (["--port", str(port + 1), "--ll-board", f"R1=tcp:{port + 1}"],
             f"port {port + 1} is given to both the simulator's control protocol"),
            (["--ll-board", f"R1=tcp:{port}"],
             f"port {port} on 127.0.0.1 (for LL board R1's line) is already in use - another "
             "skeye up or server running? Stop it, or move LL board R1's line with "
             "--ll-board R1=tcp:PORT"),
        ):
            assert main(["sim", "--port", "0", *argv]) == 2
            err = capsys.readouterr()
            assert f"skeye sim: error: {words}" in err.err, err.err
            assert "control protocol on" not in err.out and "Errno" not in err.err


def test_a_board_the_simulator_cannot_make_is_named(tmp_path):
    from contextlib import ExitStack

    from skeye.hil.cli import start_ll_board
    from tests.sim.conftest import running_sim

    with running_sim() as server:
        for text, words in (
            ("R7=pty,robot=nosuch", "--ll-board R7: .*unknown robot class 'nosuch'"),
            ("R8=pty,start=Nowhere", "--ll-board R8: no start pose 'Nowhere'"),
            (f"R9=serial:{tmp_path}/no-such-tty", f"--ll-board R9: .*{tmp_path}/no-such-tty"),
        ):
            with ExitStack() as stack, pytest.raises(ConfigError, match=words):
                start_ll_board(stack, parse_ll_board(text), f"127.0.0.1:{server.port}")
