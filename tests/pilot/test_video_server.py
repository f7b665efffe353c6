"""The pilot's video port (skeye.pilot.video_server) over real loopback sockets: frames with
detections to subscribers; garbage, idle, surplus and slow clients dealt with, others unharmed;
``publish`` never waits."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator

import numpy as np
import pytest

from skeye.errors import ConfigError
from skeye.pilot.video_server import CameraFrame, VideoServer
from skeye.wire.video import (
    Detection,
    Error,
    Frame,
    Hello,
    RingEllipse,
    Role,
    Subscribe,
    VideoConnection,
)
from tests.ground.conftest import wait_until

DETECTION = Detection(
    True, center_px=(160.5, 120.25), height_m=1.2, offset_cam_m=(0.1, -0.05),
    offset_body_m=(0.05, 0.1), rings=(1, 2),
    ellipses=(RingEllipse(1, "outer", (160.5, 120.25), (80.0, 79.0), 0.1),),
    quality=0.9, roll_rad=0.01, pitch_rad=-0.02,
)


def _frame(n: int, rng: np.random.Generator, shape: tuple[int, int] = (240, 320)) -> CameraFrame:
    bgr = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)  # noise: JPEGs of ~100 kB and up
    return CameraFrame(n, n * 0.1, bgr, DETECTION if n % 2 else Detection(False), 2.5)


class Viewer:
    """A test client: subscribes, then reads messages (blocking, with a timeout)."""

    def __init__(self, port: int, max_fps: float = 100.0, subscribe: bool = True) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=60)
        self.conn = VideoConnection(Role.CLIENT)
        self.pending: list[object] = []
        if subscribe:
            self.sock.sendall(self.conn.send(Subscribe(max_fps)))

    def next(self) -> object:
        while not self.pending:
            data = self.sock.recv(1 << 20)
            if not data:
                raise EOFError("closed by the server")
            self.pending += self.conn.receive_data(data)
        return self.pending.pop(0)

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def server() -> Iterator[VideoServer]:
    with VideoServer(port=0, camera="R1/Down", fov_h_rad=1.309, max_fps=1000.0, max_clients=3,
                     subscribe_timeout_s=1.0, send_timeout_s=2.0) as s:
        yield s


def _publish_until(server: VideoServer, pred, what: str, rng: np.random.Generator,
                   start: int = 1) -> int:
    n = start
    holder = {"n": n}

    def step() -> bool:
        server.publish(_frame(holder["n"], rng))
        holder["n"] += 1
        return bool(pred())

    wait_until(step, 60, what, poll_s=0.02)
    return holder["n"]


def test_a_subscriber_gets_hello_then_frames_with_their_detection(server: VideoServer) -> None:
    rng = np.random.default_rng(1)
    viewer = Viewer(server.port)
    try:
        hello = viewer.next()
        assert hello == Hello("R1/Down", 1.309, 80, 1000.0)
        got: list[Frame] = []
        stop = threading.Event()

        def read() -> None:
            while len(got) < 4:
                msg = viewer.next()
                assert isinstance(msg, Frame)
                got.append(msg)
            stop.set()

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        _publish_until(server, stop.is_set, "4 frames to a subscriber", rng)
        reader.join(60)
        for frame in got:
            assert frame.jpeg.startswith(b"\xff\xd8") and (frame.width, frame.height) == (320, 240)
            assert frame.time_s == pytest.approx(frame.frame_number * 0.1)
            assert frame.detection == (DETECTION if frame.frame_number % 2 else Detection(False))
            assert frame.detect_ms == 2.5
        numbers = [f.frame_number for f in got]
        assert numbers == sorted(set(numbers))  # newer frames only, never one twice
    finally:
        viewer.close()


def test_garbage_gets_an_error_and_others_are_not_touched(server: VideoServer) -> None:
    rng = np.random.default_rng(2)
    good = Viewer(server.port)
    assert isinstance(good.next(), Hello)
    for garbage in (b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", b"SV\x01\x02" + b"\0" * 8,
                    b"\x00" * 64):
        bad = socket.create_connection(("127.0.0.1", server.port), timeout=60)
        bad.sendall(garbage)
        conn = VideoConnection(Role.CLIENT)
        conn.send(Subscribe(1.0))  # as if it had subscribed: it may now read ERROR
        data = b""
        while chunk := bad.recv(4096):
            data += chunk
        msgs = conn.receive_data(data)
        assert len(msgs) == 1 and isinstance(msgs[0], Error), msgs
        assert "not the skeye video protocol" in msgs[0].reason
        bad.close()
    assert server.bad_clients == 3
    got = threading.Event()
    threading.Thread(target=lambda: (good.next(), got.set()), daemon=True).start()
    _publish_until(server, got.is_set, "a frame to the good client after the garbage", rng)
    good.close()


def test_a_bad_message_during_a_frame_gets_its_error_after_the_frame(
        server: VideoServer) -> None:
    """A viewer that sends a bad SUBSCRIBE while a frame to it is still under way receives the
    rest of that frame and then the ERROR, whole: the ERROR used to be sent at once, in the
    middle of the frame's JPEG, and the frame was cut there, so its reason was lost."""
    rng = np.random.default_rng(5)
    viewer = Viewer(server.port)
    viewer.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    assert isinstance(viewer.next(), Hello)
    n = 1

    def under_way() -> bool:
        nonlocal n
        clients = server.clients()
        if clients and clients[0].frames_sent >= 1 and clients[0].buffered_bytes > 0:
            return True
        server.publish(_frame(n, rng, (480, 640)))  # noise: JPEGs far over the socket buffers
        n += 1
        return False

    wait_until(under_way, 60, "a frame under way to a viewer that does not read", poll_s=0.05)
    header = b'{"max_fps": 0}'  # a bad field: the rate is 0.01..1000
    viewer.sock.sendall(b"SV\x01\x04" + len(header).to_bytes(4, "big") + bytes(4) + header)
    wait_until(lambda: server.bad_clients == 1, 30, "the bad SUBSCRIBE refused")
    data = b""
    while chunk := viewer.sock.recv(1 << 20):
        data += chunk
    msgs = viewer.conn.receive_data(data)
    assert [type(m) for m in msgs] == [Frame, Error], msgs
    assert isinstance(msgs[1], Error) and "not the skeye video protocol" in msgs[1].reason
    assert "max_fps" in msgs[1].reason
    viewer.close()


