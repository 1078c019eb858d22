"""``tagloc eval tags``: the tag sensor's measurement sweep on rendered images.

Registers itself on :data:`tagloc.cli.eval_cmd.eval_app` (imported by :mod:`tagloc.cli.app`).
The work is :func:`tagloc.eval.tag_sweep.run_tag_sweep`; the files are
:func:`tagloc.eval.tag_sweep_report.write_tag_sweep`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from tagloc.cli.eval_cmd import eval_app

if TYPE_CHECKING:
    from tagloc.eval.tag_sweep import TagSweepResult
    from tagloc.eval.tag_sweep_config import TagSweepConfig


@eval_app.command("tags")
def eval_tags(
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("out/tag_sweep"),
    quick: Annotated[bool, typer.Option("--quick", help="A seconds-long 3x3 grid.")] = False,
    backend: Annotated[str | None, typer.Option(help="Detector: apriltag or aruco.")] = None,
    seed: Annotated[int | None, typer.Option(help="Sweep seed.")] = None,  # checked by the config
    trials: Annotated[int | None, typer.Option(help="Views per cell.")] = None,
    config: Annotated[
        Path | None, typer.Option("--config", help="Sweep config YAML (TagSweepConfig fields).")
    ] = None,
) -> None:
    """Sweep distance, viewing angle, blur and noise on rendered tag images; write the table
    (CSV, markdown), the config and plots to OUT, print the table and the checks."""
    from rich.progress import Progress

    from tagloc.eval.tag_sweep import run_tag_sweep
    from tagloc.eval.tag_sweep_report import SWEEP_FILES, write_tag_sweep
    from tagloc.fileutil import check_outputs

    check_outputs({"--out": out}, directories={"--out": SWEEP_FILES}, inputs={"--config": config})
    sweep = _sweep_config(config, quick, backend=backend, seed=seed, trials=trials)
    with Progress(transient=True) as bar:
        task = bar.add_task("rendering and detecting", total=None)
        result = run_tag_sweep(
            sweep, progress=lambda done, total: bar.update(task, completed=done, total=total)
        )
    paths = write_tag_sweep(result, out)
    print_tag_sweep(result)
    typer.echo(f"wrote {', '.join(p.name for p in paths)} to {out}")


def _sweep_config(path: Path | None, quick: bool, **overrides: Any) -> TagSweepConfig:
    """The file's config (or the defaults), the quick grid, then the options that were given.

    Raises
    ------
    ConfigError
        One line naming the bad field.
    """
    from tagloc.config import validate
    from tagloc.eval.tag_sweep_config import QUICK_GRID, TagSweepConfig, load_tag_sweep_config

    base = load_tag_sweep_config(path) if path is not None else TagSweepConfig()
    data = base.model_dump()
    if quick:
        data.update(QUICK_GRID)
    data.update({k: v for k, v in overrides.items() if v is not None})
    return validate(TagSweepConfig, data, str(path) if path else "tagloc eval tags")


def print_tag_sweep(result: TagSweepResult) -> None:
    """One rich table per blur/noise condition, the joint table, a summary line, the checks
    (the cells of ``summary.md``'s tables, :mod:`tagloc.eval.tag_sweep_report`)."""
    from rich.console import Console
    from rich.table import Table

    from tagloc.cli.eval_cmd import checks_table
    from tagloc.eval.tag_sweep_report import JOINT_COLUMNS, SWEEP_COLUMNS, joint_cells, sweep_cells
    from tagloc.eval.tag_sweep_stats import conditions

    console = Console(width=190)
    for blur, noise in conditions(result.rows):
        table = Table(title=f"tag sweep: blur {blur:g} px, read noise {noise:g} DN")
        for column in SWEEP_COLUMNS:
            table.add_column(column, justify="left" if column == "rejected" else "right")
        for r in result.rows:
            if (r.blur_px, r.noise_dn) == (blur, noise):
                table.add_row(*sweep_cells(r))
        console.print(table)
    if result.joint_rows:
        joint = Table(title="joint PnP, face-on (reference condition)")
        for column in JOINT_COLUMNS:
            joint.add_column(column, justify="right")
        for j in result.joint_rows:
            joint.add_row(*joint_cells(j))
        console.print(joint)
    nees = f"{result.nees_per_dof:.2f}" if math.isfinite(result.nees_per_dof) else "-"
    console.print(
        f"{result.n_views} views in {result.elapsed_s:.0f} s, flips {result.flips}, "
        f"NEES/dof {nees}, per frame: detection {result.detect_ms:.1f} ms,"
        f" PnP + covariance + gates {result.rest_ms:.2f} ms"
    )
    console.print(checks_table(result.checks, undecided="inconclusive"))
