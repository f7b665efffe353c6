"""Still image files (skeye.image_files): a JPEG or PNG cut short is refused, naming the file;
a whole one, with or without bytes after its end, decodes as OpenCV's own reader decodes it.

OpenCV decodes the first 60 % of a JPEG without failing (libjpeg only warns "Premature end of
JPEG file" on stderr and paints the rest grey), so ``skeye vision detect`` and ``skeye
calibrate`` used to work on such a frame as if it were whole.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from skeye.errors import ConfigError
from skeye.image_files import damage, file_damage, read_image_file


def _picture() -> np.ndarray:
    """A 240x320 colour picture with detail everywhere (so every part of the file matters)."""
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:240, 0:320]
    base = np.stack([x * 255 // 319, y * 255 // 239, (x + y) % 256], axis=-1)
    return np.clip(base + rng.integers(-40, 40, base.shape), 0, 255).astype(np.uint8)


ENCODINGS = {
    "baseline.jpg": (".jpg", []),
    "progressive.jpg": (".jpg", [cv2.IMWRITE_JPEG_PROGRESSIVE, 1]),
    "restart.jpg": (".jpg", [cv2.IMWRITE_JPEG_RST_INTERVAL, 2]),
    "best.jpg": (".jpg", [cv2.IMWRITE_JPEG_QUALITY, 100]),
    "picture.png": (".png", []),
}
PADDING = [b"\x00" * 512, b"\xff" * 7, b"trailing camera data\n"]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    picture = _picture()
    return {name: cv2.imencode(ext, picture, params)[1].tobytes()
            for name, (ext, params) in ENCODINGS.items()}


@pytest.mark.parametrize("name", ENCODINGS)
@pytest.mark.parametrize("keep", [0.6, 0.05, 0.95, -1, -2])
def test_a_file_cut_short_is_refused_naming_it(files: dict[str, bytes], tmp_path: Path,
                                               name: str, keep: float) -> None:
    data = files[name]
    cut = data[: int(len(data) * keep)] if keep > 0 else data[:keep]
    path = tmp_path / name
    path.write_bytes(cut)
    kind = "JPEG" if name.endswith(".jpg") else "PNG"
    with pytest.raises(ConfigError, match=rf"^image {path} is truncated or corrupt: the {kind} "
                       "data ends before its (end-of-image marker|IEND chunk)"):
        read_image_file(path, cv2.IMREAD_GRAYSCALE)
    assert file_damage(path) == damage(cut) is not None


@pytest.mark.parametrize("name", ENCODINGS)
@pytest.mark.parametrize("padding", [b"", *PADDING])
def test_a_whole_file_decodes_as_opencv_reads_it_padding_or_not(
        files: dict[str, bytes], tmp_path: Path, name: str, padding: bytes) -> None:
    """Some cameras pad their JPEGs after the end-of-image marker: those are whole."""
    whole = tmp_path / f"whole-{name}"
    whole.write_bytes(files[name])
    padded = tmp_path / name
    padded.write_bytes(files[name] + padding)
    assert damage(files[name] + padding) is None and file_damage(padded) is None
    for flags in (cv2.IMREAD_COLOR, cv2.IMREAD_GRAYSCALE):
        assert np.array_equal(read_image_file(padded, flags), cv2.imread(str(whole), flags))


def test_what_is_not_a_whole_image_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=f"^no such image file: {tmp_path / 'none.png'}$"):
        read_image_file(tmp_path / "none.png")
    # A folder and a pipe exist: "no such image file" sent the user looking for a typo.
    with pytest.raises(ConfigError, match=f"^{tmp_path} is a folder, not an image file"):
        read_image_file(tmp_path)
    os.mkfifo(tmp_path / "pipe.png")
    with pytest.raises(ConfigError, match=r"pipe\.png is not a regular file"):
        read_image_file(tmp_path / "pipe.png")  # never opened: reading a FIFO may block
    for name, data in [("empty.png", b""), ("notes.png", b"not an image\n")]:
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ConfigError, match=r"cannot read image \(not a supported image "
                           rf"format\?\): {tmp_path / name}$"):
            read_image_file(tmp_path / name)
        assert file_damage(tmp_path / name) is None  # another format: OpenCV's to judge
    # Whole in structure, but its scan data is no JPEG: OpenCV's decoder says no.
    bad = tmp_path / "bad.jpg"
    bad.write_bytes(b"\xff\xd8\xff\xda\x00\x02\x00\x00\xff\xd9")
    with pytest.raises(ConfigError, match=f"^image {bad} is corrupt: its JPEG data does not"):
        read_image_file(bad)


def test_a_long_stream_of_jpegs_is_judged_by_its_first(files: dict[str, bytes],
                                                       tmp_path: Path) -> None:
    """A raw MJPEG stream (JPEGs end to end) is read through a memory map up to its first
    frame's end: the file camera's check does not read a whole video."""
    stream = tmp_path / "stream.mjpeg"
    stream.write_bytes(files["baseline.jpg"] * 3 + files["baseline.jpg"][:100])
    assert file_damage(stream) is None
    stream.write_bytes(files["baseline.jpg"][:-10])
    assert file_damage(stream) is not None


def test_stray_bytes_between_segments_are_skipped_as_libjpeg_does(files: dict[str, bytes],
                                                                  tmp_path: Path) -> None:
    """Bytes between two marker segments (libjpeg: "extraneous bytes before marker", a warning)
    decode as the file without them: such a photo is whole, not refused."""
    data = files["baseline.jpg"]
    app0_end = 4 + int.from_bytes(data[4:6], "big")  # SOI, then the APP0 segment
    assert data[app0_end] == 0xFF
    stray = tmp_path / "stray.jpg"
    stray.write_bytes(data[:app0_end] + b"camera junk" + data[app0_end:])
    assert damage(stray.read_bytes()) is None
    assert np.array_equal(read_image_file(stray), cv2.imdecode(np.frombuffer(data, np.uint8),
                                                               cv2.IMREAD_COLOR))
    # An FF 00 among them is no marker (libjpeg skips it too), not a segment of length 1.
    with_ff00 = data[:app0_end] + b"\xff\x00\x00\x01" + data[app0_end:]
    assert damage(with_ff00) is None
    assert np.array_equal(cv2.imdecode(np.frombuffer(with_ff00, np.uint8), cv2.IMREAD_COLOR),
                          cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
    # Cut short after the stray bytes: still refused.
    with pytest.raises(ConfigError, match="truncated or corrupt"):
        stray.write_bytes(data[:app0_end] + b"camera junk" + data[app0_end:-300])
        read_image_file(stray)


def with_exif_orientation(jpeg: bytes, orientation: int) -> bytes:
    """A JPEG with an EXIF APP1 segment holding one tag, Orientation (0x0112), after SOI."""
    tiff = (b"II*\x00" + (8).to_bytes(4, "little") + (1).to_bytes(2, "little")
            + (0x0112).to_bytes(2, "little") + (3).to_bytes(2, "little")
            + (1).to_bytes(4, "little") + orientation.to_bytes(2, "little") + b"\x00\x00"
            + (0).to_bytes(4, "little"))
    body = b"Exif\x00\x00" + tiff
    return jpeg[:2] + b"\xff\xe1" + (len(body) + 2).to_bytes(2, "big") + body + jpeg[2:]


def test_an_exif_orientation_tag_is_not_applied(files: dict[str, bytes], tmp_path: Path) -> None:
    """A photo tagged "rotate 90" (phones, some cameras) came out 240 wide and 320 high, so
    ``skeye vision detect`` took the horizontal field of view across the sensor's short side
    (a pad at 2.0 m measured 1.5 m, quality 0.92), a calibration refused it for its size, and
    the ``file://`` camera (OpenCV's video reader: the sensor's rows) saw another frame."""
    tagged = tmp_path / "tagged.jpg"
    tagged.write_bytes(with_exif_orientation(files["baseline.jpg"], 6))
    assert cv2.imread(str(tagged)).shape == (320, 240, 3)  # OpenCV's own reader rotates it
    plain = cv2.imdecode(np.frombuffer(files["baseline.jpg"], np.uint8), cv2.IMREAD_GRAYSCALE)
    assert np.array_equal(read_image_file(tagged, cv2.IMREAD_GRAYSCALE), plain)
    capture = cv2.VideoCapture(str(tagged))
    ok, frame = capture.read()
    capture.release()
    assert ok and frame.shape == read_image_file(tagged).shape == (240, 320, 3)


