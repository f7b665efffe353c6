"""``skeye calibrate`` end to end: the checkerboard world in the real simulator, frames fetched
from its image server at several poses, a known lens distortion, and the command's answer.

Here the simulator renders ideal pinhole frames and the known distortion is applied by OpenCV
(:func:`tests.vision.helpers.distort_image`) from a wider camera of the same focal length, so
the distorted 800x600 frame has content out to its corners: three lenses, k1 from -0.2 to
+0.1. The simulator's own lens (the webcam profile, rendered through ``skeye/sim/lens.py``) is
calibrated end to end in ``tests/validate/test_validate.py``
(``test_webcam_validation_calibrates_first_and_shows_the_uncalibrated_bias``).
"""

from __future__ import annotations

import math
import tomllib
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
import pytest

from skeye.cli import main
from skeye.control.image_client import ImageClient
from skeye.pixels import frame_image
from skeye.sim import frames
from skeye.sim.cameras import CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.image_server import FrameBuffer, ImageServer
from skeye.sim.runner import SimulationRunner
from skeye.sim.server import ControlServer
from skeye.sim.world import PAD_SURFACE_HEIGHT_M, load_world
from skeye.vision import calibration
from skeye.vision.calibration import Board, find_corners, load_calibration
from skeye.vision.camera import intrinsics
from tests.robustness.helpers import skeye_under_a_file_size_limit, wait_for
from tests.sim.conftest import LineClient
from tests.vision.helpers import FOV_H_RAD, H, W, board_views, distort_image, wide_camera

ROBOTS = Path(__file__).parents[2] / "skeye/robots"
CAMERA_FRD = np.array([0.0, 0.0, 0.035])
K = intrinsics(W, H, FOV_H_RAD)
K_WIDE, W_WIDE, H_WIDE, FOV_WIDE = wide_camera(K, W, H, 1.5)
LEAVE_TIMEOUT_S = 60.0
"""How long a closed connection's robot may take to leave the world (a loaded machine)."""


def _poses() -> list[tuple[float, float, float, float, float, float]]:
    """(camera height, north, east, roll, pitch, yaw): the board in the centre, the corners and
    the edges of the image, and tilted views (OpenCV's advice for pinning down distortion)."""
    f = float(K[0, 0])
    h = 0.42
    out = []
    for u, v, yaw in ((400, 300, 0.0), (250, 180, 0.3), (550, 180, -0.3), (250, 420, -0.3),
                      (550, 420, 0.3), (400, 170, 1.57), (400, 430, 1.57), (230, 300, 0.0),
                      (570, 300, 0.0)):
        # A level camera at (north, east) sees the board's centre at (u, v).
        out.append((h, (v - (H - 1) / 2) * h / f, -(u - (W - 1) / 2) * h / f, 0.0, 0.0, yaw))
    for roll, pitch in ((0.3, 0.0), (-0.3, 0.0), (0.25, 0.25), (-0.25, -0.25), (0.2, -0.2)):
        out.append((0.45, 0.0, 0.0, roll, pitch, 0.5))
    return out


def wide_robot(tmp_path: Path) -> Path:
    """A hummingbird whose Down camera has the reference focal length over 1.5x the image."""
    text = (ROBOTS / "hummingbird.toml").read_text()
    text = text.replace('name = "hummingbird"', 'name = "widecam"', 1)
    old = f"width = {W}\nheight = {H}\nfov_h_rad = {FOV_H_RAD}"
    assert old in text
    text = text.replace(old, f"width = {W_WIDE}\nheight = {H_WIDE}\nfov_h_rad = {FOV_WIDE!r}")
    text = text.replace('profile = "webcam"', 'profile = "ideal"')  # the pinhole, distorted here
    (tmp_path / "widecam.toml").write_text(text)
    return tmp_path


@contextmanager
def checkerboard_sim(robot_dir: Path) -> Iterator[tuple[Simulation, int, int]]:
    """The checkerboard world in lockstep, with its image server: (simulation, control port,
    image port)."""
    sim = Simulation(load_world("checkerboard"), seed=1, robot_dirs=(robot_dir,),
                     offscreen_size=(W_WIDE, H_WIDE))
    buffer = FrameBuffer()
    with (
        SimulationRunner(sim, mode="lockstep") as runner,
        CameraSystem(sim, buffer, synchronous=True),
        ControlServer(runner, port=0) as control,
        ImageServer(buffer, port=0) as images,
    ):
        yield sim, control.port, images.port


