"""The typer application and its commands (each a few lines around a pure function)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tagloc.cli import localize_cmd
from tagloc.cli.detect_cmd import detect
from tagloc.cli.eval_bag_cmd import eval_bag  # noqa: F401  (registers tagloc eval bag)
from tagloc.cli.eval_bags_cmd import eval_bags  # noqa: F401  (registers tagloc eval bags)
from tagloc.cli.eval_cmd import eval_app
from tagloc.cli.eval_tags_cmd import eval_tags  # noqa: F401  (registers tagloc eval tags)
from tagloc.cli.map_cmd import map_app
from tagloc.cli.options import duration_range, in_range, seed_range
from tagloc.cli.sim_cmd import sim_app
from tagloc.cli.tags_cmd import tags_app
from tagloc.cli.world_cmd import coverage


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            typer.echo(f"tagloc {version('tagloc')}")
        except PackageNotFoundError:  # a source tree that was never installed
            typer.echo("tagloc (not installed: version unknown)")
        raise typer.Exit()


app = typer.Typer(
    name="tagloc",
    help="Fiducial-tag localization for indoor robots whose odometry drifts.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
world_app = typer.Typer(
    help="Simulated worlds: check a world file, find where its route sees no tag.",
    no_args_is_help=True,
)
world_app.command("coverage")(coverage)
app.add_typer(world_app, name="world")
app.add_typer(map_app, name="map")
app.add_typer(eval_app, name="eval")
app.add_typer(sim_app, name="sim")
app.add_typer(tags_app, name="tags")
app.command("localize")(localize_cmd.localize)
app.command("detect")(detect)


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", help="Print the version and exit.", callback=_version, is_eager=True
        ),
    ] = False,
) -> None:
    """Fiducial-tag localization for indoor robots whose odometry drifts."""


WorldOption = Annotated[
    Path | None,
    typer.Option("--world", help="World YAML file (default: the built-in office floor)."),
]


@app.command()
def demo(
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("out"),
    world: WorldOption = None,
    seed: Annotated[
        int | None, typer.Option(help="Override the odometry seed.", callback=seed_range)
    ] = None,
    duration: Annotated[
        float | None,
        typer.Option(help="Localize only the first N s of the drive.", callback=duration_range),
    ] = None,
    quick: Annotated[
        bool, typer.Option("--quick", help="Skip the survey; localize against the true map.")
    ] = False,
    anchor: Annotated[
        list[int],
        typer.Option(
            help="Survey anchor tag id, held at its true pose (repeat; default: the "
            "first tag seen).",
            callback=in_range(ge=0),
        ),
    ] = [],  # noqa: B006
    no_lidar: Annotated[
        bool, typer.Option("--no-lidar", help="Survey and localize with tags and odometry only.")
    ] = False,
) -> None:
    """Survey the built-in building, build its tag map, localize a drive against it, report."""
    from tagloc.cli.demo import run_demo

    run_demo(out=out, world_path=world, seed=seed, duration_s=duration, quick=quick,
             anchors=anchor, lidar=not no_lidar)  # fmt: skip


@world_app.command("check")
def world_check(path: Annotated[Path, typer.Argument(help="World YAML file.")]) -> None:
    """Validate a world file; print a one-line summary or one line naming the bad field."""
    from rich import print as rprint

    from tagloc.sim import load_world

    w = load_world(path)
    rprint(
        f"{path}: ok: {len(w.walls)} walls, {len(w.tags)} tags, "
        f"{len(w.route.waypoints)} route waypoints"
    )
