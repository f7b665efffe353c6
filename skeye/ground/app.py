"""The ground-control web application (ASGI): the page, a REST API and two WebSockets.

How this works: ``create_app(bridge, video)`` builds a FastAPI app around a ``VehicleBridge``
(the vehicle link, its own thread) and an optional ``VideoRelay`` (the camera, its own
thread). Request handlers never touch a socket to the vehicle: they read the bridge's snapshot
and hand validated commands to ``bridge.execute`` in a worker thread.

- ``GET /``: the page (``static/index.html``; its ES modules, styles and the vendored uPlot
  under ``/static``, all local, no CDN; ``.js`` files are served as ``text/javascript``, which
  module scripts require).
- ``GET /api/state``: telemetry, link quality and video status; ``GET /api/history``: recent
  track; ``GET /api/commands``: the command table (names, arguments, ranges, the page's
  field labels, units and steps) and the keyboard's speed, from which the page builds its forms.
- ``POST /api/command/{name}`` with a JSON object of arguments: 200 and the outcome when the
  vehicle accepted it; 409 with the RESULT code and reason when it refused; 400 for a body that
  is not JSON, 404 for an unknown command, 422 for bad arguments (the message names the
  argument), 503 when no vehicle is connected or it did not answer.
- ``WS /ws``: pushes ``telemetry`` at ``telemetry_hz`` (only when something changed, and at
  least once a second so link ages stay fresh); takes ``{"type": "command", "id", "name",
  "args"}`` and answers ``{"type": "result", "id", ...}`` with the same outcomes and statuses.
- ``WS /ws/video``: for every new frame, a JSON ``frame`` message (size, detection: ring
  ellipses and centre in pixels) and then the JPEG as a binary message.

Every browser tab gets its own WebSocket tasks; a slow tab only slows itself (``/ws/video`` sends
it the newest frame once the previous one has gone), and one that takes nothing for 5 s is cut
(:class:`skeye.ground.limits.LimitedWebSocketProtocol`). A tab's commands
are limited (``MAX_IN_FLIGHT`` waiting for the vehicle, ``COMMAND_RATE_HZ`` on average): the
excess is answered at once with status 429, so one tab cannot queue work in front of another's.
A command whose ``id`` holds NaN or Infinity (Python reads them; JSON has them not) is
answered 400 without it: its echo would make the answer no JSON. A binary frame closes ``/ws``
with code 1003, a message over ``MAX_WS_MESSAGE_BYTES`` with 1009,
JSON nested deeper than ``MAX_JSON_DEPTH`` with 1008, each with a reason.

Access (Host, Origin, token, content type, body size) is checked before any of this by
``skeye.ground.guard.Guard``; nothing here is reachable without the server's token. There is no
``/api/docs`` page (it would load a script from a CDN): the API is described in docs/ground.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import mimetypes
from importlib import resources
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.routing import APIRoute
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException
from starlette.routing import WebSocketRoute
from starlette.websockets import WebSocketDisconnected

from skeye.errors import LocalProtocolError, SkeyeError
from skeye.ground.bridge import VehicleBridge, VehicleUnavailable
from skeye.ground.commands import (
    COMMANDS,
    VehicleLimits,
    describe_commands,
    describe_keyboard,
    parse_command,
)
from skeye.ground.guard import (
    BODY_TIMEOUT_S,
    MAX_JSON_DEPTH,
    MAX_WS_MESSAGE_BYTES,
    CommandRate,
    GroundSecurity,
    Guard,
    parse_json_limited,
)
from skeye.ground.limits import ConnectionLimits, server_config
from skeye.ground.video import VideoRelay

log = logging.getLogger(__name__)

STATIC_DIR = Path(str(resources.files("skeye.ground").joinpath("static")))
# Browsers run a module script only when it comes as JavaScript; a host without
# /etc/mime.types (or an old one) must not turn the page's modules into text/plain.
mimetypes.add_type("text/javascript", ".js")
mimetypes.add_type("text/css", ".css")
MAX_IN_FLIGHT = 2  # commands of one WebSocket waiting for the vehicle at once
COMMAND_RATE_HZ = 10.0  # average commands per second per WebSocket (the page sends ~3)
COMMAND_BURST = 20
WS_UNSUPPORTED_DATA = 1003
WS_POLICY_VIOLATION = 1008
WS_MESSAGE_TOO_BIG = 1009


class CommandError(SkeyeError):
    """A command that did not reach the vehicle: HTTP status and message."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


