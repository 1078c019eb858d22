"""Input validation for the public ``from_*`` paths and array helpers shared by the geometry types.

Internal code builds values with the private fast constructors and never comes through here; only
data that enters from outside (user arrays, files, messages) is checked, once.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import GeometryError

#: Largest accepted ``max |R^T R - I|`` for a rotation matrix handed in from outside.
ORTHONORMAL_TOL = 1e-6
#: Largest accepted ``| |q| - 1 |`` for a quaternion handed in from outside.
UNIT_QUAT_TOL = 1e-6


def readonly(array: FloatArray) -> FloatArray:
    """Mark ``array`` read-only in place and return it (no copy)."""
    array.flags.writeable = False
    return array


def to_float_array(value: npt.ArrayLike, name: str) -> FloatArray:
    """``value`` as a float64 array, or :class:`GeometryError` naming ``name``."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"{name}: cannot be read as a float array ({exc})") from exc


def check_finite(array: FloatArray, name: str) -> None:
    """Raise :class:`GeometryError` if ``array`` holds a NaN or an infinity."""
    if array.size <= 16:  # plain floats beat a numpy reduction on tiny arrays
        finite = all(map(math.isfinite, array.ravel().tolist()))
    else:
        finite = bool(np.isfinite(array).all())
    if not finite:
        bad = "NaN" if np.isnan(array).any() else "inf"
        raise GeometryError(f"{name} contains {bad}: {array!r}")


def vectors(value: npt.ArrayLike, dim: int, name: str) -> FloatArray:
    """A finite ``(dim,)`` or ``(N, dim)`` float array (a fresh copy the caller may own).

    Raises
    ------
    GeometryError
        On a wrong shape, NaN or infinity.
    """
    return _fresh_finite(value, name, (dim,), f"({dim},) or (N, {dim})")


def matrices(value: npt.ArrayLike, dim: int, name: str) -> FloatArray:
    """A finite ``(dim, dim)`` or ``(N, dim, dim)`` float array (a fresh copy); raises as
    :func:`vectors`."""
    return _fresh_finite(value, name, (dim, dim), f"({dim}, {dim}) or (N, {dim}, {dim})")


def _fresh_finite(
    value: npt.ArrayLike, name: str, item_shape: tuple[int, ...], expected: str
) -> FloatArray:
    array = np.array(to_float_array(value, name), dtype=np.float64)
    n = len(item_shape)
    if array.ndim not in (n, n + 1) or array.shape[-n:] != item_shape:
        raise GeometryError(f"{name} must have shape {expected}, got {array.shape}")
    check_finite(array, name)
    return array


def check_rotation_matrices(matrix: FloatArray, name: str) -> None:
    """Raise :class:`GeometryError` unless every ``(..., 3, 3)`` block is a proper rotation.

    A matrix passes when ``max |R^T R - I| <= ORTHONORMAL_TOL`` and ``det R > 0``.
    """
    if matrix.ndim == 2 and _is_rotation_scalar(matrix.tolist()):
        return  # fast path for one matrix (plain floats beat numpy's per-call overhead)
    gram = np.swapaxes(matrix, -1, -2) @ matrix
    error = np.abs(gram - np.eye(3)).max(axis=(-1, -2))
    worst = int(np.argmax(error)) if error.ndim else 0
    if np.max(error) > ORTHONORMAL_TOL:
        where = f" (pose {worst})" if error.ndim else ""
        raise GeometryError(
            f"{name} is not orthonormal{where}: max |R^T R - I| = {np.max(error):.3g} "
            f"> {ORTHONORMAL_TOL:g}; pass normalize=True to project it onto SO(3)"
        )
    det = np.linalg.det(matrix)
    if np.any(det <= 0.0):
        raise GeometryError(f"{name} is a reflection, not a rotation (det = {np.min(det):.3g})")


def _is_rotation_scalar(rows: list[list[float]]) -> bool:
    """True when the 3x3 ``rows`` are orthonormal within tolerance with a positive determinant."""
    (a, b, c), (d, e, f), (g, h, i) = rows
    columns = ((a, d, g), (b, e, h), (c, f, i))
    for j in range(3):
        for k in range(j, 3):
            dot = sum(x * y for x, y in zip(columns[j], columns[k], strict=True))
            if abs(dot - (1.0 if j == k else 0.0)) > ORTHONORMAL_TOL:
                return False
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) > 0.0


def check_points(points: npt.ArrayLike, dim: int, name: str = "points") -> FloatArray:
    """``points`` as a float array whose last axis has length ``dim`` (no copy, no NaN check)."""
    array = to_float_array(points, name)
    if array.ndim == 0 or array.shape[-1] != dim:
        raise GeometryError(f"{name} must have shape ({dim},) or (N, {dim}), got {array.shape}")
    return array


def broadcast_jacobian(jacobian: FloatArray, batch_shape: tuple[int, ...]) -> FloatArray:
    """``jacobian`` (``(..., r, c)``) broadcast to ``batch_shape + (r, c)`` as a writable copy."""
    target = batch_shape + jacobian.shape[-2:]
    if jacobian.shape == target:
        return jacobian
    return np.array(np.broadcast_to(jacobian, target))
