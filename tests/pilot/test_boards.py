"""The emulated boards, sans I/O: answers, refusals, stick gesture, failsafe, state table."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.pilot.boards import BoardSettings, OnboardBoards
from skeye.pilot.envelope import FlightEnvelope
from skeye.pilot.states import TRANSITIONS, FlightEvent, FlightStateMachine, IllegalTransition
from skeye.wire.crc import crc16
from skeye.wire.packets import (
    PD,
    Ack,
    CommandStreamParser,
    CtrlInput,
    CurrentWay,
    Hold,
    ImuCalcData,
    Land,
    LlStatus,
    MoveBy,
    MoveFrame,
    NavigationStatus,
    NavState,
    NavStatus,
    PadAction,
    PadMode,
    PadReport,
    Poll,
    PollMask,
    Result,
    ResultCode,
    SkeyeMask,
    Stream,
    TakeOff,
    Velocity,
    Waypoint,
    WaypointGoto,
    WaypointProps,
    encode,
)
from tests.pilot.fake_airframe import FakeAirframe


def make(link_timeout_s: float = 2.0, land_timeout_s: float = 20.0):
    air = FakeAirframe()
    boards = OnboardBoards(air, BoardSettings(link_timeout_s, land_timeout_s), now_s=0.0)
    return air, boards


def send(boards: OnboardBoards, data: bytes, now_s: float = 0.0) -> list:
    out = []
    for event in CommandStreamParser().feed(data):
        out += boards.handle(event, now_s)
    return out


def result(replies: list) -> Result:
    assert len(replies) == 1 and isinstance(replies[0], Result), replies
    return replies[0]


def skeye_frame(pd: int, payload: bytes, crc: int | None = None) -> bytes:
    c = crc16(payload) if crc is None else crc
    return (
        b">*>s"
        + len(payload).to_bytes(2, "little")
        + bytes([pd])
        + payload
        + c.to_bytes(2, "little")
        + b"<#<"
    )


def airborne(boards: OnboardBoards, air: FakeAirframe, now_s: float = 0.0) -> None:
    assert result(send(boards, encode(TakeOff(1000)), now_s)).code is ResultCode.OK
    air.finish(landed=False, armed=True, pos_ned_m=(0.0, 0.0, -1.0))
    boards.tick(now_s)
    assert boards.state is NavState.HOLDING


def test_take_off_climbs_above_the_current_height_and_holds_when_done():
    air, boards = make()
    assert result(send(boards, encode(TakeOff(1500)))).code is ResultCode.OK
    assert air.calls[-1] == ("take_off", (1.5,))
    assert boards.state is NavState.TAKING_OFF
    boards.tick(0.1)
    assert boards.state is NavState.TAKING_OFF  # still climbing
    air.finish(landed=False, armed=True)
    boards.tick(0.2)
    assert boards.state is NavState.HOLDING


@pytest.mark.parametrize(
    ("msg", "code"),
    [
        (Land(), ResultCode.REFUSED),
        (Hold(), ResultCode.REFUSED),
        (MoveBy(1000, 0, 0, 0, MoveFrame.BODY_FRD, 500), ResultCode.REFUSED),
        (Velocity(100, 0, 0, 0, 0), ResultCode.REFUSED),
    ],
)
def test_commands_refused_while_landed(msg, code):
    air, boards = make()
    r = result(send(boards, encode(msg)))
    assert r.code is code and "landed" in r.reason
    assert air.calls == []  # nothing reached the vehicle


def test_take_off_while_taking_off_is_busy():
    _, boards = make()
    send(boards, encode(TakeOff(1000)))
    r = result(send(boards, encode(TakeOff(1000))))
    assert r.code is ResultCode.BUSY and r.command_pd == PD.TAKE_OFF


def test_move_by_body_frame_turns_with_heading():
    air, boards = make()
    airborne(boards, air)
    air.finish(rpy_rad=(0.0, 0.0, 1.5707963267948966))  # facing east
    assert result(send(boards, encode(MoveBy(1000, 0, -500, 0, MoveFrame.BODY_FRD, 0)))).code == 0
    name, (n, e, alt, speed) = air.calls[-1]
    assert name == "fly_to" and n == pytest.approx(0.0, abs=1e-9) and e == pytest.approx(1.0)
    assert alt == pytest.approx(1.5) and speed == 1.0
    assert boards.state is NavState.FLYING
    air.finish()
    boards.tick(0.1)
    assert boards.state is NavState.HOLDING


def test_timed_velocity_ends_in_hold_after_its_duration_of_vehicle_time():
    """The duration is the vehicle's (the snapshot's time: sim time on the simulator), not
    the wall clock's: in lockstep the two run apart (a ground station holding the clock, an
    unpaced simulator). It ended on the wall clock: HOLDING (and a hover) after 0.3 s of wall
    time whatever the vehicle had flown."""
    air, boards = make(link_timeout_s=100.0)
    airborne(boards, air)
    air.finish(time_s=10.0)
    send(boards, encode(Velocity(500, 0, -200, 100, 300)), now_s=1.0)
    assert air.calls[-1] == ("set_velocity", (0.5, 0.0, 0.2, 0.1, 0.3))
    air.finish(time_s=10.2)
    boards.tick(50.0)  # long after on the wall clock, 0.2 s on the vehicle's
    assert boards.state is NavState.FLYING and air.calls[-1][0] == "set_velocity"
    air.finish(time_s=10.31)
    boards.tick(50.1)
    assert boards.state is NavState.HOLDING and air.calls[-1][0] == "hover"


def test_velocity_beyond_the_vehicle_limit_is_a_bad_value():
    """The boards check VELOCITY against their settings (the robot file's limits) before the
    airframe sees it: refused, code 3, naming the value and the limit; nothing is flown. An
    airframe's own refusal (the simulator's robot) is still a bad value."""
    air, boards = make()
    airborne(boards, air)
    calls = len(air.calls)
    r = result(send(boards, encode(Velocity(30000, 0, 0, 0, 0))))
    assert r.code is ResultCode.BAD_VALUE
    assert r.reason == "velocity: forward 30 m/s is over this vehicle's limit of 3 m/s"
    assert boards.state is NavState.HOLDING and len(air.calls) == calls  # nothing flown

    def refuse(*args: object) -> None:
        from skeye.errors import LocalProtocolError

        raise LocalProtocolError("set_velocity: forward_m_s=2.0 exceeds the limit 1.0")

    air.set_velocity = refuse
    r = result(send(boards, encode(Velocity(2000, 0, 0, 0, 0))))
    assert r.code is ResultCode.BAD_VALUE and "exceeds" in r.reason
    assert boards.state is NavState.HOLDING  # the state did not change


def test_bad_checksum_length_value_and_unknown_pd_are_answered_and_serving_goes_on():
    _, boards = make()
    good_ctrl = encode(CtrlInput(0, 0, 0, 0, 0))
    bad_ctrl = good_ctrl[:-2] + bytes([good_ctrl[-2] ^ 0xFF, good_ctrl[-1]])
    r = result(send(boards, bad_ctrl))
    assert (r.command_pd, r.code) == (PD.CTRL_INPUT, ResultCode.BAD_CHECKSUM)
    r = result(send(boards, skeye_frame(PD.TAKE_OFF, (1000).to_bytes(4, "little"), crc=0x1234)))
    assert (r.command_pd, r.code) == (PD.TAKE_OFF, ResultCode.BAD_CHECKSUM)
    r = result(send(boards, skeye_frame(PD.TAKE_OFF, b"\x01\x02")))
    assert (r.command_pd, r.code) == (PD.TAKE_OFF, ResultCode.BAD_LENGTH)
    r = result(send(boards, skeye_frame(PD.PAD_MODE, bytes([7, 0, 0, 0, 0]))))  # mode 7
    assert (r.command_pd, r.code) == (PD.PAD_MODE, ResultCode.BAD_VALUE)
    r = result(send(boards, skeye_frame(PD.TAKE_OFF, (0).to_bytes(4, "little"))))  # height 0
    assert (r.command_pd, r.code) == (PD.TAKE_OFF, ResultCode.BAD_VALUE)
    r = result(send(boards, skeye_frame(0x8F, b"")))
    assert (r.command_pd, r.code) == (0x8F, ResultCode.BAD_VALUE)
    r = result(send(boards, b">*>zz"))
    assert (r.command_pd, r.code) == (0, ResultCode.BAD_VALUE)
    replies = send(boards, b"garbage" + encode(Poll(0x0001)))
    assert [type(m) for m in replies] == [LlStatus]
    assert boards.errors["bad_checksum"] == 2 and boards.errors["bad_value"] == 3
    assert replies[0].chksum_error == 2


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=300))
def test_arbitrary_bytes_never_break_the_boards(data):
    _, boards = make()
    for m in send(boards, data):
        encode(m)  # every reply is a valid packet
    assert [type(m) for m in send(boards, encode(Poll(0x0004)))] == [ImuCalcData]


def test_poll_answers_each_structure_in_mask_order_with_scalings():
    _air, boards = make()
    replies = boards.poll(0x03FF)
    assert [type(m).__name__ for m in replies] == [
        "LlStatus",
        "ImuRawData",
        "ImuCalcData",
        "RcData",
        "ControllerOutput",
        "GpsData",
        "CurrentWay",
        "GpsDataAdvanced",
    ]
    ll, _, calc = replies[0], replies[1], replies[2]
    assert ll.battery_voltage_1 == 12400 and ll.flying == 0 and ll.motors_on == 0
    assert calc.acc_z_calib == -10000 and calc.acc_z == 0  # at rest: -1 g body, 0 earth
    assert calc.acc_absolute_value == 10000 and calc.height == 0
    assert replies[5].latitude == 490_000_000 and replies[5].status == 3


def test_pad_mode_is_stored_and_pad_reports_not_found():
    _, boards = make()
    assert result(send(boards, encode(PadMode(PadAction.LAND, 50, 300)))).code == 0
    assert boards.pad.settings.mode is PadAction.LAND
    assert boards.pad.settings.deadband_m == 0.05 and boards.pad.settings.max_speed_m_s == 0.3
    send(boards, encode(Stream(0, int(SkeyeMask.PAD | SkeyeMask.NAV_STATUS), 100)), now_s=0.0)
    out = boards.tick(0.0)
    nav = next(m for m in out if isinstance(m, NavStatus))
    pad = next(m for m in out if isinstance(m, PadReport))
    assert nav.pad_mode is PadAction.LAND and pad.found == 0
    assert boards.tick(0.05) == []  # not due yet
    assert len(boards.tick(0.1)) == 2


def test_link_loss_aborts_a_waypoint_flight():
    # CURRENT_WAY 0x08 for a waypoint flight the link-loss failsafe replaced (docs/protocols/
    # packets.md): a station that comes back learns its 0x02 will not come
    air, boards = make(link_timeout_s=2.0, land_timeout_s=20.0)
    airborne(boards, air, now_s=0.0)
    wp = Waypoint(properties=int(WaypointProps.HEIGHT_ENABLED), max_speed=50, time=100,
                  pos_acc=500, X=3000, Y=0, yaw=0, height=1000)
    assert send(boards, encode(wp), 0.0) == [Ack(PD.WAYPOINT)]
    assert send(boards, encode(WaypointGoto()), 0.0) == [Ack(PD.WAYPOINT_GOTO)]
    boards.tick(1.9)
    (way,) = boards.poll(int(PollMask.CURRENT_WAY))
    assert isinstance(way, CurrentWay) and way.navigation_status == 0x04, way
    boards.tick(2.0)
    assert boards.state is NavState.FAILSAFE
    (way,) = boards.poll(int(PollMask.CURRENT_WAY))
    assert way.navigation_status == int(NavigationStatus.ABORTED), way


def test_link_loss_holds_then_lands():
    air, boards = make(link_timeout_s=2.0, land_timeout_s=20.0)
    airborne(boards, air, now_s=0.0)
    boards.tick(1.9)
    assert boards.state is NavState.HOLDING
    boards.tick(2.0)
    assert boards.state is NavState.FAILSAFE and air.calls[-1][0] == "hover"
    boards.tick(21.9)
    assert boards.state is NavState.FAILSAFE
    boards.tick(22.0)
    assert boards.state is NavState.LANDING and air.calls[-1][0] == "land"
    air.finish(landed=True, armed=False)
    boards.tick(22.1)
    assert boards.state is NavState.LANDED


def test_a_simulated_vehicle_is_failsafe_only_when_the_link_is_silent_on_both_clocks():
    """A simulated vehicle (its clock sim time): a process that stalled 2.5 s of wall time
    while the simulator flew 0.1 s (a loaded machine; a lockstep ground station waiting for
    the time it granted) is not a silent ground station. On the wall clock alone that went
    FAILSAFE, and a take-off in flight never became HOLDING. A gone station is silent on both
    clocks: the failsafe comes once both have passed the link timeout. A real vehicle's
    clock is the wall clock: the wall clock alone (test_link_loss_holds_then_lands)."""
    air, boards = make(link_timeout_s=2.0, land_timeout_s=20.0)
    air.clock_is_sim = True  # type: ignore[attr-defined]
    airborne(boards, air, now_s=0.0)
    boards.tick(0.05)
    air.snap = replace(air.snap, time_s=0.1)
    boards.tick(2.5)  # 2.5 s of wall time, 0.1 s of sim time
    assert boards.state is NavState.HOLDING
    air.snap = replace(air.snap, time_s=1.9)
    boards.tick(30.0)
    assert boards.state is NavState.HOLDING
    air.snap = replace(air.snap, time_s=2.0)
    boards.tick(30.1)  # silent 2 s of sim time and of wall time
    assert boards.state is NavState.FAILSAFE and air.calls[-1][0] == "hover"
    # unpaced (sim time runs ahead): the wall clock's 2 s still count
    air, boards = make(link_timeout_s=2.0, land_timeout_s=20.0)
    air.clock_is_sim = True  # type: ignore[attr-defined]
    airborne(boards, air, now_s=0.0)
    boards.tick(0.05)
    air.snap = replace(air.snap, time_s=50.0)
    boards.tick(1.9)
    assert boards.state is NavState.HOLDING
    boards.tick(2.0)
    assert boards.state is NavState.FAILSAFE


def test_a_packet_during_failsafe_stops_the_land_countdown():
    air, boards = make(link_timeout_s=1.0, land_timeout_s=2.0)
    airborne(boards, air)
    boards.tick(1.0)
    assert boards.state is NavState.FAILSAFE
    send(boards, encode(Poll(1)), now_s=1.5)
    boards.tick(10.0)  # the client polls late: link lost again, but no landing yet
    assert boards.state is NavState.FAILSAFE
    assert result(send(boards, encode(Hold()), now_s=10.0)).code == 0
    assert boards.state is NavState.HOLDING


def test_a_link_lost_again_after_a_packet_in_failsafe_starts_the_land_countdown_again():
    """One packet in FAILSAFE stops the countdown; if the link is then lost again before
    ground control commands anything, the vehicle must still land after the land timeout. It
    hovered in FAILSAFE for good: a station heard once (a reconnect, a single poll) switched
    the failsafe's landing off."""
    air, boards = make(link_timeout_s=1.0, land_timeout_s=2.0)
    airborne(boards, air)
    boards.tick(1.0)
    assert boards.state is NavState.FAILSAFE
    send(boards, encode(Poll(1)), now_s=1.5)
    boards.tick(2.0)
    assert boards.state is NavState.FAILSAFE and boards.tick(2.4) == []
    boards.tick(2.5)  # silent for the link timeout again: lost again, the countdown restarts
    boards.tick(4.4)
    assert boards.state is NavState.FAILSAFE
    boards.tick(4.5)
    assert boards.state is NavState.LANDING and air.calls[-1][0] == "land"


