"""The pilot's camera sources by URI (skeye.pilot.camera): sim://, file://, v4l2://.

- Conformance: every source announces frames with increasing numbers and capture times on the
  vehicle's clock, gives their pixels, and reports a camera that gives none by name.
- A recorded video of the simulated pad (``file://``) gives the very detections the live frames
  gave (lossless FFV1), or ones within a few millimetres (MP4).
- ``v4l2://``: its settings from the URI (a unit test), and a real device where one exists
  (skipped, saying so, where none does).
- A camera that goes away mid-flight is reported, and the pad modes hold still.
"""

from __future__ import annotations

import contextlib
import glob
import math
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from skeye.control.connection import connect
from skeye.errors import LocalProtocolError
from skeye.pilot.camera import (
    CameraError,
    CameraOptions,
    CameraSource,
    check_camera_uri,
    open_camera,
)
from skeye.pilot.camera_file import parse_file_camera
from skeye.pilot.camera_sim import parse_sim_camera
from skeye.pilot.camera_v4l2 import V4l2Settings, parse_v4l2_uri
from skeye.vision.detector import PadEstimate, detect
from tests.sim.conftest import LineClient
from tests.sim.test_cameras import sim_with_images, small_camera_robot


class FakeClock:
    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


@pytest.fixture(scope="module")
def live() -> Iterator[dict]:
    """A lockstep simulator with its image server, and a robot climbing over the pad while
    frames of its camera are kept (pixels, sim time, attitude, FOV)."""
    with ExitStack() as stack:
        control, images, _ = stack.enter_context(sim_with_images(mode="lockstep",
                                                                 estimator="truth"))
        sim = stack.enter_context(connect(f"127.0.0.1:{control.port}",
                                          images=f"127.0.0.1:{images.port}"))
        robot = sim.spawn("hummingbird", location_ned_m=(0.25, -0.15, 0.0))
        fov = sim.request("GETCONF", ("Type", "Camera"), ("Name", "Down")).get_float("FOV")
        robot.take_off(1.0)
        robot.set_velocity(0.0, 0.0, 0.3, 0.0, duration_s=None, wait=False)
        frames = []
        for _ in range(12):
            sim.run_for(0.1)
            image = robot.camera.image()
            roll, pitch, _ = robot.ins.latest.rpy_rad
            frames.append((image, roll, pitch))
        yield {"frames": frames, "fov": fov, "images": images.port, "sim": sim}


def detections(images: list[np.ndarray], attitude: list[tuple[float, float]], fov: float
               ) -> list[PadEstimate]:
    """The pilot's detection (vision.py: grey, then the detector) of each frame."""
    return [detect(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), fov, roll_rad=r, pitch_rad=p)
            for img, (r, p) in zip(images, attitude, strict=True)]


def record(path: Path, frames: list[np.ndarray], fourcc: str, fps: float = 10.0) -> None:
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*fourcc), fps, (w, h))
    assert writer.isOpened(), f"this OpenCV cannot write {fourcc}"
    for f in frames:
        writer.write(f)
    writer.release()


def read_all(source: CameraSource, clock: FakeClock, n: int, period_s: float) -> list:
    out = []
    for _ in range(n):
        info = source.latest
        assert info is not None
        image = source.image()
        assert image.frame == info.frame and image.time_s == pytest.approx(info.time_s)
        out.append(image)
        clock.t += period_s
    return out


@pytest.mark.parametrize(("suffix", "fourcc", "exact"), [(".mkv", "FFV1", True),
                                                         (".mp4", "mp4v", False)])
def test_a_recorded_video_gives_the_live_detections(live, tmp_path, suffix, fourcc, exact):
    frames = [img.bgr for img, _, _ in live["frames"]]
    attitude = [(r, p) for _, r, p in live["frames"]]
    fov = live["fov"]
    path = tmp_path / f"pad{suffix}"
    record(path, frames, fourcc)
    clock = FakeClock(100.0)
    source = open_camera(f"file://{path}?fov_rad={fov!r}", CameraOptions(clock=clock))
    try:
        assert source.fov_h_rad == fov
        played = read_all(source, clock, len(frames), 0.1)
    finally:
        source.close()
    assert [p.frame for p in played] == list(range(1, len(frames) + 1))
    assert [p.time_s for p in played] == pytest.approx([100.0 + 0.1 * i for i in range(12)])
    live_found = detections(frames, attitude, fov)
    file_found = detections([p.bgr for p in played], attitude, fov)
    assert sum(d.found for d in live_found) >= 10
    for a, b in zip(live_found, file_found, strict=True):
        assert a.found == b.found and a.rings == b.rings
        if not a.found:
            continue
        if exact:
            assert a == b  # the same pixels: the same detection, bit for bit
        else:  # MP4's compression moves ring edges by a fraction of a pixel
            assert b.height_m == pytest.approx(a.height_m, abs=0.01)
            assert math.dist(a.offset_body_m, b.offset_body_m) < 0.005