def _png_declaring(width: int, height: int) -> bytes:
    """A whole PNG (grey, 8 bit) whose header declares ``width`` x ``height`` and whose data
    holds a few rows: small on disk, more pixels than OpenCV decodes."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    rows = zlib.compress(b"\x00" * (width + 1) * 4)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", rows)
            + chunk(b"IEND", b""))


def test_a_file_declaring_more_pixels_than_opencv_decodes_is_named(tmp_path: Path) -> None:
    """OpenCV refuses it with an assertion (cv2.error), which went up through ``skeye vision
    detect`` and ``skeye calibrate`` as a traceback (exit status 1)."""
    big = tmp_path / "big.png"
    big.write_bytes(_png_declaring(60000, 60000))
    with pytest.raises(ConfigError, match=rf"^image {big} does not decode: it declares "
                       r"60000x60000 px \(3600000000 pixels\), more than the 1073741824 "
                       "OpenCV decodes"):
        read_image_file(big, cv2.IMREAD_GRAYSCALE)


@pytest.mark.parametrize("suffix", [".tiff", ".pfm"])
def test_a_floating_point_image_is_said_to_be_one(tmp_path: Path, suffix: str) -> None:
    """A 32-bit float TIFF, which OpenCV reads only as floats, was said to be "not a supported
    image format?"; a PFM of 0..1 was read as OpenCV brings it to 8 bits, 0 and 1 (a frame
    with the pad was "not found"). Their samples are named, with the 8 or 16 bits read."""
    path = tmp_path / f"frame{suffix}"
    grey = np.linspace(0.0, 1.0, 64 * 48, dtype=np.float32).reshape(48, 64)
    assert cv2.imwrite(str(path), cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR))
    with pytest.raises(ConfigError, match=r"float32 samples.*8 or 16 bits") as info:
        read_image_file(path, cv2.IMREAD_GRAYSCALE)
    assert str(path) in str(info.value)
