"""Point-cloud algorithms: de-skew, downsampling, small_gicp registration against a prepared
target, degeneracy analysis, the degeneracy-aware lidar fix, the 2D occupancy grid and the
premap. Pure: no file I/O (PLY/PCD and map_server files are in :mod:`tagloc.io`).

- :mod:`tagloc.lidar.cloud`: :func:`finite_points`, :func:`deskew`, :func:`voxel_downsample`.
- :mod:`tagloc.lidar.registration`: :class:`RegistrationConfig`, :class:`Target`,
  :class:`Registration`, :func:`register`.
- :mod:`tagloc.lidar.local_map`: :func:`merge_scans`, :func:`local_map_target` (scan-to-map).
- :mod:`tagloc.lidar.degeneracy`: :class:`DegeneracyConfig`, :class:`Degeneracy`,
  :func:`analyse_hessian`.
- :mod:`tagloc.lidar.fix`: :class:`LidarFixConfig`, :class:`LidarFix`, :func:`lidar_fix`.
- :mod:`tagloc.lidar.occupancy`: :class:`OccupancyConfig`, :class:`OccupancyGrid`,
  :func:`build_occupancy`, :func:`build_premap`.
"""

from tagloc.lidar.cloud import deskew, finite_points, voxel_downsample
from tagloc.lidar.degeneracy import Degeneracy, DegeneracyConfig, analyse_hessian
from tagloc.lidar.fix import LidarFix, LidarFixConfig, lidar_fix
from tagloc.lidar.local_map import local_map_target, merge_scans
from tagloc.lidar.occupancy import OccupancyConfig, OccupancyGrid, build_occupancy, build_premap
from tagloc.lidar.registration import Registration, RegistrationConfig, Target, register

__all__ = [
    "Degeneracy",
    "DegeneracyConfig",
    "LidarFix",
    "LidarFixConfig",
    "OccupancyConfig",
    "OccupancyGrid",
    "Registration",
    "RegistrationConfig",
    "Target",
    "analyse_hessian",
    "build_occupancy",
    "build_premap",
    "deskew",
    "finite_points",
    "lidar_fix",
    "local_map_target",
    "merge_scans",
    "register",
    "voxel_downsample",
]
