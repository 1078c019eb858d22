"""The occupancy grid of a simulated box room against its rasterised walls; the premap."""

from __future__ import annotations

import numpy as np
import pytest
from lidar_scenes import box_room, scan

from tagloc.geometry import SE3
from tagloc.lidar import (
    OccupancyConfig,
    OccupancyGrid,
    build_occupancy,
    build_premap,
    voxel_downsample,
)

SEED = 3
LX, LY = 8.0, 6.0
#: The room's walls sit on cell centres (x = 0.025 + k 0.05), not on cell borders.
SHIFT = SE3.from_rotvec([0, 0, 0], [0.025, 0.025, 0.0])


@pytest.fixture(scope="module")
def scans() -> list[tuple[SE3, np.ndarray]]:
    rng = np.random.default_rng(SEED)
    out = []
    for x, y in [(2, 1.5), (6, 1.5), (2, 4.5), (6, 4.5), (4, 3), (1, 3), (7, 3), (4, 1), (4, 5)]:
        T_room_lidar = SE3.from_rotvec([0.0, 0.0, rng.uniform(-np.pi, np.pi)], [x, y, 0.5])
        out.append((SHIFT.compose(T_room_lidar), scan(box_room(LX, LY), T_room_lidar, rng)))
    return out


@pytest.fixture(scope="module")
def grid(scans: list[tuple[SE3, np.ndarray]]) -> OccupancyGrid:
    return build_occupancy(scans, OccupancyConfig())


def _true_walls(centers_xy: np.ndarray, res: float) -> np.ndarray:
    x = centers_xy[..., 0] - 0.025
    y = centers_xy[..., 1] - 0.025
    inside_x = (x > -res / 2) & (x < LX + res / 2)
    inside_y = (y > -res / 2) & (y < LY + res / 2)
    on_x = (np.abs(x) < res / 2) | (np.abs(x - LX) < res / 2)
    on_y = (np.abs(y) < res / 2) | (np.abs(y - LY) < res / 2)
    return (on_x & inside_y) | (on_y & inside_x)


def test_box_room_walls_and_free_inside(grid: OccupancyGrid) -> None:
    config = OccupancyConfig()
    centers = grid.cell_centers()
    walls = _true_walls(centers, config.resolution_m)
    occupied = grid.occupied()
    iou = (occupied & walls).sum() / (occupied | walls).sum()
    assert iou >= 0.9, iou
    x, y = centers[..., 0] - 0.025, centers[..., 1] - 0.025
    inside = (x > 0.1) & (x < LX - 0.1) & (y > 0.1) & (y < LY - 0.1)
    assert not occupied[inside].any()
    assert grid.free()[inside].mean() >= 0.95
    outside = (x < -0.1) | (x > LX + 0.1) | (y < -0.1) | (y > LY + 0.1)
    assert not grid.free()[outside].any() and not occupied[outside].any()


def test_grid_layout_follows_map_server(grid: OccupancyGrid) -> None:
    """Row 0 is the top (largest y); the origin is the lower-left corner of the lower-left cell."""
    height, width = grid.shape
    res = grid.resolution_m
    centers = grid.cell_centers()
    np.testing.assert_allclose(
        centers[height - 1, 0], np.array(grid.origin_xyz_yaw[:2]) + res / 2, atol=1e-12
    )
    assert centers[0, 0, 1] > centers[height - 1, 0, 1]
    rows, cols = grid.cell_of(centers.reshape(-1, 2))
    np.testing.assert_array_equal(rows.reshape(height, width), np.indices((height, width))[0])
    np.testing.assert_array_equal(cols.reshape(height, width), np.indices((height, width))[1])


def test_log_odds_are_clamped_and_band_filtered(scans: list[tuple[SE3, np.ndarray]]) -> None:
    config = OccupancyConfig()
    grid = build_occupancy(scans * 2, config)  # 18 scans: free and wall cells saturate
    assert grid.log_odds.dtype == np.float32
    assert np.isclose(grid.log_odds.max(), config.clamp_max, atol=1e-5)
    assert np.isclose(grid.log_odds.min(), config.clamp_min, atol=1e-5)
    above = build_occupancy(scans, OccupancyConfig(z_min_m=3.5, z_max_m=5.0))  # above the room
    assert not above.log_odds.any()


def test_premap_merges_scans_in_map(scans: list[tuple[SE3, np.ndarray]]) -> None:
    premap = build_premap(scans[:3], 0.2)
    merged = np.concatenate([T.act(p[np.isfinite(p).all(axis=1)]) for T, p in scans[:3]])
    np.testing.assert_allclose(premap, voxel_downsample(merged, 0.2), atol=1e-12)
    assert build_premap([], 0.2).shape == (0, 3)


def test_a_grid_beyond_the_cell_cap_is_refused_before_it_is_allocated() -> None:
    from tagloc.errors import GeometryError
    from tagloc.geometry import SE3
    from tagloc.lidar.occupancy import MAX_GRID_CELLS, OccupancyConfig, build_occupancy

    far = np.array([[900.0, 0.0, 1.0], [0.0, 900.0, 1.0]])  # 900 m at 5 mm: 3 * 10^10 cells
    config = OccupancyConfig(resolution_m=0.005, max_range_m=1000.0)
    with pytest.raises(GeometryError, match=f"more than {MAX_GRID_CELLS} cells"):
        build_occupancy([(SE3.identity(), far)], config)
