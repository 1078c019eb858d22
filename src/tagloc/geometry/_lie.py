"""The Lie-group verbs shared by :class:`SO3`, :class:`SE3` and :class:`SE2`.

Each concrete type supplies a handful of raw hooks (compose, inverse, Exp, Log, adjoint, right
Jacobian and its inverse, indexing); this base turns them into the public verbs with their
Jacobians, following J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state estimation in
robotics" (2018, arXiv:1812.01537), Sec. IV ("Derivatives on Lie groups") and its table of the
Jacobians of the elementary operations, with right perturbations:

- ``X (+) tau = X @ Exp(tau)`` and ``Y (-) X = Log(X^-1 @ Y)``;
- a Jacobian ``J_out_in`` maps a right perturbation of ``in`` to the right perturbation of ``out``:
  ``out(in (+) d) = out(in) (+) J_out_in d + o(|d|)``.

Batches: a value holds one element (``batch_shape == ()``) or ``N`` (``batch_shape == (N,)``);
binary verbs broadcast single with batch, and returned Jacobians have shape
``batch_shape + (dof, dof)`` of the result.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import ClassVar, Literal, Self, overload

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import GeometryError
from tagloc.geometry._checks import (
    broadcast_jacobian,
    check_finite,
    check_points,
    to_float_array,
)

Index = int | slice | Sequence[int] | npt.NDArray[np.integer] | npt.NDArray[np.bool_]
#: What a group's action hook returns: the moved points, or with them ``J_out_self, J_out_points``.
ActResult = FloatArray | tuple[FloatArray, FloatArray, FloatArray]


class LieGroup:
    """Mixin: the group verbs common to the geometry types (see the module docstring)."""

    __slots__ = ()

    DOF: ClassVar[int]
    #: Dimension of the points the group acts on (3 for SO3 and SE3, 2 for SE2).
    POINT_DIM: ClassVar[int]

    # ----- hooks the concrete types implement ------------------------------------------------
    @property
    def batch_shape(self) -> tuple[int, ...]:
        """``()`` for a single element, ``(N,)`` for a batch of ``N``."""
        raise NotImplementedError

    def _compose(self, other: Self) -> Self:
        raise NotImplementedError

    def _inverse(self) -> Self:
        raise NotImplementedError

    @classmethod
    def _exp(cls, tau: FloatArray) -> Self:
        raise NotImplementedError

    def _log(self) -> FloatArray:
        raise NotImplementedError

    @classmethod
    def _jr(cls, tau: FloatArray) -> FloatArray:
        raise NotImplementedError

    @classmethod
    def _jr_inv(cls, tau: FloatArray) -> FloatArray:
        raise NotImplementedError

    def _index(self, index: Index) -> Self:
        raise NotImplementedError

    @classmethod
    def _concat(cls, items: Sequence[Self]) -> Self:
        raise NotImplementedError

    def _act(self, array: FloatArray, jacobians: bool) -> ActResult:
        raise NotImplementedError

    def adjoint(self) -> FloatArray:
        """Adjoint matrix ``Ad_X`` with ``X @ Exp(tau) = Exp(Ad_X tau) @ X``."""
        raise NotImplementedError

    def as_matrix(self) -> FloatArray:
        """Homogeneous matrix (rotation matrix for SO3)."""
        raise NotImplementedError

    # ----- tangent-vector input --------------------------------------------------------------
    @classmethod
    def _tangent(cls, tau: npt.ArrayLike, name: str = "tangent vector") -> FloatArray:
        array = to_float_array(tau, name)
        dof = cls.DOF
        if array.ndim not in (1, 2) or array.shape[-1] != dof:
            raise GeometryError(
                f"{cls.__name__} {name} must have shape ({dof},) or (N, {dof}), got {array.shape}"
            )
        check_finite(array, f"{cls.__name__} {name}")
        return array

    def _eye(self, batch_shape: tuple[int, ...]) -> FloatArray:
        return broadcast_jacobian(np.eye(self.DOF), batch_shape)

    # ----- group verbs -----------------------------------------------------------------------
    def __matmul__(self, other: Self) -> Self:
        if other.__class__ is not self.__class__:
            raise GeometryError(
                f"{type(self).__name__} @ {type(other).__name__}: compose needs two "
                f"{type(self).__name__} values (use .act(points) to transform points)"
            )
        return self._compose(other)

    @overload
    def act(self, points: npt.ArrayLike, *, jacobians: Literal[False] = ...) -> FloatArray: ...
    @overload
    def act(
        self, points: npt.ArrayLike, *, jacobians: Literal[True]
    ) -> tuple[FloatArray, FloatArray, FloatArray]: ...
    def act(self, points: npt.ArrayLike, *, jacobians: bool = False) -> ActResult:
        """Move points by the group action: ``points_a = R_a_b points_b (+ t_a_b)``.

        Parameters
        ----------
        points : float array, last axis ``POINT_DIM`` (``d``)
            A single element takes ``(d,)`` or ``(..., d)``. A batch of ``N`` takes ``(d,)`` (one
            point, moved by each element), ``(N, d)`` (point ``i`` by element ``i``) or
            ``(N, M, d)`` (``M`` points per element).
        jacobians : bool
            Also return ``J_out_self`` (``out.shape[:-1] + (d, DOF)``) and ``J_out_points``
            (``out.shape[:-1] + (d, d)``); each type's ``_act`` gives the formulas.

        Returns
        -------
        float array, the broadcast shape of ``points``
        """
        return self._act(check_points(points, self.POINT_DIM), jacobians)

    @overload
    def compose(self, other: Self, *, jacobians: Literal[False] = ...) -> Self: ...
    @overload
    def compose(
        self, other: Self, *, jacobians: Literal[True]
    ) -> tuple[Self, FloatArray, FloatArray]: ...
    def compose(
        self, other: Self, *, jacobians: bool = False
    ) -> Self | tuple[Self, FloatArray, FloatArray]:
        """``self @ other``; with ``jacobians=True`` also ``J_out_self = Ad(other)^-1`` and
        ``J_out_other = I`` (Sola et al. 2018, Sec. IV-B)."""
        out = self @ other
        if not jacobians:
            return out
        shape = out.batch_shape
        return out, broadcast_jacobian(other._inverse().adjoint(), shape), self._eye(shape)

    @overload
    def inverse(self, *, jacobians: Literal[False] = ...) -> Self: ...
    @overload
    def inverse(self, *, jacobians: Literal[True]) -> tuple[Self, FloatArray]: ...
    def inverse(self, *, jacobians: bool = False) -> Self | tuple[Self, FloatArray]:
        """``self^-1``; with ``jacobians=True`` also ``J_out_self = -Ad(self)``
        (Sola et al. 2018, Sec. IV-B)."""
        out = self._inverse()
        if not jacobians:
            return out
        return out, -self.adjoint()

    @overload
    def log(self, *, jacobians: Literal[False] = ...) -> FloatArray: ...
    @overload
    def log(self, *, jacobians: Literal[True]) -> tuple[FloatArray, FloatArray]: ...
    def log(self, *, jacobians: bool = False) -> FloatArray | tuple[FloatArray, FloatArray]:
        """Tangent vector ``tau = Log(self)``, ``(dof,)`` or ``(N, dof)``; with
        ``jacobians=True`` also ``J_tau_self = Jr^-1(tau)`` (Sola et al. 2018, Sec. IV-B)."""
        tau = self._log()
        if not jacobians:
            return tau
        return tau, self._jr_inv(tau)

    @overload
    @classmethod
    def exp(cls, tau: npt.ArrayLike, *, jacobians: Literal[False] = ...) -> Self: ...
    @overload
    @classmethod
    def exp(cls, tau: npt.ArrayLike, *, jacobians: Literal[True]) -> tuple[Self, FloatArray]: ...
    @classmethod
    def exp(cls, tau: npt.ArrayLike, *, jacobians: bool = False) -> Self | tuple[Self, FloatArray]:
        """Element ``Exp(tau)`` for ``tau`` of shape ``(dof,)`` or ``(N, dof)``; with
        ``jacobians=True`` also ``J_out_tau = Jr(tau)`` (Sola et al. 2018, Sec. IV-B).

        Raises
        ------
        GeometryError
            If ``tau`` has a wrong shape or holds NaN/inf.
        """
        array = cls._tangent(tau)
        out = cls._exp(array)
        if not jacobians:
            return out
        return out, cls._jr(array)

    @overload
    def plus(self, tau: npt.ArrayLike, *, jacobians: Literal[False] = ...) -> Self: ...
    @overload
    def plus(
        self, tau: npt.ArrayLike, *, jacobians: Literal[True]
    ) -> tuple[Self, FloatArray, FloatArray]: ...
    def plus(
        self, tau: npt.ArrayLike, *, jacobians: bool = False
    ) -> Self | tuple[Self, FloatArray, FloatArray]:
        """``self (+) tau = self @ Exp(tau)``; with ``jacobians=True`` also
        ``J_out_self = Ad(Exp(tau))^-1`` and ``J_out_tau = Jr(tau)``
        (Sola et al. 2018, Sec. IV-B)."""
        array = self._tangent(tau)
        step = self._exp(array)
        out = self @ step
        if not jacobians:
            return out
        shape = out.batch_shape
        J_out_self = broadcast_jacobian(step._inverse().adjoint(), shape)
        return out, J_out_self, broadcast_jacobian(self._jr(array), shape)

    @overload
    def minus(self, other: Self, *, jacobians: Literal[False] = ...) -> FloatArray: ...
    @overload
    def minus(
        self, other: Self, *, jacobians: Literal[True]
    ) -> tuple[FloatArray, FloatArray, FloatArray]: ...
    def minus(
        self, other: Self, *, jacobians: bool = False
    ) -> FloatArray | tuple[FloatArray, FloatArray, FloatArray]:
        """``self (-) other = Log(other^-1 @ self)``; with ``jacobians=True`` also
        ``J_tau_self = Jr^-1(tau)`` and ``J_tau_other = -Jl^-1(tau) = -Jr^-1(-tau)``
        (Sola et al. 2018, Sec. IV-B)."""
        tau = (other._inverse() @ self)._log()
        if not jacobians:
            return tau
        return tau, self._jr_inv(tau), -self._jr_inv(-tau)

    @overload
    def between(self, other: Self, *, jacobians: Literal[False] = ...) -> Self: ...
    @overload
    def between(
        self, other: Self, *, jacobians: Literal[True]
    ) -> tuple[Self, FloatArray, FloatArray]: ...
    def between(
        self, other: Self, *, jacobians: bool = False
    ) -> Self | tuple[Self, FloatArray, FloatArray]:
        """``self^-1 @ other`` (e.g. ``T_a_b.between(T_a_c) = T_b_c``); with ``jacobians=True``
        also ``J_out_self = -Ad(out^-1)`` and ``J_out_other = I``."""
        out = self._inverse() @ other
        if not jacobians:
            return out
        shape = out.batch_shape
        return out, -out._inverse().adjoint(), self._eye(shape)

    def interpolate(self, other: Self, alpha: npt.ArrayLike) -> Self:
        """Geodesic interpolation ``self @ Exp(alpha * Log(self^-1 @ other))``.

        ``alpha = 0`` gives ``self``, ``alpha = 1`` gives ``other``; values outside ``[0, 1]``
        extrapolate along the same geodesic (constant body-frame twist, i.e. a screw motion for
        SE3); Sola et al. 2018, Sec. III ("interpolation" via plus/minus).

        Parameters
        ----------
        other : same type, single or a batch matching ``self``
        alpha : float or (M,) float
            An array of ``M`` fractions yields a batch of ``M`` (broadcast against batches).

        Returns
        -------
        Same type; a batch if ``self``, ``other`` or ``alpha`` is one.
        """
        alphas = to_float_array(alpha, "interpolate alpha")
        if alphas.ndim > 1:
            raise GeometryError(f"interpolate alpha must be a scalar or (M,), got {alphas.shape}")
        delta = (self._inverse() @ other)._log()
        tau = alphas[..., None] * delta if alphas.ndim else alphas * delta
        return self @ self._exp(tau)

    # ----- containers ------------------------------------------------------------------------
    @property
    def is_batch(self) -> bool:
        """True when this value holds ``N`` elements (even ``N == 1``)."""
        return bool(self.batch_shape)

    def __len__(self) -> int:
        shape = self.batch_shape
        if not shape:
            raise TypeError(f"a single {type(self).__name__} has no len(); use .is_batch")
        return shape[0]

    def __getitem__(self, index: Index) -> Self:
        if not self.batch_shape:
            raise TypeError(f"a single {type(self).__name__} cannot be indexed")
        return self._index(index)

    def __iter__(self) -> Iterator[Self]:
        for i in range(len(self)):
            yield self._index(i)

    @classmethod
    def stack(cls, items: Sequence[Self]) -> Self:
        """One batch from single elements and/or batches, in order.

        Raises
        ------
        GeometryError
            If ``items`` is empty or holds another type.
        """
        items = list(items)
        if not items:
            raise GeometryError(f"{cls.__name__}.stack needs at least one element")
        for i, item in enumerate(items):
            if not isinstance(item, cls):
                raise GeometryError(f"{cls.__name__}.stack: item {i} is a {type(item).__name__}")
        return cls._concat(items)

    def allclose(self, other: Self, atol: float = 1e-9) -> bool:
        """True if the matrices of ``self`` and ``other`` agree within ``atol`` everywhere."""
        return bool(np.allclose(self.as_matrix(), other.as_matrix(), rtol=0.0, atol=atol))
