"""Interpolation: endpoints, midpoints against GTSAM, and the geodesic property."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from geometry_helpers import SEED, to_gtsam

from tagloc.errors import GeometryError
from tagloc.geometry import SE2, SE3, SO3


def _pairs() -> list[tuple[SE3, SE3]]:
    rng = np.random.default_rng(SEED)
    pairs = [
        (SE3.random(rng, translation_scale=3.0), SE3.random(rng, translation_scale=3.0))
        for _ in range(4)
    ]
    # The relative rotation close to pi (the geodesic is still unique just below pi).
    A = SE3.random(rng)
    B = A @ SE3.from_rotvec([0.0, np.pi - 1e-6, 0.0], [1.0, -2.0, 0.5])
    pairs.append((A, B))
    return pairs


@pytest.mark.parametrize(("A", "B"), _pairs())
def test_se3_interpolation_matches_gtsam_and_is_geodesic(A: SE3, B: SE3) -> None:
    np.testing.assert_allclose(A.interpolate(B, 0.0).as_matrix(), A.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(A.interpolate(B, 1.0).as_matrix(), B.as_matrix(), atol=1e-9)
    gA, gB = to_gtsam(A), to_gtsam(B)
    for alpha in (0.25, 0.5, 0.8):
        mid = A.interpolate(B, alpha)
        np.testing.assert_allclose(mid.as_matrix(), gA.slerp(alpha, gB).matrix(), atol=1e-9)
        # Geodesic: constant body twist, so the two pieces are alpha and (1 - alpha) of the whole.
        whole = B.minus(A)
        np.testing.assert_allclose(mid.minus(A), alpha * whole, atol=1e-8)
        np.testing.assert_allclose(B.minus(mid), (1.0 - alpha) * whole, atol=1e-8)
    # Rt interpolation: slerp on the rotation and linear on the translation (GTSAM interpolateRt).
    rt = A.interpolate_rt(B, 0.3)
    expected_rot = gA.rotation().slerp(0.3, gB.rotation()).matrix()
    np.testing.assert_allclose(rt.rotation.as_matrix(), expected_rot, atol=1e-9)
    np.testing.assert_allclose(rt.translation, 0.7 * A.translation + 0.3 * B.translation)


def test_so3_midpoint_is_slerp_and_equidistant() -> None:
    rng = np.random.default_rng(SEED + 1)
    for _ in range(5):
        R1, R2 = SO3.random(rng), SO3.random(rng)
        mid = R1.interpolate(R2, 0.5)
        expected = gtsam.Rot3(R1.as_matrix()).slerp(0.5, gtsam.Rot3(R2.as_matrix()))
        np.testing.assert_allclose(mid.as_matrix(), expected.matrix(), atol=1e-12)
        d1 = np.linalg.norm(mid.minus(R1))
        d2 = np.linalg.norm(R2.minus(mid))
        assert abs(d1 - d2) < 1e-12
        assert abs(d1 + d2 - np.linalg.norm(R2.minus(R1))) < 1e-12


def test_se2_interpolation_turns_the_short_way() -> None:
    A, B = SE2(0.0, 0.0, np.pi - 0.1), SE2(2.0, 0.0, -np.pi + 0.1)
    mid = A.interpolate(B, 0.5)
    assert abs(abs(mid.theta) - np.pi) < 1e-12  # through pi, not through 0
    np.testing.assert_allclose(mid.minus(A), 0.5 * B.minus(A), atol=1e-12)


def test_interpolate_rejects_2d_alpha() -> None:
    with pytest.raises(GeometryError, match="alpha"):
        SE3.identity().interpolate(SE3.identity(), np.zeros((2, 2)))