def test_a_video_is_paced_at_its_frame_rate_and_its_end_is_said(tmp_path):
    frames = [np.full((48, 64, 3), i * 20, np.uint8) for i in range(5)]
    path = tmp_path / "five.mkv"
    record(path, frames, "FFV1", fps=25.0)
    clock = FakeClock(7.0)
    source = open_camera(f"file://{path}", CameraOptions(clock=clock))
    assert source.latest.frame == 1 and source.latest.time_s == 7.0
    clock.t = 7.0 + 0.09  # 2.25 frames later: frame 3 is due, 2 was never looked at
    image = source.image()
    assert image.frame == 3 and image.time_s == pytest.approx(7.08)
    assert int(image.bgr.mean()) == 40
    clock.t = 7.0 + 0.5  # past the end
    with pytest.raises(CameraError, match="ended after 5 frames"):
        source.image()
    assert source.lost is not None and "ended" in source.lost
    source.close()


def test_a_video_can_loop(tmp_path):
    frames = [np.full((48, 64, 3), i * 20, np.uint8) for i in range(4)]
    path = tmp_path / "four.mkv"
    record(path, frames, "FFV1", fps=10.0)
    clock = FakeClock(0.0)
    source = open_camera(f"file://{path}?loop=1", CameraOptions(clock=clock))
    assert source.latest.frame == 1
    clock.t = 0.55  # frame 6: the second pass's second frame
    image = source.image()
    assert image.frame == 6 and int(image.bgr.mean()) == 20 and source.lost is None
    source.close()


def test_a_photo_can_loop(tmp_path):
    """A photo with loop=1 (a still given to the pilot for as long as it runs): the loop
    seeked back to frame 0, which OpenCV's reader of a single image ignores, so the photo was
    shown once and the camera then said "the video ended after 0 frames". The file is now
    opened again at each end, as for any video whose seek does not take."""
    picture = np.zeros((48, 64, 3), np.uint8)
    picture[:, 32:] = 200
    path = tmp_path / "still.png"
    cv2.imwrite(str(path), picture)
    clock = FakeClock(3.0)
    source = open_camera(f"file://{path}?fps=10&loop=1", CameraOptions(clock=clock))
    try:
        played = read_all(source, clock, 4, 0.1)
        assert [p.frame for p in played] == [1, 2, 3, 4]
        assert [p.time_s for p in played] == pytest.approx([3.0, 3.1, 3.2, 3.3])
        assert all(np.array_equal(p.bgr, picture) for p in played) and source.lost is None
        clock.t = 3.0 + 100.0  # the vision busy for 100 s: frame 1001 is due
        image = source.image()
        assert image.frame == 1001 and image.time_s == pytest.approx(103.0)
        assert np.array_equal(image.bgr, picture) and source.lost is None
    finally:
        source.close()


def test_the_sim_camera_from_the_image_server_alone(live):
    clock = FakeClock(0.0)
    fov = live["fov"]
    source = open_camera(f"sim://127.0.0.1:{live['images']}/R1/Down?fov_rad={fov!r}",
                         CameraOptions(clock=clock, clock_is_sim=True))
    try:
        info = source.latest
        newest = live["frames"][-1][0]
        assert info is not None and info.frame == newest.frame and info.time_s == newest.time_s
        image = source.image()
        assert image.frame == newest.frame and np.array_equal(image.bgr, newest.bgr)
        assert source.fov_h_rad == fov and source.lost is None
    finally:
        source.close()


def test_a_sim_camera_on_another_clock_maps_the_frame_times(live):
    clock = FakeClock(1000.0)
    source = open_camera(f"sim://127.0.0.1:{live['images']}/R1/Down",
                         CameraOptions(clock=clock, clock_is_sim=False))
    try:
        image = source.image()
        assert image.time_s == pytest.approx(1000.0)  # received now, on the vehicle's clock
    finally:
        source.close()


