"""Poll round trip as a real AscTec ground station sees it: start-up and steady state, vision on.

Starts ``skeye sim`` (realtime, pad world, image server) and ``skeye pilot --images`` (the pad
detector running on the down camera) as processes, the way ``skeye up`` does. The moment the
pilot prints that it serves ground control, a plain-socket client (no skeye code on the wire
path but the CRC: ``>*>p`` + uint16 mask out, ``>*>`` frames with a CRC16 back) starts
polling LL_STATUS the way fast ground stations do, and reports

- start-up: the time from the "ground control on" line to the first answer, and how many
  polls went unanswered before it (issue 19, point 8: a client that polls at once is answered
  within a poll period);
- steady state: the round trip of ``--polls`` LL_STATUS polls and of ``--polls`` polls of all
  AscTec structures, p50/p99/max, with the pilot's vision busy on 800x600 frames (point 9:
  p99 < 10 ms on loopback; a ground station waits about 1 ms per byte, 650 tries).

Run: ``python benchmarks/bench_poll.py [--polls 2000]``. Wall-clock figures: they depend on how
busy the machine is, so the run prints the machine's load beside them.
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import struct
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from skeye.cliargs import non_negative_float, positive_int
from skeye.processes import start_skeye, stop_process
from skeye.wire.crc import crc16

LL_STATUS_MASK = 0x0001
ALL_ASCTEC_MASK = 0x0001 | 0x0002 | 0x0004 | 0x0008 | 0x0010 | 0x0080 | 0x0100 | 0x0200
POLL_PERIOD_S = 0.010  # the fast ground station: one poll every 10 ms


class RawPoller:
    """A minimal ground station: polls and counts the frames that come back."""

    def __init__(self, host: str, port: int, timeout_s: float) -> None:
        self.sock = socket.create_connection((host, port), timeout=timeout_s)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buf = b""

    def close(self) -> None:
        self.sock.close()

    def poll(self, mask: int, timeout_s: float) -> float | None:
        """Send one poll; the round trip in seconds until every requested frame arrived."""
        want = bin(mask).count("1")
        t0 = time.perf_counter()
        self.sock.sendall(b">*>p" + struct.pack("<H", mask))
        deadline = t0 + timeout_s
        got = 0
        while got < want:
            frame = self._frame(deadline)
            if frame is None:
                return None
            got += 1
        return time.perf_counter() - t0

    def _frame(self, deadline: float) -> bytes | None:
        while True:
            start = self.buf.find(b">*>")
            if start >= 0 and len(self.buf) >= start + 6:
                (length,) = struct.unpack_from("<H", self.buf, start + 3)
                end = start + 6 + length + 5
                if len(self.buf) >= end:
                    payload = self.buf[start + 6 : start + 6 + length]
                    (crc,) = struct.unpack_from("<H", self.buf, start + 6 + length)
                    stop = self.buf[end - 3 : end]
                    self.buf = self.buf[end:]
                    if stop != b"<#<" or crc != crc16(payload):
                        raise RuntimeError("a frame with a bad CRC or stop string")
                    return payload
            left = deadline - time.perf_counter()
            if left <= 0:
                return None
            self.sock.settimeout(left)
            try:
                chunk = self.sock.recv(65536)
            except TimeoutError:
                return None
            if not chunk:
                raise RuntimeError("the pilot closed the connection")
            self.buf += chunk


def _stats(name: str, rtts: list[float], lost: int) -> None:
    if not rtts:
        print(f"  {name}: no poll answered, unanswered {lost}")
        return
    ms = sorted(r * 1000 for r in rtts)
    p99 = ms[min(len(ms) - 1, int(0.99 * len(ms)))]
    print(f"  {name}: n={len(ms)} p50 {statistics.median(ms):.2f} ms  p99 {p99:.2f} ms  "
          f"max {ms[-1]:.2f} ms  unanswered {lost}  (target p99 < 10 ms)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--polls", type=positive_int, default=2000)
    ap.add_argument("--startup-s", type=non_negative_float, default=10.0,
                    help="how long to poll from the ready line on (start-up phase; 0: none)")
    args = ap.parse_args()

    print(f"load average before: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)")
    sim, found = start_skeye(
        ["sim", "--world", "pad", "--port", "0", "--image-port", "0"],
        [r"control protocol on [\d.]+:(\d+)", r"image server on [\d.]+:(\d+)"], "skeye sim")
    try:
        pilot, pfound = start_skeye(
            ["pilot", "--sim", f"127.0.0.1:{found[0].group(1)}",
             "--images", f"127.0.0.1:{found[1].group(1)}", "--port", "0"],
            [r"ground control on tcp://([\d.]+):(\d+)"], "skeye pilot")
        ready = time.perf_counter()
        try:
            m = pfound[0]
            client = RawPoller(m.group(1), int(m.group(2)), 10.0)
            connected = time.perf_counter() - ready
            # Start-up: poll every 10 ms; a poll not answered within its period counts as missed.
            first: float | None = None
            missed = 0
            startup: list[float] = []
            while time.perf_counter() - ready < args.startup_s:
                rtt = client.poll(LL_STATUS_MASK, POLL_PERIOD_S)
                if rtt is None:
                    missed += 1
                    client.buf = b""  # a late answer must not count for the next poll
                    continue
                if first is None:
                    first = time.perf_counter() - ready
                startup.append(rtt)
                time.sleep(max(0.0, POLL_PERIOD_S - rtt))
            print(f"start-up (vision on): connected {connected * 1000:.1f} ms after the ready "
                  f"line; first answer after {'-' if first is None else f'{first * 1000:.1f}'} ms; "
                  f"{missed} polls unanswered within {POLL_PERIOD_S * 1000:.0f} ms "
                  f"in the first {args.startup_s:g} s")
            if startup:
                _stats("start-up LL_STATUS", startup, missed)
            client.buf = b""
            masks = (("LL_STATUS", LL_STATUS_MASK), ("all 8 structures", ALL_ASCTEC_MASK))
            for name, mask in masks:
                rtts: list[float] = []
                lost = 0
                for _ in range(args.polls):
                    rtt = client.poll(mask, 1.0)
                    if rtt is None:
                        lost += 1
                        client.buf = b""
                    else:
                        rtts.append(rtt)
                _stats(f"steady {name}", rtts, lost)
            client.close()
            with open(f"/proc/{pilot.pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            cpu_s = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
            print(f"pilot CPU time so far: {cpu_s:.1f} s (vision running)")
        finally:
            stop_process(pilot)
    finally:
        stop_process(sim)
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
