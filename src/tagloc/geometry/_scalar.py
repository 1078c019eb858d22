"""Single-element fast paths of the SO(3)/SE(3) kernels, in plain Python floats.

numpy's per-call overhead (~0.5-1 us) dominates the small fixed-size work of one Exp or Log; the
same formulas as :mod:`tagloc.geometry._so3math` written on floats run several times faster for a
single element. The batch tests compare every batched result against these paths, so the two
implementations check each other.
"""

from __future__ import annotations

import math

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry._so3math import COT_SERIES, SERIES_ANGLE, SIN3_SERIES

Vec3 = tuple[float, float, float]


def even_series(t2: float, coefficients: tuple[float, ...]) -> float:
    """:func:`tagloc.geometry._so3math.even_series` (Horner's rule) on one float."""
    out = coefficients[-1]
    for c in coefficients[-2::-1]:
        out = out * t2 + c
    return out


def exp_coefficients(t2: float) -> tuple[float, float, float]:
    """``sin t / t``, ``(1 - cos t) / t^2``, ``(t - sin t) / t^3`` from ``t2 = t^2``."""
    if t2 == 0.0:
        return 1.0, 0.5, 1.0 / 6.0
    t = math.sqrt(t2)
    s = math.sin(t)
    h = math.sin(0.5 * t) / t
    c3 = even_series(t2, SIN3_SERIES) if t < SERIES_ANGLE else (t - s) / (t2 * t)
    return s / t, 2.0 * h * h, c3


def coeff_cot(t2: float) -> float:
    """``(1 - (t/2) cot(t/2)) / t^2`` from ``t2 = t^2``."""
    if t2 < SERIES_ANGLE * SERIES_ANGLE:
        return even_series(t2, COT_SERIES)
    half = 0.5 * math.sqrt(t2)
    return (1.0 - half * math.cos(half) / math.sin(half)) / t2


def _cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _rotation(x: float, y: float, z: float, a: float, b: float) -> FloatArray:
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    bxx, byy, bzz = b * x * x, b * y * y, b * z * z
    return np.array(
        [
            [1.0 - byy - bzz, bxy - a * z, bxz + a * y],
            [bxy + a * z, 1.0 - bxx - bzz, byz - a * x],
            [bxz - a * y, byz + a * x, 1.0 - bxx - byy],
        ]
    )


def so3_exp(phi: FloatArray) -> FloatArray:
    """``(3,)`` rotation vector -> ``(3, 3)`` matrix (Rodrigues)."""
    x, y, z = phi.tolist()
    a, b, _ = exp_coefficients(x * x + y * y + z * z)
    return _rotation(x, y, z, a, b)


def se3_exp(xi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(6,)`` ``[rho, phi]`` -> ``(R (3, 3), t (3,))`` with ``t = Jl(phi) rho``."""
    r0, r1, r2, x, y, z = xi.tolist()
    a, b, c = exp_coefficients(x * x + y * y + z * z)
    phi = (x, y, z)
    w = _cross(phi, (r0, r1, r2))
    v = _cross(phi, w)
    t = np.array([r0 + b * w[0] + c * v[0], r1 + b * w[1] + c * v[1], r2 + b * w[2] + c * v[2]])
    return _rotation(x, y, z, a, b), t


def quat_from_matrix(matrix: FloatArray) -> tuple[float, float, float, float]:
    """Shepperd's method on one ``(3, 3)`` matrix: unit ``(x, y, z, w)`` with ``w >= 0``."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = matrix.tolist()
    trace = m00 + m11 + m22
    if trace >= m00 and trace >= m11 and trace >= m22:
        q = (m21 - m12, m02 - m20, m10 - m01, 1.0 + trace)
    elif m00 >= m11 and m00 >= m22:
        q = (1.0 + 2.0 * m00 - trace, m10 + m01, m02 + m20, m21 - m12)
    elif m11 >= m22:
        q = (m10 + m01, 1.0 + 2.0 * m11 - trace, m21 + m12, m02 - m20)
    else:
        q = (m02 + m20, m21 + m12, 1.0 + 2.0 * m22 - trace, m10 - m01)
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if q[3] < 0.0:
        norm = -norm
    return q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm


def matrix_from_quat(quat: FloatArray) -> FloatArray:
    """One unit ``(4,)`` ``xyzw`` quaternion -> ``(3, 3)`` rotation matrix."""
    x, y, z, w = quat.tolist()
    xx, yy, zz, xy, xz, yz = x * x, y * y, z * z, x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return np.array(
        [
            [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
            [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
            [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
        ]
    )


def so3_log(matrix: FloatArray) -> Vec3:
    """One ``(3, 3)`` rotation matrix -> rotation vector (angle in ``[0, pi]``)."""
    x, y, z, w = quat_from_matrix(matrix)
    s = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 / w if s < 1e-12 else 2.0 * math.atan2(s, w) / s
    return x * scale, y * scale, z * scale


def se3_log(matrix: FloatArray, translation: FloatArray) -> FloatArray:
    """``(R, t)`` -> ``(6,)`` ``[rho, phi]`` with ``rho = Jl^-1(phi) t``."""
    phi = so3_log(matrix)
    t0, t1, t2 = translation.tolist()
    d = coeff_cot(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
    w = _cross(phi, (t0, t1, t2))
    v = _cross(phi, w)
    return np.array(
        [
            t0 - 0.5 * w[0] + d * v[0],
            t1 - 0.5 * w[1] + d * v[1],
            t2 - 0.5 * w[2] + d * v[2],
            phi[0],
            phi[1],
            phi[2],
        ]
    )


# ----- SE(2) ------------------------------------------------------------------------------------
def wrap(theta: float) -> float:
    """``theta`` wrapped to ``[-pi, pi)`` (same convention as ``se2.wrap_angle``)."""
    return (theta + math.pi) % (2.0 * math.pi) - math.pi


def se2_v(theta: float) -> tuple[float, float]:
    """``sin t / t`` and ``(1 - cos t) / t`` (``V = [[s, -c], [c, s]]``)."""
    if theta == 0.0:
        return 1.0, 0.0
    h = math.sin(0.5 * theta)
    return math.sin(theta) / theta, 2.0 * h * h / theta


def se2_compose(
    t1: FloatArray, theta1: float, t2: FloatArray, theta2: float
) -> tuple[FloatArray, float]:
    """``(t1, theta1) @ (t2, theta2)`` for single poses."""
    x1, y1 = t1.tolist()
    x2, y2 = t2.tolist()
    c, s = math.cos(theta1), math.sin(theta1)
    return np.array([x1 + c * x2 - s * y2, y1 + s * x2 + c * y2]), wrap(theta1 + theta2)


def se2_exp(tau: FloatArray) -> tuple[FloatArray, float]:
    """``(3,)`` ``[x, y, theta]`` tangent -> ``(t (2,), theta)``."""
    x, y, theta = tau.tolist()
    s, c = se2_v(theta)
    return np.array([s * x - c * y, c * x + s * y]), wrap(theta)


def se2_log(t: FloatArray, theta: float) -> FloatArray:
    """``(t (2,), theta)`` -> ``(3,)`` tangent ``[V^-1 t, theta]``."""
    x, y = t.tolist()
    s, c = se2_v(theta)
    det = s * s + c * c
    return np.array([(s * x + c * y) / det, (-c * x + s * y) / det, theta])
