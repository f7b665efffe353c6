"""Byte links chosen by URI: TCP, serial, and an in-memory pair for tests.

Every client of skeye takes its byte stream from here: the vehicle link and the pilot
(:mod:`skeye.link.vehicle`, :mod:`skeye.pilot.server`), the simulator connection
(:class:`skeye.control.connection.Connection`) and the image client
(:class:`skeye.control.image_client.ImageClient`).

How this works: a ``Link`` moves raw bytes and knows nothing of the packet protocol (that is
``skeye.wire.packets``, sans-IO). ``open_link(uri)`` picks the adapter:

- ``tcp://host:port``: a TCP client connection (the pilot wraps its accepted sockets the same
  way with ``TcpLink(sock)``);
- ``serial:///dev/ttyUSB0?baud=57600``: a serial port through pyserial, 8N1, no flow control,
  as the XBee radio is wired;
- ``memory_pair()``: two connected in-memory ends, for tests.

Every link has the same three calls: ``send(data)`` writes all of ``data`` (thread-safe: one
lock per link, so two threads never interleave frames), ``recv(timeout_s)`` returns whatever
arrived within the timeout (``b""`` when nothing did), and ``close()`` (idempotent; a ``recv``
blocked in another thread returns promptly with ``LinkClosed``). A peer that goes away makes
``recv`` and ``send`` raise ``LinkClosed`` (``PeerClosed``, a subclass, when it ended the stream
in order). One thread should own ``recv``. Errors are :mod:`skeye.errors` classes only.
"""

from __future__ import annotations

import os
import select
import socket
import termios
import threading
import time
import tty
from abc import ABC, abstractmethod
from collections.abc import Iterator
from contextlib import contextmanager
from types import TracebackType

from skeye.errors import LinkClosed, LinkTimeout, LocalProtocolError, PeerClosed, UnknownHost
from skeye.uris import port_of, query_of, split_uri
from skeye.values import MAX_BAUD, baud_rate

DEFAULT_BAUD = 57600
DEFAULT_CONNECT_TIMEOUT_S = 5.0
DEFAULT_SEND_TIMEOUT_S = 5.0
MAX_SOCKET_TIMEOUT_S = 1e9  # about 32 years; socket.settimeout overflows past about 9.2e9 s
RECV_CHUNK = 65536


class Link(ABC):
    """A bidirectional byte stream; a context manager that closes it."""

    name: str = "link"

    def __init__(self) -> None:
        self._send_lock = threading.Lock()
        self._closed = threading.Event()  # set by close(), or when the peer goes away
        self._released = False  # the socket or port itself closed (once, by close())
        self._release_lock = threading.Lock()

    @property
    def closed(self) -> bool:
        """True once ``close()`` ran or the peer went away."""
        return self._closed.is_set()

    def send(self, data: bytes) -> None:
        """Write all of ``data``; raises ``LinkClosed`` if the link is gone."""
        if self._closed.is_set():
            raise LinkClosed(f"{self.name}: link is closed")
        with self._send_lock:
            self._send(data)

    def recv(self, timeout_s: float) -> bytes:
        """Bytes that arrived within ``timeout_s`` (``b""`` if none); ``LinkClosed`` at the end."""
        if self._closed.is_set():
            raise LinkClosed(f"{self.name}: link is closed")
        return self._recv(max(0.0, timeout_s))

    def close(self) -> None:
        """Close the link and free its socket or port (idempotent). A link whose peer went away
        is already ``closed`` to its users, but its descriptor is freed only here."""
        self._closed.set()
        with self._release_lock:
            if self._released:
                return
            self._released = True
        self._close()

    def finish_sending(self) -> None:
        """Tell the peer that nothing more comes, and go on reading what it still sends
        (TCP's half-close); a link without one does nothing (its peer learns at close)."""
        return

    def leftover(self, max_bytes: int = RECV_CHUNK) -> bytes:
        """After the link broke (a ``send`` raised ``LinkClosed``): the bytes the peer had
        sent that were not read yet, at most ``max_bytes``, without waiting; ``b""`` if none
        or if the link was closed here. A server that refuses a connection says why and
        closes; a request sent meanwhile fails, and the reason is only in these bytes."""
        return b""

    @abstractmethod
    def _send(self, data: bytes) -> None: ...

    @abstractmethod
    def _recv(self, timeout_s: float) -> bytes: ...

    @abstractmethod
    def _close(self) -> None: ...

    def __enter__(self) -> Link:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name}{' closed' if self.closed else ''}>"


