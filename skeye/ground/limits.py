"""Ground control's server limits: uvicorn's own settings, a header timeout and a per-peer
connection cap on its h11 protocol, and a log that says a repeated error once.

How this works: :func:`server_config` is the one ``uvicorn.Config`` every ground server runs
with (``skeye ground``, the tests). uvicorn gives the keep-alive timeout
(``timeout_keep_alive``), the concurrency limit (``limit_concurrency``: beyond it a request is
answered 503), the backlog, the largest request head (``h11_max_incomplete_event_size``) and
its ``http`` setting, the protocol class, here :class:`LimitedH11Protocol`, uvicorn's own h11
protocol with two additions uvicorn lacks:

- **a header timeout**: a connection must complete its request head within
  ``header_timeout_s`` of connecting (and of its previous response, on keep-alive); else it is
  answered 408 and closed (closed without a word when it sent nothing at all: a browser's spare
  connection, which a stray 408 could be mistaken on for the answer to its next request). A
  client that trickles one header byte every 2 s holds nothing.
- **a per-peer connection cap**: one peer (:func:`skeye.peers.peer_key`: a local user however
  many loopback addresses it binds, or a remote address) holds at most ``max_per_peer``
  connections (WebSockets included). A new connection beyond it takes the place of that
  peer's oldest connection still waiting for its request head; when none is waiting, the new
  one is answered 503 and closed. No peer can hold the descriptors the others need.

and its ``ws`` setting, :class:`LimitedWebSocketProtocol`, uvicorn's WebSocket protocol (over
``websockets``' sans-IO core) with **a send timeout**: a page that takes no byte of what was
sent to it for ``send_timeout_s`` (the send has waited that long for room in the connection's
buffer, which is full: the kernel's, then asyncio's 64 KiB) is cut, its connection aborted (a
close frame could not get through the full buffer, and a plain close would wait for it to
drain for ever). The pilot's video port does the same to a viewer after the same 5 s. Until
then a stream only waits: ``/ws/video`` sends the newest frame when the previous one has gone,
so a slow page gets fewer frames, never old ones, and holds one frame of memory.

:class:`RepeatFilter` is a ``logging.Filter`` for the process's handlers: a message (logger,
level, format string) is written at most ``burst`` times per ``window_s``; the rest are counted
and summed up in one line when the window ends ("... N more like this in the last 10 s"), so a
flood of the same error (an attack, a descriptor shortage) never fills the log or the disk.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from skeye.peers import peer_key
from skeye.processes import on_stop_signals

log = logging.getLogger(__name__)

HEADER_TIMEOUT_S = 10.0
"""A request head (line and headers) must be complete this long after connecting, or after the
previous response: Apache's ``mod_reqtimeout`` allows 20 s for the first byte and 500 B/s after;
a browser sends its head in one packet, and 10 s is the other skeye servers' handshake timeout."""
KEEP_ALIVE_S = 5
"""An idle keep-alive connection is closed after this (uvicorn's default, stated)."""
MAX_PER_PEER = 32
"""Connections one peer may hold: a browser opens about 6 per host plus 2 WebSockets per tab."""
CONCURRENCY = 256
"""Connections and requests at once before uvicorn answers 503."""
SEND_TIMEOUT_S = 5.0
"""A WebSocket page that takes no byte of what is sent to it this long is cut (the pilot's
video port's ``SEND_TIMEOUT_S`` for its viewers)."""
MAX_HEAD_BYTES = 16 * 1024
"""The largest request head (request line and headers) h11 reads before refusing it."""

_TIMEOUT_408 = (b"HTTP/1.1 408 Request Timeout\r\ncontent-type: text/plain; charset=utf-8\r\n"
                b"connection: close\r\ncontent-length: 42\r\n\r\n"
                b"request head not complete within the limit")


def _busy_503(key: str, limit: int) -> bytes:
    body = f"too many connections from {key} (at most {limit} per user or address)".encode()
    return (b"HTTP/1.1 503 Service Unavailable\r\ncontent-type: text/plain; charset=utf-8\r\n"
            b"connection: close\r\nretry-after: 1\r\ncontent-length: "
            + str(len(body)).encode() + b"\r\n\r\n" + body)


