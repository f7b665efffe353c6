"""Thin byte carriers for MAVLink: UDP (listening or sending), TCP (server or client), serial.

How this works: a :class:`MavTransport` is non-blocking: ``fileobjs()`` are what a selector
waits on, ``poll()`` returns the ``(bytes, peer)`` that arrived, ``send(data, peer)`` writes one
frame to a peer (``None``: to every peer it knows). A peer is whatever identifies the other end
(a UDP address, a TCP connection, the serial line). The URIs (:func:`open_transport`):

- ``udp://HOST:PORT`` (or ``udpin://``): bind HOST:PORT and serve whoever sends to it (each
  sender's address becomes a peer; a vehicle endpoint answers every ground station). UDP has
  no connection to close, so a sender silent for ``PEER_TIMEOUT_S`` is no longer a peer: it
  gets nothing more, and its place goes to the next new sender (every restart of a ground
  station comes from a new source port).
- ``udpout://HOST:PORT``: send to HOST:PORT from a local port on 127.0.0.1 (``?bind=ADDR`` to
  choose), as PX4 SITL sends to QGroundControl's 14550 and MAVSDK's 14540; replies come back
  to that local port.
- ``tcp://HOST:PORT``: listen for TCP clients (server side, as ArduPilot SITL's 5760), at
  most ``TCP_CLIENTS``, one peer (a local user, or a remote address:
  :func:`skeye.peers.peer_key`) all but one of them. A connection at a cap takes the place of
  the connection heard from longest ago of the peer holding too many (its own at its own cap;
  else of the peer holding the most, when that is at least two more than the newcomer's); only
  when every peer holds as many is it closed at once. A connection may send nothing (a script
  that only reads telemetry), so quiet ones are never closed for it: idle connections keep no
  one out, not even their own user.
  ``tcpout://HOST:PORT``: connect to one (client side).
- ``serial:///dev/ttyACM0?baud=921600``: a serial line (pyserial); its one peer is the line.

Nothing here knows MAVLink: framing is the codec's (pymavlink). Servers bind 127.0.0.1 unless
the URI names another address. ``close`` is idempotent.
"""

from __future__ import annotations

import logging
import socket
import time
from collections import Counter
from collections.abc import Callable, Hashable, Sequence
from typing import Any, Protocol

from skeye.errors import ConfigError, LinkClosed
from skeye.peers import listen, socket_peer_key
from skeye.uris import port_of, query_of, split_uri
from skeye.values import MAX_BAUD, baud_rate

Peer = Hashable
MAX_DATAGRAM = 65535
MAX_PEERS = 8  # ground stations one listening link serves; others are told and ignored
# A listening UDP link's peer silent this long is dropped: ten of the 1 Hz heartbeats that
# QGroundControl and MAVSDK send, and time for a script to pause between commands. (Not the
# pilot's link-loss timeout, COM_DL_LOSS_T, 2 s by default: a flight failsafe setting, too short
# for a script that sends no heartbeat to keep its telemetry.) The vehicle forgets a ground
# station after the same time (GCS_TIMEOUT_S).
PEER_TIMEOUT_S = 10.0
TCP_CLIENTS = 4

log = logging.getLogger(__name__)


class MavTransport(Protocol):
    name: str
    datagram: bool  # each poll() chunk is one datagram of whole frames (UDP)

    def fileobjs(self) -> list[Any]: ...

    def poll(self) -> list[tuple[bytes, Peer]]: ...

    def send(self, data: bytes, peer: Peer | None = None) -> None: ...

    @property
    def peers(self) -> list[Peer]: ...

    def close(self) -> None: ...


