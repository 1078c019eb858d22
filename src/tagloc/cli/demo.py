"""``tagloc demo``: the main job on the built-in building, survey to evaluated localization.

Steps of :func:`run_demo`:

1. **Survey**: simulate a survey drive (the route with its own odometry seed), build the tag map
   from its drifting odometry, simulated detections and lidar sweeps (:mod:`tagloc.mapping`:
   scan matching; anchors: the first tag seen, or the ``--anchor`` tags, held at their true
   poses as if measured by hand), write ``map/tags.yaml``, its QA report, the premap
   ``map/premap.ply`` and the occupancy grid ``map/map.yaml`` + ``map/map.pgm`` (all in
   ``map``), and score the tags against the world's true poses and the grid against its walls.
   ``--no-lidar``: tags and odometry only.
2. **Localize**: simulate a second drive (the default scenario, legged odometry) and localize it
   through the same message stream a bag gives, with tag and lidar fixes against the *built*
   tag map and premap; for reference, also against the true (surveyed-by-hand) map and the
   world's true premap. ``--no-lidar``: tag fixes only.
3. **Evaluate**: the evaluation report of each run (``report.html``, ``summary.json``, TUM
   files; :func:`tagloc.eval.write_report`), the floor-plan plot, the world used, and a summary
   table on the terminal.

``--quick`` skips the survey (localizes against the true map only), for a fast look.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

from tagloc.eval.report import REPORT_FILES

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from tagloc.eval import EvalSummary
    from tagloc.eval.drive_report import DriveSummary
    from tagloc.localize.run import LocalizationRun
    from tagloc.mapping import BuildReport
    from tagloc.sim import World
    from tagloc.sim.survey import MapErrors
    from tagloc.tags.tagmap import TagMap

#: The files :func:`run_demo` may write into its output directory.
DEMO_FILES = (
    "world.yaml", "map/tags.yaml", "map/map_report.md", "map/premap.ply", "map/map.yaml",
    "map/map.pgm", "drive.png",
    *(f"{run}/{name}" for run in ("localize", "localize_true_map") for name in REPORT_FILES),
)  # fmt: skip
#: Survey drives use every n-th camera frame (30 Hz frames overlap; 10 Hz keeps the build short).
SURVEY_CAMERA_STRIDE = 3


@dataclass(frozen=True, slots=True)
class SurveyResult:
    """The demo's survey: the built map, its QA report, its errors against the world."""

    tag_map: TagMap
    report: BuildReport
    errors: MapErrors
    distance_m: float
    seconds: float
    anchors: tuple[int, ...]
    grid_iou: float | None = None
    #: ``(N, 3)`` premap points in ``map`` (None: a tags-only survey).
    premap_map: npt.NDArray[np.float64] | None = None


@dataclass(frozen=True, slots=True)
class DemoResult:
    """What :func:`run_demo` produced."""

    drive: DriveSummary
    survey: SurveyResult | None
    run_built_map: LocalizationRun | None
    run_true_map: LocalizationRun
    summaries: dict[str, EvalSummary]
    files: tuple[Path, ...]


def survey_and_build(
    world: World,
    seed: int,
    out: Path,
    anchors: Sequence[int] | None = None,
    lidar: bool = True,
) -> SurveyResult:
    """Simulate a survey drive with odometry seed ``seed``, build its tag map (``anchors``: tag
    ids held at their true poses; default the first tag seen; ``lidar``: with scan matching),
    write ``out/tags.yaml``, ``out/map_report.md`` and with lidar ``out/premap.ply`` and
    ``out/map.yaml`` + ``out/map.pgm``, and score the map against ``world``."""
    from tagloc.eval.occupancy import occupancy_iou
    from tagloc.io.survey_files import write_survey_outputs
    from tagloc.mapping import build_tag_map
    from tagloc.mapping.products import build_products
    from tagloc.sim import ObservationConfig, simulate_drive
    from tagloc.sim.survey import map_errors, sim_build_config, survey_and_anchors

    start = time.perf_counter()
    drive = simulate_drive(world, seed=seed)
    observation_config = ObservationConfig(seed=seed)
    survey, T_map_anchor = survey_and_anchors(
        drive, observation_config, list(anchors) if anchors else None, SURVEY_CAMERA_STRIDE,
        lidar=lidar,
    )  # fmt: skip
    config = sim_build_config(drive, observation_config, gravity_aligned=lidar)
    tag_map, report = build_tag_map(survey, T_map_anchor, config)
    texts = {out / "tags.yaml": tag_map.to_yaml_text(), out / "map_report.md": report.to_markdown()}
    iou, premap = None, None
    if lidar:
        built = build_products(survey, report, lidar_config=config.lidar)
        write_survey_outputs(
            texts, (out / "premap.ply", built.premap_map, "ply"), (out / "map.yaml", built.grid)
        )
        iou = occupancy_iou(built.grid, world).iou
        premap = built.premap_map
    else:
        write_survey_outputs(texts)
    distance = float(drive.distance_m[-1] - drive.distance_m[0])
    return SurveyResult(
        tag_map,
        report,
        map_errors(tag_map, world),
        distance,
        time.perf_counter() - start,
        tuple(e.id for e in tag_map.anchors),
        iou,
        premap,
    )


