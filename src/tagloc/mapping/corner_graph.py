"""Corner reprojection factors, linearized: what the builder's final refinement minimizes.

PnP pose factors carry the per-observation PnP estimator's bias: at 0.3 px corner noise the PnP
range of a 0.16 m tag at 3-8 m is 0.2 % short on average (measured on the simulator), which
does not average out over observations and shrinks the whole map. So the builder refines the
pose-factor solution with the corners themselves: it minimizes

.. math:: \\sum_{m,i} \\rho\\left(\\lVert (\\pi_m(T_{cam,tag,m}\\, p_i) - z_{m,i}) / \\sigma
   \\rVert^2\\right) + \\text{odometry} + \\text{anchors}

(``rho`` the robust kernel on each corner's 2-D residual, through the real camera model).
This module linearizes the corners: residuals and Jacobians of every observation, the robust
kernel's cost and IRLS weights (:func:`kernel_cost`, :func:`kernel_weights`, also used for the
odometry and the tilt test) and the capped robust cost; :mod:`tagloc.mapping.refine` runs the
Gauss-Newton rounds. An observation whose corners are off by more than :data:`GROSS_CHI`
(whitened norm) is a false detection and pulls nothing: the Cauchy kernel's cost still decreases
when the map moves towards a detection hundreds of pixels off, and on the simulated office with
5 % glints that folded the map (tag RMS 0.19 m -> 0.61 m) until the cost was capped.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3, adjoint_h, hat, inverse_h
from tagloc.mapping.observations import Observations
from tagloc.tags.detection import tag_object_points

IntArray = npt.NDArray[np.int64]
#: An observation whose corners' whitened norm exceeds this at the linearization point is left
#: out of that round (a false detection far off, whose Cauchy cost would still reward moving
#: towards it: on the simulated office with 5 % glints, the map folded without this gate).
#: Simulated glints start at 470 (0.5 px sigma); a true view from a keyframe just after a
#: simulated foot slip measured 133 (with the gate at 30 it was left out and that keyframe
#: stayed 1.3 deg off).
GROSS_CHI = 200.0
#: ... and exceeds this multiple of the median over its tag's observations.
GROSS_RELATIVE = 5.0
#: Whitened squared residual of a corner that does not project (behind the camera).
UNPROJECTED = 1e6


def linearize_corners(
    obs: Observations,
    idx: IntArray,
    M_map_base: FloatArray,
    M_map_tag: FloatArray,
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
    sigma_px: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Whitened corner residuals and Jacobians of observations ``idx`` at the given poses.

    Parameters
    ----------
    obs : Observations
    idx : (n,) int
        Observations to linearize.
    M_map_base : (K, 4, 4) float
        Keyframes (indexed by ``obs.keyframe``).
    M_map_tag : (n, 4, 4) float
        The observed tag's pose, per observation.
    cameras, T_base_cam : mapping of str
    sigma_px : float
        Corner noise, pixels per axis.

    Returns
    -------
    r : (n, 4, 2) float
        ``(projected - detected) / sigma_px`` per corner; NaN where a corner does not project.
    J_r_xi : (n, 4, 2, 6) float
        ``d r / d xi`` for ``T_base_tag @ Exp(xi)``, ``xi = [x, y, z, rx, ry, rz]`` (zero where
        ``r`` is NaN).
    M_base_tag : (n, 4, 4) float
    """
    cams = np.array(obs.camera)[idx]
    M_base_cam = np.empty((len(idx), 4, 4))
    for name in np.unique(cams):
        M_base_cam[cams == name] = T_base_cam[str(name)].as_matrix()
    M_base_tag = inverse_h(M_map_base[obs.keyframe[idx]]) @ M_map_tag
    M_cam_tag = inverse_h(M_base_cam) @ M_base_tag
    points_tag = tag_object_points(1.0)[None] * obs.tag_sizes[obs.tag[idx]][:, None, None]
    R = M_cam_tag[:, :3, :3]
    p = np.einsum("mij,mnj->mni", R, points_tag) + M_cam_tag[:, None, :3, 3]
    px = np.full((len(idx), 4, 2), np.nan)
    J_px_p = np.zeros((len(idx), 4, 2, 3))
    for name in np.unique(cams):
        sel = cams == name
        with np.errstate(all="ignore"):
            a, b = cameras[str(name)].project_with_jacobian(p[sel].reshape(-1, 3))
        px[sel], J_px_p[sel] = a.reshape(-1, 4, 2), b.reshape(-1, 4, 2, 3)
    r = (px - obs.corners_px[idx]) / sigma_px
    J_p_xi = np.empty((len(idx), 4, 3, 6))
    J_p_xi[..., :3] = R[:, None]
    J_p_xi[..., 3:] = -np.einsum("mij,mnjl->mnil", R, hat(points_tag))
    J_r_xi = np.einsum("mnab,mnbc->mnac", np.nan_to_num(J_px_p), J_p_xi) / sigma_px
    J_r_xi[~np.isfinite(r).all(axis=2)] = 0.0
    return r, J_r_xi, M_base_tag


