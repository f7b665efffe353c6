"""``skeye snapshot``: save one camera frame from an image server as PNG or JPEG."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import cv2

from skeye import cliargs
from skeye.control.connection import DEFAULT_IMAGE_PORT, parse_address
from skeye.control.image_client import ImageClient
from skeye.errors import ConfigError, LinkClosed, LocalProtocolError, UnknownHost
from skeye.outputs import output_file, write_whole
from skeye.pixels import frame_image
from skeye.wire.image_requests import SelectCamera
from skeye.wire.images import JPEG_TYPES, FrameType

DEFAULT_QUALITY = 95  # skeye snapshot --out FILE.jpg without --quality
MAX_TIMEOUT_S = 3600.0
"""The longest --timeout: a socket takes no timeout past about 9.2e9 s (1e10 raised an
OverflowError from the connect), and an hour is longer than any wait for a frame."""


def save_snapshot(address: str, out: Path, camera: str | None = None,
                  quality: int | None = None,
                  timeout_s: float = 10.0) -> tuple[int, int, int | None]:
    """Fetch the newest frame and write it; returns (width, height, frame number).
    ``quality`` is a JPEG file's (default 95); a PNG file, lossless, refuses one. The file's
    folder is looked at before the server is asked: a missing or read-only one is named. The
    file is written whole or not at all: a write that fails leaves the file that was there."""
    suffix = out.suffix.lower()
    if suffix not in (".png", ".jpg", ".jpeg"):
        raise LocalProtocolError(f"{out}: the file name must end in .png, .jpg or .jpeg")
    if quality is not None and suffix == ".png":
        raise LocalProtocolError(f"--quality applies to a .jpg or .jpeg file, not {out.name} "
                                 "(PNG is lossless)")
    quality = DEFAULT_QUALITY if quality is None else quality
    if not 0.0 < timeout_s <= MAX_TIMEOUT_S:
        raise LocalProtocolError(f"--timeout must be over 0 and at most {MAX_TIMEOUT_S:g} s, "
                                 f"got {timeout_s:g}")
    if not 1 <= quality <= 100:
        raise LocalProtocolError(f"--quality (a JPEG file's) must be 1..100, got {quality}")
    output_file(out, "--out")  # its folder looked at before the server is asked
    if camera is not None:  # "" too: it is no camera name, not "the first camera"
        try:
            SelectCamera(camera)
        except LocalProtocolError as exc:
            raise LocalProtocolError(f"--camera: {exc}") from None
    try:
        host, port = parse_address(address, DEFAULT_IMAGE_PORT, "image server address")
    except LocalProtocolError as exc:
        raise LocalProtocolError(f"--images: {exc}") from None
    try:
        client = ImageClient(host, port, timeout_s=timeout_s)
    except UnknownHost as exc:  # no server to start there: the name is wrong
        raise ConfigError(f"--images: {exc.__cause__ or exc}") from None
    except LinkClosed as exc:
        where = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"  # as --images takes it
        why = exc.__cause__ or exc  # the socket's word: the address is named here already
        raise ConfigError(
            f"no image server at {where} ({why}): start the simulator "
            f"with one (`skeye sim --image-port {port}`; `skeye up` and `make run` serve "
            "images on 5003), or point --images at the one that runs"
        ) from None
    with client:
        if camera is not None:
            client.select_camera(camera)
        client.set_format("png" if suffix == ".png" else "jpeg", quality=quality)
        client.set_meta(True)
        frame = client.get_frame()
    image = frame_image(frame)  # the server's file, checked: it decodes whole
    # Written whole or not at all (a partial file beside it, renamed into place): a write that
    # failed part-way, a full disk, left the frame cut short where the earlier file was.
    if (frame.frame_type is FrameType.PNG if suffix == ".png"
            else frame.frame_type in JPEG_TYPES):
        # as the server encoded it: a JPEG compressed once, at the quality asked for
        write_whole([("--out", out, lambda path: path.write_bytes(frame.data))])
    else:  # a server that sent another format than the one asked for
        params = [] if suffix == ".png" else [cv2.IMWRITE_JPEG_QUALITY, quality]

        def encode(path: Path) -> None:
            if not cv2.imwrite(str(path), image, params):  # says no more than that
                raise OSError(f"OpenCV could not write a {suffix} file")

        write_whole([("--out", out, encode)])
    number = frame.meta.frame_number if frame.meta is not None else None
    return image.shape[1], image.shape[0], number


def cmd_snapshot(args: argparse.Namespace) -> int:
    width, height, number = save_snapshot(args.images, Path(args.out), args.camera, args.quality,
                                          args.timeout)
    print(f"saved {args.out}: {width}x{height}, frame {number}", file=sys.stdout)
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("snapshot", help="save one camera frame from the image server")
    p.add_argument("--images", default="127.0.0.1:5003", help="image server host:port")
    p.add_argument("--camera", default=None, help="robot/camera, e.g. R1/Down (default: first)")
    p.add_argument("--out", type=cliargs.path, required=True,
                   help="output file (.png, .jpg or .jpeg)")
    p.add_argument("--quality", type=int, default=None,
                   help=f"JPEG quality 1-100 of a .jpg or .jpeg --out (default {DEFAULT_QUALITY})")
    p.add_argument("--timeout", type=cliargs.positive_float, default=10.0,
                   help=f"seconds to wait for a frame (at most {MAX_TIMEOUT_S:g})")
    p.set_defaults(func=cmd_snapshot)
