"""SE(3): rigid transforms as an immutable value type holding one pose or a batch of ``N``.

Tangent vectors ``xi = [x, y, z, rx, ry, rz]`` (translation part ``rho`` first, then rotation
``phi``); right perturbation ``T (+) xi = T @ Exp(xi)``. ``Exp(xi) = (Exp(phi), Jl(phi) rho)``
(Sola et al. 2018, App. D; Barfoot 2017, Sec. 7.1.3). See :mod:`tagloc.geometry`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import GeometryError
from tagloc.geometry import _checks, _scalar
from tagloc.geometry import _quatmath as quatm
from tagloc.geometry import _so3math as so3m
from tagloc.geometry import jacobians as jac
from tagloc.geometry._lie import ActResult, Index, LieGroup
from tagloc.geometry.so3 import SO3


def _matvec(matrix: FloatArray, vector: FloatArray) -> FloatArray:
    """``matrix @ vector`` for ``(..., 3, 3)`` with ``(3,)`` or ``(..., 3)``."""
    if vector.ndim == 1:
        return matrix @ vector
    out: FloatArray = np.einsum("...ij,...j->...i", matrix, vector)  # 2x faster than matmul here
    return out


@dataclass(frozen=True, slots=True, eq=False, repr=False)
class SE3(LieGroup):
    """One rigid transform ``T_a_b`` or a batch of ``N``: ``p_a = R_a_b p_b + t_a_b``.

    Build with ``SE3(rotation=R, translation=t)`` (validated), :meth:`from_matrix`,
    :meth:`from_quat`, :meth:`from_rotvec`, :meth:`exp` or :meth:`identity`.

    Attributes
    ----------
    rotation : SO3
        ``R_a_b``, single or a batch of ``N``.
    translation : (3,) or (N, 3) float, read-only
        ``t_a_b``: the origin of ``b`` expressed in ``a``.

    Notes
    -----
    Equality is identity (``is``); compare values with :meth:`allclose`. A single rotation with
    ``(N, 3)`` translations (or the reverse) is broadcast to a batch of ``N``.
    """

    rotation: SO3
    translation: FloatArray
    DOF: ClassVar[int] = 6
    POINT_DIM: ClassVar[int] = 3

    def __post_init__(self) -> None:
        rotation = self.rotation
        if not isinstance(rotation, SO3):
            raise GeometryError(f"SE3 rotation must be an SO3, got {type(rotation).__name__}")
        translation = _checks.vectors(self.translation, 3, "SE3 translation")
        r_batch, t_batch = rotation.batch_shape, translation.shape[:-1]
        if r_batch != t_batch:
            if r_batch and t_batch:
                raise GeometryError(
                    f"SE3 rotation batch {r_batch} does not match translation batch {t_batch}"
                )
            if t_batch:
                rotation = SO3._make(np.array(np.broadcast_to(rotation.matrix, (*t_batch, 3, 3))))
            else:
                translation = np.array(np.broadcast_to(translation, (*r_batch, 3)))
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation", _checks.readonly(translation))

    @classmethod
    def _make(cls, matrix: FloatArray, translation: FloatArray) -> SE3:
        """Fast private constructor: no validation, takes ownership of both arrays."""
        obj = object.__new__(cls)
        translation.flags.writeable = False
        object.__setattr__(obj, "rotation", SO3._make(matrix))
        object.__setattr__(obj, "translation", translation)
        return obj

    # ----- constructors ----------------------------------------------------------------------
    @classmethod
    def from_trusted(cls, rotation_matrix: npt.ArrayLike, translation: npt.ArrayLike) -> SE3:
        """From ``(3, 3)`` / ``(N, 3, 3)`` rotations and translations that are valid by
        construction (products of rotations, retractions in a solver's loop), unchecked.

        For hot loops where validating small batches costs more than computing them; both
        arrays are copied. Anything that is not a finite proper rotation with a matching
        translation gives an SE3 that breaks the type's contract: use the checked constructors
        for values from outside.
        """
        return cls._make(
            np.array(rotation_matrix, dtype=np.float64), np.array(translation, dtype=np.float64)
        )

    @classmethod
    def identity(cls, n: int | None = None) -> SE3:
        """The identity, or a batch of ``n`` identities."""
        return cls._make(SO3.identity(n).matrix.copy(), np.zeros(3 if n is None else (n, 3)))

    @classmethod
    def from_matrix(cls, matrix: npt.ArrayLike, *, normalize: bool = False) -> SE3:
        """From homogeneous matrices ``(4, 4)`` or ``(N, 4, 4)``.

        Parameters
        ----------
        matrix : (4, 4) or (N, 4, 4) float
            Last row must be ``[0, 0, 0, 1]`` (within ``1e-9``).
        normalize : bool
            Project the rotation block onto SO(3) first (see :meth:`SO3.from_matrix`).

        Raises
        ------
        GeometryError
            Wrong shape, NaN/inf, a bad last row, or a rotation block that is not a rotation.
        """
        array = _checks.matrices(matrix, 4, "SE3 matrix")
        if np.abs(array[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max() > 1e-9:
            raise GeometryError(f"SE3 matrix last row must be [0, 0, 0, 1], got {array[..., 3, :]}")
        rotation = array[..., :3, :3].copy()
        if normalize:
            rotation = so3m.project_to_so3(rotation)
        _checks.check_rotation_matrices(rotation, "SE3 matrix rotation block")
        return cls._make(rotation, array[..., :3, 3].copy())

    @classmethod
    def from_quat(cls, quat_xyzw: npt.ArrayLike, translation: npt.ArrayLike) -> SE3:
        """From quaternions ``[x, y, z, w]`` (``(4,)``/``(N, 4)``) and translations.

        Raises
        ------
        GeometryError
            See :meth:`SO3.from_quat`; or a translation of the wrong shape or with NaN.
        """
        return cls(rotation=SO3.from_quat(quat_xyzw), translation=np.asarray(translation))

    @classmethod
    def from_rotvec(cls, rotvec: npt.ArrayLike, translation: npt.ArrayLike) -> SE3:
        """From rotation vectors (radians) and translations, ``(3,)`` or ``(N, 3)`` each."""
        return cls(rotation=SO3.from_rotvec(rotvec), translation=np.asarray(translation))

    @classmethod
    def random(
        cls, rng: np.random.Generator, n: int | None = None, translation_scale: float = 1.0
    ) -> SE3:
        """Uniform rotations; Gaussian translations of standard deviation ``translation_scale``."""
        rotation = SO3.random(rng, n)
        translation = translation_scale * rng.standard_normal(3 if n is None else (n, 3))
        return cls._make(rotation.matrix.copy(), translation)

    @classmethod
    def from_rows(cls, rows: npt.ArrayLike) -> SE3:
        """The poses of :meth:`as_rows`' ``(..., 12)`` rows (an exact round trip; unchecked, as
        :meth:`from_trusted`: for rows this type wrote)."""
        r = np.asarray(rows, dtype=np.float64)
        return cls.from_trusted(r[..., :9].reshape(*r.shape[:-1], 3, 3), r[..., 9:12])

    # ----- conversions -----------------------------------------------------------------------
    def as_rows(self) -> FloatArray:
        """``(12,)`` or ``(N, 12)``: the rotation matrix (row-major) and the translation, for
        fixed-width numeric storage (:meth:`from_rows` reads them back)."""
        return np.concatenate(
            [np.asarray(self.rotation.matrix).reshape(*self.batch_shape, 9), self.translation],
            axis=-1,
        )

    def as_matrix(self) -> FloatArray:
        """Homogeneous matrices, ``(4, 4)`` or ``(N, 4, 4)`` (a new array)."""
        out = np.zeros((*self.batch_shape, 4, 4))
        out[..., :3, :3] = self.rotation.matrix
        out[..., :3, 3] = self.translation
        out[..., 3, 3] = 1.0
        return out

    def as_quat(self) -> FloatArray:
        """Rotation as unit quaternions ``[x, y, z, w]`` with ``w >= 0``, ``(4,)`` or ``(N, 4)``."""
        return self.rotation.as_quat()

    # ----- action ----------------------------------------------------------------------------
    def _act(self, array: FloatArray, jacobians: bool) -> ActResult:
        """``points_a = R_a_b points_b + t_a_b``; Jacobians ``J_out_T = [R, -R [p]x]`` and
        ``J_out_p = R`` (Sola et al. 2018, App. D)."""
        matrix = self.rotation.matrix
        out = so3m.transform(matrix, self.translation, array)
        if not jacobians:
            return out
        lead = out.shape[:-1]
        rot = _checks.broadcast_jacobian(so3m.rotation_for(matrix, out.ndim), lead)
        J_out_T = np.concatenate(
            [rot, -(rot @ so3m.hat(np.broadcast_to(array, out.shape)))], axis=-1
        )
        return out, J_out_T, rot.copy()

    def adjoint(self) -> FloatArray:
        """``Ad_T = [[R, [t]x R], [0, R]]`` in ``[x, y, z, rx, ry, rz]`` order, ``(6, 6)`` or
        ``(N, 6, 6)``: ``T @ Exp(xi) = Exp(Ad_T xi) @ T`` (Sola et al. 2018, App. D)."""
        matrix = self.rotation.matrix
        out = np.zeros((*self.batch_shape, 6, 6))
        out[..., :3, :3] = matrix
        out[..., 3:, 3:] = matrix
        out[..., :3, 3:] = so3m.hat(self.translation) @ matrix
        return out

    def interpolate_rt(self, other: SE3, alpha: npt.ArrayLike) -> SE3:
        """Rotation by slerp and translation linearly (not the SE(3) geodesic; like GTSAM's
        ``interpolateRt`` and ROS tf). Shapes as in :meth:`interpolate`."""
        alphas = _checks.to_float_array(alpha, "interpolate alpha")
        if alphas.ndim > 1:
            raise GeometryError(f"interpolate alpha must be a scalar or (M,), got {alphas.shape}")
        rotation = self.rotation.interpolate(other.rotation, alphas)
        a = alphas[..., None] if alphas.ndim else alphas
        translation = (1.0 - a) * self.translation + a * other.translation
        return SE3._make(rotation.matrix.copy(), translation)

    # ----- LieGroup hooks --------------------------------------------------------------------
    @property
    def batch_shape(self) -> tuple[int, ...]:
        """``()`` for one pose, ``(N,)`` for a batch."""
        return self.translation.shape[:-1]

    def _compose(self, other: SE3) -> SE3:
        r1 = self.rotation.matrix
        t2 = other.translation
        try:
            if r1.ndim == 2 and t2.ndim == 1:
                translation = r1 @ t2 + self.translation
            else:
                translation = _matvec(r1, t2) + self.translation
            return self._make(r1 @ other.rotation.matrix, translation)
        except ValueError as exc:
            raise GeometryError(
                f"cannot compose SE3 batches of {self.batch_shape} and {other.batch_shape}"
            ) from exc

    def _inverse(self) -> SE3:
        r_inv = np.swapaxes(self.rotation.matrix, -1, -2).copy()
        return self._make(r_inv, -_matvec(r_inv, self.translation))

    @classmethod
    def _exp(cls, tau: FloatArray) -> SE3:
        if tau.ndim == 1:
            return cls._make(*_scalar.se3_exp(tau))
        rho, phi = tau[..., :3], tau[..., 3:]
        _, a, b, c = so3m.exp_coefficients(phi)
        w = so3m.cross(phi, rho)
        # t = Jl(phi) rho = rho + b phi x rho + c phi x (phi x rho)
        t = rho + b[..., None] * w + c[..., None] * so3m.cross(phi, w)
        return cls._make(so3m.exp_matrix(phi, a, b), t)

    def _log(self) -> FloatArray:
        matrix, t = self.rotation.matrix, self.translation
        if matrix.ndim == 2:
            return _scalar.se3_log(matrix, t)
        phi = quatm.log(matrix)
        d = so3m.coeff_cot(so3m.angle(phi))
        w = so3m.cross(phi, t)
        # rho = Jl^-1(phi) t = t - phi x t / 2 + d phi x (phi x t)
        rho = t - 0.5 * w + d[..., None] * so3m.cross(phi, w)
        return np.concatenate([rho, phi], axis=-1)

    @classmethod
    def _jr(cls, tau: FloatArray) -> FloatArray:
        return jac.se3_right_jacobian(tau)

    @classmethod
    def _jr_inv(cls, tau: FloatArray) -> FloatArray:
        return jac.se3_right_jacobian_inv(tau)

    def _index(self, index: Index) -> SE3:
        return self._make(np.array(self.rotation.matrix[index]), np.array(self.translation[index]))

    @classmethod
    def _concat(cls, items: Sequence[SE3]) -> SE3:
        matrix = np.concatenate([np.reshape(t.rotation.matrix, (-1, 3, 3)) for t in items])
        translation = np.concatenate([np.reshape(t.translation, (-1, 3)) for t in items])
        return cls._make(matrix, translation)

    def __repr__(self) -> str:
        if self.batch_shape:
            return f"SE3(<batch of {self.batch_shape[0]}>)"
        fmt = {"precision": 6, "separator": ", "}
        t = np.array2string(self.translation, **fmt)  # type: ignore[arg-type]
        q = np.array2string(self.as_quat(), **fmt)  # type: ignore[arg-type]
        return f"SE3(translation={t}, quat_xyzw={q})"