class HeldProxy:
    """A TCP relay to a server whose answers can be held back (``hold``/``release``): what a
    client sends goes through at once (``requested`` is set), what the server answers waits
    while held. ``rewrite`` (old, new): what a client sends has ``old`` replaced by ``new``
    on its way (``connections`` counts the clients accepted)."""

    def __init__(self, port: int, rewrite: tuple[bytes, bytes] | None = None) -> None:
        self._upstream = port
        self.rewrite = rewrite
        self.connections = 0
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self.requested = threading.Event()
        self._open = threading.Event()
        self._open.set()
        self._socks: list[socket.socket] = [self._listener]
        self._threads = [threading.Thread(target=self._accept, daemon=True)]
        self._threads[0].start()

    def hold(self) -> None:
        self.requested.clear()
        self._open.clear()

    def release(self) -> None:
        self._open.set()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._listener.accept()
            except OSError:
                return
            server = socket.create_connection(("127.0.0.1", self._upstream))
            self._socks += [client, server]
            self.connections += 1
            for args in ((client, server, False), (server, client, True)):
                t = threading.Thread(target=self._pump, args=args, daemon=True)
                self._threads.append(t)
                t.start()

    def _pump(self, src: socket.socket, dst: socket.socket, answers: bool) -> None:
        held = b""  # the end of what came, held while it may be the start of ``old``
        try:
            while data := src.recv(65536):
                if answers:
                    self._open.wait(30.0)
                elif self.rewrite is not None:
                    old, new = self.rewrite
                    data = (held + data).replace(old, new)
                    keep = next((k for k in range(len(old) - 1, 0, -1)
                                 if data.endswith(old[:k])), 0)
                    data, held = data[:len(data) - keep], data[len(data) - keep:]
                dst.sendall(data)
                if not answers:
                    self.requested.set()
        except OSError:
            pass

    def __enter__(self) -> HeldProxy:
        return self

    def __exit__(self, *exc: object) -> None:
        self._open.set()
        for sock in self._socks:
            try:
                sock.shutdown(socket.SHUT_RDWR)  # wakes a thread blocked on it (close does not)
            except OSError:
                pass
            sock.close()
        for t in self._threads:
            t.join(5.0)


def _sim_camera_through_relay(stack: ExitStack, rewrite: tuple[bytes, bytes] | None = None
                              ) -> tuple[Any, HeldProxy, FakeClock, CameraSource]:
    """A lockstep simulator with a robot 0.1 s into its flight, and a ``sim://`` source of its
    camera through a :class:`HeldProxy` relay (``rewrite``: the relay's), on a vehicle clock
    the test sets (1.0 s to start with)."""
    control, images, _ = stack.enter_context(sim_with_images(mode="lockstep",
                                                             estimator="truth"))
    sim = stack.enter_context(connect(f"127.0.0.1:{control.port}"))
    sim.spawn("hummingbird", location_ned_m=(0.0, 0.0, 0.0))
    sim.run_for(0.1)
    proxy = stack.enter_context(HeldProxy(images.port, rewrite=rewrite))
    clock = FakeClock(1.0)
    source = open_camera(f"sim://127.0.0.1:{proxy.port}/R1/Down",
                         CameraOptions(clock=clock, clock_is_sim=True))
    stack.callback(source.close)
    return sim, proxy, clock, source


def test_a_sim_camera_asked_during_anothers_probe_gets_that_probes_answer():
    """The pilot's loop and its vision's worker both ask a ``sim://`` camera for its newest
    frame. Asked again at the moment of the last probe, the source answers from that probe;
    while one was under way (its answer held back here by a relay), a second caller got the
    answer before it, an older frame than the prober's: in lockstep the loop let the worker
    take that older frame while the worker saw a newer one, and each waited for the other
    (until 2026-11-28; seen about once in six lockstep pad flights under load). Now the
    second caller waits for the probe under way and gets its answer."""
    with ExitStack() as stack:
        sim, proxy, clock, source = _sim_camera_through_relay(stack)
        source.probe_interval_s = 60.0  # (the same moment: the same vehicle time)
        before = source.latest
        assert before is not None
        sim.run_for(0.2)  # newer frames; the vehicle's clock moves on
        clock.t = 2.0
        proxy.hold()
        probing: dict[str, object] = {}
        prober = threading.Thread(target=lambda: probing.update(info=source.latest))
        prober.start()
        assert proxy.requested.wait(10.0)  # its request is at the server, the answer held
        releaser = threading.Timer(0.2, proxy.release)  # (any delay: see the docstring)
        releaser.start()
        second = source.latest  # at the moment of the probe under way
        prober.join(10.0)
        releaser.join()
        first = probing["info"]
        assert isinstance(first, type(before)) and first.frame > before.frame
        assert second == first, (before, first, second)


