"""SE(2): planar rigid transforms ``(x, y, theta)``, one pose or a batch of ``N``.

Tangent vectors ``[x, y, theta]``; right perturbation ``T (+) tau = T @ Exp(tau)``;
``Exp(tau) = (V(theta) [x, y], theta)`` with ``V = [[s, -c], [c, s]]``, ``s = sin t / t``,
``c = (1 - cos t) / t`` (Sola et al. 2018, App. C). Angles are stored wrapped to ``[-pi, pi)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import GeometryError
from tagloc.geometry import _checks, _scalar
from tagloc.geometry import _so3math as so3m
from tagloc.geometry import jacobians as jac
from tagloc.geometry._lie import ActResult, Index, LieGroup
from tagloc.geometry.se3 import SE3


def wrap_angle(theta: FloatArray) -> FloatArray:
    """Angles wrapped to ``[-pi, pi)``."""
    return np.asarray((theta + np.pi) % (2.0 * np.pi) - np.pi, dtype=np.float64)


def rotation_2d(theta: FloatArray) -> FloatArray:
    """``[[cos, -sin], [sin, cos]]``: ``(...) -> (..., 2, 2)``."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)


@dataclass(frozen=True, slots=True, eq=False, repr=False, init=False)
class SE2(LieGroup):
    """One planar pose ``T_a_b = (x, y, theta)`` or a batch of ``N``.

    ``SE2(x, y, theta)`` takes floats (one pose) or ``(N,)`` arrays (a batch).

    Attributes
    ----------
    translation : (2,) or (N, 2) float, read-only
        ``[x, y]``.
    rotation_angle : () or (N,) float, read-only
        ``theta`` in radians, wrapped to ``[-pi, pi)``.

    Notes
    -----
    ``x``, ``y`` and ``theta`` are ``float`` properties of a single pose; on a batch use
    ``translation[:, 0]``, ``translation[:, 1]`` and ``rotation_angle``.
    """

    translation: FloatArray
    rotation_angle: FloatArray
    DOF: ClassVar[int] = 3
    POINT_DIM: ClassVar[int] = 2

    def __init__(self, x: npt.ArrayLike, y: npt.ArrayLike, theta: npt.ArrayLike) -> None:
        try:
            xs, ys, ts = np.broadcast_arrays(
                *(_checks.to_float_array(v, n) for v, n in ((x, "x"), (y, "y"), (theta, "theta")))
            )
        except ValueError as exc:
            raise GeometryError(f"SE2 x, y, theta do not broadcast: {exc}") from exc
        if xs.ndim > 1:
            raise GeometryError(f"SE2 x, y, theta must be scalars or (N,) arrays, got {xs.shape}")
        translation = np.stack([xs, ys], axis=-1)
        _checks.check_finite(translation, "SE2 x, y")
        _checks.check_finite(ts, "SE2 theta")
        object.__setattr__(self, "translation", _checks.readonly(translation))
        object.__setattr__(self, "rotation_angle", _checks.readonly(wrap_angle(ts)))

    @classmethod
    def _make(cls, translation: FloatArray, theta: FloatArray) -> SE2:
        """Fast private constructor: no validation (``theta`` already wrapped)."""
        obj = object.__new__(cls)
        translation.flags.writeable = False
        theta.flags.writeable = False
        object.__setattr__(obj, "translation", translation)
        object.__setattr__(obj, "rotation_angle", theta)
        return obj

    # ----- constructors and conversions ------------------------------------------------------
    @classmethod
    def identity(cls, n: int | None = None) -> SE2:
        """The identity, or a batch of ``n`` identities."""
        shape: tuple[int, ...] = () if n is None else (n,)
        return cls._make(np.zeros((*shape, 2)), np.zeros(shape))

    @classmethod
    def from_se3(cls, T: SE3) -> SE2:
        """Planar projection ``(x, y, yaw)`` of an SE(3) pose or batch,
        ``yaw = atan2(R[1, 0], R[0, 0])``.

        Drops z, roll and pitch (yaw as in a ZYX Euler decomposition).
        """
        matrix = T.rotation.matrix
        yaw = np.arctan2(matrix[..., 1, 0], matrix[..., 0, 0])
        return cls._make(T.translation[..., :2].copy(), np.asarray(yaw, dtype=np.float64))

    @classmethod
    def from_matrix(cls, matrix: npt.ArrayLike) -> SE2:
        """From homogeneous ``(3, 3)`` or ``(N, 3, 3)`` matrices.

        Raises
        ------
        GeometryError
            Wrong shape, NaN, a bad last row, or a rotation block that is not a rotation.
        """
        array = _checks.matrices(matrix, 3, "SE2 matrix")
        if np.abs(array[..., 2, :] - np.array([0.0, 0.0, 1.0])).max() > 1e-9:
            raise GeometryError(f"SE2 matrix last row must be [0, 0, 1], got {array[..., 2, :]}")
        rot = array[..., :2, :2]
        error = np.abs(np.swapaxes(rot, -1, -2) @ rot - np.eye(2)).max()
        if error > _checks.ORTHONORMAL_TOL or np.any(np.linalg.det(rot) <= 0):
            raise GeometryError(f"SE2 matrix rotation block is not a rotation (error {error:.3g})")
        theta = np.arctan2(array[..., 1, 0], array[..., 0, 0])
        return cls._make(array[..., :2, 2].copy(), wrap_angle(theta))

    @classmethod
    def from_vector(cls, xytheta: npt.ArrayLike) -> SE2:
        """From ``[x, y, theta]`` rows, ``(3,)`` or ``(N, 3)`` (not the tangent: see ``exp``)."""
        array = _checks.vectors(xytheta, 3, "SE2 [x, y, theta]")
        return cls._make(array[..., :2].copy(), wrap_angle(array[..., 2]))

    @classmethod
    def random(cls, rng: np.random.Generator, n: int | None = None, scale: float = 1.0) -> SE2:
        """Uniform angles and Gaussian ``[x, y]`` of standard deviation ``scale``."""
        shape: tuple[int, ...] = () if n is None else (n,)
        theta = rng.uniform(-np.pi, np.pi, shape)
        return cls._make(scale * rng.standard_normal((*shape, 2)), np.asarray(theta))

    @property
    def x(self) -> float:
        """``x`` of a single pose (metres)."""
        return float(self._single().translation[0])

    @property
    def y(self) -> float:
        """``y`` of a single pose (metres)."""
        return float(self._single().translation[1])

    @property
    def theta(self) -> float:
        """``theta`` of a single pose (radians, in ``[-pi, pi)``)."""
        return float(self._single().rotation_angle)

    def _single(self) -> SE2:
        if self.batch_shape:
            raise GeometryError(
                "x, y, theta are defined on a single SE2; on a batch use translation and "
                "rotation_angle"
            )
        return self

    def as_vector(self) -> FloatArray:
        """``[x, y, theta]``, ``(3,)`` or ``(N, 3)``."""
        return np.concatenate([self.translation, self.rotation_angle[..., None]], axis=-1)

    def as_matrix(self) -> FloatArray:
        """Homogeneous matrices, ``(3, 3)`` or ``(N, 3, 3)``."""
        out = np.zeros((*self.batch_shape, 3, 3))
        out[..., :2, :2] = rotation_2d(self.rotation_angle)
        out[..., :2, 2] = self.translation
        out[..., 2, 2] = 1.0
        return out

    def to_se3(self) -> SE3:
        """The SE(3) pose ``(x, y, 0)`` rotated by ``theta`` about ``z``."""
        if self.rotation_angle.ndim == 0:  # one pose: plain floats
            c, s = math.cos(float(self.rotation_angle)), math.sin(float(self.rotation_angle))
            x, y = self.translation.tolist()
            return SE3._make(
                np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([x, y, 0.0])
            )
        matrix = np.zeros((*self.batch_shape, 3, 3))
        matrix[..., :2, :2] = rotation_2d(self.rotation_angle)
        matrix[..., 2, 2] = 1.0
        translation = np.zeros((*self.batch_shape, 3))
        translation[..., :2] = self.translation
        return SE3._make(matrix, translation)

    # ----- action ----------------------------------------------------------------------------
    def _act(self, array: FloatArray, jacobians: bool) -> ActResult:
        """Planar ``p_a = R(theta) p_b + t``; Jacobians ``J_out_T = [R, R [1]x p]`` (with
        ``[1]x p = [-p_y, p_x]``) and ``J_out_p = R`` (Sola App. C)."""
        matrix = rotation_2d(self.rotation_angle)
        out = so3m.transform(matrix, self.translation, array)
        if not jacobians:
            return out
        lead = out.shape[:-1]
        rot = _checks.broadcast_jacobian(so3m.rotation_for(matrix, out.ndim), lead)
        p = np.broadcast_to(array, out.shape)
        perp = np.stack([-p[..., 1], p[..., 0]], axis=-1)
        J_out_T = np.concatenate([rot, (rot @ perp[..., None])], axis=-1)
        return out, J_out_T, rot.copy()

    def adjoint(self) -> FloatArray:
        """``Ad = [[R, [y, -x]^T], [0, 1]]`` in ``[x, y, theta]`` order (Sola App. C)."""
        if self.rotation_angle.ndim == 0:  # one pose: plain floats
            c, s = math.cos(float(self.rotation_angle)), math.sin(float(self.rotation_angle))
            x, y = self.translation.tolist()
            return np.array([[c, -s, y], [s, c, -x], [0.0, 0.0, 1.0]])
        out = np.zeros((*self.batch_shape, 3, 3))
        out[..., :2, :2] = rotation_2d(self.rotation_angle)
        out[..., 0, 2] = self.translation[..., 1]
        out[..., 1, 2] = -self.translation[..., 0]
        out[..., 2, 2] = 1.0
        return out

    # ----- LieGroup hooks --------------------------------------------------------------------
    @property
    def batch_shape(self) -> tuple[int, ...]:
        """``()`` for one pose, ``(N,)`` for a batch."""
        return self.rotation_angle.shape

    def _compose(self, other: SE2) -> SE2:
        if self.rotation_angle.ndim == 0 and other.rotation_angle.ndim == 0:
            t, angle = _scalar.se2_compose(
                self.translation,
                float(self.rotation_angle),
                other.translation,
                float(other.rotation_angle),
            )
            return self._make(t, np.array(angle))
        try:
            translation = self.act(other.translation)
            theta = wrap_angle(self.rotation_angle + other.rotation_angle)
        except (ValueError, GeometryError) as exc:
            raise GeometryError(
                f"cannot compose SE2 batches of {self.batch_shape} and {other.batch_shape}"
            ) from exc
        return self._make(translation, theta)

    def _inverse(self) -> SE2:
        if self.rotation_angle.ndim == 0:  # one pose: plain floats
            angle = -float(self.rotation_angle)
            ca, sa = math.cos(angle), math.sin(angle)
            px, py = self.translation.tolist()
            wrapped = (angle + math.pi) % (2.0 * math.pi) - math.pi
            return self._make(
                np.array([-(ca * px - sa * py), -(sa * px + ca * py)]), np.array(wrapped)
            )
        theta = -self.rotation_angle
        t = self.translation
        c, s = np.cos(theta), np.sin(theta)
        x = -(c * t[..., 0] - s * t[..., 1])
        y = -(s * t[..., 0] + c * t[..., 1])
        return self._make(np.stack([x, y], axis=-1), wrap_angle(theta))

    @classmethod
    def _exp(cls, tau: FloatArray) -> SE2:
        if tau.ndim == 1:
            t, angle = _scalar.se2_exp(tau)
            return cls._make(t, np.array(angle))
        theta = tau[..., 2]
        s, c, _ = jac.se2_coefficients(theta)
        x = s * tau[..., 0] - c * tau[..., 1]
        y = c * tau[..., 0] + s * tau[..., 1]
        return cls._make(np.stack([x, y], axis=-1), wrap_angle(theta))

    def _log(self) -> FloatArray:
        if self.rotation_angle.ndim == 0:
            return _scalar.se2_log(self.translation, float(self.rotation_angle))
        theta = self.rotation_angle
        s, c, _ = jac.se2_coefficients(theta)
        det = s * s + c * c
        t = self.translation
        x = (s * t[..., 0] + c * t[..., 1]) / det
        y = (-c * t[..., 0] + s * t[..., 1]) / det
        return np.stack([x, y, theta], axis=-1)

    @classmethod
    def _jr(cls, tau: FloatArray) -> FloatArray:
        return jac.se2_right_jacobian(tau)

    @classmethod
    def _jr_inv(cls, tau: FloatArray) -> FloatArray:
        return jac.se2_right_jacobian_inv(tau)

    def _index(self, index: Index) -> SE2:
        return self._make(np.array(self.translation[index]), np.array(self.rotation_angle[index]))

    @classmethod
    def _concat(cls, items: Sequence[SE2]) -> SE2:
        translation = np.concatenate([np.reshape(t.translation, (-1, 2)) for t in items])
        theta = np.concatenate([np.reshape(t.rotation_angle, (-1,)) for t in items])
        return cls._make(translation, theta)

    def __repr__(self) -> str:
        if self.batch_shape:
            return f"SE2(<batch of {self.batch_shape[0]}>)"
        return f"SE2(x={self.x:.6g}, y={self.y:.6g}, theta={self.theta:.6g})"
