"""Who is at the other end of a TCP connection: one key per local user, one per remote address.

How this works: every server of skeye caps how many connections one peer may hold
(docs/security.md). On loopback every address of 127.0.0.0/8 (and ``::1``) is this same host,
and any local user may bind any of them: counted per address, one user takes every slot by
binding 127.0.0.2, 127.0.0.3, ... So :func:`peer_key` counts a loopback peer by the Unix user
that owns the other end of the connection, asked of the kernel:

1. Linux's ``sock_diag`` netlink interface (``NETLINK_SOCK_DIAG``, the one ``ss`` uses): one
   exact lookup of the peer's socket by its four-tuple (its local address is our peer's, its
   remote address ours), whose answer (``inet_diag_msg``) carries the owner's ``idiag_uid``.
2. Where netlink is not available: ``/proc/net/tcp`` (``tcp6``), the same table as text, the
   peer's row found by its address pair.
3. Where neither answers (another OS, the peer already gone): the whole loopback range is one
   peer, ``"loopback"``, which still counts a user once however many addresses it binds.

A remote peer is counted by its IP address. Keys are strings: ``"uid 1000"``, ``"loopback"``,
``"192.0.2.7"``. The lookups never raise and never block for long (netlink answers from the
kernel at once; a 0.2 s timeout bounds it).
"""

from __future__ import annotations

import errno
import ipaddress
import logging
import os
import socket
import struct
import time
from pathlib import Path

__all__ = ["LOOPBACK", "accept_failed", "is_loopback", "listen", "peer_key", "socket_peer_key"]

log = logging.getLogger(__name__)

LOOPBACK = "loopback"
"""The key of a loopback peer whose user cannot be found."""

NETLINK_SOCK_DIAG = 4  # linux/netlink.h
SOCK_DIAG_BY_FAMILY = 20  # linux/sock_diag.h
NLM_F_REQUEST = 0x01
NLMSG_ERROR = 0x02
_NO_COOKIE = 0xFFFFFFFF  # INET_DIAG_NOCOOKIE
_NLMSG_HEADER = struct.Struct("=IHHII")  # len, type, flags, seq, pid
# inet_diag_req_v2: family, protocol, ext, pad, states; then inet_diag_sockid: sport, dport
# (big-endian), src[4], dst[4] (network order), if, cookie[2].
_REQUEST = struct.Struct("=BBBxI")
_SOCKID = struct.Struct(">HH16s16s")
_SOCKID_TAIL = struct.Struct("=III")
_UID_OFFSET = _NLMSG_HEADER.size + 4 + 48 + 12  # inet_diag_msg: 4 B, sockid 48 B, 3 x u32


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an IP address) is this machine's loopback (127.0.0.0/8, ::1)."""
    try:
        address = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return False
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return address.is_loopback


def _packed(host: str) -> tuple[int, bytes]:
    """(address family, 16 bytes of the address in network order) for sock_diag."""
    address = ipaddress.ip_address(host.split("%", 1)[0])
    if isinstance(address, ipaddress.IPv4Address):
        return socket.AF_INET, address.packed + bytes(12)
    return socket.AF_INET6, address.packed


def _uid_by_netlink(peer: tuple[str, int], ours: tuple[str, int]) -> int | None:
    """The uid owning the socket whose local address is ``peer`` and remote ``ours``."""
    family, src = _packed(peer[0])
    family_ours, dst = _packed(ours[0])
    if family != family_ours:
        return None
    payload = (_REQUEST.pack(family, socket.IPPROTO_TCP, 0, 0xFFFFFFFF)
               + _SOCKID.pack(peer[1], ours[1], src, dst)
               + _SOCKID_TAIL.pack(0, _NO_COOKIE, _NO_COOKIE))
    header = _NLMSG_HEADER.pack(_NLMSG_HEADER.size + len(payload), SOCK_DIAG_BY_FAMILY,
                                NLM_F_REQUEST, 1, 0)
    with socket.socket(socket.AF_NETLINK, socket.SOCK_DGRAM, NETLINK_SOCK_DIAG) as nl:
        nl.settimeout(0.2)
        nl.sendto(header + payload, (0, 0))
        answer = nl.recv(8192)
    if len(answer) < _NLMSG_HEADER.size:
        return None
    _, kind, _, _, _ = _NLMSG_HEADER.unpack_from(answer)
    if kind != SOCK_DIAG_BY_FAMILY or len(answer) < _UID_OFFSET + 4:
        return None  # NLMSG_ERROR: no such socket (the peer went), or not supported
    uid: int = struct.unpack_from("=I", answer, _UID_OFFSET)[0]
    return uid


