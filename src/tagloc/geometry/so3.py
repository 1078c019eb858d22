"""SO(3): 3D rotations as an immutable value type holding one rotation or a batch of ``N``.

Tangent vectors are rotation vectors ``[rx, ry, rz]`` (axis times angle, radians); right
perturbation ``R (+) phi = R @ Exp(phi)``. See :mod:`tagloc.geometry` for the conventions.
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
from tagloc.geometry._lie import ActResult, Index, LieGroup


@dataclass(frozen=True, slots=True, eq=False, repr=False)
class SO3(LieGroup):
    """One rotation ``R_a_b`` or a batch of ``N`` (rotates vectors from frame ``b`` into ``a``).

    Build with :meth:`from_matrix`, :meth:`from_quat`, :meth:`from_rotvec`, :meth:`from_euler`,
    :meth:`exp` or :meth:`identity`; ``SO3(matrix)`` validates like :meth:`from_matrix`.

    Attributes
    ----------
    matrix : (3, 3) or (N, 3, 3) float, read-only
        Rotation matrices.

    Notes
    -----
    Equality is identity (``is``); compare values with :meth:`allclose`.
    """

    matrix: FloatArray
    DOF: ClassVar[int] = 3
    POINT_DIM: ClassVar[int] = 3

    def __post_init__(self) -> None:
        matrix = _checks.matrices(self.matrix, 3, "SO3 matrix")
        _checks.check_rotation_matrices(matrix, "SO3 matrix")
        object.__setattr__(self, "matrix", _checks.readonly(matrix))

    @classmethod
    def _make(cls, matrix: FloatArray) -> SO3:
        """Fast private constructor: no validation, takes ownership of ``matrix``."""
        obj = object.__new__(cls)
        matrix.flags.writeable = False
        object.__setattr__(obj, "matrix", matrix)
        return obj

    # ----- constructors ----------------------------------------------------------------------
    @classmethod
    def identity(cls, n: int | None = None) -> SO3:
        """The identity, or a batch of ``n`` identities."""
        return cls._make(np.eye(3) if n is None else np.tile(np.eye(3), (n, 1, 1)))

    @classmethod
    def from_matrix(cls, matrix: npt.ArrayLike, *, normalize: bool = False) -> SO3:
        """From rotation matrices ``(3, 3)`` or ``(N, 3, 3)``.

        Parameters
        ----------
        matrix : (3, 3) or (N, 3, 3) float
        normalize : bool
            Project onto the nearest rotation (SVD) first, for matrices that drifted or were
            read with few digits; without it the matrix must be orthonormal within ``1e-6``.

        Raises
        ------
        GeometryError
            Wrong shape, NaN/inf, not orthonormal, or a reflection (``det < 0``).
        """
        array = _checks.matrices(matrix, 3, "rotation matrix")
        if normalize:
            array = so3m.project_to_so3(array)
        _checks.check_rotation_matrices(array, "rotation matrix")
        return cls._make(array)

    @classmethod
    def from_quat(cls, quat_xyzw: npt.ArrayLike) -> SO3:
        """From quaternions ``[x, y, z, w]``, shape ``(4,)`` or ``(N, 4)``, unit within ``1e-6``.

        Raises
        ------
        GeometryError
            Wrong shape, NaN/inf, or a norm off 1 by more than ``1e-6``.
        """
        quat = _checks.vectors(quat_xyzw, 4, "quat_xyzw")
        norm = np.sqrt(np.einsum("...i,...i->...", quat, quat))
        off = np.abs(norm - 1.0)
        if np.any(off > _checks.UNIT_QUAT_TOL):
            raise GeometryError(
                f"quat_xyzw is not a unit quaternion: |q| = {np.ravel(norm)[np.argmax(off)]:.9g} "
                f"(tolerance {_checks.UNIT_QUAT_TOL:g}); order is [x, y, z, w]"
            )
        if quat.ndim == 1:
            return cls._make(_scalar.matrix_from_quat(quat / norm))
        return cls._make(quatm.matrix_from_quat(quat / norm[..., None]))

    @classmethod
    def from_rotvec(cls, rotvec: npt.ArrayLike) -> SO3:
        """From rotation vectors (axis times angle, radians), ``(3,)`` or ``(N, 3)``; = ``exp``."""
        return cls._exp(_checks.vectors(rotvec, 3, "rotvec"))

    @classmethod
    def from_euler(cls, seq: str, angles: npt.ArrayLike, *, degrees: bool = False) -> SO3:
        """From Euler angles with scipy's ``seq`` semantics ("xyz" extrinsic, "XYZ" intrinsic).

        For configuration files and display; never use Euler angles inside estimation code.

        Raises
        ------
        GeometryError
            On a malformed ``seq`` or ``angles``.
        """
        from scipy.spatial.transform import Rotation

        values = _checks.to_float_array(angles, "euler angles")
        _checks.check_finite(values, "euler angles")
        try:
            matrix = Rotation.from_euler(seq, values, degrees=degrees).as_matrix()
        except ValueError as exc:
            raise GeometryError(f"euler angles for seq {seq!r}: {exc}") from exc
        return cls._make(np.array(matrix, dtype=np.float64))

    @classmethod
    def random(cls, rng: np.random.Generator, n: int | None = None) -> SO3:
        """Uniformly distributed rotations (normalized Gaussian quaternions)."""
        quat = rng.standard_normal(4 if n is None else (n, 4))
        return cls._make(quatm.matrix_from_quat(quatm.canonical_quat(quat)))

    # ----- conversions -----------------------------------------------------------------------
    def as_matrix(self) -> FloatArray:
        """Rotation matrices, ``(3, 3)`` or ``(N, 3, 3)`` (a writable copy)."""
        return self.matrix.copy()

    def as_quat(self) -> FloatArray:
        """Unit quaternions ``[x, y, z, w]`` with ``w >= 0``, ``(4,)`` or ``(N, 4)``."""
        if self.matrix.ndim == 2:
            return np.array(_scalar.quat_from_matrix(self.matrix))
        return quatm.quat_from_matrix(self.matrix)

    def as_rotvec(self) -> FloatArray:
        """Rotation vectors (angle in ``[0, pi]``), ``(3,)`` or ``(N, 3)``; = ``log()``."""
        return self._log()

    def as_euler(self, seq: str = "xyz", *, degrees: bool = False) -> FloatArray:
        """Euler angles (scipy ``seq`` semantics), ``(3,)`` or ``(N, 3)``: for display only.

        At gimbal lock the third angle is set to zero (scipy's choice; its warning is silenced).
        """
        import warnings

        from scipy.spatial.transform import Rotation

        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Gimbal lock detected")
            angles = Rotation.from_matrix(self.matrix).as_euler(seq, degrees=degrees)
        return np.asarray(angles, dtype=np.float64)

    def normalized(self) -> SO3:
        """The nearest proper rotation(s) (SVD projection), to clean up accumulated round-off."""
        return self._make(so3m.project_to_so3(self.matrix))

    # ----- action ----------------------------------------------------------------------------
    def _act(self, array: FloatArray, jacobians: bool) -> ActResult:
        """``points_a = R_a_b points_b``; Jacobians ``J_out_R = -R [p]x`` and ``J_out_p = R``
        (Sola et al. 2018, App. B)."""
        out = so3m.rotate(self.matrix, array)
        if not jacobians:
            return out
        matrix = so3m.rotation_for(self.matrix, out.ndim)
        lead = out.shape[:-1]
        J_out_R = -(matrix @ so3m.hat(np.broadcast_to(array, out.shape)))
        J_out_p = _checks.broadcast_jacobian(matrix, lead)
        return out, _checks.broadcast_jacobian(J_out_R, lead), J_out_p

    def adjoint(self) -> FloatArray:
        """``Ad_R = R``, ``(3, 3)`` or ``(N, 3, 3)``."""
        return self.matrix.copy()

    # ----- LieGroup hooks --------------------------------------------------------------------
    @property
    def batch_shape(self) -> tuple[int, ...]:
        """``()`` for one rotation, ``(N,)`` for a batch."""
        return self.matrix.shape[:-2]

    def _compose(self, other: SO3) -> SO3:
        try:
            return self._make(self.matrix @ other.matrix)
        except ValueError as exc:
            raise GeometryError(
                f"cannot compose SO3 batches of {self.batch_shape} and {other.batch_shape}"
            ) from exc

    def _inverse(self) -> SO3:
        return self._make(np.swapaxes(self.matrix, -1, -2).copy())

    @classmethod
    def _exp(cls, tau: FloatArray) -> SO3:
        return cls._make(_scalar.so3_exp(tau) if tau.ndim == 1 else so3m.exp(tau))

    def _log(self) -> FloatArray:
        if self.matrix.ndim == 2:
            return np.array(_scalar.so3_log(self.matrix))
        return quatm.log(self.matrix)

    @classmethod
    def _jr(cls, tau: FloatArray) -> FloatArray:
        return so3m.right_jacobian(tau)

    @classmethod
    def _jr_inv(cls, tau: FloatArray) -> FloatArray:
        return so3m.right_jacobian_inv(tau)

    def _index(self, index: Index) -> SO3:
        return self._make(np.array(self.matrix[index]))

    @classmethod
    def _concat(cls, items: Sequence[SO3]) -> SO3:
        return cls._make(np.concatenate([np.reshape(r.matrix, (-1, 3, 3)) for r in items]))

    def __repr__(self) -> str:
        if self.batch_shape:
            return f"SO3(<batch of {self.batch_shape[0]}>)"
        quat = np.array2string(self.as_quat(), precision=6, separator=", ")
        return f"SO3(quat_xyzw={quat})"
