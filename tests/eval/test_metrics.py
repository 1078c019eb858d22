"""ATE checked against an independent numpy computation (and Umeyama's closed form)."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.eval.metrics import EvaluationError, absolute_trajectory_error, endpoint_drift
from tagloc.geometry import SE3, SO3


def _random_path(rng: np.random.Generator, n: int) -> SE3:
    yaw = np.cumsum(rng.normal(0.0, 0.05, n))
    xyz = np.cumsum(rng.normal(0.0, 0.1, (n, 3)), axis=0)
    rotvec = np.zeros((n, 3))
    rotvec[:, 2] = yaw
    return SE3.from_rotvec(rotvec, xyz)


def _umeyama_rmse(ref: np.ndarray, est: np.ndarray) -> float:
    """Rigid (no scale) least-squares alignment of est onto ref, Umeyama (1991) eqs. 38-41."""
    mu_r, mu_e = ref.mean(0), est.mean(0)
    cov = (ref - mu_r).T @ (est - mu_e) / len(ref)
    U, _, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    S[2, 2] = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    R = U @ S @ Vt
    aligned = (R @ (est - mu_e).T).T + mu_r
    return float(np.sqrt(np.mean(np.sum((aligned - ref) ** 2, axis=1))))


def test_unaligned_ate_matches_numpy() -> None:
    rng = np.random.default_rng(7)
    stamps = np.arange(200, dtype=np.int64) * 10_000_000
    T_ref = _random_path(rng, 200)
    T_est = T_ref @ SE3.exp(rng.normal(0.0, 0.05, (200, 6)))
    result = absolute_trajectory_error(stamps, T_ref, T_est)
    errors = np.linalg.norm(np.asarray(T_ref.translation) - np.asarray(T_est.translation), axis=1)
    assert result.rmse == pytest.approx(np.sqrt(np.mean(errors**2)), rel=1e-12)
    assert result.max == pytest.approx(errors.max(), rel=1e-12)
    np.testing.assert_allclose(result.errors_m, errors, rtol=1e-12)


def test_aligned_ate_removes_a_rigid_offset_and_matches_umeyama() -> None:
    rng = np.random.default_rng(8)
    stamps = np.arange(300, dtype=np.int64) * 10_000_000
    T_ref = _random_path(rng, 300)
    T_offset = SE3(rotation=SO3.from_rotvec([0.1, -0.2, 0.7]), translation=np.array([3.0, -1, 2]))
    noise = SE3.exp(np.hstack([rng.normal(0, 0.02, (300, 3)), np.zeros((300, 3))]))
    T_est = T_offset @ T_ref @ noise
    aligned = absolute_trajectory_error(stamps, T_ref, T_est, align=True)
    unaligned = absolute_trajectory_error(stamps, T_ref, T_est)
    expected = _umeyama_rmse(np.asarray(T_ref.translation), np.asarray(T_est.translation))
    assert aligned.rmse == pytest.approx(expected, rel=1e-6)
    assert aligned.rmse < 0.05 < 1.0 < unaligned.rmse


def test_endpoint_drift_reports_translation_and_yaw() -> None:
    T_ref = SE3.stack([SE3.identity(), SE3.from_rotvec([0, 0, 0.3], [5.0, 0, 0])])
    T_est = SE3.stack([SE3.identity(), SE3.from_rotvec([0, 0, 0.5], [5.0, 0.4, 0.3])])
    drift_m, yaw = endpoint_drift(T_ref, T_est)
    assert drift_m == pytest.approx(0.5, abs=1e-12)
    assert yaw == pytest.approx(0.2, abs=1e-12)


@pytest.mark.parametrize("defect", ["length", "stamps", "nan"])
def test_bad_trajectories_are_rejected(defect: str) -> None:
    rng = np.random.default_rng(9)
    stamps = np.arange(10, dtype=np.int64)
    T_ref = _random_path(rng, 10)
    T_est = _random_path(rng, 10)
    if defect == "length":
        T_est = _random_path(rng, 9)
    elif defect == "stamps":
        stamps = stamps[::-1].copy()
    else:
        matrices = np.asarray(T_est.as_matrix()).copy()
        matrices[3, 0, 3] = np.nan
        with pytest.raises(Exception, match=r"(?i)nan|finite"):
            SE3.from_matrix(matrices)
        return
    with pytest.raises(EvaluationError):
        absolute_trajectory_error(stamps, T_ref, T_est)


@pytest.mark.parametrize("line", [False, True])
def test_alignment_of_a_degenerate_reference_is_one_evaluation_error(line: bool) -> None:
    stamps = np.arange(1, 11, dtype=np.int64) * 1_000_000_000
    xyz = np.zeros((10, 3))
    if line:
        xyz[:, 0] = np.linspace(0.0, 9.0, 10)
    T_ref = SE3(rotation=SO3.identity(10), translation=xyz)
    T_est = SE3(rotation=SO3.identity(10), translation=xyz + np.array([0.1, 0.0, 0.0]))
    with pytest.raises(EvaluationError, match=r"^cannot align the estimate onto the reference"):
        absolute_trajectory_error(stamps, T_ref, T_est, align=True)
    assert absolute_trajectory_error(stamps, T_ref, T_est).rmse == pytest.approx(0.1)
