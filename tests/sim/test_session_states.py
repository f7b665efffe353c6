"""The control connection's states as a transition table (skeye.sim.session), sans-IO."""

from __future__ import annotations

import pytest

from skeye.errors import LocalProtocolError
from skeye.sim.session import TRANSITIONS, Conn, ConnectionStates, ConnEvent


def test_a_connection_goes_from_awaiting_to_bound_to_closed() -> None:
    s = ConnectionStates()
    assert s.state is Conn.AWAITING
    assert s.refusal("DRIVE", None) == "DRIVE needs a robot: send INIT first"
    assert s.refusal("PING", None) is None and s.refusal("INIT", None) is None
    s.line()
    assert s.state is Conn.OPEN
    assert s.refusal("GETCONF", None) == "GETCONF needs a robot: send INIT first"
    s.bind()
    assert s.state is Conn.BOUND
    assert s.refusal("DRIVE", "R1") is None
    assert s.refusal("INIT", "R1") == (
        "this connection already drives robot R1 (one robot per connection)")
    s.line()
    s.close()
    assert s.state is Conn.CLOSED
    s.close()  # closing twice is harmless


def test_quiet_connections_close_unless_they_drive_a_robot() -> None:
    s = ConnectionStates()
    assert s.quiet(9.9, handshake_timeout_s=10.0, idle_timeout_s=120.0) is None
    assert s.quiet(10.0, 10.0, 120.0) == "no command within 10 s of connecting; closed"
    assert s.state is Conn.CLOSED
    s = ConnectionStates()
    s.line()
    assert s.quiet(60.0, 10.0, 120.0) is None
    assert s.quiet(120.0, 10.0, 120.0) == "idle for 120 s without a robot; closed"
    s = ConnectionStates()
    s.line()
    s.bind()
    assert s.quiet(1e6, 10.0, 120.0) is None and s.state is Conn.BOUND


def test_illegal_transitions_raise() -> None:
    s = ConnectionStates()
    s.line()
    s.bind()
    with pytest.raises(LocalProtocolError, match="no transition"):
        s.bind()  # a second robot
    s.close()
    with pytest.raises(LocalProtocolError, match="no transition"):
        s.line()
    assert (Conn.BOUND, ConnEvent.QUIET) not in TRANSITIONS
    assert all((state, ConnEvent.CLOSE) in TRANSITIONS for state in Conn)
