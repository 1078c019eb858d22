"""First-order covariance transport on SO(3), SE(3) and SE(2) (right perturbation).

A pose with covariance ``(T, C)`` means ``T_true = T @ Exp(d)``, ``d ~ N(0, C)``: ``C`` lives in the
body (right, local) tangent space of ``T``, in the tangent order of its type (SE(3):
``[x, y, z, rx, ry, rz]``; GTSAM's ``Pose3`` marginals are the same right-tangent covariance with
rotation first, i.e. ``C_tagloc = P C_gtsam P^T`` with ``P`` swapping the two 3-blocks).

Each function propagates through the Jacobians of :mod:`tagloc.geometry._lie`:
``C_out = sum_i J_out_i C_i J_out_i^T`` (inputs independent), to first order. Outputs are
symmetrized (``(C + C^T) / 2``). All functions accept single elements with ``(d, d)`` covariances
or batches with ``(N, d, d)`` (broadcast either way).

References: J. Sola et al., "A micro Lie theory for state estimation in robotics" (2018),
Sec. V-A (covariance propagation); T. Barfoot, P. Furgale, "Associating uncertainty with
three-dimensional poses for use in estimation problems" (IEEE T-RO 2014).
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import GeometryError
from tagloc.geometry._checks import check_finite, to_float_array
from tagloc.geometry._lie import LieGroup

G = TypeVar("G", bound=LieGroup)


def _cov(element: LieGroup, cov: npt.ArrayLike, name: str) -> FloatArray:
    array = to_float_array(cov, name)
    dof = element.DOF
    if array.ndim not in (2, 3) or array.shape[-2:] != (dof, dof):
        raise GeometryError(
            f"{name} for {type(element).__name__} must be ({dof}, {dof}) or (N, {dof}, {dof}), "
            f"got {array.shape}"
        )
    check_finite(array, name)
    return array


def _sandwich(jacobian: FloatArray, cov: FloatArray) -> FloatArray:
    return jacobian @ cov @ np.swapaxes(jacobian, -1, -2)


def _sym(cov: FloatArray) -> FloatArray:
    return 0.5 * (cov + np.swapaxes(cov, -1, -2))


def cov_right_to_left(T: LieGroup, cov: npt.ArrayLike) -> FloatArray:
    """Express a body-frame (right) covariance in the parent frame: ``Ad_T C Ad_T^T``.

    If ``T_true = T @ Exp(d)`` with ``d ~ N(0, C)``, then ``T_true = Exp(Ad_T d) @ T``: the
    left (global, parent-frame ``a`` of ``T_a_b``) perturbation ``Ad_T d`` has covariance
    ``Ad_T C Ad_T^T``. For SE(3) its translation block is the position covariance in frame ``a``
    (what a ROS ``PoseWithCovariance`` of ``b`` in ``a`` expects, up to the rotation block).

    Parameters
    ----------
    T : SO3, SE3 or SE2 (single or batch of N)
    cov : (d, d) or (N, d, d) float

    Returns
    -------
    (d, d) or (N, d, d) float

    Raises
    ------
    GeometryError
        On a covariance of the wrong shape or with NaN.
    """
    return _sym(_sandwich(T.adjoint(), _cov(T, cov, "cov")))


def cov_left_to_right(T: LieGroup, cov: npt.ArrayLike) -> FloatArray:
    """Inverse of :func:`cov_right_to_left`: ``Ad_T^-1 C Ad_T^-T`` (parent frame -> body frame).

    Shapes as in :func:`cov_right_to_left`.
    """
    return _sym(_sandwich(T.inverse().adjoint(), _cov(T, cov, "cov")))


def cov_inverse(T: LieGroup, cov: npt.ArrayLike) -> FloatArray:
    """Covariance of ``T^-1`` (right tangent of ``T^-1``) from that of ``T``: ``Ad_T C Ad_T^T``.

    ``J_{T^-1}_T = -Ad_T``, so e.g. the covariance of ``T_cam_tag`` from that of ``T_tag_cam``.

    Shapes as in :func:`cov_right_to_left`.
    """
    return _sym(_sandwich(T.adjoint(), _cov(T, cov, "cov")))


def cov_compose(T1: G, cov1: npt.ArrayLike, T2: G, cov2: npt.ArrayLike) -> FloatArray:
    """Covariance of ``T1 @ T2`` for independent ``T1``, ``T2``: ``Ad_T2^-1 C1 Ad_T2^-T + C2``.

    E.g. ``T_map_cam = T_map_base @ T_base_cam`` with the covariance of each factor in its own
    body frame. Pass zeros for a factor known exactly.

    Parameters
    ----------
    T1, T2 : same type, single or batches (broadcast)
    cov1, cov2 : (d, d) or (N, d, d) float

    Returns
    -------
    (d, d) or (N, d, d) float
    """
    return _first_plus_second(T1.compose(T2, jacobians=True)[1], T1, cov1, T2, cov2)


def cov_between(T1: G, cov1: npt.ArrayLike, T2: G, cov2: npt.ArrayLike) -> FloatArray:
    """Covariance of ``T1^-1 @ T2`` for independent ``T1``, ``T2``.

    ``Z = T1^-1 T2``: ``C_Z = Ad_Z^-1 C1 Ad_Z^-T + C2`` (``J_Z_T1 = -Ad_Z^-1``, ``J_Z_T2 = I``).

    ``T1``, ``T2``, ``cov1`` and ``cov2`` as in :func:`cov_compose`; returns the ``(d, d)`` or
    ``(N, d, d)`` covariance of the relative pose.
    """
    return _first_plus_second(T1.between(T2, jacobians=True)[1], T1, cov1, T2, cov2)


def _first_plus_second(
    J1: FloatArray, T1: LieGroup, cov1: npt.ArrayLike, T2: LieGroup, cov2: npt.ArrayLike
) -> FloatArray:
    """``J1 C1 J1^T + C2``: an output whose Jacobian in ``T2`` is the identity."""
    c1 = _cov(T1, cov1, "cov1")
    c2 = _cov(T2, cov2, "cov2")
    return _sym(_sandwich(J1, c1) + c2)
