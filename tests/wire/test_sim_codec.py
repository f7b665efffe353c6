"""Tests of the simulator protocol's typed codec table (skeye.wire.sim): both ways, every type."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import LocalProtocolError, RemoteProtocolError
from skeye.wire import sim
from skeye.wire.sim_lines import FREE_TEXT_KEYS, LineDecoder, LineError, Message, parse_line
from skeye.wire.sim_messages import (
    SEN_CLASSES,
    Conf,
    Drive,
    Err,
    Geo,
    GetStartPoses,
    Init,
    Nfo,
    Ping,
    Res,
    RobotConf,
    SenGps,
    SenIns,
    SenMotors,
    SenOpticalFlow,
    SenOther,
    SenSonar,
    Sta,
    StartPoses,
    Step,
)

WORDS = st.from_regex(r"[A-Za-z0-9_][A-Za-z0-9_.:,-]{0,11}", fullmatch=True)
FREE_TEXT = st.lists(WORDS, min_size=1, max_size=5).map(" ".join)


def _six(x: float) -> float:
    """A float as the wire carries it (six decimals), so a round trip is exact."""
    return float(f"{x:.6f}")


def _value(spec: sim.FieldSpec) -> st.SearchStrategy[Any]:
    lo = -1e6 if spec.min_value is None else spec.min_value
    hi = 1e6 if spec.max_value is None else spec.max_value
    number = st.floats(lo, hi).map(_six).filter(lambda x: lo <= x <= hi)
    finite = st.floats(-1e6, 1e6).map(_six)
    kind = spec.kind
    if kind == "float" and spec.scale != 1.0:  # an SI value whose wire text has six decimals
        return number.map(lambda x: x * spec.scale)
    if kind == "float":
        return number
    if kind == "int":
        return st.integers(int(max(lo, -1e9)), int(min(hi, 1e9)))
    if kind == "bool":
        return st.booleans()
    if kind == "word":
        return WORDS
    if kind == "text":
        return FREE_TEXT if spec.key.lower() in FREE_TEXT_KEYS else WORDS
    if kind in ("vec3", "uvec3"):
        return st.tuples(finite, finite, finite)
    if kind == "vec2":
        return st.tuples(finite, finite)
    if kind == "ivec2":
        small = st.integers(-(10**6), 10**6).map(float)
        return st.tuples(small, small)
    return st.lists(finite, min_size=1, max_size=6).map(tuple)


def _message(codec: sim.Codec) -> st.SearchStrategy[Any]:
    kwargs = {
        spec.attr: _value(spec) if spec.required else st.one_of(st.none(), _value(spec))
        for spec in codec.fields
    }
    # A field whose default is not None (Init's rotation, Sta's battery) is always written.
    for spec in codec.fields:
        default = {f.name: f.default for f in dataclasses.fields(codec.cls)}[spec.attr]
        if not spec.required and default is not None:
            kwargs[spec.attr] = _value(spec)
    return st.builds(codec.cls, **kwargs)


def _valid(message: Any) -> bool:
    """The combinations a single field's range cannot express (DRIVE's forms, INIT's place)."""
    try:
        sim.decode(parse_line(sim.encode(message).decode()))
    except RemoteProtocolError:
        return False
    return True


GENERIC = st.tuples(
    WORDS.filter(lambda w: w.lower() != "aerialvehicle"),
    WORDS,
    st.lists(st.tuples(st.from_regex(r"[A-Z][a-z]{1,8}", fullmatch=True), WORDS), max_size=4)
    .map(lambda pairs: tuple((k, v) for k, v in pairs if k.lower() not in ("type", "name"))),
)
MESSAGES = st.one_of(
    *(_message(codec) for codec in sim.CODECS.values()),
    *(_message(codec) for codec in sim.SEN_CODECS.values()),
    _message(sim._ROBOT_CONF).map(lambda c: dataclasses.replace(c, type="AerialVehicle")),
    GENERIC.map(lambda t: Conf(*t)),
    GENERIC.map(lambda t: Geo(*t)),
    st.lists(
        st.tuples(
            st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,8}", fullmatch=True),
            st.tuples(*[st.floats(-1e4, 1e4).map(_six)] * 3),
            st.tuples(*[st.floats(-3, 3).map(_six)] * 3),
        ),
        max_size=4,
        unique_by=lambda p: p[0].casefold(),
    ).map(lambda poses: StartPoses(tuple(poses))),
).filter(_valid)


@settings(max_examples=600, deadline=None)
@given(MESSAGES)
def test_every_message_round_trips(message: Any) -> None:
    line = sim.encode(message)
    assert line.endswith(b"\r\n") and line.count(b"\n") == 1
    assert sim.decode(parse_line(line.decode())) == message
    # and through the stream decoder, one byte at a time
    decoder = LineDecoder()
    out = [item for byte in line for item in decoder.feed(bytes([byte]))]
    assert len(out) == 1 and isinstance(out[0], Message)
    assert sim.decode(out[0]) == message


