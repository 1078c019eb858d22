"""Per-scan time of the lidar fix against a prepared office premap, beside bare small_gicp.

Scene: a synthetic 40 m x 20 m office floor (this script's own generator): outer walls, a 2.5 m
corridor along x with 1 m doorways, 8 rooms of 10 m x 8.75 m on each side, floor and a 3 m
ceiling. The premap samples every surface at 400 points/m^2 (3 mm noise); it is prepared ONCE
(:meth:`tagloc.lidar.Target.from_points`: voxel grid, covariances, KD-tree). Scans: a spinning
lidar (16 or 32 beams, +-15 deg, 1 cm range noise, 30 m range) ray-cast from random poses in
rooms and the corridor; the prior is the true pose perturbed by 0.1 m / 1 deg (seeded).

Per scan, timed back to back on the same clouds:

- ``lidar_fix``: :func:`tagloc.lidar.lidar_fix` with the default configuration (0.25 m voxels;
  range filter, source preprocessing, GICP, point-to-plane information, degeneracy, gates,
  covariance);
- ``align``: small_gicp bare on the prepared target: ``preprocess_points(scan)`` +
  ``align(target, source, target_tree)`` (the reference: registration alone);
- ``one-call``: ``small_gicp.align(premap, scan)``, which prepares the premap again every call
  (a few scans only): why the target is prepared once.

One core: the process is pinned to one CPU and every small_gicp call uses 1 thread. Both wall
clock and process CPU time are printed: on a shared machine the wall clock includes the time
other processes hold the core.

Run: ``.venv/bin/python benchmarks/bench_icp.py [--scans 40]``
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import small_gicp

from bench_detect import pin_one_core  # the same pinning as the detector benchmark
from tagloc.geometry import SE3
from tagloc.lidar import LidarFixConfig, Target, lidar_fix

#: Rectangles (axis, value, (low a, low b), (high a, high b)) on the two other axes in order.
Rect = tuple[int, float, tuple[float, float], tuple[float, float]]
LX, LY, LZ = 40.0, 20.0, 3.0
CORRIDOR = (8.75, 11.25)


def office() -> list[Rect]:
    """Walls, floor and ceiling of the office floor (rooms on both sides of a corridor)."""
    rects: list[Rect] = [(2, 0.0, (0, 0), (LX, LY)), (2, LZ, (0, 0), (LX, LY))]
    rects += [(0, 0.0, (0, 0), (LY, LZ)), (0, LX, (0, 0), (LY, LZ))]
    rects += [(1, 0.0, (0, 0), (LX, LZ)), (1, LY, (0, 0), (LX, LZ))]
    for k in range(4):  # partitions between rooms, both sides
        x = 10.0 * (k + 1)
        if k < 3:
            rects += [(0, x, (0, 0), (CORRIDOR[0], LZ)), (0, x, (CORRIDOR[1], 0), (LY, LZ))]
        for y in CORRIDOR:  # corridor walls with a 1 m doorway per room
            door = 10.0 * k + 4.5
            rects += [
                (1, y, (10.0 * k, 0), (door, LZ)),
                (1, y, (door + 1.0, 0), (10.0 * k + 10, LZ)),
            ]
    return rects


def surface(rects: list[Rect], rng: np.random.Generator, per_m2: float) -> np.ndarray:
    chunks = []
    for axis, value, low, high in rects:
        a, b = (k for k in range(3) if k != axis)
        n = int((high[0] - low[0]) * (high[1] - low[1]) * per_m2)
        points = np.empty((n, 3))
        points[:, axis] = value + rng.normal(0.0, 0.003, n)
        points[:, a] = rng.uniform(low[0], high[0], n)
        points[:, b] = rng.uniform(low[1], high[1], n)
        chunks.append(points)
    return np.concatenate(chunks)


def scan(rects: list[Rect], T_map_lidar: SE3, rng: np.random.Generator, beams: int, az: int):
    el, azi = np.meshgrid(np.deg2rad(np.linspace(-15, 15, beams)),
                          np.linspace(0, 2 * np.pi, az, endpoint=False), indexing="ij")  # fmt: skip
    rays = np.stack([np.cos(el) * np.cos(azi), np.cos(el) * np.sin(azi), np.sin(el)], -1)
    rays = rays.reshape(-1, 3)
    rays_map = T_map_lidar.rotation.act(rays)
    origin = np.asarray(T_map_lidar.translation)
    best = np.full(len(rays), np.inf)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for axis, value, low, high in rects:
            a, b = (k for k in range(3) if k != axis)
            t = (value - origin[axis]) / rays_map[:, axis]
            hit = origin + t[:, None] * rays_map
            inside = (t > 1e-6) & (hit[:, a] >= low[0]) & (hit[:, a] <= high[0])
            inside &= (hit[:, b] >= low[1]) & (hit[:, b] <= high[1])
            best = np.where(inside & (t < best), t, best)
    keep = best <= 30.0
    return rays[keep] * (best[keep] + rng.normal(0.0, 0.01, keep.sum()))[:, None]


def random_pose(rng: np.random.Generator) -> SE3:
    if rng.random() < 0.3:  # corridor
        xy = (rng.uniform(2, LX - 2), rng.uniform(CORRIDOR[0] + 0.5, CORRIDOR[1] - 0.5))
    else:
        room = rng.integers(8)
        y0 = 0.0 if rng.random() < 0.5 else CORRIDOR[1]
        xy = (10.0 * (room % 4) + rng.uniform(1.5, 8.5), y0 + rng.uniform(1.5, 7.25))
    return SE3.from_rotvec([0, 0, rng.uniform(-np.pi, np.pi)], [*xy, 0.5])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=40, help="scans per lidar configuration")
    args = parser.parse_args()
    pinned = pin_one_core()
    rng = np.random.default_rng(2026)
    config = LidarFixConfig()
    rects = office()
    premap = surface(rects, rng, 400.0)
    start = time.perf_counter()
    target = Target.from_points(premap, config.registration)
    prepare_s = time.perf_counter() - start
    cloud, tree = small_gicp.preprocess_points(
        premap, config.registration.voxel_m, config.registration.num_neighbors
    )
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"office {LX:.0f} m x {LY:.0f} m: premap {len(premap):,} points -> {len(target):,} "
          f"after the {config.registration.voxel_m} m voxel grid; target preparation "
          f"{prepare_s * 1e3:.0f} ms (once); small_gicp 1 thread, {pinned}; "
          f"load {load}")  # fmt: skip
    header = (f"{'lidar':>7s} {'points':>6s} | {'fix p50':>7s} {'p95':>6s} {'cpu p50':>7s} "
              f"{'p95':>6s} | {'align p50':>9s} {'p95':>6s} {'cpu p50':>7s} {'p95':>6s} | "
              f"{'fix/align':>9s} {'one-call':>8s} {'accepted':>8s} {'err p95 mm':>10s} "
              f"{'k=6':>4s}")  # fmt: skip
    print(header)
    print("-" * len(header))
    reg = config.registration
    for beams, az in ((16, 360), (16, 900), (32, 600)):
        fix_t, align_t, one_ms, errors, sizes, full, accepted = [], [], [], [], [], 0, 0
        for i in range(args.scans):
            T_map_base = random_pose(rng)
            points = scan(rects, T_map_base, rng, beams, az)
            prior = T_map_base.compose(SE3.exp(np.r_[rng.normal(0, 0.1, 2), 0, 0, 0,
                                                     rng.normal(0, np.deg2rad(1))]))  # fmt: skip
            wall, cpu = time.perf_counter(), time.process_time()
            fix = lidar_fix(points, target, prior, config)
            fix_t.append(((time.perf_counter() - wall) * 1e3, (time.process_time() - cpu) * 1e3))
            wall, cpu = time.perf_counter(), time.process_time()
            source, _ = small_gicp.preprocess_points(points, reg.voxel_m, reg.num_neighbors)
            small_gicp.align(cloud, source, tree, prior.as_matrix(),
                             max_correspondence_distance=reg.max_correspondence_m,
                             max_iterations=reg.max_iterations,
                             rotation_epsilon=reg.rotation_epsilon_rad,
                             translation_epsilon=reg.translation_epsilon_m)  # fmt: skip
            align_t.append(((time.perf_counter() - wall) * 1e3, (time.process_time() - cpu) * 1e3))
            if i < 3:
                start = time.process_time()
                small_gicp.align(premap, points, prior.as_matrix(),
                                 downsampling_resolution=reg.voxel_m)  # fmt: skip
                one_ms.append((time.process_time() - start) * 1e3)
            sizes.append(len(points))
            if fix.accepted:
                accepted += 1
                full += fix.basis.shape[1] == 6
                error_map = fix.T_map_base.translation - T_map_base.translation
                error_base = T_map_base.rotation.inverse().act(error_map)
                errors.append(np.linalg.norm(fix.basis[:3].T @ error_base))
        f = np.percentile(fix_t, [50, 95], axis=0)  # rows p50, p95; columns wall, cpu
        a = np.percentile(align_t, [50, 95], axis=0)
        print(f"{f'{beams}x{az}':>7s} {np.mean(sizes):6.0f} | {f[0, 0]:7.1f} {f[1, 0]:6.1f} "
              f"{f[0, 1]:7.1f} {f[1, 1]:6.1f} | {a[0, 0]:9.1f} {a[1, 0]:6.1f} {a[0, 1]:7.1f} "
              f"{a[1, 1]:6.1f} | {f[0, 1] / a[0, 1]:9.2f} {np.median(one_ms):8.0f} "
              f"{f'{accepted}/{args.scans}':>8s} {1e3 * np.percentile(errors, 95):10.2f} "
              f"{full:4d}")  # fmt: skip
    print(
        "ms per scan; wall clock and process CPU time (the machine may be shared: CPU time is "
        "what one core spends); fix/align = CPU p50 ratio; one-call = CPU median of 3 scans; "
        "err = constrained translation error of accepted fixes; k=6: fully constrained fixes"
    )


if __name__ == "__main__":
    main()
