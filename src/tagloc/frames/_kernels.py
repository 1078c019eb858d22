"""Interpolation and composition kernels behind :class:`~tagloc.frames.TransformBuffer`.

A sample is 7 floats ``[qx, qy, qz, qw, tx, ty, tz]`` (rotation as ``quat_xyzw``, unit norm).
A rigid transform inside the buffer's hot path is a 12-tuple of Python floats
``(r00, r01, r02, r10, r11, r12, r20, r21, r22, tx, ty, tz)`` (row-major rotation, then
translation): for one lookup, scalar float arithmetic beats building numpy arrays and value
objects per edge. The batched kernels (``*_many``) do the same in vectorized numpy for
``lookup_many`` and ``set_transforms``.

Interpolation is slerp on the rotation (Shoemake 1985) and linear on the translation, as ROS tf
and GTSAM's ``interpolateRt`` do; it is *not* the SE(3) geodesic (which would couple translation
to rotation along a screw). The angle between the quaternions is taken as
``2 atan2(|q1 - q0|, |q1 + q0|)``, accurate for small and large angles alike.
"""

from __future__ import annotations

import math
from typing import TypeAlias

import numpy as np

from tagloc._types import FloatArray

#: 12 floats: row-major rotation matrix, then translation.
Rt: TypeAlias = tuple[
    float, float, float, float, float, float, float, float, float, float, float, float
]

IDENTITY: Rt = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
#: Below this half-angle between quaternions (radians), slerp is replaced by normalized lerp:
#: the two agree to ``O(angle^3)``, far below float64 resolution here.
_SMALL_ANGLE = 1e-9


def quat_from_matrix(r: list[float]) -> tuple[float, float, float, float]:
    """Unit ``quat_xyzw`` (``w >= 0``) of a rotation matrix given as 9 row-major floats.

    Shepperd's method: divide by the largest of ``1 + trace`` and ``1 + 2 R_ii - trace`` for
    accuracy at every angle (S. W. Shepperd, "Quaternion from rotation matrix", JGC 1978).
    """
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = r
    trace = m00 + m11 + m22
    largest = max(trace, m00, m11, m22)
    if largest == trace:
        w = 0.5 * math.sqrt(max(1.0 + trace, 0.0))
        f = 0.25 / w
        x, y, z = (m21 - m12) * f, (m02 - m20) * f, (m10 - m01) * f
    elif largest == m00:
        x = 0.5 * math.sqrt(max(1.0 + m00 - m11 - m22, 0.0))
        f = 0.25 / x
        y, z, w = (m01 + m10) * f, (m02 + m20) * f, (m21 - m12) * f
    elif largest == m11:
        y = 0.5 * math.sqrt(max(1.0 - m00 + m11 - m22, 0.0))
        f = 0.25 / y
        x, z, w = (m01 + m10) * f, (m12 + m21) * f, (m02 - m20) * f
    else:
        z = 0.5 * math.sqrt(max(1.0 - m00 - m11 + m22, 0.0))
        f = 0.25 / z
        x, y, w = (m02 + m20) * f, (m12 + m21) * f, (m10 - m01) * f
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0:
        norm = -norm
    return x / norm, y / norm, z / norm, w / norm


def rt_from_sample(s: list[float]) -> Rt:
    """The 12-tuple of a sample ``[qx, qy, qz, qw, tx, ty, tz]`` (quaternion of unit norm)."""
    x, y, z, w, tx, ty, tz = s
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),
        2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),
        2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy),
        tx, ty, tz,
    )  # fmt: skip


def interpolate_sample(s0: list[float], s1: list[float], alpha: float) -> list[float]:
    """Slerp the quaternions and lerp the translations of two samples at ``alpha`` in [0, 1].

    Takes the shorter arc (``q`` and ``-q`` are the same rotation).
    """
    x0, y0, z0, w0, tx0, ty0, tz0 = s0
    x1, y1, z1, w1, tx1, ty1, tz1 = s1
    if x0 * x1 + y0 * y1 + z0 * z1 + w0 * w1 < 0.0:
        x1, y1, z1, w1 = -x1, -y1, -z1, -w1
    dx, dy, dz, dw = x1 - x0, y1 - y0, z1 - z0, w1 - w0
    sx, sy, sz, sw = x1 + x0, y1 + y0, z1 + z0, w1 + w0
    half = math.atan2(
        math.sqrt(dx * dx + dy * dy + dz * dz + dw * dw),
        math.sqrt(sx * sx + sy * sy + sz * sz + sw * sw),
    )  # half of the angle between q0 and q1 on the 3-sphere
    theta = 2.0 * half
    if theta < _SMALL_ANGLE:
        c0, c1 = 1.0 - alpha, alpha
    else:
        inv_sin = 1.0 / math.sin(theta)
        c0, c1 = math.sin((1.0 - alpha) * theta) * inv_sin, math.sin(alpha * theta) * inv_sin
    x, y, z, w = c0 * x0 + c1 * x1, c0 * y0 + c1 * y1, c0 * z0 + c1 * z1, c0 * w0 + c1 * w1
    n = 1.0 / math.sqrt(x * x + y * y + z * z + w * w)
    b = 1.0 - alpha
    return [
        x * n,
        y * n,
        z * n,
        w * n,
        b * tx0 + alpha * tx1,
        b * ty0 + alpha * ty1,
        b * tz0 + alpha * tz1,
    ]


