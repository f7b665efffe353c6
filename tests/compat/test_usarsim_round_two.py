"""Issue 30: USARSim clients, round two (items 1-5, 10, 11), against a real lockstep simulator.

The client (tests/compat/usarsim_client.py) reads lines positionally and numbers as
UnrealScript's ``float()``, as the clients written for USARSim do. Each test is one thing a
USARSim client met that broke, with the UDK source it follows:

1. ``AerialVehicle.Drive``: each field sets its own axis (``setPitchAngle`` ... ), the others
   keep their last values; its documented example mixes velocities and angles.
2. ``USARVehicle.GetStatus``: ``STA {Time t} {Battery n}``, no ``{Type}``.
3. A spawn below the ground (a space-separated vector read by ``ParseVector``) never
   launches the robot.
4. ``DefaultUSAR.ini [USARBot.AirRobot]``: no Sonar (GPS, IMU, AltitudeSensor, Compass, ...).
5. DRIVE values as ``float()`` reads them: ``0,000000`` is 0, with a Note.
10. ``Battery.ExpectedLifeTime`` counts down: it never rises.
11. ``--robot-dir`` class names are case-insensitive as the built-ins; the first Sonar
    reading after INIT is a real ranging.

Waits are on sim time (STEP), never on the wall clock.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.compat.usarsim_client import UsarClient, blocks, sen_lines, unreal_float, wrap_pi
from tests.sim.conftest import running_sim

ROBOTS = Path(__file__).resolve().parents[2] / "skeye" / "robots"


def _vec(text: str) -> tuple[float, float, float]:
    x, y, z = (unreal_float(v) for v in text.split(","))
    return x, y, z


def _truth(lines: list[str]) -> list[tuple[float, tuple[float, ...], tuple[float, ...],
                                           tuple[float, ...]]]:
    """(time, location NED, orientation rpy, velocity NED) of every GroundTruth line."""
    out = []
    for b in sen_lines(lines, "GroundTruth"):
        d = dict(b)
        out.append((unreal_float(d["Time"]), _vec(d["Location"]), _vec(d["Orientation"]),
                    _vec(d["Velocity"])))
    return out


def _ins_rpy_deg(lines: list[str]) -> tuple[float, float, float]:
    """The last INS orientation (the board's own estimate, which its angle loop holds), deg."""
    rpy = _vec(dict(sen_lines(lines, "INS")[-1])["Orientation"])
    r, p, y = (math.degrees(wrap_pi(a)) for a in rpy)
    return r, p, y


def _hover(client: UsarClient, robot: str = "hummingbird") -> tuple[float, ...]:
    client.send(f"INIT {{ClassName {robot}}} {{Location 0,0,-3}}")
    assert client.read_line().startswith("RES {Command INIT}")
    return _truth(client.step(500))[-1][1]


def _no_errors(client: UsarClient) -> list[str]:
    lines = client.sync()
    assert not [line for line in lines if line.startswith("ERR")], lines
    return lines


# --- 1. DRIVE: every field sets its own axis ---------------------------------------------------


def test_a_lone_pitch_angle_tilts_and_keeps_the_height(client: UsarClient) -> None:
    """``DRIVE {PitchAngle 10}`` from a hover: the pitch axis flies 10 deg nose up, the other
    axes keep what they had (climb rate 0: the height is held). It used to fall: the unsent
    thrust became 0."""
    start = _hover(client)
    client.send("DRIVE {PitchAngle 10}")
    _no_errors(client)
    lines = client.step(2500)
    truth = _truth(lines)
    heights = [-loc[2] for _, loc, _, _ in truth]
    assert min(heights) > -start[2] - 0.3, (start, min(heights))  # never near the ground
    _, loc, rpy, vel = truth[-1]
    # The board holds 10 deg on its own estimate; accelerating, that estimate's levelling on
    # the accelerometer leaves the true angle a few degrees more (as on a real board).
    assert _ins_rpy_deg(lines)[1] == pytest.approx(10.0, abs=1.5)
    assert math.degrees(wrap_pi(rpy[1])) > 7.0  # nose up
    assert vel[0] < -0.3  # and so it moves backwards (south, facing north)
    assert abs(loc[2] - start[2]) < 0.3


def test_the_documented_udk_example_flies_each_axis(client: UsarClient) -> None:
    """``AerialVehicle.Drive``'s own example, with values inside the vehicle's limits: a climb
    rate, a yaw rate and two angles in one line."""
    start = _hover(client)
    client.send("DRIVE {AltitudeVelocity 0.5} {RotationalVelocity 20} {PitchAngle 5} "
                "{RollAngle -5} {Normalized false}")
    _no_errors(client)
    client.step(1000)
    lines = client.step(1000)
    truth = _truth(lines)
    (t0, loc0, _, _), (t1, loc1, rpy1, _) = truth[0], truth[-1]
    assert (loc0[2] - loc1[2]) / (t1 - t0) == pytest.approx(0.5, abs=0.1)  # climbing
    assert loc1[2] < start[2] - 0.5
    turned = sum(wrap_pi(b[2][2] - a[2][2]) for a, b in itertools.pairwise(truth))
    assert math.degrees(turned) / (t1 - t0) == pytest.approx(20.0, abs=3.0)
    roll, pitch, _ = _ins_rpy_deg(lines)  # the board's estimate, as above
    assert pitch == pytest.approx(5.0, abs=1.5) and roll == pytest.approx(-5.0, abs=1.5)
    assert math.degrees(wrap_pi(rpy1[1])) > 3.0 and math.degrees(wrap_pi(rpy1[0])) < -3.0


def test_the_literal_udk_example_is_refused_for_its_climb_rate_only(client: UsarClient) -> None:
    """The example as UDK's comment prints it asks for 1000 m/s: refused for that value (skeye
    refuses values beyond the limits), not for mixing velocities and angles."""
    _hover(client)
    client.send("DRIVE {AltitudeVelocity 1000} {RotationalVelocity 56} {PitchAngle 15} "
                "{RollAngle -20} {Normalized false}")
    errors = [line for line in client.sync() if line.startswith("ERR")]
    assert len(errors) == 1 and "AltitudeVelocity" in errors[0], errors
    assert "mix" not in errors[0]


def test_a_later_angle_keeps_the_other_axis_velocity(client: UsarClient) -> None:
    """A forward velocity, then a roll angle alone: the pitch axis keeps flying the velocity."""
    start = _hover(client)
    client.send("DRIVE {LinearVelocity 1}")
    _no_errors(client)
    client.step(3000)
    client.send("DRIVE {RollAngle 5}")
    _no_errors(client)
    truth = _truth(client.step(1500))
    _, loc, rpy, vel = truth[-1]
    assert vel[0] == pytest.approx(1.0, abs=0.25)  # still 1 m/s forward (north)
    assert math.degrees(wrap_pi(rpy[0])) == pytest.approx(5.0, abs=1.5)
    assert vel[1] > 0.2  # leaning right: drifting east
    assert abs(loc[2] - start[2]) < 0.3


def test_velocity_and_angle_of_one_axis_fly_the_velocity_with_a_note(client: UsarClient) -> None:
    """Both fields of one axis in one line (a client that sends every field each time): as in
    UDK, where the velocity moves the vehicle and the angle is only its look, the velocity is
    flown; the answer's Note says the angle was not."""
    _hover(client)
    client.send("DRIVE {LinearVelocity 0} {LateralVelocity 0} {AltitudeVelocity 0} "
                "{RotationalVelocity 0} {PitchAngle 10} {RollAngle 0}")
    lines = _no_errors(client)
    notes = [line for line in lines if line.startswith("RES {Command DRIVE}")]
    assert len(notes) == 1 and "PitchAngle" in notes[0] and "LinearVelocity" in notes[0]
    _, _, rpy, vel = _truth(client.step(1500))[-1]
    assert abs(vel[0]) < 0.2 and abs(math.degrees(wrap_pi(rpy[1]))) < 3.0


# --- 2. STA of an aerial vehicle: {Time} {Battery}, no {Type} ------------------------------------


@pytest.mark.parametrize("robot", ["airrobot", "hummingbird"])
def test_status_lines_carry_no_type(client: UsarClient, robot: str) -> None:
    """A UT2004-era client reads ``{Type AerialVehicle}`` as UT2004's layout for that type and
    its reader dies; UDK's GetStatus writes ``STA {Time t} {Battery n}``."""
    client.send(f"INIT {{ClassName {robot}}} {{Location 0,0,-2}}")
    assert client.read_line().startswith("RES {Command INIT}")
    stas = [blocks(line) for line in client.step(1000) if line.startswith("STA")]
    assert stas
    for sta in stas:
        assert [k for k, _ in sta[:2]] == ["Time", "Battery"], sta
        assert "Type" not in [k for k, _ in sta], sta


# --- 3. a spawn below the ground ---------------------------------------------------------------


@pytest.mark.parametrize("location, north_east", [
    ("4.0 0.0 0.0", (0.0, 0.0)),  # the client: ParseVector reads 0,0,4 (over the pad)
    ("2,3,1", (2.0, 3.0)),  # plainly 1 m below the ground, beside the pad
])
def test_a_spawn_below_the_ground_stands_on_the_surface(client: UsarClient, location: str,
                                                        north_east: tuple[float, float]) -> None:
    client.send(f"INIT {{ClassName hummingbird}} {{Location {location}}}")
    res = client.read_line()
    assert res.startswith("RES {Command INIT}") and "{Status OK}" in res, res
    assert "below the ground" in res, res
    truth = _truth(client.step(3000))
    for _, loc, _, vel in truth:  # it was launched 90 m up at 74 m/s
        assert -0.5 < loc[2] < 0.05, loc
        assert math.hypot(*vel) < 0.5, vel
    _, loc, _, _ = truth[-1]
    assert (loc[0], loc[1]) == pytest.approx(north_east, abs=0.05)


# --- 4. USARSim's AirRobot has no Sonar --------------------------------------------------------


def test_the_airrobot_streams_usarsim_sensor_types_only(client: UsarClient) -> None:
    client.send("INIT {ClassName USARBot.AirRobot} {Location 0,0,-2}")
    assert client.read_line().startswith("RES {Command INIT}")
    types = {dict(blocks(line))["Type"] for line in client.step(1500) if line.startswith("SEN")}
    assert "Sonar" not in types  # a Java client built from DefaultUSAR.ini died on it
    assert types <= {"GPS", "MagneticCompass", "GroundTruth", "INS"}, types
    assert {"GPS", "MagneticCompass"} <= types  # USARSim's AirRobot carries both


def test_skeye_classes_keep_their_sonar(client: UsarClient) -> None:
    client.send("INIT {ClassName hummingbird} {Location 0,0,-2}")
    assert client.read_line().startswith("RES {Command INIT}")
    assert sen_lines(client.step(500), "Sonar")


# --- 5. DRIVE values as UnrealScript's float() reads them ---------------------------------------


def test_decimal_commas_in_drive_read_as_float_reads_them(client: UsarClient) -> None:
    _hover(client)
    client.send("DRIVE {LinearVelocity 0,000000} {LateralVelocity 0,000000} "
                "{AltitudeVelocity 0,000000} {RotationalVelocity 0,000000}")
    lines = _no_errors(client)
    res = [line for line in lines if line.startswith("RES {Command DRIVE}")]
    assert len(res) == 1 and "LinearVelocity '0,000000' read as 0" in res[0], lines
    client.send("DRIVE {LinearVelocity 1,5}")  # float("1,5") is 1
    _no_errors(client)
    client.step(3000)
    _, _, _, vel = _truth(client.step(500))[-1]
    assert vel[0] == pytest.approx(1.0, abs=0.2)
    client.send("DRIVE {LinearVelocity fast}")  # no number at all: refused, nothing moves
    errors = [line for line in client.sync() if line.startswith("ERR")]
    assert errors and "LinearVelocity" in errors[0]


# --- 10. STA Battery never rises ----------------------------------------------------------------


def _battery(lines: list[str]) -> list[int]:
    return [int(dict(blocks(line))["Battery"]) for line in lines if line.startswith("STA")]


def test_battery_life_never_rises_through_climb_hover_and_touchdown(client: UsarClient) -> None:
    client.send("INIT {ClassName hummingbird} {Location 0,0,-1}")
    assert client.read_line().startswith("RES {Command INIT}")
    series = _battery(client.step(2000))
    client.send("DRIVE {AltitudeVelocity 1.5}")
    series += _battery(client.step(2500))
    client.send("DRIVE {AltitudeVelocity 0}")
    series += _battery(client.step(4000))
    client.send("DRIVE {AltitudeVelocity -1}")
    series += _battery(client.step(6000))
    client.send("DRIVE {AltitudeVelocity 0}")
    series += _battery(client.step(4000))
    rises = [(a, b) for a, b in itertools.pairwise(series) if b > a]
    assert not rises, rises[:5]
    assert series[0] - series[-1] >= 10  # it does count down over the 18.5 s


# --- 11. robot-dir names, the first Sonar reading -----------------------------------------------


@pytest.fixture
def robot_dir_client(tmp_path: Path) -> Iterator[UsarClient]:
    text = (ROBOTS / "hummingbird.toml").read_text(encoding="utf-8")
    (tmp_path / "MyQuad.toml").write_text(text.replace('name = "hummingbird"',
                                                       'name = "MyQuad"', 1))
    with running_sim(robot_dirs=(tmp_path,)) as server:
        c = UsarClient(server.port)
        yield c
        c.close()


@pytest.mark.parametrize("class_name", ["myquad", "MYQUAD", "USARBot.MyQuad"])
def test_robot_dir_class_names_are_case_insensitive(robot_dir_client: UsarClient,
                                                    class_name: str) -> None:
    robot_dir_client.send(f"INIT {{ClassName {class_name}}} {{Location 0,0,-2}}")
    line = robot_dir_client.read_line()
    assert line.startswith("RES {Command INIT}") and "{Status OK}" in line, line


def test_the_first_sonar_reading_on_the_ground_is_a_ranging(client: UsarClient) -> None:
    client.send("INIT {ClassName hummingbird} {Start Pad1}")
    assert client.read_line().startswith("RES {Command INIT}")
    sonar = sen_lines(client.step(300), "Sonar")
    assert sonar
    first = dict(sonar[0])
    assert re.fullmatch(r"[\d.]+", first["Range"])
    assert unreal_float(first["Range"]) < 0.5, sonar[0]  # not the 6 m "no echo" value
