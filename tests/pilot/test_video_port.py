"""The pilot's video port end to end: a lockstep simulator with the pad in view, the pilot's
vision, its video port, the vehicle link. The frames served carry the pilot's own detection; a
slow, a silent and a garbage client change nothing for the control loop."""

from __future__ import annotations

import math
import socket
import threading
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import dataclass

import pytest

from skeye.control.connection import connect
from skeye.link.vehicle import Vehicle
from skeye.pilot.cli import camera_fov_rad, pad_vision_factory
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.pilot.video_server import VideoServer
from skeye.pilot.vision import PadVision
from skeye.wire.packet_units import pad_report_to_si
from skeye.wire.packets import PD, NavState, PadReport, SkeyeMask
from skeye.wire.video import Frame
from tests.ground.conftest import wait_until
from tests.pilot.test_video_server import Viewer
from tests.sim.test_cameras import sim_with_images


@dataclass
class Flight:
    vehicle: Vehicle
    pilot: PilotServer
    vision: PadVision
    video: VideoServer


@pytest.fixture
def flight() -> Iterator[Flight]:
    with ExitStack() as stack:
        # The oracle estimator: the hover check below is about the control loop, not about the
        # onboard estimate's GPS wander outdoors.
        control, images, _cameras = stack.enter_context(
            sim_with_images(mode="lockstep", estimator="truth")
        )
        sim = stack.enter_context(
            connect(f"127.0.0.1:{control.port}", images=f"127.0.0.1:{images.port}")
        )
        robot = sim.spawn("hummingbird", start="Pad1")
        video = VideoServer(port=0, camera="R1/Down", fov_h_rad=camera_fov_rad(sim),
                            max_fps=1000.0, send_timeout_s=600.0)
        pilot = stack.enter_context(
            PilotServer(SimAirframe(sim, robot), port=0, lockstep=True, lockstep_rate=5.0,
                        tick_s=0.05, vision=pad_vision_factory(sim, robot), video=video)
        )
        assert isinstance(pilot.vision, PadVision)
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=30.0))
        yield Flight(vehicle, pilot, pilot.vision, video)


class Collector:
    """A viewer on its own thread that keeps every frame."""

    def __init__(self, port: int) -> None:
        self.viewer = Viewer(port)
        self.frames: list[Frame] = []
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        try:
            while True:
                msg = self.viewer.next()
                if isinstance(msg, Frame):
                    self.frames.append(msg)
        except (EOFError, OSError):
            pass

    def close(self) -> None:
        self.viewer.close()
        self.thread.join(30)


def test_served_frames_carry_the_pilots_own_detection(flight: Flight) -> None:
    vehicle = flight.vehicle
    reports: dict[int, PadReport] = {}
    vehicle.add_callback(lambda m: reports.__setitem__(m.frame_time, m)
                         if isinstance(m, PadReport) and m.found else None)
    collector = Collector(flight.video.port)
    try:
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS | SkeyeMask.PAD), 0.05)
        vehicle.take_off(1.0)
        vehicle.wait_state(NavState.HOLDING, timeout_s=120)

        def matched() -> list[tuple[Frame, PadReport]]:
            pairs = [(f, reports[round(f.time_s * 1000)]) for f in list(collector.frames)
                     if f.detection.found and round(f.time_s * 1000) in reports]
            return pairs if len(pairs) >= 5 else []

        pairs = wait_until(matched, 120, "5 served frames with the pad, matched to PAD reports")
        for frame, packet in pairs:  # the same detection, at the PAD packet's resolution
            report = pad_report_to_si(packet)
            det = frame.detection
            assert det.offset_body_m is not None and det.height_m is not None
            assert report.dx_m == pytest.approx(det.offset_body_m[0], abs=0.0006)
            assert report.dy_m == pytest.approx(det.offset_body_m[1], abs=0.0006)
            assert report.height_m == pytest.approx(det.height_m, abs=0.0006)
            assert report.rings == sum(1 << (r - 1) for r in det.rings)
            assert report.quality == pytest.approx(det.quality, abs=0.01)
            assert 0.0 < det.height_m < 1.2  # on the way up to 1 m, or holding there
            assert det.roll_rad is not None and det.pitch_rad is not None  # tilt-compensated
            assert len(det.ellipses) == 2 * len(det.rings)
            assert (frame.width, frame.height) == (800, 600)

        # Exactly the pilot's own observation, to the bit, for the frame it last looked at.
        def exact() -> tuple[Frame, object] | None:
            obs = flight.pilot.boards.pad._latest
            if obs is None or not obs.found:
                return None
            same = [f for f in collector.frames if f.time_s == obs.frame_time_s]
            return (same[-1], obs) if same else None

        frame, obs = wait_until(exact, 60, "a served frame that is the pilot's latest one")
        assert frame.detection.offset_body_m == (obs.dx_m, obs.dy_m)  # type: ignore[attr-defined]
        assert frame.detection.height_m == obs.height_m  # type: ignore[attr-defined]
        assert frame.detection.quality == obs.quality  # type: ignore[attr-defined]
    finally:
        collector.close()


def test_slow_silent_and_garbage_clients_do_not_slow_the_control_loop(flight: Flight) -> None:
    vehicle, vision, video = flight.vehicle, flight.vision, flight.video
    slow = Viewer(video.port)  # subscribes, never reads
    slow.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    silent = socket.create_connection(("127.0.0.1", video.port), timeout=60)
    garbage = socket.create_connection(("127.0.0.1", video.port), timeout=60)
    garbage.sendall(b"POST /fly HTTP/1.1\r\n\r\n" + bytes(range(256)))
    try:
        def slow_dropped() -> int:
            port = str(slow.sock.getsockname()[1])
            return next((c.dropped for c in video.clients() if c.peer.endswith(":" + port)), 0)

        vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
        wait_until(lambda: slow_dropped() >= 3, 120, "the slow client stalled (missing frames)")
        frames0, dropped0 = vision.stats.frames, slow_dropped()
        time0 = vehicle.wait_for(PD.NAV_STATUS, timeout_s=60).time  # type: ignore[attr-defined]
        # Lockstep: sim time moves only as fast as the loop, which waits for the vision of
        # every frame; with the slow client stalled the whole time, the flight goes on.
        vehicle.take_off(1.0)
        vehicle.wait_state(NavState.HOLDING, timeout_s=120)
        wait_until(lambda: vision.stats.frames >= frames0 + 30, 120, "30 more frames looked at")
        assert slow_dropped() >= dropped0 + 20  # it missed them, nothing waited for it
        assert video.published == vision.stats.frames  # every frame handed over at once
        time1 = vehicle.wait_for(PD.NAV_STATUS, timeout_s=60).time  # type: ignore[attr-defined]
        assert time1 - time0 >= 1000  # ms of sim time flown while the slow client stalled
        wait_until(lambda: video.idle_closed == 1, 60, "the silent client closed (5 s idle)")
        assert video.bad_clients == 1
        assert flight.pilot.loop_error is None and flight.pilot.vehicle_lost is None
        north, east, _ = flight.pilot.airframe.robot.position()
        assert math.hypot(north, east) < 0.5
    finally:
        for s in (slow.sock, silent, garbage):
            s.close()
