"""A fix as the ``map -> odom`` estimator uses it: :class:`Candidate`, and the pairwise test.

A :class:`Candidate` is a fix (:class:`~tagloc.localize.fix.TagFix` or
:class:`~tagloc.localize.fix.PartialFix`) with the odometry ``T_odom_base`` at its stamp, both in
the estimator's group (SE(3), or their planar projections on SE(2)), and what follows from them:
the correction the fix implies, ``T_map_odom = z @ A^-1``, with its right-tangent covariance
``Ad(A) R Ad(A)^T``. The policy's consistency tests compare two of them (:func:`pair_d2`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SE2, SE3
from tagloc.localize.fix import PartialFix, TagFix
from tagloc.localize.projected_update import planar_constraint

__all__ = ["Candidate", "Pose", "mahalanobis_sq", "pair_d2"]

#: A state or measurement of the estimator: SE(3), or SE(2) in planar mode.
Pose = SE3 | SE2


def mahalanobis_sq(nu: FloatArray, S: FloatArray) -> float:
    """``nu^T S^-1 nu`` for an innovation ``nu (d,)`` with covariance ``S (d, d)``."""
    return float(nu @ np.linalg.solve(S, nu))


def pair_d2(a: Candidate, b: Candidate, Q_ab: FloatArray) -> float:
    """Squared Mahalanobis distance between the corrections two fixes imply (``Q_ab``: the
    random walk between their stamps); the pairwise test of
    :class:`~tagloc.localize.gating.ConsistencyBuffer`."""
    if a.stamp_ns > b.stamp_ns:
        a, b = b, a
    e, J_e_b, J_e_a = b.T_map_odom.minus(a.T_map_odom, jacobians=True)  # type: ignore[call-overload]
    S = J_e_a @ a.cov @ J_e_a.T + J_e_b @ b.cov @ J_e_b.T + Q_ab
    return mahalanobis_sq(e, S)


@dataclass(frozen=True, eq=False)
class Candidate:
    """A fix with what the estimator derived from it (the derived values computed on first use).

    Attributes
    ----------
    fix : TagFix or PartialFix
    odom : SE3
        ``T_odom_base`` at the fix's stamp.
    A : SE3 or SE2
        The same as the estimator uses it (its planar projection in planar mode).
    z, R : SE3 or SE2, (d, d) float
        The measurement and its covariance as the estimator uses them (projected in planar
        mode); for a partial fix ``R`` is ``(k, k)``, the covariance along ``basis``.
    basis : (d, k) float, optional
        A partial fix's measured directions in the estimator's tangent (None: all of them).
    """

    fix: TagFix | PartialFix
    odom: SE3
    A: Pose
    z: Pose
    R: FloatArray
    basis: FloatArray | None = None

    @classmethod
    def of_fix(cls, fix: TagFix, odom: SE3, planar: bool) -> Candidate:
        """A full fix; planar: ``z`` and ``R`` are the fix's planar projection
        (:meth:`TagFix.to_planar <tagloc.localize.fix.TagFix.to_planar>`), ``A`` the
        odometry's."""
        if planar:
            z, R = fix.to_planar()
            return cls(fix, odom, SE2.from_se3(odom), z, R)
        return cls(fix, odom, odom, fix.T_map_base, np.asarray(fix.cov))

    @classmethod
    def of_partial(cls, fix: PartialFix, odom: SE3, planar: bool) -> Candidate:
        """A partial fix; planar: its measured directions in the plane with z, roll and pitch
        marginalized out (:func:`~tagloc.localize.projected_update.planar_constraint`; the
        basis may then have no column)."""
        if planar:
            basis, R = planar_constraint(fix.basis, fix.cov)
            return cls(fix, odom, SE2.from_se3(odom), SE2.from_se3(fix.T_map_base), R, basis)
        return cls(fix, odom, odom, fix.T_map_base, fix.cov, fix.basis)

    @property
    def stamp_ns(self) -> int:
        return self.fix.stamp_ns

    @functools.cached_property
    def Ad_A_inv(self) -> FloatArray:
        """``Ad(A^-1)``: a right perturbation of ``T_map_odom`` seen at the base."""
        A = self.A
        if isinstance(A, SE2):
            return A.inverse().adjoint()
        Rt = A.rotation.matrix.T  # Ad(A^-1) = [[R^T, -R^T [t]x], [0, R^T]]
        x, y, z = A.translation.tolist()
        out = np.zeros((6, 6))
        out[:3, :3] = out[3:, 3:] = Rt
        out[:3, 3:] = Rt @ np.array([[0.0, z, -y], [-z, 0.0, x], [y, -x, 0.0]])
        return out

    @functools.cached_property
    def T_map_odom(self) -> Pose:
        """The correction the fix implies, ``z @ A^-1``."""
        return self.z @ self.A.inverse()  # type: ignore[operator]

    @functools.cached_property
    def cov(self) -> FloatArray:
        """Right-tangent covariance of :attr:`T_map_odom`: ``Ad(A) R Ad(A)^T``."""
        Ad = self.A.adjoint()
        out: FloatArray = Ad @ self.R @ Ad.T
        return out
