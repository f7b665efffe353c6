"""``skeye link`` and ``skeye pilot`` argument handling, against a pilot on a scripted airframe."""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest

from skeye.control.connection import connect
from skeye.errors import ConfigError
from skeye.link import cli as link_cli
from skeye.link.transport import pty_null_modem
from skeye.pilot import cli as pilot_cli
from skeye.pilot.server import PilotServer
from skeye.pilot.vision import PadVision
from skeye.vision.calibration import CameraCalibration
from tests.pilot.fake_airframe import FakeAirframe
from tests.sim.conftest import running_sim


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="skeye")
    sub = p.add_subparsers(dest="cmd", required=True)
    link_cli.register(sub)
    pilot_cli.register(sub)
    return p


def run(*argv: str) -> tuple[int, str]:
    args = parser().parse_args(list(argv))
    out = io.StringIO()
    return link_cli.run(args, out), out.getvalue()


def test_link_commands_print_answers_and_exit_codes():
    air = FakeAirframe()
    with PilotServer(air, port=0) as pilot:
        code, text = run("link", pilot.address, "poll", "ll_status,gps_data")
        assert code == 0 and text.startswith("LlStatus battery_voltage_1=12400")
        assert "GpsData latitude=490000000" in text
        code, _ = run("link", pilot.address, "land")
        assert code == link_cli.EXIT_REJECTED
        code, text = run("link", pilot.address, "take-off", "1.5")
        assert code == 0 and "Result command_pd=131 code=OK" in text
        assert air.calls[-1] == ("take_off", (1.5,))
        code, text = run("link", pilot.address, "pad-mode", "hold", "--deadband", "0.2")
        assert code == 0 and pilot.boards.pad.settings.deadband_m == 0.2
        code, text = run("link", pilot.address, "stream", "0.3", "--period", "0.05")
        assert code == 0 and text.count("NavStatus state=TAKING_OFF") >= 3
        code, _ = run("link", pilot.address, "poll", "no_such_bit")
        assert code == link_cli.EXIT_USAGE
    code, _ = run("link", "udp://x:1", "land")
    assert code == link_cli.EXIT_USAGE


