"""Levenberg-Marquardt on SE(3) for many pinhole PnP candidates at once (:func:`refine_poses`).

The residuals are pixel reprojection errors through the real (distorted) camera model; steps are
right perturbations ``T (+) xi`` applied with a Cayley retraction. Every candidate's arithmetic
is independent of the others in the batch (the batch only shares numpy calls).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import hat

BoolArray = npt.NDArray[np.bool_]

#: ``stop_early(R, t, sse) -> (freeze, settle)`` of :func:`refine_poses`.
StopRule = Callable[[FloatArray, FloatArray, FloatArray], tuple[BoolArray, BoolArray]]
_EYE6 = np.eye(6)


@dataclass(frozen=True, slots=True)
class Refinement:
    """Result of :func:`refine_poses` for ``K`` candidates of ``N`` points each.

    Attributes
    ----------
    R_cam_obj : (K, 3, 3) float
    t_cam_obj : (K, 3) float
    sse_px2 : (K,) float
        Sum of squared pixel residuals at the result (inf where the pose is invalid).
    jacobian : (K, 2N, 6) float
        ``d(residual)/d(xi)`` at the result, right perturbation ``[x, y, z, rx, ry, rz]``.
    R_initial, t_initial, sse_initial_px2, jacobian_initial
        The same at the initial poses.
    stopped : (K,) bool
        Candidates frozen by ``stop_early``.
    """

    R_cam_obj: FloatArray
    t_cam_obj: FloatArray
    sse_px2: FloatArray
    jacobian: FloatArray
    R_initial: FloatArray
    t_initial: FloatArray
    sse_initial_px2: FloatArray
    jacobian_initial: FloatArray
    stopped: BoolArray


_EYE3 = np.eye(3)


def _cayley(phi: FloatArray) -> FloatArray:
    """Rotations ``cay(phi)`` (K, 3, 3): ``Exp(phi)`` to first order, exactly orthonormal."""
    half = 0.5 * phi
    A = hat(half)
    scale = 2.0 / (1.0 + np.einsum("ki,ki->k", half, half))
    return np.asarray(_EYE3 + scale[:, None, None] * (A + A @ A), dtype=np.float64)


def _residuals(
    camera: CameraModel,
    R: FloatArray,
    t: FloatArray,
    points_obj: FloatArray,
    pixels: FloatArray,
    neg_hat_obj: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Residuals ``(K, 2N)``, Jacobians ``(K, 2N, 6)`` and SSE ``(K,)`` (inf where invalid).

    ``neg_hat_obj`` is ``-[p]x`` (K, N, 3, 3) of ``points_obj`` (computed if None).
    """
    k, n = points_obj.shape[:2]
    if neg_hat_obj is None:
        neg_hat_obj = hat(-points_obj)
    points_cam = np.einsum("kij,knj->kni", R, points_obj) + t[:, None, :]
    px, J_px_p = camera.project_with_jacobian(points_cam.reshape(-1, 3))
    J_p_xi = np.empty((k, n, 3, 6))
    J_p_xi[..., :3] = R[:, None]
    J_p_xi[..., 3:] = np.einsum("kij,knjl->knil", R, neg_hat_obj)
    J = (J_px_p.reshape(k, n, 2, 3) @ J_p_xi).reshape(k, 2 * n, 6)
    r = (px.reshape(k, n, 2) - pixels).reshape(k, 2 * n)
    sse = np.einsum("ki,ki->k", r, r)
    bad = ~np.isfinite(sse)
    if bad.any():
        sse[bad] = np.inf
        r[bad], J[bad] = 0.0, 0.0
    return r, J, sse


