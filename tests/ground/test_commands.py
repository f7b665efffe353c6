"""Command validation, link state table, packet rate and telemetry conversion (no I/O)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError
from skeye.ground.bridge import LinkEvent, LinkState, PacketRate, next_link_state
from skeye.ground.commands import COMMANDS, GroundCommand, describe_commands, parse_command
from skeye.ground.telemetry import telemetry_json
from skeye.wire.packet_units import NavStatusSi, PadSi, nav_status_from_si, pad_report_from_si
from skeye.wire.packets import PD, CurrentWay, Health, HealthStatus, NavState, PadAction


def test_defaults_are_filled_in() -> None:
    cmd = parse_command("velocity", {"forward_m_s": 0.5})
    assert cmd.kwargs() == {
        "forward_m_s": 0.5, "right_m_s": 0.0, "up_m_s": 0.0, "yaw_rate_rad_s": 0.0,
        "duration_s": 0.0,
    }
    assert parse_command("land", None) == GroundCommand("land", ())
    assert parse_command("pad_mode", {"mode": "HOLD"}).kwargs()["mode"] == "hold"


@pytest.mark.parametrize(
    ("name", "body", "message"),
    [
        ("fly", {}, "unknown command 'fly'; known commands: velocity"),
        ("take_off", [1.5], "arguments must be a JSON object, got list"),
        ("take_off", {"height": 1.5}, "unknown argument(s) height; expected: height_m"),
        ("goto_gps", {"latitude_deg": 50.0, "height_m": 2}, "missing argument 'longitude_deg'"),
        ("take_off", {"height_m": True}, "'height_m' must be a number, got True"),
        ("take_off", {"height_m": "2"}, "'height_m' must be a number, got '2'"),
        ("take_off", {"height_m": math.nan}, "'height_m' must be finite"),
        ("velocity", {"forward_m_s": 9}, "'forward_m_s' must be within [-5, 5], got 9"),
        ("move_by", {"frame": "map"}, "'frame' must be one of body, world, got 'map'"),
        ("pad_mode", {"mode": 1}, "'mode' must be one of off, hold, land, got 1"),
        ("land", {"now": 1}, "unknown argument(s) now; expected: none"),
    ],
)
def test_bad_commands_say_what_is_wrong(name: str, body: object, message: str) -> None:
    with pytest.raises(LocalProtocolError) as info:
        parse_command(name, body)
    assert message in str(info.value)


json_values = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=True) | st.integers() | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner),
    max_leaves=6,
)
arg_names = st.sampled_from(sorted({a.name for s in COMMANDS.values() for a in s.args}))


@given(
    st.sampled_from([*COMMANDS, "nope"]),
    st.dictionaries(arg_names | st.text(max_size=6), json_values, max_size=5) | json_values,
)
def test_any_json_gives_a_command_or_a_clear_error(name: str, body: object) -> None:
    try:
        cmd = parse_command(name, body)
    except LocalProtocolError as exc:
        assert str(exc)
        return
    spec = COMMANDS[name]
    assert [k for k, _ in cmd.args] == [a.name for a in spec.args]
    for arg, (_, value) in zip(spec.args, cmd.args, strict=True):
        if arg.choices:
            assert value in arg.choices
        else:
            assert isinstance(value, float) and arg.lo <= value <= arg.hi


def test_command_table_is_described_for_the_page() -> None:
    described = {c["name"]: c for c in describe_commands()}
    assert set(described) == set(COMMANDS)
    assert described["take_off"]["packet"] == "TAKE_OFF 0x83"
    assert described["pad_mode"]["args"][0]["choices"] == ["off", "hold", "land"]


def test_link_state_table() -> None:
    s = next_link_state(LinkState.DISCONNECTED, LinkEvent.CONNECT)
    assert s is LinkState.CONNECTING
    assert next_link_state(s, LinkEvent.TURNED_AWAY) is LinkState.REFUSED
    assert next_link_state(LinkState.REFUSED, LinkEvent.CONNECT) is LinkState.CONNECTING
    assert next_link_state(s, LinkEvent.UP) is LinkState.CONNECTED
    assert next_link_state(LinkState.CONNECTED, LinkEvent.LOST) is LinkState.DISCONNECTED
    assert next_link_state(LinkState.CONNECTED, LinkEvent.CLOSE) is LinkState.CLOSED
    with pytest.raises(LocalProtocolError, match="link state connected: event 'up'"):
        next_link_state(LinkState.CONNECTED, LinkEvent.UP)
    with pytest.raises(LocalProtocolError):
        next_link_state(LinkState.CLOSED, LinkEvent.CONNECT)


def test_packet_rate_over_a_window() -> None:
    rate = PacketRate(window_s=2.0)
    for i in range(40):
        rate.add(10.0 + i * 0.05)  # 20 Hz for 2 s
    assert rate.rate_hz(11.95) == pytest.approx(20.0)
    assert rate.rate_hz(20.0) == 0.0
    with pytest.raises(ValueError):
        PacketRate(0.0)


def test_telemetry_converts_to_si_and_leaves_missing_sections_none() -> None:
    assert telemetry_json({}) == {
        "vehicle": None, "truth": None,
        "health": None, "nav": None, "imu": None, "status": None, "gps": None, "pad": None,
        "waypoint": None,
    }
    nav = nav_status_from_si(
        NavStatusSi(NavState.HOLDING, PadAction.HOLD, (1.5, -2.25, -3.0), math.radians(90),
                    (0.5, 0.0, -0.25), 12.1, 42.0)
    )
    pad = pad_report_from_si(PadSi(True, 0b0101, 0.12, -0.05, 1.4, 0.9, 41.9))
    t = telemetry_json({PD.NAV_STATUS: nav, PD.PAD: pad})
    assert t["nav"]["state"] == "holding" and t["nav"]["pad_mode"] == "hold"
    assert (t["nav"]["north_m"], t["nav"]["east_m"], t["nav"]["height_m"]) == (1.5, -2.25, 3.0)
    assert t["nav"]["yaw_deg"] == pytest.approx(90.0)
    assert t["nav"]["climb_m_s"] == 0.25 and t["nav"]["battery_v"] == 12.1
    assert t["pad"]["rings"] == [1, 3]
    assert (t["pad"]["dx_m"], t["pad"]["dy_m"], t["pad"]["quality"]) == (0.12, -0.05, 0.9)
    assert t["pad"]["vision_too_slow"] is False
    slow = pad_report_from_si(PadSi(False, 0, 0.0, 0.0, 0.0, 0.0, 41.9, vision_too_slow=True))
    assert telemetry_json({PD.PAD: slow})["pad"]["vision_too_slow"] is True
    crashed = Health(HealthStatus.CRASHED, "crashed: hard impact at 3.2 m/s")
    assert telemetry_json({PD.HEALTH: crashed})["health"] == {
        "status": "crashed", "reason": "crashed: hard impact at 3.2 m/s"}
    assert (t["nav"]["sigma_h_m"], t["nav"]["sigma_v_m"]) == (None, None)  # not stated


def test_the_waypoint_s_status_bits_each_have_their_field() -> None:
    """CURRENT_WAY's navigation_status: 0x01 reached, 0x02 reached and waited (what a ground
    station sends the next waypoint on), 0x04 within 20 m, 0x08 aborted."""
    fields = ("reached", "waited", "within_20m", "aborted")
    for bit, field in zip((0x01, 0x02, 0x04, 0x08), fields, strict=True):
        way = CurrentWay(0, 0x03, 1, 1, 0, 0, 0, bit, 25)
        w = telemetry_json({PD.CURRENT_WAY: way})["waypoint"]
        assert {f: w[f] for f in fields} == {f: f == field for f in fields}, (bit, w)
        assert w["distance_m"] == 2.5 and w["busy"] is False


def test_the_estimate_s_sigma_and_the_truth_only_while_the_vehicle_is_simulated() -> None:
    from skeye.wire.packet_units import TruthSi, truth_from_si
    from skeye.wire.packets import VehicleInfo

    nav = nav_status_from_si(
        NavStatusSi(NavState.LANDED, PadAction.OFF, (1.0, 2.0, 0.0), 0.0, (0.0, 0.0, 0.0),
                    12.1, 42.0, sigma_h_m=0.034, sigma_v_m=0.012)
    )
    truth = truth_from_si(TruthSi((1.25, 1.5, 0.0), math.radians(45.0), 42.0))
    sim = VehicleInfo(1, "R1 in pad at sim://127.0.0.1:3000 (lockstep)")
    t = telemetry_json({PD.NAV_STATUS: nav, PD.TRUTH: truth, PD.VEHICLE: sim})
    assert (t["nav"]["sigma_h_m"], t["nav"]["sigma_v_m"]) == (0.034, 0.012)
    assert t["vehicle"] == {"simulated": True, "description": sim.description}
    assert t["truth"] == {"north_m": 1.25, "east_m": 1.5, "height_m": 0.0, "yaw_deg": 45.0,
                          "time_s": 42.0}
    # a real vehicle's page never shows a truth marker, whatever arrived
    real = VehicleInfo(0, "a MAVLink flight controller on udp:127.0.0.1:14540")
    t = telemetry_json({PD.NAV_STATUS: nav, PD.TRUTH: truth, PD.VEHICLE: real})
    assert t["truth"] is None and t["vehicle"]["simulated"] is False
    assert telemetry_json({PD.NAV_STATUS: nav, PD.TRUTH: truth})["truth"] is None  # unnamed


def test_speeds_are_checked_against_the_robot_files_limits() -> None:
    from skeye.ground.commands import VehicleLimits

    limits = VehicleLimits.for_robot("hummingbird")
    assert (limits.max_speed_m_s, limits.max_climb_m_s) == (3.0, 1.5)  # hummingbird.toml
    assert parse_command("move_by", {"speed_m_s": 2.5}, limits).kwargs()["speed_m_s"] == 2.5
    for name, body, key, bound in (
        ("move_by", {"speed_m_s": 3.5}, "max_speed_m_s", "3"),
        ("goto_gps", {"latitude_deg": 50.0, "longitude_deg": 12.0, "height_m": 2.0,
                      "speed_m_s": 10.0}, "max_speed_m_s", "3"),
        ("velocity", {"forward_m_s": -4.0}, "max_speed_m_s", "3"),
        ("velocity", {"up_m_s": 2.0}, "max_climb_m_s", "1.5"),
        ("pad_mode", {"mode": "hold", "max_speed_m_s": 4.0}, "max_speed_m_s", "3"),
    ):
        with pytest.raises(LocalProtocolError) as info:
            parse_command(name, body, limits)
        assert (f"over the vehicle's limit of {bound} ({key} in its robot file hummingbird)"
                in str(info.value)), info.value
    described = {c["name"]: {a["name"]: a for a in c["args"]}
                 for c in describe_commands(limits)}
    speed = described["goto_gps"]["speed_m_s"]
    assert speed["max"] == 3.0 and speed["limit"] == {
        "value": 3.0, "key": "max_speed_m_s", "source": "robot file hummingbird"}
    assert described["velocity"]["forward_m_s"]["min"] == -3.0
    assert described["take_off"]["height_m"]["limit"] is None
    airrobot = VehicleLimits.for_robot("airrobot")
    assert {c["name"]: c for c in describe_commands(airrobot)}["move_by"]["args"][5]["max"] == 2.0


def test_the_table_describes_every_field_of_the_page() -> None:
    from skeye.ground.commands import DISPLAY_FACTORS, KEYBOARD, Arg, describe_keyboard, si_unit

    assert [si_unit(n) for n in ("yaw_rate_rad_s", "speed_m_s", "yaw_rad", "latitude_deg",
                                 "height_m", "duration_s", "mode")] == [
        "rad/s", "m/s", "rad", "°", "m", "s", ""]
    for spec in COMMANDS.values():
        for arg in spec.args:
            where = f"{spec.name}.{arg.name}"
            assert arg.label, where
            start = arg.start_value
            if arg.choices:
                assert start is None or start in arg.choices, where
                continue
            assert arg.si_unit and arg.step is not None and arg.step > 0, where
            assert arg.display_unit == arg.si_unit or (
                (arg.si_unit, arg.display_unit) in DISPLAY_FACTORS), where
            assert start is None or (isinstance(start, float) and arg.lo <= start <= arg.hi), where
    described = {c["name"]: {a["name"]: a for a in c["args"]} for c in describe_commands()}
    yaw = described["velocity"]["yaw_rate_rad_s"]
    assert (yaw["label"], yaw["si_unit"], yaw["unit"], yaw["step"]) == ("yaw", "rad/s", "°/s", 5.0)
    assert described["take_off"]["height_m"]["initial"] == 1.5  # the page starts at 1.5 m
    assert described["take_off"]["height_m"]["default"] == 1.0  # an omitted argument: 1 m
    assert described["goto_gps"]["latitude_deg"]["initial"] is None  # blank until filled
    # The keyboard flies the velocity command: its speed and yaw rate lie inside its ranges.
    velocity = {a.name: a for a in COMMANDS["velocity"].args}
    assert KEYBOARD.speed.limit == velocity["forward_m_s"].limit == "speed"
    assert 0 < KEYBOARD.speed.lo and KEYBOARD.speed.hi <= velocity["forward_m_s"].hi
    assert abs(KEYBOARD.yaw_rate_rad_s) <= velocity["yaw_rate_rad_s"].hi
    assert KEYBOARD.duration_s <= velocity["duration_s"].hi and KEYBOARD.repeat_s < 1.0
    kbd = describe_keyboard()
    assert kbd["speed"]["max"] == KEYBOARD.speed.hi and kbd["repeat_s"] == KEYBOARD.repeat_s
    with pytest.raises(ValueError, match="cannot show m/s as 'km/h'"):
        Arg("speed_m_s", 0.0, 1.0, unit="km/h")