def _proc_address(host: str, port: int) -> tuple[str, str]:
    """(table file, the address as /proc/net/tcp writes it: host-order 32-bit words in hex)."""
    family, packed = _packed(host)
    if family == socket.AF_INET:
        words = struct.unpack("=I", packed[:4])
        return "tcp", f"{words[0]:08X}:{port:04X}"
    words = struct.unpack("=4I", packed)
    return "tcp6", "".join(f"{w:08X}" for w in words) + f":{port:04X}"


def _uid_by_proc(peer: tuple[str, int], ours: tuple[str, int]) -> int | None:
    table, local = _proc_address(*peer)
    _, remote = _proc_address(*ours)
    data = Path(f"/proc/net/{table}").read_bytes()
    at = data.find(f" {local} {remote} ".encode())
    if at < 0:
        return None
    row = data[at: data.find(b"\n", at)].split()
    return int(row[6])  # local, remote, st, tx:rx, tr:when, retrnsmt, uid


def peer_key(peer: tuple[str, int], ours: tuple[str, int]) -> str:
    """The key a connection from ``peer`` (host, port) to ``ours`` counts under (see the
    module comment). Never raises."""
    host = peer[0]
    if not is_loopback(host):
        return host
    for lookup in (_uid_by_netlink, _uid_by_proc):
        try:
            uid = lookup(peer, ours)
        except (OSError, ValueError, IndexError, struct.error):
            continue
        if uid is not None:
            return f"uid {uid}"
    return LOOPBACK


def socket_peer_key(sock: socket.socket) -> str:
    """:func:`peer_key` of an accepted socket ("" for a socket that is no longer connected)."""
    try:
        peer = sock.getpeername()
        ours = sock.getsockname()
    except OSError:
        return ""
    return peer_key((str(peer[0]), int(peer[1])), (str(ours[0]), int(ours[1])))


def own_key() -> str:
    """The key this process's own loopback connections count under."""
    return f"uid {os.getuid()}" if hasattr(os, "getuid") else LOOPBACK


RESOURCE_ERRNOS = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})
"""accept() failures that are the machine running short, not the listener failing: waited
out."""


def accept_failed(exc: OSError, last_said_s: float, what: str) -> float | None:
    """An accept() that raised: for a resource shortage, log it (once a second at most), wait a
    moment and return when it was last said; None when the listener itself is gone."""
    if exc.errno not in RESOURCE_ERRNOS:
        return None
    now = time.monotonic()
    if now - last_said_s >= 1.0:
        log.error("%s: cannot accept: %s (waiting for descriptors to free)", what, exc)
        last_said_s = now
    time.sleep(0.05)
    return last_said_s



def listen(host: str, port: int, *, backlog: int | None = None) -> socket.socket:
    """``socket.create_server((host, port), backlog=backlog)`` in the host's address family:
    an IPv6 address (``::1``; ``::``, every address, IPv4 ones too where the system can) is
    bound as IPv6, as :func:`skeye.processes.port_in_use` probes it. ``create_server`` alone
    binds IPv4, and refused ``::1`` with "Address family for hostname not supported"."""
    if ":" not in host:
        return socket.create_server((host, port), backlog=backlog)
    return socket.create_server((host, port), family=socket.AF_INET6, backlog=backlog,
                                dualstack_ipv6=host == "::" and socket.has_dualstack_ipv6())
