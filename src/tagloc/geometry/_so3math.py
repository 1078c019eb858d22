"""Vectorized SO(3) kernels on raw arrays: hat, Exp, the scalar coefficients, right Jacobians.

Every function takes arrays with any leading batch shape ``...`` and works without Python loops;
a rotation vector ``phi`` is ``(..., 3)`` and a matrix ``(..., 3, 3)`` throughout.
Nothing here validates its input: the public types do that once, at the boundary.

Formulas: J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state estimation in robotics"
(2018, arXiv:1812.01537), App. B (SO(3): Exp, Log, right Jacobian and its inverse); T. Barfoot,
"State Estimation for Robotics" (2017), Sec. 7.1. The Log and the quaternion conversions are in
:mod:`tagloc.geometry._quatmath`.
"""

from __future__ import annotations

import math

import numpy as np

from tagloc._types import FloatArray
from tagloc.errors import GeometryError

EYE3 = np.eye(3)
EYE3.flags.writeable = False

#: Below this angle the coefficients that cancel catastrophically use their Taylor series (kept
#: long enough that the truncation error at the switch is below 1e-17).
SERIES_ANGLE = 1.0

#: ``(t - sin t) / t^3 = sum_k (-1)^k t^(2k) / (2k + 3)!``
SIN3_SERIES = tuple((-1) ** k / math.factorial(2 * k + 3) for k in range(9))
#: ``|B_2n|``, n = 1..11 (Bernoulli numbers).
_BERNOULLI = (
    1 / 6, 1 / 30, 1 / 42, 1 / 30, 5 / 66, 691 / 2730, 7 / 6, 3617 / 510, 43867 / 798,
    174611 / 330, 854513 / 138,
)  # fmt: skip
#: ``(1 - (t/2) cot(t/2)) / t^2 = sum_n |B_2n| t^(2n - 2) / (2n)!``
COT_SERIES = tuple(b / math.factorial(2 * n + 2) for n, b in enumerate(_BERNOULLI))


def even_series(t2: FloatArray, coefficients: tuple[float, ...]) -> FloatArray:
    """``sum_k coefficients[k] t2^k`` by Horner's rule."""
    out = np.full_like(t2, coefficients[-1])
    for c in coefficients[-2::-1]:
        out = out * t2 + c
    return out


def hat(phi: FloatArray) -> FloatArray:
    """Skew-symmetric matrix ``[phi]x`` with ``[phi]x v = phi x v``, ``(..., 3, 3)``."""
    out = np.zeros((*phi.shape[:-1], 3, 3))
    x, y, z = phi[..., 0], phi[..., 1], phi[..., 2]
    out[..., 0, 1] = -z
    out[..., 0, 2] = y
    out[..., 1, 0] = z
    out[..., 1, 2] = -x
    out[..., 2, 0] = -y
    out[..., 2, 1] = x
    return out


def vee(matrix: FloatArray) -> FloatArray:
    """Inverse of :func:`hat`: ``(..., 3, 3)`` skew part -> ``(..., 3)``."""
    return 0.5 * np.stack(
        [
            matrix[..., 2, 1] - matrix[..., 1, 2],
            matrix[..., 0, 2] - matrix[..., 2, 0],
            matrix[..., 1, 0] - matrix[..., 0, 1],
        ],
        axis=-1,
    )


def angle(phi: FloatArray) -> FloatArray:
    """``|phi|`` over the last axis: ``(..., 3) -> (...)``."""
    out: FloatArray = np.sqrt(np.einsum("...i,...i->...", phi, phi))
    return out


def coeff_sin(theta: FloatArray) -> FloatArray:
    """``sin(theta) / theta`` (exact at 0)."""
    return np.asarray(np.sinc(theta / np.pi), dtype=np.float64)


def coeff_cos(theta: FloatArray) -> FloatArray:
    """``(1 - cos(theta)) / theta^2``, as ``2 sin^2(theta/2) / theta^2`` (no cancellation)."""
    half = np.sinc(theta / (2.0 * np.pi))
    return 0.5 * half * half


def coeff_sin3(theta: FloatArray, sin_theta: FloatArray | None = None) -> FloatArray:
    """``(theta - sin(theta)) / theta^3``; series ``1/6 - t^2/120 + ...`` below 1 rad.

    ``sin_theta`` may be passed when the caller already has it.
    """
    theta = np.asarray(theta, dtype=np.float64)
    out = np.array(even_series(theta * theta, SIN3_SERIES), dtype=np.float64)
    large = np.abs(theta) >= SERIES_ANGLE
    if large.any():
        t = theta[large]
        s = np.sin(t) if sin_theta is None else sin_theta[large]
        out[large] = (t - s) / (t * t * t)
    return out


