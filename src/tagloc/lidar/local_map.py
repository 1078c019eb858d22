"""Local maps: several sweeps placed at their poses and merged into one registration target.

Registering one sparse sweep onto another is biased by the scanner's sampling: a 16-ring scanner
samples each wall on a few horizontal lines and the floor on concentric circles, and the
covariances (local planes) estimated from one sweep's neighbours follow those lines, not the
surfaces. Between two 16-ring sweeps 0.75 m apart in a corridor this overestimates the step by
about 0.2 % and pitches it by -2.7 mrad (``tests/lidar/test_local_map.py``); chained over a
survey, that bias is a scale error of the map. Production lidar odometry registers each sweep to
a *local map* of many past sweeps instead: KISS-ICP (Vizzo et al., RA-L 2023) keeps a voxel hash
map of the recent sweeps (a bounded number of points per voxel, voxels far from the robot
dropped), FAST-LIO2 an incremental kd-tree, small_gicp an incremental Gaussian voxel map
(``GaussianVoxelMap``). Seen from many positions, the map's surfaces are sampled densely and its
planes are the walls' own; the sweep's own sampling no longer meets itself.

:func:`local_map_target` builds such a map as a :class:`~tagloc.lidar.registration.Target`: the
sweeps are moved into the map's frame, concatenated and voxelized by small_gicp's preprocessing
(one centroid per ``voxel_m`` cube, covariances from ``num_neighbors`` neighbours, a KD-tree),
so that :func:`~tagloc.lidar.registration.register` and everything built on its result (the
point-to-plane Hessian, the degeneracy analysis, the lidar fix) works unchanged against it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from tagloc.errors import GeometryError
from tagloc.lidar.cloud import finite_points
from tagloc.lidar.registration import RegistrationConfig, Target

__all__ = ["local_map_target", "merge_scans"]


def merge_scans(M_map_scan: npt.ArrayLike, points_scan: Sequence[npt.ArrayLike]) -> np.ndarray:
    """The points of every scan in the map's frame, concatenated: ``(sum N_i, 3)``.

    ``M_map_scan`` is ``(S, 4, 4)``: scan ``i``'s pose in the map; ``points_scan[i]`` its
    ``(N_i, 3)`` points in its own frame (non-finite rows dropped).
    """
    M = np.asarray(M_map_scan, dtype=np.float64).reshape(-1, 4, 4)
    if len(M) != len(points_scan):
        raise GeometryError(f"{len(M)} poses for {len(points_scan)} scans")
    if len(M) == 0:
        return np.empty((0, 3))
    moved = []
    for T, points in zip(M, points_scan, strict=True):
        p = finite_points(points)
        moved.append(p @ T[:3, :3].T + T[:3, 3])
    return np.concatenate(moved)


def local_map_target(
    M_map_scan: npt.ArrayLike, points_scan: Sequence[npt.ArrayLike], config: RegistrationConfig
) -> Target:
    """The scans placed at ``M_map_scan`` (see :func:`merge_scans`) as one prepared target in
    the map's frame (module docstring)."""
    return Target.from_points(merge_scans(M_map_scan, points_scan), config)