def test_a_sim_camera_probes_an_image_server_from_before_info_as_it_did_before():
    """An image server from before ``SKEYE INFO`` (2026-11-28: a simulator not upgraded with
    the pilot, the LL board's in a hardware-in-the-loop rig) answers it with an error frame,
    ``unknown SKEYE command``: the ``sim://`` source then probes that connection with a 1x1
    sub-rectangle, as it did before INFO. It lost the camera at every look instead, and made
    a new connection for the next. A relay makes the real server refuse INFO here."""
    with ExitStack() as stack:
        sim, proxy, clock, source = _sim_camera_through_relay(
            stack, rewrite=(b"SKEYE INFO\n", b"SKEYE INFQ\n"))
        first = source.latest
        sim.run_for(0.2)
        clock.t = 2.0
        second = source.latest
        assert (source.errors, source.lost) == (0, None)
        assert first is not None and second is not None and second.frame > first.frame
        assert proxy.connections == 1  # the probe's, kept
        assert source.image().frame == second.frame


def test_a_sim_camera_whose_robot_spawns_again_gives_the_new_cameras_frames_at_once(tmp_path):
    """The robot the camera belongs to leaves the simulator and is spawned again under its
    name (a crashed vehicle put back; a simulator started again behind the same image port):
    the new camera numbers its frames from 1 again. The source compared frame numbers only, so
    the new frames stayed unannounced, and the pad vision blind ("camera lost"), until their
    numbers passed the old camera's (as long as the old one had run); on another clock their
    times were also mapped with the old camera's offset, the old run's length in the past.
    Now the first frame of a new camera is announced at once, numbered on after the old ones
    (the vision takes a frame only if its number is above the last), timed on the new one."""
    robots = small_camera_robot(tmp_path, 64, 48)
    clock = FakeClock(1000.0)
    with sim_with_images(robot_dirs=(robots,)) as (control, images, _cameras):
        source = open_camera(f"sim://127.0.0.1:{images.port}/R1/Down?fov_deg=60",
                             CameraOptions(clock=clock, clock_is_sim=False, timeout_s=5.0))
        try:
            first = LineClient(control.port)
            first.expect("NFO")
            first.answer("INIT {ClassName smallcam} {Name R1} {Location 0,0,-1}", "INIT")
            old = None
            while old is None or old.frame < 6:
                first.step(34)
                clock.t += 0.034
                old = source.image()
            first.close()  # R1 goes with its client, shortly after
            clock.t += 1.0
            deadline = time.monotonic() + 10.0
            with pytest.raises(CameraError, match="R1/Down' is gone"):
                while time.monotonic() < deadline:
                    source.image()
            assert source.lost is not None
            second = LineClient(control.port)
            second.expect("NFO")
            second.answer("INIT {ClassName smallcam} {Name R1} {Location 0,0,-1}", "INIT")
            second.step(34)
            clock.t = 2000.0
            announced = source.latest
            assert announced is not None and announced.frame > old.frame, (announced, old)
            new = source.image()
            assert new.frame > old.frame and source.lost is None, (new, old)
            assert new.time_s == pytest.approx(2000.0, abs=0.1)  # received now
            second.step(34)
            clock.t += 0.034
            newer = source.image()
            assert newer.frame > new.frame and newer.time_s > new.time_s
            second.close()
        finally:
            source.close()


def test_a_missing_camera_is_named():
    clock = FakeClock()
    with pytest.raises(CameraError, match="no such file"):
        open_camera("file:///nonexistent/pad.mp4", CameraOptions(clock=clock))
    with ExitStack() as stack:
        import socket

        s = stack.enter_context(socket.socket())
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # nothing listens
        source = open_camera(f"sim://127.0.0.1:{port}/R1/Down",
                             CameraOptions(clock=clock, timeout_s=1.0))
        assert source.latest is None and "cannot connect" in (source.lost or "")
        with pytest.raises(CameraError, match=f"127.0.0.1:{port}"):
            source.image()
    source = open_camera("v4l2:///dev/video-nonexistent-99", CameraOptions(clock=clock))
    try:
        assert "cannot open /dev/video-nonexistent-99" in (source.lost or "")
        with pytest.raises(CameraError, match="cannot open"):
            source.image()
    finally:
        source.close()


