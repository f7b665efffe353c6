"""A simulated robot served as an AscTec LL board on a line: the board's I/O and its clock.

How this works: :class:`LLBoardServer` owns a :class:`~skeye.hil.line.BoardLine` and an
:class:`~skeye.hil.ll_board.LLBoard` over the robot's ``SimAirframe`` (a ``skeye.control``
client of the simulator). Two workers:

- ``ll-read-NAME`` alone reads the line, feeds a ``CommandStreamParser`` and writes each
  answer at once (a poll's answer never waits for the clock). A CLOCK is queued for the clock
  worker. A new client's bytes start afresh: a frame the previous one left unfinished is
  dropped (counted as garbage), not completed with the newcomer's packets.
- ``ll-clock-NAME`` ticks the board. In realtime it does so every ``tick_s`` of wall time. In
  lockstep the simulator's time moves only as the client on the line grants it: CLOCK
  ``until`` (ms of sim time) advances the simulator to it, in steps of one control period,
  ticking the board after each, and is then answered RESULT code 0 with the sim time reached
  in its reason (``sim time 12.350000 s``); a grant already passed is answered at once, so a
  client learns the time by granting 0, and the same grant sent again before it is reached is
  answered at once with the time so far (the board is alive, only busy). Grants not yet
  reached are held in :class:`Grants` (a heap: each grant costs O(log n), so a client flooding
  the line with them does not slow the board's answers), at most ``MAX_GRANTS``; one beyond
  is refused RESULT code 5 (BUSY) naming the limit. If the client leaves the line (a
  pseudo-terminal closed, a TCP connection gone or replaced by a newer one) its grants not yet
  reached are dropped (stepping on to them would race sim time ahead for no one, or answer a
  new client grants it never sent); with no client left the board's clock runs on by itself at
  real time: a vehicle does not freeze because its onboard computer went away, and the serial
  timeout's emergency procedure plays out. It goes back to granted time when a client grants
  again. Before any client has been on the line, lockstep time does not move.
  With ``rate`` (for AscTec programs, which grant no time) the board drives the lockstep clock
  itself at that pace.

A line that fails (a serial device gone) is logged as an error and kept in ``line_failed``;
the board hears nothing more, so its serial timeout's procedure plays out.

The board's time is the simulator's. A simulator that goes away (the control connection
failed) is logged and the server stops answering; ``error`` says why.
"""

from __future__ import annotations

import heapq
import logging
import math
import threading
import time
from collections.abc import Callable

from skeye.errors import SkeyeError
from skeye.hil.line import BoardLine
from skeye.hil.ll_board import LLBoard, LLSettings
from skeye.pilot.airframe import Airframe
from skeye.pilot.asctec_ll import CLOCK_TIMEOUT_S, RATE_HZ_MAX
from skeye.wire.packets import (
    PD,
    Clock,
    CommandStreamParser,
    Message,
    Result,
    ResultCode,
    encode,
)
from skeye.workers import Worker

log = logging.getLogger(__name__)

REALTIME_TICK_S = 0.01
REPORT_EVERY_S = 5.0  # garbage on the line is logged at most this often
GRANT_WAIT_S = 0.1  # lockstep: the clock waits this long at most for a grant, then looks again
MAX_GRANTS = math.ceil(RATE_HZ_MAX * CLOCK_TIMEOUT_S)
"""CLOCK grants not yet reached that a client may hold (12 000): one per control cycle at the
fastest cycle ``asctec-ll://`` allows (200 Hz) for as long as a client waits for a grant (60 s).
The pilot holds one at a time (it waits for each answer)."""


class Grants:
    """The CLOCK grants not yet reached (s of sim time), sans-IO: a min-heap gives the next
    one due and a set tells a grant sent again, each in O(log n); ``latest`` is the highest
    (the clock's target). Grants leave from the low end only, so ``latest`` is kept until the
    last one is reached."""

    def __init__(self, limit: int = MAX_GRANTS) -> None:
        self.limit = limit
        self.latest: float | None = None
        self._heap: list[float] = []
        self._held: set[float] = set()

    def __len__(self) -> int:
        return len(self._heap)

    def __contains__(self, until_s: float) -> bool:
        return until_s in self._held

    @property
    def full(self) -> bool:
        return len(self._heap) >= self.limit

    def add(self, until_s: float) -> None:
        """Hold a new grant (the caller checked it is neither held nor beyond the limit)."""
        heapq.heappush(self._heap, until_s)
        self._held.add(until_s)
        if self.latest is None or until_s > self.latest:
            self.latest = until_s

    def reached(self, now_s: float) -> int:
        """Drop every grant at or before ``now_s``; how many."""
        count = 0
        while self._heap and self._heap[0] <= now_s:
            self._held.discard(heapq.heappop(self._heap))
            count += 1
        if not self._heap:
            self.latest = None
        return count

    def clear(self) -> int:
        """Drop every grant (their client left: no one to answer); how many."""
        count = len(self._heap)
        self._heap.clear()
        self._held.clear()
        self.latest = None
        return count