def corrupt_frames() -> list[bytes]:
    """What a broken radio delivers: a skeye HOLD with a wrong CRC, sticks with a wrong command
    checksum, and bytes too broken to name a command."""
    sticks = bytearray(encode(CtrlInput(0, 0, 0, 0, 0x0F)))
    sticks[-2] ^= 0xFF  # the command checksum
    return [skeye_frame(PD.HOLD, b"", crc=0xBEEF), bytes(sticks), b">*>zz"]


def test_corrupt_frames_neither_keep_the_link_nor_stop_the_land_countdown():
    """Only bytes that pass their CRC or checksum show a ground station is there: a radio that
    delivers nothing but corrupt frames is a lost link (each still gets its error answer)."""
    air, boards = make(link_timeout_s=2.0, land_timeout_s=20.0)
    airborne(boards, air, now_s=0.0)
    for i in range(20):
        for data in corrupt_frames():
            send(boards, data, now_s=0.1 * i)
    assert boards.errors["bad_checksum"] == 40
    boards.tick(2.0)
    assert boards.state is NavState.FAILSAFE
    for i in range(200):
        for data in corrupt_frames():
            send(boards, data, now_s=2.0 + 0.1 * i)
    boards.tick(22.0)
    assert boards.state is NavState.LANDING and air.calls[-1][0] == "land"


