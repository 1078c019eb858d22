"""The odometry factors' noise, level with gravity: an upright body gets the plain diagonal
model bit for bit, any other body the same noise about the true vertical, and GTSAM's own
whitening of the factor's noise model agrees with the numpy one."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tagloc.geometry import SE3
from tagloc.mapping.config import OdometryNoise
from tagloc.mapping.gtsam_bridge import PERM
from tagloc.mapping.odometry_noise import odometry_whitening, rotations_to_z

NOISE = OdometryNoise()
#: An optical body (x right, y down, z forward) in an upright base.
R_BASE_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _drive(n: int = 30) -> np.ndarray:
    rng = np.random.default_rng(7)
    yaw = np.cumsum(rng.normal(0.0, 0.2, n))
    xy = np.cumsum(rng.normal(0.0, 0.3, (n, 2)), axis=0)
    rotvec = np.column_stack([np.zeros(n), np.zeros(n), yaw])
    return np.asarray(SE3.from_rotvec(rotvec, np.column_stack([xy, np.zeros(n)])).as_matrix())


def test_an_upright_body_is_the_plain_diagonal_model() -> None:
    M = _drive()
    e = np.random.default_rng(1).normal(0, 0.01, (len(M) - 1, 6))
    plain = odometry_whitening(M, NOISE)
    upright = odometry_whitening(M, NOISE, np.tile([0.0, 0.0, 1.0], (len(M), 1)))
    assert upright.R_level_base is None
    np.testing.assert_array_equal(upright.whiten(e), e / plain.sigmas)


def test_a_sideways_body_gets_the_same_noise_about_the_true_vertical() -> None:
    M_base = _drive()
    T_base_cam = SE3.from_matrix(np.block([[R_BASE_CAM, np.zeros((3, 1))], [np.zeros((1, 3)), 1]]))
    M_cam = M_base @ T_base_cam.as_matrix()
    up_cam = np.einsum("ji,j->i", R_BASE_CAM, [0.0, 0.0, 1.0])
    e_base = np.random.default_rng(2).normal(0, 0.01, (len(M_base) - 1, 6))
    # the same physical step error expressed in the camera body (a constant rotation)
    e_cam = np.concatenate([e_base[:, :3] @ R_BASE_CAM, e_base[:, 3:] @ R_BASE_CAM], axis=1)
    upright = odometry_whitening(M_base, NOISE).whiten(e_base)
    sideways = odometry_whitening(M_cam, NOISE, np.tile(up_cam, (len(M_cam), 1))).whiten(e_cam)
    np.testing.assert_allclose(
        np.linalg.norm(sideways, axis=1), np.linalg.norm(upright, axis=1), rtol=1e-12
    )
    # taking the camera's z for "up" (the old model) holds the true yaw tight instead
    wrong = odometry_whitening(M_cam, NOISE).whiten(e_cam)
    assert not np.allclose(np.linalg.norm(wrong, axis=1), np.linalg.norm(upright, axis=1))


def test_covariance_is_split_along_up() -> None:
    u = Rotation.random(random_state=3).apply([0.0, 0.0, 1.0])
    M = _drive(2)
    noise = odometry_whitening(M, NOISE, np.tile(u, (2, 1)))
    S = np.zeros((6, 6))
    S[:3, :3] = S[3:, 3:] = noise.R_level_base[0]  # type: ignore[index]
    S /= noise.sigmas[0][:, None]
    cov = np.linalg.inv(S.T @ S)
    s = noise.sigmas[0]
    var_t, var_r, v2 = s[0] ** 2, s[5] ** 2, (s[2] / s[0]) ** 2
    uu = np.outer(u, u)
    np.testing.assert_allclose(cov[:3, :3], var_t * (np.eye(3) - (1 - v2) * uu), atol=1e-15)
    np.testing.assert_allclose(cov[3:, 3:], var_r * (v2 * np.eye(3) + (1 - v2) * uu), atol=1e-15)
    np.testing.assert_allclose(cov[:3, 3:], 0.0, atol=1e-18)


def test_gtsam_whitens_like_numpy() -> None:
    M = _drive()
    ups = Rotation.random(len(M), random_state=4).apply([0.0, 0.0, 1.0])
    noise = odometry_whitening(M, NOISE, ups)
    e = np.random.default_rng(5).normal(0, 0.01, (len(M) - 1, 6))
    ours = noise.whiten(e)
    for k in range(len(e)):
        theirs = noise.gtsam_model(k).whiten(np.ascontiguousarray(e[k][PERM]))
        assert np.linalg.norm(theirs) == pytest.approx(np.linalg.norm(ours[k]), rel=1e-12)


def test_whitened_jacobian_is_the_jacobian_of_the_whitened_error() -> None:
    M = _drive(5)
    ups = Rotation.random(5, random_state=6).apply([0.0, 0.0, 1.0])
    noise = odometry_whitening(M, NOISE, ups)
    A = np.random.default_rng(8).normal(size=(4, 6, 3))
    x = np.random.default_rng(9).normal(size=3)
    np.testing.assert_allclose(
        noise.whiten_jacobian(A) @ x, noise.whiten(np.einsum("kij,j->ki", A, x)), rtol=1e-12
    )


def test_rotations_to_z() -> None:
    u = np.vstack([Rotation.random(20, random_state=10).apply([0, 0, 1]), [[0, 0, 1], [0, 0, -1]]])
    R = rotations_to_z(u)
    np.testing.assert_allclose(
        np.einsum("kij,kj->ki", R, u), np.tile([0, 0, 1.0], (22, 1)), atol=1e-12
    )
    np.testing.assert_array_equal(R[-2], np.eye(3))
