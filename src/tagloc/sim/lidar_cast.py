"""Vectorized ray casting for the simulated lidar: rays against vertical walls (with heights and
materials), the floor plane and upright cylinders (people).

Frame: ``map`` (z up, floor at z = 0). A ray is an origin and a *unit* direction; its parameter
``t`` is the distance travelled, metres. Every ray is tested against every wall, the floor and
every cylinder at once (numpy arrays of shape ``(rays, walls)``); the nearest opaque hit wins.

Materials (:class:`~tagloc.sim.world.Wall`):

- ``wall``: opaque, returns.
- ``glass``: transparent; the beam passes. Rays flagged in ``glass_returns`` instead return from
  the nearest glass pane in front of their opaque hit (a weak return).
- ``mirror``: specular; the beam is reflected (``d' = d - 2 (d . n) n`` about the vertical mirror
  plane) and travels on; its return is reported at the *total* travelled distance along the
  original ray (so the point appears behind the mirror: phantom geometry, the reflection of the
  true hit across the mirror plane). After ``max_bounces`` reflections a beam reaching a mirror
  is lost.

The floor is an infinite plane z = 0; there is no ceiling. Cylinders are opaque from their side
(z in ``[0, height]``); their top is not modelled, and a ray starting inside one ignores it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray

__all__ = [
    "HIT_FLOOR",
    "HIT_GLASS",
    "HIT_NONE",
    "HIT_PERSON",
    "HIT_WALL",
    "CastResult",
    "Cylinders",
    "Segments",
    "cast_rays",
]

#: What a ray returned from (:attr:`CastResult.kind`).
HIT_NONE, HIT_WALL, HIT_FLOOR, HIT_PERSON, HIT_GLASS = 0, 1, 2, 3, 4
MATERIALS = {"wall": 0, "glass": 1, "mirror": 2}
_EPS = 1e-6  # m: a reflected ray does not hit the mirror it leaves


@dataclass(frozen=True, slots=True)
class Segments:
    """Vertical walls as arrays: ``start`` (W, 2), ``end`` (W, 2), ``height`` (W,), m, from the
    floor; ``material`` (W,) codes of :data:`MATERIALS`."""

    start: FloatArray
    end: FloatArray
    height: FloatArray
    material: npt.NDArray[np.int8]

    @classmethod
    def from_walls(cls, walls: Sequence[object]) -> Segments:
        """From :class:`~tagloc.sim.world.Wall` models (``start``, ``end``, ``height``,
        ``material``), for example ``world.walls_in_map()``."""
        rows = [(*w.start, *w.end, w.height, MATERIALS[w.material]) for w in walls]  # type: ignore[attr-defined]
        a = np.array(rows, dtype=np.float64).reshape(-1, 6)
        return cls(a[:, :2].copy(), a[:, 2:4].copy(), a[:, 4].copy(), a[:, 5].astype(np.int8))

    def subset(self, mask: npt.NDArray[np.bool_]) -> Segments:
        """The walls where ``mask`` is True."""
        return Segments(self.start[mask], self.end[mask], self.height[mask], self.material[mask])

    def normals(self) -> FloatArray:
        """(W, 2) unit normals of the walls in the floor plane."""
        e = self.end - self.start
        n = np.stack([-e[:, 1], e[:, 0]], axis=1)
        return np.asarray(n / np.linalg.norm(n, axis=1, keepdims=True))


@dataclass(frozen=True, slots=True)
class Cylinders:
    """Upright cylinders standing on the floor: ``centre`` (R, P, 2) per ray (people move during
    a sweep, so each ray sees them where they are when it fires) or (P, 2) for all rays;
    ``radius`` (P,), ``height`` (P,), m."""

    centre: FloatArray
    radius: FloatArray
    height: FloatArray


@dataclass(frozen=True, slots=True)
class CastResult:
    """Per ray: ``range_m`` (R,) the distance travelled to the return (``inf``: none within the
    range), ``kind`` (R,) int8 one of ``HIT_*`` of the final surface, ``bounces`` (R,) int8 the
    mirror reflections on the way, ``hit_map`` (R, 3) the *true* point that returned (for a
    reflected beam the real surface, not its phantom; NaN without a return)."""

    range_m: FloatArray
    kind: npt.NDArray[np.int8]
    bounces: npt.NDArray[np.int8]
    hit_map: FloatArray


def _cross(ax: FloatArray, ay: FloatArray, bx: FloatArray, by: FloatArray) -> FloatArray:
    return np.asarray(ax * by - ay * bx)


def _wall_hits(o: FloatArray, d: FloatArray, seg: Segments) -> FloatArray:
    """(R, W) distance along each ray to each wall (inf: misses it)."""
    ex, ey = (seg.end - seg.start).T
    dx, dy = d[:, 0:1], d[:, 1:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = _cross(dx, dy, ex[None], ey[None])
        wx, wy = seg.start[None, :, 0] - o[:, 0:1], seg.start[None, :, 1] - o[:, 1:2]
        t = _cross(wx, wy, ex[None], ey[None]) / denom
        s = _cross(wx, wy, dx, dy) / denom
        z = o[:, 2:3] + t * d[:, 2:3]
        ok = (t > _EPS) & (s >= 0.0) & (s <= 1.0) & (z >= 0.0) & (z <= seg.height[None])
    return np.where(ok, t, np.inf)


def _cylinder_hits(o: FloatArray, d: FloatArray, cyl: Cylinders) -> FloatArray:
    """(R, P) distance along each ray to each cylinder's side (inf: misses it)."""
    centre = cyl.centre if cyl.centre.ndim == 3 else cyl.centre[None]
    px, py = o[:, None, 0] - centre[..., 0], o[:, None, 1] - centre[..., 1]
    dx, dy = d[:, 0:1], d[:, 1:2]
    a = dx * dx + dy * dy
    b = 2.0 * (dx * px + dy * py)
    c = px * px + py * py - cyl.radius[None] ** 2
    disc = b * b - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
        z = o[:, 2:3] + t * d[:, 2:3]
        ok = (disc >= 0.0) & (c > 0.0) & (t > _EPS) & (z >= 0.0) & (z <= cyl.height[None])
    return np.where(ok, t, np.inf)


