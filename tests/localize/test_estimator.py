"""The ``map -> odom`` estimator alone (``MapOdomEstimator``), without the fix policy.

Oracles: GTSAM's Gauss-Newton solution and marginal covariance of the same problem (the prior
``X0, P0`` as a prior factor, a fix ``z = X A`` with noise ``R`` as the prior factor on ``X``
at ``z A^-1`` with covariance ``Ad(A) R Ad(A)^T``, exact for right perturbations since
``z Exp(n) A^-1 = z A^-1 Exp(Ad(A) n)``): the converged iterated update is the MAP estimate
and its covariance the Laplace covariance there. And the estimator itself updated on time then
predicted, against the same fix applied late (exact for this linear model).
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from tagloc.frames import TransformBuffer
from tagloc.geometry import SE2, SE3
from tagloc.localize import FixQuality, LocalizeError, MapOdomEstimator, PartialFix, TagFix
from tagloc.localize.candidate import Candidate
from tagloc.localize.motion import ProcessNoise

S = 1_000_000_000
#: tagloc tangent [x, y, z, rx, ry, rz] -> GTSAM's [rx, ry, rz, x, y, z]
PERM = np.zeros((6, 6))
PERM[:3, 3:] = PERM[3:, :3] = np.eye(3)


def _estimator(buffer: TransformBuffer, planar: bool, *, iterations: int = 30,
               var_per_s: float = 0.0) -> MapOdomEstimator:  # fmt: skip
    d = 3 if planar else 6
    noise = ProcessNoise(np.zeros(d), np.zeros(d), np.full(d, var_per_s), S // 10)
    return MapOdomEstimator(
        buffer, map_frame="map", odom_frame="odom", base_frame="base_link", planar=planar,
        noise=noise, max_iterations=iterations, relinearize_tol=1e-13,
    )  # fmt: skip


def _cov(rng: np.random.Generator, sigmas: list[float]) -> np.ndarray:
    L = rng.normal(size=(len(sigmas), len(sigmas))) * np.asarray(sigmas)
    return L @ L.T + np.diag(np.square(sigmas)) * 0.1


def _gtsam_map(prior, P0, meas, C, pose3: bool):  # type: ignore[no-untyped-def]
    """MAP estimate and marginal covariance of two prior factors on one pose."""
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    if pose3:
        graph.add(gtsam.PriorFactorPose3(0, prior, gtsam.noiseModel.Gaussian.Covariance(P0)))
        graph.add(gtsam.PriorFactorPose3(0, meas, gtsam.noiseModel.Gaussian.Covariance(C)))
        values.insert(0, prior)
    else:
        graph.add(gtsam.PriorFactorPose2(0, prior, gtsam.noiseModel.Gaussian.Covariance(P0)))
        graph.add(gtsam.PriorFactorPose2(0, meas, gtsam.noiseModel.Gaussian.Covariance(C)))
        values.insert(0, prior)
    params = gtsam.GaussNewtonParams()
    params.setRelativeErrorTol(1e-16)
    params.setAbsoluteErrorTol(1e-16)
    params.setMaxIterations(100)
    result = gtsam.GaussNewtonOptimizer(graph, values, params).optimize()
    cov = gtsam.Marginals(graph, result).marginalCovariance(0)
    return (result.atPose3(0) if pose3 else result.atPose2(0)), cov


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_iterated_update_is_gtsams_map_estimate_on_se3(seed: int) -> None:
    rng = np.random.default_rng(seed)
    A = SE3.random(rng, translation_scale=3.0)
    buffer = TransformBuffer()
    buffer.set_static("odom", "base_link", A)
    est = _estimator(buffer, planar=False)
    X0 = SE3.random(rng, translation_scale=2.0)
    P0 = _cov(rng, [0.3, 0.3, 0.1, 0.05, 0.05, 0.2])
    est.initialize(0, X0, P0)
    R = _cov(rng, [0.05, 0.05, 0.08, 0.02, 0.02, 0.03])
    z = X0 @ SE3.exp(0.4 * rng.standard_normal(6)) @ A  # far enough to need iterations
    cand = Candidate.of_fix(TagFix(0, z, R, "tag:1", FixQuality(0.3)), A, planar=False)
    innov = est.innovation(cand)
    np.testing.assert_allclose(innov.nu, z.minus(X0 @ A), atol=1e-12)
    est.update(cand, innov)

    Ad = A.adjoint()
    X_map, cov = _gtsam_map(
        gtsam.Pose3(X0.as_matrix()), PERM @ P0 @ PERM.T,
        gtsam.Pose3((z @ A.inverse()).as_matrix()), PERM @ Ad @ R @ Ad.T @ PERM.T, pose3=True,
    )  # fmt: skip
    np.testing.assert_allclose(est.T_map_odom.as_matrix(), X_map.matrix(), atol=1e-9)
    np.testing.assert_allclose(est.covariance, PERM.T @ cov @ PERM, rtol=1e-6, atol=1e-12)
    assert est.revision == 2  # the prior, the update


@pytest.mark.parametrize("seed", [0, 1])
def test_the_iterated_update_is_gtsams_map_estimate_on_se2(seed: int) -> None:
    rng = np.random.default_rng(10 + seed)
    odom = SE3.exp([2.0, -1.0, 0.0, 0.0, 0.0, 0.7])
    buffer = TransformBuffer()
    buffer.set_static("odom", "base_link", odom)
    est = _estimator(buffer, planar=True)
    X0 = SE2(1.0, 2.0, 0.4)
    P0 = _cov(rng, [0.3, 0.3, 0.2])
    est.reset(0, odom, X0, P0)
    fix = TagFix(0, SE3.exp([3.5, 0.5, 0.1, 0.02, -0.01, 1.6]), _cov(rng, [0.05] * 6), "tag:1",
                 FixQuality(0.3))  # fmt: skip
    cand = Candidate.of_fix(fix, odom, planar=True)
    z, R = fix.to_planar()  # the planar projection is what the planar estimator sees
    est.update(cand)

    A = SE2.from_se3(odom)
    Ad, z_odom = A.adjoint(), z @ A.inverse()
    X_map, cov = _gtsam_map(
        gtsam.Pose2(X0.x, X0.y, X0.theta), P0,
        gtsam.Pose2(z_odom.x, z_odom.y, z_odom.theta),
        Ad @ R @ Ad.T, pose3=False,
    )  # fmt: skip
    got = SE2.from_se3(est.T_map_odom)
    np.testing.assert_allclose(
        [got.x, got.y, got.theta], [X_map.x(), X_map.y(), X_map.theta()], atol=1e-9
    )
    axes = [0, 1, 5]
    np.testing.assert_allclose(est.covariance[np.ix_(axes, axes)], cov, rtol=1e-6, atol=1e-12)
    assert np.all(np.delete(est.covariance, axes, axis=0) == 0.0)


def test_a_late_fix_equals_the_fix_on_time_then_the_prediction() -> None:
    """Standing still with a time-driven walk: the late update (gain from ``P - Q``, then ``Q``
    added back) must equal updating at the fix's stamp and predicting after."""
    rng = np.random.default_rng(5)
    A = SE3.random(rng, translation_scale=2.0)
    P0 = _cov(rng, [0.2, 0.2, 0.1, 0.03, 0.03, 0.1])
    z = SE3.random(rng, translation_scale=0.5) @ A
    fix = TagFix(S, z, _cov(rng, [0.05] * 3 + [0.02] * 3), "tag:1", FixQuality(0.3))
    results = []
    for late in (False, True):
        buffer = TransformBuffer()
        buffer.set_static("odom", "base_link", A)
        est = _estimator(buffer, planar=False, var_per_s=0.01)
        est.initialize(0, SE3.identity(), P0)
        est.predict(2 * S if late else S)
        cand = Candidate.of_fix(fix, A, planar=False)
        assert late == (cand.stamp_ns < est.stamp_ns)
        est.update(cand)
        if not late:
            est.predict(2 * S)
        results.append(est)
    on_time, late_est = results
    assert late_est.stamp_ns == on_time.stamp_ns == 2 * S
    np.testing.assert_allclose(
        late_est.T_map_odom.as_matrix(), on_time.T_map_odom.as_matrix(), atol=1e-12
    )
    np.testing.assert_allclose(late_est.covariance, on_time.covariance, atol=1e-12)