def run_demo(
    out: Path,
    world_path: Path | None,
    seed: int | None,
    duration_s: float | None = None,
    quick: bool = False,
    anchors: Sequence[int] = (),
    lidar: bool = True,
) -> DemoResult:
    """Survey, localize and evaluate (module docstring); every output lands in ``out``.

    Raises
    ------
    SimulationError
        An anchor id the world has no tag for (before anything is written).
    OutputPathError
        ``out`` or a file in it cannot be written (before any work).
    """
    from tagloc.eval import write_report
    from tagloc.eval.drive_report import summarize_drive
    from tagloc.eval.plots import plot_world_and_paths
    from tagloc.eval.scenarios import localize_scenario
    from tagloc.fileutil import atomic_write_text, check_outputs
    from tagloc.io import write_tum
    from tagloc.sim import load_default_world, load_world
    from tagloc.sim.scenario_source import ScenarioSource
    from tagloc.sim.scenarios import build_scenario

    check_outputs({"--out": out}, directories={"--out": DEMO_FILES}, inputs={"--world": world_path})
    console = Console()
    world = load_default_world() if world_path is None else load_world(world_path)
    for tag_id in anchors:
        world.find_tag(tag_id)
    seed = world.robot.odometry.seed if seed is None else seed
    # the drive to localize first: what fails on it fails before anything is written
    scenario = build_scenario("default", seed, duration_s, world=world)
    drive = summarize_drive(scenario.drive)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "world.yaml", world.to_yaml_text())
    files = [out / "world.yaml"]
    # 1. survey drive -> tag map (its own odometry seed: another walk through the building)
    survey = None
    if not quick:
        with console.status("surveying: simulated survey drive, factor-graph map build"):
            survey = survey_and_build(world, seed + 1, out / "map", anchors, lidar)
        files += [out / "map" / "tags.yaml", out / "map" / "map_report.md"]
        if lidar:
            files += [out / "map" / "premap.ply", out / "map" / "map.yaml"]
    # 2. localize the drive against the built map (and the true map for reference)
    use_lidar = lidar and world.robot.lidar is not None
    source = ScenarioSource(scenario, lidar=use_lidar)  # the drive's stream, shared by both runs
    with console.status("localizing against the true tag map (and the true premap)"):
        run_true = localize_scenario(scenario, source=source, lidar=use_lidar)
    run_built = None
    if survey is not None:
        with console.status("localizing against the built tag map and premap"):
            built = replace(scenario, tag_map=survey.tag_map)
            with_premap = use_lidar and survey.premap_map is not None
            run_built = localize_scenario(
                built, source=source, lidar=with_premap, premap=survey.premap_map
            )
    # 3. evaluation reports, the picture, the table
    run_true = _labelled(run_true, "the true tag map", "the true tag map (the world's tags, exact)")
    summaries = {
        "true map": write_report(run_true, out / "localize_true_map", write_trajectory=write_tum)
    }
    files += [out / "localize_true_map" / "report.html"]
    if run_built is not None:
        run_built = _labelled(
            run_built,
            "the built tag map",
            f"the built tag map ({out / 'map' / 'tags.yaml'}, from the survey)",
        )
        summaries["built map"] = write_report(
            run_built, out / "localize", write_trajectory=write_tum
        )
        files += [out / "localize" / "report.html"]
    main = run_built or run_true
    ate = summaries["built map" if run_built else "true map"].estimators["fused"].ate_rmse_m
    plot_world_and_paths(
        world,
        {"ground truth": scenario.drive.T_map_base, "odometry": scenario.drive.T_odom_base,
         "fused": main.T_map_base},
        out / "drive.png",
        title=f"{world.name}: {drive.length_m:.0f} m, {world.robot.odometry.model} odometry "
        f"(seed {scenario.drive.seed}) drifts {drive.endpoint_drift_m:.2f} m; fused ATE "
        f"{ate:.3f} m",
        tag_map=None if survey is None else survey.tag_map,
    )  # fmt: skip
    files.append(out / "drive.png")
    console.print(_table(drive, survey, summaries, main))
    console.print("wrote " + ", ".join(str(f) for f in files))
    return DemoResult(drive, survey, run_built, run_true, summaries, tuple(files))