def corner_squares(r: FloatArray) -> FloatArray:
    """``(..., 4)`` whitened squared norm of each corner's 2-D residual ``r (..., 4, 2)``;
    :data:`UNPROJECTED` where it does not project."""
    s = np.sum(r**2, axis=-1)
    return np.asarray(np.where(np.isfinite(s), s, UNPROJECTED))


def kernel_weights(s: FloatArray, kind: str, k: float) -> FloatArray:
    """IRLS weights ``rho'(s)`` of whitened squared residuals ``s`` (NaN: weight 0), for the
    cost :func:`kernel_cost`."""
    ok = np.isfinite(s)
    s0 = np.where(ok, s, 0.0)
    if kind == "huber":
        w = np.minimum(1.0, k / np.maximum(np.sqrt(s0), 1e-12))
    else:
        w = 1.0 / (1.0 + s0 / k**2)
    return np.where(ok, w, 0.0)


def corner_cost(r: FloatArray, kind: str, k: float) -> FloatArray:
    """``(M,)`` robust cost ``sum_i rho(s_i)`` (``rho`` ~ ``s / 2`` for small ``s``) of each
    observation's corners, capped at the cost of :data:`GROSS_CHI` (beyond it an observation
    pulls no more: a false detection)."""
    s = corner_squares(r)
    cap = 4.0 * kernel_cost(np.array(GROSS_CHI**2 / 4.0), kind, k)
    return np.asarray(np.minimum(np.sum(kernel_cost(s, kind, k), axis=1), cap))


def kernel_cost(s: FloatArray, kind: str, k: float) -> FloatArray:
    """``rho(s)``: half the robust kernel's cost of whitened squared residuals ``s`` (``s / 2``
    for small ``s``; ``kind`` ``"huber"`` or ``"cauchy"``, width ``k`` sigmas). Its derivative
    is :func:`kernel_weights`."""
    if kind == "huber":
        a = np.sqrt(s)
        return np.asarray(np.where(a <= k, 0.5 * s, k * a - 0.5 * k**2))
    return np.asarray(0.5 * k**2 * np.log1p(s / k**2))


def gross_outliers(chi: FloatArray, tag: IntArray) -> npt.NDArray[np.bool_]:
    """``(M,)`` observations left out: off by more than :data:`GROSS_CHI` and by more than
    :data:`GROSS_RELATIVE` times the median of their tag's observations (when every view of a
    tag is off, the tag's estimate is wrong, not its views)."""
    median = np.zeros(int(tag.max()) + 1 if len(tag) else 0)
    for j in np.unique(tag):
        median[j] = np.median(chi[tag == j])
    return np.asarray((chi > GROSS_CHI) & (chi > GROSS_RELATIVE * median[tag]))


def corner_jacobians(
    r: FloatArray,
    J_r_xi: FloatArray,
    M_base_tag: FloatArray,
    tag: IntArray,
    kind: str,
    k: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """IRLS-weighted Gauss-Newton blocks of the corners: ``A_base, A_tag`` ``(M, 8, 6)``, ``b``
    ``(M, 8)`` with ``A_base d_base + A_tag d_tag ~ b`` (right perturbations of ``T_map_base``
    and ``T_map_tag``).

    ``J_r_xi`` (:func:`linearize_corners`) is the tag's block (``T_map_tag Exp(xi)`` perturbs
    ``T_base_tag`` the same way); the keyframe's is ``-J_r_xi Ad(T_base_tag^-1)``
    (``T_map_base Exp(xi)`` gives ``Exp(-xi) T_base_tag``). Rows are scaled by the square root
    of the kernel's weight; :func:`gross_outliers` get weight 0 (``tag``: tag index per row).
    """
    sqrt_w = np.sqrt(kernel_weights(np.sum(r**2, axis=2), kind, k))
    sqrt_w[gross_outliers(corner_chi(r), tag)] = 0.0
    b = -(np.nan_to_num(r) * sqrt_w[..., None]).reshape(-1, 8)
    A_tag = (J_r_xi * sqrt_w[..., None, None]).reshape(-1, 8, 6)
    A_base = -A_tag @ adjoint_h(inverse_h(M_base_tag))
    return A_base, A_tag, b


def corner_chi(r: FloatArray) -> FloatArray:
    """``(M,)`` whitened norm of each observation's 8 corner residuals (no kernel)."""
    return np.asarray(np.sqrt(np.sum(corner_squares(r), axis=1)))