class LLBoardServer:
    """Serve ``airframe`` as an AscTec LL board on ``line`` (a context manager).

    Args:
        airframe: the simulated robot (``SimAirframe``: ``advance`` steps a lockstep simulator).
        line: the board's end of the serial line.
        sim_time: the simulator's current time (s).
        name: the robot's name (thread names, log lines).
        lockstep: the simulator is in lockstep: time moves by the client's CLOCK grants.
        tick_s: the board's tick (lockstep: the step a grant is advanced by; the robot's
            control period).
        time_step_s: the simulator's physics step (a grant is reached to within half of one).
        rate: lockstep, for clients that grant no time (any AscTec program): the board drives
            the clock itself, ``rate`` sim seconds per wall second.
        settings: the board's own figures (serial timeout, the emergency wait, stick scales).
    """

    def __init__(
        self,
        airframe: Airframe,
        line: BoardLine,
        sim_time: Callable[[], float],
        *,
        name: str = "R1",
        lockstep: bool = False,
        tick_s: float = 0.05,
        time_step_s: float = 0.001,
        settings: LLSettings | None = None,
        rate: float | None = None,
        on_error: Callable[[BaseException], None] | None = None,
    ) -> None:
        self.airframe = airframe
        self.line = line
        self.sim_time = sim_time
        self.name = name
        self.lockstep = lockstep
        self.tick_s = tick_s
        self.time_step_s = time_step_s
        self.rate = rate
        self.board = LLBoard(airframe, settings, now_s=sim_time())
        self.parser = CommandStreamParser()
        self.error: str | None = None
        self.line_failed: str | None = None  # why the line stopped reading (a device gone)
        self.free_running = False
        self.camera: tuple[str, float] | None = None  # the robot's camera: name, FOV (rad)
        self._lock = threading.Lock()  # every call into the board
        self.grants = Grants()
        self._grants_client = 0  # the line's client_number whose grants are held
        self._granted = threading.Condition()
        self._stop = threading.Event()
        self._workers: list[Worker] = []
        self._on_error = on_error  # a worker died (a bug): told at once, on its thread
        self._reported: tuple[int, int] = (0, 0)
        self._reported_at = -REPORT_EVERY_S

    # -- lifecycle -----------------------------------------------------------------------
    def start(self) -> LLBoardServer:
        self._workers = [
            Worker(self._read_loop, f"ll-read-{self.name}", on_error=self._on_error).start(),
            Worker(self._clock_loop, f"ll-clock-{self.name}", on_error=self._on_error).start(),
        ]
        return self

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop both workers and close the line (idempotent)."""
        self._stop.set()
        with self._granted:
            self._granted.notify_all()
        self.line.close()
        for w in self._workers:
            w.join(timeout_s)

    def __enter__(self) -> LLBoardServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def check(self) -> None:
        """Raise ``WorkerFailed`` if a worker died on an exception (a bug)."""
        for w in self._workers:
            w.check()

    # -- the line ------------------------------------------------------------------------
    def _read_loop(self) -> None:
        reading_from = 0  # the line's client whose bytes the parser holds
        while not self._stop.is_set():
            try:
                data = self.line.recv(0.1)
            except SkeyeError as exc:
                if not self._stop.is_set():  # not our close(): the line failed
                    self.line_failed = str(exc)
                    log.error("LL board %s: its line %s failed (%s): the board hears nothing "
                              "more; its serial timeout's procedure follows", self.name,
                              self.line.address, exc)
                return
            if not data or self.error is not None:
                continue
            if self.line.received_from != reading_from:
                # A new client: a frame the previous one left unfinished has no rest to come,
                # and the newcomer's bytes must not be read as that rest.
                reading_from = self.line.received_from
                if self.parser.buffered:
                    log.info("LL board %s: %d bytes of a frame the previous client left "
                             "unfinished are dropped", self.name, self.parser.discard())
            for event in self.parser.feed(data):
                if isinstance(event, Clock):
                    self._grant(event.until / 1000.0, self.line.received_from)
                with self._lock:
                    replies = self.board.handle(event, self.sim_time())
                self._send(replies)
            self._report_line()

    def _report_line(self) -> None:
        """Say (at most every ``REPORT_EVERY_S``) that the line carries garbage."""
        errors = (self.parser.garbage_bytes, sum(self.parser.errors.values()))
        now = time.monotonic()
        if errors != self._reported and now - self._reported_at >= REPORT_EVERY_S:
            log.warning("LL board %s: %d bytes of garbage skipped, %d bad frames on its line so "
                        "far", self.name, *errors)
            self._reported, self._reported_at = errors, now

    def _send(self, replies: list[Message]) -> None:
        if replies:
            self.line.send(b"".join(encode(m) for m in replies))

    def _grant(self, until_s: float, client: int) -> None:
        """A CLOCK grant read from the line's client number ``client``."""
        now = self.sim_time()
        with self._granted:
            self._drop_stale_grants()
            if client != self.line.client_number:  # read just before a newer client came:
                return  # no one waits for it (an answer would go to the newcomer)
            # Passed: answered at once, never held. Asked again while the simulator steps:
            # say where it is (it is alive).
            at_once = until_s <= now + self.time_step_s / 2 or until_s in self.grants
            refused = not at_once and self.grants.full
            if not at_once and not refused:
                self.grants.add(until_s)
            self._granted.notify_all()
        if at_once:
            self._send([Result(int(PD.CLOCK), ResultCode.OK, f"sim time {now:.6f} s")])
        elif refused:
            self._send([Result(int(PD.CLOCK), ResultCode.BUSY,
                               f"grant of {until_s:.3f} s refused: {self.grants.limit} grants "
                               "not yet reached are held, the most the board keeps; grant "
                               "again once some are answered")])

    def _answer_grants(self) -> None:
        """Answer every grant the sim time has reached."""
        now = self.sim_time()
        with self._granted:
            due = self.grants.reached(now + self.time_step_s / 2)
        if due:
            self._send([Result(int(PD.CLOCK), ResultCode.OK, f"sim time {now:.6f} s")] * due)

    # -- the clock -----------------------------------------------------------------------
    def _tick(self) -> None:
        with self._lock:
            self.board.tick(self.sim_time())

    def _advance(self, seconds: float) -> None:
        self.airframe.advance(seconds)
        lost = getattr(self.airframe, "lost", None)
        if lost:
            raise SkeyeError(lost)

    def _client_left(self) -> bool:
        """A client was on the line and is known to have gone (a serial port cannot tell,
        unless the port itself failed)."""
        return ((self.line.plugged is False and self.line.ever_plugged)
                or self.line_failed is not None)

    def _stale(self) -> bool:
        """The grants held are a client's that left or was replaced by another."""
        return self._client_left() or self.line.client_number != self._grants_client

    def _drop_stale_grants(self) -> None:
        """Drop the grants of a client that left or was replaced (with ``_granted`` held):
        no one is waiting for their answers, and stepping on to them would race sim time
        ahead (or answer the new client grants it never sent)."""
        if self._stale() and self.grants:
            dropped = self.grants.clear()
            log.info("LL board %s: the client that granted time left the line: its %d grants "
                     "not yet reached are dropped", self.name, dropped)
        if not self._client_left():
            self._grants_client = self.line.client_number

    def _clock_loop(self) -> None:
        next_s = time.monotonic()
        while not self._stop.is_set() and self.error is None:
            try:
                if not self.lockstep:
                    self._tick()
                    self._advance(0.0)  # sends sticks deferred while a motion ran
                    self._answer_grants()
                    next_s += self.tick_s
                    delay = next_s - time.monotonic()
                    if delay < -1.0:
                        next_s = time.monotonic()
                    self._stop.wait(max(0.0, delay))
                    continue
                wait_s = GRANT_WAIT_S
                if self.rate is not None or self.free_running:  # not past the clock's next tick
                    wait_s = min(wait_s, max(0.0, next_s - time.monotonic()))
                with self._granted:
                    self._granted.wait_for(lambda: bool(self.grants) or self._stop.is_set(),
                                           wait_s)
                    self._drop_stale_grants()
                    target = self.grants.latest
                if target is not None:
                    if self.free_running:
                        log.info("LL board %s: a client grants the clock again", self.name)
                        self.free_running = False
                    while not self._stop.is_set() and not self._stale():
                        target = self.grants.latest  # (a new client's, once the old ones go)
                        if target is None:
                            break
                        steps = math.floor((target - self.sim_time()) / self.time_step_s + 0.5)
                        if steps < 1:
                            break
                        self._advance(min(self.tick_s, steps * self.time_step_s))
                        self._tick()
                        self._answer_grants()  # the lower ones, as they are reached
                    self._answer_grants()
                elif self.rate is not None:  # the board's own clock, paced
                    now = time.monotonic()
                    if now < next_s:
                        continue  # not due yet: waited above, where a grant ends the wait
                    if now - next_s > 1.0:
                        next_s = now
                    self._advance(self.tick_s)
                    self._tick()
                    next_s += self.tick_s / self.rate
                elif self.free_running or self._client_left():  # on till a client grants
                    if not self.free_running:
                        log.warning("LL board %s: the client left the line: the board's clock "
                                    "runs on at real time", self.name)
                        self.free_running = True
                        next_s = time.monotonic()
                    self._advance(self.tick_s)
                    self._tick()
                    next_s += self.tick_s
                    self._stop.wait(max(0.0, next_s - time.monotonic()))
            except SkeyeError as exc:
                self.error = f"simulator lost: {exc}"
                log.error("LL board %s: %s; the board stops answering", self.name, self.error)