def _table(
    drive: DriveSummary,
    survey: SurveyResult | None,
    summaries: dict[str, EvalSummary],
    run: LocalizationRun,
) -> Table:
    table = Table(title="tagloc demo: survey -> tag map -> map->odom localization")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    rows = [
        ("route length / duration", f"{drive.length_m:.1f} m / {drive.duration_s:.1f} s"),
        ("odometry samples / camera frames", f"{drive.n_poses} / {drive.n_camera_frames}"),
        (
            "odometry end-point drift",
            f"{drive.endpoint_drift_m:.3f} m ({drive.drift_percent:.2f} % of distance), "
            f"yaw {drive.endpoint_yaw_drift_deg:.1f} deg",
        ),
        ("odometry-only ATE RMSE (unaligned)", f"{drive.odom_ate.rmse:.3f} m"),
    ]
    if survey is not None:
        e, r = survey.errors, survey.report
        rows += [
            ("survey: distance / tags mapped",
             f"{survey.distance_m:.0f} m / {len(survey.tag_map)}"),
            ("survey: anchor tags (true poses)",
             f"{len(survey.anchors)}: " + ", ".join(str(i) for i in survey.anchors)),
            (
                "survey: map error vs truth (RMS)",
                f"{e.position_rms_m * 100:.1f} cm, {e.rotation_rms_deg:.2f} deg "
                f"({r.reproj_rms_px:.2f} px reprojection)",
            ),
            ("survey: build time", f"{survey.seconds:.1f} s"),
        ]  # fmt: skip
        if survey.grid_iou is not None:
            rows.append(("survey: occupancy grid vs walls (IoU)", f"{survey.grid_iou:.3f}"))
    for name, s in summaries.items():
        fused = s.estimators["fused"]
        reliability = fused.reliability.fraction if fused.reliability else math.nan
        rows += [
            (f"fused ATE RMSE, {name}", f"{fused.ate_rmse_m:.3f} m"),
            (f"reliability, {name}", f"{reliability * 100:.2f} % of opportunities"),
        ]
    main = summaries["built map" if "built map" in summaries else "true map"]
    fused = main.estimators["fused"]
    cap = main.cap_translation_m
    offered = [a for a in run.fixes if not a.decision.startswith("rejected:")]
    rows += [
        (
            "tag observations / offered / accepted",
            f"{len(run.fixes)} / {len(offered)} / {sum(a.accepted for a in offered)}",
        ),
        ("false fixes accepted", str(fused.false_fixes_accepted or 0)),
        ("largest correction jump", f"{fused.largest_jump_m:.3f} m (cap {cap:g} m per step)"),
    ]
    for name, s in summaries.items():
        failed = [c.name.split(" (")[0] for c in s.checks if c.passed is False]
        rows.append((f"checks, {name}", "all pass" if not failed else "FAIL: " + "; ".join(failed)))
    calibration = run.metadata.get("odometry_calibration")
    if isinstance(calibration, dict):
        scale = calibration["scale"]["value"] * 100
        rows.append(("odometry calibration (scale)", f"{scale:+.1f} % estimated"))
    for name, value in rows:
        table.add_row(name, value)
    return table


def _labelled(run: LocalizationRun, short: str, long: str) -> LocalizationRun:
    """The run named for the map it used (the two reports' titles differ), with ``map`` in its
    metadata (the report's overview lists it)."""
    return replace(run, name=f"{run.name} against {short}", metadata={**run.metadata, "map": long})
