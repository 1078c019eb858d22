"""The survey's lidar products, in the same ``map`` frame as its tags: premap and occupancy grid.

After :func:`tagloc.mapping.build_tag_map` has optimized the keyframes (tags, odometry and scan
matching together), each lidar keyframe's sweep is placed at its *optimized* pose
(``T_map_lidar = T_map_base @ T_base_lidar``, the keyframe sits exactly at the sweep's stamp:
:mod:`tagloc.mapping.lidar_keyframes`), de-skewed as for the registration, and merged into

- the point-cloud premap (:func:`tagloc.lidar.build_premap`, voxel-downsampled; what the
  localizer's lidar fixes register against), and
- a 2D occupancy grid (:func:`tagloc.lidar.build_occupancy`: log-odds ray casting of the points
  in a height band; what planners and map_server load).

So the tags, the premap and the grid agree with each other to the survey's own accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from tagloc._types import FloatArray
from tagloc.config import StrictModel
from tagloc.geometry import SE3
from tagloc.lidar import OccupancyConfig, OccupancyGrid, build_occupancy, build_premap
from tagloc.mapping.lidar_config import LidarSurveyConfig
from tagloc.mapping.lidar_sweeps import deskewed_points, scan_velocity, steady_keyframes
from tagloc.mapping.report import BuildReport
from tagloc.mapping.survey import MappingError, Survey


class ProductsConfig(StrictModel):
    """How the premap and the occupancy grid are made.

    Attributes
    ----------
    premap_voxel_m : float
        Voxel edge of the premap (one centroid per voxel), m.
    max_range_m : float
        Points farther from the scanner are left out of the premap (the grid has its own).
    occupancy : OccupancyConfig
        Resolution, height band, log-odds of the grid (:class:`tagloc.lidar.OccupancyConfig`).
    """

    premap_voxel_m: float = Field(0.1, ge=0.01, le=10.0)
    max_range_m: float = Field(20.0, gt=0.0, le=1e4)
    occupancy: OccupancyConfig = OccupancyConfig()


@dataclass(frozen=True, slots=True, eq=False)
class SurveyProducts:
    """The premap ``(N, 3)`` (float64, m, in ``map``), the occupancy grid, and how many sweeps
    made them."""

    premap_map: FloatArray
    grid: OccupancyGrid
    scans: int


def placed_scans(
    survey: Survey, report: BuildReport, lidar_config: LidarSurveyConfig | None = None
) -> list[tuple[SE3, FloatArray]]:
    """``(T_map_lidar, points_lidar)`` of every sweep that is a keyframe of the built graph, at
    its optimized pose (points de-skewed, scanner frame).

    Raises
    ------
    MappingError
        The survey has no sweeps, or the build used none (built without lidar).
    """
    scans = survey.lidar
    if scans is None or len(scans) == 0:
        raise MappingError(f"{survey.source}: no lidar sweeps: no premap or occupancy grid")
    window = (lidar_config or LidarSurveyConfig()).deskew_window_s
    stamps = report.keyframe_stamps_ns
    index = np.clip(np.searchsorted(stamps, scans.stamps_ns), 0, len(stamps) - 1)
    on_keyframe = np.flatnonzero(stamps[index] == scans.stamps_ns)
    if report.scan_matching.get("keyframes", 0) == 0 or len(on_keyframe) == 0:
        raise MappingError(
            f"{survey.source}: the map was built without lidar: no premap or occupancy grid"
        )
    T_map_lidar = report.T_map_base_optimized[index[on_keyframe]] @ scans.T_base_lidar
    # de-skewed where the robot goes straight with the velocity of the optimized poses (as the
    # scan matching's second pass: tagloc.mapping.lidar_survey.sequential_factors)
    M_map_lidar = T_map_lidar.as_matrix()
    velocity = scan_velocity(M_map_lidar, scans.stamps_ns[on_keyframe] / 1e9)
    steady = steady_keyframes(M_map_lidar)
    chosen = [velocity[i] if steady[i] else None for i in range(len(on_keyframe))]
    return [
        (T_map_lidar[i], deskewed_points(survey, int(s), window, chosen[i]))
        for i, s in enumerate(on_keyframe)
    ]


def build_products(
    survey: Survey,
    report: BuildReport,
    config: ProductsConfig | None = None,
    lidar_config: LidarSurveyConfig | None = None,
) -> SurveyProducts:
    """The premap and the occupancy grid of a built survey (module docstring).

    Raises
    ------
    MappingError
        See :func:`placed_scans`.
    """
    config = config or ProductsConfig()
    scans = placed_scans(survey, report, lidar_config)
    near = [(T, p[np.linalg.norm(p, axis=1) <= config.max_range_m]) for T, p in scans]
    premap = build_premap(near, config.premap_voxel_m)
    grid = build_occupancy([(T, _one_per_cell(T, p, config.occupancy)) for T, p in scans],
                           config.occupancy)  # fmt: skip
    return SurveyProducts(premap, grid, len(scans))


def _one_per_cell(
    T_map_lidar: SE3, points_lidar: FloatArray, config: OccupancyConfig
) -> FloatArray:
    """The scan's points in the grid's height band and range, one per grid cell: the grid
    counts a cell hit once per scan and a ray to it once, so the others only cost ray casting
    (a sweep's 5 000 points hit a few hundred cells; 20 times faster on the office)."""
    points_map = T_map_lidar.act(points_lidar)
    origin = np.asarray(T_map_lidar.translation)
    keep = (points_map[:, 2] >= config.z_min_m) & (points_map[:, 2] <= config.z_max_m)
    keep &= np.linalg.norm(points_map[:, :2] - origin[:2], axis=1) <= config.max_range_m
    cells = np.floor(points_map[keep, :2] / config.resolution_m).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    return np.asarray(points_lidar[np.flatnonzero(keep)[np.sort(first)]])