def _sse(
    camera: CameraModel, R: FloatArray, t: FloatArray, points_obj: FloatArray, pixels: FloatArray
) -> FloatArray:
    """SSE ``(K,)`` of :func:`_residuals` without the Jacobian (inf where invalid)."""
    points_cam = np.einsum("kij,knj->kni", R, points_obj) + t[:, None, :]
    r = camera.project(points_cam.reshape(-1, 3)).reshape(pixels.shape) - pixels
    sse = np.einsum("kni,kni->k", r, r)
    sse[~np.isfinite(sse)] = np.inf
    return np.asarray(sse)


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def refine_poses(
    R_cam_obj: FloatArray,
    t_cam_obj: FloatArray,
    points_obj: FloatArray,
    pixels: FloatArray,
    camera: CameraModel,
    max_iterations: int = 15,
    stop_early: StopRule | None = None,
) -> Refinement:
    """Levenberg-Marquardt on SE(3) for ``K`` poses at once, minimizing pixel reprojection error.

    Minimizes ``sum_i |project(R p_i + t) - pixel_i|^2`` over right perturbations
    ``T (+) xi`` (``J = J_px_point [R, -R [p]x]``). Steps apply a Cayley retraction (equal to
    ``Exp`` to first order, so the fixed points and the Jacobian at convergence are those of the
    right-perturbation model). A step is kept only if it lowers the cost (per candidate).

    Parameters
    ----------
    R_cam_obj : (K, 3, 3) float
    t_cam_obj : (K, 3) float
    points_obj : (K, N, 3) or (N, 3) float
        Points in the object frame (a tag's corners, or all corners in the map frame).
    pixels : (K, N, 2) or (N, 2) float
        Observed raw-image pixels.
    camera : CameraModel
    max_iterations : int
    stop_early : callable, optional
        ``stop_early(R, t, sse) -> (freeze, settle)``, two ``(K,)`` bool masks checked after
        every iteration: candidates to freeze as unusable (a branch that crossed into the other's
        basin; reported in ``Refinement.stopped``) and candidates to stop refining as they are
        (a branch already far worse than its rival, whose exact minimum matters to nobody).

    Returns
    -------
    Refinement
    """
    k = len(R_cam_obj)
    n = points_obj.shape[-2]
    points = np.broadcast_to(points_obj, (k, n, 3))
    observed = np.broadcast_to(pixels, (k, n, 2))
    neg_hat_obj = np.broadcast_to(hat(-points_obj), (k, n, 3, 3))
    # arrays are replaced, never written: the initial ones stay as they were
    R = R_init = np.array(R_cam_obj, dtype=np.float64)
    t = t_init = np.array(t_cam_obj, dtype=np.float64)
    r, J, sse = _residuals(camera, R, t, points, observed, neg_hat_obj)
    J0, sse0 = J, sse
    lam = np.full(k, 1e-3)
    done = np.zeros(k, dtype=bool)
    stopped = np.zeros(k, dtype=bool)
    moved = True  # J, r changed since H, g were formed
    for _ in range(max_iterations):
        if moved:
            H = np.swapaxes(J, 1, 2) @ J
            g = np.einsum("kij,ki->kj", J, r)
            diag = np.einsum("kii->ki", H)
            tiny = 1e-12 * (1.0 + diag)
        A = H + (lam[:, None] * diag + tiny)[:, :, None] * _EYE6
        step = -np.linalg.solve(A, g[:, :, None])[:, :, 0]
        # Gauss-Newton's predicted decrease; negligible -> converged without another evaluation
        done |= ~stopped & (-np.einsum("ki,ki->k", g, step) <= 1e-8 * sse + 1e-12)
        if (done | stopped).all():
            break
        R_new = R @ _cayley(step[:, 3:])
        t_new = t + np.einsum("kij,kj->ki", R, step[:, :3])
        r_new, J_new, sse_new = _residuals(camera, R_new, t_new, points, observed, neg_hat_obj)
        better = (sse_new < sse) & ~stopped
        moved = bool(better.any())
        if moved:
            gain = np.where(better, sse - sse_new, 0.0)
            if better.all():
                R, t, r, J, sse = R_new, t_new, r_new, J_new, sse_new
            else:
                R = np.where(better[:, None, None], R_new, R)
                t = np.where(better[:, None], t_new, t)
                r = np.where(better[:, None], r_new, r)
                J = np.where(better[:, None, None], J_new, J)
                sse = np.where(better, sse_new, sse)
            small = (gain <= 1e-7 * sse + 1e-12) | (np.abs(step).max(axis=1) < 1e-10)
            done |= better & small
        lam = np.where(better, lam * 0.2, lam * 10.0)
        done |= (lam > 1e10) | ~np.isfinite(sse)
        if stop_early is not None:
            freeze, settle = stop_early(R, t, sse)
            stopped |= ~done & freeze
            done |= settle
        if (done | stopped).all():
            break
    return Refinement(R, t, sse, J, R_init, t_init, sse0, J0, stopped)
