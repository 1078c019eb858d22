"""The AprilTag detector's options measured: the tag sweep's accuracy beside the frame time.

For each option set (``quad_decimate``, ``quad_sigma``, ``nthreads``) this runs

- the tag sweep (:func:`tagloc.eval.run_tag_sweep`) on a reduced grid: 1, 2, 4 and 6 m, 0-75
  degrees off face-on, sharp and blurred (1.5 px), low and high read noise (1.5 and 8 DN),
  ``--trials`` seeded views a cell, 1280x720, 90-degree pinhole, one 0.16 m tag36h11 tag; the
  table gives tags detected and accepted out of the views, the RMS corner error against the
  renderer's truth (all cells, and the farthest range alone), and the fused-fix position median
  at 2 and 4 m;
- the frame time of :mod:`bench_detect`'s 1280x720 frames (four tags, 1-2.5 m), median over
  ``--repeats`` passes, measured in the same run for every option set. ``nthreads=2`` uses the
  second core; the others are pinned to one.

Run: ``.venv/bin/python benchmarks/bench_detector_options.py [--trials 3] [--repeats 10]``
"""

from __future__ import annotations

import argparse
import os
import time

import cv2
import numpy as np

from bench_detect import Frame
from tagloc.camera import PinholeRadtan
from tagloc.eval.tag_sweep import run_tag_sweep
from tagloc.eval.tag_sweep_config import TagSweepConfig
from tagloc.tags import make_detector

OPTION_SETS: tuple[dict[str, float | int], ...] = (
    {"quad_decimate": 1.0, "quad_sigma": 0.0},
    {"quad_decimate": 1.5, "quad_sigma": 0.0},
    {"quad_decimate": 2.0, "quad_sigma": 0.0},
    {"quad_decimate": 2.0, "quad_sigma": 0.8},
    {"quad_decimate": 3.0, "quad_sigma": 0.0},
    {"quad_decimate": 3.0, "quad_sigma": 0.8},
    {"quad_decimate": 4.0, "quad_sigma": 0.0},
    {"quad_decimate": 2.0, "quad_sigma": 0.0, "nthreads": 2},
)


def sweep_accuracy(options: dict[str, float | int], trials: int) -> dict[str, float]:
    """Detected, accepted (of views), corner RMS (all, farthest), position medians."""
    config = TagSweepConfig(
        distances_m=(1.0, 2.0, 4.0, 6.0), angles_deg=(0.0, 30.0, 60.0, 75.0),
        blur_px=(0.0, 1.5), noise_dn=(1.5, 8.0), trials=trials, joint_tag_counts=(),
        detector_options=dict(options),
    )  # fmt: skip
    result = run_tag_sweep(config)
    rows = result.rows
    views = sum(r.n_views for r in rows)

    def rms(selected: list[object]) -> float:
        pairs = [(r.corner_rms_px, r.n_detected) for r in selected]  # type: ignore[attr-defined]
        sq = sum(v**2 * n for v, n in pairs if n and np.isfinite(v))
        n = sum(n for v, n in pairs if n and np.isfinite(v))
        return float(np.sqrt(sq / n)) if n else float("nan")

    def median_at(distance: float) -> float:
        sharp = [r for r in rows if r.blur_px == 0.0 and r.noise_dn == 1.5]
        values = [r.position_error_median_m for r in sharp if r.distance_m == distance]
        return float(np.nanmedian(values)) if values else float("nan")

    return {
        "views": views,
        "detected": sum(r.n_detected for r in rows),
        "accepted": sum(r.n_accepted for r in rows),
        "corner_rms": rms(list(rows)),
        "corner_rms_far": rms([r for r in rows if r.distance_m == 6.0]),
        "pos_2m": median_at(2.0),
        "pos_4m": median_at(4.0),
    }


def frame_ms(options: dict[str, float | int], frames: list[Frame], repeats: int) -> float:
    """Median time of ``detect`` over the frames and passes, ms."""
    detector = make_detector("apriltag", "tag36h11", **options)
    detector.detect(frames[0].image)
    times = []
    for _ in range(repeats):
        for f in frames:
            start = time.perf_counter_ns()
            detector.detect(f.image)
            times.append((time.perf_counter_ns() - start) / 1e6)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3, help="views per sweep cell")
    parser.add_argument("--repeats", type=int, default=10, help="timing passes over the frames")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    width, height = 1280, 720
    camera = PinholeRadtan(width=width, height=height, fx=width / 2, fy=width / 2,
                           cx=(width - 1) / 2, cy=(height - 1) / 2)  # fmt: skip
    rng = np.random.default_rng(2024)
    frames = [Frame(camera, rng) for _ in range(5)]
    all_cpus = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else set()
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"AprilTag 3 tag36h11, 1280x720; sweep {args.trials} views a cell, timing "
          f"{args.repeats} passes x 5 frames of 4 tags; load average {load}")  # fmt: skip
    header = (f"{'decimate':>8s} {'sigma':>5s} {'thr':>3s} {'detected':>9s} {'accepted':>9s} "
              f"{'corner rms':>10s} {'rms @6m':>7s} {'pos 2m mm':>9s} {'pos 4m mm':>9s} "
              f"{'frame ms':>8s}")  # fmt: skip
    print(header)
    print("-" * len(header))
    for options in OPTION_SETS:
        threads = int(options.get("nthreads", 1))
        if all_cpus:
            os.sched_setaffinity(0, all_cpus if threads > 1 else {min(all_cpus)})
        ms = frame_ms(options, frames, args.repeats)
        acc = sweep_accuracy(options, args.trials)
        views = int(acc["views"])
        print(f"{options['quad_decimate']:8.1f} {options['quad_sigma']:5.1f} {threads:3d} "
              f"{int(acc['detected']):4d}/{views:<4d} {int(acc['accepted']):4d}/{views:<4d} "
              f"{acc['corner_rms']:10.3f} {acc['corner_rms_far']:7.3f} "
              f"{1e3 * acc['pos_2m']:9.1f} {1e3 * acc['pos_4m']:9.1f} {ms:8.2f}", flush=True)


if __name__ == "__main__":
    main()
