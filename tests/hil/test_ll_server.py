"""The simulator's LL board on its line (skeye.hil.ll_server): its CLOCK grants, held in
``Grants`` and bounded by ``MAX_GRANTS``, over a real loopback line."""

from __future__ import annotations

import os
import select
import socket
import threading
import time
import tty
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

import pytest

from skeye.hil.cli import parse_ll_board, start_ll_board
from skeye.hil.ll_server import MAX_GRANTS, Grants, LLBoardServer
from skeye.wire.packets import (
    PD,
    Clock,
    LlStatus,
    Message,
    Poll,
    PollMask,
    Result,
    ResultCode,
    VehicleStreamParser,
    encode,
)
from skeye.workers import WorkerFailed
from tests.sim.conftest import running_sim

FAR_MS = 3_000_000_000  # ms of sim time no test reaches


def test_grants_leave_lowest_first_and_a_grant_sent_again_is_known():
    grants = Grants(limit=3)
    for until_s in (2.0, 1.0, 3.0):
        grants.add(until_s)
    assert grants.full and len(grants) == 3 and grants.latest == 3.0
    assert 1.0 in grants and 1.5 not in grants
    assert grants.reached(1.5) == 1 and 1.0 not in grants and grants.latest == 3.0
    assert not grants.full
    assert grants.reached(3.0) == 2 and len(grants) == 0 and grants.latest is None


class LineClient:
    """A raw client of the board's TCP line: frames out, the board's messages back."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=60.0)
        self.parser = VehicleStreamParser()
        self.pending: list[object] = []

    def _events(self) -> Iterator[object]:
        """The board's messages, in order, reading the line as needed (the socket's timeout
        bounds each wait)."""
        while True:
            while self.pending:
                yield self.pending.pop(0)
            chunk = self.sock.recv(1 << 16)
            assert chunk, "the board closed the line"
            self.pending += self.parser.feed(chunk)

    def next_clock_result(self) -> Result:
        """The next CLOCK answer (the socket's timeout bounds the wait)."""
        for event in self._events():
            if isinstance(event, Result) and event.command_pd == PD.CLOCK:
                return event
        raise AssertionError("unreachable")

    def exchange(self, data: bytes) -> tuple[list[Result], LlStatus]:
        """Send ``data`` and an LL_STATUS poll; the CLOCK answers before the poll's, and it."""
        self.sock.sendall(data + encode(Poll(int(PollMask.LL_STATUS))))
        results: list[Result] = []
        for event in self._events():
            if isinstance(event, LlStatus):
                return results, event
            if isinstance(event, Result) and event.command_pd == PD.CLOCK:
                results.append(event)
            else:
                assert isinstance(event, Message), event
        raise AssertionError("unreachable")


def sim_time(answer: Result) -> float:
    """The sim time a CLOCK answer says (``sim time 12.350000 s``)."""
    words = answer.reason.split()
    assert words[:2] == ["sim", "time"] and words[3] == "s", answer
    return float(words[2])


@contextmanager
def board_line() -> Iterator[tuple[LLBoardServer, LineClient]]:
    """A lockstep simulator's board on a TCP line (the client grants time), and a client."""
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=6, estimator="truth"))
        board = start_ll_board(stack, parse_ll_board("R1=tcp:0"), f"127.0.0.1:{server.port}")
        client = LineClient(int(board.line.address.rsplit(":", 1)[1]))
        stack.callback(client.sock.close)
        yield board, client


def test_a_flood_of_grants_is_bounded_and_refused_by_name_and_the_line_still_answers():
    with board_line() as (board, client):
        extra = 5
        flood = b"".join(encode(Clock(FAR_MS - i)) for i in range(MAX_GRANTS + extra))
        results, status = client.exchange(flood)
        assert isinstance(status, LlStatus)
        assert len(results) == extra, results
        for refusal in results:
            assert refusal.code is ResultCode.BUSY
            assert f"{MAX_GRANTS} grants not yet reached are held" in refusal.reason
        assert len(board.grants) == MAX_GRANTS
        # At the limit, a grant already held (sent again) and one already passed are still
        # answered at once with the time so far; only a new one is refused.
        results, _ = client.exchange(encode(Clock(FAR_MS)) + encode(Clock(0))
                                     + encode(Clock(FAR_MS + 1)))
        assert [r.code for r in results] == [ResultCode.OK, ResultCode.OK, ResultCode.BUSY]
        assert all(r.reason.startswith("sim time ") for r in results[:2])
        board.check()


