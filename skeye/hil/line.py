"""The emulated LL board's end of its serial line: a pseudo-terminal, a TCP port or a real port.

How this works: :class:`BoardLine` is what the board's server reads and writes, whatever the
line is made of. ``recv`` returns the bytes that arrived (``b""`` when none did, or when no
client is on the line), ``send`` writes a reply or drops it when nobody is there to read it, or
the client takes none of it for 1 s (a serial line with nothing plugged in loses its bytes; the
board never blocks on its line for longer).
``plugged`` says whether a client is known to be on it: True or False for a pseudo-terminal
(the kernel tells when the last client closed its end: reading the master gives ``EIO``) and
a TCP port (a client connected or not), None for a real serial port (a line cannot tell).

- ``pty``: a new pseudo-terminal; clients open :attr:`BoardLine.path` (``/dev/pts/N``) as the
  serial device they would open on the vehicle. Raw mode (no echo, no line editing).
- ``tcp``: a port on ``host``; one client at a time, a new connection replaces the previous one
  (a line that was unplugged and plugged in again).
- ``serial``: a real serial device (a USB adapter wired to an onboard computer), through
  pyserial at ``baud``.

``unplug()`` cuts the line as a pulled cable would (tests, and ``skeye sim``'s shutdown). A line
is a context manager: ``with`` closes it (a TCP line's listener and accept thread too).
"""

from __future__ import annotations

import errno
import logging
import os
import select
import threading
import time
import tty
from typing import Self

from skeye.errors import LinkClosed, LinkTimeout, LocalProtocolError
from skeye.link.transport import Link, SerialLink, TcpLink, tcp_uri
from skeye.peers import accept_failed, listen
from skeye.workers import Worker

log = logging.getLogger(__name__)

RECV_CHUNK = 4096


class BoardLine:
    """The board's end of the line (see the module docstring)."""

    kind = "line"

    def __init__(self) -> None:
        self.dropped_bytes = 0  # replies written while nobody was on the line
        self.ever_plugged = False
        self.client_number = 0  # clients that have come on the line: the current one's number
        self.received_from = 0  # the number of the client the last recv() read from
        self._unplugged = threading.Event()

    @property
    def plugged(self) -> bool | None:
        raise NotImplementedError

    @property
    def address(self) -> str:
        """Where a client finds the line (a device path, or host:port)."""
        raise NotImplementedError

    def client_uri(self) -> str:
        """The pilot's ``--airframe`` for this line (without options)."""
        raise NotImplementedError

    def recv(self, timeout_s: float) -> bytes:
        raise NotImplementedError

    def send(self, data: bytes) -> None:
        raise NotImplementedError

    def unplug(self) -> None:
        """Cut the line: nothing more is read or written (idempotent)."""
        self._unplugged.set()
        self.close()

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class PtyLine(BoardLine):
    """A pseudo-terminal: the board holds the master, a client opens the slave's path."""

    kind = "pty"

    def __init__(self) -> None:
        super().__init__()
        master, slave = os.openpty()
        tty.setraw(slave)
        self._path = os.ttyname(slave)
        # Our copy of the slave is closed: the master then reads EIO whenever no client has
        # the device open, which is how a hang-up shows.
        os.close(slave)
        os.set_blocking(master, False)
        self._master = master
        self._plugged = False
        self._lock = threading.Lock()
        self._closed = False

    @property
    def address(self) -> str:
        return self._path

    @property
    def plugged(self) -> bool | None:
        return self._plugged

    def client_uri(self) -> str:
        return f"asctec-ll://serial{self._path}"

    def recv(self, timeout_s: float) -> bytes:
        if self._closed:
            raise LinkClosed(f"{self._path}: the line is closed")
        try:
            ready, _, _ = select.select([self._master], [], [], timeout_s)
            if not ready:
                return b""
            data = os.read(self._master, RECV_CHUNK)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if self._closed:
                raise LinkClosed(f"{self._path}: the line is closed") from None
            if exc.errno == errno.EIO:  # nobody has the device open
                if self._plugged:
                    log.warning("LL board line %s: the client closed the device", self._path)
                self._plugged = False
                time.sleep(min(timeout_s, 0.05))  # EIO keeps the master readable: do not spin
                return b""
            raise LinkClosed(f"{self._path}: {exc}") from None
        if data and not self._plugged:
            with self._lock:  # not after close() (an unplug racing this read): it stays out
                if not self._closed:
                    self._plugged = True
                    self.ever_plugged = True
                    self.client_number += 1
        self.received_from = self.client_number  # (this thread alone changes it)
        return data

    def send(self, data: bytes) -> None:
        with self._lock:
            if self._closed or not self._plugged:
                self.dropped_bytes += len(data)
                return
            view = memoryview(data)
            deadline = time.monotonic() + 1.0
            while view:
                try:
                    n = os.write(self._master, view)
                    view = view[n:]
                except BlockingIOError:  # the client reads nothing: wait a little, then drop
                    if time.monotonic() > deadline:
                        self.dropped_bytes += len(view)
                        return
                    select.select([], [self._master], [], 0.05)
                except OSError:
                    self.dropped_bytes += len(view)
                    return

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._plugged = False
            os.close(self._master)


