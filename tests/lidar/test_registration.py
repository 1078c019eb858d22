"""register() against small_gicp itself, and the Hessian convention by finite differences."""

from __future__ import annotations

import numpy as np
import pytest
import small_gicp
from lidar_scenes import box_room, scan, surface

from tagloc.geometry import SE3
from tagloc.lidar import RegistrationConfig, Target, register, voxel_downsample
from tagloc.lidar.registration import SMALL_GICP_TO_TAGLOC

SEED = 7


@pytest.fixture(scope="module")
def room() -> tuple[np.ndarray, Target]:
    premap = surface(box_room(), np.random.default_rng(SEED), sigma_m=0.003)
    return premap, Target.from_points(premap, RegistrationConfig())


@pytest.mark.parametrize("kernel", ["GICP", "PLANE_ICP"])
def test_room_recovers_a_perturbation(room: tuple[np.ndarray, Target], kernel: str) -> None:
    rng = np.random.default_rng(SEED)
    T_map_lidar = SE3.from_rotvec([0.01, -0.02, 0.7], [3.0, 2.5, 0.5])
    points = scan(box_room(), T_map_lidar, rng)
    init = T_map_lidar.compose(SE3.exp([0.25, -0.2, 0.1, 0.02, -0.02, 0.08]))
    reg = register(points, room[1], init, RegistrationConfig(kernel=kernel, max_iterations=60))
    error = T_map_lidar.inverse().compose(reg.T_target_source).log()
    assert reg.converged
    assert np.linalg.norm(error[:3]) < 0.01  # m
    assert np.rad2deg(np.linalg.norm(error[3:])) < 0.1
    assert reg.inlier_fraction > 0.95
    assert reg.rmse_m < 0.02 and reg.sigma_m <= reg.rmse_m


def test_register_agrees_with_small_gicp_align(room: tuple[np.ndarray, Target]) -> None:
    """The oracle: small_gicp called directly, on clouds it preprocessed itself (exactly the
    same result) and through its one-call ``align`` (its own preprocessing defaults)."""
    premap, target = room
    config = RegistrationConfig()
    rng = np.random.default_rng(SEED + 1)
    T_map_lidar = SE3.from_rotvec([0.0, 0.0, -1.2], [5.0, 3.5, 0.5])
    points = scan(box_room(), T_map_lidar, rng)
    points = points[np.isfinite(points).all(axis=1)]
    init = T_map_lidar.compose(SE3.exp([0.1, 0.15, 0.0, 0.0, 0.0, -0.05]))
    reg = register(points, target, init, config)
    options = dict(
        registration_type="GICP", max_correspondence_distance=config.max_correspondence_m,
        max_iterations=config.max_iterations, rotation_epsilon=config.rotation_epsilon_rad,
        translation_epsilon=config.translation_epsilon_m, num_threads=1,
    )  # fmt: skip
    target_cloud, target_tree = small_gicp.preprocess_points(premap, config.voxel_m)
    source_cloud, _ = small_gicp.preprocess_points(points, config.voxel_m)
    direct = small_gicp.align(
        target_cloud, source_cloud, target_tree, init_T_target_source=init.as_matrix(), **options
    )
    np.testing.assert_allclose(reg.T_target_source.as_matrix(), direct.T_target_source, atol=1e-12)
    assert (reg.num_inliers, reg.iterations) == (direct.num_inliers, direct.iterations + 1)
    assert reg.num_points == source_cloud.size()
    order = SMALL_GICP_TO_TAGLOC
    np.testing.assert_allclose(reg.hessian, direct.H[np.ix_(order, order)], rtol=1e-12)
    one_call = small_gicp.align(
        premap, points, init.as_matrix(), downsampling_resolution=config.voxel_m, **options
    )
    np.testing.assert_allclose(reg.T_target_source.as_matrix(), one_call.T_target_source, atol=1e-4)


def _gradient_at(target, tree, source, T: SE3) -> tuple[np.ndarray, np.ndarray]:
    """small_gicp's gradient ``b`` and Hessian ``H`` (its order) linearised at ``T``."""
    result = small_gicp.align(
        target, source, tree, init_T_target_source=T.as_matrix(), max_iterations=1,
        max_correspondence_distance=0.05,
    )  # fmt: skip
    return np.asarray(result.b), np.asarray(result.H)


def test_hessian_order_and_side_by_finite_differences() -> None:
    """Source = the target's points seen from a pose far from the origin, so the residuals
    vanish at ``T0`` and small_gicp's gradient ``b(T0 Exp(xi)) = H_sg d(delta)/d(xi) xi`` to
    first order. Differencing ``b`` along each of tagloc's tangent axes (``T0 Exp(h e_j)``,
    order ``[x, y, z, rx, ry, rz]``) and permuting its rows gives tagloc's Hessian. A wrong block
    order or a left perturbation (``Exp(h v) T0``: ``H`` changed by the adjoint of ``T0``, 5 m
    away) fails by orders of magnitude."""
    rng = np.random.default_rng(SEED)
    points_map = voxel_downsample(surface(box_room(), rng, per_m2=100), 0.1)
    T0 = SE3.from_rotvec([0.1, -0.2, 1.0], [4.0, -3.0, 2.0])
    target = small_gicp.PointCloud(points_map)
    source = small_gicp.PointCloud(T0.inverse().act(points_map))
    small_gicp.estimate_covariances(target, num_neighbors=10)
    small_gicp.estimate_covariances(source, num_neighbors=10)
    tree = small_gicp.KdTree(target)
    b0, H_small_gicp = _gradient_at(target, tree, source, T0)
    order = SMALL_GICP_TO_TAGLOC
    H = H_small_gicp[np.ix_(order, order)]
    assert np.abs(b0).max() < 1e-6 * np.abs(H).max()
    h = 1e-5
    columns = []
    for j in range(6):
        plus = _gradient_at(target, tree, source, T0.compose(SE3.exp(h * np.eye(6)[j])))[0]
        minus = _gradient_at(target, tree, source, T0.compose(SE3.exp(-h * np.eye(6)[j])))[0]
        columns.append((plus - minus) / (2 * h))
    fd = np.stack(columns, axis=1)[order]  # rows: small_gicp's order -> tagloc's
    scale = np.abs(H).max()
    np.testing.assert_allclose(fd, H, rtol=1e-4, atol=1e-6 * scale)
    Ad_inv = T0.inverse().adjoint()  # a left perturbation would give Ad^-T H Ad^-1
    assert np.abs(Ad_inv.T @ H @ Ad_inv - fd).max() > 0.1 * scale
    assert np.abs(H_small_gicp - fd).max() > 0.1 * scale  # unpermuted


def test_empty_source_gives_no_registration(room: tuple[np.ndarray, Target]) -> None:
    init = SE3.from_rotvec([0, 0, 0], [1, 1, 1])
    reg = register(np.full((10, 3), np.nan), room[1], init, RegistrationConfig())
    assert not reg.converged and reg.num_inliers == 0 and reg.inlier_fraction == 0.0
    assert np.all(reg.hessian == 0) and reg.T_target_source is init
