"""Every airframe backend passes one conformance test; the registry picks them by URI.

A backend (skeye/pilot/airframe.py) is opened by ``open_airframe(uri, options)`` and must then
behave as the boards expect of any vehicle: a sane snapshot at rest, a take-off that is busy
until the height is reached, velocities that move it, a hover, a landing that ends landed with
the motors off, a ``describe`` line, ``lost`` None while it answers, and an idempotent
``close``. The sim:// and asctec-ll:// backends fly a lockstep simulator (the latter through
the simulator's emulated LL board on a pseudo-terminal), where ``advance`` drives the time; the
mavlink:// one flies skeye's own MAVLink vehicle on a real-time simulator (a flight controller
keeps its own clock), waited on in sim time. A new backend adds its entry to
``BACKEND_FIXTURES``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager

import pytest

from skeye.errors import LocalProtocolError
from skeye.hil.cli import parse_ll_board, start_ll_board
from skeye.pilot import airframe as airframe_module
from skeye.pilot.airframe import (
    AirframeBackend,
    AirframeOptions,
    airframe_scheme,
    open_airframe,
    register_airframe,
)
from skeye.pilot.asctec_ll import parse_asctec_ll
from skeye.pilot.sim_airframe import sim_address
from tests.sim.conftest import running_sim

Truth = Callable[[], tuple[float, float, float, float]]  # sim time, north, east, down


@contextmanager
def sim_backend() -> Iterator[tuple[AirframeBackend, Truth]]:
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=5, estimator="truth"))
        air = open_airframe(f"sim://127.0.0.1:{server.port}", AirframeOptions())
        stack.callback(air.close)
        yield air, _truth(server)


@contextmanager
def asctec_ll_backend() -> Iterator[tuple[AirframeBackend, Truth]]:
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=5, estimator="truth"))
        board = start_ll_board(stack, parse_ll_board("R1=pty"), f"127.0.0.1:{server.port}")
        air = open_airframe(board.line.client_uri() + "?lockstep=1", AirframeOptions())
        stack.callback(air.close)
        yield air, _truth(server)


@contextmanager
def mavlink_backend() -> Iterator[tuple[AirframeBackend, Truth]]:
    from skeye.control.connection import connect
    from skeye.pilot.mavlink_server import MavlinkServer
    from skeye.pilot.server import PilotServer
    from skeye.pilot.sim_airframe import SimAirframe
    from tests.mavlink.conftest import free_udp_port

    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="realtime", seed=5, estimator="truth"))
        sim = stack.enter_context(connect(f"127.0.0.1:{server.port}", timeout_s=30.0))
        controller = stack.enter_context(PilotServer(SimAirframe(sim, sim.spawn(
            "hummingbird", start="Pad1")), port=0))
        port = free_udp_port()
        stack.enter_context(MavlinkServer(controller.boards, controller.lock,
                                          [f"udp://127.0.0.1:{port}"]))
        air = open_airframe(f"mavlink://udpout/127.0.0.1:{port}", AirframeOptions(timeout_s=60))
        stack.callback(air.close)
        yield air, _truth(server)


def _truth(server) -> Truth:
    def read():
        return server.runner.call(
            lambda s: (s.time_s, *(float(v) for v in s.body_state("R1").pos_ned_m)))
    return read


BACKEND_FIXTURES = {"sim": sim_backend, "asctec-ll": asctec_ll_backend,
                    "mavlink": mavlink_backend}
WALL_PER_SIM_S = 20.0  # a stuck guard for the real-time backend, not a speed expectation


def advance_until(air: AirframeBackend, done: Callable[[], bool], limit_s: float,
                  truth: Truth) -> None:
    """Until ``done()``, for at most ``limit_s`` of sim time: a lockstep backend's ``advance``
    moves the time; a real-time one's vehicle keeps its own (waited on here)."""
    start = truth()[0]
    wall_deadline = time.monotonic() + WALL_PER_SIM_S * limit_s + 60.0
    while not done():
        assert truth()[0] <= start + limit_s, f"not done in {limit_s} s of sim time"
        assert time.monotonic() < wall_deadline, "the vehicle's time stopped"
        if air.lockstep:
            air.advance(air.control_period_s)
        else:
            time.sleep(air.control_period_s)
            air.advance(0.0)
        assert air.lost is None, air.lost


