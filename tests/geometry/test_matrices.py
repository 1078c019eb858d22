"""The helpers on raw (N, 4, 4) stacks against GTSAM (adjoint, log, inverse) and numpy's cross."""

from __future__ import annotations

import gtsam
import numpy as np
from geometry_helpers import SEED, from_gtsam_matrix6, to_gtsam

from tagloc.geometry import SE3, adjoint_h, hat, inverse_h, log_h, vee

N = 20


def _poses() -> SE3:
    return SE3.random(np.random.default_rng(SEED), N, translation_scale=3.0)


def test_hat_is_the_cross_product_and_vee_inverts_it() -> None:
    rng = np.random.default_rng(SEED)
    a, b = rng.normal(size=(N, 3)), rng.normal(size=(N, 3))
    np.testing.assert_allclose(hat(a) @ b[..., None], np.cross(a, b)[..., None], atol=1e-14)
    np.testing.assert_array_equal(vee(hat(a)), a)


def test_inverse_h_matches_gtsam() -> None:
    T = _poses()
    M = np.asarray(T.as_matrix())
    expected = np.stack([to_gtsam(T[i]).inverse().matrix() for i in range(N)])
    np.testing.assert_allclose(inverse_h(M), expected, atol=1e-12)


def test_adjoint_h_matches_gtsam_and_the_method() -> None:
    T = _poses()
    A = adjoint_h(np.asarray(T.as_matrix()))
    for i in range(N):
        np.testing.assert_allclose(
            A[i], from_gtsam_matrix6(to_gtsam(T[i]).AdjointMap()), rtol=0, atol=1e-12
        )
    np.testing.assert_array_equal(A, T.adjoint())


def test_log_h_matches_gtsam_and_accepts_rounding_off_so3() -> None:
    T = _poses()
    M = np.asarray(T.as_matrix()).copy()
    expected = np.stack([gtsam.Pose3.Logmap(to_gtsam(T[i])) for i in range(N)])
    np.testing.assert_allclose(log_h(M), np.c_[expected[:, 3:], expected[:, :3]], atol=1e-10)
    M[:, :3, :3] *= 1.0 + 1e-7  # off SO(3) by more than from_matrix accepts: projected first
    np.testing.assert_allclose(log_h(M), np.c_[expected[:, 3:], expected[:, :3]], atol=1e-6)
    assert log_h(np.zeros((0, 4, 4))).shape == (0, 6)