class TcpLine(BoardLine):
    """A TCP port: the newest connection is the line's client."""

    kind = "tcp"

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        super().__init__()
        self._listener = listen(host, port)
        self._listener.settimeout(0.2)
        self.host = host
        self.port = self._listener.getsockname()[1]
        self._client: TcpLink | None = None
        self._lock = threading.Lock()
        self._closed = False
        self._accept = Worker(self._accept_loop, f"ll-line-accept-{self.port}").start()

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def plugged(self) -> bool | None:
        client = self._client
        return client is not None and not client.closed

    def client_uri(self) -> str:
        return f"asctec-ll://tcp/{tcp_uri(self.host, self.port)[len('tcp://'):]}"

    def _accept_loop(self) -> None:
        said_s = 0.0
        while not self._closed:
            try:
                sock, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError as exc:  # out of descriptors: said and waited out; else closed
                when = accept_failed(exc, said_s, f"LL board line {self.address}")
                if when is None:
                    return
                said_s = when
                continue
            link = TcpLink(sock, send_timeout_s=1.0)
            with self._lock:
                old, self._client = self._client, link
                self.ever_plugged = True
                self.client_number += 1
            if old is not None:
                log.info("LL board line %s: %s replaces %s", self.address, link.name, old.name)
                old.close()

    def recv(self, timeout_s: float) -> bytes:
        if self._closed:
            raise LinkClosed(f"{self.address}: the line is closed")
        with self._lock:  # the client and its number together (a newer one may replace it)
            client, number = self._client, self.client_number
        if client is None or client.closed:
            time.sleep(min(timeout_s, 0.05))
            return b""
        try:
            data = client.recv(timeout_s)
            self.received_from = number
            return data
        except LinkClosed:
            log.warning("LL board line %s: the client went away", self.address)
            return b""

    def send(self, data: bytes) -> None:
        client = self._client
        if client is None or client.closed:
            self.dropped_bytes += len(data)
            return
        try:
            client.send(data)
        except (LinkClosed, LinkTimeout):  # gone, or it reads nothing: the reply is lost
            self.dropped_bytes += len(data)

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            client = self._client
        self._listener.close()
        if client is not None:
            client.close()
        self._accept.join(1.0)


class SerialLine(BoardLine):
    """A real serial port (a line cannot tell whether anything is plugged in)."""

    kind = "serial"

    def __init__(self, device: str, baud: int) -> None:
        super().__init__()
        self._link: Link = SerialLink(device, baud)
        self.device = device
        self.baud = baud

    @property
    def address(self) -> str:
        return self.device

    @property
    def plugged(self) -> bool | None:
        return None

    def client_uri(self) -> str:
        return f"asctec-ll://serial{self.device}?baud={self.baud}"

    def recv(self, timeout_s: float) -> bytes:
        return self._link.recv(timeout_s)

    def send(self, data: bytes) -> None:
        try:
            self._link.send(data)
        except LinkClosed:
            self.dropped_bytes += len(data)

    def close(self) -> None:
        self._link.close()


def open_line(kind: str, *, host: str = "127.0.0.1", port: int = 0, device: str = "",
              baud: int = 57600) -> BoardLine:
    """A board line of ``kind`` pty, tcp or serial.

    Raises:
        LocalProtocolError: an unknown kind.
        LinkClosed: a serial device that cannot be opened.
        OSError: a TCP port that cannot be bound.
    """
    if kind == "pty":
        return PtyLine()
    if kind == "tcp":
        return TcpLine(host, port)
    if kind == "serial":
        return SerialLine(device, baud)
    raise LocalProtocolError(f"LL board line must be pty, tcp or serial, got {kind!r}")
