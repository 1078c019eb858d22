"""The iterated error-state EKF step of the ``map -> odom`` estimator, as pure functions.

The state is a pose ``X`` (SE(3), or SE(2) in planar mode; tangent size ``d``) and the odometry
calibration ``c`` (``(nc,)``, ``nc`` 0 or 4), with covariance ``P`` ``(n, n)``, ``n = d + nc``
(:mod:`tagloc.localize.estimator`). A fix is a :class:`~tagloc.localize.candidate.Candidate`.

Update: iterated error-state EKF on the manifold (J. Sola, J. Deray, D. Atchuthan, "A micro Lie
theory for state estimation in robotics", 2018, arXiv:1812.01537, the ESKF with right
perturbations; iterated as Gauss-Newton, B. Bell and F. Cathey, IEEE TAC 1993)
    A fix ``z = T_map_base`` at ``t`` with covariance ``R``; ``A = T_odom_base(t)`` (a late fix
    composes with the odometry of its own time); ``h(X) = X @ A``; innovation
    ``nu = z (-) h(X) = Log(h^-1 z)``. A right perturbation of ``X`` moves ``h`` by
    ``Ad(A^-1)``: ``nu(X (+) dx) ~ nu - H_x dx`` with ``H_x = Jl^-1(nu) Ad(A^-1)``; an on-time
    fix does not see ``c`` (``H = [H_x, 0]``; a late one does, :func:`linearize`);
    ``S = H P H^T + R``; ``d2 = nu^T S^-1 nu``. Iterate from ``X_0 = X``: prior residual
    ``e = [X_i (-) X_0, c_i - c_0]``, ``m = -J e``, ``P_i = J P J^T``
    (``J = diag(Jr(X_i (-) X_0), I)``), ``K = P_i H^T S^-1``, ``dx = m + K (nu - H m)``,
    ``X_{i+1} = X_i (+) dx_x``, ``c_{i+1} = c_i + dx_c``, while the step seen at the base,
    ``|H dx|``, exceeds ``relinearize_tol``. Then
    ``P <- Jd [(I-KH) P_i (I-KH)^T + K R K^T] Jd^T`` with ``Jd = diag(Jr(dx_x), I)`` (Joseph
    form, then the reset to the tangent at the new ``X``); ``c`` is clamped to ``max_abs``.
Late fixes
    A fix older than the state is compared with the state moved back to its stamp,
    ``X (+) M c`` (``M`` of the path back; ``F``, ``Q`` of the path between the two stamps):
    if the state was only predicted since, the gain uses ``P - Q`` (the prior at the fix's
    stamp carried forward by ``F``; ``H`` maps back through ``M``) and ``Q`` is added back after
    the update, which for this linear model is exactly updating on time and then predicting;
    if a newer fix was applied meanwhile, the pose walk is added to the fix's noise instead,
    ``R <- R + H_x Q_x H_x^T`` (conservative).
Partial fixes
    A fix measuring only the directions ``basis`` uses ``(B^T nu, B^T H)`` and the Schmidt gain
    (:mod:`tagloc.localize.projected_update`).

Functions: :func:`linearize` (``nu`` and ``H``), :func:`innovate` (the gate's ``d2`` and what
the gain uses), :func:`iterated_update` (the iterations and the covariance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SE2
from tagloc.localize._series import jr as _jr
from tagloc.localize._series import jr_inv as _jr_inv
from tagloc.localize.candidate import Candidate, Pose
from tagloc.localize.motion import CalibrationModel, PathMotion
from tagloc.localize.projected_update import project_step, projector

__all__ = ["Innovation", "innovate", "iterated_update", "linearize"]


@dataclass(frozen=True, slots=True)
class Innovation:
    """A fix linearized at the state.

    Attributes
    ----------
    nu : (k,) float
        ``z (-) h(X)`` (``k = d``, or a partial fix's measured directions).
    H : (k, n) float
        Its Jacobian over the whole state (pose and calibration): ``nu(X (+) dx) ~ nu - H dx``.
    S_inv : (k, k) float
    R : (k, k) float
        The fix's noise as the update uses it (a late fix's may include the walk since).
    P_fix : (n, n) float
        The prior covariance the gain uses (the state's at the fix's stamp).
    M : (d, nc) float or None
        The calibration drift from the state's stamp to the fix's (None for a fix at the
        state's stamp or without calibration).
    d2 : float
        ``nu^T S^-1 nu``, the squared Mahalanobis distance the gates test.
    """

    nu: FloatArray
    H: FloatArray
    S_inv: FloatArray
    R: FloatArray
    P_fix: FloatArray
    M: FloatArray | None
    d2: float


def linearize(
    cand: Candidate, X: Pose, c: FloatArray, M: FloatArray | None
) -> tuple[FloatArray, FloatArray]:
    """Innovation ``nu = z (-) (X (+) u) @ A``, ``u = M c``, and its Jacobian ``H`` (d, n):
    ``nu(X (+) dx, c + dc) ~ nu - H [dx, dc]``, with ``H = [H_f Ad(Exp(-u)), H_f Jr(u) M]``
    and ``H_f = Jl^-1(nu) Ad(A^-1)`` (``Jl^-1(nu) = Jr^-1(-nu)``), the Jacobian at the
    state moved to the fix's stamp. ``M = None``: a fix at the state's stamp (``u = 0``,
    ``H = [H_f, 0]``); ``c`` of size 0 (no calibration): ``H = H_f``."""
    nc = len(c)
    X_fix = X  # the state moved to the fix's stamp
    if M is not None and nc:
        E, Jr_u = type(X).exp(M @ c, jacobians=True)
        X_fix = X @ E  # type: ignore[operator]
    nu = cand.z.minus(X_fix @ cand.A)  # type: ignore[operator, arg-type]
    H_f = _jr_inv(-nu) @ cand.Ad_A_inv
    if not nc:
        return nu, H_f
    if M is None:
        dof = len(nu)
        H = np.zeros((dof, dof + nc))
        H[:, :dof] = H_f
        return nu, H
    return nu, np.hstack([H_f @ E.inverse().adjoint(), H_f @ Jr_u @ M])


def innovate(
    cand: Candidate, X: Pose, c: FloatArray, P: FloatArray, back: PathMotion | None,
    Q_back: FloatArray | None, only_predicted: bool,
) -> Innovation:  # fmt: skip
    """Linearize a fix at the (augmented) state ``X, c, P``.

    A fix at the state's stamp (``back`` None) has ``H = [H_x, 0]`` over pose and calibration.
    A fix older than the state (``back``: the path from the state's stamp to the fix's;
    ``Q_back``: its walk of the whole state) is compared with the state moved back to its
    stamp, ``X (+) M c`` (``M`` of ``back``; :func:`linearize`, which sees ``c``). If the state
    was ``only_predicted`` since the fix's stamp, the gain uses the prior at that stamp carried
    forward, ``P - Q_back`` (exact for this linear model: the same as updating on time, then
    predicting); else (a newer fix was applied meanwhile), or if ``P - Q_back`` is not
    positive definite (a differently sampled path could overshoot), the pose walk is added to
    the fix's noise instead, ``R + H_x Q_x H_x^T`` (conservative)."""
    M = back.M if back is not None and len(c) else None
    nu, H = linearize(cand, X, c, M)
    P_fix, R = P, cand.R
    if cand.basis is not None:  # a partial fix: only its measured directions
        nu, H = cand.basis.T @ nu, cand.basis.T @ H
    if back is not None:
        assert Q_back is not None
        Hx = H[:, : len(back.Q)]
        if only_predicted:
            P_fix = P - Q_back
            try:  # a differently sampled path could overshoot: then the conservative way
                np.linalg.cholesky(P_fix)
            except np.linalg.LinAlgError:
                P_fix, R = P, R + Hx @ back.Q @ Hx.T
        else:
            R = R + Hx @ back.Q @ Hx.T
    S_inv = np.linalg.inv(H @ P_fix @ H.T + R).astype(np.float64, copy=False)
    return Innovation(nu, H, S_inv, R, P_fix, M, float(nu @ S_inv @ nu))


def iterated_update(
    cand: Candidate, innov: Innovation, X0: Pose, c0: FloatArray, P: FloatArray, *,
    max_iterations: int, tol: float, calibration: CalibrationModel | None,
) -> tuple[Pose, FloatArray, FloatArray]:  # fmt: skip
    """Iterated error-state update of the pose and the calibration (the estimator's module
    docstring); returns the new ``X``, ``c`` and ``P``.

    ``X0``, ``c0``, ``P``: the state the innovation was computed at (``P`` its covariance now:
    when the gain used ``innov.P_fix`` = ``P - Q_back``, the walk since the fix's stamp is added
    back after the update). Relinearizes while the step seen at the base, ``|H dx|``, exceeds
    ``tol``, at most ``max_iterations`` times. ``c`` is clamped to ``calibration.max_abs``."""
    P0, R, M = innov.P_fix, innov.R, innov.M
    dof = 3 if isinstance(X0, SE2) else 6
    n = len(P0)
    X, c, Pi, m = X0, c0, P0, None
    nu, H, S_inv = innov.nu, innov.H, innov.S_inv
    J = None  # Jr(e) of the relinearizations, made on the first
    Pr = None if cand.basis is None else projector(cand.Ad_A_inv, cand.basis)
    for i in range(max_iterations):
        if i:  # relinearize at X: prior mean and covariance moved into X's tangent
            e = X.minus(X0)  # type: ignore[arg-type]
            if J is None:
                J = np.eye(n)
            J[:dof, :dof] = _jr(e)
            m = -np.concatenate([J[:dof, :dof] @ e, c - c0])
            Pi = J @ P0 @ J.T
            nu, H = linearize(cand, X, c, M)
            if cand.basis is not None:
                nu, H = cand.basis.T @ nu, cand.basis.T @ H
            S_inv = np.linalg.inv(H @ Pi @ H.T + R).astype(np.float64, copy=False)
        K = Pi @ H.T @ S_inv
        if Pr is not None:  # Schmidt gain: no step along unmeasured directions
            K[:dof] = Pr @ K[:dof]
        dx = K @ nu if m is None else m + K @ (nu - H @ m)
        X_from, X_new, c_new = X, X.plus(dx[:dof]), c + dx[dof:]
        if float(np.abs(H @ dx).max()) <= tol:
            break
        X, c = X_new, c_new
    if Pr is not None:  # the total step, exactly within the measured directions
        X_new = project_step(X0, X_new, Pr)
        dx[:dof] = X_new.minus(X_from)  # type: ignore[arg-type]
    IKH = np.eye(n) - K @ H
    Jd = np.eye(n)
    Jd[:dof, :dof] = _jr(dx[:dof])
    Pn = Jd @ (IKH @ Pi @ IKH.T + K @ R @ K.T) @ Jd.T  # Joseph form, then the reset
    # Plus the walk since the fix's stamp when the gain used P - Q_back (the walk's
    # covariance, Ad(A) Q Ad(A)^T, does not depend on X: no reset for it).
    if P0 is not P:
        Pn = Pn + (P - P0)
    if calibration is not None and (np.abs(c_new) > calibration.max_abs).any():
        c_new = np.clip(c_new, -calibration.max_abs, calibration.max_abs)
    return X_new, c_new, 0.5 * (Pn + Pn.T)
