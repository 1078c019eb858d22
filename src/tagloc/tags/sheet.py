"""Where printed tags go on paper: the id list, the paper sizes and the page layout (pure).

:func:`layout_tag_sheets` places tags of one family and one size on pages of A4 or Letter,
row by row, in millimetres from the page's bottom-left corner (PDF's origin). Each tag gets a
*cut box*: the black-border square (``size``), its white quiet zone (:data:`QUIET_ZONE_CELLS`
cells, what the detector needs around the border) on every side, and below it a strip for the
label (family, id, size). Cut marks go at the cut box's corners, outside it, in the gap between
boxes. Only ink needs the printable area: the black square, the label and the page's text stay
:data:`MARGIN_MM` inside the paper's edge, while the white quiet zone is paper and may reach
into that margin (so a 0.16 m tag36h11, 200 mm with its quiet zone, fits A4's 210 mm).
The top of each page holds the printing instruction, the bottom a scale bar (:func:`scale_bar_mm`).
The drawing itself is :mod:`tagloc.io.tag_pdf`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from tagloc.tags.errors import TagInputError
from tagloc.tags.families import family_spec

__all__ = [
    "PAPER_MM",
    "QUIET_ZONE_CELLS",
    "SheetLayout",
    "SheetPage",
    "TagPlacement",
    "layout_tag_sheets",
    "parse_tag_ids",
    "scale_bar_mm",
]

#: Paper sizes (width, height), millimetres, portrait.
PAPER_MM: dict[str, tuple[float, float]] = {"a4": (210.0, 297.0), "letter": (215.9, 279.4)}
#: White cells around the black border inside the cut box (as AprilTag's reference images: the
#: detector needs a white surround to find the border).
QUIET_ZONE_CELLS = 1
#: Page margin that carries no ink (printers cannot print the outer 4-6 mm), millimetres. The
#: white quiet zone is unprinted paper, so it may reach into it, up to the paper's edge.
MARGIN_MM = 6.0
#: Gap between cut boxes (room for the cut marks), millimetres.
GAP_MM = 8.0
#: Height of the label strip under each tag, and of the header and footer bands, millimetres.
LABEL_MM = 7.0
HEADER_MM = 12.0
FOOTER_MM = 16.0
#: Room between the header and the first row's cut marks, millimetres.
CUT_SPACE_MM = 5.0
#: Most ids one command may print (a typo like ``0-5870`` should not make 5871 pages).
MAX_TAGS = 2000


@dataclass(frozen=True, slots=True)
class TagPlacement:
    """One tag on a page, millimetres from the page's bottom-left corner.

    Attributes
    ----------
    tag_id : int
    x_mm, y_mm : float
        Bottom-left corner of the black-border square.
    size_mm : float
        Edge of the black-border square.
    quiet_mm : float
        Width of the white quiet zone around it (inside the cut box).
    cut_box_mm : (float, float, float, float)
        ``(x, y, width, height)`` of the cut box (quiet zone and label strip included).
    """

    tag_id: int
    x_mm: float
    y_mm: float
    size_mm: float
    quiet_mm: float
    cut_box_mm: tuple[float, float, float, float]


@dataclass(frozen=True, slots=True)
class SheetPage:
    """The tags of one page."""

    placements: tuple[TagPlacement, ...]


@dataclass(frozen=True, slots=True)
class SheetLayout:
    """Every page of a print job.

    Attributes
    ----------
    family : str
    size_m : float
        Black-border edge, metres.
    paper : str
        A key of :data:`PAPER_MM`.
    page_mm : (float, float)
        Paper width and height, millimetres.
    pages : tuple of SheetPage
    per_page : int
        Tags that fit on one page.
    """

    family: str
    size_m: float
    paper: str
    page_mm: tuple[float, float]
    pages: tuple[SheetPage, ...]
    per_page: int


def parse_tag_ids(text: str, family: str) -> tuple[int, ...]:
    """Ids from ``"0-29"``, ``"3"``, ``"0-4,7,10-12"``: sorted, each once, all in the family.

    Raises
    ------
    TagInputError
        One line for a malformed list, an empty range, ids outside ``0 .. num_ids - 1`` or more
        than :data:`MAX_TAGS` ids.
    TagBackendError
        If ``family`` is unknown.
    """
    spec = family_spec(family)
    ids: set[int] = set()
    for part in text.replace(" ", "").split(","):
        match = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if match is None:
            raise TagInputError(f"--ids {text!r}: expected ids and ranges like 0-29 or 0-4,7,9")
        lo = int(match.group(1))
        hi = int(match.group(2)) if match.group(2) is not None else lo
        if hi < lo:
            raise TagInputError(f"--ids {text!r}: range {part} is empty (write low-high)")
        if hi >= spec.num_ids:
            raise TagInputError(
                f"--ids {text!r}: {family} has ids 0-{spec.num_ids - 1}, so {hi} is not one"
            )
        if hi - lo + 1 + len(ids) > MAX_TAGS:
            raise TagInputError(f"--ids {text!r}: more than {MAX_TAGS} tags in one print job")
        ids.update(range(lo, hi + 1))
    return tuple(sorted(ids))


def scale_bar_mm(page_width_mm: float) -> float:
    """Length of the scale bar: 100 mm, or the longest multiple of 10 mm that fits."""
    return float(min(100.0, 10.0 * math.floor((page_width_mm - 2 * MARGIN_MM - 40.0) / 10.0)))


def layout_tag_sheets(
    family: str, tag_ids: tuple[int, ...], size_m: float, paper: str = "a4"
) -> SheetLayout:
    """Place ``tag_ids`` in rows on as many pages as they need (module docstring).

    Parameters
    ----------
    family : str
        A known family.
    tag_ids : tuple of int
        Ids to print, in order (see :func:`parse_tag_ids`).
    size_m : float
        Black-border edge length, metres (what ``size`` means in ``tags.yaml``).
    paper : {"a4", "letter"}

    Returns
    -------
    SheetLayout

    Raises
    ------
    TagInputError
        An unknown paper, no ids, a size that is not positive or whose cut box does not fit
        the printable area of the paper (the message gives the largest size that does).
    """
    spec = family_spec(family)
    key = paper.lower()
    if key not in PAPER_MM:
        raise TagInputError(f"--paper {paper!r}: expected one of {', '.join(PAPER_MM)}")
    if not tag_ids:
        raise TagInputError("--ids: no tag to print")
    if not (math.isfinite(size_m) and size_m > 0):
        raise TagInputError(f"--size {size_m}: expected a positive edge length in metres")
    width_mm, height_mm = PAPER_MM[key]
    size_mm = 1000.0 * size_m
    quiet_mm = size_mm * QUIET_ZONE_CELLS / spec.border_cells
    box_w = size_mm + 2 * quiet_mm
    box_h = box_w + LABEL_MM
    usable_w = width_mm - 2 * MARGIN_MM
    usable_h = height_mm - 2 * MARGIN_MM - HEADER_MM - CUT_SPACE_MM - FOOTER_MM
    if size_mm > usable_w or box_w > width_mm or box_h > usable_h:
        grow = (spec.border_cells + 2 * QUIET_ZONE_CELLS) / spec.border_cells
        largest = min(usable_w, width_mm / grow, (usable_h - LABEL_MM) / grow)
        raise TagInputError(
            f"--size {size_m:g}: a {size_mm:.0f} mm tag (with its white border and label) does "
            f"not fit on {key} paper; the largest that does is {math.floor(largest) / 1000:g} m"
        )
    cols = max(1, int((usable_w + GAP_MM) // (box_w + GAP_MM)))
    rows = max(1, int((usable_h + GAP_MM) // (box_h + GAP_MM)))
    per_page = cols * rows
    # centre the grid horizontally; rows hang from the header
    x0 = (width_mm - (cols * box_w + (cols - 1) * GAP_MM)) / 2
    top = height_mm - MARGIN_MM - HEADER_MM - CUT_SPACE_MM
    pages: list[SheetPage] = []
    for start in range(0, len(tag_ids), per_page):
        placements = []
        for k, tag_id in enumerate(tag_ids[start : start + per_page]):
            row, col = divmod(k, cols)
            bx = x0 + col * (box_w + GAP_MM)
            by = top - (row + 1) * box_h - row * GAP_MM
            placements.append(
                TagPlacement(
                    tag_id=tag_id,
                    x_mm=bx + quiet_mm,
                    y_mm=by + LABEL_MM + quiet_mm,
                    size_mm=size_mm,
                    quiet_mm=quiet_mm,
                    cut_box_mm=(bx, by, box_w, box_h),
                )
            )
        pages.append(SheetPage(tuple(placements)))
    return SheetLayout(family, size_m, key, (width_mm, height_mm), tuple(pages), per_page)
