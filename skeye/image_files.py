"""Still images read from files, with a JPEG or PNG cut short refused instead of half decoded.

How this works: OpenCV decodes a truncated JPEG without failing: libjpeg warns "Premature end
of JPEG file" on stderr and fills the missing rows with grey, so a half-copied frame would be
calibrated on or searched for the pad as if it were whole. :func:`read_image_file` therefore
first walks the file's structure (:func:`damage`): a JPEG's marker segments and entropy-coded
scans up to its end-of-image marker (FF D9), a PNG's chunks up to IEND. Bytes after that end
are allowed (some cameras pad their files). A file of another format goes to OpenCV as it is.
A 16-bit image is brought to 8 bits by the bits its data uses (a 12-bit sensor's frame in a
16-bit PNG is shifted right by 4, not 8: OpenCV's own conversion left it 16 grey levels);
a floating-point one (PFM, a 32-bit TIFF, HDR) is refused: its range is the writer's choice.
Pixels are decoded as the sensor recorded them: an EXIF orientation tag (phones, some cameras)
is not applied, as the ``file://`` camera's video reader does not apply it either, since a field
of view and a calibration describe the sensor's rows and columns (rotated, a 4:3 frame's
horizontal field of view would be taken across its short side). A file declaring more pixels
than OpenCV decodes is refused with its size, not OpenCV's assertion.
Every command and tool that reads a still image from a file (``skeye vision detect``, ``skeye
calibrate``, the ``file://`` camera given a photo) goes through here, so they agree.
"""

from __future__ import annotations

import mmap
import os
import struct
from pathlib import Path

import cv2
import numpy as np

from skeye.errors import ConfigError
from skeye.pixels import declared_size
from skeye.wire.images import FrameType

JPEG_SOI = b"\xff\xd8"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_CHUNK = struct.Struct(">I4s")  # length, type; then the data and a 4-byte CRC
_Bytes = bytes | mmap.mmap  # a file's bytes, or the file mapped into memory


def _jpeg_damage(data: _Bytes) -> str | None:
    """What is wrong with a JPEG (which starts with SOI), or None when it reaches its EOI."""
    n = len(data)
    cut = "the JPEG data ends before its end-of-image marker (FF D9)"
    i = len(JPEG_SOI)
    while True:
        if i >= n:
            return cut
        if data[i] != 0xFF:  # bytes between segments: libjpeg skips them with a warning
            i = data.find(b"\xff", i)
            if i < 0:
                return cut
        while i < n and data[i] == 0xFF:  # fill bytes before a marker
            i += 1
        if i >= n:
            return cut
        marker = data[i]
        i += 1
        if marker == 0x00:  # FF 00 is no marker: libjpeg skips it with the stray bytes
            continue
        if marker == 0xD9:  # EOI: whole; anything after it is padding
            return None
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:  # TEM, RSTn: no length
            continue
        if i + 2 > n:
            return cut
        length = (data[i] << 8) | data[i + 1]
        if length < 2:
            return f"the JPEG data has a segment of impossible length {length} (byte {i})"
        i += length
        if i > n:
            return cut
        if marker != 0xDA:  # not SOS: the next marker follows the segment
            continue
        while True:  # the entropy-coded scan: up to the first FF that is not data or RSTn
            j = data.find(b"\xff", i)
            if j < 0 or j + 1 >= n:
                return cut
            following = data[j + 1]
            if following == 0x00 or 0xD0 <= following <= 0xD7:
                i = j + 2
            elif following == 0xFF:
                i = j + 1
            else:
                i = j
                break


def _png_damage(data: _Bytes) -> str | None:
    """What is wrong with a PNG (which starts with its signature), or None when it reaches
    its IEND chunk."""
    n = len(data)
    i = len(PNG_SIGNATURE)
    while True:
        if i + _PNG_CHUNK.size > n:
            return "the PNG data ends before its IEND chunk"
        length, kind = _PNG_CHUNK.unpack(data[i : i + _PNG_CHUNK.size])
        i += _PNG_CHUNK.size + length + 4
        if i > n:
            return "the PNG data ends before its IEND chunk"
        if kind == b"IEND":
            return None


def damage(data: _Bytes) -> str | None:
    """Why a JPEG or PNG file's bytes are cut short or malformed, or None when they are whole
    (or of another format, which this does not judge). Bytes after the image's end are
    allowed."""
    if data[: len(JPEG_SOI)] == JPEG_SOI:
        return _jpeg_damage(data)
    if data[: len(PNG_SIGNATURE)] == PNG_SIGNATURE:
        return _png_damage(data)
    return None


