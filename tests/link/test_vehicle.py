"""The ground-side ``Vehicle`` over an in-memory link: bad input gives skeye errors."""

from __future__ import annotations

import pytest

from skeye.errors import LocalProtocolError
from skeye.link.transport import memory_pair
from skeye.link.vehicle import Vehicle


def test_removing_a_callback_that_was_never_added_names_the_problem() -> None:
    ground, _vehicle_side = memory_pair()
    with Vehicle(ground, keepalive_s=None) as vehicle:
        vehicle.add_callback(print)
        vehicle.remove_callback(print)
        with pytest.raises(LocalProtocolError, match="not a telemetry callback"):
            vehicle.remove_callback(print)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda v: v.pad_mode("hover"), "expected off, hold or land"),
        (lambda v: v.pad_mode(7), "expected 0"),
        (lambda v: v.move_by(1.0, frame="up"), "expected 'body' or 'world'"),
        (lambda v: v.poll(0x0400), "requests no known structure"),
        (lambda v: v.take_off(float("nan")), "must be a finite number"),
        (lambda v: v.set_velocity(40.0), "outside"),
        (lambda v: v.stream(period_s=-1.0), "outside"),
        # not 0, but 0 on the wire, where 0 is a word of its own: it was sent as that word
        (lambda v: v.stream(period_s=0.0004), "0 there means stop streaming"),
        (lambda v: v.set_velocity(1.0, duration_s=0.0004), "0 there means until replaced"),
        (lambda v: v.move_by(1.0, speed_m_s=0.0004), "0 there means the default 1 m/s"),
        (lambda v: v.goto_gps(52.0, 4.0, 10.0, speed_m_s=0.0004), "the default 1 m/s"),
        (lambda v: v.pad_mode("hold", deadband_m=0.0004), "the default 0.05 m"),
    ],
)
def test_bad_arguments_are_local_protocol_errors_sent_nowhere(call, match: str) -> None:
    ground, vehicle_side = memory_pair()
    with Vehicle(ground, keepalive_s=None) as vehicle:
        with pytest.raises(LocalProtocolError, match=match):
            call(vehicle)
        assert vehicle_side.recv(0.05) == b""  # nothing reached the vehicle


def test_a_noisy_line_logs_a_bad_frame_warning_at_most_every_five_seconds(
        caplog: pytest.LogCaptureFixture) -> None:
    """Every bad frame was a warning of its own: a line with a fifth of its frames corrupted
    logged more than one a second, where docs/onboard.md promises one at most every 5 s."""
    import logging
    import time

    ground, vehicle_side = memory_pair()
    with caplog.at_level(logging.WARNING, logger="skeye.link.vehicle"), \
            Vehicle(ground, keepalive_s=None) as vehicle:
        vehicle_side.send(b">a\x17zz" * 20)  # acks whose stop bytes are wrong
        deadline = time.monotonic() + 10.0
        while vehicle.frame_errors < 20 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert vehicle.frame_errors == 20
    warnings = [r.getMessage() for r in caplog.records if "bad frame" in r.getMessage()]
    assert len(warnings) == 1 and "(1 bad frames since the last such warning)" in warnings[0]
