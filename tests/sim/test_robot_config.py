"""Robot files INIT would refuse are refused the same way everywhere: by building the robot (what
INIT does), by ``validate_robot_dirs`` with the robot's own checks (what ``skeye sim --robot-dir``
runs at start-up) and over the control port, each time as a ConfigError naming the file, the
key and the value; never a Python exception from deeper down, never silently accepted."""

from __future__ import annotations

import subprocess
import sys
from functools import partial
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from skeye.errors import ConfigError
from skeye.robots.config import load_robot_config, validate_robot_dirs
from skeye.sim.robot import Robot, check_robot_config

from .conftest import LineClient, running_sim

PHYSICS_STEP_S = 0.001  # skeye sim's default --timestep

# (id, TOML after `name = "bad"`, key the message names, value as the message gives it)
CASES = [
    ("body-negative", "[airframe]\nbody_size_m = [0.12, -0.1, 0.06]", "body_size_m[1]", "-0.1"),
    ("body-zero", "[airframe]\nbody_size_m = [0.12, 0.12, 0.0]", "body_size_m[2]", "0.0"),
    ("body-nan", "[airframe]\nbody_size_m = [nan, 0.12, 0.06]", "body_size_m[0]", "nan"),
    # MuJoCo refused to compile these at INIT (a ValueError naming no file), after the
    # start-up check had passed them.
    ("inertia-triangle", "[airframe]\ninertia_kg_m2 = [0.001, 0.001, 0.012]", "inertia_kg_m2[2]",
     "0.012"),
    # The hull reached 12 cm into the ground on the gear: the vehicle jumped at its spawn.
    ("gear-below-hull", "[airframe]\nbody_size_m = [0.12, 0.12, 0.4]", "gear_height_m", "0.08"),
    # OverflowError out of loading the file (4 * kf * w**2), naming neither file nor key; a
    # kf of 1e305 gave an infinite max thrust and loaded.
    ("rotor-speed-overflow", "[airframe]\nmax_rotor_speed_rad_s = 1e200",
     "max_rotor_speed_rad_s", "1e+200"),
    ("kf-infinite-thrust", "[airframe]\nkf = 1e305", "kf", "1e+305"),
    ("avionics-negative", "[battery]\navionics_power_w = -5", "avionics_power_w", "-5.0"),
    ("avionics-nan", "[battery]\navionics_power_w = nan", "avionics_power_w", "nan"),
    ("avionics-inf", "[battery]\navionics_power_w = inf", "avionics_power_w", "inf"),
    ("cutoff-full", "[battery]\ncutoff_cell_v = 4.2", "cutoff_cell_v", "4.2"),
    ("status-tiny", "status_rate_hz = 1e-310", "status_rate_hz", "1e-310"),
    ("board-tiny", "board_rate_hz = 1e-310", "board_rate_hz", "1e-310"),
    ("board-inf", "board_rate_hz = inf", "board_rate_hz", "inf"),
    ("board-not-a-fraction", "board_rate_hz = 3", "board_rate_hz", "3"),
    ("motors-zero", '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = 0', "Rate", "0"),
    ("motors-text", '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = "fast"', "Rate",
     "'fast'"),
    ("motors-nan", '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = nan', "Rate", "nan"),
    ("motors-negative", '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = -25', "Rate",
     "-25"),
    ("motors-inf", '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = inf', "Rate", "inf"),
    ("motors-tiny", '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = 1e-310', "rate_hz",
     "1e-310"),
    ("motors-unknown-key", '[[sensors]]\ntype = "Motors"\nname = "M"\nspin = 1', "spin",
     "Motors"),
    ("sensor-unknown-type", '[[sensors]]\ntype = "Lidar"\nname = "L"', "Lidar", "'Lidar'"),
    ("sensor-rate-zero", '[[sensors]]\ntype = "GPS"\nname = "G"\nrate_hz = 0', "Rate", "0"),
    ("sensor-rate-negative", '[[sensors]]\ntype = "GPS"\nname = "G"\nrate_hz = -1', "Rate",
     "-1"),
    ("sensor-rate-nan", '[[sensors]]\ntype = "GPS"\nname = "G"\nrate_hz = nan', "Rate", "nan"),
    ("sensor-rate-text", '[[sensors]]\ntype = "GPS"\nname = "G"\nrate_hz = "5"', "Rate",
     "'5'"),
    ("sensor-rate-tiny", '[[sensors]]\ntype = "GPS"\nname = "G"\nrate_hz = 1e-310', "rate_hz",
     "1e-310"),
    ("camera-rate-zero", '[[sensors]]\ntype = "Camera"\nname = "C"\nrate_hz = 0', "rate_hz",
     "0"),
    ("camera-rate-nan", '[[sensors]]\ntype = "Camera"\nname = "C"\nrate_hz = nan', "rate_hz",
     "nan"),
    ("camera-rate-text", '[[sensors]]\ntype = "Camera"\nname = "C"\nrate_hz = "30"',
     "rate_hz", "'30'"),
    ("camera-unknown-key", '[[sensors]]\ntype = "Camera"\nname = "C"\nzoom = 2', "zoom",
     "unknown key"),
    # Loaded, then its first SEN line killed the engine for every client ("Name value 'Down
    # Range' contains a brace or whitespace"); a ',' or ':' garbles CONF {Sensors Type:Name,...}.
    ("sensor-name-blank", '[[sensors]]\ntype = "Sonar"\nname = "Down Range"', "'name'",
     "'Down Range'"),
    ("sensor-name-brace", '[[sensors]]\ntype = "GPS"\nname = "{G}"', "'name'", "'{G}'"),
    ("sensor-name-comma", '[[sensors]]\ntype = "GPS"\nname = "G,2"', "'name'", "'G,2'"),
    ("sensor-name-colon", '[[sensors]]\ntype = "GPS"\nname = "G:2"', "'name'", "'G:2'"),
    # Loaded: every SEN line carried the BEL to the client, and GETCONF {Type Robot} answered
    # ERR (the encoder refuses a control character in CONF {Sensors ...}).
    ("sensor-name-control", '[[sensors]]\ntype = "Sonar"\nname = "Down\\u0007"', "'name'",
     "'Down\\x07'"),
    ("sensor-name-escape", '[[sensors]]\ntype = "GPS"\nname = "G\\u001b[2J"', "'name'",
     "'G\\x1b[2J'"),
    # Sampled once per physics step (1 kHz) while CONF and the board's estimator took the
    # file's rate: a rate above the physics rate is refused.
    ("sensor-rate-above-physics", '[[sensors]]\ntype = "GPS"\nname = "G"\nrate_hz = 5000',
     "rate_hz 5000.0 Hz", "above the physics rate 1000 Hz"),
    ("motors-rate-above-physics", '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = 1500',
     "rate_hz 1500.0 Hz", "above the physics rate 1000 Hz"),
    ("camera-rate-above-physics", '[[sensors]]\ntype = "Camera"\nname = "C"\nrate_hz = 2000',
     "camera 'C': rate_hz 2000.0 Hz", "above the physics rate 1000 Hz"),
    ("status-rate-above-physics", "status_rate_hz = 1001", "status_rate_hz 1001.0 Hz",
     "above the physics rate 1000 Hz"),
    # Passed the start-up check (which built no board estimator), then INIT raised
    # OverflowError (the vibration's RMS) or refused the estimator's infinite noise.
    ("vibration-overflow", '[[sensors]]\ntype = "Accelerometer"\nname = "A"\n'
     'vibration_broadband = 1e300', "VibrationBroadband", "1e+300 is too large"),
    ("gyro-vibration-overflow", '[[sensors]]\ntype = "Gyro"\nname = "G"\n'
     'vibration_rotor = 1e200', "VibrationRotor", "1e+200 is too large"),
    # Infinite counts per radian: the first reading raised OverflowError in round() and
    # stopped the engine for every client ("the simulation engine failed").
    ("flow-pixels-overflow", '[[sensors]]\ntype = "OpticalFlow"\nname = "F"\npixels = 1e308',
     "Pixels", "1e+308 is too large"),
    ("flow-counts-overflow", '[[sensors]]\ntype = "OpticalFlow"\nname = "F"\n'
     'counts_per_pixel = 1e308', "CountsPerPixel", "1e+308 is too large"),
    # The board's filter squares the noise its sensors give: INIT refused "estimator:
    # flow_noise_rad_s must be a number >= 0, got inf" (no file, no sensor key); at 25 Hz the
    # file loaded and the filter's OverflowError stopped the engine; an accelerometer's 1e308
    # loaded and every STEP answered ERR "PositionSigma: inf is not a finite number".
    ("flow-noise-estimator", '[[sensors]]\ntype = "OpticalFlow"\nname = "F"\nrate_hz = 500\n'
     'noise_sigma = 1e308', "NoiseSigma", "1e+308 is too large"),
    ("flow-noise-estimator-slow", '[[sensors]]\ntype = "OpticalFlow"\nname = "F"\n'
     'rate_hz = 25\nnoise_sigma = 1e308', "NoiseSigma", "1e+308 is too large"),
    ("accel-noise-estimator", '[[sensors]]\ntype = "Accelerometer"\nname = "A"\n'
     'noise_sigma = 1e308', "sensor 'A' (Accelerometer): NoiseSigma", "1e+308 is too large"),
    ("gps-sigma-estimator", '[[sensors]]\ntype = "GPS"\nname = "G"\n'
     'horizontal_sigma = 1e200', "HorizontalSigma", "1e+200 is too large"),
]