def test_a_refused_command_that_arrived_intact_keeps_the_link():
    """A frame that passed its CRC was sent by a station, even when its command is refused (a
    value out of range, an unknown skeye PD): the link is up."""
    air, boards = make(link_timeout_s=2.0)
    airborne(boards, air, now_s=0.0)
    assert result(send(boards, skeye_frame(0x8F, b""), now_s=1.5)).code is ResultCode.BAD_VALUE
    bad_mode = skeye_frame(PD.PAD_MODE, bytes([7, 0, 0, 0, 0]))
    assert result(send(boards, bad_mode, now_s=3.0)).code is ResultCode.BAD_VALUE
    boards.tick(4.9)
    assert boards.state is NavState.HOLDING
    boards.tick(5.0)
    assert boards.state is NavState.FAILSAFE


@pytest.mark.parametrize("landing", [False, True])
def test_a_vehicle_lost_in_the_air_is_failsafe_a_landing_too(landing: bool) -> None:
    """The vehicle below stops answering in the air: FAILSAFE, HEALTH LOST, and the land
    timeout's attempt after it. Lost during a landing it is FAILSAFE too, not a LANDING that no
    touchdown will ever end (with an LL board that stopped answering near the ground, the pilot
    said LANDING at 0 mm for good). A ground link lost during a landing keeps landing."""
    air, boards = make(link_timeout_s=2.0, land_timeout_s=20.0)
    airborne(boards, air, now_s=0.0)
    if landing:
        assert result(send(boards, encode(Land()), now_s=0.5)).code == 0
        assert boards.state is NavState.LANDING and air.calls[-1][0] == "land"
    boards.vehicle_lost(1.0, "LL board silent: no answer")
    assert boards.state is NavState.FAILSAFE
    assert boards.health.status.name == "LOST" and "LL board silent" in boards.health.reason
    boards.tick(20.9)
    assert boards.state is NavState.FAILSAFE
    boards.tick(21.0)  # the land timeout: the pilot tries to land it
    assert boards.state is NavState.LANDING and air.calls[-1][0] == "land"
    assert TRANSITIONS[(NavState.LANDING, FlightEvent.LINK_LOST)] is NavState.LANDING


