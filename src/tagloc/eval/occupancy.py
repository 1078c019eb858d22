"""An occupancy grid against a simulated world's walls: IoU of occupied cells.

The truth is the world's walls (``world.walls_in_map()``; glass and mirrors left out: a lidar
gets no return from them) rasterized into the grid's own cells, and only where the grid has
observed anything (a wall cell next to a known cell, free or occupied: a wall the survey never
saw is not the grid's error). A wall is a segment without thickness, hit from either side in the
same cell line.

Cells are 5 cm: a wall at the border of two cells, 2 cm of range noise and a centimetre of
pose error put its hits in either, so the score allows one cell: a built occupied cell is right
if a wall cell is within one cell (8-neighbourhood) of it (precision), and a wall cell is found
if a built occupied cell is within one cell of it (recall); ``iou = 1 / (1/p + 1/r - 1)`` (the
IoU when true positives counted either way agree). ``iou_strict`` is the plain cell IoU.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.ndimage import binary_dilation

from tagloc.lidar import OccupancyGrid
from tagloc.sim.world import World

BoolArray = npt.NDArray[np.bool_]
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True, slots=True)
class OccupancyScore:
    """Occupied cells of a grid against the true walls (module docstring)."""

    iou: float
    iou_strict: float
    precision: float
    recall: float
    occupied_cells: int
    wall_cells: int


def wall_cells(grid: OccupancyGrid, world: World) -> BoolArray:
    """``(H, W)`` cells (image rows, row 0 at the top) crossed by the world's opaque walls."""
    height, width = grid.shape
    res = grid.resolution_m
    x0, y0 = grid.origin_xyz_yaw[:2]
    mask = np.zeros((height, width), dtype=bool)
    for wall in world.walls_in_map():
        if wall.material != "wall":
            continue
        a, b = np.asarray(wall.start, dtype=np.float64), np.asarray(wall.end, dtype=np.float64)
        n = max(2, int(np.ceil(np.linalg.norm(b - a) / (0.25 * res))) + 1)
        xy = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        col = np.floor((xy[:, 0] - x0) / res).astype(np.int64)
        row = height - 1 - np.floor((xy[:, 1] - y0) / res).astype(np.int64)
        ok = (col >= 0) & (col < width) & (row >= 0) & (row < height)
        mask[row[ok], col[ok]] = True
    return mask


def occupancy_iou(grid: OccupancyGrid, world: World) -> OccupancyScore:
    """Score ``grid``'s occupied cells against ``world``'s walls (module docstring)."""
    built = np.asarray(grid.occupied(), dtype=bool)
    known = built | np.asarray(grid.free(), dtype=bool)
    truth = wall_cells(grid, world) & binary_dilation(known, _EIGHT)
    found = truth & binary_dilation(built, _EIGHT)
    right = built & binary_dilation(truth, _EIGHT)
    precision = float(right.sum() / max(built.sum(), 1))
    recall = float(found.sum() / max(truth.sum(), 1))
    iou = 1.0 / (1.0 / precision + 1.0 / recall - 1.0) if precision > 0 and recall > 0 else 0.0
    union = int((built | truth).sum())
    strict = float((built & truth).sum() / union) if union else 0.0
    return OccupancyScore(iou, strict, precision, recall, int(built.sum()), int(truth.sum()))
