"""No thread dies on a value (issue 31): each worker driven with the extreme values its inputs
can carry, against real servers on loopback. (The simulator's own workers: out-of-range wind,
DRIVE, INIT and STEP values are tests/sim/test_hardening.py; fuzzed bytes at every server
tests/robustness/test_fuzz_servers.py; the pilot's vision at an upside-down attitude
tests/pilot/test_crash.py.)"""

from __future__ import annotations

import math
import socket
import struct
import threading
from dataclasses import fields, replace

import httpx
import pytest

from skeye.errors import CommandRejected
from skeye.ground.app import create_app
from skeye.ground.bridge import VehicleBridge
from skeye.ground.guard import GroundSecurity
from skeye.link.vehicle import Vehicle
from skeye.pilot.server import PilotServer
from skeye.wire.packet_defs import LAYOUTS, FrameKind
from skeye.wire.packets import (
    PD,
    CommandStreamParser,
    Poll,
    PollMask,
    SkeyeMask,
    Stream,
    encode,
)
from tests.ground.conftest import UvicornThread, wait_until
from tests.pilot.fake_airframe import FakeAirframe

BIG = 1.0e300
EXTREMES = [math.nan, math.inf, -math.inf, BIG, -BIG, 0.0]


@pytest.mark.parametrize("value", EXTREMES, ids=repr)
def test_the_pilot_loop_and_telemetry_take_any_snapshot(value: float) -> None:
    """Every number of the airframe's snapshot at an extreme (a diverged estimate, a runaway
    vehicle): the loop ticks on, every poll is answered (a structure the value does not fit is
    left out and counted), the link is kept. Before: round(nan) in IMU_RAWDATA raised a
    ValueError in the loop thread and the pilot stopped."""
    air = FakeAirframe()
    snap = air.snap
    changes = {}
    for f in fields(snap):
        v = getattr(snap, f.name)
        if isinstance(v, float) and f.name != "time_s":
            changes[f.name] = value
        elif isinstance(v, tuple) and v and all(isinstance(x, float) for x in v):
            changes[f.name] = tuple(value for _ in v)
    air.snap = replace(snap, **changes)
    with PilotServer(air, port=0) as pilot, Vehicle.open(pilot.address, timeout_s=30) as v:
        v.stream(int(sum(PollMask)), int(SkeyeMask.NAV_STATUS | SkeyeMask.PAD), 0.02)
        for _ in range(2):  # the stream goes on (HEALTH, PAD and what fits), twice a second
            v.wait_for(PD.HEALTH, timeout_s=30)
        assert PD.CURRENT_WAY in v.poll(int(PollMask.CURRENT_WAY))  # polls are answered
        unfit = pilot.boards.telemetry.unfit
        if not (math.isfinite(value) and abs(value) < 1e9):
            wait_until(lambda: sum(unfit.values()) > 0, 30, "the unfit structures counted")
        else:
            assert not unfit, unfit
        assert pilot.loop_error is None and pilot.vehicle_lost is None and v.connected
    assert pilot.loop_faults == 0


def _extreme_frames(low: bool) -> bytes:
    """Every structure the vehicle sends, each field at the bottom (or top) of its range."""
    data = b""
    for cls, layout in LAYOUTS.items():
        if layout.kind is not FrameKind.VEHICLE:
            continue
        kwargs = {}
        for f in layout.fields:
            if f.computed:
                continue
            lo, hi = f.limits
            value = lo if low else hi
            if f.enum is not None:
                members = sorted(int(m) for m in f.enum)
                value = members[0] if low else members[-1]
            if f.bits is not None:
                value = 0 if low else f.bits
            kwargs[f.name] = tuple(value for _ in range(f.count)) if f.count > 1 else value
        if layout.tail is not None:
            longest = getattr(cls, "MAX_DESCRIPTION_BYTES", getattr(cls, "MAX_REASON_BYTES", 800))
            kwargs[layout.tail] = "" if low else "\u00e9" * min(400, longest // 2)
        try:
            data += encode(cls(**kwargs))
        except Exception:  # a cross-field rule refuses this combination: leave it out
            continue
    return data


def test_the_ground_bridge_takes_every_structure_at_its_extremes() -> None:
    """A vehicle that sends every structure with every field at the bottom, then the top, of
    what the wire carries: the bridge thread lives on and the page's state stays valid JSON."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]
    stop = threading.Event()

    def vehicle() -> None:  # answers the bridge's STREAM and polls, then floods extremes
        conn, _ = listener.accept()
        with conn:
            serve(conn)

    def serve(conn: socket.socket) -> None:
        conn.settimeout(0.2)
        parser = CommandStreamParser()
        while not stop.is_set():
            try:
                data = conn.recv(4096)
            except TimeoutError:
                data = b""
            except OSError:
                return
            for event in parser.feed(data):
                if isinstance(event, Stream | Poll):
                    from skeye.wire.packets import Result, ResultCode
                    conn.sendall(encode(Result(0x87, ResultCode.OK)) if isinstance(event, Stream)
                                 else _extreme_frames(low=True))
            try:
                conn.sendall(_extreme_frames(low=True) + _extreme_frames(low=False))
            except OSError:
                return

    thread = threading.Thread(target=vehicle, daemon=True)
    thread.start()
    security = GroundSecurity()
    with VehicleBridge(f"tcp://127.0.0.1:{port}", retry_s=0.2) as bridge:
        web = UvicornThread(create_app(bridge, security=security), security.token)
        try:
            wait_until(lambda: bridge.quality().packets > 200, 60, "the extreme packets")
            r = httpx.get(f"{web.url}/api/state", headers=web.auth, timeout=30)
            assert r.status_code == 200, r.text
            state = r.json()
            assert state["nav"] is not None and state["health"] is not None
            assert bridge._thread is not None and bridge._thread.alive
        finally:
            stop.set()
            web.close()
            listener.close()
            thread.join(10)


def test_the_extreme_frames_cover_every_vehicle_structure() -> None:
    sent = {struct.unpack_from("<B", f, 5)[0] for f in _split(_extreme_frames(low=False))}
    expected = {int(lay.pd) for lay in LAYOUTS.values()
                if lay.kind is FrameKind.VEHICLE and lay.pd is not None}
    assert sent == expected


def _split(data: bytes) -> list[bytes]:
    frames = []
    while data:
        size = struct.unpack_from("<H", data, 3)[0]
        frames.append(data[: 3 + 2 + 1 + size + 2 + 3])
        data = data[3 + 2 + 1 + size + 2 + 3:]
    return frames


@pytest.mark.parametrize("value", [math.nan, math.inf], ids=repr)
def test_commands_on_a_vehicle_whose_estimate_is_not_finite_are_refused_not_fatal(
        value: float) -> None:
    """Before, a take-off on a NaN estimate raised in the pilot's reader thread: the ground
    link died with it."""
    air = FakeAirframe()
    air.snap = replace(air.snap, pos_ned_m=(value, value, value), rpy_rad=(value, 0.0, value))
    with PilotServer(air, port=0) as pilot, Vehicle.open(pilot.address, timeout_s=30) as v:
        for command in (lambda: v.take_off(1.0), lambda: v.move_by(forward_m=1.0),
                        lambda: v.set_velocity(0.5, duration_s=1.0)):
            try:
                command()
            except CommandRejected as exc:  # refused (a state, the envelope, the value)
                assert exc.code in (3, 4), exc
        assert PD.CURRENT_WAY in v.poll(int(PollMask.CURRENT_WAY))  # the link lives on
        assert pilot.loop_error is None and v.connected