def test_a_missing_v4l2_device_is_looked_for_without_opencv_warnings():
    """An unplugged camera is reopened every second (docs/onboard.md, failures): the pilot says
    "camera lost" once; OpenCV, asked to open a device node that is not there, printed its own
    "VIDEOIO(V4L2): ... can't be used to capture by name" on stderr at every try."""
    code = ("from skeye.pilot.camera import CameraOptions, open_camera\n"
            "source = open_camera('v4l2:///dev/video-nonexistent-99', CameraOptions())\n"
            "print(source.lost)\n"
            "source.close()\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 0, done.stderr
    assert "cannot open /dev/video-nonexistent-99" in done.stdout
    assert "VIDEOIO" not in done.stderr and "WARN" not in done.stderr, done.stderr


def test_a_device_that_is_no_v4l2_camera_is_named_without_opencv_warnings():
    """A node that is there but is no camera (/dev/null here; on a vehicle, a UVC camera's
    metadata node /dev/video1): the pilot said only "cannot open /dev/null", and OpenCV
    printed "VIDEOIO(V4L2): ... can't be used to capture by name" on stderr at every try,
    once a second."""
    code = ("from skeye.pilot.camera import CameraOptions, open_camera\n"
            "source = open_camera('v4l2:///dev/null', CameraOptions())\n"
            "print(source.lost)\n"
            "source.close()\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 0, done.stderr
    assert "cannot open /dev/null (not a V4L2 device)" in done.stdout
    assert "VIDEOIO" not in done.stderr and "WARN" not in done.stderr, done.stderr


def test_a_file_that_is_no_video_is_refused_when_opened(tmp_path):
    """A text file named .png was "opened" by OpenCV's image-sequence reader as a 0x0 video:
    the pilot started on it and then said only "the video ended after 0 frames"."""
    fake = tmp_path / "frames.png"
    fake.write_text("hello, not an image\n")
    with pytest.raises(CameraError, match="not a video"):
        open_camera(f"file://{fake}", CameraOptions(clock=FakeClock()))


def test_a_file_the_pilot_may_not_read_is_named_as_such():
    """A recording copied off the vehicle by root, mode 600: it was refused as "not a video,
    or one cut short or damaged" (and OpenCV warned "can't open/read file" on stderr), which
    sends a user re-copying a file that is whole."""
    frames = [np.full((48, 64, 3), 40, np.uint8)] * 2
    folder = Path(tempfile.mkdtemp(prefix="skeye-unreadable-"))  # not tmp_path: its parents
    folder.chmod(0o755)  # are the test runner's alone, and a user would be refused there
    path = folder / "flight.mkv"
    record(path, frames, "FFV1")
    path.chmod(0)
    uri = f"file://{path}"

    def refusal() -> str:
        try:
            open_camera(uri, CameraOptions(clock=FakeClock())).close()
        except CameraError as exc:
            return str(exc)
        return "opened"

    try:
        if os.geteuid() != 0:
            said = refusal()
        else:  # root reads any file: a user's refusal is seen in a child (no exec needed)
            reader, writer = os.pipe()
            pid = os.fork()
            if pid == 0:  # pragma: no cover (the child)
                try:
                    os.close(reader)
                    os.setgid(65534)
                    os.setuid(65534)  # nobody
                    os.write(writer, refusal().encode())
                finally:
                    os._exit(0)
            os.close(writer)
            with os.fdopen(reader, "rb") as f:
                said = f.read().decode()
            os.waitpid(pid, 0)
    finally:
        shutil.rmtree(folder)
    assert said == f"camera {uri}: cannot open {path} as a video (Permission denied)", said


def test_a_photo_larger_than_ffmpeg_decodes_is_named_with_its_size(tmp_path):
    """A photo of more pixels than FFmpeg decodes (an orthomosaic, a panorama) was refused as
    "not a video: no frame size", which sends a user looking for a damaged file. Its header's
    size is now said. 16000 x 16000 is within FFmpeg's limit, 16384 x 16384 past it."""
    from tests.test_image_files import _png_declaring

    picture = np.zeros((48, 64, 3), np.uint8)
    jpeg = bytearray(cv2.imencode(".jpg", picture)[1].tobytes())
    sof = jpeg.index(b"\xff\xc0")
    jpeg[sof + 5 : sof + 9] = (16384).to_bytes(2, "big") * 2  # height, width
    (tmp_path / "big.png").write_bytes(_png_declaring(16384, 16384))
    (tmp_path / "big.jpg").write_bytes(bytes(jpeg))
    for name in ("big.png", "big.jpg"):
        uri = f"file://{tmp_path / name}?fps=1"
        with pytest.raises(CameraError, match=rf"^camera {re.escape(uri)}: cannot open "
                           rf".*{name} as a video \(its header declares 16384x16384 px, more "
                           r"than FFmpeg decodes \(about 268 million\): give a smaller copy\)$"):
            open_camera(uri, CameraOptions(clock=FakeClock()))


def test_a_directory_or_an_empty_file_is_named_as_such(tmp_path):
    """Both were refused as "not a video", which sends a user looking at the codec of a
    folder of frames, or of a copy that never got its bytes."""
    (tmp_path / "frames").mkdir()
    (tmp_path / "empty.mp4").write_bytes(b"")
    for name, words in (("frames", "a directory"), ("empty.mp4", "an empty file")):
        uri = f"file://{tmp_path / name}"
        with pytest.raises(CameraError, match=rf"^camera {uri}: cannot open .*{name} as a "
                           rf"video \({words}\)$"):
            open_camera(uri, CameraOptions(clock=FakeClock()))


def test_a_video_that_gives_no_frame_is_refused_when_opened(tmp_path):
    """An MP4 whose last bytes never arrived (a recording cut short: its index, written
    last, is broken) opens in OpenCV with a frame size, rate and count, and gives no frame:
    the pilot started on it, and its camera said at once "the video ended after 0 frames".
    The first frame is now decoded when the camera opens."""
    frames = [np.full((48, 64, 3), i * 20, np.uint8) for i in range(5)]
    whole = tmp_path / "whole.mp4"
    record(whole, frames, "mp4v")
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(whole.read_bytes()[:-100])
    uri = f"file://{cut}"
    with pytest.raises(CameraError, match=rf"^camera {uri}: cannot open {cut} as a video \(no "
                       r"frame decodes: cut short or damaged\)$"):
        open_camera(uri, CameraOptions(clock=FakeClock()))
    source = open_camera(f"file://{whole}", CameraOptions(clock=FakeClock()))
    try:
        assert source.image().frame == 1 and source.lost is None
    finally:
        source.close()


def test_a_photo_plays_as_one_frame_and_a_truncated_one_is_refused(tmp_path):
    """A photo given as the file camera plays as a one-frame video; the first 60 % of a JPEG
    played too (FFmpeg decodes what is there and paints the rest grey)."""
    picture = np.zeros((48, 64, 3), np.uint8)
    picture[:, 32:] = 200
    for ext in (".jpg", ".png"):
        whole = cv2.imencode(ext, picture)[1].tobytes()
        padded = tmp_path / f"padded{ext}"  # some cameras pad after the image's end
        padded.write_bytes(whole + b"\x00" * 64)
        clock = FakeClock()
        source = open_camera(f"file://{padded}?fps=10", CameraOptions(clock=clock))
        try:
            assert source.image().bgr.shape == picture.shape
            clock.t += 0.2  # its second frame would be due: the photo has none
            with pytest.raises(CameraError, match=r"the video ended after 1 frame$"):
                source.image()
        finally:
            source.close()
        cut = tmp_path / f"cut{ext}"
        cut.write_bytes(whole[: len(whole) * 6 // 10])
        with pytest.raises(CameraError, match=rf"^camera file://{cut}: {cut} is truncated or "
                           "corrupt: the (JPEG|PNG) data ends before"):
            open_camera(f"file://{cut}", CameraOptions(clock=FakeClock()))


def test_v4l2_settings_from_the_uri():
    s = parse_v4l2_uri("v4l2:///dev/video0?width=800&height=600&fps=30&fourcc=mjpg&exposure=80"
                       "&gain=10&buffers=2&fov_deg=75")
    assert s == V4l2Settings(device="/dev/video0", width=800, height=600, fps=30.0,
                             fourcc="MJPG", exposure=80, gain=10.0, buffers=2,
                             fov_h_rad=math.radians(75))
    assert parse_v4l2_uri("v4l2:///dev/video2?exposure=auto").exposure == "auto"
    assert parse_v4l2_uri("v4l2:///dev/v4l/by-id/usb-cam").device == "/dev/v4l/by-id/usb-cam"
    for uri, words in (
        ("v4l2://video0", "device path"),
        ("v4l2:///dev/video0?width=wide", "width=wide"),
        ("v4l2:///dev/video0?fps=0", "fps=0"),
        ("v4l2:///dev/video0?fourcc=MJPEG", "four characters"),
        ("v4l2:///dev/video0?exposure=-3", "exposure=-3"),
        ("v4l2:///dev/video0?zoom=2", "unknown option"),
        ("v4l2:///dev/video0?fov_deg=200", "field of view"),
        ("v4l2:///dev/video0?fov_deg=70&fov_rad=1.2", "not both"),
    ):
        with pytest.raises(LocalProtocolError, match=words):
            parse_v4l2_uri(uri)


def test_sim_and_file_uris():
    assert parse_sim_camera("sim://127.0.0.1:5003/R1/Down") == ("127.0.0.1", 5003, "R1/Down",
                                                                None)
    assert parse_sim_camera("sim://h:1/Down", robot="R2")[2] == "R2/Down"
    assert parse_file_camera("file://video.mp4") == (Path("video.mp4"), None, False, None)
    # RFC 8089's local host: an absolute path (it was read as the folder "localhost")
    assert parse_file_camera("file://localhost/v/pad.mkv")[0] == Path("/v/pad.mkv")
    assert parse_file_camera("file://localhost")[0] == Path("localhost")  # a file of that name
    assert parse_file_camera("file:///v/pad.mkv?fps=30&loop=1")[:3] == (Path("/v/pad.mkv"),
                                                                        30.0, True)
    for uri, words in (("sim://h/Down", "HOST:PORT"), ("sim://h:1/a/b/c", "ROBOT/CAMERA"),
                       ("file://", "a video file"), ("file://x.mp4?fps=-1", "fps=-1"),
                       ("file://x.mp4?loop=yes", "loop=yes")):
        with pytest.raises(LocalProtocolError, match=words):
            (parse_sim_camera if uri.startswith("sim") else parse_file_camera)(uri)
    with pytest.raises(LocalProtocolError, match="no source for rtsp://"):
        open_camera("rtsp://cam/1")


def test_a_hash_in_a_file_name_is_not_cut_off_as_a_fragment():
    """``file://flight#3.mkv``: urlsplit takes ``#3.mkv`` as the URI's fragment, and the
    camera looked for the file "flight" ("cannot open flight as a video (no such file)"), or,
    where a file of the shorter name existed, played that one without a word. A fragment means
    nothing to a file camera: it is refused, with the name's escape (%23) said."""
    for uri in ("file://flight#3.mkv", "file:///v/pad.mkv?fps=30#t=5"):
        with pytest.raises(LocalProtocolError, match=r"'#' starts a URI fragment, .*: write a "
                           r"'#' in a file's name as %23"):
            parse_file_camera(uri)
    assert parse_file_camera("file://flight%233.mkv")[0] == Path("flight#3.mkv")


@pytest.mark.parametrize(("uri", "words"), [
    ("sim://h:abc/R1/Down", "PORT 0..65535"),
    ("sim://h:99999/R1/Down", "PORT 0..65535"),
    ("sim://h:-1/R1/Down", "PORT 0..65535"),
    ("sim://[::1/R1/Down", "Invalid IPv6 URL; expected sim://"),
    ("v4l2://[::1/dev/video0", "Invalid IPv6 URL; expected v4l2://"),
    ("file://[::1/x.mp4", "Invalid IPv6 URL; expected file://"),
    ("v4l2:///dev/video0?width=²", "width=² is not a whole number"),
    ("v4l2:///dev/video0?exposure=٣", "exposure=٣ is not a whole number"),
])
def test_malformed_uris_are_named_not_a_value_error(uri, words):
    """A bad port, an unclosed IPv6 bracket or a digit int() refuses made urllib or int()
    raise ValueError, a traceback from skeye pilot after its airframe was opened."""
    with pytest.raises(LocalProtocolError, match=words):
        open_camera(uri, CameraOptions(clock=FakeClock()))


def test_a_real_v4l2_camera_where_there_is_one():
    devices = sorted(glob.glob("/dev/video*"))
    if not devices:
        pytest.skip("no V4L2 video device on this machine (/dev/video* absent): v4l2:// is "
                    "exercised on a machine with a camera")
    clock = time.monotonic
    source = open_camera(f"v4l2://{devices[0]}?width=640&height=480&fps=30",
                         CameraOptions(clock=clock))
    try:
        deadline = time.monotonic() + 10.0
        while source.latest is None or source.latest.frame < 3:
            if source.lost:
                pytest.skip(f"{devices[0]} gives no frames here: {source.lost}")
            assert time.monotonic() < deadline, "no frames from the camera in 10 s"
            time.sleep(0.05)
        a = source.image()
        time.sleep(0.2)
        b = source.image()
        assert b.frame > a.frame and b.time_s > a.time_s and b.time_s <= clock()
        assert a.bgr.ndim == 3 and a.bgr.shape[2] == 3
    finally:
        source.close()


def test_a_lockstep_frame_slower_than_the_answer_deadline_still_comes():
    """In lockstep a frame may wait for its render, which the simulator bounds (60 s) and the
    paused world makes harmless: an image request waits at least LOCKSTEP_IMAGE_TIMEOUT_S, not
    the connection's ``timeout_s``. Here the image server's first answer comes 5 s late and
    the connection's timeout is 4 s: the request failed (a timeout, which the pilot's vision
    takes for "pad not seen", and the lockstep flight went on differently); now the frame
    comes."""
    from tests.pilot.ll_proxy import Proxy

    class FirstAnswerLate(Proxy):
        late_s = 5.0
        delayed = False

        def from_board(self, data: bytes) -> bytes:
            if not self.delayed:
                self.delayed = True
                time.sleep(self.late_s)
            return data

    with ExitStack() as stack:
        control, images, _ = stack.enter_context(sim_with_images(mode="lockstep"))
        late = FirstAnswerLate(images.port)
        stack.callback(late.close)
        sim = stack.enter_context(connect(f"127.0.0.1:{control.port}",
                                          images=f"127.0.0.1:{late.port}", timeout_s=4.0))
        robot = sim.spawn("hummingbird", location_ned_m=(0.0, 0.0, -1.0))
        image = robot.camera.image()
        assert late.delayed and image.frame >= 1 and image.bgr.shape == (600, 800, 3)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_video_from_a_fifo_is_checked_without_reading_it(tmp_path):
    # skeye pilot's check at start opened the file as a video: a FIFO's (a recorder piping into
    # it) first frames were read there and its writer ended, and the camera then waited for a
    # writer forever; with no writer yet, the check itself waited
    frames = [np.full((48, 64, 3), 10 * i, np.uint8) for i in range(5)]
    record(tmp_path / "flight.mkv", frames, "FFV1")
    data = (tmp_path / "flight.mkv").read_bytes()
    fifo = tmp_path / "live.mkv"
    os.mkfifo(fifo)
    uri = f"file://{fifo}?fov_deg=60"

    def feed() -> None:
        with contextlib.suppress(BrokenPipeError), open(fifo, "wb") as f:
            f.write(data)

    writer = threading.Thread(target=feed, daemon=True)
    writer.start()
    opened: list[Any] = []
    opening = threading.Thread(target=lambda: opened.append(_open_after_check(uri)),
                               daemon=True)
    opening.start()
    opening.join(60.0)  # the work of a moment; the limit only ends a wait that never would
    if opening.is_alive():  # its open() waits for a writer: writers that write nothing end
        for _ in range(60):  # it (OpenCV opens the file again with each of its readers)
            with contextlib.suppress(OSError):
                os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
            opening.join(1.0)
            if not opening.is_alive():
                break
        pytest.fail("the check read the FIFO's video: the camera then waited for a writer")
    source = opened[0]
    try:
        assert source.image().bgr.shape == (48, 64, 3)
    finally:
        source.close()
    writer.join(60.0)


def _open_after_check(uri: str) -> CameraSource:
    """What skeye pilot does with --camera: the check at start, then the camera."""
    check_camera_uri(uri)
    return open_camera(uri)
