"""Benchmark tagloc.sim: route planning, trajectory sampling, odometry, the default drive.

Run: ``.venv/bin/python benchmarks/bench_sim.py [--rate-hz 200] [--repeats 7]``

Prints the median wall time (over ``repeats``) of: planning the built-in office route; sampling it
at ``rate_hz`` (the route is ~377 m, so this covers the "300 m at 200 Hz" case); the legged drift
model on those samples; and ``simulate_drive`` on the default world (100 Hz odometry).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from tagloc.sim import load_default_world, simulate_drive
from tagloc.sim.odometry import DriftParameters, simulate_odometry_xy_yaw
from tagloc.sim.trajectory import generate_trajectory, plan_from_config


def median_s(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls (after one warm-up), seconds."""
    fn()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate-hz", type=float, default=200.0)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()

    world = load_default_world()
    plan = plan_from_config(world.route, world.checkpoints_xy())
    trajectory = generate_trajectory(plan, args.rate_hz)
    params = DriftParameters.from_config(world.robot.odometry)
    n = len(trajectory.stamps_ns)
    print(f"route: {plan.length_m:.1f} m, {plan.total_duration_s:.1f} s, {len(plan.kind)} pieces")
    rows = [
        ("plan route", lambda: plan_from_config(world.route, world.checkpoints_xy())),
        (
            f"sample {n} poses @ {args.rate_hz:g} Hz",
            lambda: generate_trajectory(plan, args.rate_hz),
        ),
        (
            f"legged odometry on {n} poses",
            lambda: simulate_odometry_xy_yaw(
                trajectory.xy_yaw_map_base, params, np.random.default_rng(0)
            ),
        ),
        ("simulate_drive(default world)", lambda: simulate_drive(world)),
    ]
    for name, fn in rows:
        print(f"{name:<40} {median_s(fn, args.repeats) * 1e3:8.1f} ms")


if __name__ == "__main__":
    main()
