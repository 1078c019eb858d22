"""Relative-pose factors between keyframes (lidar scan matching), in GTSAM and in numpy.

A scan-matching factor says how keyframe ``b`` sits in keyframe ``a``: the registration of
``b``'s scan onto ``a``'s gives ``Z = T_base_a_base_b``, and the factor's whitened error is

.. math:: e = R \\, \\mathrm{Log}\\left(Z^{-1}\\, x_a^{-1} x_b\\right)

with ``x = T_map_base`` and ``R`` the ``(6, 6)`` square root of the measurement's information
(``R^T R = Lambda``, tagloc order ``[x, y, z, rx, ry, rz]``, right tangent of ``Z``). A
registration's information is rank-deficient along a corridor (no return constrains the
direction of travel): its degenerate directions get :data:`DEGENERATE_INFORMATION`, nothing in
practice, so that the factor pulls only where the scans constrain it (:func:`sqrt_information`).
Every factor carries a robust kernel (Cauchy by default): a wrong loop closure has bounded pull.

The same factor enters both stages of the builder: a ``BetweenFactorPose3`` in the pose-factor
graph (:func:`add_relative_factors`, :mod:`tagloc.mapping.graph`) and a linearized factor in the
corner refinement (:func:`linearize_relative`, :mod:`tagloc.mapping.refine`), whose Jacobians
are those of the odometry factors (:mod:`tagloc.mapping.odometry_factors`): with
``B = x_a^-1 x_b``, ``E = Z^-1 B`` and ``J = J_r^-1(Log E)``, ``de/dxi_b = R J`` and
``de/dxi_a = -R J Ad(B^-1)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import gtsam
import numpy as np
import numpy.typing as npt

from tagloc.mapping.corner_graph import kernel_cost, kernel_weights
from tagloc.mapping.gtsam_bridge import PERM
from tagloc.mapping.initialize import inverse_h
from tagloc.mapping.odometry_factors import _se3, adjoint, log_batch

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
Kernel = Literal["huber", "cauchy"]

#: Information given to a direction the registration does not constrain (1 / m^2 or 1 / rad^2:
#: a standard deviation of 10 km / 10 krad), so that the square root stays invertible.
DEGENERATE_INFORMATION = 1e-8


@dataclass(frozen=True, slots=True, eq=False)
class RelativePoseFactors:
    """``n`` measured relative poses between keyframes (structure of arrays).

    Attributes
    ----------
    a, b : (n,) int64
        Keyframe indices (``a`` the reference, ``b`` the one measured in it).
    M_a_b : (n, 4, 4) float
        Measured ``T_base_a_base_b``.
    sqrt_information : (n, 6, 6) float
        ``R`` with ``R^T R`` the information of ``Log(Z^-1 x_a^-1 x_b)``, tagloc order.
    loop : (n,) bool
        A loop closure (keyframes far apart in time) rather than consecutive keyframes.
    kernel : {"huber", "cauchy"}
    robust_k : float
        Kernel width, whitened units (sigmas).
    """

    a: IntArray
    b: IntArray
    M_a_b: FloatArray
    sqrt_information: FloatArray
    loop: BoolArray
    kernel: Kernel = "cauchy"
    robust_k: float = 3.0

    def __len__(self) -> int:
        return len(self.a)

    @classmethod
    def empty(cls, kernel: Kernel = "cauchy", robust_k: float = 3.0) -> RelativePoseFactors:
        z = np.zeros(0, dtype=np.int64)
        return cls(z, z, np.zeros((0, 4, 4)), np.zeros((0, 6, 6)), np.zeros(0, bool), kernel,
                   robust_k)  # fmt: skip

    def concat(self, other: RelativePoseFactors) -> RelativePoseFactors:
        """These factors followed by ``other``'s (kernel and width of ``self``)."""
        return RelativePoseFactors(
            np.concatenate([self.a, other.a]),
            np.concatenate([self.b, other.b]),
            np.concatenate([self.M_a_b, other.M_a_b]),
            np.concatenate([self.sqrt_information, other.sqrt_information]),
            np.concatenate([self.loop, other.loop]),
            self.kernel,
            self.robust_k,
        )


def sqrt_information(information: FloatArray) -> FloatArray:
    """``(6, 6)`` upper-triangular ``R`` with ``R^T R = information`` (PSD, maybe singular).

    Eigenvalues below :data:`DEGENERATE_INFORMATION` are raised to it (the degenerate
    directions of a registration: no information, but a well-posed square root).
    """
    sym = 0.5 * (information + information.T)
    eigenvalues, eigenvectors = np.linalg.eigh(sym)
    root = np.sqrt(np.maximum(eigenvalues, DEGENERATE_INFORMATION))[:, None] * eigenvectors.T
    return _upper(root)


def _upper(root: FloatArray) -> FloatArray:
    """Upper-triangular ``R`` with ``R^T R = root^T root`` and a positive diagonal."""
    R = np.asarray(np.linalg.qr(root, mode="r"))
    return np.asarray(np.where(np.diag(R)[:, None] < 0.0, -R, R))


