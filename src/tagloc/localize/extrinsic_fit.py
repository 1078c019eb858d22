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
the spread, so a drive's noise is measured, not assumed. :func:`significance` turns the estimate
into the squared Mahalanobis distance of the observable components from zero and the Hotelling
``T^2`` threshold for that many blocks (a chi-square quantile as the blocks grow many).
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


def fit_extrinsics(
    stamps: npt.NDArray[np.int64], T_map_base: SE3, cov: FloatArray, T_odom_base: SE3,
    T_base_cam: SE3, *, min_dt_s: float, max_dt_s: float, sigma_translation_m: float,
    sigma_rotation_rad: float, sigma_lateral_drift: float, gravity: bool,
    sigma_gravity_rad: float, block_s: float,
) -> ExtrinsicFit | None:  # fmt: skip
    """Fit over the fixes (sorted by stamp; ``T_odom_base`` at their stamps); None without
    pairs. Each fix is paired with the first at least ``min_dt_s`` later, within ``max_dt_s``."""
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
    block_ns = max(round(block_s * S_NS), 1)
    blocks = np.concatenate([np.repeat(stamps[i] // block_ns, 6),
                             np.repeat(stamps // block_ns, 3) if gravity else []])  # fmt: skip
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
    reduced, n_blocks = _sandwich(J @ basis, sol.fun, n_data, blocks.astype(np.int64))
    m = Q.shape[1]
    return ExtrinsicFit(
        Q @ (Q.T @ sol.x[:6]), Q @ reduced[:m, :m] @ Q.T, observable, float(sol.x[6]),
        float(sol.x[8]), len(i), n_blocks,
    )  # fmt: skip


def _sandwich(
    jac: FloatArray, fun: FloatArray, n_data: int, blocks: npt.NDArray[np.int64]
) -> tuple[FloatArray, int]:
    """``H^-1 (S + P) H^-1``: ``H`` the robust Gauss-Newton information, ``S`` the sum over
    blocks of the outer products of the data rows' scores, ``P`` the priors' information (a
    correct noise model gives ``S = H - P`` and the usual inverse)."""
    weight = 1.0 / np.sqrt(1.0 + (fun / _F_SCALE) ** 2)  # soft-L1 rho'
    scores = jac[:n_data] * (np.sqrt(weight[:n_data]) * fun[:n_data])[:, None]
    _, index = np.unique(blocks, return_inverse=True)
    n_blocks = int(index.max()) + 1
    summed = np.zeros((n_blocks, jac.shape[1]))
    np.add.at(summed, index, scores)
    correction = n_blocks / max(n_blocks - 1, 1)
    S = correction * summed.T @ summed
    P = jac[n_data:].T @ jac[n_data:]
    H_inv = np.linalg.inv(jac.T @ jac)
    full = H_inv @ (S + P) @ H_inv
    return 0.5 * (full + full.T), n_blocks


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