def test_ground_control_heard_does_not_stop_a_lost_vehicles_land_countdown() -> None:
    """A packet stops a lost link's countdown, not a lost vehicle's: the ground being there
    does not bring the vehicle back. With a station connected (its heartbeat polls) the pilot
    never tried to land a vehicle it had lost."""
    air, boards = make(link_timeout_s=2.0, land_timeout_s=20.0)
    airborne(boards, air, now_s=0.0)
    boards.vehicle_lost(1.0, "LL board silent: no answer")
    for i in range(40):  # the heartbeat, every 0.5 s
        send(boards, encode(Poll(1)), now_s=1.0 + 0.5 * i)
        boards.tick(1.0 + 0.5 * i)
    assert boards.state is NavState.FAILSAFE
    boards.tick(21.0)
    assert boards.state is NavState.LANDING and air.calls[-1][0] == "land"


def test_a_vehicle_lost_on_the_ground_stays_landed() -> None:
    _, boards = make()
    boards.vehicle_lost(1.0, "simulator lost")
    assert boards.state is NavState.LANDED and boards.health.status.name == "LOST"


def test_no_failsafe_on_the_ground():
    _, boards = make(link_timeout_s=0.5)
    boards.tick(100.0)
    assert boards.state is NavState.LANDED


def test_motor_gesture_starts_motors_then_sticks_fly():
    air, boards = make()
    gesture = encode(CtrlInput(0, 0, -2047, 0, 0x0F))  # full negative yaw: start (AscTec SDK)
    for i in range(10):
        assert send(boards, gesture, now_s=i * 0.1) == [Ack(PD.CTRL_INPUT)]
    assert not boards.motors_on  # 0.9 s: not yet
    send(boards, gesture, now_s=1.0)
    assert boards.motors_on and boards.state is NavState.LANDED
    assert "attitude" not in air.names()
    send(boards, encode(CtrlInput(400, -400, 0, 2500, 0x0F)), now_s=1.1)
    assert boards.state is NavState.MANUAL
    name, (roll, pitch, _yaw_rate, thrust) = air.calls[-1]
    assert name == "attitude" and thrust == pytest.approx(2500 / 4095)
    assert pitch == pytest.approx(0.174533, rel=1e-4) and roll == pytest.approx(-0.174533, rel=1e-4)


