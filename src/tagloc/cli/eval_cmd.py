"""``tagloc eval``: evaluation commands (each a few lines around a pure function).

- ``tagloc eval run --scenario NAME --out DIR``: simulate and localize a scenario, then write
  the evaluation (``report.html``, ``summary.json``, TUM files) and print the checks.
- ``tagloc eval files --truth truth.tum --est fused.tum [--est ...]``: ATE and RPE (as
  ``evo_ape`` / ``evo_rpe`` compute them) of TUM trajectories against a reference, e.g. the
  files ``tagloc localize`` wrote.

Sub-commands may also register themselves on :data:`eval_app` from their own modules.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from tagloc.cli.options import SCENARIO_HELP, duration_range, in_range, seed_range

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rich.table import Table

    from tagloc.eval.summary_types import Check, EvalSummary

eval_app = typer.Typer(
    help="Evaluate: localization runs against ground truth, the tag sensor by sweep.",
    no_args_is_help=True,
)


@eval_app.command("run")
def eval_run(
    scenario: Annotated[str, typer.Option(help=SCENARIO_HELP)],
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("out/eval"),
    seed: Annotated[int, typer.Option(help="Scenario seed.", callback=seed_range)] = 0,
    duration: Annotated[
        float | None, typer.Option(help="First N s only.", callback=duration_range)
    ] = None,
    range_m: Annotated[
        float, typer.Option(help="Z: opportunity range, m.", callback=in_range(gt=0, le=1e3))
    ] = 3.0,
    position_cm: Annotated[
        float, typer.Option(help="X: position tolerance, cm.", callback=in_range(gt=0, le=1e5))
    ] = 5.0,
    rotation_deg: Annotated[
        float, typer.Option(help="Y: rotation tolerance, deg.", callback=in_range(gt=0, le=180))
    ] = 2.0,
    strict: Annotated[bool, typer.Option("--strict", help="Exit 2 if a check fails.")] = False,
    lidar: Annotated[
        bool | None,
        typer.Option(
            "--lidar/--no-lidar",
            help="Use the lidar and the truth premap (default: when the world has a lidar).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Localize a simulated scenario and write its evaluation report to OUT."""
    from tagloc.eval import EvalConfig, write_report
    from tagloc.eval.report import REPORT_FILES
    from tagloc.eval.scenarios import run_scenario
    from tagloc.fileutil import check_outputs
    from tagloc.io import write_tum

    check_outputs({"--out": out}, directories={"--out": REPORT_FILES})
    config = EvalConfig(
        opportunity_range_m=range_m,
        position_tol_m=position_cm / 100.0,
        rotation_tol_deg=rotation_deg,
    )
    run = run_scenario(scenario, seed=seed, duration_s=duration, lidar=lidar)
    summary = write_report(run, out, write_trajectory=write_tum, config=config)
    print_summary(summary)
    typer.echo(f"wrote report.html, summary.json and TUM files to {out}")
    if strict and not summary.passed:
        raise typer.Exit(2)


def print_summary(summary: EvalSummary) -> None:
    """The estimators' headline numbers and the checks, as two rich tables."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{summary.name}: estimates of T_map_base")
    for column in ("estimate", "ATE RMSE (m)", "largest jump (m)", "false fixes", "reliability"):
        table.add_column(column, justify="right")
    for name, e in summary.estimators.items():
        r = e.reliability
        reliability = "" if r is None else f"{r.fraction:.4f}"
        if r is not None and r.in_cab.n_opportunities:  # the two populations, too
            reliability += f" (map {r.in_map.fraction:.4f}, cab {r.in_cab.fraction:.4f})"
        false = "" if e.false_fixes_accepted is None else str(e.false_fixes_accepted)
        table.add_row(name, f"{e.ate_rmse_m:.4f}", f"{e.largest_jump_m:.3f}", false, reliability)
    console = Console()
    console.print(table)
    console.print(checks_table(summary.checks))


def checks_table(checks: Sequence[Check], undecided: str = "n/a") -> Table:
    """Pass/fail checks as a rich table (check, value, target, result); ``undecided``: the
    result of a check with a value but no verdict (else "n/a")."""
    from rich.table import Table

    out = Table(title="checks")
    for column in ("check", "value", "target", "result"):
        out.add_column(column, justify="right")
    for c in checks:
        none = undecided if math.isfinite(c.value) else "n/a"
        result = {True: "[green]pass[/]", False: "[red]FAIL[/]", None: none}[c.passed]
        out.add_row(c.name, _num(c.value, 4, "g"), c.target, result)
    return out


def _num(value: float, digits: int, kind: str = "f") -> str:
    return f"{value:.{digits}{kind}}" if math.isfinite(value) else "n/a"


@eval_app.command("files")
def eval_files(
    truth: Annotated[Path, typer.Option(help="Reference TUM file (ground truth).")],
    est: Annotated[list[Path], typer.Option(help="Estimate TUM file (repeatable).")],
    delta_m: Annotated[
        float, typer.Option(help="RPE pair spacing, m of truth path.", callback=in_range(gt=0))
    ] = 1.0,
    max_diff_s: Annotated[
        float, typer.Option(help="Stamp association tolerance, s.", callback=in_range(ge=0))
    ] = 0.01,
    align: Annotated[bool, typer.Option("--align", help="SE(3)-align first (evo -a).")] = False,
    correct_scale: Annotated[
        bool, typer.Option("--correct-scale", help="With --align, also fit a scale (evo -as).")
    ] = False,
) -> None:
    """ATE and RPE of TUM trajectories against a reference TUM trajectory."""
    from rich.console import Console
    from rich.table import Table

    from tagloc.eval.compare import compare_trajectories
    from tagloc.io import read_tum

    stamps_ref_ns, T_map_base_ref = read_tum(truth)
    aligned = (" (Sim(3)-aligned)" if correct_scale else " (aligned)") if align else ""
    table = Table(title=f"against {truth}{aligned}")
    for column in ("estimate", "matched", "ATE RMSE (m)", "ATE max (m)",
                   f"RPE/{delta_m:g} m (m)", "RPE rot (deg)"):  # fmt: skip
        table.add_column(column, justify="right")
    for path in est:
        stamps_est_ns, T_map_base_est = read_tum(path)
        result = compare_trajectories(
            stamps_ref_ns, T_map_base_ref, stamps_est_ns, T_map_base_est,
            max_diff_s=max_diff_s, delta_m=delta_m, align=align, correct_scale=correct_scale,
        )  # fmt: skip
        rpe = result.rpe
        table.add_row(
            str(path), str(result.n_matched), f"{result.ate.rmse:.6f}", f"{result.ate.max:.6f}",
            "n/a" if rpe is None else f"{rpe.translation_rmse_m:.6f}",
            "n/a" if rpe is None else f"{rpe.rotation_rmse_deg:.4f}",
        )  # fmt: skip
    Console(width=160).print(table)
