"""A fix that constrains only some directions: the filter's projected (partial) update.

A :class:`~tagloc.localize.fix.PartialFix` (a lidar scan match in a corridor, say) measures
``T_map_base`` only along the columns of an orthonormal basis ``B`` ``(6, k)`` of the base's
right tangent ``[x, y, z, rx, ry, rz]``: ``y = B^T Log(T_pred^-1 T_fix)`` with covariance
``C (k, k)``; nothing is said about the other directions (``N``, the orthogonal complement).

The update (:meth:`MapOdomEstimator.update_partial <tagloc.localize.estimator.
MapOdomEstimator.update_partial>`, gated by :meth:`FixPolicy.decide_partial
<tagloc.localize.policy.FixPolicy.decide_partial>`) is the estimator's iterated EKF
(:func:`~tagloc.localize.iekf.iterated_update`) on the ``k``-dimensional measurement
``(B^T nu, B^T H, C)``, gated on ``chi2.ppf(q, k)``. With the prior's cross-correlations the
optimal gain would also move the estimate along ``N`` (a y-innovation pulling x through a
correlated prior). It must not: an unconstrained direction has not been measured. So the gain
is the Schmidt ("consider") gain: in coordinates ``(B^T d, N^T d, dc)`` of the state's effect at
the fix's base (``d = Ad(A^-1) dx``, ``A = T_odom_base`` at the fix's stamp) the rows of ``N``
are zeroed, the others (and the odometry calibration's) stay optimal; the covariance follows
from the Joseph form with that gain (valid for any gain), so the variance along ``N`` is not
reduced by a measurement that did not see it. In the state's tangent this is the pose rows of
the gain premultiplied by the projector ``Pi = Ad(A) B B^T Ad(A^-1)`` (:func:`projector`).
After the iterations the total step is projected again (:func:`project_step`), so the pose
the state gives for the fix's odometry, ``X A``, moves exactly (to rounding) within ``span(B)``:
``Log((X0 A)^-1 (X A)) = B a``. A full-rank basis gives the plain update (``Pi = I``).

Planar mode (state ``x, y, yaw``) uses :func:`planar_constraint`: the information
``B C^-1 B^T`` with z, roll and pitch marginalized out (the planar filter ignores a fix's z,
roll and pitch, for a level base), re-expressed as a basis of ``[x, y, theta]`` and its
covariance.
"""

from __future__ import annotations

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SE2, SE3

__all__ = ["planar_constraint", "project_step", "projector"]

#: Planar axes of ``[x, y, z, rx, ry, rz]`` and the others.
_PLANAR, _OFF_PLANE = [0, 1, 5], [2, 3, 4]
#: Eigenvalues of the planar information below this fraction of the largest are unconstrained.
_REL_EIG = 1e-9


def planar_constraint(basis: FloatArray, cov: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The planar part of a partial fix: ``(basis (3, kp), cov (kp, kp))`` over ``[x, y, theta]``.

    The information ``L = B C^-1 B^T`` ``(6, 6)`` is marginalized over z, rx, ry (Schur
    complement ``L_pp - L_pn L_nn^+ L_np``, valid for a positive semi-definite ``L``); its
    eigenvectors with eigenvalue above ``1e-9`` of the largest are the planar basis, the
    inverse eigenvalues its (diagonal) covariance. ``kp = 0`` when nothing planar is measured.
    """
    info = basis @ np.linalg.solve(cov, basis.T)
    info = 0.5 * (info + info.T)
    pp = info[np.ix_(_PLANAR, _PLANAR)]
    pn = info[np.ix_(_PLANAR, _OFF_PLANE)]
    nn = info[np.ix_(_OFF_PLANE, _OFF_PLANE)]
    planar = pp - pn @ np.linalg.pinv(nn, rcond=1e-12, hermitian=True) @ pn.T
    w, V = np.linalg.eigh(0.5 * (planar + planar.T))
    keep = w > _REL_EIG * float(w.max()) if w.max() > 0 else np.zeros(3, dtype=bool)
    return V[:, keep], np.diag(1.0 / w[keep])


def projector(Ad_A_inv: FloatArray, basis: FloatArray) -> FloatArray:
    """``Pi = Ad(A) B B^T Ad(A^-1)`` ``(d, d)``: a step ``dx`` of the state ``T_map_odom`` moves
    the base at odometry ``A`` by ``Ad(A^-1) dx``; ``Pi dx`` keeps only its part in
    ``span(B)`` (``B`` orthonormal columns, ``(d, k)``)."""
    out = np.linalg.solve(Ad_A_inv, basis @ (basis.T @ Ad_A_inv))
    return np.asarray(out, dtype=np.float64)


def project_step(X0: SE3 | SE2, X: SE3 | SE2, Pi: FloatArray) -> SE3 | SE2:
    """``X0 (+) Pi (X (-) X0)``: the step from ``X0`` to ``X`` with its unconstrained part
    removed (exact in the tangent: ``Log((X0 A)^-1 (X' A)) = B B^T Ad(A^-1) Log(X0^-1 X)``)."""
    step = X.minus(X0)  # type: ignore[arg-type]
    return X0.plus(Pi @ step)
