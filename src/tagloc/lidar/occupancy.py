"""A 2D occupancy grid by log-odds ray casting, and the point-cloud premap (pure numpy).

Occupancy (Thrun, Burgard, Fox, "Probabilistic Robotics", 2005, Ch. 9): each scan's points in a
height band above the floor (``z_min_m .. z_max_m`` in ``map``) are cast as 2D rays from the
sensor's position. Per scan, the cells a ray crosses (a DDA / Bresenham line of cells, the
start cell included, the end cell excluded) gain ``log_odds_miss`` once, and each end cell gains
``log_odds_hit`` once (a cell that is both an end and crossed in the same scan counts as an end).
After every scan the log odds are clamped to ``[clamp_min, clamp_max]`` (OctoMap's scheme: a
cell can change its mind after a few scans). Defaults: hit probability 0.6 (``+0.405``), miss
0.4 (``-0.405``), clamp 0.12 .. 0.97 (``-1.99 .. +3.48``, OctoMap's). The hit is weaker than
OctoMap's 0.7 so that a cell must be hit in two scans before it counts as occupied
(``0.405 < logit(0.65) = 0.619 < 0.81``): a single stray return (the tail of the range noise
behind a wall, a person walking by) leaves it unknown. A free cell needs four crossing scans
(``4 x 0.405 > |logit(0.196)| = 1.41``).

The grid is stored as the ROS map_server image: row 0 is the TOP row (largest ``y``), column 0
the smallest ``x``; ``origin_xyz_yaw`` is the map pose of the lower-left corner of the
lower-left cell (yaw 0: the grid is aligned with ``map``). A cell is occupied when its
probability is above ``occupied_thresh`` (0.65), free when below ``free_thresh`` (0.196),
unknown between (map_server's defaults and semantics).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from pydantic import Field, model_validator

from tagloc.config import FieldPathError, StrictModel
from tagloc.errors import GeometryError
from tagloc.geometry import SE3
from tagloc.lidar.cloud import finite_points, voxel_downsample

__all__ = ["OccupancyConfig", "OccupancyGrid", "build_occupancy", "build_premap"]

#: Rays cast at once (bounds the memory of the traversed cells: 2048 rays of 30 m at 5 cm hold
#: 1.2 M cells).
_CHUNK = 2048
#: Most cells of a grid built (200 MB of float64 log odds while building; a 100 m x 100 m floor at
#: 2 cm is 25 M).
MAX_GRID_CELLS = 25_000_000


def _logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


class OccupancyConfig(StrictModel):
    """How :func:`build_occupancy` rasterises scans."""

    resolution_m: float = Field(0.05, ge=0.005, le=10.0)
    """Cell edge (m)."""
    z_min_m: float = Field(0.1, ge=-1e3, le=1e3)
    """Lowest point height (m, ``map`` z; the floor is z = 0) that counts as an obstacle."""
    z_max_m: float = Field(2.0, ge=-1e3, le=1e3)
    """Highest point height (m) that counts (above: ceilings, lamps)."""
    max_range_m: float = Field(30.0, gt=0.0, le=1e4)
    """Points farther (horizontally) than this from the sensor are dropped."""
    log_odds_hit: float = Field(_logit(0.6), gt=0.0, le=50.0)
    log_odds_miss: float = Field(_logit(0.4), lt=0.0, ge=-50.0)
    clamp_min: float = Field(_logit(0.12), lt=0.0, ge=-100.0)
    clamp_max: float = Field(_logit(0.97), gt=0.0, le=100.0)
    occupied_thresh: float = Field(0.65, gt=0.0, lt=1.0)
    free_thresh: float = Field(0.196, gt=0.0, lt=1.0)
    padding_m: float = Field(0.5, ge=0.0, le=1e3)
    """Margin (m) around the rays' extent."""

    @model_validator(mode="after")
    def _ordered(self) -> OccupancyConfig:
        if not self.z_min_m < self.z_max_m:
            raise FieldPathError(("z_min_m",), "must be below z_max_m")
        if not self.free_thresh < self.occupied_thresh:
            raise FieldPathError(("free_thresh",), "must be below occupied_thresh")
        return self


