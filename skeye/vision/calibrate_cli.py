"""``skeye calibrate IMAGES... --board 9x6 --square-mm 25 --out camera.toml``.

How this works: reads every image as greyscale, hands them to
:func:`skeye.vision.calibration.calibrate` (OpenCV's checkerboard corners and
``calibrateCamera``), writes camera.toml and prints what it found: the images used and
skipped, the RMS reprojection error, fx, fy, cx, cy and the distortion coefficients. The same
command serves simulator frames (``skeye snapshot``) and a real camera's. Exit 0 on success,
2 for bad input (an unreadable image, a bad --board, the board found in too few images, an
--out that cannot be written: that one checked before any image is read).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import cv2

from skeye import cliargs
from skeye.errors import ConfigError, InvalidArgument, LocalProtocolError
from skeye.image_files import read_image_file
from skeye.outputs import output_file
from skeye.vision.calibration import (
    DIST_NAMES,
    MAX_SQUARE_M,
    MIN_SQUARE_M,
    Board,
    calibrate,
    check_lens,
    parse_board,
)

EXIT_BAD_INPUT = 2
RMS_WARNING_PX = 1.0  # a good calibration reprojects to a fraction of a pixel
FEW_IMAGES = 10  # OpenCV's tutorial asks for 10 or more views


def _fail(message: str) -> int:
    print(f"skeye calibrate: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _progress(message: str) -> None:
    """A line per large image as it is searched (they take seconds each)."""
    print(f"skeye calibrate: {message}", file=sys.stderr, flush=True)


def cmd_calibrate(args: argparse.Namespace) -> int:
    try:
        cols, rows = parse_board(args.board)
        square_m = args.square_mm / 1000.0
        # one message for all: "must be positive, got inf" was said of 1e400 (nan fails too)
        if not MIN_SQUARE_M <= square_m <= MAX_SQUARE_M:
            raise InvalidArgument(
                f"--square-mm must be {MIN_SQUARE_M * 1e3:g}..{MAX_SQUARE_M * 1e3:g} (a square "
                f"from 1 um, what light can image, to 10 m), got {args.square_mm:g}")
        board = Board(cols, rows, square_m)
    except InvalidArgument as exc:
        return _fail(str(exc))
    if not args.out.lower().endswith(".toml"):
        return _fail(f"--out must name a .toml file, got {args.out}")
    try:  # a name that cannot be written costs no search (minutes for a camera's photos)
        output_file(Path(args.out), "--out")
    except ConfigError as exc:
        return _fail(str(exc))
    images = []
    for name in args.images:
        try:
            grey = read_image_file(name, cv2.IMREAD_GRAYSCALE)
        except ConfigError as exc:
            return _fail(str(exc))
        images.append((name, grey))
    try:
        result = calibrate(images, board, progress=_progress)
    except LocalProtocolError as exc:
        return _fail(str(exc))
    cal = result.calibration
    try:
        check_lens(cal, "the fitted [camera]")
    except ConfigError as exc:  # what the pilot would refuse to load is not written
        return _fail(f"{exc}; not written: take more frames, with the board in every part of "
                     "the image and tilted 20-40 degrees in different directions (level views "
                     "alone cannot tell the focal length from the distance; docs/"
                     "calibration.md, \"What is refused\")")
    try:
        cal.save(args.out)
    except OSError as exc:
        return _fail(f"cannot write {args.out}: {exc.strerror or exc}")
    for name in result.skipped:
        print(f"skeye calibrate: board not found in {name} (skipped)", file=sys.stderr)
    for name, earlier in result.repeated:
        print(f"skeye calibrate: {name} is the same image as {earlier}, pixel for pixel "
              "(skipped: a view counts once)", file=sys.stderr)
    print(f"wrote {args.out}: {cal.width_px}x{cal.height_px}, board {board.label} "
          f"({args.square_mm:g} mm squares) found in {len(result.used)} of {len(images)} images")
    print(f"  RMS reprojection error {cal.rms_px:.3f} px (worst image "
          f"{max(result.per_image_rms_px):.3f} px)")
    print(f"  fx {cal.fx:.3f}  fy {cal.fy:.3f}  cx {cal.cx:.3f}  cy {cal.cy:.3f} px "
          f"(horizontal field of view {cal.fov_h_rad:.5f} rad)")
    print("  " + "  ".join(f"{n} {v:+.5f}" for n, v in zip(DIST_NAMES, cal.dist, strict=True)))
    if cal.rms_px is not None and cal.rms_px > RMS_WARNING_PX:
        print(f"skeye calibrate: warning: RMS error above {RMS_WARNING_PX:g} px: blurred frames, "
              "a bent board or a wrong --board?", file=sys.stderr)
    if len(result.used) < FEW_IMAGES:
        print(f"skeye calibrate: warning: only {len(result.used)} usable images; {FEW_IMAGES} or "
              "more, with the board tilted and in every part of the image, pin the distortion "
              "down", file=sys.stderr)
    return 0


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "calibrate", help="calibrate a camera from checkerboard images (writes camera.toml)"
    )
    p.add_argument("images", nargs="+", type=cliargs.path,
                   help="image files of the board (any format OpenCV reads)")
    p.add_argument("--board", default="9x6",
                   help="inner corners per row x per column, COLSxROWS (default 9x6)")
    p.add_argument("--square-mm", type=float, default=25.0,
                   help="side of one printed square in millimetres (default 25)")
    p.add_argument("--out", type=cliargs.path, default="camera.toml",
                   help="calibration file to write (.toml)")
    p.set_defaults(func=cmd_calibrate)
