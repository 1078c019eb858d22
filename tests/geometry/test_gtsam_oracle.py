"""SO3/SE3/SE2 against GTSAM as the oracle (tangent orders permuted explicitly)."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from geometry_helpers import (
    SEED,
    from_gtsam_matrix6,
    from_gtsam_tangent,
    rotvec_with_angle,
    to_gtsam,
    to_gtsam_tangent,
)

from tagloc.geometry import SE2, SE3, SO3
from tagloc.geometry import jacobians as jac

_rng = np.random.default_rng(SEED)
_AXES = [_rng.standard_normal(3) for _ in range(4)] + [np.array([0.0, 0.0, 1.0])]
#: Angles covering identity, tiny, generic and the neighbourhood of pi.
ANGLES = [0.0, 1e-9, 1e-5, 0.3, 2.0, np.pi - 1e-3, np.pi - 1e-6]


def _tangents() -> list[np.ndarray]:
    rng = np.random.default_rng(SEED + 1)
    out = []
    for axis in _AXES:
        for angle in ANGLES:
            out.append(np.concatenate([rng.normal(0.0, 3.0, 3), rotvec_with_angle(axis, angle)]))
    return out


TANGENTS = _tangents()
IDS = [f"xi{i}-angle{ANGLES[i % len(ANGLES)]:.3g}" for i in range(len(TANGENTS))]


@pytest.mark.parametrize("xi", TANGENTS, ids=IDS)
def test_se3_exp_log_match_gtsam(xi: np.ndarray) -> None:
    T = SE3.exp(xi)
    expected = gtsam.Pose3.Expmap(to_gtsam_tangent(xi))
    np.testing.assert_allclose(T.as_matrix(), expected.matrix(), rtol=0, atol=1e-12)
    # Log: against the generating tangent (the angles are below pi, so Log(Exp(xi)) = xi) and GTSAM.
    np.testing.assert_allclose(T.log(), xi, rtol=0, atol=1e-8)
    np.testing.assert_allclose(
        T.log(), from_gtsam_tangent(gtsam.Pose3.Logmap(expected)), rtol=0, atol=1e-6
    )


@pytest.mark.parametrize("xi", TANGENTS, ids=IDS)
def test_se3_adjoint_and_right_jacobians_match_gtsam(xi: np.ndarray) -> None:
    T = SE3.exp(xi)
    pose = to_gtsam(T)
    np.testing.assert_allclose(
        T.adjoint(), from_gtsam_matrix6(pose.AdjointMap()), rtol=0, atol=1e-12
    )
    jr = from_gtsam_matrix6(gtsam.Pose3.ExpmapDerivative(to_gtsam_tangent(xi)))
    np.testing.assert_allclose(jac.se3_right_jacobian(xi), jr, rtol=0, atol=1e-9)
    # GTSAM's LogmapDerivative loses ~1e-7 near pi (its own closed form); the inverse of its
    # ExpmapDerivative is the tight oracle there, LogmapDerivative a loose one everywhere.
    np.testing.assert_allclose(jac.se3_right_jacobian_inv(xi), np.linalg.inv(jr), rtol=0, atol=1e-9)
    jr_inv = from_gtsam_matrix6(gtsam.Pose3.LogmapDerivative(to_gtsam_tangent(xi)))
    np.testing.assert_allclose(jac.se3_right_jacobian_inv(xi), jr_inv, rtol=0, atol=1e-6)


@pytest.mark.parametrize("xi", TANGENTS[::3], ids=IDS[::3])
def test_so3_exp_log_quat_and_jacobians_match_gtsam(xi: np.ndarray) -> None:
    phi = xi[3:]
    R = SO3.exp(phi)
    rot = gtsam.Rot3.Expmap(phi)
    np.testing.assert_allclose(R.as_matrix(), rot.matrix(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(R.log(), phi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(R.log(), gtsam.Rot3.Logmap(rot), rtol=0, atol=1e-6)
    q = rot.toQuaternion()
    q_xyzw = np.array([q.x(), q.y(), q.z(), q.w()]) * (1.0 if q.w() >= 0 else -1.0)
    np.testing.assert_allclose(R.as_quat(), q_xyzw, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        jac.so3_right_jacobian(phi), gtsam.Rot3.ExpmapDerivative(phi), rtol=0, atol=1e-10
    )
    jr_inv = np.linalg.inv(gtsam.Rot3.ExpmapDerivative(phi))
    np.testing.assert_allclose(jac.so3_right_jacobian_inv(phi), jr_inv, rtol=0, atol=1e-10)
    loose = gtsam.Rot3.LogmapDerivative(phi)  # ~5e-8 off near pi (see the SE3 test)
    np.testing.assert_allclose(jac.so3_right_jacobian_inv(phi), loose, rtol=0, atol=1e-6)


def test_log_near_pi_is_accurate() -> None:
    """A rotation by pi - 1e-6 (and exactly pi) keeps its axis and angle to ~1e-12."""
    axis = np.array([0.3, -0.5, 0.81])
    axis /= np.linalg.norm(axis)
    for angle in (np.pi - 1e-6, np.pi - 1e-9, np.pi):
        matrix = gtsam.Rot3.AxisAngle(axis, angle).matrix()  # built independently of tagloc
        phi = SO3.from_matrix(matrix).log()
        assert abs(np.linalg.norm(phi) - angle) < 1e-12
        cross = np.cross(phi / np.linalg.norm(phi), axis)
        assert np.linalg.norm(cross) < 1e-12


@pytest.mark.parametrize("seed", range(5))
def test_compose_inverse_act_between_match_gtsam(seed: int) -> None:
    rng = np.random.default_rng(SEED + 100 + seed)
    T1, T2 = SE3.random(rng, translation_scale=5.0), SE3.random(rng, translation_scale=5.0)
    g1, g2 = to_gtsam(T1), to_gtsam(T2)
    np.testing.assert_allclose((T1 @ T2).as_matrix(), g1.compose(g2).matrix(), atol=1e-12)
    np.testing.assert_allclose(T1.inverse().as_matrix(), g1.inverse().matrix(), atol=1e-12)
    np.testing.assert_allclose(T1.between(T2).as_matrix(), g1.between(g2).matrix(), atol=1e-12)
    points = rng.normal(0.0, 4.0, (7, 3))
    expected = np.array([g1.transformFrom(p) for p in points])
    np.testing.assert_allclose(T1.act(points), expected, atol=1e-12)
    np.testing.assert_allclose(T1.act(points[0]), expected[0], atol=1e-12)
    # minus is GTSAM's localCoordinates with the default (Expmap) chart.
    np.testing.assert_allclose(T2.minus(T1), from_gtsam_tangent(g1.localCoordinates(g2)), atol=1e-9)


@pytest.mark.parametrize("theta", [0.0, 1e-9, 1e-4, 0.7, -2.5, np.pi - 1e-6])
def test_se2_matches_gtsam_pose2(theta: float) -> None:
    tau = np.array([1.3, -0.4, theta])
    T = SE2.exp(tau)
    pose = gtsam.Pose2.Expmap(tau)
    np.testing.assert_allclose(T.as_matrix(), pose.matrix(), atol=1e-12)
    np.testing.assert_allclose(T.log(), gtsam.Pose2.Logmap(pose), atol=1e-9)
    np.testing.assert_allclose(T.log(), tau, atol=1e-9)
    np.testing.assert_allclose(T.adjoint(), pose.AdjointMap(), atol=1e-12)
    # GTSAM's Pose2 derivatives cancel near theta ~ 1e-4 (ExpmapDerivative ~1e-9 off, its
    # LogmapDerivative ~1e-4 off); the inverse of ExpmapDerivative is the oracle for Jr^-1.
    jr = gtsam.Pose2.ExpmapDerivative(tau)
    np.testing.assert_allclose(jac.se2_right_jacobian(tau), jr, rtol=0, atol=1e-8)
    jr_inv = np.linalg.inv(jr)
    np.testing.assert_allclose(jac.se2_right_jacobian_inv(tau), jr_inv, rtol=0, atol=1e-8)
    other = gtsam.Pose2(0.2, 3.0, -1.1)
    mine = SE2(0.2, 3.0, -1.1)
    np.testing.assert_allclose((T @ mine).as_matrix(), pose.compose(other).matrix(), atol=1e-12)
    np.testing.assert_allclose(T.inverse().as_matrix(), pose.inverse().matrix(), atol=1e-12)
    np.testing.assert_allclose(
        T.act(np.array([0.5, -2.0])), pose.transformFrom(np.array([0.5, -2.0])), atol=1e-12
    )