def test_sticks_are_ignored_while_motors_are_off():
    air, boards = make()
    send(boards, encode(CtrlInput(0, 0, 0, 3000, 0x0F)))
    assert air.calls == [] and boards.state is NavState.LANDED


def test_motor_gesture_stops_motors_on_the_ground():
    air, boards = make()
    for i in range(12):
        send(boards, encode(CtrlInput(0, 0, -2047, 0, 0x0F)), now_s=i * 0.1)
    assert boards.motors_on
    for _ in range(12):  # release, then hold again
        send(boards, encode(CtrlInput(0, 0, 0, 0, 0x0F)), now_s=2.0)
    for i in range(12):  # the start gesture again: they run already, nothing changes
        send(boards, encode(CtrlInput(0, 0, -2047, 0, 0x0F)), now_s=3.0 + i * 0.1)
    assert boards.motors_on
    for i in range(12):  # full positive yaw: stop
        send(boards, encode(CtrlInput(0, 0, 2047, 0, 0x0F)), now_s=5.0 + i * 0.1)
    assert not boards.motors_on and air.calls[-1] == ("attitude", (0.0, 0.0, 0.0, 0.0))


def test_state_table_raises_on_illegal_transitions():
    fsm = FlightStateMachine()
    with pytest.raises(IllegalTransition) as info:
        fsm.fire(FlightEvent.LAND)
    assert info.value.code is ResultCode.REFUSED
    assert fsm.fire(FlightEvent.TAKE_OFF) is NavState.TAKING_OFF
    with pytest.raises(IllegalTransition) as info:
        fsm.fire(FlightEvent.MOVE)
    assert info.value.code is ResultCode.BUSY
    assert fsm.state is NavState.TAKING_OFF
    # The sticks take over from every state (docs/pilot.md), a take-off included.
    assert fsm.fire(FlightEvent.STICKS) is NavState.MANUAL
    assert fsm.fire(FlightEvent.HOLD) is NavState.HOLDING
    for state in (NavState.LANDED, NavState.TAKING_OFF, NavState.FLYING, NavState.HOLDING,
                  NavState.LANDING, NavState.FAILSAFE, NavState.MANUAL):
        assert TRANSITIONS[(state, FlightEvent.STICKS)] is NavState.MANUAL
    # Every state can be left towards the ground somehow.
    for state in NavState:
        reachable = {nxt for (s, _), nxt in TRANSITIONS.items() if s is state}
        assert state is NavState.LANDED or reachable & {NavState.LANDING, NavState.LANDED}