def _nearest_wall(
    o: FloatArray, d: FloatArray, seg: Segments, group: int
) -> tuple[FloatArray, npt.NDArray[np.intp]]:
    """Per ray the distance to the nearest wall of ``seg`` (inf: none) and its index.

    With ``group`` > 0 the rays come in consecutive groups that share their origin and
    horizontal heading (the rings of one column of a level scanner): the floor-plane problem is
    solved once per group and each ray only checks the height of its hit."""
    if not len(seg.height):
        return np.full(len(o), np.inf), np.zeros(len(o), np.intp)
    if group <= 0:
        t = _wall_hits(o, d, seg)
        j = np.argmin(t, axis=1)
        return t[np.arange(len(o)), j], j
    og, dg = o[::group], d[::group].copy()
    scale = np.hypot(d[:, 0], d[:, 1])  # (R,) horizontal part of each unit direction
    dg[:, :2] /= scale[::group, None]
    ex, ey = (seg.end - seg.start).T
    dx, dy = dg[:, 0:1], dg[:, 1:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = _cross(dx, dy, ex[None], ey[None])
        wx, wy = seg.start[None, :, 0] - og[:, 0:1], seg.start[None, :, 1] - og[:, 1:2]
        h = _cross(wx, wy, ex[None], ey[None]) / denom  # (G, W) horizontal distance
        s = _cross(wx, wy, dx, dy) / denom
        h = np.where((h > _EPS) & (s >= 0.0) & (s <= 1.0), h, np.inf)
        slope = (d[:, 2] / scale).reshape(-1, group, 1)  # dz per horizontal metre
        z = og[:, None, 2:3] + h[:, None, :] * slope  # (G, group, W)
        hr = np.where((z >= 0.0) & (z <= seg.height), h[:, None, :], np.inf).reshape(len(o), -1)
    j = np.argmin(hr, axis=1)
    return hr[np.arange(len(o)), j] / scale, j


def cast_rays(
    origins: FloatArray,
    directions: FloatArray,
    segments: Segments,
    max_range_m: float,
    *,
    cylinders: Cylinders | None = None,
    max_bounces: int = 1,
    glass_returns: npt.NDArray[np.bool_] | None = None,
    level_group: int = 0,
) -> CastResult:
    """Cast rays into the scene (module docstring for the materials).

    Parameters
    ----------
    origins, directions : (R, 3) float
        In ``map``; directions of unit length.
    segments : Segments
        The walls.
    max_range_m : float
        Returns farther than this (total travelled distance) are dropped.
    cylinders : Cylinders, optional
        People; ``centre`` per ray (R, P, 2) or shared (P, 2).
    max_bounces : int
        Mirror reflections a beam may make (0: a mirror swallows the beam).
    glass_returns : (R,) bool, optional
        Rays that return from the first glass pane they reach.
    level_group : int
        If > 0: the rays come in consecutive groups of this size that share their origin and
        horizontal heading (a level scanner's columns; no ray vertical), which is solved faster.
        The caller guarantees it; the result is the same.

    Returns
    -------
    CastResult
    """
    o = np.array(origins, dtype=np.float64).reshape(-1, 3)  # copies: reflected rays move
    d = np.array(directions, dtype=np.float64).reshape(-1, 3)
    n = len(o)
    result_range = np.full(n, np.inf)
    kind = np.zeros(n, np.int8)
    bounces = np.zeros(n, np.int8)
    hit = np.full((n, 3), np.nan)
    glass_mask = segments.material == MATERIALS["glass"]
    opaque, glass = segments.subset(~glass_mask), segments.subset(glass_mask)
    normals = opaque.normals()
    mirror_mask = opaque.material == MATERIALS["mirror"]
    active = np.arange(n)
    travelled = np.zeros(n)
    for bounce in range(max_bounces + 1):
        if not len(active):
            break
        oa, da = o[active], d[active]
        group = level_group if bounce == 0 else 0
        t_wall, j = _nearest_wall(oa, da, opaque, group)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_floor = np.where(da[:, 2] < 0.0, -oa[:, 2] / da[:, 2], np.inf)
        t_floor = np.where(t_floor > _EPS, t_floor, np.inf)
        t_person = np.full(len(oa), np.inf)
        if cylinders is not None and len(cylinders.radius):
            sub = cylinders
            if cylinders.centre.ndim == 3:
                sub = Cylinders(cylinders.centre[active], cylinders.radius, cylinders.height)
            t_person = _cylinder_hits(oa, da, sub).min(axis=1)
        t = np.minimum(np.minimum(t_wall, t_floor), t_person)
        k = np.where(
            t == np.inf,
            HIT_NONE,
            np.where(t == t_wall, HIT_WALL, np.where(t == t_floor, HIT_FLOOR, HIT_PERSON)),
        ).astype(np.int8)
        if glass_returns is not None and len(glass.height):
            t_glass = _nearest_wall(oa, da, glass, group)[0]
            weak = glass_returns[active] & (t_glass < t)
            t, k = np.where(weak, t_glass, t), np.where(weak, HIT_GLASS, k).astype(np.int8)
        total = travelled[active] + t
        mirror = (k == HIT_WALL) & mirror_mask[j] & (total <= max_range_m)
        done = ~mirror & (k != HIT_NONE) & (total <= max_range_m)
        idx = active[done]
        result_range[idx], kind[idx], bounces[idx] = total[done], k[done], bounce
        hit[idx] = oa[done] + t[done, None] * da[done]
        if bounce == max_bounces:
            break
        # reflect the beams that reached a mirror and cast them on from the mirror
        m_idx = active[mirror]
        nrm = normals[j[mirror]]
        dm = da[mirror]
        dot = dm[:, 0] * nrm[:, 0] + dm[:, 1] * nrm[:, 1]
        reflected = dm.copy()
        reflected[:, :2] -= 2.0 * dot[:, None] * nrm
        o[m_idx] = oa[mirror] + t[mirror, None] * dm
        d[m_idx] = reflected
        travelled[m_idx] = total[mirror]
        active = m_idx
    return CastResult(result_range, kind, bounces, hit)
