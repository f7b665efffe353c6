"""Pad definitions from TOML, plain-data round trip, and the printable pad at true scale."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from skeye.errors import ConfigError, LocalProtocolError
from skeye.vision.pad import (
    SKEYE_4,
    PadDefinition,
    Ring,
    load_pad,
    pad_from_dict,
    pad_to_dict,
    render_pad,
    resolve_pad,
)
from skeye.vision.printable import METRES_PER_INCH, page_size_m, write_printable

GOOD_TOML = """
name = "big-3"
side_m = 1.2
[[rings]]
outer_m = 0.55
inner_m = 0.44
[[rings]]
outer_m = 0.35
inner_m = 0.21
[[rings]]
outer_m = 0.12
inner_m = 0.036
"""


def test_existing_pad_behaviour_kept():
    assert resolve_pad("skeye-4") is SKEYE_4
    assert [round(r.ratio, 2) for r in SKEYE_4.rings] == [0.85, 0.75, 0.6, 0.4]
    tex = render_pad(SKEYE_4, 64)
    assert tex.shape == (64, 64) and tex[0, 0] == 0 and tex[32, 32] == 0


def test_load_pad_from_toml(tmp_path):
    path = tmp_path / "big.toml"
    path.write_text(GOOD_TOML)
    pad = load_pad(path)
    assert pad.name == "big-3" and pad.side_m == 1.2
    assert pad.rings[1] == Ring(0.35, 0.21)
    assert resolve_pad(str(path)) == pad


@pytest.mark.parametrize(
    "text,match",
    [
        ("name = 'x'\nside_m = 0.6\n", "missing key 'rings'"),
        ("name = 'x'\nside_m = 'big'\nrings = [{outer_m = 0.2, inner_m = 0.1}]", "side_m"),
        ("name = 'x'\nside_m = 0.6\nrings = []", "non-empty list"),
        ("name = 'x'\nside_m = 0.6\nrings = [{outer_m = 0.2}]", r"rings\[1\]"),
        ("name = 'x'\nside_m = 0.6\nrings = [{outer_m = 0.2, inner_m = 0.3}]", "must satisfy"),
        (
            "name = 'x'\nside_m = 0.6\ncolour = 1\nrings = [{outer_m = 0.2, inner_m = 0.1}]",
            "unknown",
        ),
        (
            "name = 'x'\nside_m = 0.6\n"
            "rings = [{outer_m = 0.2, inner_m = 0.1}, {outer_m = 0.05, inner_m = 0.025}]",
            "unique",
        ),
        ("name = = 'x'", "not valid TOML"),
        # inf passed (skeye pad then raised ValueError from matplotlib's figure size); nan was
        # refused, but by the first ring's check ("outer <= nan"), not naming side_m
        ("name = 'x'\nside_m = inf\nrings = [{outer_m = 0.2, inner_m = 0.1}]",
         "side_m must be a positive finite number, got inf"),
        ("name = 'x'\nside_m = nan\nrings = [{outer_m = 0.2, inner_m = 0.1}]",
         "side_m must be a positive finite number, got nan"),
        # a name is printed on the page and said on the terminal: a newline, a tab or an
        # escape sequence went there as it was
        ('name = "a\\nb"\nside_m = 0.6\nrings = [{outer_m = 0.2, inner_m = 0.1}]',
         "name must be printable"),
        ('name = "\\u001b[31mred"\nside_m = 0.6\nrings = [{outer_m = 0.2, inner_m = 0.1}]',
         "name must be printable"),
    ],
)
def test_bad_pad_files_name_the_file_and_key(tmp_path, text, match):
    path = tmp_path / "pad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match) as info:
        load_pad(path)
    assert str(path) in str(info.value)


def test_missing_pad_file_and_unknown_name(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_pad(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="known pads: skeye-4"):
        resolve_pad("skeye-5")


@st.composite
def pads(draw):
    n = draw(st.integers(2, 5))
    side = draw(st.floats(0.1, 3.0))
    radii = sorted(
        draw(st.lists(st.floats(0.001, 0.5), min_size=2 * n, max_size=2 * n, unique=True)),
        reverse=True,
    )
    radii = [r * side for r in radii]
    rings = tuple(Ring(radii[2 * i], radii[2 * i + 1]) for i in range(n))
    try:
        return PadDefinition("p", side, rings)
    except ValueError:
        from hypothesis import reject

        reject()


@settings(max_examples=60, deadline=None)
@given(pads())
def test_dict_round_trip(pad):
    assert pad_from_dict(pad_to_dict(pad)) == pad


def test_printable_pdf_is_true_scale(tmp_path):
    out = write_printable(SKEYE_4, tmp_path / "pad.pdf")
    data = out.read_bytes()
    assert data.startswith(b"%PDF")
    box = re.search(rb"MediaBox\s*\[\s*0 0 ([\d.]+) ([\d.]+)\s*\]", data)
    assert box is not None
    side_pt = page_size_m(SKEYE_4) / METRES_PER_INCH * 72.0
    assert float(box.group(1)) == pytest.approx(side_pt, abs=0.01)
    assert float(box.group(2)) == pytest.approx(side_pt, abs=0.01)


@pytest.mark.parametrize("dpi", [40, 72])
def test_printable_png_carries_its_dpi(tmp_path, dpi):
    out = write_printable(SKEYE_4, tmp_path / "pad.png", dpi=dpi)
    with Image.open(out) as im:
        side_px = page_size_m(SKEYE_4) / METRES_PER_INCH * dpi
        assert im.size[0] == pytest.approx(side_px, abs=1.0) and im.size[0] == im.size[1]
        assert im.info["dpi"][0] == pytest.approx(dpi, rel=1e-3)  # PNG stores px per metre
        grey = np.asarray(im.convert("L"))
        c = im.size[0] // 2
        assert grey[c, c] < 30  # black centre disc
        assert grey[2, 2] > 225  # white margin
        # The outermost ring's outer border lies 0.28 m from the centre.
        px_per_m = im.size[0] / page_size_m(SKEYE_4)
        assert grey[c, c + round(0.27 * px_per_m)] > 225
        assert grey[c, c + round(0.29 * px_per_m)] < 30


@pytest.mark.parametrize(("side_m", "dpi", "words"), [
    (20.0, 300, "20.04 m page at 300 dpi is 236693 px a side, over the 32768 px a PNG may "
                "have: give --dpi 41 or less (the page is over the 5.08 m a PDF page may have)"),
    (1.0, 1200, "1.04 m page at 1200 dpi is 49134 px a side, over the 32768 px a PNG may "
                "have: give --dpi 800 or less, or write a .pdf (vector)"),
    (1e9, 10, "even at 10 dpi (the page is over the 5.08 m a PDF page may have)"),
    # the pixel count of a 1e300 m page was written out in full, 300 digits of it
    (1e300, 300, "a 1e+300 m page at 300 dpi is 1.18e+304 px a side, over the 32768 px"),
])
def test_a_png_too_large_to_draw_is_refused(tmp_path, capsys, side_m, dpi, words):
    """A 20 m pad at 300 dpi made matplotlib fail to allocate the canvas (MemoryError, or
    a ValueError over 2^16 px); a 1e9 m one at 10 dpi a TypeError (a size past C's int).
    Both tracebacks from skeye pad; now refused before drawing, saying the dpi that fits."""
    from skeye.cli import main

    pad = PadDefinition("big", side_m, (Ring(0.45 * side_m, 0.38 * side_m),
                                         Ring(0.30 * side_m, 0.15 * side_m)))
    out = tmp_path / "pad.png"
    with pytest.raises(LocalProtocolError, match=re.escape(words)):
        write_printable(pad, out, dpi=dpi)
    pad_file = tmp_path / "big.toml"
    pad_file.write_text(f"name = 'big'\nside_m = {side_m!r}\n"
                        f"rings = [{{outer_m = {0.45 * side_m!r}, inner_m = {0.38 * side_m!r}}}, "
                        f"{{outer_m = {0.30 * side_m!r}, inner_m = {0.15 * side_m!r}}}]")
    assert main(["pad", "--out", str(out), "--pad", str(pad_file), "--dpi", str(dpi)]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err, err
    assert not out.exists()


def test_a_page_needing_too_many_sheets_is_refused(tmp_path, capsys):
    """--paper a4 on a 1e9 m pad listed 1e19 tiles (MemoryError after 34 s and 5.4 GB); on a
    20 m pad it drew 8512 sheets, hours of work. Over 500 sheets is refused before drawing."""
    from skeye.cli import main
    from skeye.vision.printable import plan_tiles

    with pytest.raises(LocalProtocolError, match="needs 8512 a4 sheets, over the 500"):
        plan_tiles(20.04, "a4")
    assert len(plan_tiles(4.8, "a4").tiles) == 486
    pad_file = tmp_path / "big.toml"
    pad_file.write_text("name = 'big'\nside_m = 1e9\nrings = [{outer_m = 4e8, inner_m = 3e8}, "
                        "{outer_m = 2e8, inner_m = 1e8}]")
    out = tmp_path / "pad.pdf"
    assert main(["pad", "--out", str(out), "--pad", str(pad_file), "--paper", "a4"]) == 2
    err = capsys.readouterr().err
    assert "without --paper" in err and "Traceback" not in err, err
    assert not out.exists()


def test_printable_rejects_other_extensions(tmp_path):
    with pytest.raises(LocalProtocolError, match=r"\.pdf or \.png"):
        write_printable(SKEYE_4, tmp_path / "pad.svg")


@pytest.mark.parametrize(("paper", "sheet_pt"), [("a4", (595.3, 841.9)), ("letter", (612, 792))])
def test_pad_tiles_over_home_printer_paper(tmp_path, paper, sheet_pt):
    import re

    from skeye.vision.printable import (
        PAPER_MARGIN_M,
        PAPERS_M,
        TILE_OVERLAP_M,
        page_size_m,
        plan_tiles,
        write_printable,
    )

    side = page_size_m(SKEYE_4)
    plan = plan_tiles(side, paper)
    # every sheet fits the paper's printable area; together they cover exactly the page (no
    # sheet reaches past it: none is mostly blank), and neighbours overlap by the plan's
    # overlap, at least TILE_OVERLAP_M
    w, h = PAPERS_M[paper]
    for t in plan.tiles:
        assert t.width_m == pytest.approx((h if plan.landscape else w) - 2 * PAPER_MARGIN_M)
        assert t.height_m == pytest.approx((w if plan.landscape else h) - 2 * PAPER_MARGIN_M)
        assert -1e-9 <= t.x0_m and t.x0_m + t.width_m <= side + 1e-9, t
        assert -1e-9 <= t.y0_m and t.y0_m + t.height_m <= side + 1e-9, t
    assert min(t.x0_m for t in plan.tiles) == 0 and max(t.y0_m + t.height_m for t in plan.tiles
                                                        ) == pytest.approx(side)
    assert max(t.x0_m + t.width_m for t in plan.tiles) == pytest.approx(side)
    assert min(t.y0_m for t in plan.tiles) == pytest.approx(0, abs=1e-12)
    assert plan.overlap_x_m >= TILE_OVERLAP_M and plan.overlap_y_m >= TILE_OVERLAP_M
    by_place = {(t.row, t.col): t for t in plan.tiles}
    for (row, col), t in by_place.items():
        if (row, col + 1) in by_place:
            assert t.x0_m + t.width_m - by_place[row, col + 1].x0_m == pytest.approx(
                plan.overlap_x_m)
        if (row + 1, col) in by_place:
            below = by_place[row + 1, col]
            assert below.y0_m + below.height_m - t.y0_m == pytest.approx(plan.overlap_y_m)
    # the fewest sheets: one fewer column or row would leave a gap even with no overlap
    usable_w, usable_h = plan.tiles[0].width_m, plan.tiles[0].height_m
    assert (plan.cols - 1) * (usable_w - TILE_OVERLAP_M) + TILE_OVERLAP_M < side
    assert (plan.rows - 1) * (usable_h - TILE_OVERLAP_M) + TILE_OVERLAP_M < side
    out = write_printable(SKEYE_4, tmp_path / "pad.pdf", paper=paper)
    data = out.read_bytes()
    assert len(re.findall(rb"/Type /Page[^s]", data)) == len(plan.tiles) == plan.rows * plan.cols
    boxes = {tuple(round(float(v), 1) for v in m.split()[2:])
             for m in re.findall(rb"/MediaBox \[([^\]]*)\]", data)}
    want = sheet_pt[::-1] if plan.landscape else sheet_pt
    assert boxes == {tuple(round(v, 1) for v in want)}
    with pytest.raises(LocalProtocolError, match=r"name it \.pdf"):
        write_printable(SKEYE_4, tmp_path / "pad.png", paper=paper)


def _render_pad_reference(pad, pixels: int, supersample: int):
    """The definition: every sub-sample of every pixel, then the share inside a ring."""
    n = pixels * supersample
    coords = (np.arange(n) + 0.5) / n * pad.side_m - pad.side_m / 2
    xx, yy = np.meshgrid(coords, coords)
    r = np.hypot(xx, yy)
    white = np.zeros((n, n), dtype=bool)
    for ring in pad.rings:
        white |= (r >= ring.inner_m) & (r < ring.outer_m)
    share = white.reshape(pixels, supersample, pixels, supersample).mean(axis=(1, 3))
    return np.round(share * 255.0).astype(np.uint8)


@pytest.mark.parametrize(("pixels", "supersample"), [(8, 4), (64, 4), (257, 3), (600, 2)])
def test_render_pad_equals_sub_sampling_every_pixel(pixels: int, supersample: int):
    # render_pad sub-samples only the pixels an edge may cross; the result must be the same
    # image, bit for bit, as sub-sampling all of them (the simulator's texture depends on it).
    from skeye.vision.pad import PadDefinition, Ring

    odd = PadDefinition(name="odd", side_m=0.37, rings=(Ring(0.18, 0.1234567), Ring(0.1, 0.0031)))
    for pad in (SKEYE_4, odd):
        assert np.array_equal(render_pad(pad, pixels, supersample),
                              _render_pad_reference(pad, pixels, supersample))


def test_a_pdf_page_over_the_pdf_size_limit_is_refused(tmp_path, capsys):
    """PDF viewers take a page of at most 14 400 x 14 400 units of 1/72 in, 200 in = 5.08 m a
    side (Adobe's PDF Reference, Appendix C); skeye pad wrote a 5.09 m page (MediaBox 14 428
    units) that Acrobat refuses or crops. The page at the limit is written, with its MediaBox
    within it; one 10 mm more is refused, naming the limit and the PNG that can carry it."""
    from skeye.cli import main

    def pad_file(side_m: float) -> Path:
        path = tmp_path / f"big-{side_m}.toml"
        path.write_text(f"name = 'big'\nside_m = {side_m!r}\n"
                        f"rings = [{{outer_m = {0.45 * side_m!r}, inner_m = {0.38 * side_m!r}}}, "
                        f"{{outer_m = {0.30 * side_m!r}, inner_m = {0.15 * side_m!r}}}]")
        return path

    at_limit = tmp_path / "limit.pdf"  # 5.04 m pad + 2 x 20 mm margin = 5.08 m
    assert main(["pad", "--out", str(at_limit), "--pad", str(pad_file(5.04))]) == 0
    box = re.search(rb"/MediaBox \[ *0 +0 +([0-9.]+) +([0-9.]+) *\]", at_limit.read_bytes())
    assert box is not None and max(float(v) for v in box.groups()) <= 14400.0
    capsys.readouterr()
    over = tmp_path / "over.pdf"  # a 5.09 m page
    assert main(["pad", "--out", str(over), "--pad", str(pad_file(5.05))]) == 2
    err = capsys.readouterr().err
    assert err.startswith("skeye pad: error: a 5.09 m page is over the 5.08 m a side a PDF page "
                          "may have (14400 units of 1/72 in, 200 in"), err
    assert "write a .png (--dpi 163 or less)" in err and "Traceback" not in err
    assert not over.exists()


def test_a_pad_with_one_ring_is_refused(tmp_path, capsys):
    """The detector reports a pad only when two identified rings agree on its centre and
    scale (docs/landing-pad.md), so a one-ring pad is never found: skeye pad printed one
    (exit 0) and skeye vision detect then said "found": false on every frame of it, even
    a perfect one. The file is refused when read, naming the file and `rings`."""
    from skeye.cli import main

    path = tmp_path / "one.toml"
    path.write_text("name = 'one'\nside_m = 0.6\nrings = [{outer_m = 0.28, inner_m = 0.15}]\n")
    out = tmp_path / "one.pdf"
    assert main(["pad", "--out", str(out), "--pad", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: rings: 1 ring; the detector needs at least 2" in err, err
    assert not out.exists()
    with pytest.raises(ConfigError, match="at least 2"):
        load_pad(path)


def test_rings_that_touch_are_refused(tmp_path, capsys):
    """A ring whose outer radius equals the previous ring's inner one leaves no black between
    them: the two white rings print as one band, whose borders name neither ring, so the
    detector found no pad in any frame (a perfect render of the pad below included). The
    rules allowed it (outer <= the previous inner); a black gap is now required. A ring whose
    outer border is the square's edge stays allowed (its white still meets black inside)."""
    from skeye.cli import main

    rings = ("[[rings]]\nouter_m = 0.28\ninner_m = 0.238\n"
             "[[rings]]\nouter_m = {second}\ninner_m = 0.15\n"
             "[[rings]]\nouter_m = 0.13\ninner_m = 0.078\n")
    touching = tmp_path / "touching.toml"
    touching.write_text("name = 'touching'\nside_m = 0.6\n" + rings.format(second=0.238))
    out = tmp_path / "touching.pdf"
    assert main(["pad", "--out", str(out), "--pad", str(touching)]) == 2
    err = capsys.readouterr().err
    assert (f"{touching}: pad 'touching': ring 2 radii (0.238, 0.15) must satisfy "
            "0 < inner < outer < 0.238") in err, err
    assert not out.exists()
    edge = tmp_path / "edge.toml"  # ring 1 out to the square's edge; a gap before ring 2
    edge.write_text("name = 'edge'\nside_m = 0.56\n" + rings.format(second=0.2))
    assert load_pad(edge).rings[0].outer_m == 0.28


def test_tiled_sheets_cut_on_their_marks_assemble_into_the_pad():
    """Each sheet has a 10 mm white margin the printer cannot print. Laid over its neighbour
    on the + marks, a sheet's left and top margins covered a 10 mm strip of the pad below
    with white paper, and nothing on the sheets said to cut them: the assembled pad had white
    bars across its black square and rings. Here the A4 sheets are drawn (100 dpi), each is
    cut where its own cut marks say (none: not cut), laid on its place in order (row by row,
    left to right, each over the ones before), and the result is compared with the one-page
    pad: nowhere may white paper lie where the pad is black all around. The sheet's own words
    must be printed whole (its line on the overlap ran 95 mm off the sheet's right edge)."""
    import cv2
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from skeye.vision.printable import (
        DEFAULT_MARGIN_M,
        PAPER_MARGIN_M,
        _figure,
        _sheet_figures,
        plan_tiles,
    )

    dpi = 100
    px = dpi / METRES_PER_INCH  # pixels per metre
    m = PAPER_MARGIN_M
    side = page_size_m(SKEYE_4)
    plan = plan_tiles(side, "a4")
    sheet_h = plan.sheet_m[1]

    def draw(fig) -> np.ndarray:
        fig.set_dpi(dpi)
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].mean(axis=2)

    n = round((side + 2 * m) * px) + 2  # the floor under the sheets: the page and a margin
    floor = np.full((n, n), 255.0)
    m_px = round(m * px)
    for tile, fig in zip(plan.tiles, _sheet_figures(SKEYE_4, DEFAULT_MARGIN_M, plan),
                         strict=True):
        sheet = draw(fig)
        h, w = sheet.shape
        renderer = fig.canvas.get_renderer()
        for text in fig.texts:  # the sheet's words are printed whole, not cut by its edge
            box = text.get_window_extent(renderer)
            assert 0 <= box.x0 and box.x1 <= w and 0 <= box.y0 and box.y1 <= h, (
                text.get_text(), box.extents, (w, h))
        keep = np.ones_like(sheet, dtype=bool)
        # a cut mark on the left edge: a dark column in the top margin, near the printed area
        near = m_px + round(0.005 * px)  # 5 mm: the marks sit in line with the printed area
        top_band = sheet[2 : m_px - 2, :near] < 200
        cols = np.nonzero(top_band.any(axis=0))[0]
        if cols.size:
            keep[:, : round(cols.mean())] = False
        left_band = sheet[:near, 2 : m_px - 2] < 200  # on the top edge
        rows = np.nonzero(left_band.any(axis=1))[0]
        if rows.size:
            keep[: round(rows.mean()), :] = False
        col0 = round((tile.x0_m - m + m) * px)  # the sheet's place (the floor starts at -m)
        row0 = round((side + m - (tile.y0_m - m + sheet_h)) * px)
        place = floor[row0 : row0 + h, col0 : col0 + w]
        place[keep[: place.shape[0], : place.shape[1]]] = sheet[: place.shape[0],
                                                                : place.shape[1]][
            keep[: place.shape[0], : place.shape[1]]]
    ref = draw(_figure(SKEYE_4, DEFAULT_MARGIN_M))
    r = ref.shape[0]
    got = floor[m_px : m_px + r, m_px : m_px + r]
    five = np.ones((5, 5), np.uint8)
    black_around = cv2.dilate(ref, five) < 50  # the pad's black, 2 px from any edge
    white_around = cv2.erode(ref, five) > 205
    white_on_black = black_around & (got > 200)
    black_on_white = white_around & (got < 50)
    assert white_on_black.sum() == 0 and black_on_white.sum() == 0, (
        f"{white_on_black.sum()} px of white paper over the pad's black "
        f"({white_on_black.sum() / px**2 * 1e4:.1f} cm^2), {black_on_white.sum()} px of "
        "black over its white")
