"""Printable tag sheets as a PDF, drawn at exact physical size (matplotlib's PDF backend).

Each page is a figure of the paper's size in inches; every element is placed in millimetres
through one transform, so a printer at 100 % reproduces the sizes of
:func:`tagloc.tags.sheet.layout_tag_sheets` exactly. Each tag is the detector's own bitmap
(:func:`tagloc.tags.tag_bitmap`, one pixel per cell) embedded unresampled (``interpolation=
"none"``: the PDF holds the cell grid and the viewer or printer scales it with crisp edges),
with its white quiet zone, a label (family, id, black-border size) and cut marks; the page has
the printing instruction at the top and a scale bar at the bottom. The file is written
atomically: on any error nothing is left at the target.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from tagloc.fileutil import atomic_path
from tagloc.tags.bitmaps import tag_bitmap
from tagloc.tags.sheet import (
    FOOTER_MM,
    HEADER_MM,
    MARGIN_MM,
    SheetLayout,
    TagPlacement,
    scale_bar_mm,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["PRINT_NOTE", "write_tag_sheets"]

_MM_PER_IN = 25.4
#: The instruction printed at the top of every page.
PRINT_NOTE = (
    "Print at 100 % (actual size; turn off 'fit to page' / 'scale to fit'), "
    "then check that the scale bar measures {bar:.0f} mm."
)
_CUT_GAP_MM, _CUT_LEN_MM = 1.0, 3.0


def write_tag_sheets(layout: SheetLayout, path: str | os.PathLike[str]) -> Path:
    """Draw every page of ``layout`` into the PDF at ``path`` (atomically); return the path.

    Raises
    ------
    OutputPathError
        If the file cannot be written there.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.backends.backend_pdf import PdfPages

    target = Path(path)
    metadata = {
        "Title": f"{layout.family} tags, {1000 * layout.size_m:g} mm",
        "Creator": "tagloc",
        "CreationDate": None,
    }
    with atomic_path(target) as tmp, PdfPages(tmp, metadata=metadata) as pdf:
        for number, page in enumerate(layout.pages, start=1):
            fig = _page(layout, page.placements, number)
            pdf.savefig(fig)
            _close(fig)
    return target


def _page(layout: SheetLayout, placements: tuple[TagPlacement, ...], number: int) -> Figure:
    """One page as a figure whose data coordinates are millimetres (origin bottom-left)."""
    import matplotlib.pyplot as plt

    width_mm, height_mm = layout.page_mm
    fig = plt.figure(figsize=(width_mm / _MM_PER_IN, height_mm / _MM_PER_IN))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, width_mm)
    ax.set_ylim(0.0, height_mm)
    ax.set_axis_off()
    bar = scale_bar_mm(width_mm)
    size_mm = 1000.0 * layout.size_m
    header_y = height_mm - MARGIN_MM - HEADER_MM / 2
    ax.text(
        MARGIN_MM,
        header_y + 2.5,
        PRINT_NOTE.format(bar=bar),
        fontsize=8.5,
        va="center",
        ha="left",
        weight="bold",
    )
    ax.text(
        MARGIN_MM,
        header_y - 2.5,
        f"{layout.family}, black-border edge {size_mm:g} mm (the 'size' in tags.yaml: "
        f"{layout.size_m:g} m); cut along the marks, keep the white border. "
        f"Page {number} of {len(layout.pages)}.",
        fontsize=7,
        va="center",
        ha="left",
    )
    for placement in placements:
        _draw_tag(ax, layout.family, placement)
    _scale_bar(ax, MARGIN_MM, MARGIN_MM + FOOTER_MM / 2 - 2.0, bar)
    return fig


def _draw_tag(ax: Axes, family: str, p: TagPlacement) -> None:
    """The bitmap over the black-border square plus quiet zone, the label and the cut marks."""
    bitmap = tag_bitmap(family, p.tag_id, cells_px=1, quiet_zone_cells=0)
    ax.imshow(
        bitmap,
        cmap="gray",
        vmin=0,
        vmax=255,
        interpolation="none",
        aspect="auto",
        extent=(p.x_mm, p.x_mm + p.size_mm, p.y_mm, p.y_mm + p.size_mm),
        zorder=2,
    )
    bx, by, bw, bh = p.cut_box_mm
    label_mm = p.y_mm - p.quiet_mm - by
    ax.text(
        bx + bw / 2,
        by + label_mm / 2,
        f"{family}  id {p.tag_id}  size {p.size_mm:g} mm",
        fontsize=min(9.0, max(4.0, bw / 8)),
        ha="center",
        va="center",
    )
    for cx, cy, sx, sy in (
        (bx, by, -1, -1),
        (bx + bw, by, 1, -1),
        (bx, by + bh, -1, 1),
        (bx + bw, by + bh, 1, 1),
    ):
        ax.plot(
            [cx + sx * _CUT_GAP_MM, cx + sx * (_CUT_GAP_MM + _CUT_LEN_MM)],
            [cy, cy],
            color="black",
            lw=0.3,
        )
        ax.plot(
            [cx, cx],
            [cy + sy * _CUT_GAP_MM, cy + sy * (_CUT_GAP_MM + _CUT_LEN_MM)],
            color="black",
            lw=0.3,
        )


def _scale_bar(ax: Axes, x_mm: float, y_mm: float, length_mm: float) -> None:
    """A bar of ``length_mm`` with a tick every 10 mm and alternating black and white cm."""
    from matplotlib.patches import Rectangle

    for k in range(round(length_mm / 10)):
        face = "black" if k % 2 == 0 else "white"
        ax.add_patch(
            Rectangle((x_mm + 10 * k, y_mm), 10.0, 2.0, facecolor=face, edgecolor="black", lw=0.3)
        )
    for k in range(round(length_mm / 10) + 1):
        ax.text(x_mm + 10 * k, y_mm - 1.0, f"{10 * k}", fontsize=5, ha="center", va="top")
    note = f"{length_mm:.0f} mm: measure this bar on the print"
    ax.text(x_mm + length_mm + 3.0, y_mm + 1.0, note, fontsize=7, va="center")


def _close(fig: Figure) -> None:
    import matplotlib.pyplot as plt

    plt.close(fig)
