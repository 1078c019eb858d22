"""Covariance honesty (NEES of accepted fixes in a corner-noise simulation) and its building blocks.

Oracles: simulator ground truth for the NEES (``e^T P^-1 e``, ``e = Log(T_true^-1 T_est)``, mean
6 when honest; accepted band ``[0.5, 2] x 6``), seeded Monte Carlo sampling for the moment
formulas and the covariance transport to ``T_map_cam`` / ``T_map_base``.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError
from test_pnp import (
    CAMERA,
    SIZE,
    corners_of,
    observe_cell,
    simulate_corners,
    wall_view,
)

from tagloc.geometry import SE3
from tagloc.tags.covariance import (
    NoiseModel,
    ambiguity_mixture,
    ambiguity_weight,
    map_base_from_cam,
    map_cam_from_tag,
    nees,
    pose_covariance,
    reprojection_covariance,
    second_order_term,
    valley_term,
)
from tagloc.tags.pnp import TagPoseEstimate, estimate_tag_poses

DOF = 6
BAND = (0.5 * DOF, 2.0 * DOF)


def _accepted_nees(
    cells: list[tuple[float, float]],
    sigma: float,
    n: int,
    bias_px: float = 0.0,
    size_error_rel: float = 0.0,
    noise: NoiseModel | None = None,
) -> dict[tuple[float, float], tuple[float, int]]:
    """Mean NEES and count of the accepted fixes per cell (cells with >= 10 accepted)."""
    out = {}
    for distance, angle in cells:
        results = observe_cell(
            distance,
            angle,
            sigma,
            n,
            "rotation",
            seed=int(1000 * sigma + 10 * distance + angle),
            bias_px=bias_px,
            size_error_rel=size_error_rel,
            noise=noise,
        )
        values = [
            float(nees(T, r.accepted[0].T_cam_tag, r.accepted[0].cov_cam_tag))
            for T, r in results
            if r.accepted
        ]
        if len(values) >= 10:
            out[(distance, angle)] = (float(np.mean(values)), len(values))
    return out


@pytest.mark.parametrize("sigma", [0.3, 0.5])
def test_nees_of_accepted_fixes_is_honest_across_distance_and_angle(sigma: float) -> None:
    cells = [(d, a) for d in (0.5, 1.0, 2.0, 3.0, 4.0, 6.0) for a in (0.0, 15.0, 45.0, 75.0)]
    per_cell = _accepted_nees(cells, sigma, n=30)
    assert len(per_cell) >= 14
    weighted = sum(m * k for m, k in per_cell.values()) / sum(k for _, k in per_cell.values())
    assert BAND[0] <= weighted <= BAND[1], per_cell
    for cell, (mean, _) in per_cell.items():  # per cell: within [0.25, 2.5] x dof
        assert 0.25 * DOF <= mean <= 2.5 * DOF, (cell, mean)


def test_inflation_covers_systematic_errors_that_pure_noise_models_miss() -> None:
    # Corners pulled 0.15 px inwards, printed size off by 0.3 %, 0.3 px noise.
    cells = [(d, a) for d in (1.0, 4.0, 6.0) for a in (30.0, 60.0)]
    honest = _accepted_nees(cells, 0.3, 40, bias_px=0.15, size_error_rel=0.003)
    bare = _accepted_nees(
        cells,
        0.3,
        40,
        bias_px=0.15,
        size_error_rel=0.003,
        noise=NoiseModel.pixels_only(0.3),
    )
    assert all(BAND[0] <= m <= BAND[1] for m, _ in honest.values()), honest
    assert max(m for m, _ in bare.values()) > 3.0 * DOF, bare


@pytest.mark.slow
@pytest.mark.parametrize("sigma", [0.3, 0.5])
def test_nees_full_sweep(sigma: float) -> None:
    cells = [
        (d, a)
        for d in (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0)
        for a in (0.0, 10.0, 15.0, 30.0, 45.0, 60.0, 75.0)
    ]
    per_cell = _accepted_nees(cells, sigma, n=200)
    weighted = sum(m * k for m, k in per_cell.values()) / sum(k for _, k in per_cell.values())
    assert BAND[0] <= weighted <= BAND[1]
    for cell, (mean, k) in per_cell.items():
        if k >= 30:
            assert 0.25 * DOF <= mean <= 2.5 * DOF, (cell, mean)


# ----- building blocks -------------------------------------------------------------------------


def test_pose_covariance_without_inflation_is_the_gauss_newton_covariance() -> None:
    rng = np.random.default_rng(20)
    J = rng.normal(size=(3, 8, 6))
    R = np.repeat(np.eye(3)[None], 3, axis=0)
    t = np.array([[0.0, 0.0, 2.0]] * 3)
    bare = NoiseModel.pixels_only(0.4)
    expected = 0.16 * np.linalg.inv(np.swapaxes(J, 1, 2) @ J)
    np.testing.assert_allclose(pose_covariance(J, R, t, [50.0] * 3, bare), expected, rtol=1e-10)
    np.testing.assert_allclose(reprojection_covariance(J, 0.4), expected, rtol=1e-10)
    # each inflation only adds
    full = pose_covariance(J, R, t, [50.0] * 3, NoiseModel(sigma_px=0.4), [0.5] * 3)
    assert (np.linalg.eigvalsh(full - expected) > -1e-15).all()


def test_second_order_term_matches_sampling() -> None:
    rng = np.random.default_rng(21)
    A = rng.normal(size=(6, 6))
    P = 0.01 * (A @ A.T + np.eye(6))
    samples = rng.multivariate_normal(np.zeros(6), P, size=400_000)
    c = np.cross(samples[:, 3:], samples[:, :3])
    empirical = 0.25 * c.T @ c / len(c)
    np.testing.assert_allclose(
        second_order_term(P[None])[0], empirical, atol=0.02 * np.abs(empirical).max()
    )


def test_valley_term_only_where_the_barrier_is_lower_than_linearized() -> None:
    J = np.zeros((3, 8, 6))
    J[:, :6, :6] = 10.0 * np.eye(6)  # J^T J = 100 I
    delta = np.array([[0.0, 0.0, 0.0, 0.4, 0.0, 0.0]] * 3)
    quadratic = 100.0 * 0.16  # delta^T J^T J delta: the linearized SSE rise at the other branch
    term = valley_term(J, 1.0, delta, [quadratic, quadratic / 8.0, 1e-9])
    assert np.allclose(term[0], 0.0)  # midpoint barrier above the quadratic's quarter
    var_s = term[1][3, 3] / 0.16  # secant: sigma^2 / (4 b) - sigma^2 / (delta^T H delta)
    assert var_s == pytest.approx(1.0 / (4.0 * quadratic / 8.0) - 1.0 / quadratic)
    assert term[2][3, 3] == pytest.approx(0.25 * 0.16)  # capped: half the separation, 1 sigma


def test_ambiguity_mixture_is_the_second_moment_about_the_chosen_branch() -> None:
    rng = np.random.default_rng(22)
    T_a = SE3.from_rotvec([0.0, 0.3, 0.0], [0.1, 0.0, 2.0])
    T_b = SE3.from_rotvec([0.0, -0.3, 0.0], [0.1, 0.02, 2.05])
    C_a, C_b = np.diag([1e-4] * 3 + [4e-4] * 3), np.diag([2e-4] * 3 + [1e-4] * 3)
    log_odds = 1.2
    w = float(ambiguity_weight(log_odds))
    assert w == pytest.approx(1.0 / (1.0 + np.exp(0.6)))
    n = 200_000
    from_b = rng.random(n) < w
    xa = T_a.plus(rng.multivariate_normal(np.zeros(6), C_a, size=n))
    xb = T_b.plus(rng.multivariate_normal(np.zeros(6), C_b, size=n))
    d = np.where(from_b[:, None], xb.minus(T_a), xa.minus(T_a))
    empirical = d.T @ d / n
    np.testing.assert_allclose(
        ambiguity_mixture(T_a, C_a, T_b, C_b, log_odds),
        empirical,
        atol=0.03 * np.abs(empirical).max(),
    )
    assert np.allclose(ambiguity_mixture(T_a, C_a, T_b, C_b, np.inf), C_a)


def test_map_cam_and_map_base_covariances_match_sampling() -> None:
    rng = np.random.default_rng(23)
    T_cam_tag = SE3.from_rotvec([0.1, 2.8, 0.05], [0.2, -0.1, 2.5])
    T_map_tag = SE3.from_rotvec([0.0, 0.0, 1.0], [3.0, 4.0, 1.2])
    T_base_cam = SE3.from_rotvec([-1.5, 0.0, -1.5], [0.2, 0.0, 0.6])
    C = np.diag([1e-4, 1e-4, 4e-4, 1e-4, 2e-4, 1e-4])
    T_map_cam, C_map_cam = map_cam_from_tag(T_cam_tag, C, T_map_tag)
    T_map_base, C_map_base = map_base_from_cam(T_map_cam, C_map_cam, T_base_cam)
    assert T_map_cam.allclose(T_map_tag @ T_cam_tag.inverse())
    assert T_map_base.allclose(T_map_cam @ T_base_cam.inverse())
    samples = T_cam_tag.plus(rng.multivariate_normal(np.zeros(6), C, size=100_000))
    d_cam = (T_map_tag @ samples.inverse()).minus(T_map_cam)
    d_base = (T_map_tag @ samples.inverse() @ T_base_cam.inverse()).minus(T_map_base)
    for d, predicted in ((d_cam, C_map_cam), (d_base, C_map_base)):
        np.testing.assert_allclose(np.cov(d.T), predicted, atol=0.05 * np.abs(predicted).max())


def test_nees_is_the_mahalanobis_distance_of_the_right_tangent_error() -> None:
    T_true = SE3.from_rotvec([0.2, 0.1, 0.0], [1.0, 2.0, 3.0])
    e = np.array([0.01, -0.02, 0.03, 0.001, 0.002, -0.003])
    P = np.diag([1e-4, 4e-4, 9e-4, 1e-6, 4e-6, 9e-6])
    assert float(nees(T_true, T_true.plus(e), P)) == pytest.approx(e @ np.linalg.solve(P, e))


def test_noise_model_forbids_unknown_fields_and_bad_values() -> None:
    with pytest.raises(ValidationError, match="sigma"):
        NoiseModel(sigma=0.5)  # type: ignore[call-arg]
    with pytest.raises(ValidationError):
        NoiseModel(sigma_px=0.0)


def test_covariance_grows_with_distance_like_distance_squared_in_depth() -> None:
    rng = np.random.default_rng(24)
    depth_std = []
    for distance in (1.0, 2.0, 4.0):
        T, _ = wall_view(distance, np.deg2rad(40.0), rng, tilt_deg=0.0)
        (est,) = estimate_tag_poses([0], corners_of(T)[None], [SIZE], CAMERA)
        assert isinstance(est, TagPoseEstimate)
        ray_tag = est.T_cam_tag.rotation.inverse().act(est.T_cam_tag.translation) / est.range_m
        depth_std.append(np.sqrt(ray_tag @ est.cov_cam_tag[:3, :3] @ ray_tag))
    ratios = np.array(depth_std[1:]) / np.array(depth_std[:-1])
    assert ((ratios > 3.0) & (ratios < 5.0)).all()  # ~4x per doubling


def test_simulated_corners_helper_is_exact_without_noise() -> None:
    T, _ = wall_view(1.0, 0.5, np.random.default_rng(25))
    np.testing.assert_allclose(simulate_corners(T, 0.0, np.random.default_rng(0)), corners_of(T))
