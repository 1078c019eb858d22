"""Odometry and anchor factors linearized in numpy, with the odometry calibration as a variable.

For the corner refinement (:mod:`tagloc.mapping.refine`), every factor is linearized here and
handed to GTSAM's sparse linear solver. The odometry factor between keyframes ``k-1`` and ``k``
is

.. math:: e_k = \\mathrm{Log}\\left(Z_k(c)^{-1}\\, x_{k-1}^{-1} x_k\\right) / \\sigma_k

with ``Z_k(c)`` the raw odometry step corrected by the calibration vector ``c``
(:func:`~tagloc.mapping.calibration.corrected_steps`: distance scale and crab drift, turn scale,
yaw bias per metre) and the division by ``sigma_k`` the whitening of
:func:`tagloc.mapping.odometry_noise.odometry_whitening` (the random-walk noise, level with
gravity). Right perturbations ``x Exp(xi)``,
``xi = [x, y, z, rx, ry, rz]``; with ``B = x_{k-1}^-1 x_k``, ``E = Z^-1 B`` and
``J = J_r^-1(Log E)`` (Sola et al. 2018, Sec. IV-B):

- ``d e / d xi_k = J``; ``d e / d xi_{k-1} = -J Ad(B^-1)``;
- ``d e / d c = -J Ad(E^-1) D`` with ``D`` the right-tangent derivative of ``Z`` in ``c``
  (analytic: :func:`~tagloc.mapping.calibration.corrected_step_jacobians`).

Estimating ``c`` jointly with the map, instead of alternating fit and optimization, removes the
systematic part of legged odometry drift that alternation leaves behind (it converges slowly
because trajectory and calibration are strongly coupled).
"""

from __future__ import annotations

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import adjoint_h, inverse_h, log_h
from tagloc.geometry.matrices import as_se3
from tagloc.mapping.calibration import (
    N_CALIBRATION,
    calibration_from_vector,
    corrected_step_jacobians,
    corrected_steps,
)
from tagloc.mapping.whitening import AxisWhitening

#: The names modules that have not moved to :mod:`tagloc.geometry.matrices` still import here.
adjoint, log_batch, _se3 = adjoint_h, log_h, as_se3


def odometry_residuals(
    M_map_base: FloatArray, step_raw: FloatArray, c: FloatArray, noise: AxisWhitening
) -> FloatArray:
    """``(K-1, 6)`` whitened odometry errors ``e_k`` (module docstring)."""
    Z = corrected_steps(step_raw, calibration_from_vector(c))
    B = inverse_h(M_map_base[:-1]) @ M_map_base[1:]
    return noise.whiten(log_h(inverse_h(Z) @ B))


def linearize_odometry(
    M_map_base: FloatArray,
    step_raw: FloatArray,
    c: FloatArray,
    noise: AxisWhitening,
    calibrate: bool,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray | None]:
    """Whitened errors and Jacobians of the odometry factors at the given state.

    Parameters
    ----------
    M_map_base : (K, 4, 4) float
    step_raw : (K-1, 4, 4) float
        Raw odometry steps ``T_odom_base_{k-1}^-1 T_odom_base_k``.
    c : (4,) float
        Calibration vector (:func:`~tagloc.mapping.calibration.calibration_vector`).
    noise : AxisWhitening
        The steps' noise (:func:`tagloc.mapping.odometry_noise.odometry_whitening`).
    calibrate : bool
        Also return the Jacobian in ``c``.

    Returns
    -------
    e : (K-1, 6) float
    A_prev, A_next : (K-1, 6, 6) float
        ``d e / d xi`` of keyframes ``k-1`` and ``k``.
    A_c : (K-1, 6, 4) float or None
    """
    if len(step_raw) == 0:  # a single keyframe
        empty = np.zeros((0, 6, 6))
        return (
            np.zeros((0, 6)),
            empty,
            empty,
            (np.zeros((0, 6, N_CALIBRATION)) if calibrate else None),
        )
    Z = corrected_steps(step_raw, calibration_from_vector(c))
    B = inverse_h(M_map_base[:-1]) @ M_map_base[1:]
    E = inverse_h(Z) @ B
    e, J_e_E = as_se3(E).log(jacobians=True)  # J_r^-1(e)
    A_next = noise.whiten_jacobian(J_e_E)
    A_prev = -noise.whiten_jacobian(J_e_E @ adjoint_h(inverse_h(B)))
    if not calibrate:
        return noise.whiten(e), A_prev, A_next, None
    D = corrected_step_jacobians(step_raw, Z)
    A_c = -noise.whiten_jacobian(J_e_E @ adjoint_h(inverse_h(E)) @ D)
    return noise.whiten(e), A_prev, A_next, A_c


def prior_residuals(M: FloatArray, M_prior: FloatArray, noise: AxisWhitening) -> FloatArray:
    """``(n, 6)`` whitened ``Log(M_prior^-1 M)`` of pose priors (Jacobian: the whitening of the
    identity)."""
    return noise.whiten(log_h(inverse_h(M_prior) @ M))
