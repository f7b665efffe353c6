"""Who may talk to ground control, and how much: the one gate in front of the web app.

How this works: ``Guard`` is plain ASGI middleware wrapped around the FastAPI app (see
``skeye.ground.app.create_app``). Every HTTP request and every WebSocket handshake passes these
checks, in order, before the app sees it; a refusal is answered here with a JSON error naming
the problem:

1. **Host** (400): the ``Host`` header must name this server: an IP address literal,
   ``localhost``, or a name given with ``--allow-host``. A DNS-rebinding page reaches the server
   under the attacker's host name, so this is what stops it reading telemetry.
2. **Origin** (403): when a browser sends ``Origin`` (it always does on WebSockets and on a
   cross-origin POST), it must be this server's own origin (``scheme://`` + the Host header).
3. **Token** (401): ``/api/...`` and ``/ws...`` need the server's secret token, as Jupyter does:
   opening the printed URL ``http://host:port/?token=...`` sets a cookie (HttpOnly,
   SameSite=Strict, named after the port) and redirects to ``/``; scripts send
   ``Authorization: token ...`` or ``X-Skeye-Token``, or put ``?token=`` in the URL. ``/``
   without a token answers 401 with a page saying where to find it. ``/static/`` is public
   (the page's own code and style).
4. **POST bodies**: ``Content-Type: application/json`` (415; this is what a browser cannot send
   cross-origin without a CORS preflight, which this server never grants), at most
   ``MAX_BODY_BYTES`` (413), read here in full before the app runs, within ``body_timeout_s``
   of the request head (408 and closed: a stalled body must not hold its connection).
5. **POST rate** (429, ``Retry-After: 1``): ``POST_RATE_HZ`` per client on average, bursts of
   ``POST_BURST``, so a loop of POSTs cannot monopolise the vehicle bridge. A client is a peer
   of :func:`skeye.peers.peer_key`: a local user however many loopback addresses it binds, or a
   remote address.

Tokens are compared in constant time. ``parse_json_limited`` (bodies and WebSocket messages)
refuses JSON nested deeper than ``MAX_JSON_DEPTH`` before parsing it. ``CommandRate`` is a
token bucket, pure (time is an argument), that the app keeps per WebSocket connection and this
gate per client (peer) for POSTs.
"""

from __future__ import annotations

import asyncio
import functools
import ipaddress
import json
import logging
import secrets
import sys
import time
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from dataclasses import dataclass, field
from http.cookies import CookieError, SimpleCookie
from typing import Any
from urllib.parse import parse_qs, urlsplit

from skeye.errors import InvalidArgument
from skeye.peers import peer_key

log = logging.getLogger(__name__)

MAX_BODY_BYTES = 64 * 1024
MAX_WS_MESSAGE_BYTES = 64 * 1024
MAX_JSON_DEPTH = 8
TOKEN_ENV = "SKEYE_GROUND_TOKEN"
LOCAL_NAMES = ("localhost",)
PUBLIC_PREFIXES = ("/static/",)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]


def new_token() -> str:
    """A fresh secret (192 bits, URL-safe)."""
    return secrets.token_urlsafe(24)


@dataclass(frozen=True)
class GroundSecurity:
    """The server's secret and the host names it answers to.

    Args:
        token: the secret every API call and WebSocket must carry.
        allowed_hosts: host names accepted in ``Host`` besides IP literals and ``localhost``
            (``--allow-host``).
    """

    token: str = field(default_factory=new_token)
    allowed_hosts: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if len(self.token) < 16 or not self.token.isascii() or not self.token.isprintable():
            raise InvalidArgument("the ground token must be at least 16 printable ASCII characters")
        for name in self.allowed_hosts:
            if not name or any(c in name for c in "/:@ \t") or not name.isascii():
                raise InvalidArgument(
                    f"--allow-host {name!r}: expected a bare host name (no scheme, port or path)"
                )

    def host_allowed(self, host: str) -> bool:
        """Is ``host`` (no port) one of this server's names?"""
        host = host.strip("[]").lower().rstrip(".")
        if host in LOCAL_NAMES or host in (h.lower().rstrip(".") for h in self.allowed_hosts):
            return True
        try:
            ipaddress.ip_address(host)
        except ValueError:
            return False
        return True  # an IP literal cannot be a rebinding attacker's name

    def token_ok(self, candidate: str | None) -> bool:
        return candidate is not None and secrets.compare_digest(
            candidate.encode("utf-8", "replace"), self.token.encode("utf-8")
        )


def cookie_name(port: int | None) -> str:
    """Cookies ignore ports, so each server's cookie carries its port in its name."""
    return f"skeye-ground-{port if port is not None else 'default'}"