class TcpLink(Link):
    """A connected TCP socket (a client connection, or one the pilot accepted)."""

    def __init__(
        self,
        sock: socket.socket,
        name: str = "",
        send_timeout_s: float | None = DEFAULT_SEND_TIMEOUT_S,
        recv_bytes: int = RECV_CHUNK,
    ) -> None:
        super().__init__()
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        # The timeout bounds sendall() to a dead peer (None: no bound; close() still ends it);
        # recv() waits in select() instead.
        sock.settimeout(send_timeout_s)
        self._sock = sock
        self._recv_bytes = recv_bytes
        try:
            peer = sock.getpeername()
            self.peer = f"{peer[0]}:{peer[1]}"
        except OSError:
            self.peer = "?"
        self.name = name or f"tcp://{self.peer}"

    def _send(self, data: bytes) -> None:
        try:
            self._sock.sendall(data)
        except TimeoutError:
            raise LinkTimeout(f"{self.name}: peer did not take {len(data)} bytes") from None
        except OSError as exc:
            self._closed.set()
            raise LinkClosed(f"{self.name}: {exc}") from None

    def _recv(self, timeout_s: float) -> bytes:
        try:
            ready, _, _ = select.select([self._sock], [], [], timeout_s)
            if not ready:
                return b""
            data = self._sock.recv(self._recv_bytes)
        except (OSError, ValueError) as exc:  # ValueError: fd closed by another thread
            if self._closed.is_set():
                raise LinkClosed(f"{self.name}: link is closed") from None
            self._closed.set()
            raise LinkClosed(f"{self.name}: {exc}") from None
        if not data:
            self._closed.set()
            raise PeerClosed(f"{self.name}: peer closed the connection")
        return data

    def leftover(self, max_bytes: int = RECV_CHUNK) -> bytes:
        data = bytearray()
        with self._release_lock:
            if self._released:
                return b""
            while len(data) < max_bytes:
                try:
                    chunk = self._sock.recv(max_bytes - len(data), socket.MSG_DONTWAIT)
                except OSError:  # nothing more (EAGAIN), or the reset after the bytes
                    break
                if not chunk:
                    break
                data += chunk
        return bytes(data)

    def finish_sending(self) -> None:
        try:
            self._sock.shutdown(socket.SHUT_WR)
        except OSError:
            pass  # already gone: close() and the reader say so

    def _close(self) -> None:
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()


def serial_error(exc: BaseException) -> str:
    """pyserial's error on opening a port, with the reason said when another program holds
    it (pyserial: "Could not exclusively lock port")."""
    if "exclusively lock" in str(exc):
        return f"in use by another program (a skeye pilot or link already has it open): {exc}"
    return str(exc)


class SerialLink(Link):
    """A serial port through pyserial (8N1, no flow control)."""

    def __init__(self, port: str, baud: int = DEFAULT_BAUD) -> None:
        super().__init__()
        import serial  # pyserial; imported here so TCP-only users do not need it

        try:
            # timeout=0: non-blocking reads; recv() waits in select() on the descriptor.
            # exclusive: a second program (another pilot) opening the port is refused, not
            # given a share of the line (an advisory flock, as QGroundControl's serial links).
            self._port = serial.Serial(port, baudrate=baud, timeout=0, write_timeout=10.0,
                                       exclusive=True)
        except (serial.SerialException, ValueError) as exc:
            raise LinkClosed(f"cannot open serial port {port}: {serial_error(exc)}") from None
        self._serial_error: type[Exception] = serial.SerialException
        self.baud = baud
        self.name = f"serial://{port}?baud={baud}"

    def _send(self, data: bytes) -> None:
        try:
            self._port.write(data)
            self._port.flush()
        # termios.error is not an OSError: pyserial's flush (tcdrain) raises it when the line
        # hung up (a pseudo-terminal whose other end closed).
        except (self._serial_error, OSError, TypeError, termios.error) as exc:
            self._closed.set()
            raise LinkClosed(f"{self.name}: {exc}") from None

    def _recv(self, timeout_s: float) -> bytes:
        try:
            ready, _, _ = select.select([self._port.fileno()], [], [], timeout_s)
            if not ready:
                return b""
            data: bytes = self._port.read(max(1, self._port.in_waiting))
        except (self._serial_error, OSError, ValueError, TypeError, termios.error) as exc:
            if self._closed.is_set():
                raise LinkClosed(f"{self.name}: link is closed") from None
            self._closed.set()
            raise LinkClosed(f"{self.name}: {exc}") from None
        if not data:
            # select() said readable but nothing came: the other end of the line hung up.
            self._closed.set()
            raise PeerClosed(f"{self.name}: the line hung up")
        return data

    def _close(self) -> None:
        try:
            self._port.close()
        except (self._serial_error, OSError):
            pass


