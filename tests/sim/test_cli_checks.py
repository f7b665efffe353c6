"""``skeye sim`` and ``skeye snapshot`` refuse bad set-ups at once, with messages that say what
to change: a robot file with a typo in ``--robot-dir``, no image server at the address."""

from __future__ import annotations

import socket
import subprocess
import sys
from importlib import resources
from pathlib import Path

import pytest

from skeye.errors import ConfigError
from skeye.sim.engine import Simulation
from skeye.sim.world import load_world
from tests.ports import free_port


def _skeye(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "skeye.cli", *argv], capture_output=True,
                          text=True, timeout=120)


def test_sim_refuses_to_start_with_a_robot_file_that_has_a_typo(tmp_path: Path) -> None:
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    (tmp_path / "good.toml").write_text(text.replace('name = "hummingbird"', 'name = "good"'))
    (tmp_path / "typo.toml").write_text(
        text.replace('name = "hummingbird"', 'name = "typo"').replace("mass_kg", "mas_kg"))
    # The message INIT {ClassName typo} would get...
    sim = Simulation(load_world("pad"), seed=1, robot_dirs=(tmp_path,))
    with pytest.raises(ConfigError) as info:
        sim.spawn("typo", sink=lambda events: None, name="T")
    assert "mas_kg" in str(info.value)
    # ... is what skeye sim says at start-up, before it listens.
    done = _skeye("sim", "--port", "0", "--robot-dir", str(tmp_path))
    assert done.returncode == 2, done
    assert str(info.value) in done.stderr
    assert "control protocol on" not in done.stdout
    done = _skeye("sim", "--port", "0", "--robot-dir", str(tmp_path / "nowhere"))
    assert done.returncode == 2 and "not a folder" in done.stderr


def test_sim_names_a_robot_file_that_is_not_utf8(tmp_path: Path) -> None:
    """A robot file saved as UTF-16 (Windows Notepad's "Unicode"): a UnicodeDecodeError
    traceback at start-up, where a TOML typo is named."""
    (tmp_path / "quad.toml").write_bytes('name = "quad"\n'.encode("utf-16"))
    done = _skeye("sim", "--port", "0", "--robot-dir", str(tmp_path))
    assert done.returncode == 2, done
    assert (f"skeye sim: error: {tmp_path / 'quad.toml'}: not valid TOML (not UTF-8 text): "
            in done.stderr) and "Traceback" not in done.stderr, done.stderr
    assert "control protocol on" not in done.stdout


