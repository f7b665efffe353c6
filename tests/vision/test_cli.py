"""The ``pad`` and ``vision detect`` subcommands, through a small argparse main."""

from __future__ import annotations

import argparse
import json
import math
import re
import signal
import subprocess
import sys
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from skeye.vision.camera import render_pad_view
from skeye.vision.cli import register
from skeye.vision.pad import SKEYE_4
from tests.robustness.helpers import skeye_under_a_file_size_limit, wait_for

from .helpers import FOV_H_RAD, H, W


def run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="skeye")
    sub = parser.add_subparsers(dest="command", required=True)
    register(sub)
    args = parser.parse_args(argv)
    return int(args.func(args))


@pytest.fixture(scope="module")
def pad_png(tmp_path_factory):
    path = tmp_path_factory.mktemp("img") / "frame.png"
    roll, pitch = 0.1, -0.12
    img = render_pad_view(
        SKEYE_4, W, H, FOV_H_RAD, 1.2, (0.1, -0.2), roll_rad=roll, pitch_rad=pitch
    )
    cv2.imwrite(str(path), img)
    return path


def test_detect_prints_json(pad_png, capsys):
    rc = run(
        ["vision", "detect", str(pad_png), "--fov", "1.309", "--roll", "0.1", "--pitch", "-0.12"]
    )
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert out["found"] is True and out["rings"] == [1, 2, 3, 4]
    assert out["height_m"] == pytest.approx(1.2, rel=0.01)
    assert out["offset_cam_m"] == pytest.approx([0.1, -0.2], abs=0.01)
    assert out["offset_body_m"] == pytest.approx([0.2, 0.1], abs=0.01)
    assert 0 < out["quality"] <= 1 and len(out["center_px"]) == 2


