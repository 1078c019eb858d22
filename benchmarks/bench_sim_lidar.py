"""Benchmark the simulated lidar: ray casting (rays/s) and whole sweeps (scans/s).

Run: ``.venv/bin/python benchmarks/bench_sim_lidar.py [--repeats 5] [--sweeps 300] [--full]``

Times are this process's CPU time (``time.process_time``, medians over ``repeats``): the
machine may be shared, and wall time would measure the neighbours.

Rays: the 5 760 beams of one default sweep (16 rings x 360 columns) from the office route's
start against the office's walls (the cab's included) and the floor, cast by
:func:`tagloc.sim.lidar_cast.cast_rays` on its general path (rays x walls arrays), on its level
path (one floor-plane solution per column) and by a plain numpy reference (a Python loop over the
walls, each vectorized over the rays): the same rays, the same walls, no mirrors or glass, so the
three must agree (checked). Sweeps: :meth:`LidarSimulator.sweeps` along the default drive (true
poses, noise, mirror bounces, cab walls), and with ``--full`` the whole ~700 s drive.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from tagloc.sim import load_default_world, simulate_drive
from tagloc.sim.lidar import LidarSimulator
from tagloc.sim.lidar_cast import Segments, cast_rays


def median_s(fn: Callable[[], object], repeats: int) -> float:
    """Median CPU time of ``fn()`` over ``repeats`` calls (after one warm-up), seconds."""
    fn()
    samples = []
    for _ in range(repeats):
        start = time.process_time()
        fn()
        samples.append(time.process_time() - start)
    return statistics.median(samples)


def reference_cast(o: np.ndarray, d: np.ndarray, seg: Segments, max_range: float) -> np.ndarray:
    """Plain numpy: loop over the walls, keep the nearest hit per ray; then the floor."""
    best = np.full(len(o), np.inf)
    for a, b, h in zip(seg.start, seg.end, seg.height, strict=True):
        e = b - a
        denom = d[:, 0] * e[1] - d[:, 1] * e[0]
        w = a - o[:, :2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[:, 0] * e[1] - w[:, 1] * e[0]) / denom
            s = (w[:, 0] * d[:, 1] - w[:, 1] * d[:, 0]) / denom
        z = o[:, 2] + t * d[:, 2]
        ok = (t > 1e-6) & (s >= 0) & (s <= 1) & (z >= 0) & (z <= h)
        best = np.where(ok & (t < best), t, best)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(d[:, 2] < 0, -o[:, 2] / d[:, 2], np.inf)
    best = np.minimum(best, floor)
    return np.where(best <= max_range, best, np.inf)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sweeps", type=int, default=300)
    parser.add_argument("--full", action="store_true", help="also time the whole default drive")
    args = parser.parse_args()

    world = load_default_world()
    lidar = world.robot.lidar
    assert lidar is not None
    walls = [w.model_copy(update={"material": "wall"}) for w in world.walls_in_map()]
    sim = LidarSimulator(lidar, walls)
    drive = simulate_drive(world, seed=0)
    truth = lambda st: drive.ground_truth_at(st).xy_yaw_map_base  # noqa: E731
    sweep = sim.sweep(truth, int(drive.stamps_ns[0]), 0)
    rings = sim.directions_lidar.shape[1]
    origins = np.repeat(sweep.t_map_lidar, rings, axis=0)
    dirs = np.matmul(sim.directions_lidar, sweep.R_map_lidar.transpose(0, 2, 1)).reshape(-1, 3)
    seg = sim.segments
    n_rays = len(origins)

    general = cast_rays(origins, dirs, seg, lidar.max_range_m).range_m
    level = cast_rays(origins, dirs, seg, lidar.max_range_m, level_group=rings).range_m
    ref = reference_cast(origins, dirs, seg, lidar.max_range_m)
    for name, r in (("general", general), ("level", level)):
        finite = np.isfinite(ref)
        assert np.array_equal(finite, np.isfinite(r)), name
        assert np.abs(r[finite] - ref[finite]).max() < 1e-9, name

    print(
        f"{n_rays} rays x {len(seg.height)} walls + floor; {len(drive.stamps_ns) / 100:.0f} s drive"
    )
    print(f"{'cast (CPU time)':<44} {'ms':>8} {'Mrays/s':>9} {'vs ref':>7}")
    t_ref = median_s(lambda: reference_cast(origins, dirs, seg, lidar.max_range_m), args.repeats)
    rows = [
        ("numpy reference (loop over walls)", t_ref),
        (
            "cast_rays, general path",
            median_s(lambda: cast_rays(origins, dirs, seg, 40.0), args.repeats),
        ),
        (
            "cast_rays, level path",
            median_s(lambda: cast_rays(origins, dirs, seg, 40.0, level_group=rings), args.repeats),
        ),
    ]
    for name, t in rows:
        print(f"{name:<44} {t * 1e3:8.2f} {n_rays / t / 1e6:9.2f} {t_ref / t:6.2f}x")

    real = LidarSimulator(lidar, world.walls_in_map())  # mirror cab walls, noise: as the stream
    starts = real.sweep_starts_ns(int(drive.stamps_ns[0]), int(drive.stamps_ns[-1]))
    chunk = starts[: args.sweeps]
    t = median_s(lambda: sum(1 for _ in real.sweeps(truth, chunk)), max(1, args.repeats // 2))
    per = t / len(chunk)
    head = "sweeps (office drive, 16 x 360 beams)"
    print(f"\n{head:<44} {'ms/scan':>8} {'scans/s':>9} {'drive s':>7}")
    print(f"{f'{len(chunk)} sweeps':<44} {per * 1e3:8.2f} {1 / per:9.1f} {per * len(starts):7.1f}")
    if args.full:
        start = time.process_time()
        n = sum(1 for _ in real.sweeps(truth, starts))
        total = time.process_time() - start
        print(
            f"{f'whole drive: {n} sweeps':<44} {total / n * 1e3:8.2f} {n / total:9.1f} {total:7.1f}"
        )


if __name__ == "__main__":
    main()
