"""The pad as a printable file at true scale, from the same definition as the sim texture.

How this works: one matplotlib figure whose size in inches is the pad side plus a white
margin, converted from metres (``/ 0.0254``), with one axes filling it whose data units are
metres; the square and rings are drawn as vector shapes from the :class:`PadDefinition`. PDF
keeps them as vectors (page size in points = metres / 0.0254 * 72); PNG is rasterised at the
requested DPI and carries that DPI in its metadata, so printing at 100 % gives the true size.

A pad larger than a home printer's paper is tiled (``paper="a4"`` or ``"letter"``, PDF only):
:func:`plan_tiles` cuts the true-scale page into the fewest paper-sized tiles that overlap by at
least ``TILE_OVERLAP_M``, in whichever orientation needs fewer sheets, and spreads them evenly
so the first and last tile of a row or column end at the page's edges (every sheet carries as
much of the pad as its neighbours, none is mostly blank); each sheet shows its part of
the pad, dashed lines where its neighbours' parts begin, red ``+`` registration marks inside the
overlaps (each appears on both sheets it joins: lay one over the other), its row and column,
and a 100 mm scale bar to check the printer did not scale it (as AprilTag and ArUco print
tools do). The sheets are laid row by row, each over its left and upper neighbours, so a
sheet's left margin (column 2 on) and top margin (row 2 on), white paper that would cover the
pad below, are cut off first: black cut marks in the margins, in line with the printed area's
edge (printers' crop marks), show where, and a line in the top margin says so.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import TYPE_CHECKING, Any

from skeye.errors import LocalProtocolError
from skeye.vision.pad import PadDefinition

if TYPE_CHECKING:
    from matplotlib.figure import Figure

METRES_PER_INCH = 0.0254
DEFAULT_MARGIN_M = 0.02
DEFAULT_DPI = 300
MIN_DPI, MAX_DPI = 10, 1200  # what `skeye pad --dpi` takes for a PNG
MAX_PNG_SIDE_PX = 32768  # 4 GiB of RGBA while drawing; skeye-4's page at 1200 dpi is 30236
PAPERS_M: dict[str, tuple[float, float]] = {  # portrait width, height
    "a4": (0.210, 0.297),
    "letter": (0.2159, 0.2794),
}
PAPER_MARGIN_M = 0.010  # what most home printers cannot print, on every side
TILE_OVERLAP_M = 0.010
SCALE_BAR_M = 0.100
CUT_MARK_GAP_M = 0.002  # between a cut mark and the paper's edge / the printed area
CUT_TEXT_INSET_M = 0.010  # the margins' text and scale bar start this far right of a cut mark
# The largest PDF page viewers accept: 14 400 x 14 400 units of default user space (1/72 in),
# 200 in = 5.08 m a side (Adobe's PDF Reference, PDF 1.7, Appendix C "Implementation Limits":
# Acrobat's architectural limits, 3 to 14 400 units a side; Acrobat and Reader refuse or crop
# a larger MediaBox). PDF 1.6's
# UserUnit could scale the unit, but matplotlib does not write it and many viewers ignore it.
MAX_PDF_SIDE_M = 14400 / 72 * METRES_PER_INCH
MAX_SHEETS = 500  # a 4.8 m page on A4 (486 sheets); each sheet takes a second or more to draw


# The pad's name is printed as written: matplotlib otherwise reads text between two $ as
# mathtext (a pad "pad$1$" was printed "pad1" in italics; "a$$" was a ParseException
# traceback) and, under a matplotlibrc's text.usetex, runs it through TeX.
_PLAIN_TEXT: dict[str, Any] = {"parse_math": False, "usetex": False}


def page_size_m(pad: PadDefinition, margin_m: float = DEFAULT_MARGIN_M) -> float:
    """Side of the (square) page: the pad plus a margin on every side."""
    return pad.side_m + 2.0 * margin_m


def _figure(pad: PadDefinition, margin_m: float) -> Figure:
    # A bare Figure renders through its own canvas: no pyplot, no global backend switch.
    # matplotlib is imported here, not at the top: every `skeye` command builds its parser
    # from this package, and importing matplotlib costs a second or more.
    from matplotlib.figure import Figure

    side = page_size_m(pad, margin_m)
    fig = Figure(figsize=(side / METRES_PER_INCH, side / METRES_PER_INCH))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(-side / 2, side / 2)
    ax.set_ylim(-side / 2, side / 2)
    ax.set_aspect("equal")
    ax.axis("off")
    _draw_pad(ax, pad, margin_m)
    return fig


def _draw_pad(ax: Any, pad: PadDefinition, margin_m: float) -> None:
    """The pad centred on (0, 0), in metres, with its print note in the margin below."""
    from matplotlib.patches import Circle, Rectangle

    half = pad.side_m / 2
    ax.add_patch(Rectangle((-half, -half), pad.side_m, pad.side_m, color="black", lw=0))
    for ring in pad.rings:  # outermost first: each white disc, then its black hole
        ax.add_patch(Circle((0.0, 0.0), ring.outer_m, color="white", lw=0))
        ax.add_patch(Circle((0.0, 0.0), ring.inner_m, color="black", lw=0))
    if margin_m >= 0.006:
        ax.text(
            0.0,
            -half - margin_m / 2,
            f"{pad.name}: square side {pad.side_m * 1000:.1f} mm - print at 100 % (no scaling)",
            ha="center",
            va="center",
            fontsize=min(8.0, margin_m / METRES_PER_INCH * 72 * 0.4),
            color="0.5",
            **_PLAIN_TEXT,
        )


@dataclass(frozen=True)
class Tile:
    """One sheet: the part ``[x0, x0 + width] x [y0, y0 + height]`` of the true-scale page
    (metres, origin at the page's lower-left corner), row 1 at the top."""

    row: int
    col: int
    x0_m: float
    y0_m: float
    width_m: float
    height_m: float


@dataclass(frozen=True)
class TilePlan:
    paper: str
    landscape: bool
    page_side_m: float
    rows: int
    cols: int
    tiles: tuple[Tile, ...]
    overlap_x_m: float  # between neighbours in a row (0 with one column)
    overlap_y_m: float  # between neighbours in a column (0 with one row)

    @property
    def sheet_m(self) -> tuple[float, float]:
        w, h = PAPERS_M[self.paper]
        return (h, w) if self.landscape else (w, h)


def plan_tiles(page_side_m: float, paper: str) -> TilePlan:
    """Cut a square page of ``page_side_m`` into overlapping tiles of ``paper``'s printable
    area, in the orientation that needs fewer sheets (portrait when equal)."""
    if paper not in PAPERS_M:
        raise LocalProtocolError(f"paper must be one of {', '.join(PAPERS_M)}, got {paper!r}")
    best: TilePlan | None = None
    fewest = math.inf
    for landscape in (False, True):
        w, h = PAPERS_M[paper]
        sheet_w, sheet_h = (h, w) if landscape else (w, h)
        usable_w, usable_h = sheet_w - 2 * PAPER_MARGIN_M, sheet_h - 2 * PAPER_MARGIN_M
        cols_n = _count(page_side_m, usable_w)
        rows_n = _count(page_side_m, usable_h)
        fewest = min(fewest, rows_n * cols_n)
        if rows_n * cols_n > MAX_SHEETS:  # not listed: a 1e9 m page has 1e19 of them
            continue
        rows, cols = int(rows_n), int(cols_n)  # finite: at most MAX_SHEETS
        xs = _starts(page_side_m, usable_w, cols)  # left edges, left to right
        ys = _starts(page_side_m, usable_h, rows)[::-1]  # bottom edges, row 1 at the top
        tiles = tuple(Tile(r + 1, c + 1, xs[c], ys[r], usable_w, usable_h)
                      for r in range(rows) for c in range(cols))
        plan = TilePlan(paper, landscape, page_side_m, rows, cols, tiles,
                        usable_w - (xs[1] - xs[0]) if cols > 1 else 0.0,
                        usable_h - (ys[0] - ys[1]) if rows > 1 else 0.0)
        if best is None or len(plan.tiles) < len(best.tiles):
            best = plan
    if best is None:
        raise LocalProtocolError(
            f"a {page_side_m:g} m page needs {_sheets_text(fewest)} {paper} sheets, over the "
            f"{MAX_SHEETS} --paper writes: write it without --paper (one true-scale page) "
            "for a print shop" + ("" if page_side_m <= MAX_PDF_SIDE_M * (1 + 1e-12) else
                                  f", as a .png (over {MAX_PDF_SIDE_M:g} m a side, more than a "
                                  "PDF page may have)"))
    return best


def _sheets_text(count: float) -> str:
    """A count of sheets as a line says it: whole up to a billion, else in three digits (a
    1e300 m page's is an integer of 600 digits, which ``:.0f`` could not even convert to a
    float: an OverflowError traceback)."""
    if count < 1e9:
        return f"{count:.0f}"
    if count == math.inf:  # a page near the largest float: its rows are no finite number
        return "more than 1e+308"
    return format(Decimal(int(count)), ".3g")


def _count(length_m: float, usable_m: float) -> int | float:
    """Tiles of ``usable_m`` that span ``length_m`` with their overlaps; ``math.inf`` where
    that is no finite float (a page near the largest float)."""
    if length_m <= usable_m:
        return 1
    count = (length_m - TILE_OVERLAP_M) / (usable_m - TILE_OVERLAP_M) - 1e-9
    return math.ceil(count) if math.isfinite(count) else math.inf


def _starts(length_m: float, usable_m: float, count: int) -> list[float]:
    """Where ``count`` tiles of ``usable_m`` start so they span ``length_m`` evenly: the first
    at 0, the last ending at ``length_m`` (one tile: centred on the page)."""
    if count == 1:
        return [(length_m - usable_m) / 2]
    step = (length_m - usable_m) / (count - 1)
    return [i * step for i in range(count)]


def _sheet_figures(pad: PadDefinition, margin_m: float, plan: TilePlan) -> Iterator[Figure]:
    """One figure per sheet of ``plan``, in the order they are laid (row by row, top to
    bottom, each row left to right): each later sheet lies over its left and upper
    neighbours, so its left margin (column 2 on) and top margin (row 2 on) are cut off along
    its cut marks first; laid on the + marks, the cut edge meets the neighbour's dashed line
    farther from that neighbour's edge (where this sheet's part begins). Uncut, the white
    margin would cover a 10 mm strip of the pad below it."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    side = plan.page_side_m
    sheet_w, sheet_h = plan.sheet_m
    first_row = [t for t in plan.tiles if t.row == 1]
    first_col = [t for t in plan.tiles if t.col == 1]
    ov_x, ov_y = plan.overlap_x_m, plan.overlap_y_m
    # registration marks: centred in every overlap strip, at every crossing of the strips
    xs = [t.x0_m + ov_x / 2 for t in first_row[1:]]
    ys = [t.y0_m + t.height_m - ov_y / 2 for t in first_col[1:]]
    mark_xs = xs or [side / 2]
    mark_ys = ys or [side / 2]
    m = PAPER_MARGIN_M
    gap = CUT_MARK_GAP_M

    def line(fig: Figure, x: tuple[float, float], y: tuple[float, float], **kw: Any) -> None:
        """A line on the sheet, from paper coordinates (metres from its lower-left corner)."""
        fig.add_artist(Line2D([x[0] / sheet_w, x[1] / sheet_w], [y[0] / sheet_h, y[1] / sheet_h],
                              **kw))

    for tile in plan.tiles:
        fig = Figure(figsize=(sheet_w / METRES_PER_INCH, sheet_h / METRES_PER_INCH))
        ax = fig.add_axes((m / sheet_w, m / sheet_h, tile.width_m / sheet_w,
                           tile.height_m / sheet_h))
        # axes in page metres, shifted so the pad (drawn about 0) sits mid-page
        ax.set_xlim(tile.x0_m - side / 2, tile.x0_m + tile.width_m - side / 2)
        ax.set_ylim(tile.y0_m - side / 2, tile.y0_m + tile.height_m - side / 2)
        ax.axis("off")
        _draw_pad(ax, pad, margin_m)
        for x in xs:  # where the right/left neighbour's part begins / ends
            for edge in (x - ov_x / 2, x + ov_x / 2):
                ax.axvline(edge - side / 2, color="red", lw=0.4, ls=(0, (4, 3)))
        for y in ys:
            for edge in (y - ov_y / 2, y + ov_y / 2):
                ax.axhline(edge - side / 2, color="red", lw=0.4, ls=(0, (4, 3)))
        arm = 0.004
        for mx in mark_xs:
            for my in mark_ys:
                if (mx in xs or my in ys):
                    ax.plot([mx - arm - side / 2, mx + arm - side / 2],
                            [my - side / 2] * 2, color="red", lw=0.8)
                    ax.plot([mx - side / 2] * 2,
                            [my - arm - side / 2, my + arm - side / 2], color="red", lw=0.8)

        # cut marks (printers' crop marks): in the margins, in line with the printed area's
        # left edge (column 2 on) and top edge (row 2 on), the margin to cut off
        cuts = []
        if tile.col > 1:
            cuts.append("left")
            for span in ((gap, m - gap), (sheet_h - m + gap, sheet_h - gap)):
                line(fig, (m, m), span, color="black", lw=0.5)
        if tile.row > 1:
            cuts.append("top")
            for span in ((gap, m - gap), (sheet_w - m + gap, sheet_w - gap)):
                line(fig, span, (sheet_h - m, sheet_h - m), color="black", lw=0.5)
        # in the top margin, right of the cut marks: the sheet's place and how to lay it
        place = (f"{pad.name} sheet row {tile.row}/{plan.rows}, column {tile.col}/{plan.cols}; "
                 f"overlap {ov_x * 1000:.0f} mm across, {ov_y * 1000:.0f} mm down, between the "
                 "dashed lines: lay the + marks on each other")
        lines = [place]
        if cuts:
            lines.append(f"first cut the white margin off the {' and '.join(cuts)} edge"
                         f"{'s' if len(cuts) > 1 else ''} between the black cut marks; the cut "
                         "edge lies on the neighbour's dashed line farther from its edge")
        for k, text in enumerate(lines):
            fig.text((m + CUT_TEXT_INSET_M) / sheet_w, 1 - m * (0.3 + 0.4 * k) / sheet_h, text,
                     fontsize=5.5, va="center", color="0.2", **_PLAIN_TEXT)
        # the scale bar, in the bottom margin (right of the cut marks)
        y_bar = m * 0.45
        x0, x1 = m + CUT_TEXT_INSET_M, m + CUT_TEXT_INSET_M + SCALE_BAR_M
        line(fig, (x0, x1), (y_bar, y_bar), color="black", lw=1.2)
        for end in (x0, x1):
            line(fig, (end, end), (y_bar - 0.004 * sheet_h, y_bar + 0.004 * sheet_h),
                 color="black", lw=1.2)
        fig.text(x1 / sheet_w + 0.01, y_bar / sheet_h,
                 f"<- this bar must measure {SCALE_BAR_M * 1000:.0f} mm (print at 100 %)",
                 fontsize=5.5, va="center", color="0.2", **_PLAIN_TEXT)
        yield fig


def _write_tiled(pad: PadDefinition, out: Path, margin_m: float, paper: str) -> TilePlan:
    from matplotlib.backends.backend_pdf import PdfPages

    plan = plan_tiles(page_size_m(pad, margin_m), paper)
    with PdfPages(out) as pdf:
        for fig in _sheet_figures(pad, margin_m, plan):
            pdf.savefig(fig)
    return plan


def write_printable(
    pad: PadDefinition,
    path: str | os.PathLike[str],
    dpi: int = DEFAULT_DPI,
    margin_m: float = DEFAULT_MARGIN_M,
    paper: str | None = None,
) -> Path:
    """Write the pad at true scale to ``path`` (.pdf, or .png at ``dpi`` with DPI metadata);
    with ``paper`` ("a4", "letter") a PDF of overlapping sheets of that paper.

    Raises LocalProtocolError for another extension or bad sizes; OSError if it can't write.
    """
    out = Path(path)
    ext = out.suffix.lower()
    if ext not in (".pdf", ".png"):
        raise LocalProtocolError(f"printable pad must be .pdf or .png, got {out.name!r}")
    if not 0 <= margin_m <= 1.0:
        raise LocalProtocolError(f"margin must be within 0..1 m, got {margin_m}")
    if ext == ".png" and not MIN_DPI <= dpi <= MAX_DPI:
        raise LocalProtocolError(f"dpi must be within {MIN_DPI}..{MAX_DPI}, got {dpi}")
    side = page_size_m(pad, margin_m)
    pdf_fits = side <= MAX_PDF_SIDE_M * (1 + 1e-12)
    if ext == ".png" and paper is None:
        side_px = side / METRES_PER_INCH * dpi
        if side_px > MAX_PNG_SIDE_PX:  # matplotlib would raise, or exhaust the memory
            most = math.floor(MAX_PNG_SIDE_PX * METRES_PER_INCH / side)
            fix = [f"give --dpi {most} or less"] if most >= 10 else []
            if pdf_fits:
                fix.append("write a .pdf (vector)")
            said = (f": {', or '.join(fix)}" if fix else " even at 10 dpi") + (
                "" if pdf_fits else f" (the page is over the {MAX_PDF_SIDE_M:g} m a PDF page "
                "may have)")
            count = (f"{side_px:.0f}" if side_px < 1e9 else f"{side_px:.3g}"  # not 300 digits
                     if math.isfinite(side_px) else "more than 1e+308")
            raise LocalProtocolError(
                f"a {side:g} m page at {dpi} dpi is {count} px a side, over the "
                f"{MAX_PNG_SIDE_PX} px a PNG may have{said}")
    if ext == ".pdf" and paper is None and not pdf_fits:
        most = math.floor(MAX_PNG_SIDE_PX * METRES_PER_INCH / side)
        png = (f": write a .png (--dpi {most} or less)" if most >= 10 else
               ", and too large for a PNG even at 10 dpi")
        raise LocalProtocolError(
            f"a {side:g} m page is over the {MAX_PDF_SIDE_M:g} m a side a PDF page may have "
            f"(14400 units of 1/72 in, 200 in: Acrobat's page-size limit, PDF Reference "
            f"Appendix C; viewers refuse or crop a larger page){png}")
    if paper is not None:
        if ext != ".pdf":
            raise LocalProtocolError(f"--paper writes a PDF of sheets; name it .pdf, not {ext}")
        with _write_errors():
            _write_tiled(pad, out, margin_m, paper)
        return out
    fig = _figure(pad, margin_m)
    with _write_errors():
        if ext == ".pdf":
            fig.savefig(out, format="pdf")
        else:
            fig.savefig(out, format="png", dpi=dpi)
    return out


@contextmanager
def _write_errors() -> Iterator[None]:
    """A write that failed raises its OSError (a full disk: EFBIG, ENOSPC). matplotlib's PDF
    backend, cleaning up after a failed write, raises another error in its stead (a
    ``zlib.error`` from :class:`PdfPages`' close, an ``AttributeError`` from its stream), the
    OSError only its ``__context__``: that reached the user as a traceback."""
    try:
        yield
    except OSError:
        raise
    except Exception as exc:
        cause: BaseException | None = exc
        while cause is not None and not isinstance(cause, OSError):
            cause = cause.__cause__ or cause.__context__
        if cause is None:
            raise
        raise cause from None