def _write(folder: Path, body: str) -> Path:
    path = folder / "bad.toml"
    path.write_text(f'name = "bad"\n{body}\n', encoding="utf-8")
    return path


def _assert_names(exc: ConfigError, path: Path, key: str, value: str) -> None:
    text = str(exc)
    assert str(path) in text and key in text and value in text, text


def _build_robot(path: Path) -> Robot:
    """What INIT does with the file, short of adding the robot to MuJoCo."""
    return Robot("R", load_robot_config(path), physics_step_s=PHYSICS_STEP_S,
                 rng=np.random.default_rng(0), sink=lambda events: None,
                 spawn_pos_ned_m=(0.0, 0.0, -1.0), spawn_rpy_rad=(0.0, 0.0, 0.0), airborne=True)


@pytest.mark.parametrize(("body", "key", "value"), [c[1:] for c in CASES],
                         ids=[c[0] for c in CASES])
def test_building_the_robot_raises_config_error_naming_file_key_value(
    tmp_path: Path, body: str, key: str, value: str
) -> None:
    path = _write(tmp_path, body)
    with pytest.raises(ConfigError) as info:
        _build_robot(path)
    _assert_names(info.value, path, key, value)
    with pytest.raises(ConfigError) as checked:  # the same check, without building the robot
        check_robot_config(load_robot_config(path), PHYSICS_STEP_S)
    assert str(checked.value) == str(info.value)


