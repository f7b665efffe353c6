"""``skeye up``: starts simulator, pilot and ground control, prints the URL, stops them all."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

from tests.ground.conftest import wait_until


def _free_ports(n: int) -> list[int]:
    socks = [socket.create_server(("127.0.0.1", 0)) for _ in range(n)]
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def _children(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True)
    return [int(p) for p in out.stdout.split()]


def test_up_starts_everything_and_sigterm_stops_everything() -> None:
    sim, img, pilot, ground = _free_ports(4)
    argv = [sys.executable, "-m", "skeye.ground.cli", "up", "--sim-port", str(sim),
            "--image-port", str(img), "--pilot-port", str(pilot), "--ground-port", str(ground)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        deadline = time.monotonic() + 60
        while not any("skeye up: open" in line for line in lines):
            line = proc.stdout.readline()
            assert line and time.monotonic() < deadline, f"skeye up did not start: {lines}"
            lines.append(line)
        assert f"http://127.0.0.1:{ground}/" in lines[-1]
        token = lines[-1].split("?token=", 1)[1].split()[0]  # the page's secret, as printed
        children = _children(proc.pid)
        assert len(children) == 3

        def connected() -> bool:
            request = urllib.request.Request(
                f"http://127.0.0.1:{ground}/api/state", headers={"X-Skeye-Token": token}
            )
            with urllib.request.urlopen(request, timeout=2) as r:
                state = json.load(r)
            return state["link"]["state"] == "connected" and state["nav"] is not None

        wait_until(connected, 20, "ground control connected to the pilot")
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 0
        rest = proc.stdout.read()
        assert "skeye up: stopped" in rest
        for pid in children:
            gone = not os.path.exists(f"/proc/{pid}")
            assert gone or open(f"/proc/{pid}/stat").read().split()[2] == "Z"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
