"""Every script in examples/ runs to completion against a real lockstep simulator."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.control.conftest import sim_running
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
NEEDS_IMAGES = {"camera.py", "capture_checkerboard.py", "record_camera.py"}
WORLDS = {"capture_checkerboard.py": "checkerboard"}


def test_there_are_examples() -> None:
    names = {p.name for p in EXAMPLES}
    assert {"takeoff_land.py", "square.py", "gps_tour.py", "camera.py"} <= names


def test_takeoff_and_landing_is_under_ten_lines() -> None:
    text = (ROOT / "examples/takeoff_land.py").read_text()
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) < 10, lines


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.name)
def test_example_runs(script: Path, tmp_path: Path) -> None:
    with sim_running(images=script.name in NEEDS_IMAGES,
                     world=WORLDS.get(script.name, "pad")) as handle:
        env = dict(os.environ, SKEYE_SIM=handle.address, PYTHONPATH=str(ROOT),
                   SKEYE_CAMERA_OUT=str(tmp_path / "camera.png"), SKEYE_BOARD_DIR=str(tmp_path))
        if handle.images is not None:
            env["SKEYE_IMAGES"] = handle.images
        done = subprocess.run(
            [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True,
            text=True, timeout=120,
        )
    assert done.returncode == 0, f"{script.name} failed:\n{done.stdout}\n{done.stderr}"
    if script.name == "camera.py":
        assert (tmp_path / "camera.png").stat().st_size > 1000
        assert "(600, 800, 3)" in done.stdout
    if script.name == "record_camera.py":  # the pilot's file:// camera plays it
        from skeye.pilot.camera import open_camera

        # Every frame in a row at the camera's 30 Hz: it passed over about one in three (two
        # frames in one of the control clock's 50 ms steps) and wrote about 20 fps.
        assert "40 frames of 800x600 at " in done.stdout, done.stdout
        fps = float(done.stdout.split("800x600 at ")[1].split()[0])
        assert fps == pytest.approx(30.0, abs=0.1) and "passed over" not in done.stdout, (
            done.stdout)
        uri = done.stdout.split("--camera '")[1].split("'")[0]
        source = open_camera(uri.replace("file://", f"file://{tmp_path}/"))
        try:
            assert source.fov_h_rad is not None and source.latest is not None
            assert source.image().bgr.shape == (600, 800, 3)
        finally:
            source.close()
    if script.name == "capture_checkerboard.py":  # the frames calibrate the default camera
        from skeye.cli import main
        from skeye.robots.config import camera_model
        from skeye.vision.calibration import load_calibration

        boards = sorted(str(p) for p in tmp_path.glob("board*.png"))
        assert len(boards) == 14, done.stdout
        assert main(["calibrate", *boards, "--out", str(tmp_path / "camera.toml")]) == 0
        cal = load_calibration(tmp_path / "camera.toml")
        lens = camera_model("hummingbird")  # the webcam's
        assert abs(cal.fx / lens.fx_px - 1) < 0.01 and abs(cal.dist[0] - lens.k1) < 0.02, cal


def test_the_training_example_says_what_it_needs() -> None:
    """examples/gym/train_hover_sb3.py: ``--help`` works without Stable-Baselines3 (not a
    skeye dependency; it ended in a traceback), and a run without it names what to install."""
    import importlib.util

    script = ROOT / "examples" / "gym" / "train_hover_sb3.py"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(script), "--help"], env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "--steps" in done.stdout, done.stderr
    if importlib.util.find_spec("stable_baselines3") is None:
        done = subprocess.run([sys.executable, str(script), "--steps", "1"], env=env,
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 1 and "Traceback" not in done.stderr
        assert "needs Stable-Baselines3" in done.stderr, done.stderr


@pytest.mark.parametrize("script, args", [
    ("pad_landing_scripted.py", ["--episodes", "0"]),
    ("pad_landing_scripted.py", ["--episodes", "-1"]),
    ("train_hover_sb3.py", ["--episodes", "0"]),
    ("train_hover_sb3.py", ["--envs", "0"]),
    ("train_hover_sb3.py", ["--steps", "-5"]),
])
def test_the_gym_examples_refuse_a_count_below_one_naming_it(script: str, args: list) -> None:
    """``pad_landing_scripted.py --episodes 0`` flew nothing and ended in a ZeroDivisionError
    traceback (the landing rate of no episodes); the training script divided by zero too, after
    its training. Each count is now refused by its option, before anything is flown."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "examples" / "gym" / script), *args],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {args[0]}" in done.stderr and ">= 1" in done.stderr, done.stderr


