"""The layout of printed tag sheets: ids parsed, every tag on the paper, none overlapping."""

from __future__ import annotations

import itertools

import pytest

from tagloc.tags import TagInputError
from tagloc.tags.sheet import MARGIN_MM, PAPER_MM, layout_tag_sheets, parse_tag_ids


def test_ids_parse_ranges_and_lists() -> None:
    assert parse_tag_ids("0-3,7, 5", "tag36h11") == (0, 1, 2, 3, 5, 7)
    assert parse_tag_ids("586", "tag36h11") == (586,)
    with pytest.raises(TagInputError, match="tag16h5 has ids 0-29"):
        parse_tag_ids("0-30", "tag16h5")


@pytest.mark.parametrize(("size_m", "paper"), [(0.16, "a4"), (0.05, "letter"), (0.1, "a4")])
def test_tags_lie_on_the_paper_and_do_not_overlap(size_m: float, paper: str) -> None:
    layout = layout_tag_sheets("tag36h11", tuple(range(40)), size_m, paper)
    width, height = PAPER_MM[paper]
    placed = [p for page in layout.pages for p in page.placements]
    assert [p.tag_id for p in placed] == list(range(40))
    assert len(layout.pages) == -(-40 // layout.per_page)
    for page in layout.pages:
        for p in page.placements:
            # the black square (ink) inside the printable area, the cut box on the paper
            assert p.x_mm >= MARGIN_MM and p.x_mm + p.size_mm <= width - MARGIN_MM
            assert p.y_mm >= MARGIN_MM and p.y_mm + p.size_mm <= height - MARGIN_MM
            bx, by, bw, bh = p.cut_box_mm
            assert bx >= 0 and bx + bw <= width and by >= MARGIN_MM and by + bh <= height
            assert bx < p.x_mm and p.x_mm + p.size_mm < bx + bw
            assert p.size_mm == pytest.approx(1000 * size_m)
        for a, b in itertools.combinations(page.placements, 2):
            ax, ay, aw, ah = a.cut_box_mm
            bx, by, bw, bh = b.cut_box_mm
            assert ax + aw <= bx or bx + bw <= ax or ay + ah <= by or by + bh <= ay


def test_a_sheet_too_small_names_the_largest_size() -> None:
    with pytest.raises(TagInputError, match=r"largest that does is 0\.16"):
        layout_tag_sheets("tag36h11", (0,), 0.2, "a4")
    layout_tag_sheets("tag36h11", (0,), 0.168, "a4")  # the size named fits