def test_speeds_are_flown_as_asked_up_to_the_limit_and_refused_above_it():
    air, boards = make()  # BoardSettings' max_speed_m_s 3.0: skeye pilot sets the robot file's
    airborne(boards, air)
    assert result(send(boards, encode(MoveBy(4000, 0, 0, 0, MoveFrame.BODY_FRD, 2500)))).code == 0
    assert air.calls[-1][0] == "fly_to" and air.calls[-1][1][3] == 2.5  # not capped to 1.0
    calls = len(air.calls)
    r = result(send(boards, encode(MoveBy(4000, 0, 0, 0, MoveFrame.BODY_FRD, 3500))))
    assert r.code is ResultCode.BAD_VALUE
    assert "speed 3.5 m/s is over this vehicle's limit of 3 m/s" in r.reason
    assert len(air.calls) == calls  # refused: nothing flown


def test_check_move_is_the_rule_the_boards_refuse_moves_by():
    """``check_move`` (which the MAVLink endpoint asks too) gives the reason a MOVE_BY gets:
    the speed limit first, then the envelope around home; None inside both."""
    air = FakeAirframe()
    boards = OnboardBoards(air, BoardSettings(envelope=FlightEnvelope(max_radius_m=20.0)))
    airborne(boards, air)
    n, e, d = air.snapshot().pos_ned_m
    assert boards.check_move((n + 4.0, e, d), 2.5) is None
    assert boards.check_move(speed_m_s=3.0) is None  # the limit itself is allowed
    for move, target, speed in ((MoveBy(4000, 0, 0, 0, MoveFrame.WORLD_NED, 3500), 4.0, 3.5),
                                (MoveBy(30000, 0, 0, 0, MoveFrame.WORLD_NED, 3500), 30.0, 3.5),
                                (MoveBy(30000, 0, 0, 0, MoveFrame.WORLD_NED, 2000), 30.0, 2.0)):
        reason = boards.check_move((n + target, e, d), speed)
        r = result(send(boards, encode(move)))
        assert r.code is ResultCode.BAD_VALUE and r.reason == reason, (reason, r.reason)
    assert boards.check_move(speed_m_s=3.5) == "speed 3.5 m/s is over this vehicle's limit of 3 m/s"
    assert boards.check_move((n + 30.0, e, d)).startswith("outside the flight envelope: 30")
    assert boards.check_move((n + 30.0, e, d), home_ned_m=(n + 20.0, e, d)) is None