def split_host(value: str) -> tuple[str, int | None] | None:
    """``host[:port]`` -> (host, port); None when it does not parse."""
    try:
        parts = urlsplit(f"//{value}")
        return (parts.hostname or "", parts.port)
    except ValueError:
        return None


def json_depth_exceeds(text: str | bytes, limit: int = MAX_JSON_DEPTH) -> bool:
    """True when the JSON text opens more than ``limit`` arrays/objects at once.

    A linear scan that skips strings (with their escapes); it does not validate the JSON.
    """
    data = text.encode("utf-8", "replace") if isinstance(text, str) else text
    depth = 0
    in_string = False
    escaped = False
    for byte in data:
        if in_string:
            if escaped:
                escaped = False
            elif byte == 0x5C:  # backslash
                escaped = True
            elif byte == 0x22:  # quote
                in_string = False
        elif byte == 0x22:
            in_string = True
        elif byte in (0x5B, 0x7B):  # [ {
            depth += 1
            if depth > limit:
                return True
        elif byte in (0x5D, 0x7D):
            depth -= 1
    return False


def parse_json_limited(text: str | bytes) -> Any:
    """``json.loads`` that first refuses nesting deeper than ``MAX_JSON_DEPTH``, and then a
    string holding a lone UTF-16 surrogate (``"\\ud800"``: JSON text can spell one, but it is no
    Unicode character, so no answer echoing it could be encoded as UTF-8). A whole number of
    more digits than Python reads (``sys.get_int_max_str_digits()``, 4300) is refused naming
    that limit, not with ``int``'s advice to raise it.

    Raises:
        ValueError: not JSON, nested too deeply, a number of too many digits, or a lone
            surrogate (the message says which).
    """
    if json_depth_exceeds(text):
        raise InvalidArgument(f"is JSON nested deeper than {MAX_JSON_DEPTH} levels")
    try:
        value = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InvalidArgument(f"is not valid JSON: {exc}") from None
    except ValueError:  # int() refuses more digits than sys.get_int_max_str_digits()
        raise InvalidArgument(
            f"holds a number of more than {sys.get_int_max_str_digits()} digits"
        ) from None
    if not _may_hold_lone_surrogate(text):
        return value
    try:
        json.dumps(value, ensure_ascii=False).encode("utf-8")
    except UnicodeEncodeError as exc:
        lone = exc.object[exc.start : exc.end]
        raise InvalidArgument(
            f"holds a lone UTF-16 surrogate ({lone!a}), which is not a character"
        ) from None
    return value


def _may_hold_lone_surrogate(text: str | bytes) -> bool:
    """Whether parsed ``text`` may hold a lone surrogate, so its value must be re-encoded to
    find out. ASCII text can spell one only as an escape (``\\ud800``); other text may hold
    one as it is: ``json.loads`` decodes bytes with ``surrogatepass`` (an encoded surrogate,
    ``b'"\\xed\\xa0\\x80"'``, is read, not refused), and a string may hold one already."""
    if isinstance(text, bytes):
        return not text.isascii() or b"\\u" in text or b"\\U" in text
    return not text.isascii() or "\\u" in text or "\\U" in text


class CommandRate:
    """A token bucket: ``rate_hz`` commands per second on average, bursts of ``burst``."""

    def __init__(self, rate_hz: float, burst: int, now_s: float) -> None:
        if not rate_hz > 0 or burst < 1:
            raise InvalidArgument(f"need rate_hz > 0 and burst >= 1, got {rate_hz}, {burst}")
        self.rate_hz = rate_hz
        self.burst = burst
        self._tokens = float(burst)
        self._last_s = now_s

    def allow(self, now_s: float) -> bool:
        """Take one token if there is one."""
        self._tokens = min(self.burst, self._tokens + (now_s - self._last_s) * self.rate_hz)
        self._last_s = now_s
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False


def _headers(scope: Scope) -> dict[str, str]:
    out: dict[str, str] = {}
    for key, value in scope.get("headers", []):
        name = key.decode("latin-1").lower()
        text = value.decode("latin-1")
        if name in out:
            text = f"{out[name]}{'; ' if name == 'cookie' else ', '}{text}"
        out[name] = text
    return out


def _json_body(status: int, message: str) -> bytes:
    return json.dumps({"error": message, "status": status}).encode("utf-8")


LOGIN_PAGE = """<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>skeye ground control: token needed</title></head><body>
<h1>skeye ground control</h1><p>This server needs its access token. Open the URL that
<code>skeye ground</code> or <code>skeye up</code> printed when it started
(<code>http://HOST:PORT/?token=...</code>); the page remembers it in a cookie.</p></body></html>
"""