class MemoryLink(Link):
    """One end of an in-memory pair (see ``memory_pair``)."""

    def __init__(self, name: str) -> None:
        super().__init__()
        self.name = name
        self._inbox = bytearray()
        self._cond = threading.Condition()
        self.peer: MemoryLink | None = None

    def _deliver(self, data: bytes) -> None:
        with self._cond:
            self._inbox += data
            self._cond.notify_all()

    def _send(self, data: bytes) -> None:
        peer = self.peer
        if peer is None or peer.closed:
            self._closed.set()
            raise LinkClosed(f"{self.name}: peer closed")
        peer._deliver(bytes(data))

    def _recv(self, timeout_s: float) -> bytes:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not self._inbox:
                if self._closed.is_set():
                    raise LinkClosed(f"{self.name}: link is closed")
                if self.peer is None or self.peer.closed:
                    raise PeerClosed(f"{self.name}: peer closed")
                left = deadline - time.monotonic()
                if left <= 0:
                    return b""
                self._cond.wait(left)
            data = bytes(self._inbox)
            self._inbox.clear()
            return data

    def _close(self) -> None:
        with self._cond:
            self._cond.notify_all()
        peer = self.peer
        if peer is not None:
            with peer._cond:
                peer._cond.notify_all()


def memory_pair(name: str = "memory") -> tuple[MemoryLink, MemoryLink]:
    """Two connected in-memory links: what one sends, the other receives."""
    a, b = MemoryLink(f"{name}-a"), MemoryLink(f"{name}-b")
    a.peer, b.peer = b, a
    return a, b


def parse_uri(uri: str) -> tuple[str, str, int]:
    """Split a link URI into (scheme, host-or-device, port-or-baud); raises on a bad URI."""
    parts = split_uri(uri, "link URI", "tcp://host:port (an IPv6 address in brackets) or "
                      "serial:///dev/ttyX")
    scheme = parts.scheme.lower()
    if scheme == "tcp":
        port = port_of(parts)
        if not parts.hostname or port is None or port == 0:
            raise LocalProtocolError(f"link URI {uri!r}: expected tcp://host:port (port "
                                     "1..65535)")
        # what a tcp:// link has no use for was dropped without a word (serial:// refuses an
        # unknown option): ?baud=57600 copied from a serial URI, a path, a user name
        extra = [what for what, there in (
            (f"options (?{parts.query})", parts.query or uri.endswith("?")),
            (f"path ({parts.path})", parts.path not in ("", "/")),
            (f"fragment (#{parts.fragment})", parts.fragment or "#" in uri),
            (f"user name ({parts.netloc.rpartition('@')[0]}@)", "@" in parts.netloc)) if there]
        if extra:
            raise LocalProtocolError(f"link URI {uri!r}: a tcp:// link takes no "
                                     f"{' and no '.join(extra)}; expected tcp://host:port")
        return scheme, parts.hostname, port
    if scheme == "serial":
        device = parts.netloc + parts.path
        if not device:
            raise LocalProtocolError(f"link URI {uri!r}: expected serial:///dev/ttyX?baud=57600")
        query = query_of(uri, parts, "link URI")
        unknown = set(query) - {"baud"}
        if unknown:
            raise LocalProtocolError(f"link URI {uri!r}: unknown option(s) {sorted(unknown)}")
        baud_text = query.get("baud", [str(DEFAULT_BAUD)])[-1]
        baud = baud_rate(baud_text)  # the check asctec-ll:// and MAVLink serial links make
        if baud is None:
            raise LocalProtocolError(f"link URI {uri!r}: baud={baud_text} is not a whole number "
                                     f"1..{MAX_BAUD}")
        return scheme, device, baud
    raise LocalProtocolError(f"link URI {uri!r}: scheme must be tcp:// or serial://")