def test_grants_below_the_latest_are_answered_as_the_simulator_reaches_them():
    with board_line() as (board, client):
        results, _ = client.exchange(encode(Clock(0)))  # passed: the time now
        assert [r.code for r in results] == [ResultCode.OK]
        start_s = sim_time(results[0])
        # 30 s ahead: the clock thread, already stepping towards the far grant, must not pass
        # the near one before the reader has taken it from the same write (on a busy machine
        # the reader may wait a while between two packets; stepping 30 s takes far longer).
        near_ms = round(start_s * 1000) + 30_000
        results, _ = client.exchange(encode(Clock(FAR_MS)) + encode(Clock(near_ms)))
        # The near grant is answered on the way to the far one, not once that is reached.
        answer = results[0] if results else client.next_clock_result()
        assert answer.code is ResultCode.OK
        reached = sim_time(answer)
        assert near_ms / 1000 <= reached < near_ms / 1000 + 2 * board.tick_s
        assert board.grants.latest == FAR_MS / 1000.0


def test_a_client_that_leaves_takes_its_grants_with_it():
    """Grants held for a client that left are dropped: the board's clock runs on at real time
    (free running) instead of racing sim time to the far grant for no one."""
    with board_line() as (board, client):
        client.exchange(encode(Clock(FAR_MS)))
        assert board.grants.latest == FAR_MS / 1000.0
        client.sock.close()
        deadline = time.monotonic() + 30.0  # a stuck guard: the line notices within a read
        while not board.free_running:
            assert time.monotonic() < deadline, "the board never noticed the client left"
            time.sleep(0.05)
        assert len(board.grants) == 0 and board.grants.latest is None
        board.check()


def test_a_client_replaced_by_a_newer_one_takes_its_grants_with_it():
    """A second TCP client takes the line over while the first still has it open: the first's
    grants go (the board does not step on to them, nor answer the newcomer for them), and the
    newcomer's grants are served."""
    with board_line() as (board, first):
        first.exchange(encode(Clock(FAR_MS)))
        assert board.grants.latest == FAR_MS / 1000.0
        second = LineClient(int(board.line.address.rsplit(":", 1)[1]))
        try:
            results, _ = second.exchange(encode(Clock(0)))  # the time now, on the new client
            now_ms = round(sim_time(results[0]) * 1000)
            assert FAR_MS / 1000.0 not in board.grants
            results, _ = second.exchange(encode(Clock(now_ms + 500)))
            answer = results[0] if results else second.next_clock_result()
            assert answer.code is ResultCode.OK
            reached = sim_time(answer)
            assert now_ms / 1000 + 0.5 <= reached < now_ms / 1000 + 0.5 + 2 * board.tick_s
            assert len(board.grants) == 0 and not board.free_running
            # A grant the reader took from the first client just before the second came (the
            # race a review forced with threads) is not held for the newcomer.
            assert board.line.received_from == board.line.client_number == 2
            board._grant(FAR_MS / 1000.0, 1)
            assert len(board.grants) == 0
            board.check()
        finally:
            second.sock.close()


def test_a_frame_left_unfinished_by_a_client_that_left_does_not_swallow_the_next_ones():
    """A client that leaves mid-frame: the next client's packets are its own. The board kept
    the unfinished frame's bytes and read the newcomer's as its rest: a skeye frame header
    claiming 1000 bytes made the board deaf to a pilot's first polls (it gave up: "LL board
    silent")."""
    with board_line() as (board, first):
        first.exchange(b"")  # on the line
        first.sock.sendall(b">*>s" + (1000).to_bytes(2, "little"))  # and gone, mid-frame
        first.sock.close()
        deadline = time.monotonic() + 30.0  # a stuck guard: the line notices within a read
        while board.line.plugged:
            assert time.monotonic() < deadline, "the board never noticed the client left"
            time.sleep(0.05)
        second = LineClient(int(board.line.address.rsplit(":", 1)[1]))
        try:
            second.sock.settimeout(5.0)  # the board answers a poll at once
            _, status = second.exchange(b"")
            assert isinstance(status, LlStatus)
            assert board.parser.buffered == 0
            board.check()
        finally:
            second.sock.close()


