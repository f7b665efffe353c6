"""The pilot's camera as H.264 over RTP (QGroundControl's UDP 5600 convention), decoded by a
third-party decoder (FFmpeg, through PyAV) from the session description the module gives."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

av = pytest.importorskip("av")

from skeye.errors import ConfigError  # noqa: E402
from skeye.pilot.rtp_video import RtpVideo, check_rtp_destination, overlay  # noqa: E402
from skeye.pilot.video_server import CameraFrame  # noqa: E402
from skeye.wire.video import Detection, RingEllipse  # noqa: E402
from tests.mavlink.conftest import free_udp_port  # noqa: E402


def test_ffmpeg_decodes_the_stream_with_the_detection_drawn(tmp_path: Path):
    video = RtpVideo(f"udp://127.0.0.1:{free_udp_port()}", max_fps=10.0).start()
    sdp = tmp_path / "skeye.sdp"
    sdp.write_text(video.sdp())
    frames: list[np.ndarray] = []

    def play() -> None:
        player = av.open(str(sdp), format="sdp", timeout=10,
                         options={"protocol_whitelist": "file,udp,rtp",
                                  "analyzeduration": "200000", "probesize": "4096"})
        for frame in player.decode(video=0):
            frames.append(frame.to_ndarray(format="bgr24"))
            if len(frames) >= 5:
                break
        player.close()

    player = threading.Thread(target=play, daemon=True)
    player.start()  # it opens on the stream's first packets (a key frame comes every second)
    found = Detection(True, (160.0, 120.0), 1.5, (0.0, 0.0), (0.0, 0.0))
    deadline = time.monotonic() + 60  # a stuck guard: 5 frames take about a second
    k = 0
    while len(frames) < 5 and time.monotonic() < deadline:
        grey = np.full((240, 320, 3), 90, np.uint8)
        video.publish(CameraFrame(k, k * 0.1, grey, found, 3.0))
        k += 1
        time.sleep(0.05)
    player.join(10)
    video.close()
    assert len(frames) >= 5 and frames[-1].shape == (240, 320, 3)
    b, g, r = (int(c) for c in frames[-1][120, 160])
    assert r > 150 and g < 80 and b < 80  # the red cross on the pad's centre
    assert abs(int(frames[-1][200, 40].mean()) - 90) < 10  # the picture itself
    assert video.frames_sent >= 5


def test_only_udp_uris_are_taken():
    with pytest.raises(ConfigError, match="udp://HOST:PORT"):
        RtpVideo("tcp://127.0.0.1:5600")


def test_a_destination_it_cannot_send_to_is_named_at_start(monkeypatch: pytest.MonkeyPatch):
    # FFmpeg opened the destination only on the first frame, in the worker: the pilot flew on
    # and then stopped on "pilot-rtp-video failed: OSError: [Errno 5] Input/output error".
    with pytest.raises(ConfigError, match="port 1-65535"):
        RtpVideo("udp://127.0.0.1:0")
    with pytest.raises(ConfigError, match=r"255\.255\.255\.255 port 5600: .*broadcast"):
        RtpVideo("udp://255.255.255.255:5600")

    def no_such_host(*args: object, **kwargs: object) -> None:
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", no_such_host)
    with pytest.raises(ConfigError, match=r"cannot resolve the host 'groundstation\.invalid'"):
        RtpVideo("udp://groundstation.invalid:5600")


def test_the_host_is_resolved_within_a_bounded_wait(monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]):
    """The system resolver takes no timeout (with a DNS server unreachable it can take minutes):
    the start check waits at most ``RESOLVE_TIMEOUT_S`` and names the host and the wait."""
    import argparse

    from skeye.pilot import cli as pilot_cli
    from skeye.pilot import rtp_video

    host, port, ip = check_rtp_destination("udp://localhost:5600", timeout_s=5.0)
    assert (host, port) == ("localhost", 5600) and ip in ("127.0.0.1", "::1")
    released = threading.Event()
    resolver = socket.getaddrinfo

    def unreachable_dns(host: str, *args: object, **kwargs: object) -> object:
        if host != "gcs.example":
            return resolver(host, *args, **kwargs)  # type: ignore[arg-type]
        released.wait(30)  # the OS resolver retrying a DNS server that does not answer
        raise socket.gaierror(socket.EAI_AGAIN, "Temporary failure in name resolution")

    monkeypatch.setattr(socket, "getaddrinfo", unreachable_dns)
    try:
        with pytest.raises(ConfigError, match=r"udp://gcs\.example:5600: the host 'gcs\.example' "
                           r"did not resolve within 0\.2 s"):
            check_rtp_destination("udp://gcs.example:5600", timeout_s=0.2)
        # The pilot's start check: exit status 2, the line names the host and the wait.
        monkeypatch.setattr(rtp_video, "RESOLVE_TIMEOUT_S", 0.2)
        parser = argparse.ArgumentParser(prog="skeye")
        pilot_cli.register(parser.add_subparsers(dest="cmd", required=True))
        args = parser.parse_args(["pilot", "--sim", "127.0.0.1:1", "--images", "127.0.0.1:1",
                                  "--rtp-video", "udp://gcs.example:5600"])
        assert pilot_cli.run(args) == 2
        err = capsys.readouterr().err
        assert ("skeye pilot: error: --rtp-video: udp://gcs.example:5600: the host "
                "'gcs.example' did not resolve within 0.2 s") in err, err
    finally:
        released.set()  # the resolver threads left behind end


def _sends_rtp(video: RtpVideo, receiver: socket.socket) -> None:
    """A frame published reaches ``receiver`` as RTP (version 2, payload type 96)."""
    grey = np.full((240, 320, 3), 90, np.uint8)
    video.publish(CameraFrame(0, 0.0, grey, Detection(False), 3.0))
    packet = receiver.recv(2048)  # the first RTP packet
    assert packet[0] >> 6 == 2 and packet[1] & 0x7F == 96
    video.check()


def test_an_ipv6_destination_is_streamed():
    if not socket.has_ipv6:
        pytest.skip("no IPv6 here")
    with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as receiver:
        try:
            receiver.bind(("::1", 0))
        except OSError:
            pytest.skip("no ::1 here")
        receiver.settimeout(60)
        port = receiver.getsockname()[1]
        video = RtpVideo(f"udp://[::1]:{port}", max_fps=10.0).start()
        try:
            assert video.address == f"udp://[::1]:{port}"
            assert "c=IN IP6 ::1" in video.sdp()
            _sends_rtp(video, receiver)  # (was: the worker died)
        finally:
            video.close()


def test_the_stream_goes_to_the_address_resolved_at_start(monkeypatch: pytest.MonkeyPatch):
    """The name is resolved once, at start, within the bounded wait: FFmpeg is given the
    address, not the name (it resolved it again, unbounded, on the first frame, through its
    own resolver: here one that does not know the name, so no packet ever went out)."""
    resolver = socket.getaddrinfo

    def gcs_is_loopback(host: str, *args: object, **kwargs: object) -> object:
        return resolver("127.0.0.1" if host == "gcs.invalid" else host, *args, **kwargs)

    monkeypatch.setattr(socket, "getaddrinfo", gcs_is_loopback)  # Python's resolver only
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(60)
        port = receiver.getsockname()[1]
        video = RtpVideo(f"udp://gcs.invalid:{port}", max_fps=10.0).start()
        try:
            assert video.address == f"udp://gcs.invalid:{port}"
            assert "c=IN IP4 127.0.0.1" in video.sdp()
            _sends_rtp(video, receiver)
        finally:
            video.close()


def test_a_detection_too_far_out_to_draw_neither_kills_the_video_nor_hides_the_rest():
    """A Detection's figures are checked finite only; an ellipse or centre beyond a C int
    made OpenCV's drawing raise, the RTP worker died with it, and so did the pilot (it stops
    with a worker's error). Such a shape is left out; the rest is drawn."""
    far = RingEllipse(1, "outer", (1e12, 5.0), (3.0, 2.0), 0.0)
    huge = RingEllipse(1, "inner", (100.0, 100.0), (1e12, 1e12), 0.0)
    near = RingEllipse(2, "outer", (40.0, 30.0), (10.0, 8.0), 0.0)
    det = Detection(True, center_px=(-1e15, 0.0), height_m=1.0, offset_cam_m=(0.0, 0.0),
                    offset_body_m=(0.0, 0.0), rings=(1, 2), ellipses=(far, huge, near),
                    quality=0.5)
    black = np.zeros((60, 80, 3), np.uint8)
    img = overlay(CameraFrame(1, 0.0, black, det, 1.0))
    assert img[30, 30:51, 1].max() > 0  # the ring that fits is drawn (green)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(60)
        video = RtpVideo(f"udp://127.0.0.1:{receiver.getsockname()[1]}", max_fps=10.0).start()
        try:
            video.publish(CameraFrame(1, 0.0, np.zeros((240, 320, 3), np.uint8), det, 1.0))
            packet = receiver.recv(2048)
            assert packet[0] >> 6 == 2 and packet[1] & 0x7F == 96
            video.check()
        finally:
            video.close()
