"""``tagloc demo``: simulate the built-in building drive, localize it against the tag map, report.

Steps of :func:`run_demo`: simulate the default scenario (legged odometry), plot the drive, write
the world used, localize through the same message stream a bag gives
(:func:`tagloc.sim.scenarios.localize_scenario`), print a summary table, then hand the
:class:`~tagloc.localize.run.LocalizationRun` to :func:`write_demo_report` (the evaluation
report's hook).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from rich.console import Console
from rich.table import Table

if TYPE_CHECKING:
    from tagloc.localize.run import LocalizationRun


def write_demo_report(run: LocalizationRun, out: Path) -> list[Path]:
    """Hook for the evaluation report (HTML, ``summary.json``) of the demo's run.

    Called by :func:`run_demo` after localization with the run and the output directory;
    returns the files written. The evaluation layer fills this in; until then it writes nothing.
    """
    del run, out
    return []


def largest_correction_jump_m(run: LocalizationRun) -> float:
    """Largest jump of the published ``T_map_base`` between consecutive odometry stamps at the
    same odometry, m, (re)initializations excluded (they snap by design)."""
    A = run.T_odom_base[1:]
    jump = (run.T_map_odom[:-1] @ A).inverse() @ (run.T_map_odom[1:] @ A)
    size = np.linalg.norm(np.asarray(jump.translation), axis=1)
    snaps = [e.stamp_ns for e in run.events if e.kind in ("initialized", "reinitialized_kidnap")]
    size[np.clip(np.searchsorted(run.stamps_ns, snaps) - 1, 0, len(size) - 1)] = 0.0
    size[~run.initialized[:-1]] = 0.0
    return float(size.max()) if len(size) else 0.0


def run_demo(
    out: Path, world_path: Path | None, seed: int | None, duration_s: float | None = None
) -> LocalizationRun:
    """Simulate, plot, localize and summarize one drive; write ``out/drive.png``,
    ``out/world.yaml`` and whatever :func:`write_demo_report` adds. Returns the run."""
    from tagloc.eval.drive_report import summarize_drive
    from tagloc.eval.plots import plot_world_and_paths
    from tagloc.fileutil import atomic_write_text
    from tagloc.sim import load_default_world, load_world
    from tagloc.sim.scenarios import build_scenario, localize_scenario

    console = Console()
    # 1. the world and one drive through it (the default scenario: tags as surveyed)
    world = load_default_world() if world_path is None else load_world(world_path)
    seed = world.robot.odometry.seed if seed is None else seed
    scenario = build_scenario("default", seed, duration_s, world=world)
    drive = scenario.drive
    summary = summarize_drive(drive)
    # 2. outputs: the picture, and the exact world used (so the run can be reproduced)
    out.mkdir(parents=True, exist_ok=True)
    plot_path = out / "drive.png"
    title = (
        f"{world.name}: {summary.length_m:.0f} m, {world.robot.odometry.model} odometry "
        f"(seed {drive.seed}) drifts {summary.endpoint_drift_m:.2f} m"
    )
    plot_world_and_paths(
        world,
        {"ground truth": drive.T_map_base, "odometry": drive.T_odom_base},
        plot_path,
        title=title,
    )
    atomic_write_text(out / "world.yaml", world.to_yaml_text())
    # 3. localize against the surveyed tag map, through the message stream
    run = localize_scenario(scenario)
    # 4. the summary table
    table = Table(title="tagloc demo: simulated drive, odometry vs fused (map -> odom filter)")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for name, value in _rows(summary, run):
        table.add_row(name, value)
    console.print(table)
    # 5. the evaluation report (hook)
    extra = write_demo_report(run, out)
    written = [str(plot_path), str(out / "world.yaml"), *map(str, extra)]
    console.print(f"wrote {', '.join(written)}")
    return run


def _rows(summary: object, run: LocalizationRun) -> list[tuple[str, str]]:
    from tagloc.eval.drive_report import DriveSummary

    assert isinstance(summary, DriveSummary) and run.T_map_base_truth is not None
    truth = np.asarray(run.T_map_base_truth.translation)
    fused = np.linalg.norm(np.asarray(run.T_map_base.translation) - truth, axis=1)
    offered = [a for a in run.fixes if not a.decision.startswith("rejected:")]
    accepted = sum(a.accepted for a in offered)
    gated = sum(a.decision.startswith("gated") for a in offered)
    cap = run.metadata.get("cap_translation_m", math.nan)
    return [
        ("route length", f"{summary.length_m:.1f} m"),
        ("duration", f"{summary.duration_s:.1f} s"),
        ("odometry samples / camera frames", f"{summary.n_poses} / {summary.n_camera_frames}"),
        ("tags in the world", f"{summary.n_tags}"),
        (
            "odometry end-point drift",
            f"{summary.endpoint_drift_m:.3f} m ({summary.drift_percent:.2f} % of distance)",
        ),
        ("odometry end-point yaw drift", f"{summary.endpoint_yaw_drift_deg:.2f} deg"),
        ("odometry-only ATE RMSE (unaligned)", f"{summary.odom_ate.rmse:.3f} m"),
        ("odometry ATE RMSE (SE(3)-aligned)", f"{summary.odom_ate_aligned.rmse:.3f} m"),
        ("fused ATE RMSE (unaligned)", f"{math.sqrt(float(np.mean(fused**2))):.3f} m"),
        ("fused max position error", f"{float(fused.max()):.3f} m"),
        (
            "tag observations / offered / accepted / gated",
            f"{len(run.fixes)} / {len(offered)} / {accepted} / {gated}",
        ),
        ("suspect sources", ", ".join(run.metadata.get("suspect_sources", [])) or "none"),  # type: ignore[arg-type]
        ("largest correction jump", f"{largest_correction_jump_m(run):.3f} m (cap {cap} m/update)"),
    ]
