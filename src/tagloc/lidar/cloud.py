"""Point-cloud basics: drop non-finite rows, de-skew a sweep, voxel downsampling (pure numpy).

Points are ``(N, 3)`` arrays in metres, in the frame their name says (``points_lidar``,
``points_base``, ``points_map``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from tagloc.errors import GeometryError
from tagloc.geometry import SE3

__all__ = ["deskew", "finite_points", "voxel_downsample"]


def _points(points: npt.ArrayLike, name: str = "points") -> np.ndarray:
    array = np.asarray(points, dtype=np.float64)
    if array.size == 0:
        return np.empty((0, 3))
    if array.ndim != 2 or array.shape[1] != 3:
        raise GeometryError(f"{name} must have shape (N, 3), got {array.shape}")
    return array


def finite_points(points: npt.ArrayLike) -> np.ndarray:
    """``(M, 3)`` float64 ``points`` (``(N, 3)``) without the rows holding NaN or inf.

    A lidar marks "no return" with NaN rows (ROS ``PointCloud2`` with ``is_dense: false``).
    A float64 input without such rows is returned as is (not copied).

    Raises
    ------
    GeometryError
        ``points`` is not ``(N, 3)`` (an empty array is accepted and gives ``(0, 3)``).
    """
    array = _points(points)
    if np.isfinite(array).all():  # one flat reduction; the per-row test costs 60 times more
        return array
    return np.array(array[np.isfinite(array).all(axis=1)])


def deskew(
    points_lidar: npt.ArrayLike,
    time_offset_s: npt.ArrayLike,
    T_lidar0_lidar_t: Callable[[np.ndarray], SE3],
) -> np.ndarray:
    """Move each point of a sweep into the lidar frame at the sweep start (time offset 0).

    A spinning lidar measures point ``i`` at ``stamp + time_offset_s[i]`` from the pose the
    scanner has at that time; while the robot moves, the raw sweep is smeared. With the motion
    during the sweep (from odometry) ``T_lidar0_lidar_t(offsets)`` (``(K,)`` seconds -> a batch
    of ``K`` poses of the scanner at each offset in the scanner frame at offset 0), each point is
    ``p_lidar0 = T_lidar0_lidar_t(t_i) p_i``. The motion is evaluated once per distinct offset.

    Parameters
    ----------
    points_lidar : (N, 3) float
        Raw points, each in the scanner frame at its own measurement time; NaN rows allowed.
    time_offset_s : (N,) float
        Seconds after the sweep start (>= 0).
    T_lidar0_lidar_t : callable
        ``(K,)`` offsets -> ``SE3`` batch of ``K``.

    Returns
    -------
    (M, 3) float64
        The finite points (rows with a non-finite point or offset dropped), in ``lidar0``.
    """
    points = _points(points_lidar, "points_lidar")
    offsets = np.asarray(time_offset_s, dtype=np.float64).reshape(-1)
    if offsets.shape[0] != points.shape[0]:
        raise GeometryError(
            f"time_offset_s has {offsets.shape[0]} values for {points.shape[0]} points"
        )
    keep = np.isfinite(points).all(axis=1) & np.isfinite(offsets)
    points, offsets = points[keep], offsets[keep]
    if points.shape[0] == 0:
        return np.empty((0, 3))
    unique, index = np.unique(offsets, return_inverse=True)
    motion = T_lidar0_lidar_t(unique)
    if len(unique) == 1 and not motion.is_batch:
        return motion.act(points)
    rotations = motion.rotation.matrix[index]
    moved: np.ndarray = np.einsum("nij,nj->ni", rotations, points) + motion.translation[index]
    return moved


def voxel_downsample(points: npt.ArrayLike, voxel_m: float, *, centred: bool = False) -> np.ndarray:
    """The centroid of the points in each occupied cube of edge ``voxel_m`` (metres).

    Cubes are aligned with the frame's axes: their faces at multiples of ``voxel_m``, or with
    ``centred`` their centres (so a wall on a round coordinate, x = 0 or y = 9.0, falls in the
    middle of one layer of cubes rather than on the boundary between two). Non-finite rows are
    dropped first. Output rows are ordered by voxel index (deterministic).

    Returns
    -------
    (M, 3) float64, M <= N
    """
    if not voxel_m > 0.0:
        raise GeometryError(f"voxel_m must be > 0, got {voxel_m}")
    finite = finite_points(points)
    if finite.shape[0] == 0:
        return finite
    keys = np.floor(finite / voxel_m + (0.5 if centred else 0.0)).astype(np.int64)
    keys -= keys.min(axis=0)
    if keys.max() < 2**21:  # one int64 per voxel (same order as the rows): a fast 1D unique
        flat = (keys[:, 0] << 42) | (keys[:, 1] << 21) | keys[:, 2]
        _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    else:
        _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    sums = [np.bincount(inverse, weights=finite[:, k], minlength=counts.shape[0]) for k in range(3)]
    return np.asarray(np.stack(sums, axis=1) / counts[:, None])
