"""Command-line subcommands for the pad: ``pad`` (write a printable pad) and ``vision detect``.

How this works: :func:`register` adds the subcommands to the lead's argparse subparsers; each
sets ``func(args) -> int``. ``vision detect`` runs the same :func:`detect` the pilot calls and
prints one JSON object; without ``--fov`` it takes the field of view of the ``--robot`` file's
camera and says so on stderr; ``--calibration camera.toml`` (``skeye calibrate``) gives the
camera matrix and lens distortion instead (refused beside ``--fov``, which it replaces).
``--robot`` and ``--camera`` only choose the camera whose field of view stands in for
``--fov``, so they default to None (the hummingbird's first camera, filled in when used) and
either beside ``--fov`` or ``--calibration`` is refused: it would do nothing. It exits 0
whether or not a pad was found and 2 for bad input, with a message on stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

import cv2

from skeye import cliargs
from skeye.errors import ConfigError, LocalProtocolError
from skeye.image_files import read_image_file
from skeye.outputs import output_file, write_whole
from skeye.vision.detector import detect
from skeye.vision.pad import SKEYE_4, resolve_pad
from skeye.vision.printable import DEFAULT_DPI, MAX_DPI, MIN_DPI, write_printable

EXIT_BAD_INPUT = 2
PAD = "skeye pad"
DETECT = "skeye vision detect"
DEFAULT_ROBOT = "hummingbird"  # the robot whose camera gives the field of view without --fov


def _fail(command: str, message: str) -> int:
    """Say ``message`` as ``command``'s error on stderr (as every sub-command does)."""
    print(f"{command}: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def cmd_pad(args: argparse.Namespace) -> int:
    """Write the printable pad."""
    name = os.path.basename(args.out)
    if os.path.splitext(name)[1].lower() not in (".pdf", ".png"):  # named as given, before
        # the partial file it is written to (whose name the printer's own check would say)
        return _fail(PAD, f"--out {args.out}: a printable pad is .pdf or .png")
    if args.dpi is not None and name.lower().endswith(".pdf"):  # it would do nothing
        return _fail(PAD, f"--dpi sets a PNG's resolution; {name} is a PDF (vector: it has "
                     "none to set)")
    dpi = DEFAULT_DPI if args.dpi is None else args.dpi
    if not MIN_DPI <= dpi <= MAX_DPI:  # (the printer's own check did not name the option)
        return _fail(PAD, f"--dpi must be within {MIN_DPI}..{MAX_DPI} dots per inch, got {dpi}")
    out = args.out
    try:
        pad = resolve_pad(args.pad)
        # written whole or not at all: a partial file beside it, renamed over it once whole, so
        # a full disk or Ctrl-C part-way leaves the file that was there (it left one cut short,
        # or a valid PDF missing its later sheets)
        write_whole([("--out", output_file(Path(out), "--out"),
                      lambda partial: write_printable(pad, partial, dpi=dpi, paper=args.paper))])
    except (ConfigError, LocalProtocolError) as exc:
        return _fail(PAD, str(exc))
    if args.paper is None:
        print(f"wrote {out} ({pad.name}, side {pad.side_m} m, true scale)")
    else:
        from skeye.vision.printable import page_size_m, plan_tiles

        plan = plan_tiles(page_size_m(pad), args.paper)
        if len(plan.tiles) == 1:  # nothing to cut or lay (was "1 a4 sheets (1 rows x 1
            # columns ...); ... cut each sheet's left and top margins off ...")
            print(f"wrote {out} ({pad.name}, side {pad.side_m} m, true scale): one "
                  f"{args.paper} sheet; print at 100 %, check the 100 mm bar")
            return 0
        print(f"wrote {out} ({pad.name}, side {pad.side_m} m, true scale): {len(plan.tiles)} "
              f"{args.paper} sheets ({plan.rows} rows x {plan.cols} columns, "
              f"{'landscape' if plan.landscape else 'portrait'}); print at 100 %, check the "
              "100 mm bar, cut each sheet's left and top margins off at its cut marks, lay "
              "the sheets row by row on their + marks")
    return 0


def cmd_detect(args: argparse.Namespace) -> int:
    """Detect the pad in one image file and print the estimate as JSON."""
    calibration = None
    note = ""  # the field of view taken from the robot file, said on success
    if args.calibration is not None and args.fov is not None:  # one would do nothing
        return _fail(DETECT, "give --fov or --calibration, not both: the calibration's camera "
                     "matrix gives the geometry, --fov would be ignored")
    chosen = [flag for flag, value in (("--robot", args.robot), ("--camera", args.camera))
              if value is not None]
    if chosen and (args.fov is not None or args.calibration is not None):  # they would do nothing
        given = "--fov" if args.fov is not None else "--calibration"
        return _fail(DETECT, f"{' and '.join(chosen)} only choose the camera whose field of view "
                     f"is used without --fov or --calibration; {given} gives the geometry, so "
                     f"{'they' if len(chosen) > 1 else 'it'} would be ignored: give one or the "
                     "other")
    if args.calibration is not None:
        from skeye.vision.calibration import load_calibration

        try:
            calibration = load_calibration(args.calibration)
        except ConfigError as exc:
            return _fail(DETECT, str(exc))
        args.fov = calibration.fov_h_rad  # not used for the geometry: the matrix is
    if args.fov is None:  # the camera the frame most likely came from: the robot file's
        from skeye.robots.config import camera_model

        if args.robot is None:
            args.robot = DEFAULT_ROBOT
        try:
            model = camera_model(args.robot, args.camera)
        except ConfigError as exc:
            return _fail(DETECT, f"{exc}; give --fov")
        args.fov = model.fov_h_rad
        lens = (f"; its lens distorts (k1 {model.k1:g}): give --calibration for exact figures"
                if model.distorted else "")
        # said once the detection has run: a command that fails says its error alone
        note = (f"{DETECT}: --fov not given: using {args.fov:g} rad, the horizontal field of "
                f"view of robot {args.robot}'s camera ({model.profile} profile){lens}")
    if not math.isfinite(args.fov) or not 0.0 < args.fov < math.pi:
        return _fail(DETECT, f"--fov must be in (0, pi) radians, got {args.fov}")
    if (args.roll is None) != (args.pitch is None):
        return _fail(DETECT, "give both --roll and --pitch, or neither")
    for flag, value in (("--roll", args.roll), ("--pitch", args.pitch)):
        if value is not None and not (math.isfinite(value) and abs(value) < math.pi / 2):
            return _fail(DETECT, f"{flag} must be finite and within (-pi/2, pi/2) rad, got {value}")
    try:
        pad = resolve_pad(args.pad)
    except ConfigError as exc:
        return _fail(DETECT, str(exc))
    try:
        image = read_image_file(args.image, cv2.IMREAD_GRAYSCALE)
        est = detect(image, args.fov, pad=pad, roll_rad=args.roll, pitch_rad=args.pitch,
                     calibration=calibration)
    except (ConfigError, LocalProtocolError) as exc:
        return _fail(DETECT, str(exc))
    if note:
        print(note, file=sys.stderr)
    out: dict[str, Any] = est.to_json_dict()
    print(json.dumps(out))
    return 0


def register(subparsers: Any) -> None:
    """Add ``pad`` and ``vision detect`` to an argparse subparsers object."""
    p = subparsers.add_parser("pad", help="write the landing pad as a printable PDF or PNG")
    p.add_argument("--out", type=cliargs.path, required=True, help="output file, .pdf or .png")
    p.add_argument("--pad", default=SKEYE_4.name, help="built-in pad name or a pad .toml file")
    p.add_argument("--dpi", type=int, default=None,
                   help=f"PNG resolution (dots per inch, {MIN_DPI}..{MAX_DPI}; default "
                   f"{DEFAULT_DPI})")
    p.add_argument(
        "--paper",
        choices=("a4", "letter"),
        default=None,
        help="tile the pad over sheets of this paper (PDF), with overlap marks and a scale bar",
    )
    p.set_defaults(func=cmd_pad)

    v = subparsers.add_parser("vision", help="landing-pad vision tools")
    vsub = v.add_subparsers(dest="vision_command", required=True, metavar="COMMAND")
    d = vsub.add_parser("detect", help="detect the landing pad in an image, print JSON")
    d.add_argument("image", type=cliargs.path, help="image file (any format OpenCV reads)")
    d.add_argument(
        "--fov",
        type=float,
        default=None,
        help="horizontal field of view, rad (default: the --robot file's camera under its "
             "profile, e.g. 0.952 for the Hummingbird's webcam)",
    )
    d.add_argument("--robot", default=None,
                   help=f"robot class (or .toml) whose camera took the image, for the default "
                   f"FOV (default {DEFAULT_ROBOT}; not with --fov or --calibration)")
    d.add_argument("--camera", default=None,
                   help="that robot's camera name (default: its first; not with --fov or "
                   "--calibration)")
    d.add_argument("--roll", type=float, default=None, help="vehicle roll, rad (with --pitch)")
    d.add_argument("--pitch", type=float, default=None, help="vehicle pitch, rad (with --roll)")
    d.add_argument("--pad", default=SKEYE_4.name, help="built-in pad name or a pad .toml file")
    d.add_argument("--calibration", type=cliargs.path, default=None, metavar="CAMERA_TOML",
                   help="the camera's calibration from `skeye calibrate` (replaces --fov: not "
                   "with it; the lens distortion is corrected)")
    d.set_defaults(func=cmd_detect)
