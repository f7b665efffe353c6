"""The app's HTTP and WebSocket API: clear errors for bad requests, several tabs at once."""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import ExitStack

import httpx
import pytest
from fastapi.testclient import TestClient

from skeye.ground.app import create_app
from skeye.ground.bridge import VehicleBridge
from skeye.ground.guard import GroundSecurity
from tests.ground.conftest import Stack, UvicornThread, wait_until
from tests.ports import free_port as _free_port


@pytest.fixture
def offline() -> Iterator[TestClient]:
    """The app with a vehicle URI nobody listens on; the client sends the token and JSON."""
    security = GroundSecurity(allowed_hosts=("testserver",))
    headers = {"X-Skeye-Token": security.token, "Content-Type": "application/json"}
    with VehicleBridge(f"tcp://127.0.0.1:{_free_port()}", retry_s=0.2) as bridge:
        with TestClient(create_app(bridge, security=security), headers=headers) as client:
            yield client


def test_page_and_static_files_are_served_locally(offline: TestClient) -> None:
    page = offline.get("/")
    assert page.status_code == 200 and "skeye ground control" in page.text
    assert "http" not in page.text.replace("http-equiv", "")  # no CDN, nothing remote
    for name in ("app.js", "app.css"):
        assert offline.get(f"/static/{name}").status_code == 200


@pytest.mark.parametrize(
    ("path", "body", "status", "message"),
    [
        ("/api/command/take_off", b"{bad", 400, "request body is not valid JSON"),
        ("/api/command/fly", b"{}", 404, "unknown command 'fly'"),
        ("/api/command/take_off", b'{"height": 1}', 422, "unknown argument(s) height"),
        ("/api/command/velocity", b'{"up_m_s": 40}', 422, "'up_m_s' must be within [-3, 3]"),
        ("/api/command/goto_gps", b"[]", 422, "arguments must be a JSON object"),
        # within the argument's range, but 0 on the wire, where 0 means "until replaced":
        # it was a 500 from the send (and no answer on the WebSocket)
        ("/api/command/velocity", b'{"duration_s": 0.0004}', 422, "0 there means until"),
        ("/api/command/pad_mode", b'{"mode": "hold", "deadband_m": 0.0004}', 422,
         "0 there means the default"),
        ("/api/command/land", b"", 503, "no vehicle connected"),
    ],
)
def test_bad_requests_get_clear_errors(
    offline: TestClient, path: str, body: bytes, status: int, message: str
) -> None:
    r = offline.post(path, content=body)
    assert r.status_code == status
    assert message in r.json()["error"] and r.json()["status"] == status


def test_unknown_paths_and_methods_get_the_apis_error_naming_them() -> None:
    """A path or method the API lacks was answered in FastAPI's shape, ``{"detail": "Not
    Found"}``, naming neither; every other error is ``{"error", "status"}``."""
    security = GroundSecurity()
    with VehicleBridge(f"tcp://127.0.0.1:{_free_port()}", retry_s=0.2) as bridge:
        web = UvicornThread(create_app(bridge, security=security), security.token)
        try:
            r = httpx.get(f"{web.url}/api/nope", headers=web.auth, timeout=30)
            assert r.status_code == 404 and r.json() == {
                "error": "no such endpoint: GET /api/nope (the API: docs/ground.md#api)",
                "status": 404}, r.text
            r = httpx.delete(f"{web.url}/api/state", headers=web.auth, timeout=30)
            allowed = r.headers["allow"]  # in no fixed order: the route's methods are a set
            assert r.status_code == 405 and set(allowed.split(", ")) == {"GET", "HEAD"}, allowed
            assert r.json() == {"error": "DELETE /api/state: method not allowed here "
                                f"(allowed: {allowed})", "status": 405}, r.text
            r = httpx.get(f"{web.url}/static/nope.js", timeout=30)  # public, no token
            assert r.status_code == 404 and "GET /static/nope.js" in r.json()["error"]
        finally:
            web.close()


def test_state_and_video_without_a_vehicle(offline: TestClient) -> None:
    state = offline.get("/api/state").json()
    assert state["link"]["state"] in ("connecting", "disconnected")
    assert state["nav"] is None and state["video"] is None
    r = offline.get("/api/video/frame.jpg")
    assert r.status_code == 503 and "no video source" in r.json()["error"]
    # the detection said "no video frame yet", as if one were coming, on a ground control
    # without --video
    r = offline.get("/api/video/detection")
    assert r.status_code == 503 and r.json()["error"] == "no video source configured", r.text


def test_websocket_rejects_malformed_messages(offline: TestClient) -> None:
    with offline.websocket_connect("/ws") as ws:
        assert ws.receive_json()["type"] == "hello"
        ws.send_text("not json")
        while (msg := ws.receive_json())["type"] != "result":
            pass
        assert msg["status"] == 400
        ws.send_text(json.dumps({"type": "command", "id": 7, "name": "take_off",
                                 "args": {"height_m": -1}}))
        while (msg := ws.receive_json())["type"] != "result":
            pass
        assert msg["id"] == 7 and msg["status"] == 422
        assert "'height_m' must be within" in msg["error"]
        # no name: it was "unknown command 'None'" (404), as if None were a command's name
        ws.send_text(json.dumps({"type": "command", "id": 8, "args": {}}))
        while (msg := ws.receive_json())["type"] != "result":
            pass
        assert msg["id"] == 8 and msg["status"] == 400
        assert msg["error"].startswith('a command needs its name, text: "name": one of'), msg


