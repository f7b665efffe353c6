"""Long fuzz of every wire format the simulator side parses, for N seconds per codec.

Codecs: control-protocol lines (LineDecoder + Message accessors), image requests
(RequestParser), image frames (FrameDecoder, the client side), vehicle packets
(VehicleStreamParser, CommandStreamParser) and flight-recording lines (parse_record). Inputs are
random bytes, mutations of valid messages, and protocol-shaped fragments, fed in random chunks.
The invariant: every input gives messages or protocol errors (RemoteProtocolError, LineError,
RequestError, FrameError, CommandError, ProtocolViolation, RemoteError), never any other
exception. Prints inputs tried per codec and the count of unexpected exceptions (must be 0).

Usage: python benchmarks/fuzz_protocols.py [--seconds 10] [--seed 1]
"""

from __future__ import annotations

import argparse
import random
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


from skeye.cliargs import positive_float
from skeye.errors import RemoteProtocolError
from skeye.pixels import frame_image
from skeye.recording.records import parse_record
from skeye.wire import images as ip
from skeye.wire import packets
from skeye.wire.image_requests import RequestParser
from skeye.wire.sim_lines import LineDecoder, LineError

SEEDS: dict[str, list[bytes]] = {
    "sim-lines": [
        b"INIT {ClassName hummingbird} {Location 1.5,2,-3} {Rotation 0,0,1.57}\r\n",
        b"DRIVE {LinearVelocity 1} {AltitudeVelocity -0.5} {Normalized false}\r\n",
        b"SET {Type Wind} {Mode constant} {Params speed_m_s=3,from_deg=90}\r\n",
        b"STEP {Count 100}\r\nPING {Id 7}\r\nGETGEO {Type Sonar} {Name Down}\r\n",
        b"SEN {Time 0.1} {Type GroundTruth} {Location 0,0,-1} {Name A F1 Range 2.5}\r\n",
    ],
    "image-requests": [
        b"OK",
        b"U\x00\x00\x00\x01\x00\x00\x00\x02\x00\x00\x00\x10\x00\x00\x00\x10",
        b"SKEYE CAMERA R1/Down\nSKEYE FORMAT JPEG 80\nSKEYE META on\nSKEYE STREAM 30\n",
    ],
    "image-frames": [
        ip.encode_frame(1, b"\xff\xd8jpeg"),
        ip.encode_error_frame("no frame"),
        ip.frame_header(ip.META_OFFSET, ip.META_HEADER_BYTES) + ip.meta_header(1, 0.5, 1, 2, 2),
    ],
}


def _vehicle_seeds() -> list[bytes]:
    out = []
    for cls in list(packets.VEHICLE_BY_PD.values())[:8]:
        try:
            out.append(packets.encode(cls.example()) if hasattr(cls, "example") else b"")
        except Exception:
            pass
    out.append(packets.START + b"\x02\x00\x01ab\x00\x00" + packets.STOP)
    out.append(packets.ACK_START + b"\x01a<")
    return [s for s in out if s]


SEEDS["vehicle-packets"] = _vehicle_seeds()
SEEDS["command-packets"] = [packets.SKEYE_START + b"\x01\x00\x05x\x00\x00" + packets.STOP]
SEEDS["recording"] = [b"1.0 0.5 3 > SEN {Time 0.5} {Type Sonar}\n", b"1 2 0 = TRUTH {Name R1}\n"]


def _mutate(rng: random.Random, seeds: list[bytes]) -> bytes:
    choice = rng.random()
    if choice < 0.3:
        return rng.randbytes(rng.randint(0, 400))
    data = bytearray(b"".join(rng.choice(seeds) for _ in range(rng.randint(1, 4))))
    for _ in range(rng.randint(0, 8)):
        op = rng.random()
        pos = rng.randint(0, len(data)) if data else 0
        if op < 0.4 and data:
            data[min(pos, len(data) - 1)] = rng.randrange(256)
        elif op < 0.7:
            data[pos:pos] = rng.randbytes(rng.randint(1, 8))
        elif data:
            del data[pos : pos + rng.randint(1, 8)]
    return bytes(data)


def _chunks(rng: random.Random, data: bytes) -> list[bytes]:
    out, pos = [], 0
    while pos < len(data):
        n = rng.randint(1, 64)
        out.append(data[pos : pos + n])
        pos += n
    return out


def _sim_lines(rng: random.Random, data: bytes) -> None:
    decoder = LineDecoder(max_line_bytes=rng.choice([64, 1024, 65536]))
    for chunk in _chunks(rng, data):
        for event in decoder.feed(chunk):
            if isinstance(event, LineError):
                continue
            for key, _ in event.fields:
                for accessor in (event.get_float, event.get_int, event.get_bool):
                    try:
                        accessor(key)
                    except RemoteProtocolError:
                        pass
                try:
                    event.get_vector(key, 3)
                except RemoteProtocolError:
                    pass


def _image_requests(rng: random.Random, data: bytes) -> None:
    parser = RequestParser()
    for chunk in _chunks(rng, data):
        parser.feed(chunk)
    assert parser.buffered_bytes <= ip.DEFAULT_MAX_LINE_BYTES + 17


def _image_frames(rng: random.Random, data: bytes) -> None:
    decoder = ip.FrameDecoder(max_frame_bytes=1 << 16)
    for chunk in _chunks(rng, data):
        for event in decoder.feed(chunk):
            if isinstance(event, ip.DecodedFrame):
                try:
                    frame_image(event)
                except RemoteProtocolError:
                    pass


def _vehicle(rng: random.Random, data: bytes) -> None:
    parser = packets.VehicleStreamParser()
    for chunk in _chunks(rng, data):
        parser.feed(chunk)


def _command(rng: random.Random, data: bytes) -> None:
    parser = packets.CommandStreamParser()
    for chunk in _chunks(rng, data):
        parser.feed(chunk)


def _recording(rng: random.Random, data: bytes) -> None:
    for line in data.split(b"\n"):
        try:
            parse_record(line.decode("utf-8", "replace"))
        except RemoteProtocolError:
            pass


TARGETS: dict[str, Callable[[random.Random, bytes], None]] = {
    "sim-lines": _sim_lines,
    "image-requests": _image_requests,
    "image-frames": _image_frames,
    "vehicle-packets": _vehicle,
    "command-packets": _command,
    "recording": _recording,
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=positive_float, default=10.0, help="per codec")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    failures = 0
    for name, target in TARGETS.items():
        rng = random.Random(f"{args.seed}-{name}")
        tried = unexpected = 0
        total_bytes = 0
        end = time.monotonic() + args.seconds
        while time.monotonic() < end:
            data = _mutate(rng, SEEDS[name])
            total_bytes += len(data)
            tried += 1
            try:
                target(rng, data)
            except Exception:
                unexpected += 1
                if unexpected <= 3:
                    print(f"{name}: unexpected exception for {data!r}", file=sys.stderr)
                    traceback.print_exc()
        failures += unexpected
        print(
            f"{name:16s} {tried:9d} inputs ({total_bytes / 1e6:6.1f} MB) "
            f"in {args.seconds:g} s, unexpected exceptions: {unexpected}"
        )
    print("OK: only protocol errors" if failures == 0 else f"FAILED: {failures} unexpected")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