def fetch_frame(sim: Simulation, control_port: int, image_port: int, name: str,
                pose: tuple[float, float, float, float, float, float]) -> np.ndarray:
    """Spawn a wide-camera robot with its camera at the pose, step once, fetch its frame, and
    wait until the robot has left the world.

    The robot leaves when the server sees its connection close, on the server's thread. The
    tilted poses share one place, so a robot still there would stand in the next one's view (on
    a loaded machine it did: one frame showed the previous robot's body and the calibration
    read fx 4272 px for 521).
    """
    height, north, east, roll, pitch, yaw = pose
    rot = frames.quat_to_matrix(frames.euler_to_quat(roll, pitch, yaw))
    off = rot @ CAMERA_FRD
    body = [float(v) for v in
            (north - off[0], east - off[1], -PAD_SURFACE_HEIGHT_M - height - off[2])]
    c = LineClient(control_port)
    try:
        c.expect("NFO")
        answer = c.answer(
            f"INIT {{ClassName widecam}} {{Name {name}}} "
            f"{{Location {body[0]!r},{body[1]!r},{body[2]!r}}} {{Rotation {roll},{pitch},{yaw}}}",
            "INIT")
        assert answer.type == "RES", answer
        c.step(1)  # frame 1 is rendered from the state at the first step
        with ImageClient("127.0.0.1", image_port) as img:
            img.select_camera(f"{name}/Down")
            img.set_format("png")
            bgr = frame_image(img.get_frame())
    finally:
        c.close()  # the robot leaves the world with its connection
    assert wait_for(lambda: name not in sim.robots, LEAVE_TIMEOUT_S), \
        f"{name} still in the world {LEAVE_TIMEOUT_S} s on"
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)


@pytest.fixture(scope="module")
def ideal_frames(tmp_path_factory: pytest.TempPathFactory) -> list[np.ndarray]:
    robot_dir = wide_robot(tmp_path_factory.mktemp("robots"))
    with checkerboard_sim(robot_dir) as (sim, control_port, image_port):
        return [fetch_frame(sim, control_port, image_port, f"C{i}", pose)
                for i, pose in enumerate(_poses())]


def _write(tmp_path: Path, grey_frames: list[np.ndarray]) -> list[str]:
    names = []
    for i, grey in enumerate(grey_frames):
        name = str(tmp_path / f"board{i:02d}.png")
        assert cv2.imwrite(name, grey)
        names.append(name)
    return names


@pytest.mark.parametrize("k1", [-0.2, 0.1])
def test_calibrate_recovers_the_lens(ideal_frames: list[np.ndarray], tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str], k1: float) -> None:
    dist = (k1, 0.0, 0.0, 0.0, 0.0)
    shots = [distort_image(g, K_WIDE, K, dist, (W, H)) for g in ideal_frames]
    out = tmp_path / "camera.toml"
    status = main(["calibrate", *_write(tmp_path, shots), "--board", "9x6", "--square-mm", "25",
                   "--out", str(out)])
    assert status == 0, capsys.readouterr().err
    cal = load_calibration(out)
    f = float(K[0, 0])
    assert abs(cal.fx - f) / f <= 0.01, (cal.fx, f)
    assert abs(cal.fy - f) / f <= 0.01, (cal.fy, f)
    assert abs(cal.dist[0] - k1) <= 0.02, cal.dist
    assert (cal.width_px, cal.height_px) == (W, H)
    assert cal.rms_px is not None and cal.rms_px < 0.5
    assert cal.images is not None and cal.images >= 10
    assert cal.board is not None and cal.board.label == "9x6"
    assert math.isclose(cal.board.square_m, 0.025)
    # The file is plain TOML with the documented keys.
    data = tomllib.loads(out.read_text())
    assert set(data["camera"]) == {"width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px",
                                   "k1", "k2", "p1", "p2", "k3"}
    assert "rms_reprojection_px" in data["calibration"]


