"""``tagloc world coverage``: where the route sees no tag (:mod:`tagloc.sim.coverage`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError

from tagloc.cli.options import in_range, positive_int
from tagloc.errors import ConfigError

#: Most laps ``tagloc world coverage`` drives (each lap costs seconds and tens of MB).
MAX_LAPS = 10


def coverage(
    path: Annotated[
        Path | None, typer.Argument(help="World YAML file (default: the built-in office floor).")
    ] = None,
    laps: Annotated[
        int,
        typer.Option(help="Laps of the route to drive.", callback=in_range(ge=1, le=MAX_LAPS)),
    ] = 1,
    stride: Annotated[
        int, typer.Option(help="Check every n-th camera frame.", callback=positive_int)
    ] = 3,
    min_distance: Annotated[
        float,
        typer.Option(help="List gaps of at least this many metres ...", callback=in_range(ge=0)),
    ] = 1.0,
    min_rotation: Annotated[
        float,
        typer.Option(help="... or of this many degrees of turn.", callback=in_range(ge=0)),
    ] = 30.0,
    max_range: Annotated[
        float | None,
        typer.Option(
            help="Count a tag as in view within this range, m (default 8).",
            callback=in_range(gt=0),
        ),
    ] = None,
    max_view_angle: Annotated[
        float | None,
        typer.Option(
            help="... and this angle off its face, deg (default 75).",
            callback=in_range(gt=0, le=90),
        ),
    ] = None,
    csv_out: Annotated[
        Path | None, typer.Option("--csv", help="Also write the gaps as CSV.")
    ] = None,
) -> None:
    """List the stretches of the route where the camera sees no tag (plan tags before
    installing them: the survey and the filter run on odometry alone there)."""
    from rich.console import Console
    from rich.table import Table

    from tagloc.fileutil import atomic_write_text, check_outputs
    from tagloc.sim import ObservationConfig, load_default_world, load_world
    from tagloc.sim.coverage import gaps_csv, route_coverage

    check_outputs({"--csv": csv_out}, inputs={"PATH": path})
    world = load_default_world() if path is None else load_world(path)
    limits = {
        k: v
        for k, v in (("max_range_m", max_range), ("max_view_angle_deg", max_view_angle))
        if v is not None
    }
    try:
        config = ObservationConfig(**limits)
    except ValidationError as exc:
        raise ConfigError(f"--max-range / --max-view-angle: {exc.errors()[0]['msg']}") from exc
    report = route_coverage(
        world, config, laps=laps, stride=stride, min_distance_m=min_distance,
        min_rotation_deg=min_rotation,
    )  # fmt: skip
    table = Table(title=f"{world.name or path}: stretches with no tag in view")
    for name in ("t (s)", "from (x, y)", "to (x, y)", "m", "deg", "tags before", "tags after"):
        table.add_column(name, justify="right" if name in ("t (s)", "m", "deg") else "left")
    rows = [
        (
            f"{g.start_s:.1f}-{g.end_s:.1f}",
            f"{g.start_xy[0]:.1f}, {g.start_xy[1]:.1f}",
            f"{g.end_xy[0]:.1f}, {g.end_xy[1]:.1f}",
            f"{g.distance_m:.1f}",
            f"{g.rotation_deg:.0f}",
            " ".join(map(str, g.tags_before)) or "-",
            " ".join(map(str, g.tags_after)) or "-",
        )
        for g in report.gaps
    ]
    for row in rows:
        table.add_row(*row)
    console = Console()
    console.print(table)
    longest = report.longest()
    console.print(
        f"{report.length_m:.0f} m driven, {report.frames} frames checked: a tag in view over "
        f"{report.covered_fraction * 100:.1f} % of the distance; {len(report.gaps)} gaps of "
        f">= {min_distance:g} m or >= {min_rotation:g} deg"
        + (f", the longest {longest.distance_m:.1f} m" if longest else "")
    )
    if csv_out is not None:
        atomic_write_text(csv_out, gaps_csv(report))
        console.print(f"wrote {csv_out}")
