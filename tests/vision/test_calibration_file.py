"""camera.toml and the lens model: round trips, errors naming the key, OpenCV agreement."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from skeye.cli import main
from skeye.errors import ConfigError, InvalidArgument
from skeye.vision.calibration import Board, CameraCalibration, load_calibration, parse_board
from skeye.vision.level_view import LevelView

CAL = CameraCalibration(800, 600, 521.3, 520.9, 401.2, 298.7,
                        (-0.21, 0.035, 0.0007, -0.0004, -0.002), 0.083, Board(9, 6, 0.025), 14)


def test_toml_round_trip_is_exact(tmp_path: Path) -> None:
    path = tmp_path / "camera.toml"
    CAL.save(path)
    assert load_calibration(path) == CAL
    bare = CameraCalibration(640, 480, 500.0, 500.0, 319.5, 239.5, (0.0,) * 5)
    bare.save(path)
    assert load_calibration(path) == bare
    assert "[calibration]" not in path.read_text()


@pytest.mark.parametrize(
    ("old", "new", "problem"),
    [
        # A hand-edited value the dataclass refuses was not named by its key ("fx and fy
        # must be positive", "image size must be at least 16x16", "a board needs ...").
        ("fx_px = 521.3", "fx_px = -5.0", "[camera].fx_px: a focal length must be positive"),
        ("fy_px = 520.9", "fy_px = 0.0", "[camera].fy_px: a focal length must be positive"),
        ("width_px = 800", "width_px = 4", "[camera].width_px: an image side is at least 16"),
        ("height_px = 600", "height_px = -600", "[camera].height_px: an image side is at least"),
        ('board = "9x6"', 'board = "1x1"', "[calibration].board: a board needs at least 3x3"),
        ('board = "9x6"', 'board = "2x6"', "[calibration].board: a board needs at least 3x3"),
        ("square_mm = 25.0", "square_mm = 0.0", "[calibration].square_mm: square size must be"),
        ("square_mm = 25.0", "square_mm = 1e9", "[calibration].square_mm: square size must be"),
        ("fx_px = 521.3", 'fx_px = "wide"', "[camera].fx_px: must be a finite number"),
        ("width_px = 800", "width_px = 800.5", "[camera].width_px: must be an integer"),
        ("width_px = 800\n", "", "missing required key width_px"),
        # A size no frame has: 10^23 px was blamed on fx_px (its view "of exactly pi")
        ("width_px = 800", "width_px = 99999999999999999999999",
         "[camera].width_px: an image side is at most 65535 px (a JPEG's or a RAW frame's), "
         "got 99999999999999999999999"),
        ("height_px = 600", "height_px = 65536",
         "[camera].height_px: an image side is at most 65535 px"),
        ("k1 = -0.21", "kappa = -0.21", "unknown key(s) ['kappa']"),
        ('board = "9x6"', 'board = "nine"', "[calibration].board: board must be COLSxROWS"),
        ("format = 1", "format = 7", "format must be 1"),
        # a boolean and a float: read as format 1 (True == 1.0 == 1 in Python)
        ("format = 1", "format = true", "format must be 1, got True"),
        ("format = 1", "format = 1.0", "format must be 1, got 1.0"),
        ("[camera]", "[lens]", "unknown key(s) ['lens']"),
        # A camera no lens makes (fx 1e-300 used to be blamed on vision detect's --fov, the
        # others to load and find nothing).
        ("fx_px = 521.3", "fx_px = 1e-300", "[camera].fx_px: 1e-300 px gives a horizontal"),
        ("fy_px = 520.9", "fy_px = 1e-300", "[camera].fy_px: 1e-300 px gives a vertical"),
        ("cx_px = 401.2", "cx_px = -1e12", "[camera].cx_px: the principal point must lie in"),
        ("cy_px = 298.7", "cy_px = 600.0", "[camera].cy_px: the principal point must lie in"),
        ("k1 = -0.21", "k1 = 1e10", "[camera].k1: a distortion coefficient must be within"),
        ("p2 = -0.0004", "p2 = -10.5", "[camera].p2: a distortion coefficient must be within"),
        # the record of how it was found: no calibration has these (they were read as given)
        ("images = 14", "images = 0",
         "[calibration].images: a calibration is made from at least one image with the board, "
         "got 0"),
        ("images = 14", "images = -5", "[calibration].images: a calibration is made from"),
        ("rms_reprojection_px = 0.083", "rms_reprojection_px = -1.0",
         "[calibration].rms_reprojection_px: an RMS error is not negative, got -1.0"),
        # one half of the board: square_mm alone was dropped unread, board alone "got None"
        ('board = "9x6"\n', "", "[calibration]: square_mm without board: the board used is "
         "both, its inner corners COLSxROWS and its square side in mm"),
        ("square_mm = 25.0\n", "", "[calibration]: board without square_mm: the board used is"),
    ],
)
def test_bad_files_name_the_key(tmp_path: Path, old: str, new: str, problem: str) -> None:
    text = CAL.to_toml()
    assert old in text
    path = tmp_path / "camera.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ConfigError) as err:
        load_calibration(path)
    assert str(path) in str(err.value) and problem in str(err.value), err.value


def test_a_fit_that_folds_over_outside_the_board_is_accepted(tmp_path: Path) -> None:
    """k1 -0.2 alone at a 75 degree view folds over before the image corners (docs/
    calibration.md's accuracy lens): a real OpenCV fit, read as written."""
    f = 400.0 / np.tan(np.radians(37.5))
    folded = CameraCalibration(800, 600, f, f, 399.5, 299.5, (-0.2, 0.0, 0.0, 0.0, 0.0))
    r = folded.max_radius()  # the distorted radius stops growing there, short of the corner's
    assert r * (1.0 - 0.2 * r * r) < np.hypot(400.0, 300.0) / f
    folded.save(tmp_path / "camera.toml")
    assert load_calibration(tmp_path / "camera.toml") == folded


def test_unreadable_and_non_toml_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read calibration file"):
        load_calibration(tmp_path / "none.toml")
    (tmp_path / "x.toml").write_text("fx = = 3")
    with pytest.raises(ConfigError, match="not a TOML file"):
        load_calibration(tmp_path / "x.toml")


def test_board_parsing() -> None:
    assert parse_board("9x6") == (9, 6) and parse_board("7X5") == (7, 5)
    for bad in ("9", "9x", "ax6", "9x6x2", "-9x6"):
        with pytest.raises(InvalidArgument):
            parse_board(bad)
    with pytest.raises(InvalidArgument):
        Board(1, 6, 0.025)


def test_board_with_odd_digits_or_too_many_corners_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """"²x6" passed str.isdigit() and then made int() raise ValueError (a traceback from
    skeye calibrate); a 100000x100000 board asked numpy for 112 GiB of object points."""
    for bad in ("²x6", "9x٦"):
        with pytest.raises(InvalidArgument, match="COLSxROWS"):
            parse_board(bad)
    with pytest.raises(InvalidArgument, match="at most 1000 inner corners"):
        Board(100_000, 100_000, 0.025)
    image = tmp_path / "board.png"
    cv2.imwrite(str(image), np.full((480, 640), 128, np.uint8))
    out = tmp_path / "camera.toml"
    for board in ("²x6", "100000x100000"):
        assert main(["calibrate", str(image), "--board", board, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("skeye calibrate: error: ") and "Traceback" not in err, err
    assert not out.exists()
    (tmp_path / "huge.toml").write_text(
        CAL.to_toml().replace('board = "9x6"', 'board = "100000x100000"'))
    with pytest.raises(ConfigError, match="at most 1000 inner corners"):
        load_calibration(tmp_path / "huge.toml")


def test_forward_model_is_opencvs() -> None:
    rng = np.random.default_rng(4)
    pts = np.column_stack((rng.uniform(-0.7, 0.7, 200), rng.uniform(-0.5, 0.5, 200), np.ones(200)))
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), CAL.camera_matrix(),
                               CAL.dist_coeffs())
    u, v = CAL.distort_normalized(pts[:, 0], pts[:, 1])
    assert np.column_stack((u, v)) == pytest.approx(ref.reshape(-1, 2), abs=1e-6)


def test_level_view_maps_there_and_back() -> None:
    grey = np.zeros((600, 800), np.uint8)
    view = LevelView(grey, 1.309, 0.12, -0.08, True, CAL)
    u, v = np.meshgrid(np.linspace(0, 799, 9), np.linspace(0, 599, 7))
    lx, ly = view.to_level(u, v)
    bu, bv = view.to_image(lx, ly)
    assert np.abs(bu - u).max() < 1e-4 and np.abs(bv - v).max() < 1e-4
    # Far outside the lens's valid radius a level point is not in the image.
    fx, fy = view.to_image(np.array([1e5]), np.array([0.0]))
    assert fx[0] < 0 and fy[0] < 0


def test_calibrate_refuses_mixed_sizes_and_too_few_boards() -> None:
    from skeye.errors import LocalProtocolError
    from skeye.vision.calibration import calibrate

    board = Board(9, 6, 0.025)
    blank = np.full((480, 640), 128, np.uint8)
    with pytest.raises(LocalProtocolError, match="all images must come from one camera"):
        calibrate([("a.png", blank), ("b.png", np.full((600, 800), 128, np.uint8))], board)
    with pytest.raises(LocalProtocolError, match="found in 0 of 2 images"):
        calibrate([("a.png", blank), ("b.png", blank)], board)
    with pytest.raises(LocalProtocolError, match="no images"):
        calibrate([], board)


@pytest.mark.parametrize("sizes", [((1, 1),), ((2, 2), (2, 2)), ((15, 640), (15, 640)),
                                   ((480, 640), (1, 1))])
def test_calibrate_refuses_tiny_images(sizes: tuple[tuple[int, int], ...], tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A 1x1 or 2x2 image made OpenCV's corner finder fail an assertion (cv2.error, a
    traceback from skeye calibrate); such images are refused naming the image and its size."""
    names = []
    for i, (h, w) in enumerate(sizes):
        names.append(str(tmp_path / f"img{i}.png"))
        cv2.imwrite(names[-1], np.full((h, w), 128, np.uint8))
    out = tmp_path / "camera.toml"
    assert main(["calibrate", *names, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("skeye calibrate: error: ") and "Traceback" not in err, err
    h, w = sizes[0] if min(sizes[0]) < 16 else sizes[1]
    assert f"is {w}x{h}" in err, err
    assert not out.exists()


@pytest.mark.parametrize("board", ["2x2", "3x2", "2x6"])
def test_a_board_with_two_corners_a_side_is_refused_in_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], board: str) -> None:
    """A board of 2 inner corners a side (docs/calibration.md said 2 to 1000) made OpenCV's
    findChessboardCorners fail its assertion ("Both width and height of the pattern should have
    bigger than 2"): a traceback out of skeye calibrate. Now one line, status 2, nothing
    written."""
    image = tmp_path / "board.png"
    cv2.imwrite(str(image), np.full((480, 640), 128, np.uint8))
    out = tmp_path / "camera.toml"
    assert main(["calibrate", str(image), "--board", board, "--out", str(out)]) == 2
    assert capsys.readouterr().err == (
        "skeye calibrate: error: a board needs at least 3x3 inner corners (OpenCV's corner "
        f"finders), got {board}\n")
    assert not out.exists()
