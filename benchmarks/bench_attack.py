"""A real client's time to be served while its port is attacked (issue 31).

Runs ``skeye sim`` (control and image ports, a small-camera Hummingbird spawned by the pilot),
``skeye pilot`` (packets and video) and ``skeye ground`` as child processes, then attacks one
port at a time the way the issue's probe did: an attacker process holds ``--connections``
(1,000) connections from ``--addresses`` (128) loopback addresses, each trickling its request
one byte every ``--trickle-s`` (2 s) (the pilot's and the video port's attackers connect and
send nothing), and opens a new one (at most ``--rate`` a second) whenever the server closes
one. Meanwhile a real client of that port connects and is served, ``--samples`` times:

- control: NFO, then a PING answered; image: a frame (``OK``) received; pilot: ``Vehicle.open``
  and a poll answered; video: SUBSCRIBE answered with HELLO; ground: ``GET /api/state``.

It prints, per port, the real client's median and worst time to be served without and under the
attack, and how many connections the attacker held. Goal: under 1 s. When run as root the
attacker is another local user (``nobody``, uid 65534: the threat model's "another local user");
``--same-user`` attacks as this user (who then shares its caps with the real client: a newer
connection of the same user takes the place of an idle one, so the client is still served).

The process's open-file limit is raised to its hard limit first (it holds the attacker's side
of the connections only through the attacker process, which does the same), and both limits
are printed; the servers keep the soft limit they inherit.

Usage: python benchmarks/bench_attack.py [--connections 1000] [--addresses 128] [--samples 10]
       [--ports control,image,pilot,video,ground] [--same-user]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import selectors
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TOKEN = "bench" * 8
PAYLOADS = {  # what each attacker connection trickles (nothing: an idle connection)
    "control": b"PING {Id attack}\r\n",
    "image": b"SKEYE META on\n",
    "pilot": b"",
    "video": b"",
    "ground": b"GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Pad: " + b"a" * 64 + b"\r\n\r\n",
}


def raise_open_files() -> tuple[int, int]:
    """Raise the soft open-file limit to the hard one; returns (soft, hard) now."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < hard:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    return resource.getrlimit(resource.RLIMIT_NOFILE)


def loopback(i: int) -> str:
    return f"127.0.{(i + 2) // 250}.{(i + 2) % 250 + 1}"


# --- the attacker (a process of its own) -------------------------------------------------------


def attack(port: int, payload: bytes, connections: int, addresses: int, trickle_s: float,
           rate: float, other_user: bool) -> None:
    """Keep ``connections`` connections open to ``port``, trickling ``payload``; report the
    count held once a second on stdout."""
    raise_open_files()
    if other_user and os.geteuid() == 0:
        os.setgid(65534)
        os.setuid(65534)
    sel = selectors.DefaultSelector()
    conns: dict[socket.socket, int] = {}  # socket -> bytes of the payload sent
    next_byte: dict[socket.socket, float] = {}
    made = 0
    budget = 0.0
    last = time.monotonic()
    report = last
    while True:
        now = time.monotonic()
        budget = min(budget + (now - last) * rate, rate)
        last = now
        while len(conns) < connections and budget >= 1.0:
            budget -= 1.0
            s = socket.socket()
            s.setblocking(False)
            try:
                s.bind((loopback(made % addresses), 0))
                s.connect_ex(("127.0.0.1", port))
            except OSError:
                s.close()
                break
            made += 1
            conns[s] = 0
            next_byte[s] = now + trickle_s * (made % 100) / 100  # spread the trickle
            sel.register(s, selectors.EVENT_READ)
        for key, _ in sel.select(0.05):
            s = key.fileobj
            assert isinstance(s, socket.socket)
            try:
                data = s.recv(65536)
            except BlockingIOError:
                continue
            except OSError:
                data = b""
            if not data:  # closed by the server: a new one will take its place
                sel.unregister(s)
                s.close()
                conns.pop(s, None)
                next_byte.pop(s, None)
        now = time.monotonic()
        if payload:
            for s, due in list(next_byte.items()):
                if due <= now:
                    sent = conns[s]
                    try:
                        s.send(payload[sent % len(payload): sent % len(payload) + 1])
                        conns[s] = sent + 1
                    except OSError:
                        pass
                    next_byte[s] = now + trickle_s
        if now - report >= 1.0:
            report = now
            print(json.dumps({"held": len(conns), "made": made}), flush=True)