def test_calibrate_refuses_bad_input(ideal_frames: list[np.ndarray], tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    names = _write(tmp_path, ideal_frames[:4])
    out = str(tmp_path / "camera.toml")
    run: Callable[..., int] = lambda *a: main(["calibrate", *a, "--out", out])  # noqa: E731
    assert run(*names, "--board", "9by6") == 2
    assert "COLSxROWS" in capsys.readouterr().err
    assert run(*names, "--board", "9x6", "--square-mm", "-3") == 2
    assert "--square-mm" in capsys.readouterr().err
    assert run(str(tmp_path / "missing.png"), "--board", "9x6") == 2
    assert "no such image" in capsys.readouterr().err
    # The wrong corner count finds no board anywhere.
    assert run(*names, "--board", "8x6") == 2
    assert "found in 0 of 4" in capsys.readouterr().err
    (tmp_path / "notes.txt").write_text("not an image")
    assert run(str(tmp_path / "notes.txt"), "--board", "9x6") == 2
    assert "cannot read image" in capsys.readouterr().err
    assert not Path(out).exists()


def test_calibrate_refuses_a_truncated_image_naming_it(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A JPEG cut short decoded (libjpeg only warned, painting the rest grey) and was searched
    for the board as a whole frame; it is refused, naming the file, and nothing is written."""
    rng = np.random.default_rng(3)
    whole = cv2.imencode(".jpg", rng.integers(0, 256, (120, 160), dtype=np.uint8))[1].tobytes()
    good, cut = tmp_path / "good.jpg", tmp_path / "cut.jpg"
    good.write_bytes(whole + b"\xff" * 16)  # padded after its end: whole
    cut.write_bytes(whole[: len(whole) * 6 // 10])
    out = tmp_path / "camera.toml"
    assert main(["calibrate", str(good), str(cut), "--out", str(out)]) == 2
    assert capsys.readouterr().err == (
        f"skeye calibrate: error: image {cut} is truncated or corrupt: the JPEG data ends "
        "before its end-of-image marker (FF D9)\n")
    assert not out.exists()


def test_calibrate_does_not_write_a_lens_the_loader_refuses(
        ideal_frames: list[np.ndarray], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Level views alone pin nothing down (OpenCV cannot tell the focal length from the
    distance without tilted ones): the first six ideal frames, all level, fit with fx about
    4e5 px and k1 about 160, reprojecting to 0.04 px (measured 2026-11-26; five to nine level
    frames give k1 or k2 from -43 to 5e5). Such a fit used to be written, and the pilot then
    found nothing with it; it is now refused naming the key, and no file is written."""
    out = tmp_path / "camera.toml"
    status = main(["calibrate", *_write(tmp_path, ideal_frames[:6]), "--board", "9x6",
                   "--square-mm", "25", "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2 and "a distortion coefficient must be within -10..10" in err, err
    assert "not written" in err and not out.exists()


def test_calibrate_bounds_the_square_size_with_one_line(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """``--square-mm 1e308`` overflowed the board's float32 points (numpy's RuntimeWarning)
    and OpenCV's calibrateCamera then failed an assertion, a traceback; 1e-300 underflowed
    the same way. A square is now 0.001..10000 mm (1 um, what light can image, to 10 m):
    outside, one line and status 2, nothing written. The intrinsics do not depend on the
    square size, so both bounds calibrate exactly as 25 mm does."""
    names = _write(tmp_path, board_views(640, 480, 576.0))
    out = tmp_path / "camera.toml"
    # inf (1e400 too) and nan were "must be positive, got inf": inf is positive
    for given in ("1e308", "1e-300", "0.0009", "10001", "inf", "1e400", "nan", "0", "-3"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no numpy overflow warning either
            status = main(["calibrate", *names, "--square-mm", given, "--out", str(out)])
        err = capsys.readouterr().err
        assert status == 2 and err == (
            "skeye calibrate: error: --square-mm must be 0.001..10000 (a square from 1 um, "
            f"what light can image, to 10 m), got {float(given):g}\n"), err
        assert not out.exists()
    fitted = []
    for given in ("25", "0.001", "10000"):
        assert main(["calibrate", *names, "--square-mm", given, "--out", str(out)]) == 0
        capsys.readouterr()
        cal = load_calibration(out)
        assert cal.board is not None and math.isclose(cal.board.square_m, float(given) / 1e3)
        fitted.append((cal.fx, cal.fy, cal.cx, cal.cy))
    # the same fit, up to calibrateCamera's own convergence (float32 points, 1e-6 px apart)
    assert np.allclose(fitted[1], fitted[0], rtol=0, atol=1e-3), fitted
    assert np.allclose(fitted[2], fitted[0], rtol=0, atol=1e-3), fitted
    assert abs(fitted[0][0] - 576.0) < 576.0 * 0.01, fitted  # and right: f to 1 %


def test_calibrate_searches_a_large_image_on_a_reduced_copy(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 7559x5669 image was searched at full size, with no progress said: OpenCV's corner
    finders take time in proportion to the pixels where the board is not found at once (85 s
    for one such image without a board, measured 2026-11-27). Now an image over
    DETECT_MAX_PX a side is searched on a copy of at most that size and the corners are
    refined on the image itself, with a line for each image said as it is done. The corners
    are those of a full-size search: both end at the same cornerSubPix fixed point (its steps
    stop under 1e-4 px; 0.0005 px apart measured), so 0.01 px, far under the 0.04-0.09 px RMS
    of the calibrations in docs/calibration.md."""
    w, h = 7559, 5669
    f = 0.9 * w
    views = board_views(w, h, f, count=3)
    board = Board(9, 6, 0.025)
    for grey in views:
        reduced = find_corners(grey, board)
        full = calibration._find_corners(grey, board)  # the full-size search, as before
        assert reduced is not None and full is not None
        assert reduced.shape == full.shape
        assert np.abs(reduced.reshape(-1, 2) - full.reshape(-1, 2)).max() < 0.01
    names = _write(tmp_path, views)
    out = tmp_path / "camera.toml"
    assert main(["calibrate", *names, "--board", "9x6", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    for i, name in enumerate(names, 1):
        assert (f"skeye calibrate: image {i} of 3, {name} (7559x5669, searched at 2048x1536): "
                "board found in ") in err, err
    cal = load_calibration(out)
    assert (cal.width_px, cal.height_px) == (w, h)
    assert abs(cal.fx - f) / f <= 0.01, (cal.fx, f)  # as test_calibrate_recovers_the_lens


def test_calibrate_refuses_an_out_it_cannot_write_before_searching(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--out`` in a missing folder, or naming a folder, was found out only after every image
    had been searched and calibrated (minutes for a camera's full-size photos): here, with
    frames in which no board is found, the answer was "found in 0 of 3 images" and the --out
    that could never be written went unsaid. It is now refused first, naming --out."""
    names = _write(tmp_path, [np.full((480, 640), 128, np.uint8)] * 3)
    (tmp_path / "folder.toml").mkdir()
    for out, problem in ((tmp_path / "missing" / "camera.toml",
                          f"no folder {tmp_path / 'missing'} to write it in"),
                         (tmp_path / "folder.toml", "is a directory: give a file name"),
                         (Path(names[0]) / "camera.toml", f"{names[0]} is not a folder")):
        assert main(["calibrate", *names, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"skeye calibrate: error: --out {out}") and problem in err, err
        assert err.count("\n") == 1, err


def test_a_failed_write_keeps_the_camera_toml_that_was_there(tmp_path: Path) -> None:
    """camera.toml was written in place: a write that failed part-way (a full disk; here the
    process's file size limit, ``ulimit -f``, which fails a write past it with EFBIG as a full
    disk does) truncated the good calibration already there and left 200 bytes of the new one,
    a file the pilot then refused. It is now written beside and renamed over: the old file is
    left as it was, and no partial file stays behind."""
    names = _write(tmp_path, board_views(640, 480, 576.0))
    out = tmp_path / "camera.toml"
    assert main(["calibrate", *names, "--square-mm", "25", "--out", str(out)]) == 0
    before = out.read_bytes()
    limit = 200
    assert len(before) > limit
    run = skeye_under_a_file_size_limit(
        ["calibrate", *names, "--square-mm", "24", "--out", str(out)], limit)
    assert run.returncode == 2, run.stderr
    assert run.stderr == f"skeye calibrate: error: cannot write {out}: File too large\n"
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [*(Path(n).name for n in names), "camera.toml"])


def test_calibrate_refuses_mixed_sizes_before_searching(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Images of another size than the first were found out only when the search reached them:
    every image before was searched first (a line on stderr each for a camera's large photos,
    2-3 s each for 2200x1600 here). The sizes are now compared before any search."""
    first, other = tmp_path / "first.png", tmp_path / "other.png"
    assert cv2.imwrite(str(first), np.full((1600, 2200), 128, np.uint8))
    assert cv2.imwrite(str(other), np.full((1600, 2100), 128, np.uint8))
    out = tmp_path / "camera.toml"
    assert main(["calibrate", str(first), str(other), "--out", str(out)]) == 2
    assert capsys.readouterr().err == (
        f"skeye calibrate: error: {other} is 2100x1600, the first image 2200x1600: all images "
        "must come from one camera at one resolution\n")
    assert not out.exists()


def test_too_few_boards_names_the_frames_without_one(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """With the board found in some frames but fewer than 3, the refusal named none of the
    frames it was not found in (docs/calibration.md: the images without a complete board are
    named) and asked whether --board counted the inner corners, which finding it had shown
    right. Those frames are now named (five, then a count), and the advice is about frames."""
    views = _write(tmp_path, board_views(640, 480, 576.0, count=2))
    blank = []
    for i in range(7):
        blank.append(str(tmp_path / f"blank{i}.png"))
        assert cv2.imwrite(blank[-1], np.full((480, 640), 128, np.uint8))
    out = tmp_path / "camera.toml"
    assert main(["calibrate", *views, "--out", str(out)]) == 2
    assert capsys.readouterr().err == (
        "skeye calibrate: error: the 9x6 board was found in 2 of 2 images; at least 3 are "
        "needed: take more frames, each with the whole board in view, sharp and without glare\n")
    assert main(["calibrate", views[0], *blank, "--out", str(out)]) == 2
    assert capsys.readouterr().err == (
        f"skeye calibrate: error: the 9x6 board was found in 1 of 8 images (not in "
        f"{', '.join(blank[:5])} and 2 more); at least 3 are needed: take more frames, each with "
        "the whole board in view, sharp and without glare\n")
    assert main(["calibrate", *blank[:3], "--out", str(out)]) == 2  # in none: the corner count
    assert capsys.readouterr().err == (
        "skeye calibrate: error: the 9x6 board was found in 0 of 3 images; at least 3 are "
        "needed (is --board the count of INNER corners, COLSxROWS?)\n")
    assert not out.exists()


def test_a_view_given_twice_counts_once(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """One view given three times (a name repeated) was calibrated as three: fx 2.0e10 px and
    fy 1.3e10 px, a field of view of 3e-8 rad, at 0.000 px RMS, written with exit status 0.
    An image with the board identical, pixel for pixel, to an earlier one is now skipped,
    saying which it repeats, and the views are counted once."""
    names = _write(tmp_path, board_views(640, 480, 576.0, count=3))
    out = tmp_path / "camera.toml"
    assert main(["calibrate", names[0], names[0], names[0], "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (
        "skeye calibrate: error: the 9x6 board was found in 1 of 3 images (and 2 more the same "
        "as one of those, pixel for pixel, not used); at least 3 are needed: take more frames, "
        "each with the whole board in view, sharp and without glare\n"), err
    assert not out.exists()
    copy = tmp_path / "copy.png"
    copy.write_bytes(Path(names[1]).read_bytes())
    blank = tmp_path / "blank.png"
    assert cv2.imwrite(str(blank), np.full((480, 640), 128, np.uint8))
    assert main(["calibrate", *names, str(copy), str(blank), str(blank), "--out",
                 str(out)]) == 0
    printed = capsys.readouterr()
    assert (f"skeye calibrate: {copy} is the same image as {names[1]}, pixel for pixel "
            "(skipped: a view counts once)\n") in printed.err, printed.err
    # identical frames without the board are searched, and skipped, each
    assert printed.err.count(f"board not found in {blank} (skipped)") == 2
    assert "found in 3 of 6 images" in printed.out
    assert out.exists()