def test_idle_and_surplus_clients_are_closed_with_a_reason(server: VideoServer) -> None:
    idle = socket.create_connection(("127.0.0.1", server.port), timeout=60)
    viewer = Viewer(server.port)
    assert isinstance(viewer.next(), Hello)
    wait_until(lambda: len(server.clients()) == 2, 30, "two clients")
    conn = VideoConnection(Role.CLIENT)
    conn.send(Subscribe(1.0))
    data = b""
    while chunk := idle.recv(4096):  # closed after subscribe_timeout_s
        data += chunk
    (error,) = conn.receive_data(data)
    assert isinstance(error, Error) and "no SUBSCRIBE within 1 s" in error.reason
    assert server.idle_closed == 1
    wait_until(lambda: len(server.clients()) == 1, 30, "the idle client gone")
    # One user holds all slots but one (2 of 3): with two viewers, a third of the same user is
    # turned away, naming the cap.
    second = Viewer(server.port)
    assert isinstance(second.next(), Hello)
    wait_until(lambda: sum(c.state == "streaming" for c in server.clients()) == 2, 30,
               "two viewers")
    surplus = Viewer(server.port)
    msg = surplus.next()
    assert isinstance(msg, Error) and "busy" in msg.reason and "2 of" in msg.reason, msg
    assert server.turned_away == 1
    for c in (idle, surplus, viewer, second):
        c.close()


