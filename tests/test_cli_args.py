"""Bad command-line values: every sub-command refuses them with one line naming the option and
exit status 2, never a traceback (the shared validators of :mod:`skeye.cliargs`, and the checks
made at start-up). Each case is built to end quickly even where the check is missing."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from skeye import cliargs
from skeye.cli import main
from skeye.pilot.cli import describe_airframe
from skeye.pilot.server import PilotServer
from tests.pilot.fake_airframe import FakeAirframe

ROOT = Path(__file__).resolve().parents[1]
PILOT = ["pilot", "--sim", "127.0.0.1:1"]  # nothing listens there: a pilot past its checks exits 4
NO_SIM = "127.0.0.1:1"

CASES = [
    (["sim", "--port", "-1"], "--port"),
    (["sim", "--port", "70000"], "--port"),
    (["sim", "--port", "0", "--image-port", "-3"], "--image-port"),
    (["sim", "--port", "0", "--seed", "-1"], "--seed"),
    ([*PILOT, "--port", "-5"], "--port"),
    ([*PILOT, "--port", "0", "--link-timeout", "-1"], "--link-timeout"),
    ([*PILOT, "--port", "0", "--tick", "-1"], "--tick"),
    ([*PILOT, "--port", "0", "--lockstep-rate", "-1"], "--lockstep-rate"),
    ([*PILOT, "--serial", "/dev/null", "--baud", "-1"], "--baud"),
    ([*PILOT, "--serial", "/dev/null", "--baud", "99999999999"], "--baud"),  # went to the port
    ([*PILOT, "--serial", "/dev/nonexistent-skeye"], "--serial"),
    # a camera URI is parsed whole before the airframe opens (only its scheme was)
    ([*PILOT, "--port", "0", "--camera", "v4l2:///dev/video0?width=abc"], "--camera"),
    ([*PILOT, "--port", "0", "--camera", "sim://h:abc/R1/Down"], "--camera"),
    ([*PILOT, "--port", "0", "--camera", "file://clip.mp4?fps=-3"], "--camera"),
    # an image server or simulator address with a bad port was blamed on --airframe (given or
    # not) as "simulator address"
    ([*PILOT, "--port", "0", "--images", "127.0.0.1:0"], "--images: image server address"),
    (["pilot", "--sim", "127.0.0.1:70000", "--port", "0"], "--sim: simulator address"),
    (["snapshot", "--images", "127.0.0.1:5OO3", "--out", "x.png"],
     "--images: image server address"),
    # the up cases give a calibration file that is not there: without the option's check, up
    # stops on that (status 1) before anything starts
    (["up", "--sim-port", "-1", "--calibration", "/nonexistent"], "--sim-port"),
    (["up", "--ground-port", "70000", "--calibration", "/nonexistent"], "--ground-port"),
    (["up", "--seed", "-1", "--calibration", "/nonexistent"], "--seed"),
    # the ground cases bind an address that cannot be: without the check, that stops them
    (["ground", "--vehicle", "tcp://127.0.0.1:7000", "--port", "-1"], "--port"),
    (["ground", "--video-fps", "-1", "--host", "256.0.0.1"], "--video-fps"),
    # a frame rate for a video it has none of (--video not given): was accepted, unused
    (["ground", "--video-fps", "5", "--host", "256.0.0.1"], "--video-fps"),
    (["ground", "--vehicle", "foo://x:1", "--host", "256.0.0.1"], "--vehicle"),
    # a port that is no number, and a bracket left open: urllib's ValueError used to escape
    (["ground", "--vehicle", "tcp://127.0.0.1:abc", "--host", "256.0.0.1"], "--vehicle"),
    (["ground", "--vehicle", "tcp://[::1:7000", "--host", "256.0.0.1"], "--vehicle"),
    (["link", "tcp://127.0.0.1:99999", "poll", "all"], "tcp://127.0.0.1:99999"),
    (["replay", "flight.rec", "--port", "-1"], "--port"),
    ([*PILOT, "--robot-dir", "no-such-folder"], "--robot-dir"),  # was ignored
    (["ground", "--robot-dir", "no-such-folder", "--host", "256.0.0.1"], "--robot-dir"),
    # --seeds 0 after the bad option ends a run the option's check would not stop
    (["validate", "E1", "--quick", "--first-seed", "-3", "--seeds", "0"], "--first-seed"),
    (["validate", "--workers", "0", "--seeds", "0"], "--workers"),
    (["validate", "E1", "--quick", "--seeds", "99999999999999"], "--seeds"),  # MemoryError
    (["sweep", "spec.toml", "--out", "o", "--workers", "0"], "--workers"),
    # an empty name was the current folder: the trials were run and written there, and said
    # to be kept in "/trials"
    (["sweep", "spec.toml", "--out", ""], "--out"),
    # Every file or folder named empty (a shell variable left empty) is refused naming its
    # option: it was the current folder, "." ("recording . is a directory", "--out . is a
    # directory", "calibration file: Is a directory"), searched for robots, or nothing.
    *[(argv, option) for argv, option in (
        (["sim", "--record", ""], "--record"), (["sim", "--world", ""], "--world"),
        (["sim", "--robot-dir", ""], "--robot-dir"), (["replay", ""], "file"),
        (["plot", ""], "file"), (["plot", "x.rec", "--out", ""], "--out"),
        (["snapshot", "--images", NO_SIM, "--out", ""], "--out"),
        (["pad", "--out", ""], "--out"), (["calibrate", ""], "images"),
        (["calibrate", "a.png", "--out", ""], "--out"), (["logs", ""], "log"),
        (["logs", "--json", ""], "--json"), (["up", "--calibration", ""], "--calibration"),
        (["up", "--world", ""], "--world"), (["ground", "--robot-dir", ""], "--robot-dir"),
        ([*PILOT, "--robot-dir", ""], "--robot-dir"), (["vision", "detect", ""], "image"))],
    (["snapshot", "--images", NO_SIM, "--timeout", "-1", "--out", "x.png"], "--timeout"),
    # past what a socket's timeout takes (about 9.2e9 s): an OverflowError traceback
    (["snapshot", "--images", NO_SIM, "--timeout", "1e10", "--out", "x.png"], "--timeout"),
    # an empty --camera took the server's first camera, as no --camera does; a bad one was
    # said only after connecting, without the option's name (no server: "no image server")
    (["snapshot", "--images", NO_SIM, "--camera", "", "--out", "x.png"], "--camera"),
    (["snapshot", "--images", NO_SIM, "--camera", "R1 Down", "--out", "x.png"], "--camera"),
    # said as "JPEG quality must be 1..100", without the option's name
    (["snapshot", "--images", NO_SIM, "--out", "x.jpg", "--quality", "0"], "--quality"),
    (["snapshot", "--images", NO_SIM, "--out", "x.jpg", "--quality", "101"], "--quality"),
    # outside the replay's range: said as "replay speed must be in [0.01, 1000], got 5000.0"
    (["replay", "flight.rec", "--port", "0", "--speed", "5000"], "--speed"),
    (["replay", "flight.rec", "--port", "0", "--speed", "0.001"], "--speed"),
    (["plot", "flight.rec", "--out", "x.txt"], "--out"),
    # said as "dpi must be within 10..1200", without the option's name
    (["pad", "--out", "x.png", "--dpi", "0"], "--dpi"),
    (["pad", "--out", "x.png", "--dpi", "5000"], "--dpi"),
    (["logs", "--rate", "200", "--seconds", "-5"], "--seconds"),
    (["logs", "--rate", "200", "--seconds", "0"], "--seconds"),
    (["logs", "--rate", "200", "--seconds", "1"], "--seconds"),
    (["link", "tcp://" + NO_SIM, "stream", "-1"], "seconds"),
    (["link", "tcp://" + NO_SIM, "stream", "1", "--period", "0"], "--period"),
    (["link", "tcp://" + NO_SIM, "--timeout", "-1", "poll", "all"], "--timeout"),
    # values a packet cannot carry: said in SI before the link is opened (they were said in
    # wire units, and only by a vehicle that answered: exit 1 without one)
    (["link", "tcp://" + NO_SIM, "velocity", "1", "0", "0", "--duration", "70"],
     "--duration 70 s is outside 0..65.535 s"),
    (["link", "tcp://" + NO_SIM, "velocity", "40", "0", "0"], "40 m/s is outside"),
    (["link", "tcp://" + NO_SIM, "take-off", "1e300"], "is outside"),
    (["link", "tcp://" + NO_SIM, "poll", "no_such_bit"], "unknown mask bit"),
]


@pytest.mark.parametrize(("argv", "option"), CASES, ids=[" ".join(a) for a, _ in CASES])
def test_a_bad_value_is_refused_naming_its_option(argv: list[str], option: str,
                                                  capsys: pytest.CaptureFixture[str],
                                                  tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # flight.rec, spec.toml, x.png: not there
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's refusal
        code = exc.code
    captured = capsys.readouterr()
    text = captured.out + captured.err
    assert code == 2, text
    assert option in text and "Traceback" not in text


def test_the_shared_validators_take_their_ranges_whole() -> None:
    assert cliargs.port("0") == 0 and cliargs.port("65535") == 65535
    assert cliargs.fixed_port("1") == 1 and cliargs.seed("0") == 0
    assert cliargs.baud("57600") == 57600 and cliargs.baud("4000000") == 4_000_000
    assert cliargs.positive_float("0.5") == 0.5 and cliargs.non_negative_float("0") == 0.0
    for check, text in ((cliargs.fixed_port, "0"), (cliargs.port, "x"), (cliargs.seed, "1.5"),
                        (cliargs.positive_float, "nan"), (cliargs.positive_float, "inf"),
                        (cliargs.positive_int, "0"), (cliargs.non_negative_float, "-0.1"),
                        (cliargs.baud, "4000001"), (cliargs.baud, "+57600")):
        with pytest.raises(Exception, match="must be"):
            check(text)


def test_the_pilot_start_up_line_says_the_clock_mode_once() -> None:
    class Args:
        lockstep_rate = 2.0

    sim = "R1 in pad at sim://127.0.0.1:3000"
    assert describe_airframe(f"{sim} (realtime)", False, Args()) == f"{sim} (realtime)"
    assert describe_airframe(f"{sim} (lockstep)", True, Args()) == f"{sim} (lockstep x2)"
    board = "AscTec LL board on tcp://h:1"
    assert describe_airframe(f"{board} (realtime, 100 Hz)", False, Args()).count("realtime") == 1
    assert describe_airframe("a MAVLink flight controller", False, Args()).endswith("(realtime)")


def test_a_closed_output_ends_a_stream_quietly() -> None:
    """``skeye link ... stream 60 | head -1``: the first line read, the pipe closed; the command
    ends soon, with no BrokenPipeError on stderr."""
    with PilotServer(FakeAirframe(), port=0) as pilot:
        child = subprocess.Popen(
            [sys.executable, "-m", "skeye.cli", "link", pilot.address, "stream", "60",
             "--period", "0.02"],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        assert child.stdout is not None and child.stderr is not None
        first = child.stdout.readline()
        child.stdout.close()  # as head does after its line
        start = time.monotonic()
        err = child.stderr.read().decode()
        child.stderr.close()
        code = child.wait(30)
    assert first and code == 0, err
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert time.monotonic() - start < 30.0  # stopped at the closed pipe, not after 60 s


def test_a_broken_pipe_that_is_not_the_output_is_an_error(monkeypatch, capsys) -> None:
    """Only a closed standard output ends a command quietly: a socket's broken pipe (stdout
    still open) is an error like any other OSError."""
    from skeye.link import cli as link_cli

    def broken(*_: object) -> int:
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(link_cli, "run", broken)
    assert main(["link", "tcp://" + NO_SIM, "poll", "all"]) == 2
    assert "skeye link: error: [Errno 32] Broken pipe" in capsys.readouterr().err


WITHOUT_PYMAVLINK = """
import sys


