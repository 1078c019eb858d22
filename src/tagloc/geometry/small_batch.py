"""``minus`` and ``plus`` of small :class:`~tagloc.geometry.SE3` batches with less overhead.

Also :func:`row_norms`, ``np.linalg.norm(v, axis=-1)`` without the wrapper's cost.

For the few poses a solver handles per call (the branches of a frame's tags), numpy's per-call
overhead, not arithmetic, is the cost of :meth:`SE3.minus` and :meth:`SE3.plus`: the Taylor
series of the Exp / Log coefficients alone are ~20 array operations each. These functions run
*the same floating-point operations in the same order*, so their results are bit-identical to
the methods' (tested bit for bit), but evaluate the series by Horner's rule on plain floats for
small batches (IEEE ``*`` and ``+`` round the same in Python and numpy) and skip the closed
forms the series guard when no angle needs them.

Formulas, orders and conventions are those of :mod:`tagloc.geometry.se3` (Sola et al. 2018).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import _quatmath as quatm
from tagloc.geometry import _scalar
from tagloc.geometry import _so3math as so3m
from tagloc.geometry.se3 import SE3, _matvec

#: Batches up to this size evaluate the series on plain floats.
_SCALAR_SERIES_MAX = 32


def se3_minus(T: SE3, other: SE3) -> FloatArray:
    """``T.minus(other) = Log(other^-1 @ T)`` for batches of ``N`` (bit-identical).

    Parameters
    ----------
    T, other : SE3, batches of N

    Returns
    -------
    (N, 6) float
        ``[rho, phi]`` in ``[x, y, z, rx, ry, rz]`` order.
    """
    r_inv = np.swapaxes(other.rotation.matrix, -1, -2).copy()
    t_inv = -_matvec(r_inv, other.translation)
    matrix = r_inv @ T.rotation.matrix
    t = _matvec(r_inv, T.translation) + t_inv
    phi = quatm.log(matrix)
    d = _coeff_cot(so3m.angle(phi))
    w = so3m.cross(phi, t)
    rho = t - 0.5 * w + d[..., None] * so3m.cross(phi, w)
    return np.concatenate([rho, phi], axis=-1)


def se3_plus(T: SE3, tau: npt.ArrayLike) -> SE3:
    """``T.plus(tau) = T @ Exp(tau)`` for a batch of ``N`` and finite ``tau`` (N, 6)
    (bit-identical; ``tau`` is not validated)."""
    array = np.asarray(tau, dtype=np.float64)
    rho, phi = array[..., :3], array[..., 3:]
    a, b, c = _exp_coefficients(phi)
    w = so3m.cross(phi, rho)
    t = rho + b[..., None] * w + c[..., None] * so3m.cross(phi, w)
    r1 = T.rotation.matrix
    return SE3.from_trusted(r1 @ so3m.exp_matrix(phi, a, b), _matvec(r1, t) + T.translation)


def row_norms(v: npt.ArrayLike) -> FloatArray:
    """``np.linalg.norm(v, axis=-1)``: the same products, sum and root, without its overhead."""
    array = np.asarray(v, dtype=np.float64)
    return np.asarray(np.sqrt((array * array).sum(axis=-1)))


def _series(t2: FloatArray, coefficients: tuple[float, ...]) -> FloatArray:
    """:func:`so3m.even_series` (Horner's rule), on plain floats for small batches."""
    if t2.size > _SCALAR_SERIES_MAX:
        return so3m.even_series(t2, coefficients)
    values = [_scalar.even_series(x, coefficients) for x in t2.ravel().tolist()]
    return np.array(values, dtype=np.float64).reshape(t2.shape)


def _coeff_cot(theta: FloatArray) -> FloatArray:
    """:func:`so3m.coeff_cot`; the series alone when every angle is below the switch."""
    if np.abs(theta).max(initial=0.0) < so3m.SERIES_ANGLE:
        return _series(theta * theta, so3m.COT_SERIES)
    return so3m.coeff_cot(theta)


def _exp_coefficients(phi: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``sin t / t``, ``(1 - cos t) / t^2``, ``(t - sin t) / t^3`` as
    :func:`so3m.exp_coefficients` computes them."""
    theta = so3m.angle(phi)
    if not (theta > 0.0).all():
        _, a, b, c = so3m.exp_coefficients(phi)
        return a, b, c
    s = np.sin(theta)
    h = np.sin(0.5 * theta) / theta
    c = _series(theta * theta, so3m.SIN3_SERIES)
    large = np.abs(theta) >= so3m.SERIES_ANGLE
    if large.any():
        t = theta[large]
        c[large] = (t - s[large]) / (t * t * t)
    return s / theta, 2.0 * h * h, c