def test_every_scheme_in_the_registry_has_a_conformance_fixture():
    assert set(airframe_module.BACKENDS) <= set(BACKEND_FIXTURES)


@pytest.mark.parametrize("scheme", sorted(BACKEND_FIXTURES))
def test_backend_conformance(scheme):
    with BACKEND_FIXTURES[scheme]() as (air, truth):
        assert isinstance(air, AirframeBackend)
        assert air.uri.startswith(scheme + "://") and air.describe()
        assert air.lockstep == air.clock_is_sim  # a lockstep vehicle runs on sim time
        assert air.control_period_s > 0 and air.lost is None
        assert air.limits.max_speed_m_s > 0 and air.limits.max_climb_m_s > 0
        snap = air.snapshot()
        assert snap.landed and not snap.armed and not air.busy
        assert 9.0 < -snap.specific_force_frd_m_s2[2] < 10.6  # gravity, at rest
        assert all(abs(a) < 0.1 for a in snap.rpy_rad[:2]) and snap.battery_v > 9.0
        ground_m = snap.altitude_m

        air.take_off(ground_m + 1.0)
        air.advance(air.control_period_s if air.lockstep else 0.0)
        assert air.busy
        advance_until(air, lambda: not air.busy, 30.0, truth)
        _, n0, e0, d0 = truth()
        assert air.snapshot().altitude_m == pytest.approx(ground_m + 1.0, abs=0.15)
        assert -d0 == pytest.approx(ground_m + 1.0, abs=0.2) and not air.snapshot().landed

        air.set_velocity(0.5, 0.0, 0.0, 0.0, 2.0)  # facing north: 1 m north
        t_start = truth()[0]
        advance_until(air, lambda: truth()[0] >= t_start + 3.0, 5.0, truth)
        air.hover()
        advance_until(air, lambda: truth()[0] >= t_start + 5.0, 3.0, truth)
        _, n1, e1, _ = truth()
        assert n1 - n0 == pytest.approx(1.0, abs=0.3) and abs(e1 - e0) < 0.3

        air.land()
        advance_until(air, lambda: not air.busy, 30.0, truth)
        snap = air.snapshot()
        assert snap.landed and not snap.armed
        assert -truth()[3] < 0.15
        assert air.lost is None
        air.close()
        air.close()  # idempotent


@pytest.mark.parametrize(("uri", "words"), [
    ("127.0.0.1:3000", "expected a URI"),
    ("udp://x:1", "no backend for udp://"),
    ("sim://h:1/path", "no path or options"),
    ("asctec-ll://usb/x", "must be serial/DEVICE or tcp/HOST:PORT"),
    ("asctec-ll://tcp/host", "expected asctec-ll://tcp/HOST:PORT"),
    ("asctec-ll://serial/dev/ttyS1?baud=x", "baud=x"),
    ("asctec-ll://serial/dev/ttyS1?speed=9", "unknown option"),
    ("asctec-ll://tcp/h:1?baud=9600", "baud is for a serial line"),
    ("asctec-ll://serial/dev/ttyS1?lockstep=maybe", "lockstep=maybe"),
    # a baud rate is a whole number: 57600.5 and 5.76e4 were truncated and flown at 57600
    ("asctec-ll://serial/dev/ttyS1?baud=57600.5", "baud=57600.5 is not a whole number"),
    ("asctec-ll://serial/dev/ttyS1?baud=5.76e4", "baud=5.76e4 is not a whole number"),
    # a port of digits str.isdigit takes and int refuses ended the pilot in a ValueError
    # traceback; digits int reads but no link takes (Arabic-Indic) were refused naming an
    # inner tcp:// URI the user never wrote
    ("asctec-ll://tcp/127.0.0.1:\u00b2", "expected asctec-ll://tcp/HOST:PORT"),
    ("asctec-ll://tcp/127.0.0.1:7000\u00b2", "expected asctec-ll://tcp/HOST:PORT"),
    ("asctec-ll://tcp/127.0.0.1:\u0667\u0660\u0660\u0660", "expected asctec-ll://tcp/HOST:PORT"),
    # an IPv6 host without its brackets, or one left open: refused naming an inner tcp:// URI
    ("asctec-ll://tcp/::1:7000", r"asctec-ll://tcp/::1:7000.*in brackets"),
    ("asctec-ll://tcp/[::1:7000", r"asctec-ll://tcp/\[::1:7000.*in brackets"),
])
def test_bad_airframe_uris_are_named(uri, words):
    with pytest.raises(LocalProtocolError, match=words):
        airframe_scheme(uri)
        if uri.startswith("sim://"):
            sim_address(uri)
        else:
            parse_asctec_ll(uri)


