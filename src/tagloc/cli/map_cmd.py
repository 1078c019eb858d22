"""``tagloc map``: check a tag map file, compare two (thin glue over :mod:`tagloc.tags.tagmap`).

- ``tagloc map check tags.yaml`` prints ``tags.yaml: ok: <summary>`` (tags per family, tags per
  frame, anchors), or one error line naming file, entry and field, and exits 1.
- ``tagloc map diff old.yaml new.yaml`` prints one line per change (see
  :mod:`tagloc.tags.tagmap_diff`), or ``no differences``. It exits 0 either way; with
  ``--exit-code`` it exits 1 when there are differences, like ``git diff --exit-code`` (an
  unreadable or invalid file also exits 1, with a ``tagloc: error:`` line on stderr).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

map_app = typer.Typer(help="Tag maps (tags.yaml): check one, compare two.", no_args_is_help=True)

MapFile = Annotated[Path, typer.Argument(help="Tag map YAML file.", show_default=False)]


@map_app.command("check")
def map_check(path: MapFile) -> None:
    """Validate a tag map; print a one-line summary or one line naming the bad field."""
    from tagloc.tags.tagmap import load_tag_map

    typer.echo(f"{path}: ok: {load_tag_map(path).summary()}")


@map_app.command("diff")
def map_diff(
    old: MapFile,
    new: MapFile,
    min_move_cm: Annotated[float, typer.Option(help="Smaller moves are not reported.")] = 0.5,
    min_rot_deg: Annotated[float, typer.Option(help="Smaller rotations are not reported.")] = 0.5,
    exit_code: Annotated[
        bool, typer.Option("--exit-code", help="Exit with 1 if the maps differ (as git diff).")
    ] = False,
) -> None:
    """Print what changed from OLD to NEW: added, removed, moved tags, changed fields."""
    from tagloc.tags.tagmap import load_tag_map
    from tagloc.tags.tagmap_diff import diff_tag_maps, format_tag_map_diff

    diff = diff_tag_maps(
        load_tag_map(old),
        load_tag_map(new),
        min_move_m=min_move_cm / 100.0,
        min_rot_deg=min_rot_deg,
    )
    typer.echo("\n".join(format_tag_map_diff(diff)) or f"no differences: {old} {new}")
    if exit_code and not diff.is_empty:
        raise typer.Exit(code=1)