def test_a_serial_line_that_fails_is_said_not_left_silently(caplog):
    """The board on a serial device whose other end hangs up (a USB adapter pulled): its
    reader stopped without a word, the board never answered again, and in lockstep its clock
    stood still (so its serial timeout never played out). Now the failure is logged naming
    the line and what happened, and the clock runs on as after a client that left."""
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    os.close(slave)
    try:
        with ExitStack() as stack:
            server = stack.enter_context(running_sim(mode="lockstep", seed=6,
                                                     estimator="truth"))
            board = start_ll_board(stack, parse_ll_board(f"R1=serial:{path}"),
                                   f"127.0.0.1:{server.port}")
            os.write(master, encode(Poll(int(PollMask.LL_STATUS))))
            parser, answers = VehicleStreamParser(), []
            deadline = time.monotonic() + 30.0  # a stuck guard: a poll is answered at once
            while not any(isinstance(a, LlStatus) for a in answers):
                assert time.monotonic() < deadline, "the board never answered"
                if select.select([master], [], [], 0.1)[0]:
                    answers += parser.feed(os.read(master, 4096))
            os.close(master)
            master = -1
            said = f"LL board R1: its line {path} failed"

            def errors() -> list[str]:
                return [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]

            deadline = time.monotonic() + 30.0  # the reader sees the hang-up within a read
            while not any(said in e for e in errors()):
                assert time.monotonic() < deadline, f"the failure was never said: {errors()}"
                time.sleep(0.05)
            assert board.line_failed is not None and path in board.line_failed
            # No client will grant time again: the board's clock runs on by itself (lockstep),
            # so its serial timeout's procedure plays out, as after a client that left.
            while not board.free_running:
                assert time.monotonic() < deadline, "the board's clock did not run on"
                time.sleep(0.05)
            board.check()
    finally:
        if master >= 0:
            os.close(master)


def _skeye_frame(pd: int, payload: bytes) -> bytes:
    """A skeye command frame as docs/protocols/packets.md spells it (``>*>s``, uint16 length,
    PD, payload, CRC16 of the payload, ``<#<``), built byte by byte as a third-party client
    would, not by skeye's codec."""
    crc = 0x00FF
    for byte in payload:
        d = byte ^ (crc & 0xFF)
        d ^= (d << 4) & 0xFF
        crc = (((d << 8) | (crc >> 8)) ^ (d >> 4) ^ (d << 3)) & 0xFFFF
    return (b">*>s" + len(payload).to_bytes(2, "little") + bytes([pd]) + payload
            + crc.to_bytes(2, "little") + b"<#<")


def test_an_intact_skeye_frame_the_board_cannot_take_is_answered_not_dropped_silently():
    """A CLOCK with a payload of the wrong length, a skeye PD the protocol does not have and a
    skeye command with a field it cannot carry all arrive intact (their CRC and stop string
    hold): the board answered none of them and counted none in LL_STATUS ``chksum_error``, so
    a client granting time waited out its own timeout on a board that had heard it. Each is
    now answered with a RESULT naming its PD, as the board's other skeye packets are: code 2
    for the CLOCK the board takes, code 3 for the packets it does not."""
    with board_line() as (_board, client):
        client.sock.settimeout(10.0)  # the board answers at once
        sent = [
            (_skeye_frame(PD.CLOCK, b"\x00\x00\x00"), PD.CLOCK, ResultCode.BAD_LENGTH),
            (_skeye_frame(0x8F, b""), 0x8F, ResultCode.BAD_VALUE),
            (_skeye_frame(0x42, b""), 0x42, ResultCode.BAD_VALUE),  # below the skeye PDs
            (_skeye_frame(0x99, b""), 0x99, ResultCode.BAD_VALUE),  # above them
            (_skeye_frame(PD.TAKE_OFF, b"\x00"), PD.TAKE_OFF, ResultCode.BAD_VALUE),
        ]
        for data, pd, code in sent:
            client.sock.sendall(data + encode(Poll(int(PollMask.LL_STATUS))))
            answers = []
            for event in client._events():
                if isinstance(event, LlStatus):
                    break
                answers.append(event)
            assert len(answers) == 1 and isinstance(answers[0], Result), (pd, answers)
            assert answers[0].command_pd == pd and answers[0].code is code, answers[0]
            assert event.chksum_error == 0  # intact: not a checksum error
        _board.check()


def test_a_tcp_client_that_reads_nothing_does_not_silence_the_board():
    """A TCP client that floods the line with polls and reads none of the answers: the board's
    send to it timed out (LinkTimeout, which the line did not catch) and killed the board's
    reader, so the board never answered anyone again, a new client included. The answers it
    cannot deliver are dropped (counted), as on a line with nobody reading, and it serves on."""
    with board_line() as (board, client):
        client.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        client.sock.settimeout(0.5)
        flood = encode(Poll(0xFFFF)) * 1000  # every structure: ~65 times the bytes back
        try:
            while True:  # until the board stops taking them (it waits on its own sends)
                client.sock.sendall(flood)
        except TimeoutError:
            pass
        deadline = time.monotonic() + 60.0  # a stuck guard: a send times out within 1 s
        while board.line.dropped_bytes == 0:
            assert time.monotonic() < deadline, "the board's sends never timed out"
            board.check()  # the reader is alive
            time.sleep(0.05)
        client.sock.close()
        second = LineClient(int(board.line.address.rsplit(":", 1)[1]))
        try:
            second.sock.settimeout(30.0)  # the board answers a poll at once
            _, status = second.exchange(b"")
            assert isinstance(status, LlStatus)
            board.check()
        finally:
            second.sock.close()


