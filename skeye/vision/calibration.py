"""Camera calibration: the camera.toml file, the lens model, and the checkerboard solver.

How this works: a :class:`CameraCalibration` is what OpenCV's ``calibrateCamera`` finds for
one camera at one resolution - the camera matrix (fx, fy, cx, cy in pixels, OpenCV index
coordinates: pixel (u, v) has its centre at (u, v)) and the Brown-Conrady distortion
coefficients in OpenCV's order (k1, k2, p1, p2, k3) - plus how it was found (RMS reprojection
error, board, number of images). :func:`calibrate` runs the standard recipe (Zhang 2000, as
OpenCV implements it): find the board's inner corners in every image
(``findChessboardCorners``, refined with ``cornerSubPix``; the sector-based detector
``findChessboardCornersSB`` when the classic one finds nothing; an image over
``DETECT_MAX_PX`` a side on a reduced copy, the corners then refined on the image itself), then
``calibrateCamera`` on all of them. :func:`load_calibration` /
:meth:`CameraCalibration.to_toml` read and write camera.toml (format: docs/calibration.md).

:meth:`CameraCalibration.distort_normalized` is OpenCV's forward model (normalized camera
coordinates -> pixels), vectorized; the detector uses it to sample the image at undistorted
positions, and ``cv2.undistortPoints`` for the way back.

Invariants: a calibration belongs to one image size; using it on frames of another size is an
error, never a silent rescale. Nothing is rounded when written, and a file is written whole or
not at all (a failed write leaves the previous file as it was).
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from skeye.errors import ConfigError, InvalidArgument, LocalProtocolError
from skeye.outputs import partial_beside
from skeye.robots.camera_model import DISTORTION_LIMIT

DIST_NAMES = ("k1", "k2", "p1", "p2", "k3")
FORMAT_VERSION = 1
MAX_BOARD_CORNERS = 1000  # inner corners a side: far beyond any printed board
MIN_BOARD_CORNERS = 3  # inner corners a side: findChessboardCorners refuses fewer (cv2.error)
MIN_IMAGE_PX = 16  # a side: a camera's smallest (OpenCV's corner finder fails below it)
MAX_IMAGE_PX = 0xFFFF  # a side: a JPEG's largest (ITU T.81's 16-bit sizes), a RAW frame's too
MIN_SQUARE_M = 1e-6
"""A board's smallest square side, 1 um: visible light cannot image a checkerboard much finer
(the diffraction limit, half a wavelength, is 0.2-0.4 um even through a microscope)."""
MAX_SQUARE_M = 10.0
"""A board's largest square side, 10 m: a 9x6 board of them is 100 m x 70 m, beyond any board
painted on a field for a camera flying high. The calibration's intrinsics do not depend on the
square size (it only scales the board poses), and these bounds keep the board's points (up to
1000 corners a side, float32) finite and far from zero; 1e308 mm overflowed them, and OpenCV's
calibrateCamera then failed an assertion."""


@dataclass(frozen=True)
class Board:
    """A checkerboard target: inner corners per row (cols) and per column (rows), square side."""

    cols: int
    rows: int
    square_m: float

    def __post_init__(self) -> None:
        check_corners(self.cols, self.rows)
        check_square(self.square_m)

    @property
    def label(self) -> str:
        return f"{self.cols}x{self.rows}"

    def object_points(self) -> np.ndarray:
        """The inner corners on the board plane (z = 0), metres, in OpenCV's row-major order."""
        grid = np.zeros((self.rows * self.cols, 3), np.float32)
        grid[:, :2] = np.mgrid[0 : self.cols, 0 : self.rows].T.reshape(-1, 2) * self.square_m
        return grid


def check_corners(cols: int, rows: int) -> None:
    """InvalidArgument unless a board of ``cols`` x ``rows`` inner corners can be found."""
    if cols < MIN_BOARD_CORNERS or rows < MIN_BOARD_CORNERS:
        raise InvalidArgument(f"a board needs at least {MIN_BOARD_CORNERS}x{MIN_BOARD_CORNERS} "
                              f"inner corners (OpenCV's corner finders), got {cols}x{rows}")
    if cols > MAX_BOARD_CORNERS or rows > MAX_BOARD_CORNERS:
        raise InvalidArgument(f"a board has at most {MAX_BOARD_CORNERS} inner corners a "
                              f"side, got {cols}x{rows}")