def relative_errors(M_map_base: FloatArray, factors: RelativePoseFactors) -> FloatArray:
    """``(n, 6)`` whitened errors ``R Log(Z^-1 x_a^-1 x_b)`` (no kernel)."""
    B = inverse_h(M_map_base[factors.a]) @ M_map_base[factors.b]
    e = log_batch(inverse_h(factors.M_a_b) @ B)
    return np.asarray(np.einsum("nij,nj->ni", factors.sqrt_information, e))


def relative_cost(M_map_base: FloatArray, factors: RelativePoseFactors) -> float:
    """The factors' robust cost ``sum rho(|e|^2)`` (``|e|^2 / 2`` for small errors)."""
    if len(factors) == 0:
        return 0.0
    s = np.sum(relative_errors(M_map_base, factors) ** 2, axis=1)
    return float(np.sum(kernel_cost(s, factors.kernel, factors.robust_k)))


def linearize_relative(
    M_map_base: FloatArray, factors: RelativePoseFactors
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Robustly weighted errors and Jacobians at ``M_map_base`` (IRLS, module docstring).

    Returns
    -------
    e : (n, 6) float
        ``sqrt(w) R Log(E)``, with ``w`` the kernel's weight at the current error.
    A_a, A_b : (n, 6, 6) float
        ``d e / d xi`` of keyframes ``a`` and ``b`` (same weighting).
    """
    if len(factors) == 0:
        return np.zeros((0, 6)), np.zeros((0, 6, 6)), np.zeros((0, 6, 6))
    B = inverse_h(M_map_base[factors.a]) @ M_map_base[factors.b]
    E = inverse_h(factors.M_a_b) @ B
    log_E, J = _se3(E).log(jacobians=True)  # J = J_r^-1(Log E)
    R = factors.sqrt_information
    e = np.einsum("nij,nj->ni", R, log_E)
    w = kernel_weights(np.sum(e**2, axis=1), factors.kernel, factors.robust_k)
    sqrt_w = np.sqrt(w)[:, None]
    A_b = R @ J
    A_a = -(A_b @ adjoint(inverse_h(B)))
    return e * sqrt_w, A_a * sqrt_w[..., None], A_b * sqrt_w[..., None]


def add_relative_factors(
    graph: gtsam.NonlinearFactorGraph, factors: RelativePoseFactors, key: Callable[[int], int]
) -> None:
    """One ``BetweenFactorPose3(key(a), key(b), Z)`` per factor, robust, in GTSAM's order.

    ``key(k)`` names keyframe ``k``'s variable. GTSAM orders the tangent rotation first: with
    ``v_tagloc = v_gtsam[PERM]``, the square root becomes ``R[:, PERM]``.
    """
    kernel: gtsam.noiseModel.mEstimator.Base
    if factors.kernel == "huber":
        kernel = gtsam.noiseModel.mEstimator.Huber.Create(factors.robust_k)
    else:
        kernel = gtsam.noiseModel.mEstimator.Cauchy.Create(factors.robust_k)
    for a, b, M, R in zip(factors.a, factors.b, factors.M_a_b, factors.sqrt_information,
                          strict=True):  # fmt: skip
        R_gtsam = _upper(R[:, PERM])
        model = gtsam.noiseModel.Robust.Create(
            kernel, gtsam.noiseModel.Gaussian.SqrtInformation(np.ascontiguousarray(R_gtsam))
        )
        Z = gtsam.Pose3(gtsam.Rot3(M[:3, :3]), M[:3, 3])
        graph.add(gtsam.BetweenFactorPose3(key(int(a)), key(int(b)), Z, model))


def scan_scale(M_map_base: FloatArray, factors: RelativePoseFactors) -> tuple[float, float]:
    """The scale of the consecutive registrations against the trajectory ``M_map_base``:
    ``(s, sigma)`` with ``(1 + s)`` the least-squares factor from the trajectory's relative
    translations to the registrations' (``s`` > 0: the scans measure the steps longer than the
    map has them), over the non-loop factors, and its standard error. ``(nan, nan)`` with fewer
    than two factors.

    A registration chain that over- or underestimates each step (the ring sampling of one sweep
    against another) shows here as ``s``: the builder reports it (the map's scale is that of the
    tags and the calibrated odometry; this says whether the scans agree).
    """
    keep = ~factors.loop
    if keep.sum() < 2:
        return float("nan"), float("nan")
    B = inverse_h(M_map_base[factors.a[keep]]) @ M_map_base[factors.b[keep]]
    t_map, t_scan = B[:, :3, 3], factors.M_a_b[keep, :3, 3]
    norm2 = float(np.sum(t_map * t_map))
    if norm2 <= 0.0:
        return float("nan"), float("nan")
    factor = float(np.sum(t_scan * t_map)) / norm2
    residual = t_scan - factor * t_map
    n = int(keep.sum())
    sigma = float(np.sqrt(np.sum(residual**2) / max(3 * n - 1, 1) / norm2))
    return factor - 1.0, sigma
