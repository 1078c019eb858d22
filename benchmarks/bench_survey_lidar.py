"""Cost of the lidar-aided survey: the default drive, built with and without lidar.

Run: ``.venv/bin/python benchmarks/bench_survey_lidar.py [--seed N]``

The demo's survey of the built-in office (legged odometry, seed 1, one anchor, every third
camera frame; the sweeps a recorder keeps every 0.5 m) built three ways on the same simulated
drive:

1. tags only (``--no-lidar``): the reference;
2. lidar-aided with each scan registered onto the previous one alone (scan-to-scan, as before
   the local maps and with one de-skew: ``local_map_m`` 0, ``deskew_passes`` 1): the reference
   the lidar-aided build is held to;
3. lidar-aided: keyframe scans (de-skew), registrations onto local maps (small_gicp), the pose
   rounds and the corner refinement with the scan factors, then the premap and the occupancy
   grid;
4. GTSAM alone: ``LevenbergMarquardtOptimizer.optimize()`` on the final pose-factor graph (tags,
   odometry and scan factors), the share no wrapper can remove.

Prints the stages, the tag position RMS against the truth and the grid's IoU against the walls.
Target: the lidar-aided build no slower than the scan-to-scan one (wall and CPU seconds; on a
shared machine the CPU seconds are the fairer measure).
"""

from __future__ import annotations

import argparse
import time

import gtsam
import numpy as np

from tagloc.eval.occupancy import occupancy_iou
from tagloc.mapping import build_tag_map
from tagloc.mapping.graph import build_graph, lm_params
from tagloc.mapping.products import build_products
from tagloc.sim import ObservationConfig, load_default_world, simulate_drive
from tagloc.sim.survey import map_errors, sim_build_config, survey_and_anchors

STRIDE = 3  # as the demo


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seed", type=int, default=1)
    seed = parser.parse_args().seed
    world = load_default_world()
    drive = simulate_drive(world, seed=seed)
    observations = ObservationConfig(seed=seed)
    config = sim_build_config(drive, observations, gravity_aligned=True)
    rows: list[tuple[str, float, str]] = []
    scan_to_scan = config.lidar.model_copy(
        update={"local_map_m": 0.0, "local_map_every": 1, "deskew_passes": 1}
    )
    cases = [("tags only", False, config),
             ("lidar-aided, scan-to-scan (before)", True,
              config.model_copy(update={"lidar": scan_to_scan})),
             ("lidar-aided", True, config)]  # fmt: skip
    for name, lidar, case_config in cases:
        start = time.perf_counter()
        survey, anchors = survey_and_anchors(drive, observations, None, STRIDE, lidar)
        simulate_s = time.perf_counter() - start
        start, cpu = time.perf_counter(), time.process_time()
        tag_map, report = build_tag_map(survey, anchors, case_config)
        build_s, cpu_s = time.perf_counter() - start, time.process_time() - cpu
        errors = map_errors(tag_map, world)
        t = report.timings_s
        sweeps = f", {len(survey.lidar)} sweeps kept" if survey.lidar is not None else ""
        if name != "lidar-aided, scan-to-scan (before)":
            rows.append((f"{name}: simulate survey", simulate_s, f"detections{sweeps}"))
        if lidar:
            m = report.scan_matching
            rows.append((f"{name}: keyframe scans", t["lidar_keyframes"],
                         f"{m['keyframes']} de-skewed, downsampled"))  # fmt: skip
            rows.append((f"{name}: registrations", t["scan_matching"],
                         f"{m['sequential']} consecutive + {m['loops']} loops "
                         f"({m['registrations']} small_gicp calls)"))  # fmt: skip
        rows.append((f"{name}: pose rounds", t["pose_rounds"], f"{report.keyframes} keyframes"))
        rows.append((f"{name}: corner refinement", t["corner_refinement"], ""))
        rows.append((f"{name}: build", build_s,
                     f"CPU {cpu_s:.1f} s; tag RMS {100 * errors.position_rms_m:.2f} cm, "
                     f"{errors.rotation_rms_deg:.2f} deg"
                     + ("; target: no slower than scan-to-scan" if name == "lidar-aided"
                        else "")))  # fmt: skip
        if name == "lidar-aided":
            start = time.perf_counter()
            products = build_products(survey, report, lidar_config=case_config.lidar)
            products_s = time.perf_counter() - start
            score = occupancy_iou(products.grid, world)
            rows.append(("lidar-aided: premap + occupancy grid", products_s,
                         f"{len(products.premap_map)} points; grid IoU {score.iou:.3f} "
                         f"(strict {score.iou_strict:.3f})"))  # fmt: skip
            rows.append(("gtsam alone (final pose graph)", _gtsam_alone(survey, anchors, config),
                         "LM optimize() on tags + odometry + scan factors"))  # fmt: skip
    width = max(len(name) for name, _, _ in rows)
    print(f"{'case':<{width}}  {'seconds':>8}  notes")
    for name, seconds, note in rows:
        shown = "       -" if np.isnan(seconds) else f"{seconds:8.3f}"
        print(f"{name:<{width}}  {shown}  {note}")


def _gtsam_alone(survey: object, anchors: object, config: object) -> float:
    """Seconds of GTSAM's LM on the lidar-aided pose graph, from the builder's initial values."""
    from tagloc.mapping import builder

    captured: list[object] = []
    solve = builder.solve_graph

    def spy(data: object, cfg: object) -> object:
        captured.append(data)
        return solve(data, cfg)  # type: ignore[arg-type]

    builder.solve_graph = spy  # type: ignore[assignment]
    try:
        builder.build_tag_map(survey, anchors, config)  # type: ignore[arg-type]
    finally:
        builder.solve_graph = solve
    graph, values = build_graph(captured[-1], config)  # type: ignore[arg-type]
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, lm_params(config))  # type: ignore[arg-type]
    start = time.perf_counter()
    optimizer.optimize()
    return time.perf_counter() - start


if __name__ == "__main__":
    main()
