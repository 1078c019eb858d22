"""Right Jacobians of ``Exp`` (and their inverses) for SO(3), SE(3) and SE(2), on raw arrays.

``Jr(tau)`` maps a small tangent increment ``d`` at ``tau`` to the right increment of the group
element: ``Exp(tau + d) = Exp(tau) @ Exp(Jr(tau) d) + o(|d|)``; ``Jr^-1(tau)`` is the derivative of
``Log`` with the same convention, and the left Jacobian is ``Jl(tau) = Jr(-tau)``.

Tangent orders: SO(3) ``[rx, ry, rz]``; SE(3) ``[x, y, z, rx, ry, rz]`` (translation first, so the
blocks are the transpose-arranged version of GTSAM's); SE(2) ``[x, y, theta]``. All functions take
a single vector or a batch ``(N, dof)`` and return ``(dof, dof)`` or ``(N, dof, dof)``.

References: J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state estimation in robotics"
(2018, arXiv:1812.01537), App. B (SO(3)), C (SE(2)) and D (SE(3)); T. Barfoot, "State Estimation
for Robotics" (2017), Sec. 7.1.5 (the ``Q`` block of the SE(3) Jacobian).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import _so3math as so3m
from tagloc.geometry._checks import to_float_array

#: ``(t^2 + 2 cos t - 2) / (2 t^4) = sum_k (-1)^k t^(2k) / (2k + 4)!``
A2_SERIES = tuple((-1) ** k / math.factorial(2 * k + 4) for k in range(9))
#: ``(2 t - 3 sin t + t cos t) / (2 t^5) = sum_k (-1)^k (k + 1) t^(2k) / (2k + 5)!``
A3_SERIES = tuple((-1) ** k * (k + 1) / math.factorial(2 * k + 5) for k in range(9))


def _as_tangent(tau: npt.ArrayLike, dof: int) -> FloatArray:
    from tagloc.errors import GeometryError

    array = to_float_array(tau, "tangent vector")
    if array.ndim not in (1, 2) or array.shape[-1] != dof:
        raise GeometryError(
            f"tangent vector must have shape ({dof},) or (N, {dof}), got {array.shape}"
        )
    return array


def so3_right_jacobian(phi: npt.ArrayLike) -> FloatArray:
    """SO(3) ``Jr(phi) = I - (1 - cos t)/t^2 [phi]x + (t - sin t)/t^3 [phi]x^2``, ``t = |phi|``.

    Parameters
    ----------
    phi : (3,) or (N, 3) float

    Returns
    -------
    (3, 3) or (N, 3, 3) float
    """
    return so3m.right_jacobian(_as_tangent(phi, 3))


def so3_right_jacobian_inv(phi: npt.ArrayLike) -> FloatArray:
    """SO(3) ``Jr^-1(phi) = I + [phi]x/2 + (1/t^2 - (1 + cos t)/(2 t sin t)) [phi]x^2``.

    Parameters
    ----------
    phi : (3,) or (N, 3) float, ``|phi| < 2 pi``

    Returns
    -------
    (3, 3) or (N, 3, 3) float
    """
    return so3m.right_jacobian_inv(_as_tangent(phi, 3))


def _q_coefficients(theta: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The three scalar factors of Barfoot's ``Q(rho, phi)``, with Taylor series below 1 rad.

    ``a1 = (t - sin t)/t^3``, ``a2 = (t^2 + 2 cos t - 2)/(2 t^4)``,
    ``a3 = (2 t - 3 sin t + t cos t)/(2 t^5)``.
    """
    small = theta < so3m.SERIES_ANGLE
    t = np.where(small, 1.0, theta)
    s, c = np.sin(t), np.cos(t)
    a1 = so3m.coeff_sin3(theta)
    series2 = so3m.even_series(theta * theta, A2_SERIES)
    series3 = so3m.even_series(theta * theta, A3_SERIES)
    a2 = np.where(small, series2, (t * t + 2.0 * c - 2.0) / (2.0 * t**4))
    a3 = np.where(small, series3, (2.0 * t - 3.0 * s + t * c) / (2.0 * t**5))
    return a1, a2, a3


def se3_q_matrix(rho: FloatArray, phi: FloatArray) -> FloatArray:
    """Barfoot's ``Q(rho, phi)``: the off-diagonal block of the SE(3) left Jacobian.

    ``Q = 1/2 P + a1 (K P + P K + K P K) + a2 (K K P + P K K - 3 K P K)
    + a3 (K P K K + K K P K)`` with ``P = [rho]x``, ``K = [phi]x`` (Barfoot eq. 7.86; Sola
    App. D writes the same with ``a2``, ``a3`` of the opposite sign convention).

    Parameters
    ----------
    rho, phi : (..., 3) float

    Returns
    -------
    (..., 3, 3) float
    """
    a1, a2, a3 = (a[..., None, None] for a in _q_coefficients(so3m.angle(phi)))
    P, K = so3m.hat(rho), so3m.hat(phi)
    KP, PK = K @ P, P @ K
    KPK = KP @ K
    KKP = K @ KP
    PKK = PK @ K
    return 0.5 * P + a1 * (KP + PK + KPK) + a2 * (KKP + PKK - 3.0 * KPK) + a3 * (KPK @ K + K @ KPK)