@dataclass(frozen=True, slots=True, eq=False)
class OccupancyGrid:
    """A 2D occupancy grid in log odds (see the module docstring for the layout).

    Attributes
    ----------
    log_odds : (H, W) float32
        ``log(p / (1 - p))``; 0 = unknown. Row 0 is the top of the map image.
    resolution_m : float
        Cell edge (m).
    origin_xyz_yaw : (x, y, z, yaw)
        ``map`` pose of the lower-left corner of the lower-left cell (m, m, m, rad).
    occupied_thresh, free_thresh : float
        map_server probability thresholds.
    """

    log_odds: np.ndarray
    resolution_m: float
    origin_xyz_yaw: tuple[float, float, float, float]
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196

    def probability(self) -> np.ndarray:
        """``(H, W)`` occupancy probability ``1 - 1 / (1 + exp(log_odds))``."""
        return 1.0 - 1.0 / (1.0 + np.exp(self.log_odds.astype(np.float64)))

    def occupied(self) -> np.ndarray:
        """``(H, W)`` bool: probability > ``occupied_thresh``."""
        return self.probability() > self.occupied_thresh

    def free(self) -> np.ndarray:
        """``(H, W)`` bool: probability < ``free_thresh``."""
        return self.probability() < self.free_thresh

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.log_odds.shape[0]), int(self.log_odds.shape[1]))

    def cell_of(self, xy_map: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(rows, cols)`` int arrays of the cells holding ``xy_map`` (``(N, 2)`` metres);
        may lie outside the grid."""
        col = np.floor((xy_map[:, 0] - self.origin_xyz_yaw[0]) / self.resolution_m)
        row_up = np.floor((xy_map[:, 1] - self.origin_xyz_yaw[1]) / self.resolution_m)
        return (self.shape[0] - 1 - row_up).astype(np.int64), col.astype(np.int64)

    def cell_centers(self) -> np.ndarray:
        """``(H, W, 2)`` the ``map`` xy (m) of every cell's centre."""
        rows, cols = np.indices(self.shape)
        x = self.origin_xyz_yaw[0] + (cols + 0.5) * self.resolution_m
        y = self.origin_xyz_yaw[1] + (self.shape[0] - 1 - rows + 0.5) * self.resolution_m
        return np.stack([x, y], axis=-1)


def build_occupancy(
    scans: Iterable[tuple[SE3, np.ndarray]], config: OccupancyConfig
) -> OccupancyGrid:
    """Ray-cast scans ``(T_map_lidar, points_lidar (N, 3))`` into a 2D log-odds grid.

    The grid covers every sensor position and kept point, plus ``padding_m``.

    Raises
    ------
    GeometryError
        A grid of more than :data:`MAX_GRID_CELLS` cells (before it is allocated).
    """
    rays = [_band_rays(T_map_lidar, points, config) for T_map_lidar, points in scans]
    res = config.resolution_m
    if rays:
        every = np.concatenate([np.vstack([o[None], e]) for o, e in rays])
        low, high = every.min(axis=0) - config.padding_m, every.max(axis=0) + config.padding_m
    else:
        low, high = np.zeros(2), np.zeros(2)
    low = np.floor(low / res) * res
    width, height = (np.ceil((high - low) / res).astype(np.int64) + 1).tolist()
    if width * height > MAX_GRID_CELLS:  # checked before the grid is allocated
        raise GeometryError(
            f"occupancy grid of {width} x {height} cells of {res:g} m: more than "
            f"{MAX_GRID_CELLS} cells; use a coarser resolution_m or a shorter max_range_m"
        )
    log_odds = np.zeros(height * width, dtype=np.float64)
    for origin, ends in rays:
        o = np.floor((origin - low) / res).astype(np.int64)
        e = np.floor((ends - low) / res).astype(np.int64)
        end_cells = np.unique(e[:, 1] * width + e[:, 0])
        chunks = [_line_cells(o, e[k : k + _CHUNK], width) for k in range(0, len(e), _CHUNK)]
        crossed = np.unique(np.concatenate(chunks)) if chunks else np.empty(0, np.int64)
        crossed = np.setdiff1d(crossed, end_cells, assume_unique=True)
        log_odds[crossed] += config.log_odds_miss
        log_odds[end_cells] += config.log_odds_hit
        np.clip(log_odds, config.clamp_min, config.clamp_max, out=log_odds)
    image = log_odds.reshape(height, width)[::-1].astype(np.float32)  # row 0 = top (max y)
    return OccupancyGrid(
        log_odds=image,
        resolution_m=res,
        origin_xyz_yaw=(float(low[0]), float(low[1]), 0.0, 0.0),
        occupied_thresh=config.occupied_thresh,
        free_thresh=config.free_thresh,
    )


def _band_rays(
    T_map_lidar: SE3, points_lidar: np.ndarray, config: OccupancyConfig
) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's map xy and the map xy of its points inside the height band and range."""
    points_map = T_map_lidar.act(finite_points(points_lidar))
    origin = np.asarray(T_map_lidar.translation[:2], dtype=np.float64)
    keep = (points_map[:, 2] >= config.z_min_m) & (points_map[:, 2] <= config.z_max_m)
    ends = points_map[keep, :2]
    ends = ends[np.linalg.norm(ends - origin, axis=1) <= config.max_range_m]
    return origin, ends


def _line_cells(start: np.ndarray, ends: np.ndarray, width: int) -> np.ndarray:
    """Flat indices (unique) of the cells on the DDA lines from cell ``start`` to each end cell,
    the start included, the end excluded: ``n = max(|dx|, |dy|)`` steps, cell
    ``start + round(k d / n)`` for ``k = 0 .. n-1`` (a symmetric Bresenham line)."""
    delta = ends - start
    steps = np.abs(delta).max(axis=1)
    ray = np.repeat(np.arange(len(ends)), steps)
    if ray.size == 0:
        return np.empty(0, dtype=np.int64)
    first = np.cumsum(steps) - steps
    k = np.arange(ray.size) - first[ray]
    frac = k / steps[ray]
    cells = start + np.rint(frac[:, None] * delta[ray]).astype(np.int64)
    return np.unique(cells[:, 1] * width + cells[:, 0])


def build_premap(scans: Iterable[tuple[SE3, np.ndarray]], voxel_m: float) -> np.ndarray:
    """The point-cloud premap: every scan ``(T_map_lidar, points_lidar)`` moved into ``map``,
    merged and voxel-downsampled to ``voxel_m`` (m). Returns ``(N, 3)`` float64 in ``map``."""
    moved = [T.act(finite_points(points)) for T, points in scans]
    if not moved:
        return np.empty((0, 3))
    return voxel_downsample(np.concatenate(moved), voxel_m)
