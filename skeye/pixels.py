"""Pixels to image-protocol payloads and back, with OpenCV: RAW, JPEG and PNG.

How this works: the image server renders RGB arrays; :func:`encode_image` turns one into the
frame type and payload of the format a client asked for (:mod:`skeye.wire.images` frames it).
A client turns a received :class:`~skeye.wire.images.DecodedFrame` back into pixels with
:func:`frame_image` (BGR, OpenCV's order) or :func:`frame_image_rgb`. This is the half of the
image protocol that needs an image codec, so it lives outside the sans-IO :mod:`skeye.wire`.
"""

from __future__ import annotations

import struct

import cv2
import numpy as np

from skeye.errors import LocalProtocolError, RemoteProtocolError
from skeye.wire.images import (
    MAX_RAW_SIDE_PX,
    RAW_PREFIX,
    RAW_PREFIX_BYTES,
    DecodedFrame,
    FrameType,
    ImageFormat,
    check_quality,
    decode_raw,
    jpeg_type_for_quality,
    raw_row_bytes,
)

MAX_DECODED_PIXELS = 8192 * 8192
"""The most pixels a received JPEG or PNG may declare: the simulator's largest camera (8192 px a
side, skeye/sim/cameras.py). A few hundred KiB of PNG can declare 30000x30000 px, 2.7 GB of
BGR; the size is read from the file's header and checked before anything is decoded."""

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# JPEG start-of-frame markers (SOF0-SOF15 but DHT 0xC4, JPG 0xC8, DAC 0xCC): height, width.
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def declared_size(frame_type: FrameType, data: bytes) -> tuple[int, int] | None:
    """(width, height) a PNG's IHDR or a JPEG's start-of-frame header declares, read without
    decoding; None when ``data`` is not a file of the frame's type or has no such header."""
    if frame_type is FrameType.PNG:
        if len(data) >= 24 and data[:8] == _PNG_SIGNATURE and data[12:16] == b"IHDR":
            width, height = struct.unpack_from(">II", data, 16)
            return int(width), int(height)
        return None
    if data[:2] != b"\xff\xd8":  # JPEG: SOI, then marker segments up to the frame header
        return None
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # a fill byte
            i += 1
        elif marker == 0x01 or 0xD0 <= marker <= 0xD7:  # TEM, RSTn: no length
            i += 2
        elif marker in (0xD9, 0xDA):  # EOI or SOS before any frame header
            return None
        elif marker in _JPEG_SOF:
            if i + 9 > len(data):
                return None
            height, width = struct.unpack_from(">HH", data, i + 5)
            return int(width), int(height)
        else:
            i += 2 + int.from_bytes(data[i + 2 : i + 4], "big")
    return None


def _check_rgb(rgb: np.ndarray) -> None:
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8:
        raise LocalProtocolError("image must be a uint8 numpy array")
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] == 0 or rgb.shape[1] == 0:
        raise LocalProtocolError(f"image must have shape (H, W, 3) with H, W > 0, got {rgb.shape}")


def raw_payload(rgb: np.ndarray) -> bytes:
    """UPIS raw: uint16 BE width, height, then B, G, R rows top to bottom padded to 4 bytes."""
    _check_rgb(rgb)
    height, width = rgb.shape[:2]
    if width > MAX_RAW_SIDE_PX or height > MAX_RAW_SIDE_PX:
        raise LocalProtocolError(f"RAW frames are at most 65535 px a side, got {width}x{height}")
    row = raw_row_bytes(width)
    out = np.empty(RAW_PREFIX_BYTES + row * height, dtype=np.uint8)
    out[:RAW_PREFIX_BYTES] = np.frombuffer(RAW_PREFIX.pack(width, height), dtype=np.uint8)
    rows = out[RAW_PREFIX_BYTES:].reshape(height, row)
    if row == 3 * width:
        # cv2 swaps channels straight into the output, several times faster than numpy's
        # reversed-stride copy; it needs a C-contiguous source.
        cv2.cvtColor(
            np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR, dst=rows.reshape(height, width, 3)
        )
    else:
        rows[:, 3 * width :] = 0
        rows[:, : 3 * width].reshape(height, width, 3)[...] = rgb[:, :, ::-1]
    return out.tobytes()