def test_update_and_update_partial_take_their_own_kind_of_fix() -> None:
    buffer = TransformBuffer()
    buffer.set_static("odom", "base_link", SE3.identity())
    est = _estimator(buffer, planar=False)
    full = Candidate.of_fix(TagFix(0, SE3.identity(), np.eye(6) * 1e-2, "tag:1",
                                   FixQuality(0.3)), SE3.identity(), planar=False)  # fmt: skip
    with pytest.raises(LocalizeError, match="not initialized"):
        est.innovation(full)
    est.initialize(0, SE3.identity(), np.eye(6) * 1e-2)
    partial = Candidate.of_partial(
        PartialFix(0, SE3.exp([0.1, 0.2, 0, 0, 0, 0]), np.eye(6)[:, [1]], [[1e-4]], "lidar"),
        SE3.identity(), planar=False,
    )  # fmt: skip
    with pytest.raises(LocalizeError, match="update_partial"):
        est.update(partial)
    with pytest.raises(LocalizeError, match="enters through update"):
        est.update_partial(full)
    est.update_partial(partial)  # y measured: x stays
    assert est.T_map_odom.translation[0] == pytest.approx(0.0, abs=1e-12)
    assert est.T_map_odom.translation[1] > 0.15
    with pytest.raises(LocalizeError, match="before the state"):
        est.predict(-1)
