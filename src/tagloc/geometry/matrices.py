"""Lie helpers on raw homogeneous arrays, for solvers that keep stacks of ``(N, 4, 4)``.

The same formulas and tangent order as :class:`~tagloc.geometry.SE3` (``[x, y, z, rx, ry, rz]``,
right perturbation); new code uses :class:`SE3` batches, these serve the survey's solvers whose
state is a stack of matrices.

- :func:`hat` / :func:`vee`: ``[phi]x`` with ``[phi]x v = phi x v`` and its inverse;
- :func:`inverse_h`: ``T^-1 = [[R^T, -R^T t], [0, 1]]``;
- :func:`adjoint_h`: ``Ad_T = [[R, [t]x R], [0, R]]`` (:meth:`SE3.adjoint`);
- :func:`log_h`: ``Log(T)`` (:meth:`SE3.log`), projecting onto SO(3) only the matrices that
  rounding has left off it.
"""

from __future__ import annotations

import numpy as np

from tagloc._types import FloatArray
from tagloc.errors import GeometryError
from tagloc.geometry._so3math import hat, vee
from tagloc.geometry.se3 import SE3

__all__ = ["adjoint_h", "as_se3", "hat", "inverse_h", "log_h", "vee"]


def inverse_h(M: FloatArray) -> FloatArray:
    """Inverse of rigid ``(..., 4, 4)`` transforms."""
    out = np.zeros_like(M)
    R_t = np.swapaxes(M[..., :3, :3], -1, -2)
    out[..., :3, :3] = R_t
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", R_t, M[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def adjoint_h(M: FloatArray) -> FloatArray:
    """``(n, 6, 6)`` adjoint ``[[R, [t]x R], [0, R]]`` of ``(n, 4, 4)`` rigid transforms."""
    R, t = M[:, :3, :3], M[:, :3, 3]
    A = np.zeros((len(M), 6, 6))
    A[:, :3, :3] = R
    A[:, 3:, 3:] = R
    A[:, :3, 3:] = hat(t) @ R
    return A


def as_se3(M: FloatArray) -> SE3:
    """``(n, 4, 4)`` as an SE3 batch; projected onto SO(3) only if rounding has left it off (an
    SVD of every matrix would cost a solver's step a tenth of its time)."""
    try:
        return SE3.from_matrix(M)
    except GeometryError:
        return SE3.from_matrix(M, normalize=True)


def log_h(M: FloatArray) -> FloatArray:
    """``(n, 6)`` SE(3) logarithm ``[x, y, z, rx, ry, rz]`` of ``(n, 4, 4)`` rigid transforms."""
    if len(M) == 0:
        return np.zeros((0, 6))
    return np.asarray(as_se3(M).log())