def test_uris_parse():
    assert sim_address("sim://127.0.0.1:3000") == "127.0.0.1:3000"
    assert sim_address("sim://localhost") == "localhost:3000"
    s = parse_asctec_ll("asctec-ll://serial/dev/ttyS1?baud=57600")
    assert s.link_uri == "serial:///dev/ttyS1?baud=57600" and not s.lockstep
    s = parse_asctec_ll("asctec-ll://tcp/10.0.0.2:7100?lockstep=1&rate_hz=50")
    assert s.link_uri == "tcp://10.0.0.2:7100" and s.lockstep and s.rate_hz == 50


def test_a_new_scheme_is_one_registration():
    opened = []

    def opener(uri: str, options: AirframeOptions):
        opened.append((uri, options.name))
        return "an airframe"

    register_airframe("test-only", opener)
    try:
        assert open_airframe("test-only://x", AirframeOptions(name="R7")) == "an airframe"
        assert opened == [("test-only://x", "R7")]
    finally:
        del airframe_module.BACKENDS["test-only"]
    with pytest.raises(LocalProtocolError):
        register_airframe("Bad://", opener)


def test_baro_climb_is_the_altitude_change_over_readings_50_ms_apart():
    from skeye.pilot.airframe import BaroClimb

    climb = BaroClimb()
    assert climb.update(10.0, 5.0) == 0.0  # one reading: no rate yet
    assert climb.update(10.04, 9.0) == 0.0  # under 50 ms later: not used
    assert climb.update(10.1, 5.2) == pytest.approx(2.0)  # 0.2 m in 0.1 s
    assert climb.update(10.12, 0.0) == pytest.approx(2.0)  # kept in between
    assert climb.update(10.3, 4.8) == pytest.approx(-2.0)
    assert climb.climb_m_s == pytest.approx(-2.0)


@pytest.mark.parametrize("reason", ["sim time 1.2.3 s", "sim time . s", "sim time - s", "busy"])
def test_a_clock_answer_without_a_readable_sim_time_is_named(reason):
    from types import SimpleNamespace

    from skeye.errors import CommandRejected
    from skeye.pilot.asctec_ll import AscTecLLAirframe, LLLinkSettings
    from skeye.wire.packets import PD, Result, ResultCode

    class Board:  # answers every CLOCK grant OK, with a reason a skeye board never gives
        frame_errors = 0

        def send_raw(self, data: bytes) -> None:
            pass

        def wait_result(self, pd: int, timeout_s: float, *,
                        bad_frames_since: int | None = None) -> Result:
            return Result(int(PD.CLOCK), ResultCode.OK, reason)

    air = SimpleNamespace(vehicle=Board(), settings=LLLinkSettings("tcp://127.0.0.1:1"))
    # "1.2.3" used to reach float() and raise ValueError, which no caller of a cycle expects
    with pytest.raises(CommandRejected, match="did not say its sim time"):
        AscTecLLAirframe._grant(air, 1.0)  # type: ignore[arg-type]


def test_docs_onboard_has_a_row_for_every_airframe_and_camera_scheme():
    """docs/onboard.md's two tables ("Airframes and cameras by URI") are where a user on the
    vehicle looks up what ``--airframe`` and ``--camera`` take: each scheme of the registries
    (``airframe.BACKENDS``, ``camera.BACKENDS``) has a row there. ``mavlink://``, a PX4-style
    flight controller, had none until 2026-11-27 (only docs/protocols/mavlink.md said it)."""
    import re
    from pathlib import Path

    from skeye.pilot import camera as camera_module

    text = (Path(__file__).resolve().parents[2] / "docs" / "onboard.md").read_text()
    section = text.split("## Airframes and cameras by URI", 1)[1].split("\n## ", 1)[0]
    rows = {m.group(1).lower() for m in re.finditer(r"^\| `([a-z0-9-]+)://", section, re.M)}
    for scheme in (*airframe_module.BACKENDS, *camera_module.BACKENDS):
        assert scheme in rows, f"docs/onboard.md has no table row for {scheme}://"