POST_RATE_HZ = 10.0
"""Average POSTs per second per client address: the page's own command rate (it uses the
WebSocket; a script with ``curl`` needs a few per second), so a loop of POSTs from one machine
cannot monopolise the vehicle bridge or the event loop."""
POST_BURST = 20
BODY_TIMEOUT_S = 10.0
"""A POST body must be complete this long after its request head (``skeye ground`` gives it
``--header-timeout``): else 408 and the connection is closed."""
MAX_TRACKED_CLIENTS = 1024  # clients with a POST bucket; the oldest is forgotten


@functools.lru_cache(maxsize=1024)
def _peer_key(client: tuple[str, int], server: tuple[str, int]) -> str:
    """:func:`skeye.peers.peer_key`, once per connection (a keep-alive connection's requests
    share its four-tuple)."""
    return peer_key(client, server)


class Guard:
    """ASGI middleware: Host, Origin, token, content type, body size and POST rate (see the
    module doc)."""

    def __init__(self, app: ASGIApp, security: GroundSecurity, *,
                 post_rate_hz: float = POST_RATE_HZ, post_burst: int = POST_BURST,
                 body_timeout_s: float = BODY_TIMEOUT_S) -> None:
        CommandRate(post_rate_hz, post_burst, 0.0)  # refuses a bad rate or burst here
        if not body_timeout_s > 0:
            raise InvalidArgument(f"body_timeout_s must be > 0, got {body_timeout_s!r}")
        self.body_timeout_s = body_timeout_s
        self.timed_out = 0  # POSTs answered 408: their body was not complete in time
        self.app = app
        self.security = security
        self.refused = 0
        self.post_rate_hz = post_rate_hz
        self.post_burst = post_burst
        self._post_rates: dict[str, CommandRate] = {}

    def _post_allowed(self, scope: Scope) -> bool:
        """One token from this client's bucket (insertion order = age)."""
        client, server = scope.get("client"), scope.get("server")
        peer = "?"
        if client:
            peer = str(client[0])
            if server and server[1] is not None:
                peer = _peer_key((str(client[0]), int(client[1])), (str(server[0]),
                                                                   int(server[1])))
        now = time.monotonic()
        rate = self._post_rates.pop(peer, None)
        if rate is None:
            rate = CommandRate(self.post_rate_hz, self.post_burst, now)
            if len(self._post_rates) >= MAX_TRACKED_CLIENTS:
                del self._post_rates[next(iter(self._post_rates))]
        self._post_rates[peer] = rate
        return rate.allow(now)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope.get("type")
        if kind not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = _headers(scope)
        problem, port = self._check(scope, headers)
        if problem is not None:
            status, message = problem
            self.refused += 1
            log.info("refused %s %s: %s", kind, scope.get("path"), message)
            await self._refuse(scope, receive, send, status, message)
            return
        if kind == "http" and scope.get("method") == "POST":
            if not self._post_allowed(scope):
                self.refused += 1
                await _respond(
                    send, 429,
                    _json_body(429, f"too many requests: at most {self.post_rate_hz:g} POST/s "
                               f"on average (bursts of {self.post_burst}) per client"),
                    b"application/json", [(b"retry-after", b"1")],
                )
                return
            await self._post(scope, receive, send, headers)
            return
        if kind == "http" and scope.get("path") == "/" and self._query_token(scope):
            await self._login(send, port)
            return
        await self.app(scope, receive, send)

    # -- checks ------------------------------------------------------------------------------
    def _check(
        self, scope: Scope, headers: dict[str, str]
    ) -> tuple[tuple[int, str] | None, int | None]:
        host_header = headers.get("host", "")
        parsed = split_host(host_header) if host_header else None
        if parsed is None or not self.security.host_allowed(parsed[0]):
            return (
                400,
                f"Host {host_header!r} is not a name of this server (allowed: IP addresses, "
                f"localhost{''.join(', ' + h for h in self.security.allowed_hosts)}; "
                "start skeye ground with --allow-host NAME to add one)",
            ), None
        port = parsed[1]
        origin = headers.get("origin")
        if origin is not None:
            scheme = "https" if scope.get("scheme") in ("https", "wss") else "http"
            if origin.rstrip("/").lower() != f"{scheme}://{host_header}".lower():
                return (403, f"cross-origin request from {origin!r} refused"), port
        path = str(scope.get("path", ""))
        if path.startswith(PUBLIC_PREFIXES):
            return None, port
        if path == "/":
            if self._has_token(scope, headers, port):
                return None, port
            return (401, "token needed: open the URL printed at start (with ?token=...)"), port
        if not self._has_token(scope, headers, port):
            return (
                401,
                "missing or wrong token: open the URL printed at start, or send "
                "'Authorization: token ...' / 'X-Skeye-Token'",
            ), port
        return None, port

    def _query_token(self, scope: Scope) -> bool:
        query = parse_qs(bytes(scope.get("query_string", b"")).decode("latin-1"))
        return any(self.security.token_ok(v) for v in query.get("token", []))

    def _has_token(self, scope: Scope, headers: dict[str, str], port: int | None) -> bool:
        candidates: list[str] = []
        auth = headers.get("authorization", "")
        if auth.lower().startswith("token "):
            candidates.append(auth[6:].strip())
        if "x-skeye-token" in headers:
            candidates.append(headers["x-skeye-token"].strip())
        if "cookie" in headers:
            jar: SimpleCookie = SimpleCookie()
            try:
                jar.load(headers["cookie"])
            except CookieError:  # a malformed cookie header is just no token
                jar = SimpleCookie()
            morsel = jar.get(cookie_name(port))
            if morsel is not None:
                candidates.append(morsel.value)
        if self._query_token(scope):
            return True
        return any(self.security.token_ok(c) for c in candidates)

    # -- answers -----------------------------------------------------------------------------
    async def _refuse(
        self, scope: Scope, receive: Receive, send: Send, status: int, message: str
    ) -> None:
        body = _json_body(status, message)
        ctype = b"application/json"
        if scope["type"] == "http" and scope.get("path") == "/" and status == 401:
            body, ctype = LOGIN_PAGE.encode("utf-8"), b"text/html; charset=utf-8"
        if scope["type"] == "websocket":
            await receive()  # websocket.connect
            if "websocket.http.response" in scope.get("extensions", {}):
                await send(
                    {
                        "type": "websocket.http.response.start",
                        "status": status,
                        "headers": [(b"content-type", ctype)],
                    }
                )
                await send({"type": "websocket.http.response.body", "body": body})
            else:
                await send({"type": "websocket.close", "code": 1008, "reason": message[:120]})
            return
        await _respond(send, status, body, ctype)

    async def _login(self, send: Send, port: int | None) -> None:
        cookie = (
            f"{cookie_name(port)}={self.security.token}; Path=/; HttpOnly; SameSite=Strict"
        ).encode("latin-1")
        await _respond(
            send, 303, b"", b"text/plain", [(b"location", b"/"), (b"set-cookie", cookie)]
        )

    async def _post(
        self, scope: Scope, receive: Receive, send: Send, headers: dict[str, str]
    ) -> None:
        ctype = headers.get("content-type", "").split(";")[0].strip().lower()
        if ctype != "application/json":
            self.refused += 1
            await _respond(
                send,
                415,
                _json_body(415, f"Content-Type must be application/json, got {ctype or 'none'!r}"),
            )
            return
        declared = headers.get("content-length")
        if declared is not None and (not declared.isdigit() or int(declared) > MAX_BODY_BYTES):
            self.refused += 1
            await _respond(send, 413, _json_body(413, _too_large()))
            return
        chunks: list[bytes] = []
        size = 0
        try:
            # A body that stalls (or trickles) held its connection for good: the header
            # timeout ends with the head, and 32 such POSTs locked their user out.
            async with asyncio.timeout(self.body_timeout_s):
                while True:
                    message = await receive()
                    if message["type"] == "http.disconnect":
                        return
                    chunk = bytes(message.get("body", b""))
                    size += len(chunk)
                    if size > MAX_BODY_BYTES:
                        self.refused += 1
                        await _respond(send, 413, _json_body(413, _too_large()))
                        return
                    chunks.append(chunk)
                    if not message.get("more_body", False):
                        break
        except TimeoutError:
            self.timed_out += 1
            log.info("closing a POST to %s: body not complete within %g s (%d bytes came)",
                     scope.get("path"), self.body_timeout_s, size)
            await _respond(
                send, 408,
                _json_body(408, f"request body not complete within {self.body_timeout_s:g} s "
                           f"of the request head ({size} bytes came)"),
                b"application/json", [(b"connection", b"close")],
            )
            return
        body = b"".join(chunks)
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)


def _too_large() -> str:
    return f"request body over {MAX_BODY_BYTES} bytes"


async def _respond(
    send: Send,
    status: int,
    body: bytes,
    ctype: bytes = b"application/json",
    extra: Iterable[tuple[bytes, bytes]] = (),
) -> None:
    headers = [
        (b"content-type", ctype),
        (b"content-length", str(len(body)).encode()),
        (b"cache-control", b"no-store"),
        *extra,
    ]
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})