@pytest.mark.parametrize(("body", "key", "value"), [c[1:] for c in CASES],
                         ids=[c[0] for c in CASES])
def test_start_up_validation_refuses_what_init_refuses(
    tmp_path: Path, body: str, key: str, value: str
) -> None:
    path = _write(tmp_path, body)
    with pytest.raises(ConfigError) as init:
        _build_robot(path)
    with pytest.raises(ConfigError) as info:
        validate_robot_dirs((tmp_path,), partial(check_robot_config,
                                                 physics_step_s=PHYSICS_STEP_S))
    _assert_names(info.value, path, key, value)
    assert str(info.value) == str(init.value)  # the message INIT would give


@pytest.mark.parametrize(("text", "key", "value"), [
    # Loaded: GETCONF {Type Robot} then answered ERR "Class: 'my quad' is not one word".
    ('name = "my quad"', "'name'", "'my quad'"),
    ('name = "q}"', "'name'", "'q}'"),
    ('name = "q\\u001b[2J"', "'name'", "'q\\x1b[2J'"),
    # Turned into the text "5" without a word.
    ('name = "q"\ndescription = 5', "'description'", "5"),
])
def test_robot_name_and_description_are_refused_naming_the_file(
    tmp_path: Path, text: str, key: str, value: str
) -> None:
    path = tmp_path / "q.toml"
    path.write_text(text + "\n", encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        validate_robot_dirs((tmp_path,))
    _assert_names(info.value, path, key, value)


def test_good_robot_files_pass_start_up_validation(tmp_path: Path) -> None:
    for name in ("hummingbird", "airrobot"):
        text = resources.files("skeye.robots").joinpath(f"{name}.toml").read_text("utf-8")
        (tmp_path / f"my{name}.toml").write_text(
            text.replace(f'name = "{name}"', f'name = "my{name}"'), encoding="utf-8")
    check = partial(check_robot_config, physics_step_s=PHYSICS_STEP_S)
    assert len(validate_robot_dirs((tmp_path,), check)) == 2
    _write(tmp_path, '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = 50')
    assert len(validate_robot_dirs((tmp_path,), check)) == 3


def test_a_rate_at_the_physics_rate_is_sampled_every_step(tmp_path: Path) -> None:
    path = _write(tmp_path, '[[sensors]]\ntype = "Gyro"\nname = "G"\nrate_hz = 1000\n'
                  '[[sensors]]\ntype = "Camera"\nname = "C"\nrate_hz = 1000')
    robot = _build_robot(path)
    assert [s.period_steps for s in robot.sensors] == [1]
    assert robot.cameras[0].rate_hz == 1000.0


def test_sim_refuses_to_start_with_a_file_init_would_refuse(tmp_path: Path) -> None:
    path = _write(tmp_path, "board_rate_hz = 3")
    done = subprocess.run([sys.executable, "-m", "skeye.cli", "sim", "--port", "0",
                           "--robot-dir", str(tmp_path)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2, done
    assert f"{path}: board_rate_hz 3" in done.stderr
    assert "control protocol on" not in done.stdout


def test_a_bad_init_gets_a_clear_err_and_the_server_goes_on(tmp_path: Path) -> None:
    path = _write(tmp_path, '[[sensors]]\ntype = "Motors"\nname = "M"\nrate_hz = 0')
    with running_sim(robot_dirs=(tmp_path,)) as server:
        c = LineClient(server.port)
        c.expect("NFO")
        err = c.answer("INIT {ClassName bad} {Name B} {Location 0,0,-1}", "INIT")
        reason = err.get("Reason") or ""
        assert err.type == "ERR" and str(path) in reason and "Rate must be > 0" in reason, err
        assert "failed:" not in reason  # not a Python exception from deeper down
        d = LineClient(server.port)
        d.expect("NFO")
        assert d.answer("INIT {ClassName hummingbird} {Name G} {Location 0,0,-1}",
                        "INIT").type == "RES"
        assert c.answer("INIT {ClassName hummingbird} {Name H} {Location 3,0,-1}",
                        "INIT").type == "RES"
        c.close()
        d.close()


@pytest.mark.parametrize("key", ["noise_sigma", "quality_sigma"])
def test_a_huge_flow_noise_saturates_the_registers_and_the_engine_goes_on(
    tmp_path: Path, key: str
) -> None:
    """A sigma of 1e308 times a normal deviate above 1.8 is inf: round(inf) raised
    OverflowError out of the flow sensor's reading and stopped the engine for every client."""
    # The oracle estimator: the board's own filter does not read the flow sensor.
    _write(tmp_path, f'[estimator]\nkind = "truth"\n[[sensors]]\ntype = "OpticalFlow"\n'
                     f'name = "F"\nrate_hz = 25\n{key} = 1e308')
    with running_sim(robot_dirs=(tmp_path,)) as server:
        c = LineClient(server.port)
        c.expect("NFO")
        init = c.answer("INIT {ClassName bad} {Name B} {Location 0,0,-1}", "INIT")
        assert init.type == "RES", init
        c.send("STEP {Count 400}")
        seen, done = c.read_until(lambda m: m.type in ("RES", "ERR")
                                  and m.get("Command") == "STEP")
        assert done.type == "RES", done
        flows = [m for m in seen if m.type == "SEN" and m.get("Type") == "OpticalFlow"]
        assert len(flows) >= 5
        for m in flows:
            dx, dy = (int(v) for v in m.require("Delta").split(","))
            assert -128 <= dx <= 127 and -128 <= dy <= 127, m
            assert 0 <= int(m.require("Quality")) <= 169, m
        c.close()


def test_sim_check_builds_the_board_filter_that_estimator_option_asks_for(tmp_path: Path) -> None:
    """A file of ``[estimator] kind = "truth"`` was checked without the board's filter even
    under ``skeye sim --estimator onboard``: an accelerometer noise the filter refuses passed
    ``skeye sim --check`` (status 0), and every INIT of the class was then refused."""
    path = _write(tmp_path, '[estimator]\nkind = "truth"\n[[sensors]]\ntype = "Accelerometer"\n'
                            'name = "A"\nnoise_sigma = 1e308')
    argv = [sys.executable, "-m", "skeye.cli", "sim", "--check", "--robot-dir", str(tmp_path)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done  # the oracle does not filter its readings
    done = subprocess.run([*argv, "--estimator", "onboard"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2, done
    assert f"{path}: sensor 'A' (Accelerometer): NoiseSigma 1e+308 is too large" in done.stderr


@pytest.mark.parametrize(("robot_file", "why"), [
    # A compass noise_sigma of 1e308 loads, and one of its readings is -inf: the encoder's
    # refusal ended the engine's hand-over of every robot's lines, and from then on every STEP
    # of every client answered ERR "Field: -inf is not a finite number".
    ('[[sensors]]\ntype = "MagneticCompass"\nname = "C"\nrate_hz = 500\nnoise_sigma = 1e308',
     "is not a finite number"),
    # An [estimator] attitude_kp of 1e308 drove the board's attitude filter to NaN, and the
    # ZeroDivisionError out of its next gyro reading ended the engine for every client.
    ("[estimator]\nattitude_kp = 1e308", "its board failed"),
], ids=["unsendable reading", "board fault"])
def test_a_robot_that_fails_is_stopped_and_the_others_fly_on(tmp_path: Path, robot_file: str,
                                                            why: str) -> None:
    _write(tmp_path, robot_file)
    with running_sim(robot_dirs=(tmp_path,)) as server:
        good = LineClient(server.port)
        good.expect("NFO")
        assert good.answer("INIT {ClassName hummingbird} {Name H} {Location 3,0,-1}",
                           "INIT").type == "RES"
        bad = LineClient(server.port)
        bad.expect("NFO")
        assert bad.answer("INIT {ClassName bad} {Name B} {Location 0,0,-1}", "INIT").type == "RES"
        for _ in range(3):
            good.send("STEP {Count 200}")
            seen, done = good.read_until(lambda m: m.type in ("RES", "ERR")
                                         and m.get("Command") == "STEP")
            assert done.type == "RES", done
            assert any(m.type == "SEN" and m.get("Name") == "GPS" for m in seen)
        stopped = bad.read_until(lambda m: m.type == "ERR")[1]
        reason = stopped.get("Reason") or ""
        assert "robot stopped" in reason and why in reason, stopped
        good.close()
        bad.close()


@pytest.mark.parametrize(("file_name", "why"), [
    ("hummingbird.toml", "INIT {ClassName hummingbird} takes the built-in class hummingbird"),
    ("AirRobot.toml", "INIT {ClassName AirRobot} takes the built-in class airrobot"),
    ("my.quad.toml", "holds only letters, digits, '-' and '_'"),
])
def test_a_robot_file_init_never_loads_is_refused(tmp_path: Path, file_name: str,
                                                   why: str) -> None:
    """A --robot-dir hummingbird.toml passed the start-up check while INIT {ClassName
    hummingbird} flew the built-in (its mass_kg 0.9 unseen: CONF said Mass 0.68); my.quad.toml
    could not be asked for at all."""
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    (tmp_path / file_name).write_text(text.replace("mass_kg = 0.68", "mass_kg = 0.9"))
    with pytest.raises(ConfigError) as info:
        validate_robot_dirs((tmp_path,))
    assert str(info.value) == f"--robot-dir {tmp_path}: {file_name} is never used: " + (
        f"{why}; give the file (and its 'name') another name" if "INIT" in why
        else f"a class name (the file's name) {why}")



def test_a_class_an_earlier_robot_dir_gives_is_refused(tmp_path: Path) -> None:
    """INIT takes the first --robot-dir's file of a class: a second folder's MyQuad.toml (mass_kg
    0.9) passed the start-up check and was never flown. The same folder named twice is fine."""
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    text = text.replace('name = "hummingbird"', 'name = "myquad"')
    first, second = tmp_path / "a", tmp_path / "b"
    first.mkdir()
    second.mkdir()
    (first / "myquad.toml").write_text(text)
    (second / "MyQuad.toml").write_text(text.replace("mass_kg = 0.68", "mass_kg = 0.9"))
    assert load_robot_config("MyQuad", (first, second)).airframe.mass_kg == 0.68
    assert len(validate_robot_dirs((first, first))) == 1
    with pytest.raises(ConfigError) as info:
        validate_robot_dirs((first, second))
    assert str(info.value) == (f"--robot-dir {second}: MyQuad.toml is never used: INIT "
                               f"{{ClassName MyQuad}} takes {first / 'myquad.toml'} (an earlier "
                               "--robot-dir; class names ignore case)")
