"""Ground control's camera view comes from the vehicle: ``/ws/video`` and
``/api/video/detection`` show the frames and the detections the pilot served on its video port,
byte for byte, with the pad in view; ground control runs no detector of its own."""

from __future__ import annotations

import json
import subprocess
import sys
import threading

import httpx
from websockets.sync.client import connect as ws_connect

from skeye.ground.video import frame_detection_json
from skeye.wire.video import Frame
from tests.ground.conftest import Stack, wait_until
from tests.pilot.test_video_server import Viewer

DETECTION_KEYS = {"found", "center_px", "height_m", "offset_cam_m", "offset_body_m", "rings",
                  "quality", "ellipses", "tilt_compensated"}


def _command(stack: Stack, name: str, args: dict[str, object]) -> int:
    r = httpx.post(f"{stack.web.url}/api/command/{name}", json=args,
                   headers={**stack.web.auth, "Origin": stack.web.url}, timeout=60)
    return r.status_code


def test_the_page_shows_what_the_vehicle_saw_and_detected(stack: Stack) -> None:
    wait_until(lambda: stack.bridge.state.value == "connected", 60, "the vehicle link")
    wait_until(lambda: stack.bridge.snapshot()["nav"] is not None
               and stack.bridge.snapshot()["nav"]["state"] == "landed", 120, "landed")
    served: dict[int, Frame] = {}
    viewer = Viewer(stack.pilot.video_port)  # beside ground control, straight from the pilot

    def read() -> None:
        try:
            while True:
                msg = viewer.next()
                if isinstance(msg, Frame):
                    served[msg.frame_number] = msg
        except (EOFError, OSError):
            pass

    threading.Thread(target=read, daemon=True).start()
    assert _command(stack, "take_off", {"height_m": 1.0}) == 200
    url = f"ws://127.0.0.1:{stack.web.port}/ws/video?token={stack.web.token}"
    try:
        with ws_connect(url, open_timeout=30) as ws:
            matched = 0
            while matched < 3:
                meta = json.loads(ws.recv(60))
                assert meta["type"] == "frame"
                jpeg = ws.recv(60)
                assert isinstance(jpeg, bytes) and len(jpeg) == meta["bytes"]
                assert set(meta["detection"]) >= DETECTION_KEYS
                frame = served.get(meta["frame_number"])
                if frame is None or not frame.detection.found:
                    continue  # not (yet) seen by this viewer, or the pad not yet in view
                # Exactly what the vehicle sent: its JPEG, its detection, its times.
                assert jpeg == frame.jpeg
                assert meta["detection"] == frame_detection_json(frame)
                assert meta["detection"]["tilt_compensated"] is True
                assert len(meta["detection"]["ellipses"]) >= 2
                assert meta["sim_time_s"] == frame.time_s
                assert (meta["width"], meta["height"]) == (frame.width, frame.height) == (320, 240)
                assert meta["detect_ms"] == round(frame.detect_ms, 1)
                matched += 1
        latest = httpx.get(f"{stack.web.url}/api/video/detection", headers=stack.web.auth,
                           timeout=30).json()
        assert latest["type"] == "frame" and set(latest["detection"]) >= DETECTION_KEYS
        state = httpx.get(f"{stack.web.url}/api/state", headers=stack.web.auth, timeout=30).json()
        video = state["video"]
        assert video["source"] == f"tcp://127.0.0.1:{stack.pilot.video_port}"
        assert video["state"] == "streaming" and video["camera"].endswith("/Down")
    finally:
        viewer.close()
        assert _command(stack, "land", {}) == 200
        wait_until(lambda: stack.bridge.snapshot()["nav"]["state"] == "landed", 120,
                   "landed again")


