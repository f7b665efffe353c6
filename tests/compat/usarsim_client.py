"""An independent USARSim-style client for the conformance tests (plain sockets, no skeye code).

Written from the public USARSim UDK sources, not from skeye's codec, so that it fails where a
real USARSim client would:

- lines are ``TYPE {...} {...}``, read *positionally*: a client indexes the blocks of a line,
  as the Gamebots-era clients do (``Sensor.GetHead`` writes ``SEN {Time t} {Type T}``, then each
  sensor's ``GetData`` writes ``{Name n}`` and its keys in a fixed order);
- numbers are read with UnrealScript's ``float()`` (C ``atof``: the leading number, else 0);
- vectors with ``Utilities.ParseVector`` (split at the first two commas, ``float()`` of each);
- DRIVE angles are degrees and angular velocities deg/s (``AerialVehicle.uc``, ``AngleFromDeg``).
"""

from __future__ import annotations

import math
import re
import socket
import time

_BLOCK = re.compile(r"\{([^{}]*)\}")
_LEADING_NUMBER = re.compile(r"\s*([+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?)")


def unreal_float(text: str) -> float:
    """UnrealScript ``float(string)``: the leading decimal number, 0.0 if there is none."""
    match = _LEADING_NUMBER.match(text)
    return float(match.group(1)) if match else 0.0


def parse_vector(text: str) -> tuple[float, float, float]:
    """``Utilities.ParseVector``: x before the first comma, y before the next, z the rest."""
    if text == "":
        return (0.0, 0.0, 0.0)
    i = text.find(",")
    x = unreal_float(text[:i] if i >= 0 else "")
    text = text[i + 1 :]
    i = text.find(",")
    y = unreal_float(text[:i] if i >= 0 else "")
    z = unreal_float(text[i + 1 :])
    return (x, y, z)


def blocks(line: str) -> list[tuple[str, str]]:
    """The ``{Key Value}`` blocks of a line in order, as (key, value text)."""
    out = []
    for content in _BLOCK.findall(line):
        key, _, value = content.strip().partition(" ")
        out.append((key, value.strip()))
    return out


def wrap_pi(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


class UsarClient:
    """One connection: send lines, read lines, step a lockstep simulator."""

    def __init__(self, port: int, timeout_s: float = 60.0) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout_s)
        self.buffer = b""
        self.timeout_s = timeout_s
        self.greeting = self.read_line()

    def send(self, line: str) -> None:
        self.sock.sendall(line.encode("ascii") + b"\r\n")

    def read_line(self) -> str:
        deadline = time.monotonic() + self.timeout_s
        while b"\r\n" not in self.buffer:
            if time.monotonic() > deadline:
                raise TimeoutError("no line from the simulator")
            data = self.sock.recv(65536)
            if not data:
                raise ConnectionError("the simulator closed the connection")
            self.buffer += data
        line, self.buffer = self.buffer.split(b"\r\n", 1)
        return line.decode("ascii")

    def read_until(self, prefix: str) -> tuple[list[str], str]:
        """Lines until one that starts with ``prefix``: (the lines before, that line)."""
        seen = []
        while True:
            line = self.read_line()
            if line.startswith(prefix):
                return seen, line
            seen.append(line)

    def step(self, count: int) -> list[str]:
        """Lockstep (a skeye extension): every line those steps produced."""
        self.send(f"STEP {{Count {count}}}")
        seen, _ = self.read_until("RES {Command STEP}")
        return seen

    def sync(self) -> list[str]:
        """PING and wait for its answer: what came before it (an ERR, if the last line failed)."""
        self.send("PING {Id sync}")
        seen, _ = self.read_until("RES {Command PING}")
        return seen

    def close(self) -> None:
        self.sock.close()


def sen_lines(lines: list[str], type_name: str) -> list[list[tuple[str, str]]]:
    """The blocks of every ``SEN`` line whose second block is ``{Type type_name}``."""
    out = []
    for line in lines:
        if line.startswith("SEN "):
            b = blocks(line)
            if len(b) > 1 and b[1] == ("Type", type_name):
                out.append(b)
    return out