@pytest.mark.parametrize("relative", [False, True])
def test_sim_names_a_folder_given_as_the_world_file(tmp_path: Path, relative: bool) -> None:
    """``--world worlds`` (the folder of one's world files, not a file in it) was "world file
    not found", or, for a bare folder name, "unknown world ... and no such file": both
    false, the folder is there. It is now named as a folder, not a world file."""
    (tmp_path / "worlds").mkdir()
    given = "worlds" if relative else str(tmp_path / "worlds")
    done = subprocess.run([sys.executable, "-m", "skeye.cli", "sim", "--port", "0", "--world",
                           given], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 2, done
    assert done.stderr == (f"skeye sim: error: {given} is a folder, not a world file (give a "
                           f".toml file, e.g. {Path(given) / 'my_world.toml'})\n"), done.stderr
    assert "control protocol on" not in done.stdout


@pytest.mark.parametrize("which", ["--port", "--image-port"])
def test_sim_on_a_taken_port_names_it_and_the_option_that_moves_it(which: str) -> None:
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        argv = ["sim", "--port", "0", "--image-port", "0", which, str(port)]
        done = _skeye(*argv)
    assert done.returncode == 2, done
    assert f"port {port} on 127.0.0.1" in done.stderr and "already in use" in done.stderr
    assert f"{which} PORT" in done.stderr
    assert "Errno" not in done.stderr and "control protocol on" not in done.stdout


def test_snapshot_without_an_image_server_names_the_address_and_the_option() -> None:
    port = free_port()  # nothing listens there
    done = _skeye("snapshot", "--images", f"127.0.0.1:{port}", "--out", "x.png")
    assert done.returncode == 2
    assert f"no image server at 127.0.0.1:{port}" in done.stderr
    assert f"--image-port {port}" in done.stderr and "--images" in done.stderr


def test_snapshot_without_an_image_server_names_an_ipv6_address_in_brackets(tmp_path) -> None:
    """'no image server at ::1:5003' named no address --images takes (the port read as part
    of the IPv6 address); it is written as --images takes it, [::1]:5003."""
    from skeye.errors import ConfigError
    from skeye.recording.snapshot import save_snapshot

    port = free_port()  # nothing listens there
    with pytest.raises(ConfigError, match=rf"^no image server at \[::1\]:{port} \("):
        save_snapshot(f"[::1]:{port}", tmp_path / "x.png", timeout_s=5.0)


def test_snapshot_of_a_host_that_does_not_resolve_says_so(tmp_path, monkeypatch) -> None:
    """A host name that does not resolve was said as "no image server at HOST:5003 (...
    cannot connect: [Errno -2] Name or service not known): start the simulator with one
    (`skeye sim --image-port 5003` ...)", as if the name were right and nothing listened."""
    from skeye.recording.snapshot import save_snapshot

    def no_such_name(*args: object, **kwargs: object) -> list[object]:
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", no_such_name)  # no DNS wait in a test
    with pytest.raises(ConfigError) as refused:
        save_snapshot("groundstation.invalid:5003", tmp_path / "x.png", timeout_s=5.0)
    said = str(refused.value)
    assert said == ("--images: tcp://groundstation.invalid:5003: cannot resolve the host "
                    "'groundstation.invalid': Name or service not known"), said


def test_snapshot_refuses_a_jpeg_quality_for_a_png_file() -> None:
    """``--quality`` is JPEG's: with a .png file it was accepted and ignored (a lossless PNG
    was written); it is refused before the image server is asked, as ``skeye sim`` refuses
    --image-quality for a format other than jpeg."""
    port = free_port()  # nothing listens: the refusal comes first
    done = _skeye("snapshot", "--images", f"127.0.0.1:{port}", "--out", "x.png",
                  "--quality", "50")
    assert done.returncode == 2, done
    assert done.stderr.startswith("skeye snapshot: error: --quality applies to a .jpg or .jpeg "
                                  "file, not x.png"), done.stderr


def test_image_format_option_sets_what_a_new_image_client_gets() -> None:
    """``skeye sim --image-format jpeg --image-quality 60``: a client that asks for a frame
    without SKEYE FORMAT gets JPEG of that quality's UPIS type (as USARSim's operator-chosen
    default); a later SKEYE FORMAT still changes it."""
    import time

    from skeye.processes import start_skeye, stop_process
    from skeye.wire.images import DecodedFrame, FrameDecoder, FrameType, jpeg_type_for_quality

    sim, found = start_skeye(
        ["sim", "--port", "0", "--image-port", "0", "--image-format", "jpeg",
         "--image-quality", "60"],
        [r"control protocol on [\d.]+:(\d+)", r"image server on [\d.]+:(\d+) .*frames JPEG 60"],
        "skeye sim")
    try:
        control = socket.create_connection(("127.0.0.1", int(found[0].group(1))), timeout=60)
        control.sendall(b"INIT {ClassName hummingbird} {Name R1} {Start Pad1}\r\n")
        images = socket.create_connection(("127.0.0.1", int(found[1].group(1))), timeout=60)

        def frame(request: bytes) -> DecodedFrame:
            decoder = FrameDecoder()
            deadline = time.monotonic() + 120  # the first render on a busy host
            while True:
                images.sendall(request)
                events: list[object] = []
                while not events:
                    data = images.recv(65536)
                    assert data, "the image server closed the connection"
                    events = decoder.feed(data)
                if isinstance(events[0], DecodedFrame):
                    return events[0]
                assert time.monotonic() < deadline, events  # "no frame available" so far
                request = b"OK"

        first = frame(b"OK")
        assert first.frame_type == jpeg_type_for_quality(60) == FrameType.JPEG_NORMAL
        assert first.data[:2] == b"\xff\xd8"
        raw = frame(b"SKEYE FORMAT RAW\nOK")
        assert raw.frame_type == FrameType.RAW
        control.close()
        images.close()
    finally:
        stop_process(sim)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--image-port", "0", "--image-quality", "50"], "--image-format jpeg only"),
        (["--image-port", "0", "--image-format", "jpeg", "--image-quality", "0"], "1-100"),
        (["--image-format", "png"], "need --image-port"),
        (["--timestep", "1e9"], "--timestep must be in [1e-05, 0.01] s (the physics step), "
                                "got 1e+09"),
        (["--wind", "dryden", "--wind-params", "gust=3"],
         "unknown parameter 'gust' for mode 'dryden'; known: from_deg, height_m, w20_m_s\n"),
    ],
)
def test_bad_options_are_refused_before_anything_starts(argv: list[str], message: str) -> None:
    done = _skeye("sim", "--port", "0", *argv)
    assert done.returncode == 2 and message in done.stderr, done
    assert "control protocol on" not in done.stdout


def test_estimator_option_reaches_the_simulator() -> None:
    """``skeye sim --estimator truth`` says so at start-up and flies a robot; a kind that does
    not exist is refused before anything listens."""
    from skeye.processes import start_skeye, stop_process

    sim, found = start_skeye(
        ["sim", "--port", "0", "--mode", "lockstep", "--estimator", "truth"],
        [r"estimator truth; control protocol on [\d.]+:(\d+)"], "skeye sim")
    try:
        with socket.create_connection(("127.0.0.1", int(found[0].group(1))), timeout=60) as c:
            c.sendall(b"INIT {ClassName hummingbird} {Name R1} {Location 0,0,-1}\r\n")
            reply = b""
            while b"INIT" not in reply and b"ERR" not in reply:
                data = c.recv(65536)
                assert data, "the simulator closed the connection"
                reply += data
            assert b"ERR" not in reply and b"RES" in reply, reply
    finally:
        stop_process(sim)
    done = _skeye("sim", "--port", "0", "--estimator", "oracle")
    assert done.returncode == 2 and "--estimator" in done.stderr


