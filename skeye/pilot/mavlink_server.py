"""The pilot's MAVLink endpoint: the vehicle served as a MAVLink 2 autopilot on one or more links.

How this works: :class:`MavlinkServer` opens each link URI (``skeye.mavlink.transport``: UDP
listening or sending, TCP, serial) and runs one worker thread (``pilot-mavlink``) that alone owns
every link's socket: it waits on all of them with a selector (at most ``tick_s``), parses each
peer's bytes with its own pymavlink parser (``skeye.mavlink.codec``), hands each message to the
sans-IO :class:`~skeye.pilot.mavlink_vehicle.MavlinkVehicle` under the boards' lock (the lock the
AscTec link and the control loop take), and sends what comes back; every ``tick_s`` it ticks the
vehicle (streams, programs, timers). A send never blocks: a full socket buffer drops telemetry.
Bad input never stops the thread (the vehicle answers it); an exception the thread cannot
handle reaches the owner through :meth:`check` (``WorkerFailed``). ``close`` is idempotent and
joins the thread with a deadline.
"""

from __future__ import annotations

import logging
import selectors
import threading
import time
from collections.abc import Callable, Hashable
from types import TracebackType

from skeye.errors import LinkClosed
from skeye.mavlink.codec import MavParser
from skeye.mavlink.transport import MavTransport, open_transport
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.mavlink_vehicle import MavlinkVehicle, Out, Settings
from skeye.workers import Worker

log = logging.getLogger(__name__)

DEFAULT_TICK_S = 0.01
MAX_PARSERS = 64  # peers remembered per link (parsers of vanished TCP clients are dropped)


class MavlinkServer:
    """Serve ``boards`` as a MAVLink vehicle on every link in ``uris``."""

    def __init__(
        self,
        boards: OnboardBoards,
        lock: threading.Lock | threading.RLock,
        uris: list[str],
        *,
        settings: Settings | None = None,
        tick_s: float = DEFAULT_TICK_S,
        clock: Callable[[], float] = time.monotonic,
        wall_clock: Callable[[], float] = time.time,
        system_id: int = 1,
    ) -> None:
        self.lock = lock
        self.clock = clock
        self.tick_s = tick_s
        with lock:
            self.vehicle = MavlinkVehicle(boards, settings=settings, now_s=clock(),
                                          wall_clock=wall_clock, system_id=system_id)
        self.transports: list[MavTransport] = []
        self._worker: Worker | None = None  # before the links: close() below needs them
        self._stop = threading.Event()
        try:
            for uri in uris:
                self.transports.append(open_transport(uri))
                with lock:
                    self.vehicle.add_link(clock())
        except BaseException:
            self.close()
            raise
        boards.pad.add_listener(self.vehicle.on_pad)
        self._parsers: list[dict[Hashable, MavParser]] = [{} for _ in self.transports]
        self._selector = selectors.DefaultSelector()
        self.sent = 0
        self.received = 0
        self.errors = 0  # messages whose handling raised (logged; a bug, never a crash)

    @property
    def addresses(self) -> list[str]:
        """Each link's URI as opened (with the port a ``:0`` became)."""
        return [t.name for t in self.transports]

    def start(self) -> MavlinkServer:
        if self._worker is None:
            self._worker = Worker(self._run, "pilot-mavlink").start()
        return self

    def check(self) -> None:
        """Raise ``WorkerFailed`` if the thread died."""
        if self._worker is not None:
            self._worker.check()

    def close(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        if self._worker is not None:
            self._worker.join(timeout_s)
        for t in self.transports:
            t.close()

    def __enter__(self) -> MavlinkServer:
        return self.start()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- the thread ----------------------------------------------------------------------
    def _register(self) -> None:
        registered = {key.fileobj for key in self._selector.get_map().values()}
        wanted = {}
        for i, t in enumerate(self.transports):
            for f in t.fileobjs():
                wanted[f] = i
        for f in registered - set(wanted):
            self._selector.unregister(f)
        for f, i in wanted.items():
            if f not in registered:
                self._selector.register(f, selectors.EVENT_READ, i)

    def _run(self) -> None:
        next_tick = self.clock()
        try:
            while not self._stop.is_set():
                self._register()
                timeout = max(0.0, next_tick - self.clock())
                ready = {key.data for key, _ in self._selector.select(timeout)}
                for i in sorted(ready):
                    self._read(i)
                if self.clock() >= next_tick:
                    next_tick = max(next_tick + self.tick_s, self.clock())
                    with self.lock:
                        out = self.vehicle.tick(self.clock())
                    self._send(out, None, None)
        finally:
            self._selector.close()

    def _read(self, i: int) -> None:
        transport = self.transports[i]
        try:
            chunks = transport.poll()
        except LinkClosed as exc:
            log.warning("MAVLink link %s: %s", transport.name, exc)
            return
        parsers = self._parsers[i]
        for data, peer in chunks:
            parser = parsers.get(peer)
            if parser is None:
                if len(parsers) >= MAX_PARSERS:
                    live = set(transport.peers)
                    for gone in [p for p in parsers if p not in live]:
                        del parsers[gone]
                parser = parsers[peer] = MavParser()
            for msg in parser.feed(data, datagram=transport.datagram):
                self.received += 1
                try:
                    with self.lock:
                        out = self.vehicle.handle(i, peer, msg, self.clock())
                except Exception:  # a bug on one message must not stop the vehicle's link
                    self.errors += 1
                    log.exception("MAVLink message %s from %s not handled",
                                  getattr(msg, "get_type", lambda: "?")(), peer)
                    continue
                self._send(out, i, peer)

    def _send(self, out: list[Out], link: int | None, peer: Hashable | None) -> None:
        for item in out:
            try:
                data = self.vehicle.codec.encode(item.msg)
            except Exception as exc:  # a value pymavlink cannot pack: a bug, logged
                log.error("MAVLink message %s not sent: %s", item.msg.get_type(), exc)
                continue
            links = range(len(self.transports)) if item.link is None else [item.link]
            for i in links:
                target = item.peer if item.link is not None else None
                try:
                    self.transports[i].send(data, target)
                    self.sent += 1
                except LinkClosed as exc:
                    log.warning("MAVLink link %s: %s", self.transports[i].name, exc)