async def perform(
    bridge: VehicleBridge, name: str, body: Any, limits: VehicleLimits | None = None
) -> tuple[int, dict[str, Any]]:
    """Validate and execute one command; returns (HTTP status, JSON answer)."""
    if name not in COMMANDS:
        raise CommandError(
            404, f"unknown command {name!r}; known commands: {', '.join(COMMANDS)}"
        )
    try:
        command = parse_command(name, body, limits)
    except LocalProtocolError as exc:
        raise CommandError(422, str(exc)) from None
    try:
        outcome = await asyncio.to_thread(bridge.execute, command)
    except VehicleUnavailable as exc:
        raise CommandError(503, str(exc)) from None
    except LocalProtocolError as exc:  # a packet that cannot be built: never a bare 500
        raise CommandError(422, str(exc)) from None
    return (200 if outcome.ok else 409), outcome.to_json()


def uvicorn_config(app: Any, log_level: str = "warning",
                   limits: ConnectionLimits | None = None) -> Any:
    """The uvicorn settings every ground server runs with: the connection limits of
    :mod:`skeye.ground.limits` (header and keep-alive timeouts, concurrency, connections per
    peer), WebSocket messages at most ``MAX_WS_MESSAGE_BYTES`` (larger: closed with 1009), a
    short receive queue per socket (a flooding client is held back by TCP, not buffered), no
    pings (the page reconnects)."""
    return server_config(
        app,
        log_level,
        limits=limits,
        ws_ping_interval=None,
        ws_max_size=MAX_WS_MESSAGE_BYTES,
        ws_max_queue=4,
    )


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": message, "status": status}, status_code=status)