def test_ground_control_imports_no_detector_and_no_image_client() -> None:
    code = ("import sys, skeye.ground.video, skeye.ground.app, skeye.ground.cli; "
            "bad = [m for m in sys.modules if m.startswith(('skeye.vision', 'skeye.sim'))]; "
            "print(','.join(bad))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "", done.stdout


def test_a_bad_video_address_is_named(capsys) -> None:
    from skeye.cli import main

    for uri in ("udp://127.0.0.1:7001", "tcp://127.0.0.1", "tcp://127.0.0.1:99999"):
        assert main(["ground", "--vehicle", "tcp://127.0.0.1:1", "--video", uri,
                     "--port", "0"]) == 2
        err = capsys.readouterr().err
        assert f"video source {uri!r}: expected tcp://host:port" in err, err


def test_the_relay_names_a_bad_video_source_and_keeps_trying() -> None:
    """Something that is not a vehicle's video port: the relay says why and reconnects."""
    import socket

    from skeye.ground.video import VideoRelay

    with socket.create_server(("127.0.0.1", 0)) as fake:
        port = fake.getsockname()[1]
        with VideoRelay("127.0.0.1", port, retry_s=0.1, timeout_s=30) as relay:
            for n in (1, 2):  # two connections: it came back after the first failure
                conn, _ = fake.accept()
                conn.settimeout(30)
                assert conn.recv(64).startswith(b"SV")  # its SUBSCRIBE
                conn.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")
                conn.close()
                wait_until(lambda n=n: relay.failures == n, 30, "the relay to give up")
                assert "not a skeye video stream" in relay.last_error
            assert relay.latest() is None and relay.frames == 0
            relay.check()  # its worker is alive and well


def test_a_vehicle_that_trickles_bytes_without_a_whole_message_is_timed_out() -> None:
    """A stalled or misbehaving vehicle that sends HELLO, then a frame one byte at a time, each
    byte well within the timeout: the relay waited for it for ever ("waiting for frames", no
    error); now the timeout is for whole messages, and it says what it was waiting for."""
    import socket

    from skeye.ground.video import VideoRelay
    from skeye.wire.video import MAGIC, PREFIX, VERSION, Hello, MsgType, encode

    done = threading.Event()
    with socket.create_server(("127.0.0.1", 0)) as fake:
        port = fake.getsockname()[1]
        with VideoRelay("127.0.0.1", port, retry_s=0.1, timeout_s=1.0) as relay:
            conn, _ = fake.accept()
            conn.settimeout(30)
            assert conn.recv(64).startswith(b"SV")  # its SUBSCRIBE
            conn.sendall(encode(Hello("R1/Down", 1.0, 80, 10.0)))
            conn.sendall(PREFIX.pack(MAGIC, VERSION, MsgType.FRAME, 100, 100_000))

            def trickle() -> None:
                try:
                    while not done.wait(0.1):
                        conn.sendall(b" ")
                except OSError:
                    pass  # the relay gave up and closed

            sender = threading.Thread(target=trickle, daemon=True)
            sender.start()
            try:
                wait_until(lambda: relay.failures >= 1, 60, "the relay to time the vehicle out")
                assert "bytes of an unfinished message" in relay.last_error, relay.last_error
                assert relay.frames == 0
                relay.check()
            finally:
                done.set()
                sender.join(30)
                conn.close()


def test_ground_stops_after_video_pages_came_and_went_while_no_frame_came(tmp_path) -> None:
    """``/ws/video`` only sent, never read: a page that closed it while no frame came (the
    vehicle's video down) left its task waiting for a frame for good, and so did an open page
    at the stop. SIGTERM then hung ``skeye ground`` for good (uvicorn waits for every task;
    under ``skeye up``, 10 s, then SIGKILL). Each page's task now ends when its page goes, or
    when the server closes it."""
    import os
    import signal

    from tests.ports import free_ports

    port, video_port = free_ports(2)  # nothing serves video there
    env = {**os.environ, "SKEYE_GROUND_TOKEN": "t" * 32}
    child = subprocess.Popen(
        [sys.executable, "-m", "skeye.cli", "ground", "--vehicle", "tcp://127.0.0.1:1",
         "--video", f"tcp://127.0.0.1:{video_port}", "--port", str(port)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
        env=env)
    try:
        assert child.stdout is not None
        said = ""
        while "?token=" not in said:
            line = child.stdout.readline()
            assert line, said
            said += line
        url = f"ws://127.0.0.1:{port}/ws/video?token={'t' * 32}"
        for _ in range(3):  # pages that came and went
            with ws_connect(url, open_timeout=60):
                pass
        with ws_connect(url, open_timeout=60):  # a page still open at the stop
            child.send_signal(signal.SIGTERM)
            rest, _ = child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(30)
    assert child.returncode == 0 and rest.endswith("skeye ground: stopped\n"), (said, rest)
