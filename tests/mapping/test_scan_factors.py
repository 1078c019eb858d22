"""Scan-matching (relative-pose) factors on synthetic measurements: truth + known noise.

Oracles: GTSAM's own ``BetweenFactorPose3`` (error, optimum), numerical differentiation, and
the simulated truth the measurements were drawn from.
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from tagloc.geometry import SE3
from tagloc.mapping.graph import X
from tagloc.mapping.initialize import inverse_h
from tagloc.mapping.observations import Observations
from tagloc.mapping.odometry_factors import log_batch
from tagloc.mapping.scan_factors import (
    DEGENERATE_INFORMATION,
    RelativePoseFactors,
    add_relative_factors,
    linearize_relative,
    relative_cost,
    relative_errors,
    scan_scale,
    sqrt_information,
)


def _loop(n: int, radius: float = 4.0) -> np.ndarray:
    """``(n, 4, 4)`` true ``T_map_base`` around a circle (yaw along the path, a little z)."""
    out = np.tile(np.eye(4), (n, 1, 1))
    for k, a in enumerate(np.linspace(0.0, 2 * np.pi, n, endpoint=False)):
        xyz = [radius * np.cos(a), radius * np.sin(a), 0.01 * k]
        out[k] = SE3.from_rotvec([0.0, 0.0, a + np.pi / 2], xyz).as_matrix()
    return out


def _measure(
    M_true: np.ndarray, pairs: list[tuple[int, int]], sigmas: np.ndarray, rng: np.random.Generator
) -> RelativePoseFactors:
    a = np.array([p[0] for p in pairs], dtype=np.int64)
    b = np.array([p[1] for p in pairs], dtype=np.int64)
    Z = inverse_h(M_true[a]) @ M_true[b]
    noise = SE3.exp(rng.normal(size=(len(pairs), 6)) * sigmas).as_matrix()
    R = np.array([sqrt_information(np.diag(1.0 / sigmas**2))] * len(pairs))
    loop = np.abs(b - a) > 1
    return RelativePoseFactors(a, b, Z @ noise, R, loop, "cauchy", 3.0)


def _gtsam_values(M: np.ndarray) -> gtsam.Values:
    values = gtsam.Values()
    for k, Mk in enumerate(M):
        values.insert(X(k), gtsam.Pose3(gtsam.Rot3(Mk[:3, :3]), Mk[:3, 3]))
    return values


def test_sqrt_information_squares_back_and_floors_degenerate_directions() -> None:
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 4))
    info = A @ A.T  # rank 4: two directions unconstrained
    R = sqrt_information(info)
    assert np.allclose(np.tril(R, -1), 0.0)
    eig = np.linalg.eigvalsh(R.T @ R)
    assert np.allclose(np.sort(eig)[:2], DEGENERATE_INFORMATION, rtol=1e-3)
    assert np.allclose(R.T @ R, info, atol=1e-6)


def test_cost_and_errors_match_gtsam_between_factor() -> None:
    rng = np.random.default_rng(2)
    M_true = _loop(12)
    factors = _measure(M_true, [(k, k + 1) for k in range(11)] + [(0, 11), (2, 9)],
                       np.array([0.05] * 3 + [0.02] * 3), rng)  # fmt: skip
    # evaluate away from the measurements so that some factors are in the kernel's tail
    M = M_true @ SE3.exp(rng.normal(size=(12, 6)) * 0.1).as_matrix()
    graph = gtsam.NonlinearFactorGraph()
    add_relative_factors(graph, factors, X)
    values = _gtsam_values(M)
    assert graph.error(values) == pytest.approx(relative_cost(M, factors), rel=1e-9)
    e = relative_errors(M, factors)
    for i in range(len(factors)):  # the whitened error, up to GTSAM's rotation-first order
        whitened = graph.at(i).noiseModel().noise().whiten(graph.at(i).unwhitenedError(values))
        assert np.linalg.norm(whitened) == pytest.approx(np.linalg.norm(e[i]), rel=1e-9)


def test_jacobians_match_numerical_differentiation() -> None:
    rng = np.random.default_rng(3)
    M = _loop(6) @ SE3.exp(rng.normal(size=(6, 6)) * 0.05).as_matrix()
    factors = _measure(_loop(6), [(0, 1), (1, 3), (5, 2)], np.array([0.02] * 3 + [0.01] * 3), rng)
    # kernel weight 1: plain least squares
    factors = RelativePoseFactors(factors.a, factors.b, factors.M_a_b, factors.sqrt_information,
                                  factors.loop, "huber", 1e9)  # fmt: skip
    _, A_a, A_b = linearize_relative(M, factors)
    h = 1e-6
    for which, A in (("a", A_a), ("b", A_b)):
        for d in range(6):
            for i in range(len(factors)):
                k = int(getattr(factors, which)[i])
                step = np.zeros(6)
                step[d] = h
                Mp = M.copy()
                Mp[k] = M[k] @ SE3.exp(step).as_matrix()
                Mm = M.copy()
                Mm[k] = M[k] @ SE3.exp(-step).as_matrix()
                plus, minus = relative_errors(Mp, factors)[i], relative_errors(Mm, factors)[i]
                numeric = (plus - minus) / (2 * h)
                assert np.allclose(A[i][:, d], numeric, atol=1e-5)


def _solve_numpy(
    M0: np.ndarray, odometry: RelativePoseFactors, scans: RelativePoseFactors, prior_sigma: float
) -> np.ndarray:
    """Gauss-Newton with :func:`linearize_relative` (dense), keyframe 0 held by a prior."""
    M, n = M0.copy(), len(M0)
    M_prior = M0[0].copy()
    for _ in range(15):
        rows, rhs = [], []
        for f in (odometry, scans):
            e, A_a, A_b = linearize_relative(M, f)
            for i in range(len(f)):
                J = np.zeros((6, 6 * n))
                J[:, 6 * f.a[i] : 6 * f.a[i] + 6] += A_a[i]
                J[:, 6 * f.b[i] : 6 * f.b[i] + 6] += A_b[i]
                rows.append(J)
                rhs.append(-e[i])
        J0 = np.zeros((6, 6 * n))
        J0[:, :6] = np.eye(6) / prior_sigma
        rows.append(J0)
        rhs.append(-log_batch((inverse_h(M_prior) @ M[0])[None])[0] / prior_sigma)
        J, r = np.vstack(rows), np.concatenate(rhs)
        delta = np.linalg.solve(J.T @ J, J.T @ r)
        M = M @ SE3.exp(delta.reshape(n, 6)).as_matrix()
        if np.abs(delta).max() < 1e-9:
            break
    return M


def test_scan_factors_remove_odometry_drift_in_gtsam_and_in_numpy_alike() -> None:
    rng = np.random.default_rng(4)
    n = 24
    M_true = _loop(n)
    # odometry with a yaw bias of 2 deg per step plus noise: drifts ~0.8 m around the loop
    odo_sigmas = np.array([0.02, 0.02, 0.002, 0.002, 0.002, 0.02])
    steps = inverse_h(M_true[:-1]) @ M_true[1:]
    bias = SE3.from_rotvec([0.0, 0.0, np.radians(2.0)], [0.0, 0.0, 0.0]).as_matrix()
    noisy = steps @ bias @ SE3.exp(rng.normal(size=(n - 1, 6)) * odo_sigmas).as_matrix()
    M_odo = np.tile(M_true[0], (n, 1, 1))
    for k in range(1, n):
        M_odo[k] = M_odo[k - 1] @ noisy[k - 1]
    odometry = RelativePoseFactors(
        np.arange(n - 1), np.arange(1, n), noisy,
        np.array([sqrt_information(np.diag(1.0 / odo_sigmas**2))] * (n - 1)), np.zeros(n - 1, bool),
        "huber", 1e9,
    )  # fmt: skip
    scan_sigmas = np.array([0.005] * 3 + [0.001] * 3)
    pairs = [(k, k + 1) for k in range(n - 1)] + [(0, n - 1), (0, n - 2), (3, n - 3)]
    scans = _measure(M_true, pairs, scan_sigmas, rng)
    # GTSAM: prior on x0, odometry between factors, the scan factors
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(M_true[0]),
                                     gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))  # fmt: skip
    add_relative_factors(graph, odometry, X)
    add_relative_factors(graph, scans, X)
    result = gtsam.LevenbergMarquardtOptimizer(graph, _gtsam_values(M_odo)).optimize()
    M_gtsam = np.array([result.atPose3(X(k)).matrix() for k in range(n)])
    M_numpy = _solve_numpy(M_odo, odometry, scans, 1e-6)

    def rms(M: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((M[:, :3, 3] - M_true[:, :3, 3]) ** 2, axis=1))))

    assert rms(M_odo) > 0.3  # the odometry alone drifts
    # scans: mm per step, closed loops; the odometry's unmodelled yaw bias (1.7 sigma a step)
    # still pulls with 1/400 of the scans' weight
    assert rms(M_gtsam) < 0.05 * rms(M_odo)
    assert np.allclose(M_numpy[:, :3, 3], M_gtsam[:, :3, 3], atol=1e-5)
    assert np.allclose(M_numpy[:, :3, :3], M_gtsam[:, :3, :3], atol=2e-5)


def test_degenerate_direction_does_not_pull() -> None:
    """A corridor registration (nothing along x) corrects y and yaw, leaves x to odometry."""
    M0 = np.eye(4)
    M1_odo = SE3.from_rotvec([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]).as_matrix()
    M1_scan = SE3.from_rotvec([0.0, 0.0, 0.05], [1.4, 0.2, 0.0]).as_matrix()
    info = np.diag([0.0, 1e6, 1e6, 1e6, 1e6, 1e6])  # x unconstrained
    scan = RelativePoseFactors(np.array([0]), np.array([1]), M1_scan[None],
                               sqrt_information(info)[None], np.array([False]), "huber",
                               1e9)  # fmt: skip
    odo_sig = np.array([0.05, 0.05, 0.05, 0.01, 0.01, 0.01])
    odometry = RelativePoseFactors(np.array([0]), np.array([1]), M1_odo[None],
                                   sqrt_information(np.diag(1 / odo_sig**2))[None],
                                   np.array([False]), "huber", 1e9)  # fmt: skip
    M = _solve_numpy(np.array([M0, M1_odo]), odometry, scan, 1e-6)
    # yaw from the scan (the odometry's weight is 1e-3 of it); the position anywhere on the
    # line through the scan's (1.4, 0.2) along the measurement's own x axis (turned 0.05 rad),
    # where the odometry's 1.0 m puts it
    assert np.arctan2(M[1, 1, 0], M[1, 0, 0]) == pytest.approx(0.05, abs=1e-3)
    assert M[1, 0, 3] == pytest.approx(1.0, abs=0.01)
    assert M[1, 1, 3] == pytest.approx(0.2 + (M[1, 0, 3] - 1.4) * np.tan(0.05), abs=1e-3)


def test_a_wrong_loop_closure_has_bounded_pull() -> None:
    rng = np.random.default_rng(5)
    n = 16
    M_true = _loop(n)
    sig = np.array([0.01] * 3 + [0.002] * 3)
    scans = _measure(M_true, [(k, k + 1) for k in range(n - 1)] + [(0, n - 1)], sig, rng)
    bad = _measure(M_true, [(2, 10)], sig, rng)
    wrong = bad.M_a_b @ SE3.from_rotvec([0.0, 0.0, 0.3], [1.5, -1.0, 0.0]).as_matrix()
    bad = RelativePoseFactors(bad.a, bad.b, wrong, bad.sqrt_information, bad.loop, "cauchy", 3.0)
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(M_true[0]),
                                     gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))  # fmt: skip
    add_relative_factors(graph, scans.concat(bad), X)
    result = gtsam.LevenbergMarquardtOptimizer(graph, _gtsam_values(M_true)).optimize()
    M = np.array([result.atPose3(X(k)).matrix() for k in range(n)])
    assert np.abs(M[:, :3, 3] - M_true[:, :3, 3]).max() < 0.05  # the 1.8 m lie moved it < 5 cm


def test_with_keyframes_keeps_every_observation_at_its_stamp() -> None:
    from tagloc.mapping.lidar_keyframes import with_keyframes
    from tagloc.mapping.survey import Survey

    odom_stamps = np.arange(0, 11, dtype=np.int64) * 1_000_000_000
    T = SE3.from_rotvec(np.zeros((11, 3)), np.column_stack([np.arange(11.0), np.zeros((11, 2))]))
    survey = Survey(odom_stamps, T, (), {}, {})
    kf_stamps = np.array([1, 4, 7], dtype=np.int64) * 1_000_000_000
    obs = Observations(
        keyframe_stamps_ns=kf_stamps, T_odom_base=T[[1, 4, 7]], tag_keys=(("tag36h11", 0),),
        tag_sizes=np.array([0.16]), keyframe=np.array([0, 2, 2, 1]), tag=np.zeros(4, np.int64),
        camera=("c",) * 4, T_base_tag=np.zeros((4, 2, 4, 4)), cov=np.zeros((4, 2, 6, 6)),
        ambiguity=np.zeros(4), range_m=np.ones(4), corners_px=np.zeros((4, 4, 2)), dropped={},
    )  # fmt: skip
    extra = np.array([2_500_000_000, 4_000_000_000, 9_000_000_000], dtype=np.int64)
    merged, index = with_keyframes(obs, survey, extra)
    assert np.array_equal(merged.keyframe_stamps_ns[index], extra)
    assert len(merged.keyframe_stamps_ns) == 5  # the sweep at 4 s shares the camera keyframe
    assert np.array_equal(
        merged.keyframe_stamps_ns[merged.keyframe], obs.keyframe_stamps_ns[obs.keyframe]
    )
    assert np.allclose(merged.T_odom_base.translation[:, 0], [1.0, 2.5, 4.0, 7.0, 9.0])


@pytest.mark.parametrize("scale", [0.0, 0.003, -0.01])
def test_scan_scale_recovers_the_scale_the_measurements_were_drawn_with(scale: float) -> None:
    rng = np.random.default_rng(11)
    M_true = _loop(60)
    pairs = [(k, k + 1) for k in range(59)]
    factors = _measure(M_true, pairs, np.array([0.002] * 3 + [0.001] * 3), rng)
    scaled = factors.M_a_b.copy()
    scaled[:, :3, 3] *= 1.0 + scale
    loops = _measure(M_true, [(0, 30)], np.array([0.002] * 3 + [0.001] * 3), rng)
    wrong_loop = loops.M_a_b.copy()
    wrong_loop[:, :3, 3] *= 1.5  # a loop closure is not a step: left out
    measured = RelativePoseFactors(
        np.concatenate([factors.a, loops.a]), np.concatenate([factors.b, loops.b]),
        np.concatenate([scaled, wrong_loop]),
        np.concatenate([factors.sqrt_information, loops.sqrt_information]),
        np.concatenate([np.zeros(59, dtype=bool), np.ones(1, dtype=bool)]),
    )  # fmt: skip
    found, sigma = scan_scale(M_true, measured)
    # 2 mm of noise on 0.42 m steps, 59 of them: a standard error near 0.1 %
    assert 0.0003 < sigma < 0.003
    assert abs(found - scale) < 3.0 * sigma
    assert np.isnan(scan_scale(M_true, loops)[0])  # loops only: no scale