def test_the_landing_example_refuses_a_negative_seed_naming_it() -> None:
    """``pad_landing_scripted.py --seed -1`` was taken and ended in a traceback from inside
    Gymnasium's reset ("Seed must be greater or equal to zero"); it is now refused by its
    option, before anything is flown."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(ROOT / "examples" / "gym" /
                                               "pad_landing_scripted.py"), "--seed", "-1"],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert "argument --seed" in done.stderr and "non-negative" in done.stderr, done.stderr


@pytest.mark.parametrize("script", [p for p in EXAMPLES if p.name != "takeoff_land.py"],
                         ids=lambda p: p.name)
def test_an_example_without_a_simulator_says_so_in_one_line(script: Path,
                                                            tmp_path: Path) -> None:
    """With nothing listening at $SKEYE_SIM, each example ended in a traceback of skeye's
    internals (LinkClosed from Connection.__init__); it now exits with status 1 and one line
    naming the script and the address. takeoff_land.py stays the under-ten-lines example."""
    port = free_port()
    env = dict(os.environ, SKEYE_SIM=f"127.0.0.1:{port}", SKEYE_IMAGES=f"127.0.0.1:{port}",
               PYTHONPATH=str(ROOT), SKEYE_BOARD_DIR=str(tmp_path))
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.startswith(f"{script.stem}: cannot connect to the simulator at "
                                  f"127.0.0.1:{port}: "), done.stderr
    assert list(tmp_path.iterdir()) == [], "it wrote files though it flew nothing"


@pytest.mark.parametrize("name", ["missing/camera.png", "camera.txt"])
def test_the_camera_example_says_when_it_cannot_save_the_frame(name: str,
                                                               tmp_path: Path) -> None:
    """examples/camera.py into a folder that does not exist printed 'saved missing/camera.png'
    and exited 0 (OpenCV's imwrite returns False, never raises, for that), and a name without
    an image format's ending ended in a cv2.error traceback; each now exits 1 naming the file."""
    with sim_running(images=True) as handle:
        env = dict(os.environ, SKEYE_SIM=handle.address, SKEYE_IMAGES=str(handle.images),
                   PYTHONPATH=str(ROOT), SKEYE_CAMERA_OUT=str(tmp_path / name))
        done = subprocess.run([sys.executable, str(ROOT / "examples" / "camera.py")],
                              cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert f"camera: could not write {tmp_path / name}" in done.stderr, done.stderr
    assert "saved" not in done.stdout, done.stdout


@pytest.mark.parametrize("name", ["missing/flight.mkv", "flight.txt"])
def test_the_recording_example_refuses_a_file_it_cannot_write_before_it_flies(
        name: str, tmp_path: Path) -> None:
    """examples/record_camera.py flew and recorded its 40 frames, then said only 'this OpenCV
    cannot write FFV1 video to missing/flight.mkv' (of a folder that does not exist) and lost
    the recording (a .txt: the same); the name is now checked first, and nothing is flown (nor
    connected to: here nothing listens) when it cannot be written."""
    port = free_port()
    env = dict(os.environ, SKEYE_SIM=f"127.0.0.1:{port}", SKEYE_IMAGES=f"127.0.0.1:{port}",
               PYTHONPATH=str(ROOT), SKEYE_VIDEO_OUT=str(tmp_path / name))
    done = subprocess.run([sys.executable, str(ROOT / "examples" / "record_camera.py")],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.startswith(f"record_camera: cannot write FFV1 video to {tmp_path / name}"
                                  " ("), done.stderr  # OpenCV's own warnings first, no more
    assert list(tmp_path.iterdir()) == []


def test_the_board_example_names_a_folder_it_cannot_make(tmp_path: Path) -> None:
    """SKEYE_BOARD_DIR naming a file (or a path through one) ended capture_checkerboard.py in a
    FileExistsError (NotADirectoryError) traceback; it now says so in one line, before any
    simulator is asked."""
    (tmp_path / "a_file").write_text("")
    for board_dir in (tmp_path / "a_file", tmp_path / "a_file" / "frames"):
        env = dict(os.environ, SKEYE_SIM=f"127.0.0.1:{free_port()}", PYTHONPATH=str(ROOT),
                   SKEYE_BOARD_DIR=str(board_dir))
        done = subprocess.run([sys.executable, str(ROOT / "examples" /
                                                   "capture_checkerboard.py")],
                              cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
        assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
        assert done.stderr.startswith(f"capture_checkerboard: no folder {board_dir} to write "
                                      "the frames in: "), done.stderr


def test_the_gps_tour_without_gps_says_so_in_one_line(tmp_path: Path) -> None:
    """examples/gps_tour.py in the indoor world (no GPS) ended in 'AssertionError: no GPS fix'
    with a traceback (and under ``python -O`` the assert is gone: a TypeError formatting None);
    it now lands and exits 1 saying the world has no GPS."""
    with sim_running(world="indoor") as handle:
        env = dict(os.environ, SKEYE_SIM=handle.address, PYTHONPATH=str(ROOT))
        done = subprocess.run([sys.executable, str(ROOT / "examples" / "gps_tour.py")],
                              cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.startswith("gps_tour: no GPS fix ("), done.stderr
    assert "this world has no GPS" in done.stderr, done.stderr


def test_the_landing_example_keeps_the_episodes_flown_when_interrupted() -> None:
    """``pad_landing_scripted.py`` printed nothing until every episode had flown (20 take some
    minutes), and a Ctrl-C threw them all away in a KeyboardInterrupt traceback; each
    episode's line now comes as it ends, and a Ctrl-C prints the tally of those flown."""
    import select
    import signal
    import time

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, str(ROOT / "examples" / "gym" / "pad_landing_scripted.py"),
         "--episodes", "20", "--seed", "100"], env=env, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # as a terminal's
    try:
        assert proc.stdout is not None
        deadline = time.monotonic() + 300
        while not select.select([proc.stdout], [], [], 1.0)[0]:
            assert time.monotonic() < deadline and proc.poll() is None, "no episode ended"
        first = proc.stdout.readline()
        assert first.startswith("seed 100: "), first
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130 and "Traceback" not in err, err
    flown = 1 + sum(line.startswith("seed ") for line in out.splitlines())
    assert f"interrupted after {flown} of 20 episodes" in out, out
    assert f" of {flown} episodes (" in out, out  # the tally of those flown