def coeff_cot(theta: FloatArray) -> FloatArray:
    """``(1 - (theta/2) cot(theta/2)) / theta^2``, the ``[phi]x^2`` factor of ``Jr^{-1}``.

    Equal to ``1/theta^2 - (1 + cos theta) / (2 theta sin theta)`` (Sola et al. 2018, App. B)
    but finite at ``theta = pi``; series ``1/12 + t^2/720 + t^4/30240 + ...`` below 1 rad.
    """
    theta = np.asarray(theta, dtype=np.float64)
    small = np.abs(theta) < SERIES_ANGLE
    safe = np.where(small, 1.0, theta)
    series = even_series(theta * theta, COT_SERIES)
    half = 0.5 * safe
    return np.where(small, series, (1.0 - half * np.cos(half) / np.sin(half)) / (safe * safe))


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a x b`` over the last axis for ``(..., 3)`` arrays (broadcast), elementwise."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def exp_coefficients(phi: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``theta``, ``sin t / t``, ``(1 - cos t) / t^2`` and ``(t - sin t) / t^3`` of ``(..., 3)``.

    ``(1 - cos t) / t^2`` is evaluated as ``2 (sin(t/2) / t)^2`` (no cancellation).
    """
    theta = angle(phi)
    nonzero = theta > 0.0
    safe = np.where(nonzero, theta, 1.0)
    s = np.sin(safe)
    h = np.sin(0.5 * safe) / safe
    a = np.where(nonzero, s / safe, 1.0)
    b = np.where(nonzero, 2.0 * h * h, 0.5)
    return theta, a, b, coeff_sin3(theta, s)


def exp_matrix(phi: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """``I + a [phi]x + b [phi]x^2`` built entry by entry (``[phi]x^2 = phi phi^T - |phi|^2 I``).

    Parameters
    ----------
    phi : (..., 3) float
    a, b : (...) float

    Returns
    -------
    (..., 3, 3) float
    """
    x, y, z = phi[..., 0], phi[..., 1], phi[..., 2]
    bx, by, bz = b * x, b * y, b * z
    ax, ay, az = a * x, a * y, a * z
    bxy, bxz, byz = bx * y, bx * z, by * z
    bxx, byy, bzz = bx * x, by * y, bz * z
    out = np.empty((*phi.shape[:-1], 3, 3))
    out[..., 0, 0] = 1.0 - byy - bzz
    out[..., 0, 1] = bxy - az
    out[..., 0, 2] = bxz + ay
    out[..., 1, 0] = bxy + az
    out[..., 1, 1] = 1.0 - bxx - bzz
    out[..., 1, 2] = byz - ax
    out[..., 2, 0] = bxz - ay
    out[..., 2, 1] = byz + ax
    out[..., 2, 2] = 1.0 - bxx - byy
    return out


def exp(phi: FloatArray) -> FloatArray:
    """Rodrigues' formula ``Exp(phi) = I + A [phi]x + B [phi]x^2`` (Sola et al. 2018, App. B).

    Parameters
    ----------
    phi : (..., 3) float
        Rotation vectors (axis times angle, radians).

    Returns
    -------
    (..., 3, 3) float
        Rotation matrices.
    """
    _, a, b, _ = exp_coefficients(phi)
    return exp_matrix(phi, a, b)


def right_jacobian(phi: FloatArray) -> FloatArray:
    """``Jr(phi) = I - (1 - cos t)/t^2 [phi]x + (t - sin t)/t^3 [phi]x^2`` (Sola App. B)."""
    theta = angle(phi)
    skew = hat(phi)
    b = coeff_cos(theta)[..., None, None]
    c = coeff_sin3(theta)[..., None, None]
    return EYE3 - b * skew + c * (skew @ skew)


def right_jacobian_inv(phi: FloatArray) -> FloatArray:
    """``Jr^{-1}(phi) = I + [phi]x / 2 + (1/t^2 - (1 + cos t)/(2 t sin t)) [phi]x^2`` (Sola App. B).

    Parameters
    ----------
    phi : (..., 3) float
        Norm below ``2 pi`` (``Jr`` is singular at ``2 pi``).

    Returns
    -------
    (..., 3, 3) float
    """
    theta = angle(phi)
    skew = hat(phi)
    d = coeff_cot(theta)[..., None, None]
    return EYE3 + 0.5 * skew + d * (skew @ skew)


def rotate(matrix: FloatArray, points: FloatArray) -> FloatArray:
    """Rotate ``points`` by one rotation or a batch (see :meth:`SO3.act` for the shapes).

    Works for any dimension ``d`` (``matrix`` is ``(d, d)`` or ``(N, d, d)``).
    """
    if matrix.ndim == 2:
        return matrix @ points if points.ndim == 1 else points @ matrix.T
    n, d = matrix.shape[0], matrix.shape[-1]
    if points.ndim == 1:
        return matrix @ points
    if points.ndim == 2 and points.shape[0] == n:
        out: FloatArray = np.einsum("nij,nj->ni", matrix, points)  # 2x faster than matmul here
        return out
    if points.ndim == 3 and points.shape[0] == n:
        return points @ np.swapaxes(matrix, -1, -2)
    raise GeometryError(
        f"a batch of {n} poses acts on points of shape ({d},), ({n}, {d}) or ({n}, M, {d}); "
        f"got {points.shape}"
    )


def transform(matrix: FloatArray, translation: FloatArray, points: FloatArray) -> FloatArray:
    """``R p + t`` for one rigid transform or a batch (shapes as :func:`rotate`; ``translation``
    is ``(d,)`` or ``(N, d)``)."""
    out = rotate(matrix, points)
    out += translation[:, None, :] if (translation.ndim == 2 and out.ndim == 3) else translation
    return out


def rotation_for(matrix: FloatArray, out_ndim: int) -> FloatArray:
    """``matrix`` reshaped to broadcast against per-point ``(..., 3, 3)`` Jacobians."""
    if matrix.ndim == 3 and out_ndim == 3:
        return matrix[:, None]
    return matrix


def project_to_so3(matrix: FloatArray) -> FloatArray:
    """Nearest rotation(s) in the Frobenius norm: ``U diag(1, 1, det(U V^T)) V^T``.

    Parameters
    ----------
    matrix : (..., 3, 3) float

    Returns
    -------
    (..., 3, 3) float
    """
    u, _, vt = np.linalg.svd(matrix)
    det = np.asarray(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, 2] *= det[..., None]
    out: FloatArray = u @ vt
    return out
