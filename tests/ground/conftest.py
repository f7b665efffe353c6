"""The full stack for ground-control tests: ``skeye sim`` (a child process, realtime, images on
a free port), the pilot in this process (so the tests read the simulator's ground truth from
its robot; it serves its camera and detections on its video port) and the ground app in this
process (uvicorn in a thread on a free port), whose video comes from the pilot's video port."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from skeye.processes import die_with_parent

os.environ.setdefault("MUJOCO_GL", "egl")

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]

# A hummingbird with a smaller, slower camera: rendering is the costliest thing on a 2-core CI
# machine, and the pad is still found at 320x240.
SMALL_CAMERA_ROBOT = "groundtest"


def _robot_dir(tmp: Path) -> Path:
    from importlib import resources

    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    text = re.sub(r'(?m)^name = "hummingbird"', f'name = "{SMALL_CAMERA_ROBOT}"', text, count=1)
    text = re.sub(r"(?m)^width = 800$", "width = 320", text)
    text = re.sub(r"(?m)^height = 600$", "height = 240", text)
    text = re.sub(r"(?m)^rate_hz = 30$", "rate_hz = 10", text)
    (tmp / f"{SMALL_CAMERA_ROBOT}.toml").write_text(text, encoding="utf-8")
    return tmp


class UvicornThread:
    """The ground app served by uvicorn in a thread, on a free port, with ``skeye ground``'s
    settings (``uvicorn_config``); ``token`` is the app's secret."""

    def __init__(self, app: Any, token: str = "", limits: Any = None) -> None:
        import uvicorn

        from skeye.ground.app import uvicorn_config

        self.token = token
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.server = uvicorn.Server(uvicorn_config(app, limits=limits))
        self.thread = threading.Thread(
            target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True
        )
        self.thread.start()
        deadline = time.monotonic() + 120  # an event wait: only a stuck server reaches it
        while not self.server.started:
            assert time.monotonic() < deadline, "uvicorn did not start"
            time.sleep(0.05)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def page_url(self) -> str:
        """The URL ``skeye ground`` prints: the page, with the token."""
        return f"{self.url}/?token={self.token}"

    @property
    def auth(self) -> dict[str, str]:
        """Headers that carry the token (for scripts)."""
        return {"X-Skeye-Token": self.token}

    def close(self) -> None:
        self.server.should_exit = True
        self.thread.join(10)


@dataclass
class Pilot:
    """``skeye pilot`` in this process: connection, robot, airframe and server."""

    sim_address: str
    images: str
    port: int = 0
    name: str = "R1"
    video_port: int = 0
    conn: Any = None
    robot: Any = None
    server: Any = None

    def start(self) -> Pilot:
        from skeye.control.connection import connect
        from skeye.pilot.boards import BoardSettings
        from skeye.pilot.server import PilotServer
        from skeye.pilot.sim_airframe import SimAirframe

        self.conn = connect(self.sim_address, images=self.images, timeout_s=10.0)
        self.robot = self.conn.spawn(SMALL_CAMERA_ROBOT, start="Pad1", name=self.name)
        airframe = SimAirframe(self.conn, self.robot)  # sets the robot file's limits
        mc = self.robot.motion_config
        settings = BoardSettings(
            max_speed_m_s=mc.max_speed_m_s, default_speed_m_s=min(1.0, mc.max_speed_m_s)
        )
        from skeye.pilot.cli import camera_fov_rad, pad_vision_factory
        from skeye.pilot.video_server import VideoServer

        # As `skeye pilot --images ... --video-port N` runs: the pad vision, and its frames
        # with its detections served on the vehicle's video port.
        video = VideoServer(port=self.video_port, camera=f"{self.name}/Down",
                            fov_h_rad=camera_fov_rad(self.conn, "Down"))
        self.server = PilotServer(
            airframe, port=self.port, settings=settings,
            vision=pad_vision_factory(self.conn, self.robot), video=video,
        ).start()
        self.port = self.server.port
        self.video_port = video.port
        return self

    def ground_truth(self) -> tuple[float, float, float]:
        """The simulator's true position (north, east, down) in metres."""
        reading = self.robot.ground_truth.latest
        assert reading is not None
        return tuple(reading.position_ned_m)

    def stop(self) -> None:
        if self.server is not None:
            self.server.close()
        if self.conn is not None:
            self.conn.close()


@dataclass
class Stack:
    sim: subprocess.Popen[str]
    sim_address: str
    image_port: int
    pilot: Pilot
    bridge: Any
    video: Any
    web: UvicornThread
    lines: list[str] = field(default_factory=list)

    def restart_pilot(self, down_s: float = 1.5) -> None:
        port, video_port = self.pilot.port, self.pilot.video_port
        self.pilot.stop()
        time.sleep(down_s)
        n = int(self.pilot.name[1:]) + 1
        self.pilot = Pilot(self.sim_address, f"127.0.0.1:{self.image_port}", port, f"R{n}",
                           video_port).start()


def _start_sim(robot_dir: Path) -> tuple[subprocess.Popen[str], int, int]:
    argv = [sys.executable, "-c", "import sys; from skeye.cli import main; sys.exit(main())",
            "sim", "--port", "0", "--image-port", "0", "--robot-dir", str(robot_dir)]
    sim = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                           preexec_fn=die_with_parent())
    ports: dict[str, int] = {}
    deadline = time.monotonic() + 300  # a busy 2-core host can take minutes to import MuJoCo
    assert sim.stdout is not None
    while len(ports) < 2:
        line = sim.stdout.readline()
        if not line or time.monotonic() > deadline:
            sim.kill()
            raise RuntimeError(f"skeye sim did not start: {line!r}")
        if m := re.search(r"control protocol on [\d.]+:(\d+)", line):
            ports["control"] = int(m.group(1))
        if m := re.search(r"image server on [\d.]+:(\d+)", line):
            ports["images"] = int(m.group(1))
    threading.Thread(target=_drain, args=(sim.stdout,), daemon=True).start()
    return sim, ports["control"], ports["images"]


def _drain(out: Any) -> None:
    """Read the child's output to its end (it never blocks on a full pipe), then close it."""
    with out:
        for _ in out:
            pass


@pytest.fixture(scope="package")
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    from skeye.ground.app import create_app
    from skeye.ground.bridge import VehicleBridge
    from skeye.ground.guard import GroundSecurity
    from skeye.ground.video import VideoRelay

    sim, control_port, image_port = _start_sim(_robot_dir(tmp_path_factory.mktemp("robots")))
    sim_address = f"127.0.0.1:{control_port}"
    pilot = Pilot(sim_address, f"127.0.0.1:{image_port}").start()
    bridge = VehicleBridge(f"tcp://127.0.0.1:{pilot.port}", retry_s=0.5).start()
    video = VideoRelay("127.0.0.1", pilot.video_port, fps=6.0, retry_s=0.5).start()
    security = GroundSecurity()
    web = UvicornThread(create_app(bridge, video, security=security), security.token)
    s = Stack(sim, sim_address, image_port, pilot, bridge, video, web)
    try:
        yield s
    finally:
        web.close()
        video.close()
        bridge.close()
        s.pilot.stop()
        sim.terminate()
        try:
            sim.wait(10)
        except subprocess.TimeoutExpired:
            sim.kill()


def wait_until(pred, timeout_s: float, what: str, poll_s: float = 0.1):
    """Poll ``pred()`` until truthy; fail naming ``what``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = pred()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(poll_s)