def _pace(board: LLBoardServer, sim_s: float) -> float:
    """Sim seconds per wall second while the board's clock moves ``sim_s`` of sim time."""
    start_sim, start_wall = board.sim_time(), time.monotonic()
    deadline = start_wall + 120.0  # a stuck guard
    while board.sim_time() < start_sim + sim_s:
        assert time.monotonic() < deadline, "the board's clock did not move"
        board.check()
        time.sleep(0.01)
    return (board.sim_time() - start_sim) / (time.monotonic() - start_wall)


def _granted_pace(board: LLBoardServer, client: LineClient, sim_s: float) -> float:
    """How fast the simulator steps when a client grants ``sim_s`` ahead (unpaced)."""
    results, _ = client.exchange(encode(Clock(0)))
    start_sim, start_wall = sim_time(results[0]), time.monotonic()
    results, _ = client.exchange(encode(Clock(round((start_sim + sim_s) * 1000))))
    answer = results[0] if results else client.next_clock_result()
    return (sim_time(answer) - start_sim) / (time.monotonic() - start_wall)


def test_the_boards_paced_clock_keeps_the_rate_it_was_given():
    """``rate=R``: the board drives the lockstep clock at R sim seconds per wall second. Each
    of its ticks first waited out the whole 0.1 s wait for a CLOCK grant, so the clock never
    passed 0.5 (one 0.05 s tick per 0.1 s): ``rate=4`` ran at 0.44. Measured against how fast
    the simulator steps on a grant, so a slow machine cannot fail it."""
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=6, estimator="truth"))
        board = start_ll_board(stack, parse_ll_board("R1=tcp:0,rate=4"),
                               f"127.0.0.1:{server.port}")
        client = LineClient(int(board.line.address.rsplit(":", 1)[1]))
        able = _granted_pace(board, client, 2.0)
        client.sock.close()  # the board's own clock from here
        paced = _pace(board, 2.0)
        assert paced >= 0.6 * min(4.0, able), (paced, able)


def test_the_boards_clock_runs_on_at_real_time_once_its_client_left():
    """With no client left the lockstep board's clock runs on at real time (docs/onboard.md),
    so its serial timeout plays out as on the vehicle; it ran at half of it (each 0.05 s tick
    waited out a 0.1 s wait for a grant first)."""
    with board_line() as (board, client):
        able = _granted_pace(board, client, 2.0)
        client.sock.close()
        deadline = time.monotonic() + 30.0  # a stuck guard: the line notices within a read
        while not board.free_running:
            assert time.monotonic() < deadline, "the board never noticed the client left"
            time.sleep(0.05)
        free = _pace(board, 2.0)
        assert free >= 0.6 * min(1.0, able), (free, able)


def test_a_paced_clock_slower_than_a_timeout_can_wait_still_serves_grants():
    """``rate=1e-300`` (above 0, so taken): the paced clock's next tick lay beyond what a
    thread can wait for, and the clock worker died on an OverflowError; no grant was answered
    again. A slow paced clock also held a grant sent meanwhile until its next tick (at
    ``rate=0.001``, 50 s). The clock now waits for a grant and its next tick together."""
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=6, estimator="truth"))
        board = start_ll_board(stack, parse_ll_board("R1=tcp:0,rate=1e-300"),
                               f"127.0.0.1:{server.port}")
        # (its first tick is due at once, as the board starts: the next one is not)
        client = LineClient(int(board.line.address.rsplit(":", 1)[1]))
        stack.callback(client.sock.close)
        client.sock.settimeout(30.0)  # the simulator steps 0.5 s on a grant in well under it
        results, _ = client.exchange(encode(Clock(0)))
        now_ms = round(sim_time(results[0]) * 1000)
        results, _ = client.exchange(encode(Clock(now_ms + 500)))
        answer = results[0] if results else client.next_clock_result()
        assert answer.code is ResultCode.OK and sim_time(answer) >= (now_ms + 500) / 1000
        board.check()