def jpeg_payload(rgb: np.ndarray, quality: int) -> bytes:
    """A JPEG file of ``rgb`` at ``quality`` (1-100)."""
    _check_rgb(rgb)
    check_quality(quality)
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise LocalProtocolError(f"JPEG encoding failed for a {rgb.shape} image")
    return buf.tobytes()


# zlib level 1 with the "up" row filter: about twice as fast as OpenCV's default adaptive filter
# on rendered images, for a similar size. Lossless either way.
_PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1]
if hasattr(cv2, "IMWRITE_PNG_FILTER"):
    _PNG_PARAMS += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_UP]


def png_payload(rgb: np.ndarray) -> bytes:
    """A PNG file of ``rgb`` (lossless)."""
    _check_rgb(rgb)
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", bgr, _PNG_PARAMS)
    if not ok:
        raise LocalProtocolError(f"PNG encoding failed for a {rgb.shape} image")
    return buf.tobytes()


def encode_image(
    rgb: np.ndarray, kind: ImageFormat, quality: int | None
) -> tuple[FrameType, bytes]:
    """The base frame type and payload of ``rgb`` in a format (quality for JPEG only)."""
    if kind is ImageFormat.RAW:
        return FrameType.RAW, raw_payload(rgb)
    if kind is ImageFormat.PNG:
        return FrameType.PNG, png_payload(rgb)
    if kind is ImageFormat.JPEG:
        if quality is None:
            raise LocalProtocolError("JPEG needs a quality 1-100")
        return jpeg_type_for_quality(quality), jpeg_payload(rgb, quality)
    raise LocalProtocolError(f"unknown image format {kind!r}")


def frame_image(frame: DecodedFrame) -> np.ndarray:
    """The image as an (H, W, 3) BGR uint8 array (OpenCV's order).

    Raises:
        RemoteProtocolError: the data does not decode, or disagrees with the META header.
    """
    if frame.frame_type is FrameType.RAW:
        img = decode_raw(frame.data)
    else:
        if not frame.data:  # OpenCV raises its own error on an empty buffer
            raise RemoteProtocolError(f"{frame.frame_type.name} frame with no image data")
        base = FrameType.PNG if frame.frame_type is FrameType.PNG else FrameType.JPEG_SUPER
        size = declared_size(base, frame.data)
        kind = "PNG" if base is FrameType.PNG else "JPEG"
        if size is None:
            raise RemoteProtocolError(f"{frame.frame_type.name} frame of {len(frame.data)} "
                                      f"bytes does not decode: no {kind} header")
        if size[0] * size[1] > MAX_DECODED_PIXELS:
            raise RemoteProtocolError(
                f"{frame.frame_type.name} frame declares {size[0]}x{size[1]} px, over the "
                f"{MAX_DECODED_PIXELS} px (8192x8192) an image may have: not decoded")
        img_or_none = cv2.imdecode(np.frombuffer(frame.data, np.uint8), cv2.IMREAD_COLOR)
        if img_or_none is None:
            raise RemoteProtocolError(
                f"{frame.frame_type.name} frame of {len(frame.data)} bytes does not decode"
            )
        img = img_or_none
    if frame.meta is not None and img.shape[:2] != (frame.meta.height, frame.meta.width):
        raise RemoteProtocolError(
            f"image is {img.shape[1]}x{img.shape[0]} but META says "
            f"{frame.meta.width}x{frame.meta.height}"
        )
    return img


def frame_image_rgb(frame: DecodedFrame) -> np.ndarray:
    """The image in RGB order."""
    return np.ascontiguousarray(frame_image(frame)[:, :, ::-1])
