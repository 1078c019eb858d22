"""Voxel centroids of a cloud that arrives in pieces (scans), in memory bounded by the voxels.

:class:`VoxelCentroids` gives what :func:`~tagloc.lidar.cloud.voxel_downsample` gives on all the
points at once (the centroid of the points in each occupied cube, rows ordered by voxel index)
while holding only a per-voxel sum and count and at most ``chunk_points`` pending points: a
premap merged from a long drive's scans grows with the ground covered, not with the drive.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from tagloc.errors import GeometryError
from tagloc.lidar.cloud import finite_points

__all__ = ["VoxelCentroids"]

_BITS = 21
_OFFSET = 1 << (_BITS - 1)  # voxel indices in [-2**20, 2**20) pack into one int64


class VoxelCentroids:
    """Accumulates points into voxels of edge ``voxel_m`` (metres).

    Parameters
    ----------
    voxel_m : float
        Cube edge, > 0.
    centred : bool
        Cube centres (rather than faces) at multiples of ``voxel_m``, as in
        :func:`~tagloc.lidar.cloud.voxel_downsample`.
    chunk_points : int
        Points held before they are merged into the voxels' sums.

    Raises
    ------
    GeometryError
        If ``voxel_m`` is not > 0.
    """

    def __init__(self, voxel_m: float, *, centred: bool = False, chunk_points: int = 200_000):
        if not voxel_m > 0.0:
            raise GeometryError(f"voxel_m must be > 0, got {voxel_m}")
        self.voxel_m, self.centred, self.chunk_points = float(voxel_m), centred, chunk_points
        self._keys: np.ndarray = np.empty((0, 3), dtype=np.int64)
        self._sums: np.ndarray = np.empty((0, 3))
        self._counts: np.ndarray = np.empty(0)
        self._pending: list[np.ndarray] = []
        self._n_pending = 0

    @property
    def n_voxels(self) -> int:
        """Occupied voxels so far (pending points merged)."""
        self._merge()
        return int(self._keys.shape[0])

    def add(self, points: npt.ArrayLike) -> None:
        """Add ``(N, 3)`` points (non-finite rows are dropped)."""
        finite = finite_points(points)
        if finite.shape[0]:
            self._pending.append(finite)
            self._n_pending += finite.shape[0]
        if self._n_pending >= self.chunk_points:
            self._merge()

    def centroids(self) -> np.ndarray:
        """``(M, 3)`` float64: each occupied voxel's centroid, ordered by voxel index."""
        self._merge()
        return np.asarray(self._sums / self._counts[:, None])

    def _merge(self) -> None:
        if not self._pending:
            return
        points = np.concatenate(self._pending)
        self._pending, self._n_pending = [], 0
        keys = np.floor(points / self.voxel_m + (0.5 if self.centred else 0.0)).astype(np.int64)
        keys = np.concatenate([self._keys, keys])
        sums = np.concatenate([self._sums, points])
        counts = np.concatenate([self._counts, np.ones(points.shape[0])])
        if keys.min() >= -_OFFSET and keys.max() < _OFFSET:  # a fast 1D unique, same order
            packed = keys + _OFFSET
            flat = (packed[:, 0] << (2 * _BITS)) | (packed[:, 1] << _BITS) | packed[:, 2]
            _, first, inverse = np.unique(flat, return_index=True, return_inverse=True)
        else:
            _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        n = first.shape[0]
        self._keys = keys[first]
        self._sums = np.stack(
            [np.bincount(inverse, weights=sums[:, k], minlength=n) for k in range(3)], axis=1
        )
        self._counts = np.bincount(inverse, weights=counts, minlength=n)
