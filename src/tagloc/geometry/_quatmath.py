"""Vectorized quaternion kernels: matrix -> quaternion (Shepperd), quaternion -> matrix, and Log.

The Log of a rotation matrix goes through the quaternion: of the four algebraically equal
expressions of ``4 q_k q`` (pivot ``k`` on ``x``, ``y``, ``z`` or ``w``), each element uses the one
with the largest pivot (S. W. Shepperd, "Quaternion from rotation matrix", J. Guidance and
Control 1(3), 1978), then ``theta = 2 atan2(|v|, |w|)``. Both steps keep full precision at every
angle, including near pi where an axis read from the skew-symmetric part ``R - R^T`` alone is lost.

Internally the work is done on ``(9, M)`` component rows (contiguous), which is about three times
faster in numpy than on strided ``(M, 3, 3)`` entries.
"""

from __future__ import annotations

import numpy as np

from tagloc._types import FloatArray


def _quat_rows(matrix: FloatArray) -> FloatArray:
    """Unnormalized ``4 q_k q`` rows ``(4, M)`` (``x, y, z, w``) of ``(..., 3, 3)`` matrices."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = np.ascontiguousarray(matrix.reshape(-1, 9).T)
    trace = m00 + m11 + m22
    s21, d21 = m21 + m12, m21 - m12
    s02, d02 = m02 + m20, m02 - m20
    s10, d10 = m10 + m01, m10 - m01
    # Pivot on w where the trace is the largest candidate (rotations below ~120 degrees) ...
    q = np.stack([d21, d02, d10, 1.0 + trace])
    # ... and on the largest diagonal entry elsewhere.
    rest = np.flatnonzero(np.maximum(np.maximum(m00, m11), m22) > trace)
    if rest.size:
        a00, a11, a22, tr = m00[rest], m11[rest], m22[rest], trace[rest]
        on_x = (a00 >= a11) & (a00 >= a22)
        on_y = ~on_x & (a11 >= a22)
        x_, y_, z_ = 1.0 + 2.0 * a00 - tr, 1.0 + 2.0 * a11 - tr, 1.0 + 2.0 * a22 - tr
        s21r, s02r, s10r = s21[rest], s02[rest], s10[rest]
        q[0, rest] = np.where(on_x, x_, np.where(on_y, s10r, s02r))
        q[1, rest] = np.where(on_x, s10r, np.where(on_y, y_, s21r))
        q[2, rest] = np.where(on_x, s02r, np.where(on_y, s21r, z_))
        q[3, rest] = np.where(on_x, d21[rest], np.where(on_y, d02[rest], d10[rest]))
    return q


def quat_from_matrix(matrix: FloatArray) -> FloatArray:
    """Unit quaternions ``xyzw`` with ``w >= 0`` from rotation matrices (Shepperd's method).

    Parameters
    ----------
    matrix : (..., 3, 3) float

    Returns
    -------
    (..., 4) float
    """
    q = _quat_rows(matrix)
    q *= np.where(q[3] < 0.0, -1.0, 1.0) / np.sqrt(np.einsum("ij,ij->j", q, q))
    return q.T.reshape(*matrix.shape[:-2], 4)


def canonical_quat(quat: FloatArray) -> FloatArray:
    """Normalize ``(..., 4)`` ``xyzw`` quaternions and flip their sign so that ``w >= 0``."""
    norm = np.sqrt(np.einsum("...i,...i->...", quat, quat))
    sign = np.where(quat[..., 3] < 0.0, -1.0, 1.0)
    out: FloatArray = quat * (sign / norm)[..., None]
    return out


def matrix_from_quat(quat: FloatArray) -> FloatArray:
    """Rotation matrices from unit ``xyzw`` quaternions: ``(..., 4) -> (..., 3, 3)``."""
    x, y, z, w = quat[..., 0], quat[..., 1], quat[..., 2], quat[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rows = [
        [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
        [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
        [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
    ]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def log(matrix: FloatArray) -> FloatArray:
    """``Log`` of rotation matrices: ``(..., 3, 3) -> (..., 3)``, angle in ``[0, pi]``.

    With ``q = (v, w)`` from :func:`_quat_rows` (any positive scale), ``theta = 2 atan2(|v|, |w|)``
    and ``phi = sign(w) v theta / |v|`` (``2 v / |w|`` when ``|v|`` underflows).
    """
    v0, v1, v2, w = _quat_rows(matrix)
    sign = np.where(w < 0.0, -1.0, 1.0)
    w = np.abs(w)
    s = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    small = s < 1e-300
    theta = 2.0 * np.arctan2(s, w)
    scale = sign * np.where(small, 2.0 / np.where(small, w, 1.0), theta / np.where(small, 1.0, s))
    out = np.stack([v0 * scale, v1 * scale, v2 * scale], axis=-1)
    return out.reshape(*matrix.shape[:-2], 3)