def test_ctrl_c_ends_a_link_stream_in_one_line_not_a_traceback(tmp_path):
    """``skeye link URI stream 60`` is stopped with Ctrl-C: it said so in a KeyboardInterrupt
    traceback; now one line and status 130 (a shell's SIGINT status)."""
    out, err = tmp_path / "out", tmp_path / "err"
    with PilotServer(FakeAirframe(), port=0) as pilot, out.open("w") as o, err.open("w") as e:
        child = subprocess.Popen(
            [sys.executable, "-m", "skeye.cli", "link", pilot.address, "stream", "60"],
            stdout=o, stderr=e, stdin=subprocess.DEVNULL,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # as a terminal
        try:
            deadline = time.monotonic() + 60
            while "NavStatus" not in out.read_text() and child.poll() is None:
                assert time.monotonic() < deadline, "no telemetry streamed within 60 s"
                time.sleep(0.05)
            child.send_signal(signal.SIGINT)
            status = child.wait(30)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait(10)
    said = err.read_text()
    assert status == 130 and said == "skeye link: interrupted (Ctrl-C)\n", (status, said)


def test_pilot_arguments():
    args = parser().parse_args(
        [
            "pilot",
            "--sim",
            "127.0.0.1:3000",
            "--serial",
            "/dev/ttyUSB0",
            "--baud",
            "57600",
            "--link-timeout",
            "0.5",
            "--land-timeout",
            "3",
        ]
    )
    assert args.serial == "/dev/ttyUSB0" and args.link_timeout == 0.5 and args.land_timeout == 3
    assert args.host == "127.0.0.1" and args.func is pilot_cli.run


def test_a_pilot_that_cannot_reach_its_simulator_exits_with_status_4(capsys):
    # skeye up reads status 4 as "look at the simulator": it waits for the simulator's own exit
    # status (the root cause) before naming what failed.
    import socket

    with socket.socket() as s:  # a port nothing listens on: bound, never listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        args = parser().parse_args(["pilot", "--sim", f"127.0.0.1:{port}", "--port", "0"])
        assert pilot_cli.run(args) == pilot_cli.EXIT_LOST_SIMULATOR == 4
    assert "cannot connect to the simulator" in capsys.readouterr().err


def test_pilot_video_options_are_checked_before_anything_starts(capsys):
    base = ["pilot", "--sim", "127.0.0.1:1"]
    for extra, words in (
        (["--video-port", "0"], "needs --images"),
        (["--images", "127.0.0.1:1", "--video-port", "0", "--video-quality", "0"],
         "--video-quality must be 1..100"),
        (["--images", "127.0.0.1:1", "--video-port", "0", "--video-fps", "0"],
         "--video-fps must be in"),
        (["--images", "127.0.0.1:1", "--video-port", "0", "--video-clients", "0"],
         "--video-clients must be at least 1"),
    ):
        args = parser().parse_args(base + extra)
        assert pilot_cli.run(args) == 2
        assert words in capsys.readouterr().err


def test_pilot_names_a_taken_video_port(capsys):
    import socket

    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        args = parser().parse_args(["pilot", "--sim", "127.0.0.1:1", "--images", "127.0.0.1:1",
                                    "--port", "0", "--video-port", str(port)])
        assert pilot_cli.run(args) == 1
    err = capsys.readouterr().err
    assert f"port {port}" in err and "--video-port" in err and "video" in err


def test_pilot_calibration_is_checked_before_anything_starts(capsys, tmp_path):
    base = ["pilot", "--sim", "127.0.0.1:1", "--port", "0"]
    args = parser().parse_args([*base, "--calibration", str(tmp_path / "camera.toml")])
    assert pilot_cli.run(args) == 2
    assert "--calibration is for the pad vision: it needs --images" in capsys.readouterr().err
    (tmp_path / "camera.toml").write_text("[camera]\nwidth_px = 800\n")
    args = parser().parse_args([*base, "--images", "127.0.0.1:1",
                                "--calibration", str(tmp_path / "camera.toml")])
    assert pilot_cli.run(args) == 2
    err = capsys.readouterr().err
    assert "--calibration" in err and "missing required key" in err
    # a hand-edited focal length is named by its key (it was "fx and fy must be positive")
    text = CameraCalibration.pinhole(320, 240, 1.0).to_toml()
    (tmp_path / "camera.toml").write_text(
        "\n".join("fx_px = -400.0" if line.startswith("fx_px") else line
                  for line in text.splitlines()))
    assert pilot_cli.run(args) == 2
    err = capsys.readouterr().err
    assert err == (f"skeye pilot: error: --calibration: {tmp_path / 'camera.toml'}: [camera]"
                   ".fx_px: a focal length must be positive, got -400.0\n"), err
    # an empty name (a variable left empty) was read as the folder "." ("Is a directory")
    with pytest.raises(SystemExit) as refused:
        parser().parse_args([*base, "--images", "127.0.0.1:1", "--calibration", ""])
    assert refused.value.code == 2
    err = capsys.readouterr().err
    assert "argument --calibration: must name a file or folder, got ''" in err, err


def test_pilot_hands_the_calibration_to_the_detector():
    """Against a real simulator: the camera's size is checked, and the vision keeps it."""
    good = CameraCalibration(800, 600, 521.0, 521.0, 399.5, 299.5, (-0.2, 0.0, 0.0, 0.0, 0.0))
    small = CameraCalibration(640, 480, 420.0, 420.0, 319.5, 239.5, (0.0,) * 5)
    with running_sim() as server, connect(f"127.0.0.1:{server.port}") as sim:
        robot = sim.spawn("hummingbird", start="Pad1")
        with pytest.raises(ConfigError, match="640x480 images, camera Down gives 800x600"):
            pilot_cli.pad_vision_factory(sim, robot, "Down", small)
        make = pilot_cli.pad_vision_factory(sim, robot, "Down", good)
        vision = make(None, threading.Lock())
        assert isinstance(vision, PadVision) and vision.calibration is good


def test_pilot_vision_latency_option_is_checked_before_anything_starts(capsys):
    assert pilot_cli.vision_latency_s("300") == pytest.approx(0.3)
    assert pilot_cli.vision_latency_s("0") == 0.0
    assert pilot_cli.vision_latency_s("measured") is None
    base = ["pilot", "--sim", "127.0.0.1:1", "--port", "0"]
    for bad in ("-5", "fast", "nan"):
        args = parser().parse_args([*base, "--vision-latency-ms", bad])
        assert pilot_cli.run(args) == 2
        assert "--vision-latency-ms must be" in capsys.readouterr().err


def test_a_serial_device_that_cannot_be_opened_is_a_bad_option(capsys, monkeypatch, tmp_path):
    # A directory exists and is readable and writable, so only opening it finds it is no serial
    # port: that is --serial's fault (status 2), not a lost simulator (status 4).
    from skeye.pilot.airframe import VehicleLimits
    from tests.pilot.fake_airframe import FakeAirframe

    class Backend(FakeAirframe):  # what run() asks of an opened airframe besides the Airframe
        limits = VehicleLimits()
        lockstep = False
        closed = False

        def close(self) -> None:
            self.closed = True

    opened: list[Backend] = []
    monkeypatch.setattr(pilot_cli, "open_airframe",
                        lambda uri, options: opened.append(Backend()) or opened[-1])
    args = parser().parse_args(["pilot", "--sim", "127.0.0.1:1", "--serial", str(tmp_path)])
    assert pilot_cli.run(args) == 2
    err = capsys.readouterr().err
    assert "--serial" in err and str(tmp_path) in err
    assert opened and opened[0].closed


def test_link_errors_name_the_command(capsys):
    """Every message ``skeye link`` prints names it (the main parser's command, never the
    link's sub-command)."""
    code, _ = run("link", "udp://x:1", "land")
    assert code == link_cli.EXIT_USAGE
    assert capsys.readouterr().err.startswith("skeye link: error: link URI 'udp://x:1'")


def _unused_port() -> int:
    from tests.ports import free_port

    return free_port()  # nothing listens: a connection there is refused


@pytest.mark.parametrize(("extra", "status", "words"), [
    (["--frame-jitter-ms", "2000"], 2, "--frame-jitter-ms must be 0..1000 ms, got 2000.0"),
    (["--rtp-video", "udp://127.0.0.1:5600"], 2,
     "--rtp-video sends the camera: it needs --images or --camera URI"),
    (["--port", "0"], pilot_cli.EXIT_LOST_SIMULATOR, "cannot connect to the simulator at"),
    # refused by the RTP video only once the robot was spawned (status 1), and here as a
    # simulator not there (status 4)
    (["--port", "0", "--images", "127.0.0.1:1", "--rtp-video", "udp://127.0.0.1:5600",
      "--rtp-fps", "100"], 2, "--rtp-fps must be 0.1..60 frames/s, got 100"),
], ids=["bad option", "option needs another", "simulator not there", "bad --rtp-fps"])
def test_pilot_errors_go_to_stderr_naming_the_command(capsys, extra, status, words):
    """As every sub-command: ``skeye pilot: error: ...`` on stderr, nothing on stdout (which
    carries the start-up line and ``stopping``), and the exit status says which error."""
    from skeye.cli import main

    assert main(["pilot", "--sim", f"127.0.0.1:{_unused_port()}", *extra]) == status
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith(f"skeye pilot: error: {words}"), captured.err
    assert captured.err.count("\n") == 1, captured.err


@pytest.mark.parametrize(("extra", "words"), [
    (["--baud", "9600"], "--baud applies to the --serial line: it needs --serial"),
    (["--video-quality", "50"], "--video-quality applies to the video port: it needs "
                                "--video-port"),
    (["--rtp-fps", "5"], "--rtp-fps applies to the RTP video: it needs --rtp-video"),
    (["--policy-rate", "10"], "--policy-rate applies to the policy: it needs --policy"),
    (["--frame-time", "capture"], "--frame-time applies to the simulator's camera frames: it "
                                  "needs --images"),
    (["--vision-latency-ms", "40"], "--vision-latency-ms applies to the pad vision: it needs "
                                    "--images or --camera URI"),
    (["--no-vision-prediction"], "--no-vision-prediction applies to the pad vision: it needs "
                                 "--images or --camera URI"),
], ids=lambda v: v[0] if isinstance(v, list) else "")
def test_options_that_would_do_nothing_are_refused(capsys, extra, words):
    """A tuning option without the option it tunes (--baud without --serial, --video-quality
    without --video-port, ...) was accepted and ignored, the pilot starting as if it had been
    obeyed; as --calibration without a camera already was, it is refused before anything
    starts (exit 2)."""
    from skeye.cli import main

    assert main(["pilot", "--sim", f"127.0.0.1:{_unused_port()}", "--port", "0",
                 *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"skeye pilot: error: {words}"), err


@pytest.mark.parametrize("camera", ["/dev/video0", "flight.mp4", "Front"])
def test_a_camera_name_without_images_is_refused_naming_the_camera_uris(capsys, camera):
    """``--camera /dev/video0`` (the device, its ``v4l2://`` forgotten) on a real vehicle's
    airframe: a ``--camera`` that is no URI names a camera of the robot the pilot spawns, which
    only ``--images`` reads, so without it the pilot started, flew without a camera and said
    nothing (PAD never found). It is refused before the airframe opens (here a closed port,
    which would give status 4), naming the URIs that were likely meant."""
    from skeye.cli import main

    status = main(["pilot", "--airframe", f"asctec-ll://tcp/127.0.0.1:{_unused_port()}",
                   "--port", "0", "--camera", camera])
    err = capsys.readouterr().err
    assert status == 2, err
    assert err.startswith(f"skeye pilot: error: --camera {camera}: "), err
    assert "--images" in err and "v4l2:///dev/video0" in err and "file://" in err, err
    if camera.startswith("/dev/"):
        assert f"v4l2://{camera}" in err, err


@pytest.mark.parametrize("what", ["a directory", "the wrong size"])
def test_a_camera_file_that_cannot_be_flown_on_is_a_bad_camera_option(capsys, tmp_path, what):
    """``--camera file://...`` naming a directory, or a photo of another size than
    ``--calibration``'s: the pilot ended with status 1, "other errors", the message naming the
    camera but not the option, where a bad ``--camera`` (a malformed URI, a camera name the
    robot lacks) is status 2 naming it (docs/pilot.md). The airframe here is an LL board
    emulated on a fake vehicle, over TCP (the camera opens once the airframe is there)."""
    import cv2
    import numpy as np

    from skeye.cli import main
    from skeye.hil.line import open_line
    from skeye.hil.ll_server import LLBoardServer

    if what == "a directory":
        uri, extra, words = f"file://{tmp_path}", [], "(a directory)"
    else:
        cv2.imwrite(str(tmp_path / "pad.png"), np.zeros((48, 64, 3), np.uint8))
        CameraCalibration.pinhole(320, 240, 1.0).save(tmp_path / "camera.toml")
        uri = f"file://{tmp_path / 'pad.png'}"
        extra = ["--calibration", str(tmp_path / "camera.toml")]
        words = "frames are 64x48, the calibration is for 320x240"
    with LLBoardServer(FakeAirframe(), open_line("tcp"), time.monotonic) as board:
        status = main(["pilot", "--airframe", board.line.client_uri(), "--port", "0",
                       "--camera", uri, *extra])
    err = capsys.readouterr().err
    assert status == 2, err
    assert err.startswith(f"skeye pilot: error: --camera: camera {uri}: "), err
    assert words in err, err


@pytest.mark.parametrize("what", ["missing", "empty", "not a video", "a photo cut short",
                                  "text named .png"])
def test_a_camera_file_that_is_not_there_is_named_before_the_vehicle_is_opened(capsys, tmp_path,
                                                                              what):
    """``--camera file://...`` naming a file that is not there (a typo) or empty: the pilot
    opened the vehicle first (connected to the LL board and polled it; on a ``sim://``
    airframe, spawned its robot), and named the file only then, or not at all when the
    vehicle failed first ("LL board silent"). The file is now looked at with the URI, before
    the vehicle is opened. The "board" here is a loopback listener that must see no one."""
    import socket

    from skeye.cli import main

    path = tmp_path / "flihgt.mkv"
    if what == "empty":
        path.write_bytes(b"")
    elif what == "not a video":  # until 2026-11-28 these three were opened after the vehicle
        path = tmp_path / "notes.mp4"
        path.write_text("not a video\n")
    elif what == "a photo cut short":
        import cv2
        import numpy as np

        path = tmp_path / "pad.png"
        cv2.imwrite(str(path), np.random.default_rng(1).integers(0, 255, (48, 64, 3), np.uint8))
        path.write_bytes(path.read_bytes()[:200])
    elif what == "text named .png":
        path = tmp_path / "pad.png"
        path.write_text("not a photo\n")
    uri = f"file://{path}?fov_deg=60"
    with socket.create_server(("127.0.0.1", 0)) as board:
        board.settimeout(0.0)
        status = main(["pilot", "--airframe", f"asctec-ll://tcp/127.0.0.1:{board.getsockname()[1]}",
                       "--port", "0", "--camera", uri])
        with pytest.raises(BlockingIOError):  # nobody connected
            board.accept()
    err = capsys.readouterr().err
    assert status == 2, err
    words = {"missing": f"cannot open {path} as a video (no such file)",
             "empty": f"cannot open {path} as a video (an empty file)",
             "not a video": f"cannot open {path} as a video (not a video, or one cut short",
             "a photo cut short": f"{path} is truncated or corrupt",
             "text named .png": f"cannot open {path} as a video (not a video"}[what]
    assert err.startswith(f"skeye pilot: error: --camera: camera {uri}: {words}"), err
    assert err.count("\n") == 1, err


def test_a_start_pose_the_world_lacks_names_the_start_option(capsys):
    """The message said ``--airframe: no start pose ...``: an option the user had not given
    (the airframe came from --sim) and not the one at fault."""
    from skeye.cli import main

    with running_sim() as server:
        status = main(["pilot", "--sim", f"127.0.0.1:{server.port}", "--port", "0",
                       "--start", "Nowhere"])
    err = capsys.readouterr().err
    assert status == 2, err
    assert err.startswith(f"skeye pilot: error: sim://127.0.0.1:{server.port}: no start pose "
                          "'Nowhere'; the world has: Pad1"), err
    assert "give --start one of them" in err and "--airframe" not in err, err


def test_a_camera_name_the_robot_lacks_is_a_bad_camera_option(capsys):
    """``--images`` with ``--camera Nope`` ended with status 1 and ``GETCONF: robot R1 has no
    sensor ...``, naming neither the option nor the status of a bad option (docs/pilot.md)."""
    from skeye.cli import main

    with running_sim() as server:
        status = main(["pilot", "--sim", f"127.0.0.1:{server.port}", "--port", "0",
                       "--images", f"127.0.0.1:{_unused_port()}", "--camera", "Nope"])
    captured = capsys.readouterr()
    assert status == 2, captured.err
    assert captured.out == ""
    assert captured.err.startswith("skeye pilot: error: --camera Nope: "), captured.err
    assert "no sensor of type Camera named Nope" in captured.err, captured.err


def test_a_camera_lost_at_start_is_a_warning_on_stderr(capsys, monkeypatch, tmp_path):
    """The pilot runs on without its camera (the pad modes hold still): a warning, not an
    error. The --serial directory then stops it, as a bad option."""
    from skeye.pilot.airframe import VehicleLimits

    class Backend(FakeAirframe):
        limits = VehicleLimits()
        lockstep = False
        clock_is_sim = False

        def close(self) -> None:
            pass

    monkeypatch.setattr(pilot_cli, "open_airframe", lambda uri, options: Backend())
    camera = "v4l2:///dev/skeye-test-no-camera?fov_deg=60"  # not plugged in
    args = parser().parse_args(["pilot", "--sim", "127.0.0.1:1", "--camera", camera,
                                "--serial", str(tmp_path)])
    assert pilot_cli.run(args) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    warning, error = captured.err.splitlines()
    assert warning.startswith(f"skeye pilot: warning: camera {camera}: cannot open "), warning
    assert warning.endswith("; the pad modes hold still until it gives frames"), warning
    assert error.startswith("skeye pilot: error: --serial: "), error


def test_link_to_a_port_that_is_no_pilot_says_so(capsys):
    """``skeye link`` at a simulator's control port timed out with 'no poll answer', which did
    not say that nothing a vehicle sends had come; now it asks whether that is a pilot's link."""
    from skeye.cli import main

    with running_sim() as server:
        uri = f"tcp://127.0.0.1:{server.port}"
        status = main(["link", "--timeout", "1", uri, "poll"])
    err = capsys.readouterr().err
    assert status == link_cli.EXIT_LINK, err
    assert "nothing a vehicle sends came on this link" in err, err
    assert f"is {uri} a skeye pilot's link (skeye pilot --port)?" in err, err


@pytest.mark.parametrize(("argv", "said"), [
    (["velocity", "100", "0", "0"], "forward 100 m/s is outside -32.768..32.767 m/s, what a "
                                    "VELOCITY packet carries"),
    (["velocity", "0", "0", "40"], "up 40 m/s is outside -32.767..32.768 m/s"),
    (["velocity", "0", "0", "0", "--yaw-rate-deg-s", "5000"],
     "--yaw-rate-deg-s 5000 deg/s is outside -1877.47..1877.41 deg/s"),
    (["velocity", "0", "0", "0", "--duration", "100"], "--duration 100 s is outside 0..65.535 s"),
    (["velocity", "nan", "0", "0"], "forward must be a finite number (m/s), got nan"),
    (["move-by", "0", "0", "0", "--speed", "1e6"], "--speed 1e+06 m/s is outside 0..65.535 m/s, "
                                                   "what a MOVE_BY packet carries"),
    (["goto-gps", "100", "0", "1"], "latitude 100 deg is outside -90..90 deg, what a GOTO_GPS "
                                    "packet carries"),
    (["take-off", "1e9"], "height 1e+09 m is outside 0.001..2.14748e+06 m, what a TAKE_OFF "
                          "packet carries"),
    (["pad-mode", "hold", "--deadband", "1e9"], "--deadband 1e+09 m is outside 0..65.535 m"),
])
def test_link_values_the_packet_cannot_carry_are_said_in_the_users_terms(argv, said, capsys):
    """A value a command's packet cannot carry was said with skeye's internal field names
    (``VelocitySi.vel_frd_m_s[0] 100 m/s ...``, ``up`` as a down velocity); it is said with the
    argument or option the user typed, in its unit (deg/s for --yaw-rate-deg-s), as the
    command's own error (status 2), before the link is opened."""
    from skeye.cli import main

    assert main(["link", "tcp://127.0.0.1:1", *argv]) == link_cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.startswith(f"skeye link: error: {said}"), err
    assert "Si." not in err and "_m_s" not in err and "link error" not in err


@pytest.mark.parametrize(("argv", "said"), [
    (["poll", "0"], "mask 0 requests no structure; known: ll_status, "),
    (["poll", "0x0020"], "mask 0x0020 requests no structure; known: ll_status, "),
    (["poll", "0x10000"], "mask 0x10000 is outside 0..0xffff, what a POLL packet carries"),
    (["stream", "1", "--poll-mask", "0x10000"],
     "--poll-mask 0x10000 is outside 0..0xffff, what a STREAM packet carries"),
    (["stream", "1", "--skeye-mask", "0x10000"],
     "--skeye-mask 0x10000 is outside 0..0xffff, what a STREAM packet carries"),
    (["stream", "1", "--poll-mask", "0", "--skeye-mask", "0"],
     "--poll-mask 0 and --skeye-mask 0 request nothing to stream"),
    (["stream", "1", "--poll-mask", "0x0021"],
     "--poll-mask 0x0021 sets bits (0x0020) that name no structure a STREAM packet carries; "
     "known: ll_status, "),
    (["stream", "1", "--period", "100"],
     "--period 100 s is outside 0..65.535 s, what a STREAM packet carries"),
])
def test_link_masks_that_request_nothing_are_refused_before_the_link_opens(argv, said, capsys):
    """A poll mask that requests no structure (``poll 0``) was only refused by ``Vehicle.poll``
    after the link had opened, and one the packet cannot carry (``0x10000``) when it was
    encoded; with nothing listening (port 1 on loopback) the user read a connect error
    (status 1) about a command that could never have been sent. Masks are checked as the
    command packets are, before the link is opened: status 2, in the user's terms (a stream's
    --period too, which was only found too long for its packet once sent)."""
    from skeye.cli import main

    assert main(["link", "tcp://127.0.0.1:1", *argv]) == link_cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.startswith(f"skeye link: error: {said}"), err
    assert err.count("\n") == 1 and "link error" not in err, err


@pytest.mark.parametrize("uri", ["asctec-ll://serial/dev/ttyS1?baud=abc",
                                 "asctec-ll://bogus/x", "sim://127.0.0.1:1/x?zz=1"])
def test_an_airframe_uri_its_backend_refuses_is_named_once(capsys, uri):
    """The pilot put the URI before the backend's message, which names it already
    ("asctec-ll://...: airframe 'asctec-ll://...': ..."): one line, the URI said once."""
    from skeye.cli import main

    status = main(["pilot", "--airframe", uri, "--port", "0"])
    err = capsys.readouterr().err
    assert status == 2, err
    assert err.count(uri) == 1 and err.count("\n") == 1, err
    assert err.startswith(f"skeye pilot: error: airframe '{uri}': "), err


@pytest.mark.parametrize("scheme", ["asctec-ll://tcp/127.0.0.1:{port}",
                                    "mavlink://udpout/127.0.0.1:{port}"])
def test_images_on_a_real_vehicle_is_refused_before_the_vehicle_is_opened(capsys, scheme):
    """``--images`` reads the camera of a robot the pilot spawns; a real vehicle's airframe
    spawns none. The refusal came after the airframe was opened (a real board or flight
    controller, here a closed port: status 4 after the wait); it now comes first."""
    from skeye.cli import main

    uri = scheme.format(port=_unused_port())
    status = main(["pilot", "--airframe", uri, "--port", "0", "--images", "127.0.0.1:5000",
                   "--timeout", "30"])
    err = capsys.readouterr().err
    assert status == 2, err
    assert err == (f"skeye pilot: error: --images reads the camera of a robot the pilot "
                   f"spawned (sim://); {uri} has none: give --camera URI\n"), err


@pytest.mark.parametrize("where", ["-3,0,0", "-2.5,-1,-1.5", "-1e1,0,0"])
def test_a_location_south_or_west_of_the_origin_is_a_value_not_an_option(where):
    """A fleet's second vehicle spawns beside the pad, south or west of it as often as north or
    east: ``--location -3,0,0`` was read as an unknown option ("argument --location: expected
    one argument", exit 2) until 2026-11-27; a negative number alone always was a value."""
    args = parser().parse_args(["pilot", "--location", where])
    assert args.location == where
    options = pilot_cli.airframe_options(args)
    assert options.location_ned_m == tuple(float(v) for v in where.split(","))



@pytest.mark.parametrize("airframe", [None, "sim://127.0.0.1:{port}"])
def test_a_sim_pilot_given_another_robots_camera_is_refused(capsys, airframe):
    """A vehicle's camera is on the vehicle: a ``sim://`` pilot flying R1 given
    ``--camera sim://.../R2/Down`` would fly R1 on what R2 sees (its pad offsets, its height).
    Refused at start, exit 2, naming both robots, before the simulator is reached (nothing
    listens at ``--sim``: until 2026-11-28 the pilot went on to it, exit 4; with a simulator
    there it would have flown R1 on R2's camera). Its own camera, by its name or the short
    form, passes this check (then exit 4: no simulator)."""
    from skeye.cli import main

    port = _unused_port()
    where = ["--sim", f"127.0.0.1:{port}"] if airframe is None else [
        "--airframe", airframe.format(port=port)]
    other = "sim://127.0.0.1:5003/R2/Down?fov_deg=60"
    status = main(["pilot", *where, "--name", "R1", "--port", "0", "--timeout", "1",
                   "--camera", other])
    err = capsys.readouterr().err
    assert status == 2, err
    assert err == (f"skeye pilot: error: --camera {other} is robot R2's camera; this pilot "
                   "flies R1 (--name): a vehicle's camera is on the vehicle: give "
                   "sim://HOST:PORT/R1/CAMERA, or sim://HOST:PORT/CAMERA\n"), err
    for own in ("sim://127.0.0.1:5003/R1/Down?fov_deg=60", "sim://127.0.0.1:5003/Down"):
        status = main(["pilot", *where, "--name", "R1", "--port", "0", "--timeout", "1",
                       "--camera", own])
        err = capsys.readouterr().err
        assert status == 4, err


def test_lockstep_sync_on_a_real_vehicle_is_refused(capsys):
    """``--lockstep-sync`` is about a lockstep simulator's clock: on an LL board it would do
    nothing, so it is refused before the vehicle is opened (a closed port: without the check,
    status 4 after the wait)."""
    from skeye.cli import main

    uri = f"asctec-ll://tcp/127.0.0.1:{_unused_port()}"
    status = main(["pilot", "--airframe", uri, "--port", "0", "--lockstep-sync",
                   "--timeout", "30"])
    err = capsys.readouterr().err
    assert status == 2, err
    assert err == (f"skeye pilot: error: --lockstep-sync keeps a lockstep simulator's clock "
                   f"with the other pilots of its robots (sim://); {uri} steps no "
                   "simulator\n"), err


def test_lockstep_options_on_a_realtime_simulator_are_a_warning(capsys, tmp_path):
    """``--lockstep-sync``, ``--lockstep-rate`` and ``--ground-clock`` are about a lockstep
    simulator's clock; on a realtime one (known only once connected) they do nothing, and the
    pilot says so on stderr and flies on."""
    with running_sim(mode="realtime") as server:
        args = parser().parse_args([
            "pilot", "--sim", f"127.0.0.1:{server.port}", "--lockstep-sync",
            "--lockstep-rate", "3", "--serial", str(tmp_path)])
        assert pilot_cli.run(args) == 2  # the --serial directory then stops it, a bad option
    warning, error = capsys.readouterr().err.splitlines()
    assert warning.startswith("skeye pilot: warning: --lockstep-rate and --lockstep-sync: the "
                              "vehicle runs in real time (R1 in "), warning
    assert warning.endswith("(realtime)), with no lockstep clock to pace, keep together or "
                            "grant: they do nothing"), warning
    assert error.startswith("skeye pilot: error: --serial: "), error
    with running_sim(mode="lockstep") as server:  # where they apply: not a word
        args.sim = f"127.0.0.1:{server.port}"
        assert pilot_cli.run(args) == 2
    (error,) = capsys.readouterr().err.splitlines()
    assert error.startswith("skeye pilot: error: --serial: "), error


@pytest.mark.parametrize("camera", ["file://{tmp}/pad.png", "v4l2:///dev/video63?width=800"])
def test_a_camera_whose_field_of_view_nothing_gives_is_named_before_the_vehicle(capsys, tmp_path,
                                                                              camera):
    """``--camera file://pad.png`` or ``v4l2:///dev/video0`` (the first table of
    docs/onboard.md, copied as written) with no ``fov_deg=`` and no ``--calibration``: the pad
    detector cannot work, and the pilot says so with exit status 2. Until 2026-11-28 it said it
    only after opening the vehicle (connecting to the LL board, spawning a robot), so a vehicle
    that did not answer (here a closed port) ended it with status 4 and the missing option
    unsaid. A ``sim://`` camera's field of view is the simulator's: not asked for."""
    import cv2
    import numpy as np

    from skeye.cli import main

    cv2.imwrite(str(tmp_path / "pad.png"), np.zeros((48, 64, 3), np.uint8))
    uri = camera.format(tmp=tmp_path)
    status = main(["pilot", "--airframe", f"asctec-ll://tcp/127.0.0.1:{_unused_port()}",
                   "--port", "0", "--camera", uri])
    err = capsys.readouterr().err
    assert status == 2, err
    assert err == (f"skeye pilot: error: --camera {uri}: its field of view is not known: add "
                   "fov_deg= to the URI, or give --calibration camera.toml (skeye "
                   "calibrate)\n"), err


@pytest.mark.parametrize("name", ["notes.mp4", "notes.png"])
def test_a_camera_file_that_is_no_video_is_refused_in_one_line(tmp_path, name):
    """``skeye pilot --camera file://notes.mp4`` (a text file): the refusal is one line. Until
    2026-11-28 FFmpeg's own message came first on the pilot's stderr (``[mov,mp4,... @ 0x...]
    moov atom not found``, ``[png @ 0x...] Invalid PNG signature``), written by the library to
    the process's stderr, so a process of its own is run here."""
    import os
    import sys

    path = tmp_path / name
    path.write_text("not a video\n")
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    done = subprocess.run(
        [sys.executable, "-m", "skeye", "pilot", "--airframe",
         f"asctec-ll://tcp/127.0.0.1:{_unused_port()}", "--port", "0",
         "--camera", f"file://{path}?fov_deg=60"],
        capture_output=True, text=True, timeout=60, env=env, stdin=subprocess.DEVNULL)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith(f"skeye pilot: error: --camera: camera file://{path}"), \
        done.stderr
    assert done.stderr.count("\n") == 1, done.stderr


def test_a_camera_file_name_that_decodes_to_a_control_character_is_refused(capsys, tmp_path):
    """``--camera file://frames/%04d.png`` (a printf pattern, as OpenCV and FFmpeg write image
    sequences): ``%04`` is a URI escape, the byte 0x04, and the pilot said ``cannot open
    frames/d.png as a video (no such file)``, the control character invisible. Now the URI
    is refused naming the decoded name and how a ``%`` is written."""
    from skeye.cli import main

    uri = f"file://{tmp_path}/%04d.png?fov_deg=60"
    status = main(["pilot", "--airframe", f"asctec-ll://tcp/127.0.0.1:{_unused_port()}",
                   "--port", "0", "--camera", uri])
    err = capsys.readouterr().err
    assert status == 2, err
    assert "\\x04d.png" in err and "%25" in err and "\x04" not in err, err


@pytest.mark.parametrize(("argv", "said"), [
    (["stream", "1", "--period", "0.0004"],
     "--period 0.0004 s is 0 in the STREAM packet, which carries it in steps of 0.001 s, and 0 "
     "there means stop streaming: give at least 0.001 s"),
    (["velocity", "0", "0", "0", "--duration", "0.0004"],
     "--duration 0.0004 s is 0 in the VELOCITY packet, which carries it in steps of 0.001 s, "
     "and 0 there means until replaced"),
    (["move-by", "1", "0", "0", "--speed", "0.0004"],
     "--speed 0.0004 m/s is 0 in the MOVE_BY packet, which carries it in steps of 0.001 m/s, "
     "and 0 there means the default 1 m/s"),
    (["move-by", "1", "0", "0", "--speed", "-0.0004"], "--speed -0.0004 m/s is 0 in the MOVE_BY"),
    (["goto-gps", "49", "8", "1", "--speed", "0.0001"],
     "--speed 0.0001 m/s is 0 in the GOTO_GPS packet"),
    (["pad-mode", "hold", "--deadband", "0.0001"],
     "--deadband 0.0001 m is 0 in the PAD_MODE packet, which carries it in steps of 0.001 m, "
     "and 0 there means the default 0.05 m"),
    (["pad-mode", "hold", "--max-speed", "0.0001"],
     "--max-speed 0.0001 m/s is 0 in the PAD_MODE packet, which carries it in steps of "
     "0.001 m/s, and 0 there means the default 0.3 m/s"),
])
def test_link_a_value_that_would_be_sent_as_a_zero_of_another_meaning_is_refused(argv, said,
                                                                                 capsys):
    """A field whose 0 is a word of its own (STREAM's period 0 = stop, a speed's 0 = the
    default 1 m/s, VELOCITY's duration 0 = until replaced, PAD_MODE's 0 = its defaults) took a
    value typed not 0 that rounds to 0 counts as that word: ``stream 5 --period 0.0004`` was
    sent as "stop" and printed 0 frames, status 0; ``move-by --speed 0.0004`` asked for
    1 m/s. It is refused before it is sent (status 2), and the vehicle is left as it was."""
    from skeye.cli import main

    air = FakeAirframe()
    with PilotServer(air, port=0) as pilot:
        settings = pilot.boards.pad.settings
        assert main(["link", pilot.address, *argv]) == link_cli.EXIT_USAGE
        err = capsys.readouterr().err
        assert err.startswith(f"skeye link: error: {said}"), err
        assert err.count("\n") == 1, err
        assert air.calls == [] and pilot.boards.pad.settings == settings


@contextlib.contextmanager
def a_port_that_completes_no_connection() -> Iterator[int]:
    """A loopback port whose accept queue is full (listen(0), never accepted): the kernel
    drops each further SYN, so a connect to it waits, as one to a host that does not answer."""
    server = socket.socket()
    fillers: list[socket.socket] = []
    try:
        server.bind(("127.0.0.1", 0))
        server.listen(0)
        while True:  # until a connect does not complete: the queue is full
            filler = socket.socket()
            fillers.append(filler)
            filler.settimeout(1.0)
            try:
                filler.connect(server.getsockname())
            except TimeoutError:
                break
            assert len(fillers) < 64, "the accept queue never filled"
        yield server.getsockname()[1]
    finally:
        for filler in fillers:
            filler.close()
        server.close()


def test_link_timeout_bounds_the_connection_too(capsys):
    """--timeout ("seconds to wait for the connection and for the answer") did not bound the
    connection: that waited 5 s whatever was given (--timeout 0.5 said "no connection within
    5.0 s"; --timeout 30 gave up after 5). A timeout past what a socket takes (1e300 s) is no
    bound at all, not an OverflowError traceback."""
    from skeye.cli import main

    with a_port_that_completes_no_connection() as port:
        assert main(["link", "--timeout", "0.5", f"tcp://127.0.0.1:{port}", "land"]
                    ) == link_cli.EXIT_LINK
    err = capsys.readouterr().err
    assert err == f"skeye link: link error: tcp://127.0.0.1:{port}: no connection within 0.5 s\n"
    assert main(["link", "--timeout", "1e300", "tcp://127.0.0.1:1", "land"]) == link_cli.EXIT_LINK
    assert "cannot connect" in capsys.readouterr().err


def test_link_stream_prints_only_what_it_asked_for():
    """``stream`` printed (and counted) an LL_STATUS every 0.5 s that --poll-mask never asked
    for: the answers to the link's keepalive poll, sent while the command sends nothing. They
    are left out unless --poll-mask asks for LL_STATUS, as the docs' example shows."""
    air = FakeAirframe()
    with PilotServer(air, port=0) as pilot:
        # longer than two keepalive intervals (0.5 s of silence each)
        code, text = run("link", pilot.address, "stream", "1.5", "--period", "0.1")
        assert code == 0, text
        lines = text.splitlines()
        assert lines[0].startswith("Result command_pd=135 code=OK")
        assert "NavStatus state=LANDED" in text
        assert not [line for line in lines if line.startswith("LlStatus")], text
        assert lines[-1] == f"# {len(lines) - 2} frames in 1.5 s"  # what it printed
        code, text = run("link", pilot.address, "stream", "0.5", "--period", "0.1",
                         "--poll-mask", "ll_status")
        assert code == 0 and "LlStatus battery_voltage_1=12400" in text, text



class _Watched(io.StringIO):
    """Standard output that says when a NAV_STATUS frame was printed."""

    def __init__(self) -> None:
        super().__init__()
        self.frame = threading.Event()

    def write(self, text: str) -> int:
        if text.startswith("NavStatus"):
            self.frame.set()
        return super().write(text)


def test_link_stream_says_when_the_vehicle_closed_the_link(capsys):
    """A vehicle that closed the link mid-stream was reported as "link is closed" (the error
    of the STREAM sent to stop it): nothing said who closed it, nor after how much of the
    stream. It is said as the vehicle closing it, after how long and how many frames."""
    out = _Watched()
    result: list[int] = []
    with PilotServer(FakeAirframe(), port=0) as pilot:
        args = parser().parse_args(["link", pilot.address, "stream", "60", "--period", "0.05"])
        worker = threading.Thread(target=lambda: result.append(link_cli.run(args, out)))
        worker.start()
        assert out.frame.wait(30.0), out.getvalue()
    # the pilot has stopped: its connection is closed
    worker.join(30.0)
    assert not worker.is_alive()
    assert result == [link_cli.EXIT_LINK]
    err = capsys.readouterr().err
    assert re.fullmatch(r"skeye link: link error: tcp://127\.0\.0\.1:\d+: the vehicle closed the "
                        r"link after \d+\.\d of 60 s, [1-9]\d* frames\n", err), err


@pytest.mark.parametrize("line", ["silent", "garbage"])
def test_link_on_a_serial_line_where_no_pilot_answers_says_what_to_check(capsys, line):
    """A serial line on which no whole frame came was asked whether it was "a skeye pilot's
    link (skeye pilot --port)" and told that a simulator's or ground control's port speaks
    another protocol: the TCP port's advice. It now names the device and baud rate to check,
    and where unreadable bytes came, that a line at another baud rate reads so."""
    from skeye.cli import main

    with pty_null_modem() as (ours, theirs):
        stop = threading.Event()
        far = os.open(theirs, os.O_RDWR | os.O_NOCTTY)

        def babble() -> None:  # what a line at the wrong baud rate reads: no frame
            while not stop.wait(0.02):
                os.write(far, bytes(range(0, 256, 3)))

        talker = threading.Thread(target=babble)
        if line == "garbage":
            talker.start()
        try:
            status = main(["link", "--timeout", "1", f"serial://{ours}?baud=9600", "land"])
        finally:
            stop.set()
            if talker.is_alive():
                talker.join(5.0)
            os.close(far)
    err = capsys.readouterr().err
    assert status == link_cli.EXIT_LINK, err
    assert "skeye pilot --port" not in err and "simulator" not in err, err
    assert (f"is a skeye pilot on the other end of {ours} at 9600 baud (skeye pilot --serial "
            "DEVICE --baud 9600)? ") in err, err
    assert err.endswith("Unreadable bytes are what a line read at another baud rate than its "
                        "sender's gives: try the pilot's --baud\n" if line == "garbage" else
                        "Nothing at all came: check the cable and that the pilot runs\n"), err