def test_the_table_covers_every_message_class() -> None:
    words = {codec.word for codec in sim.CODECS.values()}
    assert words == {"INIT", "DRIVE", "STEP", "SET", "PING", "GETCONF", "GETGEO",
                     "GETSTARTPOSES", "RESET", "STA", "RES", "ERR", "NFO"}
    assert {c.TYPE for c in SEN_CLASSES} == {
        "GroundTruth", "INS", "Accelerometer", "Gyro", "MagneticCompass", "Barometer", "GPS",
        "Sonar", "OpticalFlow", "Battery", "Motors", "Camera"}


@pytest.mark.parametrize(
    ("message", "line"),
    [
        (Drive(forward_m_s=0.8, right_m_s=0.3, up_m_s=0.0, yaw_rate_rad_s=0.0),
         b"DRIVE {LinearVelocity 0.800000} {LateralVelocity 0.300000} "
         b"{AltitudeVelocity 0.000000} {RotationalVelocity 0.000000}\r\n"),
        (Drive(roll_rad=math.radians(5.0), pitch_rad=math.radians(-10.0),
               yaw_rate_rad_s=math.radians(30.0), thrust_fraction=0.6),
         b"DRIVE {RollAngle 5.000000} {PitchAngle -10.000000} {RotationalVelocity 30.000000} "
         b"{Thrust 0.600000}\r\n"),
        (Res("INIT", name="R1", status="OK", note="Location '1 2 3' read as 0,0,1"),
         b"RES {Command INIT} {Name R1} {Status OK} {Note Location '1 2 3' read as 0,0,1}\r\n"),
        (Res("INIT", name="R1", status="OK"), b"RES {Command INIT} {Name R1} {Status OK}\r\n"),
        (Res("PING", id="7", time_s=1.5), b"RES {Command PING} {Id 7} {Time 1.500000}\r\n"),
        (Err("DRIVE", reason="no {robot}\r\n here"),
         b"ERR {Command DRIVE} {Reason no (robot) here}\r\n"),
        (Err("PHYSICS", name="R1", reason="robot stopped: NaN"),
         b"ERR {Command PHYSICS} {Name R1} {Reason robot stopped: NaN}\r\n"),
        (Sta(name="R1", time_s=0.5, battery_s=600, voltage_v=12.6, current_a=3.0,
             armed=True, landed=False),
         b"STA {Time 0.500000} {Battery 600} {Name R1} "
         b"{Voltage 12.600000} {Current 3.000000} {Armed true} {Landed false}\r\n"),
        (SenOpticalFlow(1.0, "Flow", (3.0, -4.0), 120),
         b"SEN {Time 1.000000} {Type OpticalFlow} {Name Flow} {Delta 3,-4} {Quality 120}\r\n"),
        (GetStartPoses(), b"GETSTARTPOSES\r\n"),
        (StartPoses(()), b"NFO {StartPoses 0}\r\n"),
    ],
)
def test_known_lines(message: Any, line: bytes) -> None:
    assert sim.encode(message) == line


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ("INIT {Name R1}", "missing {ClassName ...}"),
        ("INIT {ClassName x}", "INIT needs {Location x,y,z} or {Start name}"),
        ("INIT {ClassName x} {Location 0,0,0} {Rotation 0,0,90}", "radians, not degrees"),
        ("INIT {ClassName x} {Location 2e4,0,0}", "outside the world"),
        ("DRIVE {Thrust 0.3} {AltitudeVelocity 1}", "both set the vertical axis"),
        ("DRIVE {Speed 1}", "unknown key(s) ['Speed']"),
        ("DRIVE {Normalized true}", "needs at least one velocity or attitude segment"),
        ("DRIVE {Thrust 1.5}", "Thrust: '1.5' is out of range [0.0, 1.0]"),
        ("STEP {Count 0}", "Count: '0' is out of range [1, 10000000]"),
        ("SEN {Time 1} {Type Sonar} {Name S}", "missing {Range ...}"),
        ("SEN {Time -1} {Type Sonar} {Name S} {Range 1}", "Time: '-1' is below the minimum"),
        ("SEN {Time 1} {Name S}", "missing {Type ...}"),
        ("FLY {Away 1}", "unknown command FLY"),
        ("NFO {StartPoses 1}", "needs 3 tokens"),
    ],
)
def test_decoding_errors_name_the_problem(line: str, reason: str) -> None:
    with pytest.raises(RemoteProtocolError, match=None) as info:
        sim.decode_line(line)
    assert reason in str(info.value)


