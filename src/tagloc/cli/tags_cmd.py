"""``tagloc tags``: tags to put on the walls.

``tagloc tags print --family tag36h11 --ids 0-29 --size 0.16 -o tags.pdf`` writes printable
sheets (A4 or Letter) with each tag at its exact size: the bitmap the detector decodes, its white
border, a label (family, id, size), cut marks, a scale bar and the instruction to print at
100 %. Ids outside the family, or a size that does not fit the paper, fail in one line before
anything is written.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tagloc.cli.options import in_range

tags_app = typer.Typer(help="Tags for the walls: print them at their exact size.",
                       no_args_is_help=True)  # fmt: skip


@tags_app.command("print")
def tags_print(
    out: Annotated[Path, typer.Option("--out", "-o", help="PDF file to write.")],
    ids: Annotated[str, typer.Option(help="Ids to print: 0-29, or 0-4,7,10-12.")],
    size: Annotated[
        float,
        typer.Option(
            help="Black-border edge, metres (the size in tags.yaml).",
            callback=in_range(gt=0, le=1.0),
        ),
    ] = 0.16,
    family: Annotated[
        str, typer.Option(help="Tag family (tag36h11, tag25h9, aruco_4x4_50, ...).")
    ] = "tag36h11",
    paper: Annotated[str, typer.Option(help="a4 or letter.")] = "a4",
) -> None:
    """Write printable sheets of tags at their exact physical size (print at 100 %)."""
    from tagloc.fileutil import check_outputs
    from tagloc.io.tag_pdf import write_tag_sheets
    from tagloc.tags.sheet import layout_tag_sheets, parse_tag_ids

    tag_ids = parse_tag_ids(ids, family)
    layout = layout_tag_sheets(family, tag_ids, size, paper)
    check_outputs({"--out": out})
    write_tag_sheets(layout, out)
    typer.echo(
        f"wrote {out}: {len(tag_ids)} {family} tags of {1000 * size:g} mm on "
        f"{len(layout.pages)} {layout.paper} page(s), {layout.per_page} a page; "
        "print at 100 % and measure the scale bar"
    )