def test_detect_without_attitude_takes_camera_level(tmp_path, capsys):
    path = tmp_path / "level.png"
    cv2.imwrite(str(path), render_pad_view(SKEYE_4, W, H, FOV_H_RAD, 0.9, (-0.1, 0.15)))
    assert run(["vision", "detect", str(path), "--fov", "1.309", "--pad", "skeye-4"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["found"] is True
    assert out["height_m"] == pytest.approx(0.9, rel=0.01)
    assert out["offset_cam_m"] == pytest.approx([-0.1, 0.15], abs=0.01)


def test_detect_not_found_exits_zero_with_nulls(tmp_path, capsys):
    path = tmp_path / "blank.png"
    cv2.imwrite(str(path), render_pad_view(SKEYE_4, W, H, FOV_H_RAD, 1.0, (5.0, 5.0)))
    assert run(["vision", "detect", str(path), "--fov", "1.309"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out == {
        "found": False,
        "center_px": None,
        "height_m": None,
        "offset_cam_m": None,
        "offset_body_m": None,
        "rings": [],
        "quality": 0.0,
    }


@pytest.mark.parametrize(
    "extra,match",
    [
        (["--fov", "0"], "--fov"),
        (["--fov", "nan"], "--fov"),
        (["--fov", "1.3", "--roll", "0.1"], "--roll and --pitch"),
        (["--fov", "1.3", "--pad", "nope"], "unknown pad"),
        # in (0, pi), but no focal length: a ZeroDivisionError traceback, and Infinity and NaN
        # (no JSON) printed for the height and offsets
        (["--fov", "5e-324"], "too small"),
        (["--fov", "1e-308"], "too small"),
        # said as detect()'s "roll_rad must be ...", a name the command line does not have
        (["--fov", "1.3", "--roll", "2", "--pitch", "0"],
         "error: --roll must be finite and within (-pi/2, pi/2) rad, got 2.0"),
        (["--fov", "1.3", "--roll", "0", "--pitch", "nan"],
         "error: --pitch must be finite and within (-pi/2, pi/2) rad, got nan"),
    ],
)
def test_detect_bad_values(pad_png, capsys, extra, match):
    assert run(["vision", "detect", str(pad_png), *extra]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and match in captured.err


def test_detect_missing_and_unreadable_image(tmp_path, capsys):
    assert run(["vision", "detect", str(tmp_path / "none.png"), "--fov", "1.3"]) == 2
    assert "no such image" in capsys.readouterr().err
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"this is not a png")
    assert run(["vision", "detect", str(junk), "--fov", "1.3"]) == 2
    assert "cannot read image" in capsys.readouterr().err


def test_detect_without_fov_needs_a_robot_with_a_camera(pad_png, capsys):
    # --fov used to be required (issue 21 made it default to the robot file's camera); with no
    # usable robot file the command still refuses, naming the problem.
    assert run(["vision", "detect", str(pad_png), "--robot", "no_such_robot"]) == 2
    assert "unknown robot class 'no_such_robot'" in capsys.readouterr().err


def test_pad_refuses_a_dpi_for_a_pdf(tmp_path, capsys):
    """--dpi is a PNG's resolution: with a .pdf (or --paper) it was accepted and ignored, the
    vector PDF written as if it had one; it is refused before anything is written."""
    for extra in ([], ["--paper", "a4"]):
        pdf = tmp_path / "pad.pdf"
        assert run(["pad", "--out", str(pdf), "--dpi", "600", *extra]) == 2
        err = capsys.readouterr().err
        assert err.startswith("skeye pad: error: --dpi sets a PNG's resolution; pad.pdf is a "
                              "PDF"), err
        assert not pdf.exists()


def test_pad_refuses_another_extension_naming_the_out_given(tmp_path, capsys):
    """A .txt --out was refused by the printer's own check, which named the partial file it
    was being written to ('.pad.15423.partial.txt'), a file the user never gave."""
    out = tmp_path / "pad.txt"
    assert run(["pad", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}: a printable pad is .pdf or .png" in err, err
    assert "partial" not in err
    assert list(tmp_path.iterdir()) == []


def test_pad_command_writes_files(tmp_path, capsys):
    pdf = tmp_path / "pad.pdf"
    assert run(["pad", "--out", str(pdf)]) == 0
    assert pdf.read_bytes().startswith(b"%PDF")
    png = tmp_path / "pad.png"
    assert run(["pad", "--out", str(png), "--dpi", "30"]) == 0
    assert png.read_bytes().startswith(b"\x89PNG")
    assert run(["pad", "--out", str(tmp_path / "pad.jpg")]) == 2
    assert ".pdf or .png" in capsys.readouterr().err
    toml = tmp_path / "p.toml"
    toml.write_text("name = 'x'\nside_m = 0.3\nrings = [{outer_m = 0.1, inner_m = 0.2}]\n")
    assert run(["pad", "--out", str(pdf), "--pad", str(toml)]) == 2
    assert "p.toml" in capsys.readouterr().err


def test_a_pad_or_robot_file_that_is_not_utf8_is_named(pad_png, tmp_path, capsys):
    """A TOML saved as UTF-16 or Latin-1 (or a binary given by mistake): tomllib's
    UnicodeDecodeError escaped as a traceback from `skeye pad --pad` and `--robot FILE.toml`."""
    from skeye.cli import main

    latin1 = tmp_path / "latin1.toml"
    latin1.write_bytes("name = 'caf\u00e9'\n".encode("latin-1"))
    assert main(["pad", "--out", str(tmp_path / "pad.png"), "--pad", str(latin1)]) == 2
    assert capsys.readouterr().err.startswith(
        f"skeye pad: error: {latin1}: not valid TOML (not UTF-8 text): ")
    assert main(["vision", "detect", str(pad_png), "--robot", str(latin1)]) == 2
    assert capsys.readouterr().err.startswith(
        f"skeye vision detect: error: {latin1}: not valid TOML (not UTF-8 text): ")


def test_detect_takes_the_fov_from_the_robot_file_and_says_so(pad_png, capsys):
    """Without --fov: the robot's camera under its profile (the Hummingbird's webcam, 0.952 rad;
    the synthetic frame is a tilted 1.309 rad pinhole's, so the height comes out scaled by about
    the focal lengths' ratio), and the advice to calibrate a lens that distorts."""
    assert run(["vision", "detect", str(pad_png), "--roll", "0.1", "--pitch", "-0.12"]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    ratio = math.tan(1.309 / 2) / math.tan(0.9521046116251194 / 2)  # 1.49 (1.45 under tilt)
    assert out["found"] is True and out["height_m"] == pytest.approx(1.2 * ratio, rel=0.05)
    assert ("--fov not given: using 0.952105 rad, the horizontal field of view of robot "
            "hummingbird's camera (webcam profile); its lens distorts") in captured.err
    assert "give --calibration" in captured.err
    assert run(["vision", "detect", str(pad_png), "--fov", "1.309", "--roll", "0.1",
                "--pitch", "-0.12"]) == 0
    captured = capsys.readouterr()
    assert "--fov not given" not in captured.err
    assert json.loads(captured.out)["height_m"] == pytest.approx(1.2, rel=0.01)
    assert run(["vision", "detect", str(pad_png), "--camera", "Front"]) == 2
    assert ("has no camera named 'Front' (its cameras: Down); give --fov"
            in capsys.readouterr().err)
    # An image that cannot be read: the error alone, one line (the --fov note came first, and
    # made it two, about a detection that never ran)
    junk = pad_png.parent / "junk.png"
    junk.write_bytes(b"\x00\xffnot an image")
    assert run(["vision", "detect", str(junk)]) == 2
    err = capsys.readouterr().err
    assert err == (f"skeye vision detect: error: cannot read image (not a supported image "
                   f"format?): {junk}\n"), err


def test_pad_command_tiles_over_paper(tmp_path, capsys):
    out = tmp_path / "pad.pdf"
    assert run(["pad", "--out", str(out), "--paper", "letter"]) == 0
    assert "12 letter sheets (3 rows x 4 columns" in capsys.readouterr().out
    assert out.read_bytes().startswith(b"%PDF")
    assert run(["pad", "--out", str(tmp_path / "pad.png"), "--paper", "a4"]) == 2
    assert "--paper writes a PDF of sheets" in capsys.readouterr().err


def test_a_pad_on_one_sheet_is_not_said_to_need_cutting_and_laying(tmp_path, capsys):
    # A pad that fits one sheet was said as "1 a4 sheets (1 rows x 1 columns, portrait); ...
    # cut each sheet's left and top margins off at its cut marks, lay the sheets row by row"
    pad_file = tmp_path / "small.toml"
    pad_file.write_text("name = 'small'\nside_m = 0.1\nrings = [{outer_m = 0.05, inner_m = 0.04}, "
                        "{outer_m = 0.03, inner_m = 0.01}]")
    out = tmp_path / "small.pdf"
    assert run(["pad", "--out", str(out), "--pad", str(pad_file), "--paper", "a4"]) == 0
    said = capsys.readouterr().out
    assert said == (f"wrote {out} (small, side 0.1 m, true scale): one a4 sheet; print at "
                    "100 %, check the 100 mm bar\n"), said
    assert out.read_bytes().startswith(b"%PDF")


def test_detect_takes_a_calibration_file(tmp_path, capsys):
    """A rendered pad seen through k1 = -0.2: --calibration gives the true height back."""
    from skeye.vision.calibration import CameraCalibration
    from skeye.vision.camera import intrinsics
    from tests.vision.helpers import distort_image, wide_camera

    k = intrinsics(W, H, FOV_H_RAD)
    k_wide, w2, h2, fov_wide = wide_camera(k, W, H, 1.5)
    ideal = render_pad_view(SKEYE_4, w2, h2, fov_wide, 1.0, (0.05, -0.1))
    dist = (-0.2, 0.0, 0.0, 0.0, 0.0)
    path = tmp_path / "lens.png"
    cv2.imwrite(str(path), distort_image(ideal, k_wide, k, dist, (W, H)))
    cal = tmp_path / "camera.toml"
    CameraCalibration(W, H, k[0, 0], k[1, 1], k[0, 2], k[1, 2], dist).save(cal)
    assert run(["vision", "detect", str(path), "--calibration", str(cal)]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert out["found"] and out["height_m"] == pytest.approx(1.0, rel=0.002)
    assert "--fov not given" not in captured.err
    (tmp_path / "bad.toml").write_text("[camera]\nfx_px = 3\n")
    assert run(["vision", "detect", str(path), "--calibration", str(tmp_path / "bad.toml")]) == 2
    assert "missing required key" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv,command,match",
    [
        (["pad", "--out", "pad.jpg"], "skeye pad", ".pdf or .png"),
        (["pad", "--out", "pad.pdf", "--pad", "nope"], "skeye pad", "unknown pad"),
        (["vision", "detect", "{png}", "--fov", "4.0"], "skeye vision detect",
         "--fov must be in (0, pi) radians, got 4.0"),
        (["vision", "detect", "{png}", "--fov", "1.3", "--roll", "0.1"], "skeye vision detect",
         "give both --roll and --pitch"),
        (["vision", "detect", "none.png", "--fov", "1.3"], "skeye vision detect",
         "no such image file: none.png"),
    ],
)
def test_errors_name_the_sub_command(pad_png, tmp_path, monkeypatch, capsys, argv, command,
                                     match):
    """`skeye pad` and `skeye vision detect` said `skeye: error: ...`, naming no command, where
    every other sub-command says `skeye COMMAND: error: ...`."""
    from skeye.cli import main

    monkeypatch.chdir(tmp_path)
    assert main([a.format(png=pad_png) for a in argv]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith(f"{command}: error: ") and match in captured.err


def test_detect_refuses_a_truncated_jpeg_and_takes_a_padded_one(pad_png, tmp_path, capsys):
    """The first 60 % of a JPEG decoded (libjpeg only warned on stderr, painting the rest
    grey), and the pad was searched for in it as in a whole frame."""
    whole = cv2.imencode(".jpg", cv2.imread(str(pad_png)))[1].tobytes()
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(whole[: len(whole) * 6 // 10])
    assert run(["vision", "detect", str(cut), "--fov", "1.309"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (f"skeye vision detect: error: image {cut} is truncated or corrupt: "
                            "the JPEG data ends before its end-of-image marker (FF D9)\n")
    padded = tmp_path / "padded.jpg"  # some cameras pad after the end-of-image marker
    padded.write_bytes(whole + b"\x00" * 256)
    assert run(["vision", "detect", str(padded), "--fov", "1.309", "--roll", "0.1",
                "--pitch", "-0.12"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["found"] is True and out["height_m"] == pytest.approx(1.2, rel=0.01)
    png = pad_png.read_bytes()
    cut.write_bytes(png[: len(png) * 6 // 10])
    assert run(["vision", "detect", str(cut), "--fov", "1.309"]) == 2
    assert ("truncated or corrupt: the PNG data ends before its IEND chunk"
            in capsys.readouterr().err)


def test_detect_reads_a_tagged_photo_in_the_sensors_orientation(tmp_path, capsys):
    """An EXIF orientation tag ("rotate 90") turned the 800x600 frame into 600x800 before the
    detector saw it: the pad at 2.0 m measured 1.5 m (the horizontal field of view taken
    across the short side), quality 0.92, and a calibration refused the frame for its size."""
    from skeye.vision.calibration import CameraCalibration

    from ..test_image_files import with_exif_orientation

    frame = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, 2.0)
    photo = tmp_path / "photo.jpg"
    photo.write_bytes(with_exif_orientation(cv2.imencode(".jpg", frame)[1].tobytes(), 6))
    cal = tmp_path / "camera.toml"
    CameraCalibration.pinhole(W, H, FOV_H_RAD).save(cal)
    for extra in (["--fov", "1.309"], ["--calibration", str(cal)]):
        assert run(["vision", "detect", str(photo), *extra]) == 0
        out = json.loads(capsys.readouterr().out)
        assert out["found"] is True and out["height_m"] == pytest.approx(2.0, rel=0.005)
        assert out["center_px"] == pytest.approx([(W - 1) / 2, (H - 1) / 2], abs=0.5)


def test_detect_and_calibrate_name_an_image_too_large_to_decode(tmp_path, capsys):
    """A 12 KB PNG declaring 60000x60000 px: OpenCV's assertion (cv2.error) came out of both
    commands as a traceback, exit status 1."""
    from skeye.cli import main

    from ..test_image_files import _png_declaring

    big = tmp_path / "big.png"
    big.write_bytes(_png_declaring(60000, 60000))
    for argv, command in ((["vision", "detect", str(big), "--fov", "1.3"], "skeye vision detect"),
                          (["calibrate", str(big), "--out", str(tmp_path / "c.toml")],
                           "skeye calibrate")):
        assert main(argv) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        assert captured.err == (f"{command}: error: image {big} does not decode: it declares "
                                "60000x60000 px (3600000000 pixels), more than the 1073741824 "
                                "OpenCV decodes (OPENCV_IO_MAX_IMAGE_PIXELS)\n")


def test_detect_refuses_fov_beside_a_calibration(pad_png, tmp_path, capsys):
    """--calibration replaces --fov (its camera matrix gives the geometry): both given, one
    would do nothing, so the command is refused (status 2) naming both, before any image is
    read, as skeye sim, pilot and logs refuse options that would do nothing."""
    from skeye.vision.calibration import CameraCalibration

    cal = tmp_path / "camera.toml"
    CameraCalibration.pinhole(W, H, FOV_H_RAD).save(cal)
    rc = run(["vision", "detect", str(pad_png), "--fov", "0.5", "--calibration", str(cal)])
    captured = capsys.readouterr()
    assert rc == 2 and captured.out == ""
    assert captured.err.startswith("skeye vision detect: error: ")
    assert "--fov" in captured.err and "--calibration" in captured.err


@pytest.mark.parametrize("extra", [["--robot", "airrobot"], ["--camera", "Down"],
                                   ["--robot", "hummingbird", "--camera", "Down"]])
def test_detect_refuses_a_robot_or_camera_beside_fov_or_calibration(pad_png, tmp_path, capsys,
                                                                    extra):
    """--robot and --camera choose the camera whose field of view stands in for --fov; beside
    --fov or --calibration they would do nothing (they were ignored, status 0), so the command
    is refused (status 2) with one line naming the options, before any image is read."""
    from skeye.vision.calibration import CameraCalibration

    cal = tmp_path / "camera.toml"
    CameraCalibration.pinhole(W, H, FOV_H_RAD).save(cal)
    for given in (["--fov", "1.309"], ["--calibration", str(cal)]):
        assert run(["vision", "detect", str(pad_png), *given, *extra]) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.count("\n") == 1
        assert captured.err.startswith("skeye vision detect: error: ")
        for flag in (given[0], *(f for f in extra if f.startswith("--"))):
            assert flag in captured.err


@pytest.mark.parametrize("extra", [[], ["--paper", "a4"]], ids=["pdf", "tiled-pdf"])
def test_pad_a_failed_write_keeps_the_file_that_was_there(tmp_path, extra):
    """The pad was written in place: a write that failed part-way (a full disk; here the
    file size limit, ``ulimit -f``, which fails a write past it with EFBIG as a full disk
    does) left the first kilobytes of a PDF over the file that was there, and matplotlib's
    PDF backend, cleaning up, raised a zlib.error or AttributeError: a traceback, exit 1. It
    is now written beside and renamed over: exit 2 naming --out, the old file as it was, no
    partial file left."""
    out = tmp_path / "pad.pdf"
    out.write_bytes(b"the pad printed last week")
    run = skeye_under_a_file_size_limit(["pad", "--out", str(out), *extra], 4096)
    assert run.returncode == 2, run.stderr
    # the last line: matplotlib may warn first that its font cache cannot be saved
    assert run.stderr.splitlines()[-1] == (f"skeye pad: error: --out {out}: cannot write it: "
                                           "File too large"), run.stderr
    assert out.read_bytes() == b"the pad printed last week"
    assert [p.name for p in tmp_path.iterdir()] == ["pad.pdf"]


def test_pad_interrupted_leaves_no_part_of_a_tiled_pdf(tmp_path):
    """Ctrl-C while the sheets were drawn: PdfPages closed the file on its way out, leaving a
    valid PDF of the sheets drawn so far (41 of a 4 m pad's) where the whole pad was asked
    for, over the file that was there. Now nothing is written until every sheet is."""
    toml = tmp_path / "big.toml"
    toml.write_text("name = 'big'\nside_m = 4.0\n[[rings]]\nouter_m = 1.8\ninner_m = 1.5\n"
                    "[[rings]]\nouter_m = 1.0\ninner_m = 0.5\n")
    out = tmp_path / "pad.pdf"
    out.write_bytes(b"the pad printed last week")
    # SIGINT as a terminal leaves it: a runner started in the background of a shell (nohup
    # CMD &) hands its children SIGINT ignored, and the pad was drawn whole past the timeout
    proc = subprocess.Popen(
        [sys.executable, "-m", "skeye", "pad", "--out", str(out), "--paper", "a4", "--pad",
         str(toml)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        cwd=Path(__file__).resolve().parents[2],
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        # the sheets are being written once their file is open (a partial one beside --out;
        # before, --out itself)
        assert wait_for(lambda: len(list(tmp_path.iterdir())) > 2
                        or out.read_bytes() != b"the pad printed last week", timeout_s=120.0)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert err == "skeye pad: interrupted (Ctrl-C)\n"
    assert out.read_bytes() == b"the pad printed last week"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.toml", "pad.pdf"]


@pytest.mark.parametrize(("side", "sheets", "px"), [
    ("1e300", "2.16e+601", "1.18e+304"), ("1.7e308", "more than 1e+308", "more than 1e+308")])
def test_pad_far_too_large_for_sheets_is_refused_with_its_count(tmp_path, capsys, side, sheets,
                                                                px):
    """A pad file of a 1e300 m side with --paper: its count of sheets, an integer of 600
    digits, was formatted as a float, an OverflowError traceback (exit 1); near the largest
    float the count of rows was no finite number (math.ceil raised). It is refused, exit 2,
    with the count in three digits; so is the PNG, whose size was said as "inf px"."""
    toml = tmp_path / "huge.toml"
    toml.write_text(f"name = 'huge'\nside_m = {side}\n[[rings]]\nouter_m = 0.9\ninner_m = 0.5\n"
                    "[[rings]]\nouter_m = 0.4\ninner_m = 0.1\n")
    out = tmp_path / "pad.pdf"
    assert run(["pad", "--out", str(out), "--pad", str(toml), "--paper", "letter"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"skeye pad: error: a {float(side):g} m page needs {sheets} letter "
                          "sheets, over the 500 --paper writes"), err
    assert run(["pad", "--out", str(tmp_path / "pad.png"), "--pad", str(toml)]) == 2
    err = capsys.readouterr().err
    assert f"m page at 300 dpi is {px} px a side" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["huge.toml"]


@pytest.mark.parametrize("bits", [16, 12, 10])
def test_detect_reads_a_16_bit_frame_by_the_bits_it_uses(tmp_path, capsys, bits):
    """A 12-bit (or 10-bit) sensor's frame kept in a 16-bit PNG (0..4095) was brought to 8 bits
    by OpenCV's division by 256: 16 grey levels (4 for 10 bits), in which the pad was not
    found ("found": false, status 0: a silent wrong answer). It is shifted by the bits its
    data uses, and the pad is found as in the 8-bit frame; a frame using all 16 bits is read
    as before."""
    img = render_pad_view(SKEYE_4, W, H, FOV_H_RAD, 1.2, (0.1, -0.2))
    deep = np.round(img.astype(np.float64) / 255.0 * (2**bits - 1)).astype(np.uint16)
    path = tmp_path / f"frame{bits}.png"
    assert cv2.imwrite(str(path), deep)
    assert run(["vision", "detect", str(path), "--fov", str(FOV_H_RAD)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["found"] and out["rings"] == [1, 2, 3, 4], out
    assert out["height_m"] == pytest.approx(1.2, abs=0.01)
    assert out["offset_cam_m"] == pytest.approx([0.1, -0.2], abs=0.01)


def _pdf_text(path: Path) -> str:
    """The text a matplotlib PDF shows: its content streams' strings, in order."""
    text = []
    data = path.read_bytes()
    for stream in re.finditer(rb"stream\r?\n(.*?)\r?\nendstream", data, re.S):
        try:
            content = zlib.decompress(stream.group(1))
        except zlib.error:  # a font or an image, not a page's content
            continue
        for block in re.findall(rb"BT(.*?)ET", content, re.S):
            strings = re.findall(rb"\(((?:\\.|[^\\)])*)\)", block)
            text.append(b"".join(re.sub(rb"\\(.)", rb"\1", s) for s in strings).decode("latin-1"))
    return "\n".join(text)


@pytest.mark.parametrize("name", ["pad$1$", "a$$", "x_y^2"])
def test_pad_prints_its_name_as_written(tmp_path, capsys, name):
    """The pad's name went to matplotlib as mathtext: "pad$1$" was printed "pad1" (the 1 set
    as maths) and "a$$" was a ParseException traceback, exit 1. It is printed as written, on
    the page and on every sheet."""
    toml = tmp_path / "named.toml"
    toml.write_text(f"name = '{name}'\nside_m = 0.6\n[[rings]]\nouter_m = 0.28\ninner_m = 0.2\n"
                    "[[rings]]\nouter_m = 0.1\ninner_m = 0.05\n")
    for extra in ([], ["--paper", "a4"]):
        out = tmp_path / "pad.pdf"
        assert run(["pad", "--out", str(out), "--pad", str(toml), *extra]) == 0
        assert capsys.readouterr().out.startswith(f"wrote {out} ({name}, side 0.6 m")
        text = _pdf_text(out)
        assert f"{name}: square side 600.0 mm" in text, text
        if extra:
            assert f"{name} sheet row 1/3, column 1/4" in text, text


def test_vision_without_its_command_names_it_as_the_user_sees_it(capsys):
    """``skeye vision`` alone said "the following arguments are required: vision_command",
    the parser's attribute; it says COMMAND, as ``skeye`` and ``skeye link`` do."""
    from skeye.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(["vision"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.endswith("skeye vision: error: the following arguments are required: COMMAND\n")
    assert "vision_command" not in err, err


def test_pad_files_are_known_by_toml_in_any_case(tmp_path, capsys):
    """--pad PAD.TOML was looked up as a built-in pad's name ("unknown pad 'PAD.TOML'; known
    pads: skeye-4"), as was a pad file of another name, with nothing said of the file. A
    .TOML file is read; a file of another name is said to need .toml."""
    text = ("name = 'upper'\nside_m = 0.6\n[[rings]]\nouter_m = 0.28\ninner_m = 0.2\n"
            "[[rings]]\nouter_m = 0.1\ninner_m = 0.05\n")
    upper = tmp_path / "PAD.TOML"
    upper.write_text(text)
    assert run(["pad", "--out", str(tmp_path / "pad.pdf"), "--pad", str(upper)]) == 0
    assert "(upper, side 0.6 m" in capsys.readouterr().out
    other = tmp_path / "pad.txt"
    other.write_text(text)
    assert run(["pad", "--out", str(tmp_path / "other.pdf"), "--pad", str(other)]) == 2
    assert capsys.readouterr().err == (
        f"skeye pad: error: unknown pad '{other}'; known pads: skeye-4 ({other} is a file, but "
        "a pad file's name ends in .toml)\n")
    assert not (tmp_path / "other.pdf").exists()
