"""Degeneracy of registration Hessians: a corridor frees exactly its axis; synthetic cases."""

from __future__ import annotations

import numpy as np
import pytest
from lidar_scenes import box_room, corridor, scan, surface

from tagloc.errors import GeometryError
from tagloc.geometry import SE3
from tagloc.lidar import DegeneracyConfig, RegistrationConfig, Target, analyse_hessian, register

SEED = 11


@pytest.fixture(scope="module")
def corridor_target() -> Target:
    premap = surface(corridor(60.0), np.random.default_rng(SEED), sigma_m=0.003)
    return Target.from_points(premap, RegistrationConfig())


@pytest.mark.parametrize("yaw", [0.0, 0.4, -2.0])
def test_corridor_frees_exactly_the_along_axis_translation(
    corridor_target: Target, yaw: float
) -> None:
    rng = np.random.default_rng([SEED, int(100 + 10 * yaw)])
    T_map_base = SE3.from_rotvec([0.0, 0.0, yaw], [3.0, 1.1, 0.5])
    points = scan(corridor(), T_map_base, rng)
    init = T_map_base.compose(SE3.exp([0.2, 0.05, 0.0, 0.0, 0.0, 0.01]))
    reg = register(points, corridor_target, init, RegistrationConfig())
    degeneracy = analyse_hessian(reg.plane_hessian, DegeneracyConfig())
    assert degeneracy.constrained.tolist() == [False, True, True, True, True, True]
    axis_base = reg.T_target_source.rotation.inverse().act(np.array([1.0, 0.0, 0.0]))
    assert abs(degeneracy.eigenvectors[:3, 0] @ axis_base) > 0.999
    basis = degeneracy.basis()
    assert basis.shape == (6, 5)
    np.testing.assert_allclose(basis.T @ basis, np.eye(5), atol=1e-12)
    assert np.abs(basis[:3].T @ axis_base).max() < 0.05


def test_room_constrains_everything() -> None:
    rng = np.random.default_rng(SEED)
    target = Target.from_points(surface(box_room(), rng, sigma_m=0.003), RegistrationConfig())
    T_map_base = SE3.from_rotvec([0.0, 0.0, 0.3], [3.0, 2.0, 0.5])
    reg = register(scan(box_room(), T_map_base, rng), target, T_map_base, RegistrationConfig())
    assert analyse_hessian(reg.plane_hessian, DegeneracyConfig()).constrained.all()


def _information(gradients: np.ndarray) -> np.ndarray:
    return gradients.T @ gradients


def test_a_floor_constrains_z_roll_and_pitch() -> None:
    rng = np.random.default_rng(SEED)
    points = np.column_stack([rng.uniform(-5, 5, (2000, 2)), np.zeros(2000)])
    normal = np.array([0.0, 0.0, 1.0])
    gradients = np.hstack([np.tile(normal, (2000, 1)), np.cross(points, normal)])
    degeneracy = analyse_hessian(_information(gradients), DegeneracyConfig())
    assert degeneracy.num_constrained == 3
    np.testing.assert_allclose(degeneracy.basis()[[0, 1, 5]], 0.0, atol=1e-9)  # x, y, yaw free


def test_a_null_direction_mixing_rotation_and_translation_shows_in_both_blocks() -> None:
    """A screw-like null vector: both blocks' Schur complements lose a direction."""
    rng = np.random.default_rng(SEED)
    null = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.5])
    null /= np.linalg.norm(null)
    basis = np.linalg.qr(np.column_stack([null, rng.normal(size=(6, 5))]))[0][:, 1:]
    H = basis @ np.diag([1.0, 2.0, 3.0, 4.0, 5.0]) @ basis.T
    degeneracy = analyse_hessian(H, DegeneracyConfig())
    assert degeneracy.num_constrained == 4
    assert np.abs(degeneracy.basis().T @ null).max() < 1e-6


def test_nothing_is_constrained_by_a_zero_hessian_and_bad_input_is_refused() -> None:
    assert analyse_hessian(np.zeros((6, 6)), DegeneracyConfig()).num_constrained == 0
    with pytest.raises(GeometryError, match=r"\(6, 6\)"):
        analyse_hessian(np.eye(5), DegeneracyConfig())
    with pytest.raises(GeometryError, match="finite"):
        analyse_hessian(np.full((6, 6), np.nan), DegeneracyConfig())