def test_a_connection_that_never_subscribes_gives_its_slot_to_a_viewer(
        server: VideoServer) -> None:
    """Idle connections (from however many loopback addresses) never keep a viewer out: at its
    cap, a user's new connection takes the place of its oldest one that has not subscribed."""
    idle = [socket.create_connection(("127.0.0.1", server.port), timeout=60) for _ in range(2)]
    wait_until(lambda: len(server.clients()) == 2, 30, "two idle connections")
    viewer = Viewer(server.port)
    assert isinstance(viewer.next(), Hello)
    conn = VideoConnection(Role.CLIENT)
    conn.send(Subscribe(1.0))
    data = b""
    while chunk := idle[0].recv(4096):  # the oldest: replaced at once
        data += chunk
    (error,) = conn.receive_data(data)
    assert isinstance(error, Error) and "replaced by a newer connection" in error.reason
    assert server.turned_away == 0
    for c in (*idle, viewer):
        c.close()


def test_a_slow_client_misses_frames_and_never_holds_up_publish_or_others(
    server: VideoServer,
) -> None:
    rng = np.random.default_rng(3)
    slow = Viewer(server.port)  # subscribes, then never reads again
    slow.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    fast = Viewer(server.port)
    assert isinstance(fast.next(), Hello)
    received: list[int] = []

    def read() -> None:
        try:
            while True:
                msg = fast.next()
                if isinstance(msg, Frame):
                    received.append(msg.frame_number)
        except (EOFError, OSError):
            pass

    threading.Thread(target=read, daemon=True).start()

    def slow_stats():
        return next((c for c in server.clients() if c.peer.endswith(
            str(slow.sock.getsockname()[1]))), None)

    n = _publish_until(server, lambda: (s := slow_stats()) is not None and s.dropped >= 10
                       and len(received) >= 10, "the slow client missing 10 frames", rng)
    # Every publish returned (this thread was never held up), and the fast client kept up.
    assert server.published == n - 1
    assert received == sorted(set(received))
    # The slow client is closed once it took nothing for send_timeout_s; the fast one stays.
    _publish_until(server, lambda: server.slow_closed == 1, "the slow client closed", rng, n)
    before = len(received)
    _publish_until(server, lambda: len(received) > before + 3, "frames to the fast client", rng,
                   n + 1000)
    fast.close()
    slow.close()


def test_bad_settings_are_config_errors() -> None:
    with pytest.raises(ConfigError, match="jpeg_quality"):
        VideoServer(port=0, fov_h_rad=1.0, jpeg_quality=0)
    with pytest.raises(ConfigError, match="max_clients"):
        VideoServer(port=0, fov_h_rad=1.0, max_clients=0)


def test_close_is_idempotent_and_frees_the_port() -> None:
    server = VideoServer(port=0, fov_h_rad=1.0).start()
    port = server.port
    server.close()
    server.close()
    with socket.create_server(("127.0.0.1", port)):
        pass


def test_a_frame_that_cannot_be_served_is_skipped(server: VideoServer) -> None:
    rng = np.random.default_rng(4)
    viewer = Viewer(server.port)
    assert isinstance(viewer.next(), Hello)
    bad = CameraFrame(1, -1.0, np.zeros((8, 8, 3), np.uint8), Detection(False), 0.0)  # time < 0
    server.publish(bad)
    wait_until(lambda: server.bad_frames == 1, 30, "the bad frame refused")
    got = threading.Event()
    frames: list[Frame] = []
    threading.Thread(target=lambda: (frames.append(viewer.next()), got.set()),  # type: ignore[func-returns-value]
                     daemon=True).start()
    _publish_until(server, got.is_set, "a good frame after the bad one", rng, start=2)
    assert isinstance(frames[0], Frame) and frames[0].frame_number >= 2
    server.check()  # the server's thread lives on
    viewer.close()
