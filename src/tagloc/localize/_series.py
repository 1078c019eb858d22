"""Right Jacobians of SE(3) and SE(2) for the filter's small steps: ``Jr`` and ``Jr^-1`` as
their series in the small adjoint ``ad`` when the tangent vector is small (the closed forms of
:mod:`tagloc.geometry` otherwise). Tangent order ``[x, y, z, rx, ry, rz]`` / ``[x, y, theta]``."""

from __future__ import annotations

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import (
    se2_right_jacobian,
    se2_right_jacobian_inv,
    se3_right_jacobian,
    se3_right_jacobian_inv,
)

__all__ = ["jr", "jr_inv"]

_SERIES_BELOW = 0.3  # sum |tau_i| under which Jr, Jr^-1 use their series (error < 1e-6)


def _ad(tau: FloatArray) -> FloatArray:
    """Small adjoint ``ad(tau)`` of se(3) ``[rho, phi]`` (se(2): :func:`_se2_series`)."""
    a, b, c, d, e, f = tau.tolist()  # [[phi^, rho^], [0, phi^]]
    return np.array([
        [0.0, -f, e, 0.0, -c, b], [f, 0.0, -d, c, 0.0, -a], [-e, d, 0.0, -b, a, 0.0],
        [0.0, 0.0, 0.0, 0.0, -f, e], [0.0, 0.0, 0.0, f, 0.0, -d], [0.0, 0.0, 0.0, -e, d, 0.0],
    ])  # fmt: skip


def _se2_series(tau: FloatArray, c1: float, c2: float, c3: float, c4: float) -> FloatArray:
    """``I + c1 ad + c2 ad^2 + c3 ad^3 + c4 ad^4`` for se(2) ``[x, y, theta]`` on plain floats:
    ``ad^2 = [[-t^2, 0, t x], [0, -t^2, t y], 0]``, ``ad^3 = -t^2 ad``, ``ad^4 = -t^2 ad^2``."""
    x, y, t = tau.tolist()
    t2 = t * t
    a = c1 - c3 * t2  # coefficient of ad (ad^3 folded in)
    b = c2 - c4 * t2  # coefficient of ad^2 (ad^4 folded in)
    return np.array([
        [1.0 - b * t2, -a * t, a * y + b * t * x],
        [a * t, 1.0 - b * t2, -a * x + b * t * y],
        [0.0, 0.0, 1.0],
    ])  # fmt: skip


def jr(tau: FloatArray) -> FloatArray:
    """Right Jacobian ``Jr(tau) = sum_k (-ad)^k / (k+1)!`` (series to ``ad^4`` when small)."""
    if float(np.abs(tau).sum()) < _SERIES_BELOW:
        if len(tau) == 3:
            return _se2_series(tau, -0.5, 1.0 / 6.0, -1.0 / 24.0, 1.0 / 120.0)
        a = _ad(tau)
        a2 = a @ a
        return np.eye(len(tau)) - 0.5 * a + a2 / 6.0 - a2 @ a / 24.0 + a2 @ a2 / 120.0
    return se2_right_jacobian(tau) if len(tau) == 3 else se3_right_jacobian(tau)


def jr_inv(tau: FloatArray) -> FloatArray:
    """``Jr^-1(tau) = I + ad/2 + ad^2/12 - ad^4/720 + ...`` (Bernoulli numbers; series when
    small)."""
    if float(np.abs(tau).sum()) < _SERIES_BELOW:
        if len(tau) == 3:
            return _se2_series(tau, 0.5, 1.0 / 12.0, 0.0, -1.0 / 720.0)
        a = _ad(tau)
        a2 = a @ a
        return np.eye(len(tau)) + 0.5 * a + a2 / 12.0 - a2 @ a2 / 720.0
    return se2_right_jacobian_inv(tau) if len(tau) == 3 else se3_right_jacobian_inv(tau)