# --- the real clients ---------------------------------------------------------------------------


def _line(f: Any) -> bytes:
    return bytes(f.readline())


def serve_control(port: int) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=30) as s, s.makefile("rb") as f:
        assert _line(f).startswith(b"NFO"), "no greeting"
        s.sendall(b"PING {Id real}\r\n")
        while b"{Id real}" not in _line(f):
            pass


def serve_image(port: int) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=30) as s:
        s.sendall(b"OK\n")
        got = b""
        while len(got) < 5:  # a frame's type byte and size: the frame is on its way
            chunk = s.recv(5 - len(got))
            assert chunk, "closed"
            got += chunk


def serve_pilot(port: int) -> None:
    from skeye.link.vehicle import Vehicle
    from skeye.wire.packets import PD, PollMask

    with Vehicle.open(f"tcp://127.0.0.1:{port}", timeout_s=30) as v:
        assert PD.LL_STATUS in v.poll(int(PollMask.LL_STATUS))


def serve_video(port: int) -> None:
    from skeye.wire.video import Hello, Role, Subscribe, VideoConnection

    conn = VideoConnection(Role.CLIENT)
    with socket.create_connection(("127.0.0.1", port), timeout=30) as s:
        s.sendall(conn.send(Subscribe(1.0)))
        while True:
            data = s.recv(65536)
            assert data, "closed"
            if any(isinstance(m, Hello) for m in conn.receive_data(data)):
                return


def serve_ground(port: int) -> None:
    import httpx

    r = httpx.get(f"http://127.0.0.1:{port}/api/state", headers={"X-Skeye-Token": TOKEN},
                  timeout=30)
    assert r.status_code == 200, r.status_code


CLIENTS = {"control": serve_control, "image": serve_image, "pilot": serve_pilot,
           "video": serve_video, "ground": serve_ground}


def timed(kind: str, port: int, samples: int, gap_s: float) -> list[float | None]:
    """Seconds each real client took to be served (None: not served within 30 s)."""
    out: list[float | None] = []
    for _ in range(samples):
        t0 = time.monotonic()
        try:
            CLIENTS[kind](port)
            out.append(time.monotonic() - t0)
        except Exception:  # any failure: not served
            out.append(None)
        time.sleep(gap_s)
    return out


def summary(times: list[float | None]) -> dict[str, Any]:
    served = [t for t in times if t is not None]
    return {"served": f"{len(served)}/{len(times)}",
            "median_s": round(statistics.median(served), 3) if served else None,
            "max_s": round(max(served), 3) if served else None}


# --- the system under attack -------------------------------------------------------------------


def _robot_dir(tmp: Path) -> Path:
    from importlib import resources

    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    text = re.sub(r'(?m)^name = "hummingbird"', 'name = "benchbird"', text, count=1)
    text = re.sub(r"(?m)^width = 800$", "width = 320", text)
    text = re.sub(r"(?m)^height = 600$", "height = 240", text)
    text = re.sub(r"(?m)^rate_hz = 30$", "rate_hz = 10", text)
    (tmp / "benchbird.toml").write_text(text, encoding="utf-8")
    return tmp