def test_a_pad_landing_ends_pad_mode_at_touchdown_and_hold_stays():
    air, boards = make()
    airborne(boards, air)
    assert result(send(boards, encode(PadMode(PadAction.LAND, 50, 300)))).code == 0
    boards.land()  # the pad controller's touchdown hand-over
    air.finish(landed=True, armed=False)
    boards.tick(0.1)
    assert boards.state is NavState.LANDED
    assert boards.pad.mode is PadAction.OFF
    assert boards.pad.settings.deadband_m == 0.05  # only the mode ends
    airborne(boards, air, now_s=1.0)
    assert result(send(boards, encode(PadMode(PadAction.HOLD, 50, 300)))).code == 0
    assert result(send(boards, encode(Land()))).code == 0
    air.finish(landed=True, armed=False)
    boards.tick(1.1)
    assert boards.pad.mode is PadAction.HOLD  # only a pad *landing* ends with the landing


def test_nav_status_height_is_above_the_ground_at_home():
    air, boards = make()
    air.finish(pos_ned_m=(2.0, 3.0, -0.09))  # resting on its gear, body origin 9 cm up
    boards = OnboardBoards(air, BoardSettings(), now_s=0.0)
    send(boards, encode(Stream(0, int(SkeyeMask.NAV_STATUS), 100)))
    nav = next(m for m in boards.tick(0.0) if isinstance(m, NavStatus))
    assert (nav.x, nav.y, nav.z) == (2000, 3000, 0)  # landed: height 0
    assert result(send(boards, encode(TakeOff(1500)))).code == 0
    assert air.calls[-1][0] == "take_off" and air.calls[-1][1][0] == pytest.approx(1.59)
    air.finish(landed=False, armed=True, pos_ned_m=(2.0, 3.0, -1.59))
    nav = next(m for m in boards.tick(1.0) if isinstance(m, NavStatus))
    assert nav.z == -1500  # "take off to 1.5 m" shows 1.5 m


def test_the_stream_names_the_vehicle_and_sends_truth_only_for_a_simulated_one():
    """VEHICLE once a second with NAV_STATUS; TRUTH when asked for and the airframe knows its
    truth (a simulated one), in NAV_STATUS's frame; NAV_STATUS carries the estimate's sigma."""
    from dataclasses import replace

    from skeye.pilot.telemetry import GPS_DRMS_M
    from skeye.wire.packets import Truth, VehicleInfo

    air, boards = make()
    air.finish(pos_ned_m=(2.0, 3.0, -0.09))
    boards = OnboardBoards(air, BoardSettings(), now_s=0.0)
    mask = int(SkeyeMask.NAV_STATUS | SkeyeMask.TRUTH)
    send(boards, encode(Stream(0, mask, 100)))
    out = boards.tick(0.0)
    info = next(m for m in out if isinstance(m, VehicleInfo))
    assert info == VehicleInfo(0, air.describe())  # a real vehicle, as far as it says
    assert not any(isinstance(m, Truth) for m in out)  # it knows no truth: none is made up
    nav = next(m for m in out if isinstance(m, NavStatus))
    assert (nav.sigma_h, nav.sigma_v) == (0, 0)  # not stated
    air.finish(pos_sigma_ned_m=(0.03, 0.04, 0.0002), truth_ned_m=(2.5, 2.5, -0.09),
               truth_yaw_rad=math.radians(90.0))
    out = boards.tick(0.15)
    nav = next(m for m in out if isinstance(m, NavStatus))
    # GPS-aided: the filter's sqrt(30^2 + 40^2) = 50 mm with the receiver's 2.5 m CEP (3.0 m
    # DRMS) added, which the filter does not model; vertical: at least 1 mm
    assert (nav.sigma_h, nav.sigma_v) == (round(math.hypot(0.05, GPS_DRMS_M) * 1000), 1)
    assert GPS_DRMS_M == pytest.approx(3.0, abs=0.01)
    truth = next(m for m in out if isinstance(m, Truth))
    assert (truth.x, truth.y, truth.z, truth.yaw) == (2500, 2500, 0, 90000)
    assert not any(isinstance(m, VehicleInfo) for m in out)  # once a second
    info = next(m for m in boards.tick(1.05) if isinstance(m, VehicleInfo))
    assert info.simulated == 1
    send(boards, encode(Stream(0, int(SkeyeMask.NAV_STATUS), 100)), now_s=1.1)
    assert not any(isinstance(m, Truth) for m in boards.tick(1.3))  # not asked for
    air.finish(gps=replace(air.snap.gps, fix=False))  # indoors: the filter's own figure
    nav = next(m for m in boards.tick(1.5) if isinstance(m, NavStatus))
    assert nav.sigma_h == 50
    air.finish(pos_sigma_ned_m=(math.nan, 0.0, math.inf))  # a diverged filter
    nav = next(m for m in boards.tick(1.7) if isinstance(m, NavStatus))
    assert (nav.sigma_h, nav.sigma_v) == (0, 0xFFFF)  # not known; saturated