@dataclass
class ConnectionLimits:
    """The header timeout and per-peer cap of one server, and its open connections by peer."""

    header_timeout_s: float = HEADER_TIMEOUT_S
    max_per_peer: int = MAX_PER_PEER
    send_timeout_s: float = SEND_TIMEOUT_S
    by_peer: dict[str, list[LimitedH11Protocol]] = field(default_factory=dict)
    timed_out: int = 0  # connections closed for an incomplete request head
    replaced: int = 0  # waiting connections closed for a newer one of the same peer
    refused: int = 0  # connections refused: their peer's connections were all busy
    slow_cut: int = 0  # WebSockets cut: their page took nothing for send_timeout_s

    def admit(self, proto: LimitedH11Protocol) -> bool:
        """Count a new connection under its peer; False when it must be refused."""
        mine = [p for p in self.by_peer.get(proto.peer, []) if not p.transport.is_closing()]
        if len(mine) >= self.max_per_peer:
            waiting = [p for p in mine if p.awaiting_head]
            if not waiting:
                self.by_peer[proto.peer] = mine
                self.refused += 1
                return False
            oldest = min(waiting, key=lambda p: p.connected_s)
            self.replaced += 1
            oldest.transport.close()
            mine.remove(oldest)
        mine.append(proto)
        self.by_peer[proto.peer] = mine
        return True

    def forget(self, proto: LimitedH11Protocol) -> None:
        mine = self.by_peer.get(proto.peer)
        if mine is None:
            return
        if proto in mine:
            mine.remove(proto)
        if not mine:
            del self.by_peer[proto.peer]


class LimitedConfig(uvicorn.Config):
    """``uvicorn.Config`` carrying the server's :class:`ConnectionLimits`."""

    def __init__(self, app: Any, *, limits: ConnectionLimits, **kwargs: Any) -> None:
        super().__init__(app, **kwargs)
        self.connection_limits = limits


class LimitedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with a header timeout and a per-peer cap (see the module)."""

    def __init__(self, config: uvicorn.Config, *args: Any, **kwargs: Any) -> None:
        super().__init__(config, *args, **kwargs)
        limits = getattr(config, "connection_limits", None)
        self.limits: ConnectionLimits = limits if limits is not None else ConnectionLimits()
        self.peer = ""
        self.connected_s = 0.0
        self.awaiting_head = True
        self._head_bytes = False  # a byte of the awaited head has come
        self._head_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self.connected_s = time.monotonic()
        peer = transport.get_extra_info("peername")
        ours = transport.get_extra_info("sockname")
        if isinstance(peer, tuple) and isinstance(ours, tuple):
            self.peer = peer_key((str(peer[0]), int(peer[1])), (str(ours[0]), int(ours[1])))
        if not self.limits.admit(self):
            log.warning("refusing a connection of %s: %d connections already, none waiting",
                        self.peer, self.limits.max_per_peer)
            transport.write(_busy_503(self.peer, self.limits.max_per_peer))
            transport.close()
            return
        self._arm()

    def _arm(self) -> None:
        self.awaiting_head = True
        self._head_bytes = False
        if self._head_timer is not None:
            self._head_timer.cancel()
        self._head_timer = self.loop.call_later(self.limits.header_timeout_s, self._head_late)

    def _head_late(self) -> None:
        self._head_timer = None
        if self.awaiting_head and not self.transport.is_closing():
            self.limits.timed_out += 1
            log.info("closing a connection of %s: no complete request head within %g s",
                     self.peer, self.limits.header_timeout_s)
            if self._head_bytes:
                self.transport.write(_TIMEOUT_408)
            self.transport.close()

    def data_received(self, data: bytes) -> None:
        self._head_bytes = True
        cycle = self.cycle
        super().data_received(data)
        # The head is in when it started a new request cycle (or a WebSocket took the
        # connection over): the request is the app's now.
        if self.awaiting_head and (self.cycle is not cycle
                                   or self.transport.get_protocol() is not self):
            self.awaiting_head = False
            if self._head_timer is not None:
                self._head_timer.cancel()
                self._head_timer = None

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._arm()  # keep-alive: the next head gets the same time

    def connection_lost(self, exc: Exception | None) -> None:
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None
        self.limits.forget(self)
        super().connection_lost(exc)


class LimitedWebSocketProtocol(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol with a send timeout (see the module).

    It keeps its own flow control: ``writable`` follows the transport's buffer (cleared over
    its high-water mark, set below its low one) and is set when the connection is lost, so a
    waiting send ends; some uvicorn releases' sans-IO protocol did neither (it never paused,
    and buffered a page that never reads without bound).
    """

    def __init__(self, config: uvicorn.Config, *args: Any, **kwargs: Any) -> None:
        super().__init__(config, *args, **kwargs)
        limits = getattr(config, "connection_limits", None)
        self.limits: ConnectionLimits = limits if limits is not None else ConnectionLimits()

    def pause_writing(self) -> None:
        self.writable.clear()

    def resume_writing(self) -> None:
        self.writable.set()

    def connection_lost(self, exc: Exception | None) -> None:
        super().connection_lost(exc)
        self.writable.set()

    async def send(self, message: Any) -> None:
        if not self.writable.is_set():  # the buffer is full: the page has not taken it yet
            try:
                await asyncio.wait_for(self.writable.wait(), self.limits.send_timeout_s)
            except TimeoutError:
                # Also when the transport is already closing (the server shutting down, a
                # close frame sent): close() waits for the full buffer to drain, for ever.
                self.limits.slow_cut += 1
                log.info("cutting a WebSocket of %s: it took nothing of what was sent to "
                         "it for %g s", self.client, self.limits.send_timeout_s)
                self.transport.abort()  # the send below ends as a disconnect
        await super().send(message)