@pytest.mark.parametrize(("extra", "message"), [
    (["--record-rotate"], "--record-rotate needs --record FILE"),
    (["--record-max-mb", "5", "--record-parts", "3"],
     "--record-max-mb, --record-parts need --record FILE"),
    (["--record", "x.rec", "--record-parts", "3"], "--record-parts counts --record-rotate's"),
], ids=["rotate alone", "size and parts alone", "parts without rotate"])
def test_sim_refuses_recording_options_that_would_do_nothing(extra: list[str], message: str,
                                                             tmp_path: Path) -> None:
    """The --record-* options shape the --record file: without it (or --record-parts without
    --record-rotate) the simulator started and recorded nothing, as if asked to."""
    proc = subprocess.Popen([sys.executable, "-m", "skeye.cli", "sim", "--port", "0", *extra],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()  # the start-up line, or nothing when it refuses
        assert "control protocol on" not in first, f"it started: {first}"
        assert proc.wait(60) == 2
        err = proc.stderr.read() if proc.stderr else ""
        assert err.startswith(f"skeye sim: error: {message}"), err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()
    assert not (tmp_path / "x.rec").exists()


@pytest.mark.parametrize("where", ["missing", "file"])
def test_snapshot_names_an_output_folder_it_cannot_write_to_before_asking_the_server(
        tmp_path: Path, where: str) -> None:
    """``--out`` in a folder that does not exist (or under a file): the frame was fetched
    first, then ``could not write FILE`` said nothing of why (OpenCV's imwrite returns False
    without a reason). The folder is now looked at before the image server is asked, and named."""
    if where == "file":
        (tmp_path / "notes.txt").write_text("x")
        out = tmp_path / "notes.txt" / "frame.png"
        why = f"{tmp_path / 'notes.txt'} is not a folder"
    else:
        out = tmp_path / "frames" / "frame.png"
        why = f"no folder {tmp_path / 'frames'} to write it in"
    port = free_port()  # nothing listens: the refusal comes first
    done = _skeye("snapshot", "--images", f"127.0.0.1:{port}", "--out", str(out))
    assert done.returncode == 2, done
    assert done.stderr == f"skeye snapshot: error: --out {out}: {why}\n", done.stderr


def test_sim_check_says_what_is_wrong_with_a_world_or_robot_file_and_starts_nothing(
        tmp_path: Path) -> None:
    """``skeye sim --check``: the world and the robot files loaded and checked as at the
    simulator's start, and nothing started (``skeye up`` asks it before it starts anything)."""
    done = _skeye("sim", "--check", "--world", "yard")
    assert done.returncode == 0 and done.stdout == "" and done.stderr == "", done
    world = tmp_path / "mine.toml"
    world.write_text("[ground]\nsize_m = [40, 40]\n[[pads]]\nposition_ned_m = [0, 0, 1e9]\n")
    done = _skeye("sim", "--check", "--world", str(world))
    assert done.returncode == 2 and str(world) in done.stderr, done
    assert "control protocol on" not in done.stdout
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    robots = tmp_path / "robots"
    robots.mkdir()
    (robots / "typo.toml").write_text(
        text.replace('name = "hummingbird"', 'name = "typo"').replace("mass_kg", "mas_kg"))
    done = _skeye("sim", "--check", "--robot-dir", str(robots))
    assert done.returncode == 2 and "mas_kg" in done.stderr, done


@pytest.mark.parametrize("robots", [False, True])
def test_sim_check_refuses_a_timestep_the_simulator_refuses(tmp_path: Path, robots: bool) -> None:
    """``skeye sim --check --timestep 0.5`` said nothing (status 0) where ``skeye sim`` refuses
    it; with a robot folder, --timestep 1e9 was blamed on the robot file ("board_rate_hz 250.0:
    the board rate is not an integer fraction of the physics rate 1e-09 Hz")."""
    argv = ["sim", "--check", "--timestep", "1e9" if robots else "0.5"]
    if robots:
        text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
        (tmp_path / "mine.toml").write_text(text.replace('name = "hummingbird"', 'name = "mine"'))
        argv += ["--robot-dir", str(tmp_path)]
    done = _skeye(*argv)
    assert done.returncode == 2, done
    assert "--timestep must be in [1e-05, 0.01] s (the physics step)" in done.stderr, done
    assert "mine.toml" not in done.stderr
