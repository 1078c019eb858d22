"""finite_points, deskew and voxel_downsample against brute-force oracles."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.errors import GeometryError
from tagloc.geometry import SE3
from tagloc.lidar import deskew, finite_points, voxel_downsample

SEED = 20261202


def test_finite_points_drops_non_finite_rows() -> None:
    points = np.array([[1, 2, 3], [np.nan, 0, 0], [0, np.inf, 0], [4, 5, 6]], dtype=np.float32)
    out = finite_points(points)
    assert out.dtype == np.float64
    np.testing.assert_array_equal(out, [[1, 2, 3], [4, 5, 6]])
    assert finite_points(np.empty((0, 3))).shape == (0, 3)
    assert finite_points([]).shape == (0, 3)


def test_finite_points_refuses_bad_shape() -> None:
    with pytest.raises(GeometryError, match=r"shape \(N, 3\)"):
        finite_points(np.zeros((4, 2)))


def test_voxel_downsample_matches_a_per_voxel_loop() -> None:
    rng = np.random.default_rng(SEED)
    points = rng.uniform(-2, 2, (3000, 3))
    points[::97] = np.nan
    voxel = 0.37
    groups: dict[tuple[int, ...], list[np.ndarray]] = {}
    for p in points[np.isfinite(points).all(axis=1)]:
        groups.setdefault(tuple(np.floor(p / voxel).astype(int)), []).append(p)
    expected = np.array([np.mean(groups[k], axis=0) for k in sorted(groups)])
    np.testing.assert_allclose(voxel_downsample(points, voxel), expected, atol=1e-12)
    with pytest.raises(GeometryError, match="voxel_m"):
        voxel_downsample(points, 0.0)


def test_deskew_moves_each_point_with_its_own_pose() -> None:
    rng = np.random.default_rng(SEED)
    points = rng.uniform(-5, 5, (500, 3))
    offsets = rng.choice(np.linspace(0.0, 0.1, 37), 500)  # repeated offsets, as a real sweep
    points[7] = np.nan
    offsets[11] = np.nan
    twist = np.array([1.5, 0.2, 0.0, 0.0, 0.05, 0.8])  # m/s, rad/s in the scanner frame

    def motion(t: np.ndarray) -> SE3:
        return SE3.exp(t[:, None] * twist)

    out = deskew(points, offsets, motion)
    keep = np.ones(500, dtype=bool)
    keep[[7, 11]] = False
    expected = np.array(
        [SE3.exp(t * twist).act(p) for p, t in zip(points[keep], offsets[keep], strict=True)]
    )
    np.testing.assert_allclose(out, expected, atol=1e-12)
    with pytest.raises(GeometryError, match="time_offset_s"):
        deskew(points, offsets[:-1], motion)


def test_deskew_with_a_single_offset_and_no_point() -> None:
    T = SE3.from_rotvec([0, 0, 0.3], [1, 2, 3])
    points = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    np.testing.assert_allclose(deskew(points, [0.0, 0.0], lambda t: T), T.act(points))
    assert deskew(np.full((3, 3), np.nan), np.zeros(3), lambda t: T).shape == (0, 3)