def test_several_tabs_at_once(stack: Stack) -> None:
    from websockets.sync.client import connect

    url = stack.web.url.replace("http", "ws") + "/ws?token=" + stack.web.token
    wait_until(lambda: stack.bridge.state.value == "connected", 20, "the vehicle link")
    with ExitStack() as opened:
        tabs = [opened.enter_context(connect(url)) for _ in range(4)]
        for ws in tabs:
            assert json.loads(ws.recv(5))["type"] == "hello"
        seqs = []
        for ws in tabs:
            frames = [json.loads(ws.recv(5)) for _ in range(3)]
            assert all(f["type"] == "telemetry" for f in frames)
            assert frames[-1]["link"]["state"] == "connected"
            assert frames[-1]["nav"] is not None
            seqs.append(frames[-1]["seq"])
        assert min(seqs) > 0
        # a command from one tab is answered to that tab only
        tabs[1].send(json.dumps({"type": "command", "id": 99, "name": "hold", "args": {}}))
        while (msg := json.loads(tabs[1].recv(5)))["type"] != "result":
            pass
        assert msg["id"] == 99 and msg["status"] in (200, 409)
        if msg["status"] == 409:  # landed: the vehicle refuses HOLD, with its reason
            assert msg["code"] == 4 and msg["reason"]
        for other in (tabs[0], tabs[2], tabs[3]):
            for _ in range(3):
                assert json.loads(other.recv(5))["type"] == "telemetry"


def test_the_link_tells_of_each_failure_once_and_of_the_vehicle_coming_back() -> None:
    """``on_link`` (``skeye ground``'s terminal lines): a vehicle nobody serves is said once,
    not at each retry, and the link coming up after it is said; a pilot started on the port
    later is reached."""
    from skeye.ground.bridge import LinkState
    from skeye.pilot.airframe import AirframeOptions, open_airframe
    from skeye.pilot.server import PilotServer
    from tests.sim.conftest import running_sim

    port = _free_port()
    said: list[tuple[LinkState, str]] = []
    with VehicleBridge(f"tcp://127.0.0.1:{port}", retry_s=0.05,
                       on_link=lambda state, error: said.append((state, error))) as bridge:
        wait_until(lambda: bridge.seq >= 10, 60, "five attempts to reach the vehicle")
        assert len(said) == 1, said
        assert said[0][0] is LinkState.DISCONNECTED and "refused" in said[0][1], said
        with ExitStack() as stack:
            server = stack.enter_context(running_sim(mode="realtime"))
            airframe = open_airframe(f"sim://127.0.0.1:{server.port}", AirframeOptions())
            stack.callback(airframe.close)
            stack.enter_context(PilotServer(airframe, port=port))
            wait_until(lambda: len(said) == 2, 60, "the link up again")
            assert said[1] == (LinkState.CONNECTED, ""), said


def test_head_is_answered_where_get_is() -> None:
    """``HEAD`` (``curl -I``, uptime checks) got 405 on every page and API address, whose
    ``GET`` it is the body-less form of (RFC 9110: a general-purpose server supports both).
    It is answered as ``GET`` is, without the body."""
    security = GroundSecurity()
    with VehicleBridge(f"tcp://127.0.0.1:{_free_port()}", retry_s=0.2) as bridge:
        web = UvicornThread(create_app(bridge, security=security), security.token)
        try:
            for path in ("/", "/api/state", "/api/history", "/api/commands"):
                got = httpx.get(f"{web.url}{path}", headers=web.auth, timeout=30)
                head = httpx.head(f"{web.url}{path}", headers=web.auth, timeout=30)
                assert head.status_code == got.status_code == 200, (path, head.status_code)
                assert head.content == b"", path
                assert head.headers["content-type"] == got.headers["content-type"], path
            head = httpx.head(f"{web.url}/api/video/frame.jpg", headers=web.auth, timeout=30)
            assert head.status_code == 503, head.status_code  # no video, as GET says
            assert httpx.head(f"{web.url}/api/state", timeout=30).status_code == 401
        finally:
            web.close()


def test_a_websocket_address_asked_with_plain_http_says_so() -> None:
    """``GET /ws`` without the WebSocket upgrade (a curl, a link opened in the browser) was
    answered ``no such endpoint: GET /ws``, which it is. It is now 426 Upgrade Required,
    naming it a WebSocket endpoint."""
    security = GroundSecurity()
    with VehicleBridge(f"tcp://127.0.0.1:{_free_port()}", retry_s=0.2) as bridge:
        web = UvicornThread(create_app(bridge, security=security), security.token)
        try:
            for path in ("/ws", "/ws/video"):
                r = httpx.get(f"{web.url}{path}", headers=web.auth, timeout=30)
                assert r.status_code == 426 and r.headers["upgrade"] == "websocket", r.text
                assert r.json() == {"error": f"GET {path}: a WebSocket endpoint: open it as "
                                    "one (ws://, with the upgrade), not with plain HTTP",
                                    "status": 426}, r.text
            r = httpx.get(f"{web.url}/wsx", headers=web.auth, timeout=30)
            assert r.status_code == 404  # not every unknown path
        finally:
            web.close()