def create_app(
    bridge: VehicleBridge,
    video: VideoRelay | None = None,
    *,
    telemetry_hz: float = 10.0,
    security: GroundSecurity | None = None,
    limits: VehicleLimits | None = None,
    body_timeout_s: float = BODY_TIMEOUT_S,
) -> FastAPI:
    """The ground-control app; the caller owns (starts and closes) ``bridge`` and ``video``.

    ``security`` holds the token and the extra host names (a fresh random token when None:
    then nobody can use the API, which only suits tests of the refusals). ``limits``: the
    vehicle's speed limits (default: the hummingbird robot file's). ``body_timeout_s``: how
    long a POST body may take after its request head (then 408).
    """
    if limits is None:
        limits = VehicleLimits.for_robot("hummingbird")
    app = FastAPI(
        title="skeye ground control", docs_url=None, redoc_url=None, openapi_url=None
    )
    app.add_middleware(Guard, security=security or GroundSecurity(),
                       body_timeout_s=body_timeout_s)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    period_s = 1.0 / telemetry_hz

    @app.exception_handler(HTTPException)
    async def http_error(request: Request, exc: HTTPException) -> Response:
        # The API's own error shape ({"error", "status"}), naming what was asked for
        where = f"{request.method} {request.url.path}"
        websockets = {r.path for r in app.routes if isinstance(r, WebSocketRoute)}
        if exc.status_code == 404 and request.url.path in websockets:
            # there is one, but it speaks WebSocket: "no such endpoint" said otherwise
            return JSONResponse(
                {"error": f"{where}: a WebSocket endpoint: open it as one (ws://, with the "
                          "upgrade), not with plain HTTP", "status": 426},
                status_code=426, headers={"Upgrade": "websocket"})
        if exc.status_code == 404:
            message = f"no such endpoint: {where} (the API: docs/ground.md#api)"
        elif exc.status_code == 405:
            allowed = next((v for k, v in (exc.headers or {}).items() if k.lower() == "allow"),
                           "")
            message = f"{where}: method not allowed here (allowed: {allowed or 'none'})"
        else:
            message = f"{where}: {exc.detail}"
        return JSONResponse({"error": message, "status": exc.status_code},
                            status_code=exc.status_code, headers=exc.headers)

    def video_status() -> dict[str, Any] | None:
        return None if video is None else video.status_json()

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-cache"})

    @app.get("/api/state")
    async def state() -> dict[str, Any]:
        return {**bridge.snapshot(), "video": video_status()}

    @app.get("/api/history")
    async def history() -> dict[str, Any]:
        return {"points": bridge.history()}

    @app.get("/api/commands")
    async def commands() -> dict[str, Any]:
        return {"commands": describe_commands(limits), "keyboard": describe_keyboard(limits)}

    @app.post("/api/command/{name}")
    async def command(name: str, request: Request) -> Response:
        raw = await request.body()  # the Guard has bounded it
        body: Any = None
        if raw.strip():
            try:
                body = parse_json_limited(raw)
            except ValueError as exc:
                return _error(400, f"request body {exc}")
        try:
            status, answer = await perform(bridge, name, body, limits)
        except CommandError as exc:
            return _error(exc.status, exc.message)
        return JSONResponse(answer, status_code=status)

    @app.get("/api/video/frame.jpg")
    async def frame() -> Response:
        latest = None if video is None else video.latest()
        if latest is None:
            why = "no video source configured" if video is None else "no frame yet"
            return _error(503, why)
        return Response(latest.jpeg, media_type="image/jpeg", headers={"Cache-Control": "no-store"})

    @app.get("/api/video/detection")
    async def detection() -> Response:
        latest = None if video is None else video.latest()
        if latest is None:
            why = "no video source configured" if video is None else "no video frame yet"
            return _error(503, why)
        return JSONResponse(latest.meta_json())

    @app.websocket("/ws")
    async def telemetry_ws(ws: WebSocket) -> None:
        await ws.accept()
        send_lock = asyncio.Lock()
        gone = asyncio.Event()  # the page went: nothing more is sent, every task ends quietly

        async def send(msg: dict[str, Any]) -> None:
            if gone.is_set():
                raise WebSocketDisconnect(1006)
            async with send_lock:
                try:
                    await ws.send_json(msg)
                except (WebSocketDisconnect, WebSocketDisconnected, OSError):
                    gone.set()  # a reply (a 429, a result) to a page that has gone
                    raise WebSocketDisconnect(1006) from None

        async def pusher() -> None:
            last_seq = -1
            last_sent = 0.0
            loop = asyncio.get_running_loop()
            try:
                while True:
                    now = loop.time()
                    if bridge.seq != last_seq or now - last_sent >= 1.0:
                        snap = bridge.snapshot()
                        last_seq, last_sent = snap["seq"], now
                        snap["video"] = video_status()
                        await send(snap)
                    await asyncio.sleep(period_s)
            except WebSocketDisconnect:
                return  # the page went

        async def run_command(msg: dict[str, Any]) -> None:
            ident = msg.get("id")
            try:
                status, answer = await perform(
                    bridge, str(msg.get("name")), msg.get("args"), limits
                )
            except CommandError as exc:
                status, answer = exc.status, {"error": exc.message}
            try:
                await send({"type": "result", "id": ident, "status": status, **answer})
            except WebSocketDisconnect:
                return  # the page went before its answer

        await send(
            {
                "type": "hello",
                "commands": describe_commands(limits),
                "keyboard": describe_keyboard(limits),
                "max_in_flight": MAX_IN_FLIGHT,
                "history": bridge.history(),
                "video": video_status(),
            }
        )
        push = asyncio.create_task(pusher())
        tasks: set[asyncio.Task[None]] = set()
        loop = asyncio.get_running_loop()
        rate = CommandRate(COMMAND_RATE_HZ, COMMAND_BURST, loop.time())
        try:
            while True:
                message = await ws.receive()
                if message["type"] == "websocket.disconnect":
                    break
                text = message.get("text")
                if text is None:
                    await ws.close(WS_UNSUPPORTED_DATA, "binary frames are not accepted on /ws")
                    break
                if len(text) > MAX_WS_MESSAGE_BYTES:
                    reason = f"message over {MAX_WS_MESSAGE_BYTES} bytes"
                    await ws.close(WS_MESSAGE_TOO_BIG, reason)
                    break
                try:
                    msg = parse_json_limited(text)
                except ValueError as exc:
                    if "nested" in str(exc):
                        reason = f"JSON nested deeper than {MAX_JSON_DEPTH} levels"
                        await ws.close(WS_POLICY_VIOLATION, reason)
                        break
                    await send({"type": "result", "id": None, "status": 400,
                                "error": f"message {exc}"})
                    continue
                if not isinstance(msg, dict) or msg.get("type") != "command":
                    await send({"type": "result", "id": None, "status": 400,
                                "error": 'expected {"type": "command", "name": ..., "args": {}}'})
                    continue
                try:  # the id is echoed in the answer, which must be JSON
                    json.dumps(msg.get("id"), allow_nan=False)
                except ValueError:
                    await send({"type": "result", "id": None, "status": 400,
                                "error": "a command's \"id\" holds NaN or Infinity, which JSON "
                                "has not (give text or a number); got "
                                f"{json.dumps(msg.get('id')):.40}"})
                    continue
                if not isinstance(msg.get("name"), str):  # (was: "unknown command 'None'")
                    await send({"type": "result", "id": msg.get("id"), "status": 400,
                                "error": "a command needs its name, text: "
                                f"\"name\": one of {', '.join(COMMANDS)}; got "
                                f"{msg.get('name')!r:.40}"})
                    continue
                ident = msg.get("id")
                if len(tasks) >= MAX_IN_FLIGHT or not rate.allow(loop.time()):
                    why = (
                        f"{MAX_IN_FLIGHT} commands of this page are still waiting for the vehicle"
                        if len(tasks) >= MAX_IN_FLIGHT
                        else f"more than {COMMAND_RATE_HZ:g} commands/s from this page"
                    )
                    await send({"type": "result", "id": ident, "status": 429,
                                "error": f"too many commands: {why}"})
                    continue
                task = asyncio.create_task(run_command(msg))
                tasks.add(task)
                task.add_done_callback(tasks.discard)
        except (WebSocketDisconnect, WebSocketDisconnected, OSError):
            pass  # the page went (a close or a reply to a page that had gone)
        finally:
            push.cancel()
            for task in list(tasks):
                task.cancel()

    @app.websocket("/ws/video")
    async def video_ws(ws: WebSocket) -> None:
        await ws.accept()
        if video is None:
            await ws.send_json({"type": "status", "state": "no video source configured"})
            await ws.close()
            return
        # The page sends nothing here, but its going (or the server closing it at a stop) is
        # read: a task that only sent waited for the next frame for good while none came (the
        # vehicle's video down), and held the server's shutdown with it.
        gone = asyncio.Event()

        async def watch() -> None:
            try:
                while (await ws.receive())["type"] != "websocket.disconnect":
                    pass  # nothing is taken from the page on /ws/video
            except (WebSocketDisconnect, WebSocketDisconnected, OSError, RuntimeError):
                pass  # closed under it (RuntimeError: receive after the disconnect)
            finally:
                gone.set()

        watcher = asyncio.create_task(watch())
        last_seq = -1
        try:
            while not gone.is_set():
                latest = video.latest()
                if latest is not None and latest.seq != last_seq:
                    last_seq = latest.seq
                    await ws.send_json(latest.meta_json())
                    await ws.send_bytes(latest.jpeg)
                else:
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(gone.wait(), 0.5 / video.fps)
        except (WebSocketDisconnect, WebSocketDisconnected, OSError):
            pass  # the page went
        finally:
            watcher.cancel()

    # HEAD wherever GET is (RFC 9110 9.3.2: the same answer without its body; uvicorn sends
    # none); FastAPI's GET routes took only GET, and `curl -I` got 405.
    for route in app.routes:
        if isinstance(route, APIRoute) and route.methods and "GET" in route.methods:
            route.methods.add("HEAD")
    return app