def file_damage(path: str | Path) -> str | None:
    """:func:`damage` of a file, read through a memory map (a long MJPEG stream is walked only
    up to its first frame's end); None for what is not a regular file. OSError if the file
    cannot be opened."""
    if not Path(path).is_file():  # a FIFO or a device: not read here (opening may block)
        return None
    with open(path, "rb") as f:
        if f.seek(0, 2) == 0:
            return None
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as view:
            return damage(view)


def read_image_file(path: str | Path, flags: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """The pixels of an image file (any format OpenCV reads), decoded with ``flags``
    (``cv2.IMREAD_GRAYSCALE``: one channel), in the sensor's orientation (an EXIF orientation
    tag is ignored).

    Raises:
        ConfigError: naming the file: missing, unreadable, truncated or corrupt, or not an image.
    """
    if not Path(path).is_file():  # missing, a directory, or a FIFO (reading it may block)
        if Path(path).is_dir():
            raise ConfigError(f"{path} is a folder, not an image file (give its images, "
                              f"e.g. {Path(path) / '*.png'})")
        if Path(path).exists():
            raise ConfigError(f"{path} is not a regular file (a pipe or a device): give an "
                              "image file")
        raise ConfigError(f"no such image file: {path}")
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read image file {path}: {exc.strerror or exc}") from None
    problem = damage(data)
    if problem is not None:
        raise ConfigError(f"image {path} is truncated or corrupt: {problem}")
    try:
        image = (cv2.imdecode(np.frombuffer(data, np.uint8),
                              flags | cv2.IMREAD_IGNORE_ORIENTATION | cv2.IMREAD_ANYDEPTH)
                 if data else None)
        if image is None and data:  # a colour float TIFF does not decode as grey: as it is
            image = cv2.imdecode(np.frombuffer(data, np.uint8),
                                 cv2.IMREAD_UNCHANGED | cv2.IMREAD_IGNORE_ORIENTATION)
            if image is not None and image.dtype in (np.uint8, np.uint16):
                image = None  # (it decodes only unchanged: OpenCV's refusal stands)
        if image is not None and image.dtype == np.uint16:
            image = _to_8_bits(image)
        elif image is not None and image.dtype != np.uint8:  # float (TIFF, PFM, HDR, EXR)
            # Their range is the writer's choice, and OpenCV's own 8 bits are no grey levels to
            # take: a PFM of 0..1 became 0 and 1 (the pad "not found", status 0), a 32-bit
            # float TIFF nothing ("not a supported image format?"), a Radiance HDR a gamma curve.
            raise ConfigError(f"image {path} has {image.dtype} samples, which are not brought "
                              "to 8 bits (their range is the writer's choice): save it with 8 "
                              "or 16 bits")
    except cv2.error as exc:  # OpenCV refuses, with an assertion, what it will not decode
        raise ConfigError(f"image {path} does not decode: {_too_large(data) or _reason(exc)}"
                          ) from None
    if image is None:
        if data.startswith((JPEG_SOI, PNG_SIGNATURE)):
            kind = "JPEG" if data.startswith(JPEG_SOI) else "PNG"
            raise ConfigError(f"image {path} is corrupt: its {kind} data does not decode")
        raise ConfigError(f"cannot read image (not a supported image format?): {path}")
    return image


def _to_8_bits(image: np.ndarray) -> np.ndarray:
    """A 16-bit image as 8 bits, by the bits its data uses: a 12-bit sensor's frame kept in a
    16-bit PNG (0..4095) is shifted right by 4, not 8. OpenCV's own conversion divides by 256
    whatever the data, which left such a frame 16 grey levels (0..15), a 10-bit one 4: the
    pad was not found in it. A frame that uses all 16 bits is converted as OpenCV does."""
    top = int(image.max())
    shift = max(0, top.bit_length() - 8)
    return (image >> shift).astype(np.uint8)


def _too_large(data: bytes) -> str | None:
    """Why OpenCV will not decode a JPEG or PNG whose header declares more pixels than it
    decodes (``OPENCV_IO_MAX_IMAGE_PIXELS``, 2^30 by default); None otherwise."""
    kind = FrameType.PNG if data.startswith(PNG_SIGNATURE) else FrameType.JPEG_SUPER
    size = declared_size(kind, data)
    try:
        limit = int(os.environ.get("OPENCV_IO_MAX_IMAGE_PIXELS", 1 << 30))
    except ValueError:
        limit = 1 << 30
    if size is None or size[0] * size[1] <= limit:
        return None
    width, height = size
    return (f"it declares {width}x{height} px ({width * height} pixels), more than the "
            f"{limit} OpenCV decodes (OPENCV_IO_MAX_IMAGE_PIXELS)")


def _reason(exc: cv2.error) -> str:
    """OpenCV's one-line reason, without its source location."""
    lines = str(exc).strip().splitlines()
    return lines[-1].split(" error: ", 1)[-1] if lines else "OpenCV refused it"