@pytest.mark.parametrize(
    "message",
    [
        Step(count=1.5),  # type: ignore[arg-type]
        Drive(thrust_fraction=2.0),
        Drive(forward_m_s=math.nan),
        Ping(id="a {b}"),
        Init("two words", start="Pad1"),
        SenOpticalFlow(0.0, "F", (0.5, 1.0), 3),
        SenIns(0.0, "INS", (0.0, 0.0), (0.0, 0.0, 0.0)),  # type: ignore[arg-type]
        Sta(time_s=1.0, battery_s=-1),  # a negative battery life cannot be written
        Sta(time_s=1.0, battery_s=1.5),  # nor a fraction of a second: USARSim's is an int
    ],
)
def test_encoding_refuses_bad_values(message: Any) -> None:
    with pytest.raises(LocalProtocolError):
        sim.encode(message)


def test_unknown_sensor_types_decode_as_raw_fields() -> None:
    msg = sim.decode_line("SEN {Time 2} {Type Lidar} {Name L} {Ranges 1,2,3}")
    assert msg == SenOther(2.0, "Lidar", "L", (("Time", "2"), ("Type", "Lidar"),
                                                ("Name", "L"), ("Ranges", "1,2,3")))


def test_lenient_optional_fields() -> None:
    assert sim.decode_line("SEN {Time 1} {Type GPS} {Name G} {Fix 0} {Satellites 3}") == SenGps(
        1.0, "G", fix=0, satellites=3)
    assert sim.decode_line("STA {Time 1}") == Sta(name=None, time_s=1.0)
    with pytest.raises(RemoteProtocolError, match=r"missing \{Time"):
        sim.decode_line("STA {Name R1} {Armed true}")
    conf = sim.decode_line("CONF {Type AerialVehicle} {Name R1} {MaxSpeed 5} "
                           "{Sensors INS:INS,Sonar:Down}")
    assert isinstance(conf, RobotConf) and conf.max_speed_m_s == 5.0
    assert conf.mounted() == [("INS", "INS"), ("Sonar", "Down")]
    assert sim.decode_line("NFO {Level a} {TimeStep 0.001} {Mode lockstep}") == Nfo(
        level="a", time_step_s=0.001, mode="lockstep")


def test_drive_in_si_applies_the_robot_limits() -> None:
    limits = sim.DriveLimits(speed_m_s=5.0, climb_m_s=2.0, yaw_rate_rad_s=1.0)
    msg = parse_line("DRIVE {LinearVelocity 50} {AltitudeVelocity -100} {Normalized true}")
    drive = sim.drive_in_si(msg, sim.decode(msg), limits)
    assert drive == Drive(forward_m_s=2.5, up_m_s=-2.0)
    msg = parse_line("DRIVE {AltitudeVelocity 2.5}")
    with pytest.raises(RemoteProtocolError, match=r"AltitudeVelocity: '2.5' is out of range"):
        sim.drive_in_si(msg, sim.decode(msg), limits)


def test_drive_angles_are_degrees_on_the_wire() -> None:
    """USARSim's AerialVehicle.uc: RotationalVelocity deg/s, PitchAngle and RollAngle deg."""
    limits = sim.DriveLimits(speed_m_s=5.0, climb_m_s=2.0, yaw_rate_rad_s=math.radians(100.0),
                             tilt_rad=math.radians(20.0))
    msg = parse_line("DRIVE {RotationalVelocity 10}")
    drive = sim.drive_in_si(msg, sim.decode(msg), limits)
    assert drive.yaw_rate_rad_s == pytest.approx(math.radians(10.0))
    msg = parse_line("DRIVE {RollAngle -15} {PitchAngle 7.5} {Thrust 0.5}")
    drive = sim.drive_in_si(msg, sim.decode(msg), limits)
    assert (drive.roll_rad, drive.pitch_rad) == pytest.approx(
        (math.radians(-15.0), math.radians(7.5)))
    msg = parse_line("DRIVE {PitchAngle 50} {Normalized true}")  # percent of MaxTilt
    assert sim.drive_in_si(msg, sim.decode(msg), limits).pitch_rad == pytest.approx(
        math.radians(10.0))
    for line, key in (("DRIVE {RotationalVelocity 101}", "RotationalVelocity"),
                      ("DRIVE {RollAngle 90}", "RollAngle")):
        msg = parse_line(line)
        with pytest.raises(RemoteProtocolError, match=key + r": '.*' is out of range"):
            sim.drive_in_si(msg, sim.decode(msg), limits)
    assert sim.decode(parse_line("DRIVE {RotationalVelocity 90}")).yaw_rate_rad_s == (
        pytest.approx(math.pi / 2))


