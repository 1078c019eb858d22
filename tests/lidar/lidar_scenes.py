"""Synthetic lidar scenes for the tests: axis-aligned rectangles, a spinning lidar, ray casting.

A scene is a list of :class:`Rect` (a rectangle on the plane ``x[axis] = value`` bounded in the
two other axes). :func:`scan` ray-casts a 16-beam spinning lidar exactly against them (range
noise along each ray, NaN for no return); :func:`surface` samples the rectangles densely (the
premap of a perfect survey).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagloc.geometry import SE3


@dataclass(frozen=True)
class Rect:
    axis: int
    value: float
    low: tuple[float, float]  # bounds on the two other axes, in increasing axis order
    high: tuple[float, float]

    def others(self) -> tuple[int, int]:
        a, b = (k for k in range(3) if k != self.axis)
        return a, b


def box_room(lx: float = 8.0, ly: float = 6.0, lz: float = 3.0) -> list[Rect]:
    """Floor, ceiling and four walls of ``[0, lx] x [0, ly] x [0, lz]``."""
    return [
        Rect(2, 0.0, (0, 0), (lx, ly)), Rect(2, lz, (0, 0), (lx, ly)),
        Rect(0, 0.0, (0, 0), (ly, lz)), Rect(0, lx, (0, 0), (ly, lz)),
        Rect(1, 0.0, (0, 0), (lx, lz)), Rect(1, ly, (0, 0), (lx, lz)),
    ]  # fmt: skip


def corridor(length: float = 200.0, width: float = 2.5) -> list[Rect]:
    """Two parallel walls (y = 0 and y = width) and a floor along x, no end walls, no ceiling."""
    return [
        Rect(2, 0.0, (-length / 2, 0), (length / 2, width)),
        Rect(1, 0.0, (-length / 2, 0), (length / 2, 3.0)),
        Rect(1, width, (-length / 2, 0), (length / 2, 3.0)),
    ]


def directions(beams: int = 16, azimuths: int = 900, fov_deg: float = 30.0) -> np.ndarray:
    """``(beams * azimuths, 3)`` unit rays of a spinning lidar in its own frame."""
    elevation = np.deg2rad(np.linspace(-fov_deg / 2, fov_deg / 2, beams))
    azimuth = np.linspace(0.0, 2 * np.pi, azimuths, endpoint=False)
    el, az = np.meshgrid(elevation, azimuth, indexing="ij")
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1).reshape(
        -1, 3
    )


def scan(
    rects: list[Rect],
    T_map_lidar: SE3,
    rng: np.random.Generator,
    *,
    sigma_m: float = 0.01,
    max_range_m: float = 30.0,
    beams: int = 16,
    azimuths: int = 900,
) -> np.ndarray:
    """``(N, 3)`` points in the lidar frame (NaN rows: no return within ``max_range_m``)."""
    rays_lidar = directions(beams, azimuths)
    rays_map = T_map_lidar.rotation.act(rays_lidar)
    origin = np.asarray(T_map_lidar.translation)
    best = np.full(len(rays_map), np.inf)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for rect in rects:
            t = (rect.value - origin[rect.axis]) / rays_map[:, rect.axis]
            hit = origin + t[:, None] * rays_map
            a, b = rect.others()
            inside = (
                (t > 1e-6)
                & (hit[:, a] >= rect.low[0]) & (hit[:, a] <= rect.high[0])
                & (hit[:, b] >= rect.low[1]) & (hit[:, b] <= rect.high[1])
            )  # fmt: skip
            best = np.where(inside & (t < best), t, best)
    ranges = np.where(np.isfinite(best), best + rng.normal(0.0, sigma_m, best.shape), np.nan)
    points = rays_lidar * ranges[:, None]
    points[~(best <= max_range_m)] = np.nan
    return points


def surface(
    rects: list[Rect], rng: np.random.Generator, *, per_m2: float = 400.0, sigma_m: float = 0.0
) -> np.ndarray:
    """``(N, 3)`` points uniformly on the rectangles (``per_m2`` per square metre), in map."""
    chunks = []
    for rect in rects:
        a, b = rect.others()
        area = (rect.high[0] - rect.low[0]) * (rect.high[1] - rect.low[1])
        n = int(area * per_m2)
        points = np.empty((n, 3))
        points[:, rect.axis] = rect.value + rng.normal(0.0, sigma_m, n)
        points[:, a] = rng.uniform(rect.low[0], rect.high[0], n)
        points[:, b] = rng.uniform(rect.low[1], rect.high[1], n)
        chunks.append(points)
    return np.concatenate(chunks)
