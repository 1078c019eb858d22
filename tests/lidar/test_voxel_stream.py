"""Voxel centroids accumulated scan by scan equal the centroids of all the points at once."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.errors import GeometryError
from tagloc.lidar import voxel_downsample
from tagloc.lidar.voxel_stream import VoxelCentroids


@pytest.mark.parametrize("centred", [False, True])
@pytest.mark.parametrize("chunk_points", [1, 700, 10**6])
def test_chunks_equal_all_at_once(centred: bool, chunk_points: int) -> None:
    rng = np.random.default_rng(3)
    scans = [rng.uniform(-4.0, 6.0, size=(int(rng.integers(0, 900)), 3)) for _ in range(12)]
    scans[4][::7] = np.nan  # non-finite rows are dropped, as voxel_downsample drops them
    voxels = VoxelCentroids(0.5, centred=centred, chunk_points=chunk_points)
    for scan in scans:
        voxels.add(scan)
    expected = voxel_downsample(np.concatenate(scans), 0.5, centred=centred)
    got = voxels.centroids()
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert voxels.n_voxels == expected.shape[0]


def test_brute_force_centroid_of_each_cube() -> None:
    points = np.array([[0.1, 0.1, 0.1], [0.3, 0.2, 0.4], [1.2, 0.1, 0.1], [-0.2, 0.0, 0.0]])
    voxels = VoxelCentroids(1.0, chunk_points=1)
    for p in points:
        voxels.add(p[None, :])
    np.testing.assert_allclose(
        voxels.centroids(), [[-0.2, 0.0, 0.0], [0.2, 0.15, 0.25], [1.2, 0.1, 0.1]], atol=1e-15
    )


def test_far_coordinates_take_the_general_path() -> None:
    points = np.array([[0.0, 0.0, 0.0], [1e7, 0.0, 0.0], [1e7 + 0.01, 0.0, 0.0]])
    voxels = VoxelCentroids(0.1)
    voxels.add(points[:2])
    voxels.add(points[2:])
    np.testing.assert_allclose(voxels.centroids(), voxel_downsample(points, 0.1), atol=1e-9)


def test_empty_and_bad_voxel() -> None:
    assert VoxelCentroids(0.1).centroids().shape == (0, 3)
    with pytest.raises(GeometryError, match="voxel_m"):
        VoxelCentroids(0.0)
