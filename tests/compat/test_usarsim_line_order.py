"""Issue 19, point 3: every line a USARSim client knows keeps USARSim's block positions.

From the UDK sources: ``Sensor.GetHead`` writes ``SEN {Time t} {Type T}`` and each sensor's
``GetData`` then ``{Name n}`` and its keys:

- ``GroundTruth.uc`` and ``INS.uc``: ``{Location x,y,z} {Orientation r,p,y}``;
- ``AcceleroMeter.uc``: ``{ProperAcceleration x,y,z}``;
- ``MagneticCompass.uc``: ``{MagneticAngle a}``;
- ``GPSSensor.uc``: ``{Latitude d,m,N} {Longitude d,m,E} {Fix 1} {Satellites n}`` with a fix,
  ``{Fix 0} {Satellites n}`` without: a client reads Latitude/Longitude after Name and
  Fix/Satellites as the last two blocks (they move with the form);
- ``USARVehicle.GetStatus``: ``STA {Time t} {Battery n}``.

skeye's extension keys may follow (or, for GPS, sit between Longitude and Fix); these tests
read the lines the way a positional client does and fail if an extension moved a USARSim key.
"""

from __future__ import annotations

import re

import pytest

from tests.compat.usarsim_client import UsarClient, blocks, sen_lines, unreal_float

NUMBER = re.compile(r"[+-]?\d+(\.\d+)?\Z")
DEG_MIN = re.compile(r"\d+,\d+\.\d{4},[NSEW]\Z")  # GPSSensor.GPSString: 47,40.3323,N


def _stream(client: UsarClient) -> list[str]:
    client.send("INIT {ClassName hummingbird} {Name R1} {Location 0,0,-2}")
    assert client.read_line().startswith("RES {Command INIT}")
    return client.step(1200)


def _vector_ok(text: str) -> bool:
    return len(text.split(",")) == 3 and all(NUMBER.match(p) for p in text.split(","))


def _header(line: list[tuple[str, str]], type_name: str) -> None:
    assert line[0][0] == "Time" and NUMBER.match(line[0][1])
    assert line[1] == ("Type", type_name)
    assert line[2][0] == "Name"


@pytest.mark.parametrize("type_name", ["GroundTruth", "INS"])
def test_pose_sensors(client: UsarClient, type_name: str) -> None:
    lines = sen_lines(_stream(client), type_name)
    assert lines
    for line in lines:
        _header(line, type_name)
        assert line[3][0] == "Location" and _vector_ok(line[3][1])
        assert line[4][0] == "Orientation" and _vector_ok(line[4][1])


def test_accelerometer_and_compass(client: UsarClient) -> None:
    lines = _stream(client)
    accel = sen_lines(lines, "Accelerometer")  # USARSim's ItemType is "AcceleroMeter"
    compass = sen_lines(lines, "MagneticCompass")
    assert accel and compass
    for line in accel:
        _header(line, "Accelerometer")
        assert line[3][0] == "ProperAcceleration" and _vector_ok(line[3][1])
    for line in compass:
        _header(line, "MagneticCompass")
        assert line[3][0] == "MagneticAngle" and NUMBER.match(line[3][1])


def test_gps_with_a_fix(client: UsarClient) -> None:
    client.send("INIT {ClassName hummingbird} {Name R1} {Location 0,0,-2}")
    assert client.read_line().startswith("RES {Command INIT}")
    # The receiver acquires its fix FixTime (1 s, a hot start) after the first reading: take
    # the lines once it has one (the ones before are checked as "without a fix" below).
    lines = [line for line in sen_lines(client.step(4000), "GPS") if ("Fix", "1") in line]
    assert lines
    for line in lines:
        _header(line, "GPS")
        assert line[3][0] == "Latitude" and DEG_MIN.match(line[3][1])
        assert line[4][0] == "Longitude" and DEG_MIN.match(line[4][1])
        assert line[-2] == ("Fix", "1")
        assert line[-1][0] == "Satellites" and int(line[-1][1]) >= 4  # a fix needs 4


@pytest.mark.parametrize("server", ["indoor"], indirect=True)
def test_gps_without_a_fix(client: UsarClient) -> None:
    lines = sen_lines(_stream(client), "GPS")
    assert lines
    for line in lines:
        _header(line, "GPS")
        assert line[-2] == ("Fix", "0")
        assert line[-1][0] == "Satellites" and re.fullmatch(r"\d+", line[-1][1])


def test_status_line_starts_time_battery(client: UsarClient) -> None:
    stas = [blocks(line) for line in _stream(client) if line.startswith("STA ")]
    assert stas
    for sta in stas:
        assert sta[0][0] == "Time" and unreal_float(sta[0][1]) > 0
        assert sta[1][0] == "Battery" and re.fullmatch(r"\d+", sta[1][1])  # an int, as USARSim
