"""People for the simulated lidar: upright cylinders that walk a path or a seeded random walk.

A world file may list ``people`` (:class:`Person`); the ``crowd`` scenario makes its own
(:func:`crowd_around`): people walking with the robot, close enough to hide a requested fraction
of its lidar beams. People occlude lidar beams only: the camera's tag visibility is unchanged,
and people walk through walls (nothing steers them around the building).

Times are seconds after the route start; positions ``(x, y)`` in ``map``, metres.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from pydantic import Field, model_validator

from tagloc._types import FloatArray
from tagloc.config import FieldPathError, StrictModel

__all__ = ["Person", "RandomWalk", "crowd_around", "people_xy"]

_WALK_STEP_S = 0.5


class RandomWalk(StrictModel):
    """A seeded random walk from ``start`` at ``speed_mps``, turning by a Gaussian
    ``turn_sigma_deg`` every 0.5 s and bouncing off the box ``bounds = [x_min, y_min, x_max,
    y_max]``, for ``duration_s`` (then standing still)."""

    start: tuple[float, float]
    speed_mps: float = Field(default=1.0, ge=0.0, le=5.0)
    turn_sigma_deg: float = Field(default=30.0, ge=0.0, le=180.0)
    bounds: tuple[float, float, float, float]
    duration_s: float = Field(default=1800.0, gt=0.0, le=36000.0)
    seed: int = Field(default=0, ge=0)

    @model_validator(mode="after")
    def _check(self) -> RandomWalk:
        x0, y0, x1, y1 = self.bounds
        if not (x0 < x1 and y0 < y1):
            raise FieldPathError(("bounds",), "expected [x_min, y_min, x_max, y_max], min < max")
        if not (x0 <= self.start[0] <= x1 and y0 <= self.start[1] <= y1):
            raise FieldPathError(("start",), "lies outside bounds")
        return self

    def waypoints(self) -> FloatArray:
        """(K, 3) ``[t_s, x, y]`` every 0.5 s."""
        rng = np.random.default_rng(self.seed)
        n = math.ceil(self.duration_s / _WALK_STEP_S) + 1
        heading = rng.uniform(-math.pi, math.pi) + np.cumsum(
            rng.normal(0.0, math.radians(self.turn_sigma_deg), n)
        )
        lo, hi = np.array(self.bounds[:2]), np.array(self.bounds[2:])
        xy = np.empty((n, 2))
        xy[0] = self.start
        step = self.speed_mps * _WALK_STEP_S
        for i in range(1, n):
            p = xy[i - 1] + step * np.array([math.cos(heading[i]), math.sin(heading[i])])
            p = np.where(p < lo, 2 * lo - p, np.where(p > hi, 2 * hi - p, p))  # bounce
            xy[i] = np.clip(p, lo, hi)
        return np.column_stack([np.arange(n) * _WALK_STEP_S, xy])


class Person(StrictModel):
    """One person: an upright cylinder of ``radius_m`` and ``height_m`` standing on the floor,
    following either ``path`` (``[t_s, x, y]`` waypoints, times increasing, linear in between,
    standing still before the first and after the last) or ``random_walk``."""

    radius_m: float = Field(default=0.25, gt=0.0, le=2.0)
    height_m: float = Field(default=1.75, gt=0.0, le=3.0)
    path: tuple[tuple[float, float, float], ...] | None = None
    random_walk: RandomWalk | None = None

    @model_validator(mode="after")
    def _check(self) -> Person:
        if (self.path is None) == (self.random_walk is None):
            raise ValueError("give exactly one of 'path' or 'random_walk'")
        if self.path is not None:
            if not self.path:
                raise FieldPathError(("path",), "needs at least one waypoint")
            times = [p[0] for p in self.path]
            if any(b <= a for a, b in itertools.pairwise(times)):
                raise FieldPathError(("path",), "waypoint times must increase")
        return self

    def waypoints(self) -> FloatArray:
        """(K, 3) ``[t_s, x, y]``."""
        if self.path is not None:
            return np.array(self.path, dtype=np.float64)
        assert self.random_walk is not None
        return self.random_walk.waypoints()


def people_xy(waypoints: Sequence[FloatArray], t_s: FloatArray) -> FloatArray:
    """Positions ``(len(t_s), P, 2)`` of P people (their :meth:`Person.waypoints`) at ``t_s``."""
    t = np.asarray(t_s, dtype=np.float64)
    out = np.empty((len(t), len(waypoints), 2))
    for p, w in enumerate(waypoints):
        out[:, p, 0] = np.interp(t, w[:, 0], w[:, 1])
        out[:, p, 1] = np.interp(t, w[:, 0], w[:, 2])
    return out


def crowd_around(
    xy_yaw: FloatArray,
    t_s: FloatArray,
    blocked_fraction: float,
    *,
    distance_m: float = 0.9,
    radius_m: float = 0.25,
    height_m: float = 1.8,
    seed: int = 0,
) -> tuple[Person, ...]:
    """People walking with the robot so that they hide about ``blocked_fraction`` of a 360 degree
    scanner's beams.

    Each person keeps ``distance_m`` from the robot's path ``xy_yaw`` (``(K, 3)`` at ``t_s``,
    ``map``), at a bearing that wanders slowly (a seeded random walk, so the gaps between them
    move); the bearings stay evenly spread. A cylinder of radius r at distance D hides
    ``2 asin(r / D)`` of the circle, over every ring up to its height (true for the default
    Mid-360-like scanner at 0.9 m), so ``n = round(fraction * pi / asin(r / D))`` people.

    Raises
    ------
    ValueError
        If the fraction is not in ``(0, 0.9]`` or the people would overlap.
    """
    if not 0.0 < blocked_fraction <= 0.9:
        raise ValueError(f"blocked_fraction must be in (0, 0.9], got {blocked_fraction}")
    share = math.asin(radius_m / distance_m) / math.pi
    n = max(1, round(blocked_fraction / share))
    if n * 2 * share > 0.95:
        raise ValueError(f"{n} people of radius {radius_m} m overlap at {distance_m} m")
    rng = np.random.default_rng(seed)
    t = np.asarray(t_s, dtype=np.float64)
    steps = np.diff(t, prepend=t[0])
    wander = np.cumsum(rng.normal(0.0, 0.15, len(t)) * np.sqrt(steps))  # rad, shared drift
    people = []
    for i in range(n):
        bearing = xy_yaw[:, 2] + 2 * math.pi * i / n + wander
        x = xy_yaw[:, 0] + distance_m * np.cos(bearing)
        y = xy_yaw[:, 1] + distance_m * np.sin(bearing)
        path = tuple(zip(t.tolist(), x.tolist(), y.tolist(), strict=True))
        people.append(Person(radius_m=radius_m, height_m=height_m, path=path))
    return tuple(people)