def test_a_tcp_line_out_of_descriptors_accepts_again_once_they_free(caplog):
    """accept() failing for want of file descriptors (EMFILE, a simulator serving many
    clients) ended the line's accept thread without a word: the board never took a client
    again. It is said and waited out, as the simulator's and the pilot's own listeners do
    (skeye.peers.accept_failed)."""
    import resource

    from skeye.hil.line import TcpLine

    line = TcpLine()
    try:
        client = socket.socket()  # made before the descriptors run out: connect needs none
        filler: list[int] = []
        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (len(os.listdir("/proc/self/fd")) + 8,
                                                        hard))
            try:
                while True:
                    filler.append(os.open(os.devnull, os.O_RDONLY))
            except OSError:
                pass
            client.connect(("127.0.0.1", line.port))  # the kernel completes it; accept fails
            deadline = time.monotonic() + 30.0  # a stuck guard: accept wakes every 0.2 s
            while line._accept.alive and "cannot accept" not in caplog.text:
                assert time.monotonic() < deadline, "accept never ran out of descriptors"
                time.sleep(0.01)
        finally:
            for fd in filler:
                os.close(fd)
            resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
        try:
            deadline = time.monotonic() + 30.0  # a stuck guard: accepted within a retry
            while not line.plugged:
                assert line._accept.alive, "the line's accept thread ended"
                assert time.monotonic() < deadline, "the client was never accepted"
                time.sleep(0.01)
        finally:
            client.close()
    finally:
        line.close()


def test_a_board_line_is_a_context_manager_that_closes_its_port_and_thread():
    """A line is a server (a TCP line listens on a thread of its own): ``with`` closes it, its
    listener and its accept thread with it; it was no context manager at all."""
    from skeye.hil.line import open_line

    with open_line("tcp") as line:
        assert line.plugged is False
    assert not line._accept.alive
    with socket.socket() as probe:
        assert probe.connect_ex(("127.0.0.1", line.port)) != 0  # nobody listens there
    with open_line("pty") as pty:
        path = pty.address
    assert pty._closed and path.startswith("/dev/")


def test_a_client_that_only_polls_does_not_stop_the_clock_that_runs_on():
    """The client that granted time left: the board's clock runs on at real time, and goes
    back to granted time when a client grants again (docs/onboard.md). A client that came on
    the line and only polled (a tool watching the emergency landing) stopped it instead: the
    vehicle stood still in mid-air, its serial timeout's procedure frozen, for as long as that
    client stayed."""
    with board_line() as (board, client):
        client.exchange(encode(Clock(0)))
        client.sock.close()
        deadline = time.monotonic() + 30.0  # a stuck guard: the line notices within a read
        while not board.free_running:
            assert time.monotonic() < deadline, "the board never noticed the client left"
            time.sleep(0.05)
        watcher = LineClient(int(board.line.address.rsplit(":", 1)[1]))
        try:
            watcher.sock.settimeout(30.0)  # the board answers a poll at once
            watcher.exchange(b"")  # on the line, polling
            start_s = board.sim_time()
            deadline = time.monotonic() + 30.0  # a stuck guard: it runs on at real time
            while board.sim_time() < start_s + 0.5:
                assert time.monotonic() < deadline, "the clock stopped for a client that polls"
                watcher.exchange(b"")
                time.sleep(0.05)
            assert board.free_running
            # A grant takes the clock back.
            results, _ = watcher.exchange(encode(Clock(0)))
            now_ms = round(sim_time(results[0]) * 1000)
            results, _ = watcher.exchange(encode(Clock(now_ms + 5000)))
            answer = results[0] if results else watcher.next_clock_result()
            assert answer.code is ResultCode.OK and not board.free_running
            board.check()
        finally:
            watcher.sock.close()


def test_a_board_worker_that_dies_is_told_to_its_owner(monkeypatch):
    """A worker of the board that died on an exception (a bug) was logged with its traceback
    and nothing more: ``skeye sim`` served on with a board that answered no one, a bench that
    looked alive. Its owner is told at once (``on_error``); ``skeye sim`` then stops, naming
    the board, with status 3."""
    failed: list[BaseException] = []
    told = threading.Event()
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=6, estimator="truth"))
        board = start_ll_board(stack, parse_ll_board("R1=tcp:0"), f"127.0.0.1:{server.port}",
                               on_error=lambda exc: (failed.append(exc), told.set()))

        def broken(timeout_s: float) -> bytes:
            raise RuntimeError("a bug under the board's reader")

        monkeypatch.setattr(board.line, "recv", broken)
        assert told.wait(30.0), "the owner was not told"  # a stuck guard: it reads every 0.1 s
        assert isinstance(failed[0], RuntimeError) and "a bug under" in str(failed[0])
        with pytest.raises(WorkerFailed, match="ll-read-R1 failed"):
            board.check()