def _start(argv: list[str], patterns: dict[str, str], env: dict[str, str]
           ) -> tuple[subprocess.Popen[str], dict[str, int]]:
    proc = subprocess.Popen([sys.executable, "-m", "skeye.cli", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env, cwd=ROOT)
    found: dict[str, int] = {}
    assert proc.stdout is not None
    deadline = time.monotonic() + 600
    while len(found) < len(patterns):
        line = proc.stdout.readline()
        if not line or time.monotonic() > deadline:
            raise RuntimeError(f"{argv[0]} did not start: {line!r}")
        for name, pattern in patterns.items():
            if m := re.search(pattern, line):
                found[name] = int(m.group(1))
    out = proc.stdout
    import threading

    threading.Thread(target=lambda: [None for _ in out], daemon=True).start()
    return proc, found


def port_kinds(text: str) -> str:
    """``--ports``: a comma-separated list of the ports PAYLOADS attacks."""
    if not text or any(kind not in PAYLOADS for kind in text.split(",")):
        raise argparse.ArgumentTypeError(f"must be a comma-separated list of "
                                         f"{', '.join(PAYLOADS)}, got {text!r}")
    return text


def main() -> None:
    from skeye.cliargs import non_negative_float, positive_float, positive_int

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--connections", type=positive_int, default=1000)
    parser.add_argument("--addresses", type=positive_int, default=128)
    parser.add_argument("--trickle-s", type=positive_float, default=2.0)
    parser.add_argument("--rate", type=positive_float, default=200.0,
                        help="the attacker's new connections per second at most")
    parser.add_argument("--samples", type=positive_int, default=10)
    parser.add_argument("--ramp-s", type=non_negative_float, default=8.0,
                        help="seconds of attack before the real client is timed")
    parser.add_argument("--ports", type=port_kinds, default="control,image,pilot,video,ground")
    parser.add_argument("--same-user", action="store_true")
    parser.add_argument("--attacker", nargs=2, metavar=("PORT", "KIND"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    other_user = not args.same_user and os.geteuid() == 0
    if args.attacker:
        attack(int(args.attacker[0]), PAYLOADS[args.attacker[1]], args.connections,
               args.addresses, args.trickle_s, args.rate, other_user)
        return
    before = resource.getrlimit(resource.RLIMIT_NOFILE)
    now = raise_open_files()
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
           "PYTHONUNBUFFERED": "1", "SKEYE_GROUND_TOKEN": TOKEN, "PYTHONPATH": str(ROOT)}
    with tempfile.TemporaryDirectory() as tmp:
        robots = str(_robot_dir(Path(tmp)))
        sim, sim_ports = _start(["sim", "--port", "0", "--image-port", "0", "--robot-dir", robots],
                                {"control": r"control protocol on [\d.]+:(\d+)",
                                 "image": r"image server on [\d.]+:(\d+)"}, env)
        procs = [sim]
        try:
            pilot, pilot_ports = _start(
                ["pilot", "--sim", f"127.0.0.1:{sim_ports['control']}", "--images",
                 f"127.0.0.1:{sim_ports['image']}", "--port", "0", "--video-port", "0",
                 "--robot", "benchbird", "--robot-dir", robots, "--link-timeout", "2"],
                {"pilot": r"ground control on tcp://[\d.]+:(\d+)",
                 "video": r"video on tcp://[\d.]+:(\d+)"}, env)
            procs.append(pilot)
            ground, ground_ports = _start(
                ["ground", "--vehicle", "tcp://127.0.0.1:9", "--port", "0"],
                {"ground": r"http://[\d.]+:(\d+)/\?token="}, env)
            procs.append(ground)
            ports = {**sim_ports, **pilot_ports, **ground_ports}
            result: dict[str, Any] = {
                "open_files": {"before": list(before), "raised_to": list(now)},
                "attacker": "uid 65534 (another local user)" if other_user else "this user",
                "connections": args.connections, "addresses": args.addresses,
                "load_avg_at_start": [round(v, 2) for v in os.getloadavg()],
            }
            for kind in args.ports.split(","):
                port = ports[kind]
                baseline = timed(kind, port, max(3, args.samples // 2), 0.2)
                attacker = subprocess.Popen(
                    [sys.executable, __file__, "--attacker", str(port), kind,
                     "--connections", str(args.connections), "--addresses", str(args.addresses),
                     "--trickle-s", str(args.trickle_s), "--rate", str(args.rate),
                     *(["--same-user"] if args.same_user else [])],
                    stdout=subprocess.PIPE, text=True, env=env)
                try:
                    time.sleep(args.ramp_s)
                    attacked = timed(kind, port, args.samples, 0.3)
                finally:
                    attacker.terminate()
                    out, _ = attacker.communicate(timeout=30)
                reports = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
                result[kind] = {
                    "baseline": summary(baseline),
                    "under_attack": summary(attacked),
                    "attacker_held_max": max((r["held"] for r in reports), default=0),
                    "attacker_connections_made": reports[-1]["made"] if reports else 0,
                }
                print(kind, json.dumps(result[kind]), flush=True)
            result["load_avg_at_end"] = [round(v, 2) for v in os.getloadavg()]
            print(json.dumps(result, indent=2))
        finally:
            for p in reversed(procs):
                p.terminate()
            for p in procs:
                try:
                    p.wait(30)
                except subprocess.TimeoutExpired:
                    p.kill()


if __name__ == "__main__":
    main()