class UdpTransport:
    """A UDP socket: listening (peers are who sent within ``peer_timeout_s`` of ``clock``) or
    sending to one remote address (its one peer, never dropped)."""

    def __init__(self, host: str, port: int, *, remote: tuple[str, int] | None = None,
                 max_peers: int = MAX_PEERS, peer_timeout_s: float = PEER_TIMEOUT_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise ConfigError(f"cannot bind UDP {host}:{port}: {exc}") from None
        self.sock.setblocking(False)
        self.remote = remote
        self.max_peers = max_peers
        self.peer_timeout_s = peer_timeout_s
        self.clock = clock
        # The peers, in the order first heard, with when each last sent; a sending link starts
        # with its remote, and nothing on it expires.
        self._heard: dict[Peer, float] = {remote: clock()} if remote is not None else {}
        self.refused_peers = 0
        self.expired_peers = 0
        self.datagram = True
        self.port = self.sock.getsockname()[1]
        self.name = (f"udpout://{remote[0]}:{remote[1]}" if remote is not None
                     else f"udp://{host}:{self.port}")

    def fileobjs(self) -> list[Any]:
        return [self.sock]

    @property
    def peers(self) -> list[Peer]:
        self._expire()
        return list(self._heard)

    def _expire(self) -> None:
        """Drop the listening link's peers silent for ``peer_timeout_s``."""
        if self.remote is not None:
            return
        now = self.clock()
        for peer in [p for p, t in self._heard.items() if now - t > self.peer_timeout_s]:
            del self._heard[peer]
            self.expired_peers += 1

    def poll(self) -> list[tuple[bytes, Peer]]:
        out: list[tuple[bytes, Peer]] = []
        while True:
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError:  # ICMP port unreachable from a peer that went away
                return out
            if addr not in self._heard:
                self._expire()
                if len(self._heard) >= self.max_peers:
                    self.refused_peers += 1
                    out.append((data, ("refused", addr)))
                    continue
            self._heard[addr] = self.clock()
            out.append((data, addr))

    def send(self, data: bytes, peer: Peer | None = None) -> None:
        if peer is None:
            self._expire()
        targets = list(self._heard) if peer is None else [peer]
        for target in targets:
            addr = target[1] if isinstance(target, tuple) and target[:1] == ("refused",) else target
            try:
                self.sock.sendto(data, addr)  # type: ignore[arg-type]
            except (BlockingIOError, InterruptedError):
                pass  # the kernel buffer is full: telemetry is dropped, never waited for
            except OSError:
                pass  # nobody listening there (yet): UDP does not care

    def close(self) -> None:
        self.sock.close()


class TcpServerTransport:
    """A TCP listener; each accepted connection is a peer (at most ``max_clients``)."""

    def __init__(self, host: str, port: int, max_clients: int = TCP_CLIENTS) -> None:
        try:
            self.listener = listen(host, port)
        except OSError as exc:
            raise ConfigError(f"cannot listen on TCP {host}:{port}: {exc}") from None
        self.listener.setblocking(False)
        self.port = self.listener.getsockname()[1]
        self.max_clients = max_clients
        self.max_clients_per_peer = max(1, max_clients - 1)  # one slot left for someone else
        self.clients: list[socket.socket] = []
        self._keys: dict[socket.socket, str] = {}  # each client's peer (skeye.peers)
        self._heard_s: dict[socket.socket, float] = {}  # when it last sent (or connected)
        self.refused_clients = 0
        self.replaced_clients = 0
        self.datagram = False
        self.name = f"tcp://{host}:{self.port}"

    def fileobjs(self) -> list[Any]:
        return [self.listener, *self.clients]

    @property
    def peers(self) -> list[Peer]:
        return list(self.clients)

    def poll(self) -> list[tuple[bytes, Peer]]:
        out: list[tuple[bytes, Peer]] = []
        while True:
            try:
                conn, _ = self.listener.accept()
            except (BlockingIOError, InterruptedError, OSError):
                break
            if not self._make_room(conn):
                self.refused_clients += 1
                conn.close()
                continue
            conn.setblocking(False)
            self.clients.append(conn)
            self._heard_s[conn] = time.monotonic()
        for conn in list(self.clients):
            try:
                data = conn.recv(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                data = b""
            if not data:
                self._drop(conn)
                continue
            self._heard_s[conn] = time.monotonic()
            out.append((data, conn))
        return out

    def _make_room(self, conn: socket.socket) -> bool:
        """Whether ``conn`` may join (see the module docstring), after closing the connection
        whose place it takes, if any."""
        key = self._keys[conn] = socket_peer_key(conn)
        held = Counter(self._keys[c] for c in self.clients)
        if held[key] >= self.max_clients_per_peer:
            victim = key
        elif len(self.clients) >= self.max_clients:
            victim, most = held.most_common(1)[0]
            if most < held[key] + 2:
                del self._keys[conn]
                log.info("MAVLink link %s: turning away a connection of %s: its %d clients "
                         "are taken and none holds two more than %s's %d", self.name, key,
                         self.max_clients, key, held[key])
                return False
        else:
            return True
        old = min((c for c in self.clients if self._keys[c] == victim),
                  key=self._heard_s.__getitem__)
        log.info("MAVLink link %s: a connection of %s takes the place of %s's heard from "
                 "longest ago (%d of its %d clients held by %s)", self.name, key, victim,
                 held[victim], self.max_clients, victim)
        self.replaced_clients += 1
        self._drop(old)
        return True

    def _drop(self, conn: socket.socket) -> None:
        if conn in self.clients:
            self.clients.remove(conn)
        self._keys.pop(conn, None)
        self._heard_s.pop(conn, None)
        conn.close()

    def send(self, data: bytes, peer: Peer | None = None) -> None:
        targets = list(self.clients) if peer is None else [peer]
        for conn in targets:
            if not isinstance(conn, socket.socket) or conn not in self.clients:
                continue
            try:
                conn.send(data)  # whole frames or nothing: a full buffer drops this frame
            except (BlockingIOError, InterruptedError):
                pass
            except OSError:
                self._drop(conn)

    def close(self) -> None:
        for conn in list(self.clients):
            self._drop(conn)
        self.listener.close()


class TcpClientTransport:
    """A TCP connection to a MAVLink server (a flight controller's or SITL's TCP port)."""

    def __init__(self, host: str, port: int, timeout_s: float = 5.0) -> None:
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout_s)
        except OSError as exc:
            raise LinkClosed(f"cannot connect to tcp://{host}:{port}: {exc}") from None
        self.sock.setblocking(False)
        self.name = f"tcpout://{host}:{port}"
        self.closed = False
        self.datagram = False

    def fileobjs(self) -> list[Any]:
        return [] if self.closed else [self.sock]

    @property
    def peers(self) -> list[Peer]:
        return [] if self.closed else ["tcp"]

    def poll(self) -> list[tuple[bytes, Peer]]:
        if self.closed:
            return []
        try:
            data = self.sock.recv(MAX_DATAGRAM)
        except (BlockingIOError, InterruptedError):
            return []
        except OSError:
            data = b""
        if not data:
            self.close()
            raise LinkClosed(f"{self.name}: the connection closed")
        return [(data, "tcp")]

    def send(self, data: bytes, peer: Peer | None = None) -> None:
        if self.closed:
            raise LinkClosed(f"{self.name}: the connection is closed")
        try:
            self.sock.sendall(data)
        except OSError as exc:
            self.close()
            raise LinkClosed(f"{self.name}: {exc}") from None

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.sock.close()


class SerialOpenError(ConfigError):
    """A serial device that cannot be opened: not there, or held by another program. A bad
    option of a ``--mavlink`` link (exit status 2); the vehicle unreachable where it is the
    airframe's line (``mavlink://serial/...``: ``LinkClosed``, exit status 4)."""


class SerialTransport:
    """A serial line (pyserial); one peer."""

    def __init__(self, device: str, baud: int) -> None:
        import serial

        from skeye.link.transport import serial_error

        try:  # exclusive: as the AscTec link's (skeye.link.transport.SerialLink)
            self.port = serial.Serial(device, baud, timeout=0, write_timeout=0.5,
                                      exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise SerialOpenError(f"cannot open serial {device} at {baud} baud: "
                              f"{serial_error(exc)}") from None
        self.name = f"serial://{device}?baud={baud}"
        self.datagram = False

    def fileobjs(self) -> list[Any]:
        return [self.port]

    @property
    def peers(self) -> list[Peer]:
        return ["serial"]

    def poll(self) -> list[tuple[bytes, Peer]]:
        try:
            data = self.port.read(self.port.in_waiting or 1)
        except OSError as exc:
            raise LinkClosed(f"{self.name}: {exc}") from None
        return [(bytes(data), "serial")] if data else []

    def send(self, data: bytes, peer: Peer | None = None) -> None:
        try:
            self.port.write(data)
        except Exception as exc:  # pyserial's SerialTimeoutException / OSError
            raise LinkClosed(f"{self.name}: {exc}") from None

    def close(self) -> None:
        self.port.close()


def parse_uri(uri: str) -> tuple[str, str, int, dict[str, str]]:
    """``(scheme, host_or_device, port, query)`` of a MAVLink link URI.

    Raises:
        ConfigError: an unknown scheme, a missing or bad port.
    """
    parts = split_uri(uri, "MAVLink link", "HOST:PORT, an IPv6 address in brackets "
                      "([::1]:14540)", ConfigError)
    scheme = parts.scheme.lower()
    query = {k: v[0] for k, v in query_of(uri, parts, "MAVLink link", ConfigError).items()}
    if scheme == "serial":
        device = (parts.netloc + parts.path) if parts.netloc else parts.path
        if not device:
            raise ConfigError(f"{uri}: give the serial device, e.g. serial:///dev/ttyACM0")
        if "baud" in query and baud_rate(query["baud"]) is None:
            raise ConfigError(f"{uri}: baud={query['baud']} is not a whole number "
                              f"1..{MAX_BAUD}")
        return scheme, device, 0, query
    if scheme not in ("udp", "udpin", "udpout", "tcp", "tcpout"):
        raise ConfigError(f"{uri}: MAVLink links are udp://, udpout://, tcp://, tcpout:// or "
                          "serial:// URIs")
    port = port_of(parts)
    if port is None or not parts.hostname:
        raise ConfigError(f"{uri}: give HOST:PORT, e.g. {scheme}://127.0.0.1:14540")
    return ("udp" if scheme == "udpin" else scheme), parts.hostname, port, query


def listening_links(uris: Sequence[str]) -> list[tuple[str, str, int, str]]:
    """``(scheme, host, port, uri)`` of the links among ``uris`` that listen on this machine
    (``tcp://``, and ``udp://`` / ``udpin://`` as ``udp``), for the checks that two listeners
    of one process share no port.

    Raises:
        ConfigError: a URI that is not a MAVLink link's (:func:`parse_uri`).
    """
    links = []
    for uri in uris:
        scheme, host, port, _ = parse_uri(uri)
        if scheme in ("tcp", "udp"):
            links.append((scheme, host, port, uri))
    return links


def open_transport(uri: str) -> MavTransport:
    """Open the link a URI names (see the module's docstring).

    Raises:
        ConfigError: a bad URI, a port that cannot be bound, a serial device that cannot open
            (``SerialOpenError``).
        LinkClosed: a TCP server that cannot be reached.
    """
    scheme, host, port, query = parse_uri(uri)
    if scheme == "udp":
        return UdpTransport(host, port)
    if scheme == "udpout":
        return UdpTransport(query.get("bind", "127.0.0.1"), 0, remote=(host, port))
    if scheme == "tcp":
        return TcpServerTransport(host, port)
    if scheme == "tcpout":
        return TcpClientTransport(host, port)
    return SerialTransport(host, int(query.get("baud", "57600")))  # checked by parse_uri


def check_free(uri: str, option: str = "--mavlink") -> None:
    """Raise ``ConfigError`` naming ``option`` if a listening link's port is taken (or the URI
    is bad); sending links (udpout, tcpout) and serial lines have nothing to check here."""
    scheme, host, port, _ = parse_uri(uri)
    if scheme not in ("udp", "tcp") or port == 0:
        return
    kind = socket.SOCK_DGRAM if scheme == "udp" else socket.SOCK_STREAM
    with socket.socket(socket.AF_INET, kind) as probe:
        if scheme == "tcp":
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError:
            raise ConfigError(
                f"{scheme.upper()} port {port} on {host} (for the MAVLink link {uri}) is already "
                f"in use - another skeye or autopilot running? Move it with {option} URI"
            ) from None