def test_init_vectors_read_as_usarsim_parse_vector() -> None:
    msg = parse_line("INIT {ClassName x} {Location 0,0000, 0,0000, 0,0000} {Rotation 0,0,1.5}")
    init = sim.decode(msg)
    assert init.location_ned_m == (0.0, 0.0, 0.0) and init.rotation_rpy_rad == (0.0, 0.0, 1.5)
    notes = sim.usarsim_notes(msg)
    assert len(notes) == 1 and "Location '0,0000, 0,0000, 0,0000' read as 0,0,0" in notes[0]
    msg = parse_line("INIT {ClassName x} {Location 1.0 2.0 -0.5}")
    assert sim.decode(msg).location_ned_m == (0.0, 0.0, 1.0)
    assert sim.usarsim_notes(parse_line("INIT {ClassName x} {Location 1,2,-3}")) == []


def test_line_format_writes_what_encode_writes() -> None:
    ins = SenIns(1.25, "INS", (1.0, 2.0, -3.0), (0.1, 0.2, 0.3), (0.0, 0.5, 0.0),
                 (0.02, 0.02, 0.05))
    fmt = sim.line_format(SenIns, {"Name": "INS"})
    values = (1.25, 1.0, 2.0, -3.0, 0.1, 0.2, 0.3, 0.0, 0.5, 0.0, 0.02, 0.02, 0.05)
    assert fmt.format(values) == sim.encode(ins)
    assert b"{PositionSigma 0.020000,0.020000,0.050000}" in sim.encode(ins)
    motors = SenMotors(0.5, "M", (1.0,) * 4, (2.0,) * 4, 9.5)
    layout = sim.sen_layout(SenMotors, counts={"Speeds": 4, "Commands": 4})
    fmt = sim.line_format(SenMotors, {"Name": "M"}, layout)
    assert fmt.format((0.5, *(1.0,) * 4, *(2.0,) * 4, 9.5)) == sim.encode(motors)
    sta = Sta(name="R1", time_s=1.0, battery_s=5, voltage_v=12.0, current_a=1.0, armed=True)
    fmt = sim.line_format(Sta, {"Name": "R1"})
    assert fmt.format((1.0, 5, 12.0, 1.0, True, False)) == sim.encode(sta)


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=300))
def test_fuzz_arbitrary_bytes_give_a_message_or_a_protocol_error(data: bytes) -> None:
    for item in LineDecoder().feed(data + b"\n"):
        if isinstance(item, LineError):
            continue
        try:
            sim.decode(item)
        except RemoteProtocolError:
            pass


_KEYS = st.sampled_from(sorted({spec.key for codec in (*sim.CODECS.values(),
                                                       *sim.SEN_CODECS.values())
                                for spec in codec.fields} | {"Type", "StartPoses"}))
_TEXTS = st.one_of(
    st.sampled_from(["1", "-2.5", "1e400", "nan", "true", "x", "", "1,2", "1,2,3", "1,,3",
                     "INS", "GPS", "Sonar", "Motors", "AerialVehicle", "0", "3"]),
    st.text(st.characters(blacklist_characters="{}\r\n", blacklist_categories=["Cs"]),
            max_size=12),
)


@settings(max_examples=600, deadline=None)
@given(
    st.sampled_from([*sim.CODECS, "SEN", "CONF", "GEO", "NFO"]),
    st.lists(st.tuples(_KEYS, _TEXTS), max_size=8),
)
def test_fuzz_protocol_shaped_lines_never_raise_anything_else(
    word: str, pairs: list[tuple[str, str]]
) -> None:
    blocks = " ".join("{" + f"{k} {v}".strip() + "}" for k, v in pairs)
    for item in LineDecoder().feed(f"{word} {blocks}\r\n".encode()):
        if isinstance(item, Message):
            try:
                sim.decode(item)
            except RemoteProtocolError:
                pass


def test_decode_as_reads_a_known_sensors_lines_without_type_or_name() -> None:
    """A client's sensor object is handed its own lines: Type and Name may be left out."""
    msg = parse_line("SEN {Time 1.5} {Range 2.25}")
    assert sim.decode_as(msg, SenSonar) == SenSonar(1.5, "", 2.25)
    msg = parse_line("SEN {Time 1} {Type Lidar} {Name L} {Ranges 1,2}")
    assert sim.decode_as(msg, SenOther) == SenOther(1.0, "Lidar", "L", msg.fields)
    assert sim.decode_as(parse_line("STA {Time 2} {Armed true}"), Sta) == Sta(
        time_s=2.0, armed=True)
    with pytest.raises(RemoteProtocolError, match=r"missing \{Range"):
        sim.decode_as(parse_line("SEN {Time 1}"), SenSonar)
