"""Covariance transport against seeded Monte Carlo sampling (an independent check).

Noise is small (first-order transport is then exact to ~1e-3 relative); 40,000 samples give
~1% sampling error on each variance, so the tolerance is 5% of the largest entry.
"""

from __future__ import annotations

import numpy as np
import pytest
from geometry_helpers import SEED

from tagloc.geometry import (
    SE2,
    SE3,
    cov_between,
    cov_compose,
    cov_inverse,
    cov_left_to_right,
    cov_right_to_left,
)
from tagloc.geometry._lie import LieGroup

SAMPLES = 40_000


def _random_cov(rng: np.random.Generator, dof: int, scale: float = 1e-3) -> np.ndarray:
    A = rng.normal(size=(dof, dof))
    return scale * (A @ A.T / dof + 0.1 * np.eye(dof))


def _sample(T: LieGroup, cov: np.ndarray, rng: np.random.Generator) -> LieGroup:
    """Batch of ``T @ Exp(d)``, ``d ~ N(0, cov)`` (the right-perturbation meaning of ``cov``)."""
    d = rng.multivariate_normal(np.zeros(T.DOF), cov, size=SAMPLES)
    return T.plus(d)


def _assert_cov_close(empirical: np.ndarray, predicted: np.ndarray) -> None:
    np.testing.assert_allclose(empirical, predicted, rtol=0, atol=0.05 * np.abs(predicted).max())


def _elements(rng: np.random.Generator) -> list[LieGroup]:
    return [SE3.random(rng, translation_scale=3.0), SE2.random(rng, scale=3.0)]


@pytest.mark.parametrize("which", [0, 1], ids=["SE3", "SE2"])
def test_cov_inverse_and_compose_and_between_match_sampling(which: int) -> None:
    rng = np.random.default_rng(SEED + which)
    T1 = _elements(rng)[which]
    T2 = _elements(rng)[which]
    c1, c2 = _random_cov(rng, T1.DOF), _random_cov(rng, T1.DOF)
    S1, S2 = _sample(T1, c1, rng), _sample(T2, c2, rng)

    inv = S1.inverse().minus(T1.inverse())
    _assert_cov_close(np.cov(inv.T), cov_inverse(T1, c1))

    comp = (S1 @ S2).minus(T1 @ T2)
    _assert_cov_close(np.cov(comp.T), cov_compose(T1, c1, T2, c2))

    betw = S1.between(S2).minus(T1.between(T2))
    _assert_cov_close(np.cov(betw.T), cov_between(T1, c1, T2, c2))

    # The sampled answer differs from a wrong (untransported) one: the check can fail.
    assert np.abs(np.cov(comp.T) - (c1 + c2)).max() > 0.2 * np.abs(c1 + c2).max()


def test_cov_right_to_left_is_the_parent_frame_covariance() -> None:
    rng = np.random.default_rng(SEED + 7)
    T = SE3.random(rng, translation_scale=3.0)
    cov = _random_cov(rng, 6)
    samples = _sample(T, cov, rng)
    # Left (parent-frame) perturbation e with samples = Exp(e) @ T.
    left = (samples @ T.inverse()).log()
    predicted = cov_right_to_left(T, cov)
    _assert_cov_close(np.cov(left.T), predicted)
    np.testing.assert_allclose(cov_left_to_right(T, predicted), cov, atol=1e-15)
    # The position block is the position covariance in the parent frame when t = 0.
    R_only = SE3(rotation=T.rotation, translation=np.zeros(3))
    positions = _sample(R_only, cov, rng).translation
    _assert_cov_close(np.cov(positions.T), cov_right_to_left(R_only, cov)[:3, :3])


def test_batched_covariances() -> None:
    rng = np.random.default_rng(SEED + 9)
    Ts = SE3.random(rng, 5)
    cov = _random_cov(rng, 6)
    batch = cov_right_to_left(Ts, cov)
    assert batch.shape == (5, 6, 6)
    for i in range(5):
        np.testing.assert_allclose(batch[i], cov_right_to_left(Ts[i], cov), atol=1e-15)
        np.testing.assert_allclose(batch[i], batch[i].T, atol=0)
