"""The bytes a seeded lockstep flight streams, as a SHA-256: a refactoring check.

Starts ``skeye sim --mode lockstep --seed SEED`` on a free loopback port, flies a fixed script
over the raw simulator protocol (spawn, wind, take-off, translate, yaw, descend, queries), and
prints the digest and size of every byte the simulator sent. Two checkouts that stream the same
bytes print the same line; ``--save FILE`` keeps the bytes for a ``cmp``.

    python tools/stream_digest.py [--seed 7] [--save stream.bin]

Only the same machine and MuJoCo build are comparable (floating point is not portable).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import socket
import subprocess
import sys
import time

SCRIPT: list[tuple[str, int]] = [  # (command, steps to run after it)
    ("INIT {ClassName hummingbird} {Name R1} {Start Pad1}", 200),
    ("SET {Type Wind} {Mode turbulence} {Params sigma_m_s=0.5}", 0),
    ("GETCONF {Type Robot}", 0),
    ("GETGEO {Type Robot}", 0),
    ("DRIVE {AltitudeVelocity 0.5}", 3000),
    ("DRIVE {LinearVelocity 0.8} {LateralVelocity 0.3} {AltitudeVelocity 0}", 2000),
    ("DRIVE {LinearVelocity 0} {LateralVelocity 0} {RotationalVelocity 28.6479}", 1500),
    ("DRIVE {RotationalVelocity 0} {AltitudeVelocity -0.4}", 4000),  # deg/s, as USARSim
    ("PING {Id 1}", 0),
]

ANSWERS = {"INIT": b"RES {Command INIT}", "SET": b"RES {Command SET}", "GETCONF": b"CONF",
           "GETGEO": b"GEO", "PING": b"RES {Command PING}"}  # what each command waits for


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _read_until(sock: socket.socket, buf: bytearray, marker: bytes, timeout_s: float) -> None:
    end = time.monotonic() + timeout_s
    while marker not in buf[-4096 - len(marker):] or not buf.endswith(b"\n"):
        if time.monotonic() > end:
            raise TimeoutError(f"no {marker!r} within {timeout_s:g} s; last: {bytes(buf[-300:])!r}")
        sock.settimeout(max(0.1, end - time.monotonic()))
        try:
            data = sock.recv(65536)
        except TimeoutError:
            continue
        if b"\nERR " in data or data.startswith(b"ERR "):
            raise RuntimeError(f"the simulator refused: {data[-300:]!r}")
        if not data:
            raise ConnectionError("the simulator closed the connection")
        buf += data


def stream(seed: int, timeout_s: float = 60.0) -> bytes:
    """Every byte the simulator sends during :data:`SCRIPT`."""
    port, image_port = _free_port(), _free_port()
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.setdefault("MUJOCO_GL", "egl")
    proc = subprocess.Popen(
        [sys.executable, "-m", "skeye.cli", "sim", "--mode", "lockstep", "--seed", str(seed),
         "--port", str(port), "--image-port", str(image_port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        end = time.monotonic() + timeout_s
        while True:
            try:
                sock = socket.create_connection(("127.0.0.1", port), timeout=1.0)
                break
            except OSError:
                if proc.poll() is not None or time.monotonic() > end:
                    raise RuntimeError("skeye sim did not start") from None
                time.sleep(0.2)
        buf = bytearray()
        with sock:
            _read_until(sock, buf, b"NFO", timeout_s)
            for command, steps in SCRIPT:
                word = command.split()[0]
                sock.sendall(command.encode() + b"\r\n")
                if word in ANSWERS:
                    _read_until(sock, buf, ANSWERS[word], timeout_s)
                if steps:
                    sock.sendall(f"STEP {{Count {steps}}}\r\n".encode())
                    _read_until(sock, buf, b"RES {Command STEP}", timeout_s)
        return bytes(buf)
    finally:
        proc.terminate()
        proc.wait(30)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--save", metavar="FILE", help="also write the bytes to FILE")
    args = parser.parse_args()
    data = stream(args.seed)
    if args.save:
        with open(args.save, "wb") as f:
            f.write(data)
    print(f"sha256 {hashlib.sha256(data).hexdigest()}  {len(data)} bytes  "
          f"seed {args.seed}  {data.count(b'SEN ')} SEN lines  {data.count(b'ERR')} ERR")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