class NotInstalled:  # as on the onboard install, which has no `mavlink` extra
    @staticmethod
    def find_spec(name, path=None, target=None):
        if name.split(".")[0] in ("pymavlink", "av"):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, NotInstalled)
from skeye.cli import main

sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("argv", [
    ["pilot", "--airframe", "mavlink://udp/127.0.0.1:0", "--port", "0"],
    [*PILOT, "--port", "0", "--mavlink", "udp://127.0.0.1:0"],
])
def test_a_mavlink_pilot_without_pymavlink_names_the_extra(argv: list[str]) -> None:
    """README and docs/onboard.md: on ``pip install 'skeye[onboard]'`` a command that needs an
    extra says which; the MAVLink airframe and links need the ``mavlink`` extra."""
    done = subprocess.run([sys.executable, "-c", WITHOUT_PYMAVLINK, *argv], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    assert ("skeye pilot: error: pymavlink is not installed: this command needs skeye's "
            "mavlink extra (pip install 'skeye[mavlink]'") in done.stderr


def test_an_output_folder_that_is_a_file_is_refused_naming_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """skeye validate --out and skeye sweep --out are folders: a file there was
    ``[Errno 17] File exists`` (validate) naming neither the option nor what to give."""
    taken = tmp_path / "results.txt"
    taken.write_text("kept")
    (tmp_path / "spec.toml").write_text('name = "x"\nexperiment = "E2"\nquick = true\n'
                                        'seeds = [1]\n[grid]\ne2_duration_s = [1.0]\n')
    for argv in (["validate", "E1", "--quick", "--out", str(taken)],
                 ["sweep", str(tmp_path / "spec.toml"), "--out", str(taken)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert f"--out {taken} is a file: give a folder" in err and "Traceback" not in err, err
    assert taken.read_text() == "kept"


def test_the_command_table_names_every_command_its_component_adds() -> None:
    """``skeye COMMAND`` builds only that command's options (``build_parser(argv)``): the table
    of names must name exactly what the components add, or a command would go missing."""
    from skeye.cli import _REGISTRARS, build_parser

    def commands(parser: Any) -> set[str]:
        (sub,) = [a for a in parser._actions if a.dest == "command"]
        return set(sub.choices)

    assert commands(build_parser()) == set(_REGISTRARS)
    for name in _REGISTRARS:
        alone = commands(build_parser(["-v", name, "--help"]))
        assert name in alone and alone < set(_REGISTRARS), (name, alone)
    assert commands(build_parser(["--help"])) == commands(build_parser(["no-such"])) == set(
        _REGISTRARS)


def test_a_command_starts_without_importing_the_other_commands() -> None:
    """``skeye ground`` (and every process ``skeye up`` or a sweep starts) imported every
    component's options, the pilot's image stack (OpenCV) among them: about 0.5 s of CPU a
    start."""
    script = ("import sys; from skeye.cli import build_parser; build_parser(['ground']); "
              "print(' '.join(sorted(m for m in sys.modules if m in ('cv2', 'skeye.pilot.cli', "
              "'skeye.validate.cli', 'skeye.sweep.cli', 'skeye.recording.snapshot'))))")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [], out.stdout


def test_python_dash_m_skeye_is_the_command_line() -> None:
    """``python -m skeye`` runs what the ``skeye`` script runs (a venv's python without its
    ``bin`` on PATH, as ``make`` and the benchmarks call it); it answered "No module named
    skeye.__main__"."""
    from skeye import __version__

    out = subprocess.run([sys.executable, "-m", "skeye", "--version"], capture_output=True,
                         text=True, timeout=120, cwd=ROOT)
    assert (out.returncode, out.stdout.strip()) == (0, f"skeye {__version__}"), out.stderr
    bad = subprocess.run([sys.executable, "-m", "skeye", "sim", "--port", "-1"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert bad.returncode == 2 and "usage: skeye sim" in bad.stderr, bad.stderr


def test_a_camera_name_far_too_long_is_refused_without_being_echoed_whole(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """``skeye snapshot --camera`` of 100 000 characters printed all of them back in its
    error."""
    assert main(["snapshot", "--images", NO_SIM, "--camera", "x" * 100_000,
                 "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "--camera" in err and "100000 characters" in err and len(err) < 400, err[:400]