def compose(a: Rt, b: Rt) -> Rt:
    """``T_a_c = T_a_b @ T_b_c`` on 12-tuples."""
    a00, a01, a02, a10, a11, a12, a20, a21, a22, ax, ay, az = a
    b00, b01, b02, b10, b11, b12, b20, b21, b22, bx, by, bz = b
    return (
        a00 * b00 + a01 * b10 + a02 * b20, a00 * b01 + a01 * b11 + a02 * b21,
        a00 * b02 + a01 * b12 + a02 * b22,
        a10 * b00 + a11 * b10 + a12 * b20, a10 * b01 + a11 * b11 + a12 * b21,
        a10 * b02 + a11 * b12 + a12 * b22,
        a20 * b00 + a21 * b10 + a22 * b20, a20 * b01 + a21 * b11 + a22 * b21,
        a20 * b02 + a21 * b12 + a22 * b22,
        a00 * bx + a01 * by + a02 * bz + ax, a10 * bx + a11 * by + a12 * bz + ay,
        a20 * bx + a21 * by + a22 * bz + az,
    )  # fmt: skip


def invert(a: Rt) -> Rt:
    """``T_b_a`` from ``T_a_b`` on 12-tuples: ``(R^T, -R^T t)``."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22, x, y, z = a
    return (
        r00, r10, r20, r01, r11, r21, r02, r12, r22,
        -(r00 * x + r10 * y + r20 * z), -(r01 * x + r11 * y + r21 * z),
        -(r02 * x + r12 * y + r22 * z),
    )  # fmt: skip


# ----- batched (numpy) -------------------------------------------------------------------------
def interpolate_samples_many(s0: FloatArray, s1: FloatArray, alpha: FloatArray) -> FloatArray:
    """Vectorized :func:`interpolate_sample`: ``(N, 7)``, ``(N, 7)``, ``(N,)`` -> ``(N, 7)``."""
    q0, q1 = s0[:, :4], s1[:, :4].copy()
    q1[np.einsum("ij,ij->i", q0, q1) < 0.0] *= -1.0
    theta = 2.0 * np.arctan2(np.linalg.norm(q1 - q0, axis=1), np.linalg.norm(q1 + q0, axis=1))
    small = theta < _SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    c0 = np.where(small, 1.0 - alpha, np.sin((1.0 - alpha) * safe) / np.sin(safe))
    c1 = np.where(small, alpha, np.sin(alpha * safe) / np.sin(safe))
    q = c0[:, None] * q0 + c1[:, None] * q1
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    a = alpha[:, None]
    t = (1.0 - a) * s0[:, 4:] + a * s1[:, 4:]
    out: FloatArray = np.concatenate([q, t], axis=1)
    return out


def matrices_from_quats(q: FloatArray) -> FloatArray:
    """Rotation matrices ``(N, 3, 3)`` from unit ``quat_xyzw`` ``(N, 4)``."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    out = np.empty((len(q), 3, 3))
    out[:, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[:, 0, 1] = 2.0 * (x * y - w * z)
    out[:, 0, 2] = 2.0 * (x * z + w * y)
    out[:, 1, 0] = 2.0 * (x * y + w * z)
    out[:, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[:, 1, 2] = 2.0 * (y * z - w * x)
    out[:, 2, 0] = 2.0 * (x * z - w * y)
    out[:, 2, 1] = 2.0 * (y * z + w * x)
    out[:, 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return out


def compose_many(
    R_a_b: FloatArray, t_a_b: FloatArray, R_b_c: FloatArray, t_b_c: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``T_a_c = T_a_b @ T_b_c`` with rotations ``(N, 3, 3)`` or ``(3, 3)`` and translations
    ``(N, 3)`` or ``(3,)`` (single broadcast against batch)."""
    R_a_c: FloatArray = R_a_b @ R_b_c
    t_a_c: FloatArray = np.einsum("...ij,...j->...i", R_a_b, t_b_c) + t_a_b
    return R_a_c, t_a_c


def invert_many(R_a_b: FloatArray, t_a_b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``T_b_a`` from ``T_a_b`` (shapes as in :func:`compose_many`)."""
    R_b_a = np.swapaxes(R_a_b, -1, -2)
    t_b_a: FloatArray = -np.einsum("...ij,...j->...i", R_b_a, t_a_b)
    return R_b_a, t_b_a