def check_square(square_m: float) -> None:
    """InvalidArgument unless ``square_m`` is a square side from MIN_SQUARE_M to MAX_SQUARE_M."""
    if not (math.isfinite(square_m) and square_m > 0):
        raise InvalidArgument(f"square size must be positive, got {square_m} m")
    if not MIN_SQUARE_M <= square_m <= MAX_SQUARE_M:
        raise InvalidArgument(
            f"square size must be {MIN_SQUARE_M * 1e3:g}..{MAX_SQUARE_M * 1e3:g} mm (1 um, "
            f"what light can image, to 10 m), got {square_m * 1e3:g} mm")


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` -> (9, 6): inner corners per row and per column."""
    parts = text.lower().split("x")
    # isascii: str.isdigit() also accepts digits int() refuses (superscripts such as "²")
    if len(parts) != 2 or not all(p.strip().isascii() and p.strip().isdigit() for p in parts):
        raise InvalidArgument(f"board must be COLSxROWS inner corners, e.g. 9x6, got {text!r}")
    return int(parts[0]), int(parts[1])


@dataclass(frozen=True)
class CameraCalibration:
    """One camera's intrinsics and lens distortion at one image size (pixels)."""

    width_px: int
    height_px: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float]  # k1, k2, p1, p2, k3 (OpenCV order)
    rms_px: float | None = None  # RMS reprojection error of the calibration
    board: Board | None = None
    images: int | None = None  # images the board was found in (and used)

    def __post_init__(self) -> None:
        if self.width_px < MIN_IMAGE_PX or self.height_px < MIN_IMAGE_PX:
            raise InvalidArgument(f"image size must be at least {MIN_IMAGE_PX}x{MIN_IMAGE_PX}, got "
                                  f"{self.width_px}x{self.height_px}")
        values = (self.fx, self.fy, self.cx, self.cy, *self.dist)
        if len(self.dist) != 5 or not all(math.isfinite(v) for v in values):
            raise InvalidArgument("fx, fy, cx, cy and the 5 distortion coefficients must be "
                                  "finite numbers")
        if self.fx <= 0 or self.fy <= 0:
            raise InvalidArgument(f"fx and fy must be positive, got {self.fx}, {self.fy}")

    @classmethod
    def pinhole(cls, width_px: int, height_px: int, fov_h_rad: float) -> CameraCalibration:
        """The ideal camera the simulator renders (no distortion, centred principal point)."""
        from skeye.vision.camera import focal_length_px, principal_point_px

        f = focal_length_px(width_px, fov_h_rad)
        cx, cy = principal_point_px(width_px, height_px)
        return cls(width_px, height_px, f, f, cx, cy, (0.0, 0.0, 0.0, 0.0, 0.0))

    def camera_matrix(self) -> np.ndarray:
        return np.array(((self.fx, 0.0, self.cx), (0.0, self.fy, self.cy), (0.0, 0.0, 1.0)))

    def dist_coeffs(self) -> np.ndarray:
        return np.array(self.dist, dtype=np.float64)

    @property
    def fov_h_rad(self) -> float:
        """The horizontal field of view of the undistorted (pinhole) camera."""
        return 2.0 * math.atan(self.width_px / 2.0 / self.fx)

    def check_size(self, width_px: int, height_px: int) -> None:
        if (width_px, height_px) != (self.width_px, self.height_px):
            raise LocalProtocolError(
                f"the calibration is for {self.width_px}x{self.height_px} images, the frame is "
                f"{width_px}x{height_px}: calibrate the camera at the resolution it flies with"
            )

    def max_radius(self) -> float:
        """Largest normalized radius up to which the radial model keeps growing (invertible).

        Past it (strong barrel distortion, far outside the image) the polynomial folds back;
        points there are not in the image.
        """
        k1, k2, _, _, k3 = self.dist
        r = np.linspace(0.0, 4.0, 4001)
        r2 = r * r
        d = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2 + 7.0 * k3 * r2 * r2 * r2  # d(r*L(r))/dr
        bad = np.nonzero(d <= 0.05)[0]
        return float(r[bad[0]]) if bad.size else 4.0

    def distort_normalized(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV's forward model: normalized undistorted coordinates -> image pixels."""
        k1, k2, p1, p2, k3 = self.dist
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy = x * y
        xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy
        return self.fx * xd + self.cx, self.fy * yd + self.cy

    def to_toml(self) -> str:
        """camera.toml text (docs/calibration.md); floats written with ``repr`` (exact)."""
        lines = [
            "# skeye camera calibration (docs/calibration.md). Pixels are OpenCV index",
            "# coordinates; distortion is OpenCV's (k1, k2, p1, p2, k3) Brown-Conrady model.",
            f"format = {FORMAT_VERSION}",
            "",
            "[camera]",
            f"width_px = {int(self.width_px)}",
            f"height_px = {int(self.height_px)}",
            f"fx_px = {float(self.fx)!r}",
            f"fy_px = {float(self.fy)!r}",
            f"cx_px = {float(self.cx)!r}",
            f"cy_px = {float(self.cy)!r}",
            *(f"{n} = {float(v)!r}" for n, v in zip(DIST_NAMES, self.dist, strict=True)),
        ]
        if self.rms_px is not None or self.board is not None or self.images is not None:
            lines += ["", "[calibration]"]
            if self.rms_px is not None:
                lines.append(f"rms_reprojection_px = {float(self.rms_px)!r}")
            if self.board is not None:
                lines.append(f'board = "{self.board.label}"')
                lines.append(f"square_mm = {float(self.board.square_m) * 1000.0!r}")
            if self.images is not None:
                lines.append(f"images = {self.images}")
        return "\n".join(lines) + "\n"

    def save(self, path: str | Path) -> None:
        """Write camera.toml whole or not at all: to a partial file beside ``path``, then
        renamed over it, so a write that fails (a full disk, a file size limit) leaves the
        file that was there, or none, never one cut short. A symbolic link is written through
        (the file it names is replaced, the link kept), as a plain write does.

        Raises:
            OSError: the file could not be written (no partial file is left behind).
        """
        target, partial = partial_beside(Path(path))
        try:
            partial.write_text(self.to_toml(), encoding="utf-8")
            os.replace(partial, target)
        finally:
            with contextlib.suppress(OSError):
                partial.unlink(missing_ok=True)


def _number(table: dict[str, Any], key: str, where: str) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(f"{where}.{key}: must be a finite number, got {value!r}")
    return float(value)


def _integer(table: dict[str, Any], key: str, where: str) -> int:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(f"{where}.{key}: must be an integer, got {value!r}")
    return value


def load_calibration(path: str | Path) -> CameraCalibration:
    """Read camera.toml; ConfigError names the file and the key at fault."""
    if isinstance(path, str) and not path:  # Path("") is ".": "Is a directory", said of "."
        raise ConfigError("no calibration file named (an empty name)")
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read calibration file: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: not a TOML file: {exc}") from None
    unknown = sorted(set(data) - {"format", "camera", "calibration"})
    if unknown:
        raise ConfigError(f"{p}: unknown key(s) {unknown}; known: format, [camera], "
                          "[calibration]")
    fmt = data.get("format", FORMAT_VERSION)  # true and 1.0 equal 1 in Python: not in TOML
    if isinstance(fmt, bool) or not isinstance(fmt, int) or fmt != FORMAT_VERSION:
        raise ConfigError(f"{p}: format must be {FORMAT_VERSION}, got {data.get('format')!r}")
    cam = data.get("camera")
    if not isinstance(cam, dict):
        raise ConfigError(f"{p}: missing [camera] table (see docs/calibration.md)")
    where = f"{p}: [camera]"
    known = {"width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px", *DIST_NAMES}
    unknown = sorted(set(cam) - known)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}; known: {sorted(known)}")
    for key in ("width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px"):
        if key not in cam:
            raise ConfigError(f"{where}: missing required key {key}")
    dist = tuple(_number(cam, n, where) if n in cam else 0.0 for n in DIST_NAMES)
    rms = board = images = None
    cal = data.get("calibration", {})
    if not isinstance(cal, dict):
        raise ConfigError(f"{p}: [calibration] must be a table")
    cwhere = f"{p}: [calibration]"
    unknown = sorted(set(cal) - {"rms_reprojection_px", "board", "square_mm", "images"})
    if unknown:
        raise ConfigError(f"{cwhere}: unknown key(s) {unknown}")
    # Each value is checked here, naming its key; the dataclasses' own checks say no key.
    if "rms_reprojection_px" in cal:
        rms = _number(cal, "rms_reprojection_px", cwhere)
        if rms < 0.0:  # a root mean square
            raise ConfigError(f"{cwhere}.rms_reprojection_px: an RMS error is not negative, "
                              f"got {rms!r}")
    # one without the other: square_mm alone was dropped unread, board alone "got None"
    if ("board" in cal) != ("square_mm" in cal):
        given, lacking = ("board", "square_mm") if "board" in cal else ("square_mm", "board")
        raise ConfigError(f"{cwhere}: {given} without {lacking}: the board used is both, its "
                          "inner corners COLSxROWS and its square side in mm")
    if "board" in cal:
        if not isinstance(cal["board"], str):
            raise ConfigError(f"{cwhere}.board: must be a string like \"9x6\"")
        try:
            cols, rows = parse_board(cal["board"])
            check_corners(cols, rows)
        except InvalidArgument as exc:
            raise ConfigError(f"{cwhere}.board: {exc}") from None
        square_m = _number(cal, "square_mm", cwhere) / 1000.0
        try:
            check_square(square_m)
        except InvalidArgument as exc:
            raise ConfigError(f"{cwhere}.square_mm: {exc}") from None
        board = Board(cols, rows, square_m)
    if "images" in cal:
        images = _integer(cal, "images", cwhere)
        if images < 1:  # the board was found in them all
            raise ConfigError(f"{cwhere}.images: a calibration is made from at least one "
                              f"image with the board, got {images}")
    sizes = {key: _integer(cam, key, where) for key in ("width_px", "height_px")}
    for key, size in sizes.items():
        if size < MIN_IMAGE_PX:
            raise ConfigError(f"{where}.{key}: an image side is at least {MIN_IMAGE_PX} px, "
                              f"got {size}")
    focal = {key: _number(cam, key, where) for key in ("fx_px", "fy_px")}
    for key, f in focal.items():
        if f <= 0:
            raise ConfigError(f"{where}.{key}: a focal length must be positive, got {f!r}")
    calibration = CameraCalibration(
        sizes["width_px"], sizes["height_px"], focal["fx_px"], focal["fy_px"],
        _number(cam, "cx_px", where), _number(cam, "cy_px", where),
        (dist[0], dist[1], dist[2], dist[3], dist[4]), rms, board, images,
    )
    check_lens(calibration, where)
    return calibration


def check_lens(c: CameraCalibration, where: str) -> None:
    """Refuse (ConfigError naming ``where`` and the key) a camera no lens makes: a focal
    length whose field of view is not strictly inside (0, pi) (a pinhole camera's cannot
    reach pi), a principal point outside the image, a distortion coefficient beyond
    +-:data:`~skeye.robots.camera_model.DISTORTION_LIMIT` (the simulator's camera model's
    range). A fit that folds over outside the region the board covered is a real OpenCV
    result and is accepted (docs/calibration.md, "What is refused"). An image side beyond
    :data:`MAX_IMAGE_PX` is refused first: no frame has it, and its field of view would
    round to pi and be blamed on the focal length."""
    for key, size in (("width_px", c.width_px), ("height_px", c.height_px)):
        if size > MAX_IMAGE_PX:
            raise ConfigError(f"{where}.{key}: an image side is at most {MAX_IMAGE_PX} px (a "
                              f"JPEG's or a RAW frame's), got {size}")
    for key, size, f, axis in (("fx_px", c.width_px, c.fx, "horizontal"),
                               ("fy_px", c.height_px, c.fy, "vertical")):
        fov = 2.0 * math.atan(size / 2.0 / f)
        if not 0.0 < fov < math.pi:
            raise ConfigError(f"{where}.{key}: {f!r} px gives a {axis} field of view of "
                              f"{fov!r} rad; a lens's is strictly between 0 and pi")
    for key, size, value in (("cx_px", c.width_px, c.cx), ("cy_px", c.height_px, c.cy)):
        if not -0.5 <= value <= size - 0.5:
            raise ConfigError(f"{where}.{key}: the principal point must lie in the image, "
                              f"-0.5..{size - 0.5:g} px, got {value!r}")
    for key, value in zip(DIST_NAMES, c.dist, strict=True):
        if abs(value) > DISTORTION_LIMIT:
            raise ConfigError(f"{where}.{key}: a distortion coefficient must be within "
                              f"-{DISTORTION_LIMIT:g}..{DISTORTION_LIMIT:g} (the simulator's "
                              f"camera model's range), got {value!r}")


_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)


def undistort_points(
    pts: np.ndarray, k: np.ndarray, dist: np.ndarray, r: np.ndarray | None, p: np.ndarray | None
) -> np.ndarray:
    """``cv2.undistortPoints`` iterated to convergence (its default 5 iterations leave pixels
    of error in the corners of a strongly distorted image). ``pts`` (N, 1, 2) float64."""
    iterate = getattr(cv2, "undistortPointsIter", None)  # OpenCV 4.x
    if iterate is not None:
        return np.asarray(iterate(pts, k, dist, r, p, _UNDISTORT_CRITERIA))
    return np.asarray(cv2.undistortPoints(pts, k, dist, R=r, P=p, criteria=_UNDISTORT_CRITERIA))


# ----------------------------------------------------------------------------------------------
# Solving


_SUBPIX = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-4)


DETECT_MAX_PX = 2048
"""The board is searched for on a copy of at most this many pixels a side. OpenCV's corner
finders take time in proportion to the pixels when the board is not where they look first (a
7559x5669 image without a board took 85 s here, a 2000x1500 one 3-5 s); the corners found on
the copy are then refined at full resolution with ``cornerSubPix``, as ROS's camera_calibration
does (``downsample_and_detect``, which searches a copy of about 640x480). Images up to this size
(the simulator's 800x600, a webcam's 1920x1080) are searched as they are, unchanged."""


def searched_size(width: int, height: int) -> tuple[int, int]:
    """The size of the copy :func:`find_corners` searches for an image of this size."""
    scale = max(width, height) / DETECT_MAX_PX
    if scale <= 1.0:
        return width, height
    return max(1, round(width / scale)), max(1, round(height / scale))


def find_corners(grey: np.ndarray, board: Board) -> np.ndarray | None:
    """The board's inner corners in one greyscale image (N, 1, 2) float32, or None. An image
    over ``DETECT_MAX_PX`` a side is searched on a reduced copy (area-averaged), and the corners
    found there are refined on the image itself."""
    height, width = grey.shape[:2]
    scale = max(width, height) / DETECT_MAX_PX
    if scale <= 1.0:
        return _find_corners(grey, board)
    small = cv2.resize(grey, searched_size(width, height), interpolation=cv2.INTER_AREA)
    found = _find_corners(small, board)
    if found is None:
        return None
    # pixel centres are at integer index coordinates in both images
    corners = found.astype(np.float32)  # a copy, in the finder's own shape
    corners[..., 0] = (corners[..., 0] + 0.5) * (width / small.shape[1]) - 0.5
    corners[..., 1] = (corners[..., 1] + 0.5) * (height / small.shape[0]) - 0.5
    # the window must reach the true corner from the scaled-up one (a fraction of a reduced
    # pixel off, so up to about `scale` pixels here), and stay under half the spacing
    return _refine(grey, corners, board, reach_px=math.ceil(2.0 * scale))


def _refine(grey: np.ndarray, corners: np.ndarray, board: Board,
            reach_px: int = 11) -> np.ndarray:
    """``cornerSubPix`` with a window under half the smallest corner spacing, at most
    ``reach_px`` (11 for corners found on the image itself) and at least 2 pixels."""
    pts = corners.reshape(board.rows, board.cols, 2)
    spacing = min(
        float(np.linalg.norm(np.diff(pts, axis=1), axis=2).min()),
        float(np.linalg.norm(np.diff(pts, axis=0), axis=2).min()),
    )
    half = int(max(2, min(max(11, reach_px), math.floor(0.4 * spacing))))
    return cv2.cornerSubPix(grey, corners, (half, half), (-1, -1), _SUBPIX)


def _find_corners(grey: np.ndarray, board: Board) -> np.ndarray | None:
    size = (board.cols, board.rows)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(grey, size, flags=flags)
    if ok:
        # The refinement window: under half the smallest corner spacing, at most 11x11.
        return _refine(grey, corners, board)
    ok, corners = cv2.findChessboardCornersSB(grey, size, flags=cv2.CALIB_CB_ACCURACY)
    return corners.astype(np.float32) if ok else None


MISSING_NAMED = 5
"""Images without the board a refusal for too few boards names (the rest are counted)."""


@dataclass(frozen=True)
class CalibrationResult:
    calibration: CameraCalibration
    used: tuple[str, ...]  # image names the board was found in
    skipped: tuple[str, ...]  # ... and not found in
    per_image_rms_px: tuple[float, ...]  # reprojection RMS of each used image
    repeated: tuple[tuple[str, str], ...] = ()  # (name, the earlier image it is): not used


def calibrate(
    images: Sequence[tuple[str, np.ndarray]], board: Board, min_images: int = 3,
    progress: Callable[[str], None] | None = None,
) -> CalibrationResult:
    """Calibrate from (name, greyscale uint8 image) pairs, all of one size. Images over
    ``DETECT_MAX_PX`` a side are searched on a reduced copy (:func:`find_corners`), and
    ``progress`` is told about each of them as it is done (which, its size, the copy's, found
    or not, the seconds it took).

    Raises:
        LocalProtocolError: mixed image sizes, an image under 16 px a side, or fewer than
            ``min_images`` distinct images with the whole board found (an image with the board
            identical, pixel for pixel, to an earlier one is not used: ``repeated``).
    """
    if not images:
        raise LocalProtocolError("no images given")
    size = images[0][1].shape[:2]
    if min(size) < MIN_IMAGE_PX:  # findChessboardCorners fails an assertion on them
        raise LocalProtocolError(
            f"{images[0][0]} is {size[1]}x{size[0]}: a calibration image must be at least "
            f"{MIN_IMAGE_PX}x{MIN_IMAGE_PX} px")
    for name, grey in images:  # all before any search (seconds an image for a camera's photos)
        if grey.shape[:2] != size:
            raise LocalProtocolError(
                f"{name} is {grey.shape[1]}x{grey.shape[0]}, the first image "
                f"{size[1]}x{size[0]}: all images must come from one camera at one resolution")
    obj = board.object_points()
    object_points, image_points = [], []
    used: list[str] = []
    skipped: list[str] = []
    repeated: list[tuple[str, str]] = []
    found_in: dict[bytes, str] = {}  # the images with the board, by their pixels' digest
    for name, grey in images:
        digest = hashlib.sha256(np.ascontiguousarray(grey).tobytes()).digest()
        if digest in found_in:  # one view given twice: a name or a glob repeated, a copy, a
            # stalled camera's frame saved again. Used, it adds nothing to the fit but weight:
            # one view given thrice fitted fx 2e10 px, a field of view of 3e-8 rad
            repeated.append((name, found_in[digest]))
            continue
        started = time.monotonic()
        corners = find_corners(grey, board)
        if progress is not None and max(size) > DETECT_MAX_PX:
            copy = searched_size(size[1], size[0])
            progress(f"image {len(used) + len(skipped) + 1} of {len(images)}, {name} "
                     f"({size[1]}x{size[0]}, searched at {copy[0]}x{copy[1]}): board "
                     f"{'found' if corners is not None else 'not found'} in "
                     f"{time.monotonic() - started:.1f} s")
        if corners is None:
            skipped.append(name)
            continue
        object_points.append(obj)
        image_points.append(corners)
        used.append(name)
        found_in[digest] = name
    if len(used) < min_images:
        found = f"the {board.label} board was found in {len(used)} of {len(images)} images"
        if repeated:
            found += (f" (and {len(repeated)} more the same as one of those, pixel for pixel, "
                      "not used)")
        if not used:  # in none: most likely the wrong count of corners
            raise LocalProtocolError(f"{found}; at least {min_images} are needed (is --board "
                                     "the count of INNER corners, COLSxROWS?)")
        # in some: --board is right, the frames are too few or miss the board; name those
        missing = ", ".join(skipped[:MISSING_NAMED])
        if len(skipped) > MISSING_NAMED:
            missing += f" and {len(skipped) - MISSING_NAMED} more"
        raise LocalProtocolError(
            f"{found}{f' (not in {missing})' if skipped else ''}; at least {min_images} are "
            "needed: take more frames, each with the whole board in view, sharp and without "
            "glare")
    height, width = size
    rms, k, dist, rvecs, tvecs = cv2.calibrateCamera(
        object_points, image_points, (width, height), None, None
    )
    per_image = []
    for o, i, r, t in zip(object_points, image_points, rvecs, tvecs, strict=True):
        proj, _ = cv2.projectPoints(o, r, t, k, dist)
        err = proj.reshape(-1, 2) - np.asarray(i).reshape(-1, 2)
        per_image.append(float(np.sqrt(np.mean(np.sum(err * err, axis=1)))))
    d = [float(v) for v in np.asarray(dist).reshape(-1)[:5]]
    cal = CameraCalibration(
        width, height, float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]),
        (d[0], d[1], d[2], d[3], d[4]), float(rms), board, len(used),
    )
    return CalibrationResult(cal, tuple(used), tuple(skipped), tuple(per_image), tuple(repeated))
