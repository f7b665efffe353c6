"""One corrupted answer from an AscTec LL board: the ``asctec-ll://`` airframe resynchronises
on the next good frame (or on the bad frame itself, when it was the last answer due) instead of
waiting out its answer deadline (docs/onboard.md, "Failures and the failsafe").

The simulator's emulated LL board (lockstep) answers over TCP through a proxy that corrupts
one frame of one kind: the ack of the cycle's CTRL_INPUT, the RESULT of its CLOCK grant, the
first (LL_STATUS) or the last (IMU_CALCDATA, in a cycle that asks nothing after it) frame of its
poll. Every such cycle waited out
its ``timeout_s`` (0.5 s by default; 10 s here, so the difference cannot be the host's load)
and counted towards "LL board silent"; the pilot's control cycle stood still meanwhile.
"""

from __future__ import annotations

import time
from contextlib import ExitStack

from skeye.hil.cli import parse_ll_board, start_ll_board
from skeye.pilot.airframe import AirframeOptions, open_airframe
from skeye.pilot.asctec_ll import AscTecLLAirframe
from skeye.wire.packets import PD
from tests.pilot.ll_proxy import Proxy
from tests.sim.conftest import running_sim

ANSWER_TIMEOUT_S = 10.0  # the airframe's answer deadline here (timeout_s in its URI)


class CorruptingProxy(Proxy):
    """TCP between the airframe and the board's line; ``corrupt(pd)`` spoils the next frame
    with that descriptor the board sends (a payload byte of a framed structure or RESULT, which
    fails its CRC; the stop string of an ack), once."""

    def __init__(self, port: int) -> None:
        self.armed: int | None = None
        self.corrupted = 0
        super().__init__(port)

    def corrupt(self, pd: int) -> None:
        self.armed = pd

    def from_board(self, data: bytes) -> bytes:
        pd = self.armed
        if pd is None:
            return data
        if pd == PD.CTRL_INPUT:  # the ack: >a PD a<
            at = data.find(b">a" + bytes([pd]) + b"a<")
            spoil_at = at + 3
        else:  # >*> length(2) PD payload CRC(2) <#<
            at = 0
            while (at := data.find(b">*>", at)) >= 0 and (
                at + 6 >= len(data) or data[at + 5] != pd
            ):
                at += 1
            spoil_at = at + 6
        if at < 0:
            return data
        self.armed = None
        self.corrupted += 1
        spoiled = bytearray(data)
        spoiled[spoil_at] ^= 0x5A
        return bytes(spoiled)


def test_one_corrupted_answer_costs_no_wait_for_the_answer_deadline() -> None:
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=6, estimator="truth"))
        board = start_ll_board(stack, parse_ll_board("R1=tcp:0"), f"127.0.0.1:{server.port}")
        proxy = CorruptingProxy(int(board.line.address.rsplit(":", 1)[1]))
        stack.callback(proxy.close)
        airframe = open_airframe(f"asctec-ll://tcp/127.0.0.1:{proxy.port}?lockstep=1"
                                 f"&timeout_s={ANSWER_TIMEOUT_S:g}", AirframeOptions())
        stack.callback(airframe.close)
        assert isinstance(airframe, AscTecLLAirframe)
        for _ in range(3):  # the line runs
            airframe.advance(0.05)
        waited: list[str] = []
        for pd in (PD.CTRL_INPUT, PD.RESULT, PD.LL_STATUS, PD.IMU_CALCDATA):
            corrupted = proxy.corrupted
            proxy.corrupt(pd)
            for _ in range(5):  # a frame split between two reads is left alone: the next cycle
                cycles, updates = airframe.cycles, airframe.estimate.updates
                begun = time.monotonic()
                airframe.advance(0.05)
                took_s = time.monotonic() - begun
                if proxy.corrupted > corrupted:
                    break
            assert proxy.corrupted == corrupted + 1, f"{pd!r}: no frame corrupted"
            assert airframe.line_errors()[1] > 0, "the bad frame was not seen"
            # The cycle went on at the next good frame: done, its poll taken, nothing silent,
            # and inside the answer deadline it used to wait out.
            done = airframe.cycles == cycles + 1 and airframe.estimate.updates == updates + 1
            if not done or airframe._silent or took_s >= ANSWER_TIMEOUT_S:
                waited.append(f"{pd.name}: cycle done {done}, silent {airframe._silent}, "
                              f"took {took_s:.2f} s")
            assert airframe.lost is None, (pd, airframe.lost)
        assert not waited, waited


class LengthProxy(Proxy):
    """Spoils the length field of the next LL_STATUS frame the board sends, once: 1000 bytes
    (within the protocol's 1024) where the structure has 21."""

    armed = False
    corrupted = 0

    def from_board(self, data: bytes) -> bytes:
        if not self.armed:
            return data
        at = data.find(b">*>")
        while at >= 0 and (at + 5 >= len(data) or data[at + 5] != PD.LL_STATUS):
            at = data.find(b">*>", at + 1)
        if at < 0:
            return data
        self.armed = False
        self.corrupted += 1
        spoiled = bytearray(data)
        spoiled[at + 3 : at + 5] = (1000).to_bytes(2, "little")
        return bytes(spoiled)


def test_an_answer_whose_length_field_is_corrupted_does_not_lose_the_board() -> None:
    """The parser took the length field at its word and held every later byte as that frame's
    rest, waiting for 1000 bytes; the pilot, its answers never parsed, sent nothing more than
    each cycle's sticks (5 bytes of ack a cycle), and after 3 cycles called the board silent
    (``vehicle lost``, for good: it stops commanding, and the board starts its emergency
    procedure), the line's errors reading 0. A structure's length is known from its descriptor:
    a length field that disagrees is a bad frame at once, and the frames behind it are read.
    A real-time board over TCP, on a fake vehicle (no simulator)."""
    from skeye.hil.line import open_line
    from skeye.hil.ll_server import LLBoardServer
    from tests.pilot.fake_airframe import FakeAirframe

    with ExitStack() as stack:
        board = stack.enter_context(LLBoardServer(FakeAirframe(), open_line("tcp"),
                                                  time.monotonic))
        proxy = LengthProxy(int(board.line.address.rsplit(":", 1)[1]))
        stack.callback(proxy.close)
        airframe = open_airframe(f"asctec-ll://tcp/127.0.0.1:{proxy.port}", AirframeOptions())
        stack.callback(airframe.close)
        assert isinstance(airframe, AscTecLLAirframe)
        proxy.armed = True
        deadline = time.monotonic() + 5.0
        while proxy.corrupted == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert proxy.corrupted == 1, "no frame corrupted"
        cycles = airframe.cycles
        while airframe.cycles < cycles + 10 and airframe.lost is None:  # 0.5 s at 20 Hz
            assert time.monotonic() < deadline + 5.0, f"stuck at {airframe.cycles} cycles"
            time.sleep(0.01)
        assert airframe.lost is None, airframe.lost
        assert airframe.line_errors()[1] >= 1, "the bad frame was not counted"
