"""The pad as a printable file at true scale, from the same definition as the sim texture.

How this works: one matplotlib figure whose size in inches is the pad side plus a white
margin, converted from metres (``/ 0.0254``), with one axes filling it whose data units are
metres; the square and rings are drawn as vector shapes from the :class:`PadDefinition`. PDF
keeps them as vectors (page size in points = metres / 0.0254 * 72); PNG is rasterised at the
requested DPI and carries that DPI in its metadata, so printing at 100 % gives the true size.
"""

from __future__ import annotations

import os
from pathlib import Path

# A bare Figure renders through its own canvas: no pyplot, no global backend switch.
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Rectangle

from skeye.errors import LocalProtocolError
from skeye.vision.pad import PadDefinition

METRES_PER_INCH = 0.0254
DEFAULT_MARGIN_M = 0.02
DEFAULT_DPI = 300


def page_size_m(pad: PadDefinition, margin_m: float = DEFAULT_MARGIN_M) -> float:
    """Side of the (square) page: the pad plus a margin on every side."""
    return pad.side_m + 2.0 * margin_m


def _figure(pad: PadDefinition, margin_m: float) -> Figure:
    side = page_size_m(pad, margin_m)
    fig = Figure(figsize=(side / METRES_PER_INCH, side / METRES_PER_INCH))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(-side / 2, side / 2)
    ax.set_ylim(-side / 2, side / 2)
    ax.set_aspect("equal")
    ax.axis("off")
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
        )
    return fig


def write_printable(
    pad: PadDefinition,
    path: str | os.PathLike[str],
    dpi: int = DEFAULT_DPI,
    margin_m: float = DEFAULT_MARGIN_M,
) -> Path:
    """Write the pad at true scale to ``path`` (.pdf, or .png at ``dpi`` with DPI metadata).

    Raises LocalProtocolError for another extension or bad sizes; OSError if it can't write.
    """
    out = Path(path)
    ext = out.suffix.lower()
    if ext not in (".pdf", ".png"):
        raise LocalProtocolError(f"printable pad must be .pdf or .png, got {out.name!r}")
    if not 0 <= margin_m <= 1.0:
        raise LocalProtocolError(f"margin must be within 0..1 m, got {margin_m}")
    if ext == ".png" and not 10 <= dpi <= 1200:
        raise LocalProtocolError(f"dpi must be within 10..1200, got {dpi}")
    fig = _figure(pad, margin_m)
    if ext == ".pdf":
        fig.savefig(out, format="pdf")
    else:
        fig.savefig(out, format="png", dpi=dpi)
    return out