def server_config(app: Any, log_level: str = "warning", *,
                  limits: ConnectionLimits | None = None, **settings: Any) -> LimitedConfig:
    """The uvicorn settings of a ground server, with its connection limits (see the module);
    ``settings`` are more ``uvicorn.Config`` arguments."""
    return LimitedConfig(
        app,
        limits=limits or ConnectionLimits(),
        log_level=log_level,
        http=LimitedH11Protocol,
        ws=LimitedWebSocketProtocol,
        timeout_keep_alive=KEEP_ALIVE_S,
        limit_concurrency=CONCURRENCY,
        h11_max_incomplete_event_size=MAX_HEAD_BYTES,
        **settings,
    )


class GroundServer(uvicorn.Server):
    """``uvicorn.Server`` stopped by SIGINT and SIGTERM as skeye's other servers are: it shuts
    down, and ``run`` returns.

    uvicorn's own handling raises the signal again once the server has shut down, with the
    handlers it found restored: Ctrl-C then ended ``skeye ground`` with a KeyboardInterrupt
    traceback (status 130), and SIGTERM killed it (143) before it closed its vehicle link and
    video relay or said it stopped. A second Ctrl-C still ends the shutdown at once (uvicorn's
    ``force_exit``).

    ``on_started`` is called once the server listens with these handlers in place (``skeye
    ground`` prints its page's address there): a Ctrl-C at the address it printed always stops
    it in order. Printed before ``run``, a signal that came before the handlers were set ended
    it with a KeyboardInterrupt (status 130) and a coroutine never awaited.
    """

    def __init__(self, config: uvicorn.Config,
                 on_started: Callable[[], None] | None = None) -> None:
        super().__init__(config)
        self.on_started = on_started

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        await super().startup(sockets=sockets)
        if self.on_started is not None and self.started and not self.should_exit:
            self.on_started()

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        if threading.current_thread() is not threading.main_thread():
            yield  # only the main thread may set handlers (a test's server in a thread)
            return
        original = on_stop_signals(self.handle_exit)
        try:
            yield
        finally:
            for sig, handler in original.items():
                signal.signal(sig, handler)


class RepeatFilter(logging.Filter):
    """Let a message through at most ``burst`` times per ``window_s`` (see the module)."""

    def __init__(self, burst: int = 5, window_s: float = 10.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.burst = burst
        self.window_s = window_s
        self._clock = clock
        self._seen: dict[tuple[str, int, str], tuple[float, int]] = {}  # start, count

    def filter(self, record: logging.LogRecord) -> bool:
        key = (record.name, record.levelno, str(record.msg))
        now = self._clock()
        start, count = self._seen.get(key, (now, 0))
        if now - start >= self.window_s:
            if count > self.burst:
                record.msg = (f"{record.msg} [and {count - self.burst} more like this in the "
                              f"last {self.window_s:g} s]")
            start, count = now, 0
        count += 1
        self._seen[key] = (start, count)
        if len(self._seen) > 4096:  # forget the oldest kinds: memory stays bounded
            for stale in list(self._seen)[:1024]:
                del self._seen[stale]
        return count <= self.burst


def limit_repeats(burst: int = 5, window_s: float = 10.0) -> RepeatFilter:
    """Install a :class:`RepeatFilter` on every handler there is now (the root logger's and
    those uvicorn configured for its own loggers); returns it."""
    repeat = RepeatFilter(burst, window_s)
    loggers = [logging.getLogger()] + [
        lg for lg in logging.root.manager.loggerDict.values() if isinstance(lg, logging.Logger)
    ]
    for logger in loggers:
        for handler in logger.handlers:
            if repeat not in handler.filters:
                handler.addFilter(repeat)
    return repeat