def se3_right_jacobian(xi: npt.ArrayLike) -> FloatArray:
    """SE(3) ``Jr(xi) = [[Jr(phi), Q(-rho, -phi)], [0, Jr(phi)]]`` for ``xi = [rho, phi]``.

    Parameters
    ----------
    xi : (6,) or (N, 6) float, order ``[x, y, z, rx, ry, rz]``

    Returns
    -------
    (6, 6) or (N, 6, 6) float
    """
    array = _as_tangent(xi, 6)
    rho, phi = array[..., :3], array[..., 3:]
    jr = so3m.right_jacobian(phi)
    out = np.zeros((*array.shape[:-1], 6, 6))
    out[..., :3, :3] = jr
    out[..., 3:, 3:] = jr
    out[..., :3, 3:] = se3_q_matrix(-rho, -phi)
    return out


def se3_right_jacobian_inv(xi: npt.ArrayLike) -> FloatArray:
    """SE(3) ``Jr^-1(xi) = [[Jr^-1, -Jr^-1 Q(-rho, -phi) Jr^-1], [0, Jr^-1]]``.

    Parameters
    ----------
    xi : (6,) or (N, 6) float, order ``[x, y, z, rx, ry, rz]``, ``|phi| < 2 pi``

    Returns
    -------
    (6, 6) or (N, 6, 6) float
    """
    array = _as_tangent(xi, 6)
    rho, phi = array[..., :3], array[..., 3:]
    jr_inv = so3m.right_jacobian_inv(phi)
    out = np.zeros((*array.shape[:-1], 6, 6))
    out[..., :3, :3] = jr_inv
    out[..., 3:, 3:] = jr_inv
    out[..., :3, 3:] = -(jr_inv @ se3_q_matrix(-rho, -phi) @ jr_inv)
    return out


def se2_coefficients(theta: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``sin t / t``, ``(1 - cos t) / t`` and ``(t - sin t) / t^2`` (exact near 0).

    ``d = (t - sin t) / t^2``, ``kc = (1 - cos t) / t^2`` give the third column of ``Jr``.
    """
    return so3m.coeff_sin(theta), theta * so3m.coeff_cos(theta), theta * so3m.coeff_sin3(theta)


def se2_right_jacobian(tau: npt.ArrayLike) -> FloatArray:
    """SE(2) right Jacobian for ``tau = [x, y, theta]`` (Sola et al. 2018, App. C).

    ``Jr = [[s, c, (x (t - sin t) - y (1 - cos t)) / t^2], [-c, s, (x (1 - cos t) + y (t -
    sin t)) / t^2], [0, 0, 1]]`` with ``s = sin t / t``, ``c = (1 - cos t) / t``.

    Parameters
    ----------
    tau : (3,) or (N, 3) float

    Returns
    -------
    (3, 3) or (N, 3, 3) float
    """
    array = _as_tangent(tau, 3)
    x, y, theta = array[..., 0], array[..., 1], array[..., 2]
    s, c, d = se2_coefficients(theta)
    kc = so3m.coeff_cos(theta)
    out = np.zeros((*array.shape[:-1], 3, 3))
    out[..., 0, 0] = s
    out[..., 0, 1] = c
    out[..., 1, 0] = -c
    out[..., 1, 1] = s
    out[..., 0, 2] = x * d - y * kc
    out[..., 1, 2] = x * kc + y * d
    out[..., 2, 2] = 1.0
    return out


def se2_right_jacobian_inv(tau: npt.ArrayLike) -> FloatArray:
    """Inverse of :func:`se2_right_jacobian` in closed form: ``[[A^-1, -A^-1 b], [0, 1]]``.

    Parameters
    ----------
    tau : (3,) or (N, 3) float, ``|theta| < 2 pi``

    Returns
    -------
    (3, 3) or (N, 3, 3) float
    """
    jr = se2_right_jacobian(tau)
    a = jr[..., :2, :2]
    det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    a_inv = np.empty_like(a)
    a_inv[..., 0, 0] = a[..., 1, 1]
    a_inv[..., 1, 1] = a[..., 0, 0]
    a_inv[..., 0, 1] = -a[..., 0, 1]
    a_inv[..., 1, 0] = -a[..., 1, 0]
    a_inv /= det[..., None, None]
    out = np.zeros_like(jr)
    out[..., :2, :2] = a_inv
    out[..., :2, 2] = -(a_inv @ jr[..., :2, 2:3])[..., 0]
    out[..., 2, 2] = 1.0
    return out