def test_gps_best_estimate_is_the_ins_position_anchored_to_the_mean_fix():
    from skeye.geo import GeoOrigin
    from skeye.pilot.airframe import GpsFix
    from skeye.wire.packet_units import gps_data_advanced_to_si
    from skeye.wire.packets import GpsDataAdvanced, PollMask

    air, boards = make()
    origin = GeoOrigin(49.0, 8.0, 0.0)
    truth = (10.0, -4.0, -1.0)  # where the INS (and the vehicle) is
    errors = [(2.0, -1.5), (-1.0, 2.5), (0.5, -0.5), (-1.5, -0.5)]  # fix errors, mean 0
    for i, (dn, de) in enumerate(errors):
        lat, lon, _ = origin.to_geodetic(truth[0] + dn, truth[1] + de, 0.0)
        air.finish(pos_ned_m=truth, gps=GpsFix(True, 9, lat, lon, 100.0, (0.0, 0.0, 0.0)))
        boards.tick(0.01 * i)
    assert boards.geo.fixes == 5  # and the fake's first, exact fix at the origin
    msg = boards.poll(int(PollMask.GPS_DATA_ADVANCED))[0]
    assert isinstance(msg, GpsDataAdvanced)
    raw, best = gps_data_advanced_to_si(msg)
    n, e, _ = origin.to_ned(best.latitude_deg, best.longitude_deg, 0.0)
    assert math.hypot(n - truth[0], e - truth[1]) < 0.05  # the mean fix: errors cancel
    n, e, _ = origin.to_ned(raw.latitude_deg, raw.longitude_deg, 0.0)
    assert math.hypot(n - truth[0], e - truth[1]) > 1.0  # the last raw fix is 1.6 m off


def test_the_envelope_stops_stick_flight_beyond_it_and_the_sticks_take_over_again():
    air = FakeAirframe()
    boards = OnboardBoards(air, BoardSettings(envelope=FlightEnvelope(max_radius_m=20.0)))
    airborne(boards, air)
    send(boards, encode(CtrlInput(-600, 0, 0, 2500, 0x0F)))  # attitude mode: not limited
    assert boards.state is NavState.MANUAL
    air.finish(pos_ned_m=(20.5, 0.0, -1.0), vel_ned_m_s=(2.0, 0.0, 0.0))
    boards.tick(0.1)
    assert boards.state is NavState.HOLDING and air.names()[-1] == "hover"
    assert boards.envelope_stops == 1
    send(boards, encode(CtrlInput(600, 0, 0, 2500, 0x0F)), now_s=0.2)  # back in: the sticks win
    assert boards.state is NavState.MANUAL


def test_at_the_pole_a_gps_target_is_placed_and_the_envelope_applies_to_it():
    """A fix at latitude 90 deg is valid (longitude degenerate there): a GOTO_GPS target is
    measured from the pole like any other, so the envelope around home refuses a far one."""
    from dataclasses import replace

    from skeye.pilot.airframe import GpsFix
    from skeye.wire.packet_units import GotoGpsSi, goto_gps_from_si

    air = FakeAirframe()
    air.snap = replace(air.snap, gps=GpsFix(True, 9, 90.0, 0.0, 2835.0, (0.0, 0.0, 0.0)))
    boards = OnboardBoards(air, BoardSettings(envelope=FlightEnvelope(max_radius_m=20.0)))
    airborne(boards, air)
    near = 90.0 - 10.0 / 111_694.0  # 10 m from the pole (any longitude)
    far = 90.0 - 100.0 / 111_694.0
    r = result(send(boards, encode(goto_gps_from_si(GotoGpsSi(far, 120.0, 1.0, 1.0)))))
    assert r.code is ResultCode.BAD_VALUE and "outside the flight envelope: 100" in r.reason
    r = result(send(boards, encode(goto_gps_from_si(GotoGpsSi(near, 120.0, 1.0, 1.0)))))
    assert r.code is ResultCode.OK and air.names()[-1] == "fly_to_gps"