def tcp_uri(host: str, port: int) -> str:
    """The ``tcp://`` URI of a host and port (an IPv6 address in brackets)."""
    return f"tcp://[{host}]:{port}" if ":" in host else f"tcp://{host}:{port}"


def open_link(
    uri: str,
    timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
    *,
    send_timeout_s: float | None = DEFAULT_SEND_TIMEOUT_S,
    recv_bytes: int = RECV_CHUNK,
) -> Link:
    """Open the link a URI names: ``tcp://host:port`` or ``serial:///dev/ttyX?baud=57600``.

    Args:
        uri: where to connect.
        timeout_s: the deadline for connecting.
        send_timeout_s: TCP: how long a send may wait for a peer that reads nothing before it
            raises LinkTimeout (None: as long as it takes; ``close()`` still ends it).
        recv_bytes: TCP: the most bytes one ``recv`` returns.

    Raises:
        LocalProtocolError: a malformed URI.
        LinkTimeout: no connection within ``timeout_s``.
        LinkClosed: the connection was refused, or the port cannot be opened.
    """
    scheme, where, number = parse_uri(uri)
    if scheme == "tcp":
        try:
            # a timeout past what a socket takes (time_t: socket.settimeout raises
            # OverflowError) is no bound at all: connect waits as the kernel lets it
            sock = socket.create_connection(
                (where, number), timeout=timeout_s if timeout_s < MAX_SOCKET_TIMEOUT_S else None)
        except TimeoutError:
            raise LinkTimeout(f"{uri}: no connection within {timeout_s} s") from None
        except socket.gaierror as exc:  # said as "cannot connect: [Errno -2] ...", the
            # simulator's start suggested as if the name were right and nothing listened
            raise UnknownHost(f"{uri}: cannot resolve the host {where!r}: "
                              f"{exc.strerror or exc}") from None
        except OSError as exc:
            raise LinkClosed(f"{uri}: cannot connect: {exc}") from None
        return TcpLink(sock, name=tcp_uri(where, number), send_timeout_s=send_timeout_s,
                       recv_bytes=recv_bytes)
    return SerialLink(where, number)


@contextmanager
def pty_null_modem() -> Iterator[tuple[str, str]]:
    """Two pseudo-terminals wired back to back, like ``socat`` or a null-modem cable.

    Yields two device paths; what is written to one is read from the other. Each side opens
    its path with ``serial:///dev/pts/N`` as it would a real port, so serial links are tested
    without hardware (POSIX only). A bridge thread copies bytes until the context exits.
    """
    m1, s1 = os.openpty()
    m2, s2 = os.openpty()
    for fd in (s1, s2):
        tty.setraw(fd)
    for fd in (m1, m2):  # a side nobody reads fills up: the bridge must still see stop
        os.set_blocking(fd, False)
    stop = threading.Event()

    def put(fd: int, data: bytes) -> None:
        while data and not stop.is_set():
            try:
                data = data[os.write(fd, data):]
            except BlockingIOError:
                select.select([], [fd], [], 0.05)

    def bridge() -> None:
        route = {m1: m2, m2: m1}
        try:
            while not stop.is_set():
                try:
                    ready, _, _ = select.select(list(route), [], [], 0.05)
                    for fd in ready:
                        data = os.read(fd, RECV_CHUNK)
                        if data:
                            put(route[fd], data)
                except BlockingIOError:
                    pass
                except OSError:  # a side was hung up and reopened: keep bridging
                    time.sleep(0.01)
        finally:  # the thread's own descriptors: closed when it no longer uses them, never
            for fd in (m1, s1, m2, s2):  # under it (another socket may take a freed number)
                os.close(fd)

    thread = threading.Thread(target=bridge, name="pty-null-modem", daemon=True)
    thread.start()
    try:
        yield os.ttyname(s1), os.ttyname(s2)
    finally:
        stop.set()
        thread.join(10.0)  # it sees stop within 0.05 s of select
