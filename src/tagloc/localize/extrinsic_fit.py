"""The mounting check's estimate and its uncertainty: hand-eye ``A X = X B`` from fix pairs.

:func:`fit_extrinsics` takes the accepted fixes as arrays (stamps, ``T_map_base``, covariances)
and the odometry at their stamps, forms pairs of fixes a short time apart, and solves for the
correction ``xi`` (``X = T_base_cam @ Exp(xi)``) with three nuisances of the odometry over a
pair: its distance scale, its turn scale, and its *sideways drift* ``k`` (a legged base crabs:
each metre forward moves it ``k`` metres sideways, so the odometry's translation is turned by
about ``k`` rad). Camera yaw about the base's vertical and sideways drift turn the pair's
translation alike (a rotation of the whole mounting about the base's origin and a drift of the
same angle fit the pairs equally), so ``k`` is held by a prior of 1-sigma
``sigma_lateral_drift``; fitting without it is what made a legged drive look like a camera
turned by its drift (0.6-0.9 deg).

The uncertainty is a cluster-robust ("sandwich") covariance: pairs and fixes are grouped in
blocks of ``block_s`` seconds, within which errors are correlated (a pair shares fixes and
odometry with its neighbours; PnP errors of one tag drift slowly), and the blocks' scores give
the spread, so a drive's noise is measured, not assumed. Given each fix's tag, the clustering is
two-way (Cameron, Gelbach and Miller 2011, "Robust inference with multiway clustering"): by
block and by tag, ``V = V_block + V_tag - V_block&tag``. A tag's surveyed pose is off by its own
small tilt for as long as it is seen, in every block it is seen in, and that tilt enters the
gravity rows of all its fixes alike; time blocks alone take it for independent noise (on the
dupont drive the tags' mean tilts spread by 0.5 deg, the same in both cameras). :func:`significance`
turns the estimate into the squared Mahalanobis distance of the observable components from zero
and the Hotelling ``T^2`` threshold for that many blocks (a chi-square quantile as they grow
many; the blocks, not the fewer of blocks and tags that Cameron et al. advise: on the simulator's
legged drives the tags seen, 17 in 120 s, would take the power to find a 1 deg / 3 cm mis-set).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.units import S_NS

__all__ = ["ExtrinsicFit", "fit_extrinsics", "significance"]

_F_SCALE = 3.0  # soft-L1 knee, in whitened units
_MIN_TAGS = 8  # tags at least for the clustering by tag
_PRIOR = 1e-3  # a weak pull of xi to 0 (1 km / 1000 rad): keeps unobservable directions finite


@dataclass(frozen=True, slots=True)
class ExtrinsicFit:
    """What :func:`fit_extrinsics` found (``xi`` and ``cov`` over all six components; the
    ``observable`` ones are those the drive constrains beyond the weak prior)."""

    xi: FloatArray
    cov: FloatArray
    observable: npt.NDArray[np.bool_]
    odometry_scale: float
    lateral_drift: float
    n_pairs: int
    n_blocks: int
    n_tags: int = 0


def fit_extrinsics(
    stamps: npt.NDArray[np.int64], T_map_base: SE3, cov: FloatArray, T_odom_base: SE3,
    T_base_cam: SE3, *, min_dt_s: float, max_dt_s: float, sigma_translation_m: float,
    sigma_rotation_rad: float, sigma_lateral_drift: float, gravity: bool,
    sigma_gravity_rad: float, block_s: float, tag_keys: npt.NDArray[np.int64] | None = None,
) -> ExtrinsicFit | None:  # fmt: skip
    """Fit over the fixes (sorted by stamp; ``T_odom_base`` at their stamps); None without
    pairs. Each fix is paired with the first at least ``min_dt_s`` later, within ``max_dt_s``.
    ``tag_keys`` (N,): each fix's tag (any integer naming it), for the two-way clustering; a
    pair counts under its first fix's tag."""
    from scipy.optimize import least_squares

    T_map_cam = T_map_base @ T_base_cam
    j = np.searchsorted(stamps, stamps + round(min_dt_s * S_NS))
    i = np.flatnonzero(j < len(stamps))
    j = j[i]
    keep = (stamps[j] - stamps[i]) <= max_dt_s * S_NS
    i, j = i[keep], j[keep]
    if len(i) == 0:
        return None
    A = T_odom_base[i].inverse() @ T_odom_base[j]
    B = T_map_cam[i].inverse() @ T_map_cam[j]
    rotvec_A, t_A = A.rotation.log(), A.translation
    side_A = np.column_stack([-t_A[:, 1], t_A[:, 0], np.zeros(len(t_A))])  # e_z x t_A
    # each pair's noise: both fixes' covariances moved to B's right tangent, plus the odometry's
    Ad_cam_base = T_base_cam.inverse().adjoint()
    cov_cam = Ad_cam_base @ cov @ Ad_cam_base.T
    Ad_B_inv = B.inverse().adjoint()
    odom = np.diag(np.square([sigma_translation_m] * 3 + [sigma_rotation_rad] * 3))
    cov_B = Ad_B_inv @ cov_cam[i] @ np.swapaxes(Ad_B_inv, -1, -2) + cov_cam[j] + odom
    W = np.linalg.inv(np.linalg.cholesky(cov_B))  # whitening: r_w = W r
    # gravity: "up" seen by each fix in the camera frame, and by the odometry in the base
    up_cam = T_map_cam.rotation.matrix[..., 2, :]  # R_map_cam^T e_z, per fix
    up_base = T_odom_base.rotation.matrix[..., 2, :]
    tilt_var = np.trace(cov_cam[:, 3:, 3:], axis1=1, axis2=2) / 3.0
    g_weight = 1.0 / np.sqrt(tilt_var + sigma_gravity_rad**2)
    k_weight = 1.0 / max(sigma_lateral_drift, 1e-9)

    def residuals(p: FloatArray) -> FloatArray:
        X = T_base_cam @ SE3.exp(p[:6])
        A_scaled = SE3.from_rotvec(rotvec_A * p[7], (t_A + p[8] * side_A) * p[6])
        B_pred = X.inverse() @ A_scaled @ X
        parts = [np.einsum("nij,nj->ni", W, (B_pred.inverse() @ B).log()).ravel()]
        if gravity:
            parts.append((((up_cam @ X.rotation.matrix.T) - up_base) * g_weight[:, None]).ravel())
        parts += [_PRIOR * p[:6], [k_weight * p[8]]]
        return np.concatenate(parts)

    p0 = np.zeros(9)
    p0[6:8] = 1.0
    sol = least_squares(residuals, p0, loss="soft_l1", f_scale=_F_SCALE, x_scale="jac")
    # rows: 6 per pair, 3 per fix (gravity), then the 7 prior rows
    n_data = 6 * len(i) + (3 * len(stamps) if gravity else 0)
    # each data row's clusters: its block (and its tag)
    keys = [_row_keys(stamps // max(round(block_s * S_NS), 1), i, gravity)]
    if tag_keys is not None:
        keys.append(_row_keys(np.asarray(tag_keys, dtype=np.int64), i, gravity))
    # the directions the data constrain far beyond the weak prior on xi (nuisances marginalized)
    J = sol.jac
    H = J.T @ J
    H6 = H[:6, :6] - H[:6, 6:] @ np.linalg.pinv(H[6:, 6:]) @ H[6:, :6]
    w, V = np.linalg.eigh(0.5 * (H6 + H6.T))
    Q = V[:, w > (100.0 * _PRIOR) ** 2]
    observable = np.linalg.norm(Q, axis=1) > 0.95
    # the covariance of xi's projection on them: the sandwich in those coordinates + nuisances
    basis = np.zeros((9, Q.shape[1] + 3))
    basis[:6, : Q.shape[1]] = Q
    basis[6:, Q.shape[1] :] = np.eye(3)
    reduced, counts = _sandwich(J @ basis, sol.fun, n_data, keys)
    m = Q.shape[1]
    return ExtrinsicFit(
        Q @ (Q.T @ sol.x[:6]), Q @ reduced[:m, :m] @ Q.T, observable, float(sol.x[6]),
        float(sol.x[8]), len(i), counts[0], counts[1] if len(counts) > 1 else 0,
    )  # fmt: skip


def _row_keys(
    per_fix: npt.NDArray[np.int64], i: npt.NDArray[np.intp], gravity: bool
) -> npt.NDArray[np.int64]:
    """A per-fix key for every data row: 6 per pair (its first fix ``i``), 3 per fix."""
    parts = [np.repeat(per_fix[i], 6)] + ([np.repeat(per_fix, 3)] if gravity else [])
    return np.concatenate(parts).astype(np.int64)


def _sandwich(
    jac: FloatArray, fun: FloatArray, n_data: int, keys: list[npt.NDArray[np.int64]]
) -> tuple[FloatArray, list[int]]:
    """``H^-1 (S + P) H^-1``: ``H`` the robust Gauss-Newton information, ``S`` the outer
    products of the data rows' scores summed by cluster, ``P`` the priors' information (a
    correct noise model gives ``S = H - P`` and the usual inverse). One key array: clusters by
    it; two (blocks, tags): ``S = S_1 + S_2 - S_12`` (two-way clustering, its negative
    eigenvalues clipped), if there are at least ``_MIN_TAGS`` tags (with fewer, the tags' sums
    are no measure of a spread: one tag's scores sum to about zero at the optimum). Returns
    the covariance and the numbers of blocks and tags."""
    weight = 1.0 / np.sqrt(1.0 + (fun / _F_SCALE) ** 2)  # soft-L1 rho'
    scores = jac[:n_data] * (np.sqrt(weight[:n_data]) * fun[:n_data])[:, None]
    S, counts = _clustered(scores, keys[0])
    S_tag, n_tags = _clustered(scores, keys[1]) if len(keys) > 1 else (S, [0])
    if n_tags[0] >= _MIN_TAGS:
        span = int(keys[1].max()) - int(keys[1].min()) + 1
        both = keys[0] * span + keys[1] - int(keys[1].min())
        S_both, _ = _clustered(scores, both)
        w, V = np.linalg.eigh(0.5 * ((S + S_tag - S_both) + (S + S_tag - S_both).T))
        S = (V * np.clip(w, 0.0, None)) @ V.T
    counts = [counts[0], n_tags[0]]
    P = jac[n_data:].T @ jac[n_data:]
    H_inv = np.linalg.inv(jac.T @ jac)
    full = H_inv @ (S + P) @ H_inv
    return 0.5 * (full + full.T), counts


def _clustered(scores: FloatArray, keys: npt.NDArray[np.int64]) -> tuple[FloatArray, list[int]]:
    """The scores' outer products summed by cluster (with the small-sample factor
    ``G / (G - 1)``), and ``[G]``."""
    _, index = np.unique(keys, return_inverse=True)
    n = int(index.max()) + 1
    summed = np.zeros((n, scores.shape[1]))
    np.add.at(summed, index, scores)
    return n / max(n - 1, 1) * summed.T @ summed, [n]


def significance(fit: ExtrinsicFit, alpha: float) -> tuple[float, float]:
    """``(d2, threshold)``: the observable components' squared Mahalanobis distance from 0 and
    the level-``alpha`` threshold of Hotelling's ``T^2`` with ``fit.n_blocks`` blocks
    (``inf`` with no more blocks than components)."""
    from scipy.stats import f as f_dist

    obs = fit.observable
    dof = int(obs.sum())
    if dof == 0:
        return 0.0, math.inf
    x = fit.xi[obs]
    d2 = float(x @ np.linalg.pinv(fit.cov[np.ix_(obs, obs)]) @ x)
    g = fit.n_blocks
    if g <= dof:
        return d2, math.inf
    return d2, float(dof * (g - 1) / (g - dof) * f_dist.ppf(1.0 - alpha, dof, g - dof))

