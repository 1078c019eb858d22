"""Tag poses from corners: IPPE (both solutions), refined in pixels; joint PnP over many tags.

Single tag (:func:`estimate_tag_poses`, all tags of a frame in one vectorized pass):

1. Undistort the corners to normalized coordinates with the camera model.
2. ``cv2.solvePnPGeneric(..., flags=cv2.SOLVEPNP_IPPE_SQUARE)`` with ``K = I`` and no distortion
   gives *both* solutions of the planar two-fold ambiguity (T. Collins, A. Bartoli,
   "Infinitesimal Plane-Based Pose Estimation", IJCV 109(3), 2014).
3. Refine each with Levenberg-Marquardt on SE(3) (right perturbation) minimizing the *pixel*
   reprojection error through the distorted camera model (``camera.project_with_jacobian``):
   IPPE is a first-order method and its tilt is poor for near face-on tags.
4. Rank by refined error, compute both covariances (:mod:`tagloc.tags.covariance`).

Object points: :func:`~tagloc.tags.detection.tag_object_points` is exactly IPPE_SQUARE's order
and axes (0 ``(-s/2, s/2, 0)``, 1 ``(s/2, s/2, 0)``, 2 ``(s/2, -s/2, 0)``, 3 ``(-s/2, -s/2, 0)``;
tag x right, y up, z out of the face), so ``rvec, tvec`` are ``T_cam_tag`` unchanged (tested).

Reprojection error: RMS over the corners of the Euclidean pixel residual,
``sqrt(SSE / n_corners)``; ``SSE`` sums ``2 n_corners`` residual components (8 for one tag, 6 dof).

Joint PnP (:func:`estimate_joint_pose`): the same refinement on all corners of all tags of known
map pose, started from the best-fitting branches of the tags, solved in a frame at the corners'
centroid (map axes) so that the covariance's natural origin is where the tags are.

Both run :func:`solve_branches`: refine every candidate, keep the best minimum and the best
*other* minimum (else the worst raw candidate), measure the valley between them, and compute
both covariances.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.geometry.small_batch import se3_minus, se3_plus
from tagloc.tags.covariance import (
    NoiseModel,
    map_base_from_cam,
    map_cam_from_tag,
    pose_covariance,
    pose_covariance_and_lobe,
)
from tagloc.tags.detection import TagDetection, tag_object_points
from tagloc.tags.errors import TagError

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: A refined alternative within this rotation angle of the best one is the same minimum.
_SAME_MINIMUM_RAD = 1e-3
#: A branch this much worse than its rival (SSE / sigma_px^2, chi-square units: 4x the default
#: ambiguity threshold) after 3 iterations stops refining: its exact minimum decides nothing.
_SETTLE_CHI2 = 75.0
#: ``stop_early(R, t, sse) -> (freeze, settle)`` of :func:`refine_poses`.
StopRule = Callable[[FloatArray, FloatArray, FloatArray], tuple[BoolArray, BoolArray]]
_EYE6 = np.eye(6)


class TagPoseError(TagError, ValueError):
    """A tag whose corners give no pose (outside the camera model, degenerate, behind)."""


@dataclass(frozen=True, slots=True, eq=False)
class TagPoseEstimate:
    """Pose of one tag in the camera optical frame, both IPPE branches, with covariance.

    Attributes
    ----------
    tag_id : int
    size : float
        Black-border edge length used, metres.
    T_cam_tag, T_cam_tag_alt : SE3
        Chosen pose (lowest refined reprojection error, unless a policy swapped them) and the
        other branch of the two-fold ambiguity (refined; the raw IPPE one if refinement took it
        into the chosen minimum).
    reproj_err_px, reproj_err_alt_px : float
        RMS corner reprojection error (pixels, through the real camera model) of each.
    ambiguity_ratio : float
        ``reproj_err_px / reproj_err_alt_px``: <= 1 from PnP (0 if there is no alternative);
        > 1 only after a policy chose the alternative (:meth:`swapped`).
    cov_cam_tag, cov_cam_tag_alt : (6, 6) float
        Covariance in the right tangent of each pose, ``[x, y, z, rx, ry, rz]``:
        ``T_true = T_cam_tag @ Exp(d)``, ``d ~ N(0, cov)`` (so the translation block is in the tag
        frame), given that branch (:func:`tagloc.tags.covariance.pose_covariance`). Estimates
        accepted by :func:`tagloc.tags.observation.observe_tags` also carry the other branch's
        posterior weight (:func:`tagloc.tags.covariance.ambiguity_mixture`). For ``T_map_cam`` /
        ``T_map_base`` use :func:`tagloc.tags.covariance.map_cam_from_tag`.
    range_m : float
        Distance camera center to tag center.
    view_angle_rad : float
        Angle between the tag normal (its +z) and the ray from the tag to the camera.
    cov_rot_laplace, cov_rot_laplace_alt : (3, 3) float
        Rotation block of each branch's likelihood lobe: ``sigma^2 (J^T J)^-1`` plus the valley
        term towards the other branch (no other inflation). The ambiguity policy weighs a prior
        with it (:func:`tagloc.tags.gates.prior_evidence`).
    """

    tag_id: int
    size: float
    T_cam_tag: SE3
    T_cam_tag_alt: SE3
    reproj_err_px: float
    reproj_err_alt_px: float
    ambiguity_ratio: float
    cov_cam_tag: FloatArray
    cov_cam_tag_alt: FloatArray
    range_m: float
    view_angle_rad: float
    cov_rot_laplace: FloatArray
    cov_rot_laplace_alt: FloatArray

    @property
    def sse_px2(self) -> float:
        """Sum of squared pixel residuals of ``T_cam_tag`` (8 components)."""
        return 4.0 * self.reproj_err_px**2

    @property
    def sse_alt_px2(self) -> float:
        """Sum of squared pixel residuals of ``T_cam_tag_alt``."""
        return 4.0 * self.reproj_err_alt_px**2

    def with_covariance(self, cov_cam_tag: FloatArray) -> TagPoseEstimate:
        """The same estimate with ``cov_cam_tag`` replaced (``dataclasses.replace``, faster)."""
        return TagPoseEstimate(
            self.tag_id,
            self.size,
            self.T_cam_tag,
            self.T_cam_tag_alt,
            self.reproj_err_px,
            self.reproj_err_alt_px,
            self.ambiguity_ratio,
            cov_cam_tag,
            self.cov_cam_tag_alt,
            self.range_m,
            self.view_angle_rad,
            self.cov_rot_laplace,
            self.cov_rot_laplace_alt,
        )

    def swapped(self) -> TagPoseEstimate:
        """The same estimate with the alternative branch chosen (range, angle recomputed)."""
        alt = self.T_cam_tag_alt
        range_m, angle = _range_and_view_angle(alt.rotation.matrix, alt.translation)
        return TagPoseEstimate(
            self.tag_id,
            self.size,
            alt,
            self.T_cam_tag,
            self.reproj_err_alt_px,
            self.reproj_err_px,
            _ratio(self.reproj_err_alt_px, self.reproj_err_px),
            self.cov_cam_tag_alt,
            self.cov_cam_tag,
            float(range_m),
            float(angle),
            self.cov_rot_laplace_alt,
            self.cov_rot_laplace,
        )


@dataclass(frozen=True, slots=True, eq=False)
class JointPoseEstimate:
    """Camera pose in the map from all corners of several tags (:func:`estimate_joint_pose`).

    Attributes
    ----------
    tag_ids : tuple of int
    T_map_cam, T_map_cam_alt : SE3
        Best minimum and the best other one (the worst start if there is no other minimum).
    cov_map_cam, cov_map_cam_alt : (6, 6) float
        Right-tangent covariances of each, ``[x, y, z, rx, ry, rz]`` (camera frame).
    reproj_err_px, reproj_err_alt_px : float
        RMS corner reprojection errors (``inf``: no alternative).
    cov_rot_laplace, cov_rot_laplace_alt : (3, 3) float
        Laplace rotation covariances in the right tangent of ``T_cam_map`` (map frame axes).
    n_corners : int
    T_map_base : SE3 or None
        ``T_map_cam @ T_base_cam^-1`` if extrinsics were given.
    cov_map_base : (6, 6) float or None
        Its right-tangent covariance.
    """

    tag_ids: tuple[int, ...]
    T_map_cam: SE3
    cov_map_cam: FloatArray
    reproj_err_px: float
    T_map_cam_alt: SE3
    cov_map_cam_alt: FloatArray
    reproj_err_alt_px: float
    cov_rot_laplace: FloatArray
    cov_rot_laplace_alt: FloatArray
    n_corners: int
    T_map_base: SE3 | None = None
    cov_map_base: FloatArray | None = None

    @property
    def sse_px2(self) -> float:
        """Sum of squared pixel residuals (``2 n_corners`` components)."""
        return self.n_corners * self.reproj_err_px**2

    @property
    def sse_alt_px2(self) -> float:
        """The same for the alternative."""
        return self.n_corners * self.reproj_err_alt_px**2

    @property
    def ambiguity_ratio(self) -> float:
        """``reproj_err_px / reproj_err_alt_px`` (0 without alternative)."""
        return _ratio(self.reproj_err_px, self.reproj_err_alt_px)

    def swapped(self) -> JointPoseEstimate:
        """The alternative chosen instead (``T_map_base`` is dropped: recompute it)."""
        return JointPoseEstimate(
            self.tag_ids,
            self.T_map_cam_alt,
            self.cov_map_cam_alt,
            self.reproj_err_alt_px,
            self.T_map_cam,
            self.cov_map_cam,
            self.reproj_err_px,
            self.cov_rot_laplace_alt,
            self.cov_rot_laplace,
            self.n_corners,
        )


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


#: ``[v]x.reshape(9) = v @ _HAT_BASIS``: each entry is one component (or zero), exactly.
_HAT_BASIS = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    ]
)
_EYE3 = np.eye(3)


def _hat(v: FloatArray) -> FloatArray:
    """``[v]x`` of (..., 3) vectors, (..., 3, 3)."""
    return np.asarray(v @ _HAT_BASIS).reshape(*v.shape[:-1], 3, 3)


def _cayley(phi: FloatArray) -> FloatArray:
    """Rotations ``cay(phi)`` (K, 3, 3): ``Exp(phi)`` to first order, exactly orthonormal."""
    half = 0.5 * phi
    A = _hat(half)
    scale = 2.0 / (1.0 + np.einsum("ki,ki->k", half, half))
    return np.asarray(_EYE3 + scale[:, None, None] * (A + A @ A), dtype=np.float64)


def _residuals(
    camera: CameraModel,
    R: FloatArray,
    t: FloatArray,
    points_obj: FloatArray,
    pixels: FloatArray,
    hat_obj: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Residuals ``(K, 2N)``, Jacobians ``(K, 2N, 6)`` and SSE ``(K,)`` (inf where invalid).

    ``hat_obj`` is ``[p]x`` (K, N, 3, 3) of ``points_obj`` (computed if None).
    """
    k, n = points_obj.shape[:2]
    if hat_obj is None:
        hat_obj = _hat(points_obj)
    points_cam = np.einsum("kij,knj->kni", R, points_obj) + t[:, None, :]
    px, J_px_p = camera.project_with_jacobian(points_cam.reshape(-1, 3))
    J_p_xi = np.empty((k, n, 3, 6))
    J_p_xi[..., :3] = R[:, None]
    J_p_xi[..., 3:] = -np.einsum("kij,knjl->knil", R, hat_obj)
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
    hat_obj = np.broadcast_to(_hat(points_obj), (k, n, 3, 3))
    # arrays are replaced, never written: the initial ones stay as they were
    R = R_init = np.array(R_cam_obj, dtype=np.float64)
    t = t_init = np.array(t_cam_obj, dtype=np.float64)
    r, J, sse = _residuals(camera, R, t, points, observed, hat_obj)
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
        r_new, J_new, sse_new = _residuals(camera, R_new, t_new, points, observed, hat_obj)
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


def _range_and_view_angle(R: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Range ``|t|`` and the angle between the tag normal ``R[:, 2]`` and the ray ``-t``."""
    range_m = np.linalg.norm(t, axis=-1)
    with np.errstate(all="ignore"):
        cos_angle = -np.einsum("...i,...i->...", R[..., :, 2], t) / range_m
    return range_m, np.arccos(np.clip(cos_angle, -1.0, 1.0))


def _ratio(err: float, err_alt: float) -> float:
    """``err / err_alt`` with ``0 / 0 = 1`` (two exact fits) and ``x / inf = 0``."""
    if err_alt == 0.0:
        return 1.0 if err == 0.0 else float("inf")
    return float(err / err_alt)


def _ippe_square(normalized: FloatArray, points_tag: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Both IPPE_SQUARE solutions ``(2, 3, 3)``, ``(2, 3)`` for one tag (NaN if none)."""
    R = np.full((2, 3, 3), np.nan)
    t = np.full((2, 3), np.nan)
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            points_tag, normalized, np.eye(3), None, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
    except cv2.error:
        return R, t
    for i in range(min(int(n), 2)):
        R[i] = cv2.Rodrigues(rvecs[i])[0]
        t[i] = np.ravel(tvecs[i])
    if int(n) == 1:
        R[1], t[1] = R[0], t[0]
    return R, t


@dataclass(frozen=True, slots=True)
class Branches:
    """Best and alternative minimum of ``K`` PnP problems (:func:`solve_branches`).

    Attributes
    ----------
    R, t : (K, 2, 3, 3), (K, 2, 3) float
        ``T_cam_obj`` of the best (index 0) and the alternative (1) branch.
    sse_px2 : (K, 2) float
        Their SSE (``inf``: none / invalid).
    cov, cov_rot_laplace : (K, 2, 6, 6), (K, 2, 3, 3) float
        Full and Laplace covariances (see :class:`TagPoseEstimate`).
    view_angle : (K, 2) float
    T_best, T_alt : SE3, batches of K
    """

    R: FloatArray
    t: FloatArray
    sse_px2: FloatArray
    cov: FloatArray
    cov_rot_laplace: FloatArray
    view_angle: FloatArray
    T_best: SE3
    T_alt: SE3


def _plus(T: SE3, tau: FloatArray) -> SE3:
    """``T.plus(tau)`` (which raises on NaN / inf) through the small-batch fast path."""
    return se3_plus(T, tau) if np.isfinite(tau).all() else T.plus(tau)


def _as_se3(R: FloatArray, t: FloatArray) -> SE3:
    """The solver's rotations are orthonormal by construction (Cayley steps from IPPE's)."""
    return SE3.from_trusted(R, t)


def _pick_branches(
    ref: Refinement, valid: BoolArray, k: int, c: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Best refined minimum and best *distinct* one; without one, the worst other start."""
    R, t = ref.R_cam_obj.reshape(k, c, 3, 3), ref.t_cam_obj.reshape(k, c, 3)
    sse_initial = ref.sse_initial_px2.reshape(k, c)
    sse = np.where(valid & ~ref.stopped.reshape(k, c), ref.sse_px2.reshape(k, c), np.inf)
    J = ref.jacobian.reshape(k, c, *ref.jacobian.shape[1:])
    rows = np.arange(k)
    first = np.argmin(sse, axis=1)
    cos_rel = (np.einsum("kij,kcij->kc", R[rows, first], R) - 1.0) / 2.0
    far = _norm(t - t[rows, first][:, None])
    distinct = (cos_rel < np.cos(_SAME_MINIMUM_RAD)) | (far > 1e-3 * _norm(t))
    # within the best minimum, the start that was already best represents it
    raw_sse = np.where(valid, sse_initial, np.inf)
    best = np.argmin(np.where(~distinct & np.isfinite(sse), raw_sse, np.inf), axis=1)
    alt = np.argmin(np.where(distinct, sse, np.inf), axis=1)
    has_alt = np.isfinite(sse[rows, alt]) & distinct[rows, alt]
    pick = np.empty((k, 2), dtype=np.intp)
    pick[:, 0], pick[:, 1] = best, alt
    R_out, t_out = R[rows[:, None], pick], t[rows[:, None], pick]
    sse_out, J_out = sse[rows[:, None], pick], J[rows[:, None], pick]
    if has_alt.all():
        return R_out, t_out, sse_out, J_out
    other_raw = np.where(valid, sse_initial, -np.inf)
    other_raw[rows, best] = -np.inf
    raw = np.argmax(other_raw, axis=1)
    fb = ~has_alt & np.isfinite(other_raw[rows, raw]) & np.isfinite(sse[rows, best])
    if fb.any():
        R0, t0 = ref.R_initial.reshape(k, c, 3, 3), ref.t_initial.reshape(k, c, 3)
        R_out[fb, 1], t_out[fb, 1] = R0[fb, raw[fb]], t0[fb, raw[fb]]
        J_out[fb, 1] = ref.jacobian_initial.reshape(J.shape)[fb, raw[fb]]
        sse_out[fb, 1] = other_raw[fb, raw[fb]]
    sse_out[~has_alt & ~fb, 1] = np.inf
    return R_out, t_out, sse_out, J_out


def _norm(v: FloatArray) -> FloatArray:
    """``np.linalg.norm(v, axis=-1)`` (the same sum and root) without its overhead."""
    return np.asarray(np.sqrt((v * v).sum(axis=-1)))


def _pair_rule(R_start: FloatArray, settle_px2: float) -> StopRule:
    """``stop_early`` for pairs of starts ``(K, 2, 3, 3)`` (the two IPPE branches of a tag, or
    the two joint starts). Freeze a candidate that came within 35 % of the starting angle to
    the other start (it crossed into that basin); after three iterations, settle one whose SSE
    is more than ``settle_px2`` above its rival's (no policy would call that pair ambiguous)."""
    other = R_start[:, ::-1].reshape(-1, 3, 3)
    start_cos = np.einsum("kij,kij->k", R_start.reshape(-1, 3, 3), other)
    start_angle = np.arccos(np.clip((start_cos - 1.0) / 2.0, -1.0, 1.0))
    calls = [0]

    def rule(R: FloatArray, t: FloatArray, sse: FloatArray) -> tuple[BoolArray, BoolArray]:
        calls[0] += 1
        angle = np.arccos(np.clip((np.einsum("kij,kij->k", R, other) - 1.0) / 2.0, -1.0, 1.0))
        freeze = (angle < 0.35 * start_angle) & (start_angle > 0.05)
        rival = sse.reshape(-1, 2)[:, ::-1].reshape(-1)
        settle = (sse > rival + settle_px2) & (calls[0] >= 3)
        return np.asarray(freeze, dtype=bool), np.asarray(settle, dtype=bool)

    return rule


def branch_valley(
    camera: CameraModel,
    T_best: SE3,
    T_alt: SE3,
    sse: FloatArray,
    points_obj: FloatArray,
    pixels: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Tangents between the two branches of ``K`` problems and the cost barrier between them.

    Parameters
    ----------
    camera : CameraModel
    T_best, T_alt : SE3, batches of K
        ``T_cam_obj`` of the two branches.
    sse : (K, 2) float
        Their sums of squared pixel residuals.
    points_obj : (K, N, 3) float
    pixels : (K, N, 2) float

    Returns
    -------
    delta : (K, 2, 6) float
        ``T_other (-) T`` from each branch to the other.
    barrier : (K, 2) float
        SSE at the geodesic midpoint minus each branch's SSE (pixels^2).
    """
    delta = se3_minus(T_alt, T_best)
    mid = _plus(T_best, 0.5 * delta)
    points_cam = mid.act(points_obj)
    r = camera.project(points_cam.reshape(-1, 3)).reshape(pixels.shape) - pixels
    sse_mid = np.einsum("kni,kni->k", r, r)
    sse_mid[~np.isfinite(sse_mid)] = np.inf
    return np.stack([delta, -delta], axis=1), sse_mid[:, None] - sse


def _branch_covariances(
    camera: CameraModel,
    R: FloatArray,
    t: FloatArray,
    J: FloatArray,
    points: FloatArray,
    pixels: FloatArray,
    delta: FloatArray,
    barrier: FloatArray,
    extent_px: FloatArray,
    view_angle: FloatArray,
    noise: NoiseModel,
) -> tuple[FloatArray, FloatArray]:
    """Covariances ``(K, 2, 6, 6)`` of both branches: :func:`pose_covariance` at the branch, and
    again with the Jacobian taken two sigmas towards the other branch; the one wider along
    ``delta`` is kept. Near face-on the tilt information grows like ``sin^2`` of the tilt, so
    the Jacobian at an estimate whose tilt came out large overstates what the pixels know (NEES
    at 3-6 m and 10-15 deg: ~10 -> ~5; elsewhere the two agree). Also the lobes' rotation
    covariances ``(K, 2, 3, 3)``: ``sigma^2 (J^T J)^-1`` plus the valley term."""
    k, n = points.shape[:2]
    J2 = J.reshape(2 * k, 2 * n, 6)
    args = (
        R.reshape(-1, 3, 3),
        t.reshape(-1, 3),
        np.repeat(extent_px, 2),
        noise,
        view_angle.reshape(-1),
        delta.reshape(-1, 6),
        barrier.reshape(-1),
    )
    cov, lobe = pose_covariance_and_lobe(J2, *args)
    d = delta.reshape(-1, 6)
    laplace = lobe[:, 3:, 3:]
    spread = np.einsum("ki,kij,kj->k", d, cov, d)
    with np.errstate(all="ignore"):
        s = 2.0 * np.sqrt(np.maximum(spread, 0.0)) / np.einsum("ki,ki->k", d, d)
    s = np.where(np.isnan(s), 0.0, np.minimum(s, 0.5))  # nan_to_num, then at most 0.5
    # only where the shift turns the pose by more than ~2 deg does the information change
    rows = np.flatnonzero((s * np.linalg.norm(d[:, 3:], axis=1) > 0.03) & np.isfinite(spread))
    if len(rows):
        T = SE3.from_trusted(R.reshape(-1, 3, 3)[rows], t.reshape(-1, 3)[rows])  # 2i + b: branch b
        shifted = _plus(T, s[rows, None] * d[rows])
        _, J_shift, _ = _residuals(
            camera,
            shifted.rotation.matrix,
            shifted.translation,
            np.repeat(points, 2, axis=0)[rows],
            np.repeat(pixels, 2, axis=0)[rows],
        )
        sub = tuple(a[rows] if isinstance(a, np.ndarray) else a for a in args)
        cov_shift = pose_covariance(J_shift, *sub)  # type: ignore[arg-type]
        wider = np.einsum("ki,kij,kj->k", d[rows], cov_shift, d[rows]) > spread[rows]
        cov[rows[wider]] = cov_shift[wider]
    return cov.reshape(k, 2, 6, 6), laplace.reshape(k, 2, 3, 3)


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def solve_branches(
    R0: FloatArray,
    t0: FloatArray,
    valid0: BoolArray,
    points_obj: FloatArray,
    pixels: FloatArray,
    camera: CameraModel,
    noise: NoiseModel,
    extent_px: FloatArray,
    view_angle: FloatArray | None = None,
) -> Branches:
    """Refine ``C`` candidates of each of ``K`` PnP problems; best and alternative branch.

    Parameters
    ----------
    R0, t0 : (K, C, 3, 3), (K, C, 3) float
        Initial ``T_cam_obj`` candidates.
    valid0 : (K, C) bool
    points_obj : (K, N, 3) float
    pixels : (K, N, 2) float
    camera : CameraModel
    noise : NoiseModel
    extent_px : (K,) float
        Apparent target size for the systematic-error term.
    view_angle : (K,) float, optional
        Tag viewing angle for the noise model; default from each branch's pose (single tags).

    Returns
    -------
    Branches
    """
    k, c = valid0.shape
    n = points_obj.shape[1]
    R0 = np.where(valid0[..., None, None], R0, np.eye(3))
    t0 = np.where(valid0[..., None], t0, np.array([0.0, 0.0, 1.0]))
    stop = _pair_rule(R0, _SETTLE_CHI2 * noise.sigma_px**2) if c == 2 else None
    ref = refine_poses(
        R0.reshape(-1, 3, 3),
        t0.reshape(-1, 3),
        np.repeat(points_obj, c, axis=0),
        np.repeat(pixels, c, axis=0),
        camera,
        stop_early=stop,
    )
    R, t, sse, J = _pick_branches(ref, valid0, k, c)
    ok, alt_ok = np.isfinite(sse[:, 0]), np.isfinite(sse[:, 1])
    R[~alt_ok, 1], t[~alt_ok, 1] = R[~alt_ok, 0], t[~alt_ok, 0]
    T_best, T_alt = _as_se3(R[:, 0], t[:, 0]), _as_se3(R[:, 1], t[:, 1])
    delta, barrier = branch_valley(camera, T_best, T_alt, sse, points_obj, pixels)
    barrier[~alt_ok] = np.inf
    if view_angle is None:
        angle = _range_and_view_angle(R, t)[1]
    else:
        angle = np.repeat(np.asarray(view_angle, dtype=np.float64)[:, None], 2, axis=1)
    cov, laplace = _branch_covariances(
        camera,
        R,
        t,
        J.reshape(k, 2, 2 * n, 6),
        points_obj,
        pixels,
        delta,
        barrier,
        extent_px,
        angle,
        noise,
    )
    cov[~ok] = np.nan
    return Branches(R, t, sse, cov, laplace, angle, T_best, T_alt)


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def estimate_tag_poses(
    tag_ids: Sequence[int],
    corners_px: npt.ArrayLike,
    sizes: npt.ArrayLike,
    camera: CameraModel,
    noise: NoiseModel | None = None,
) -> list[TagPoseEstimate | None]:
    """Pose of every tag in one frame (vectorized over tags; one ``cv2`` call per tag).

    Parameters
    ----------
    tag_ids : sequence of M int
    corners_px : (M, 4, 2) float
        Raw-image corners in the order of :func:`~tagloc.tags.detection.tag_object_points`.
    sizes : (M,) float
        Edge lengths, metres (> 0).
    camera : CameraModel
    noise : NoiseModel, optional
        Pixel-noise and inflation model for the covariances (defaults).

    Returns
    -------
    list of M TagPoseEstimate or None
        None where the corners give no pose (not undistortable, IPPE failed, behind the
        camera, NaN covariance): callers count it as a degenerate detection.
    """
    noise = noise or NoiseModel()
    corners = np.asarray(corners_px, dtype=np.float64).reshape(-1, 4, 2)
    size = np.asarray(sizes, dtype=np.float64).reshape(-1)
    m = len(corners)
    if m == 0:
        return []
    objects = np.abs(size)[:, None, None] * tag_object_points(1.0)
    # 1-2. undistort, IPPE (both solutions)
    with np.errstate(all="ignore"):
        normalized = camera.undistort(corners.reshape(-1, 2)).reshape(m, 4, 2)
    R0, t0 = np.full((m, 2, 3, 3), np.nan), np.full((m, 2, 3), np.nan)
    for i in np.flatnonzero(np.isfinite(normalized).all(axis=(1, 2)) & (size > 0)):
        R0[i], t0[i] = _ippe_square(normalized[i], objects[i])
    valid = np.isfinite(R0).all(axis=(2, 3)) & np.isfinite(t0).all(axis=2)
    valid &= np.where(valid, t0[..., 2], 0.0) > 0.0
    # 3-5. refine both, rank, valley, covariances
    diagonal_px = 0.5 * (
        np.linalg.norm(corners[:, 2] - corners[:, 0], axis=1)
        + np.linalg.norm(corners[:, 3] - corners[:, 1], axis=1)
    )
    br = solve_branches(R0, t0, valid, objects, corners, camera, noise, diagonal_px)
    range_m = np.linalg.norm(br.t[:, 0], axis=1)
    err = np.sqrt(br.sse_px2 / 4.0)
    ok = [bool(np.isfinite(br.cov[i, 0]).all()) for i in range(m)]
    T_best, T_alt = br.T_best, br.T_alt
    return [
        TagPoseEstimate(
            int(tag_ids[i]),
            float(size[i]),
            T_best[i],
            T_alt[i],
            float(err[i, 0]),
            float(err[i, 1]),
            _ratio(err[i, 0], err[i, 1]),
            br.cov[i, 0],
            br.cov[i, 1],
            float(range_m[i]),
            float(br.view_angle[i, 0]),
            br.cov_rot_laplace[i, 0],
            br.cov_rot_laplace[i, 1],
        )
        if ok[i]
        else None
        for i in range(m)
    ]


def estimate_tag_pose(
    detection: TagDetection, camera: CameraModel, size: float, noise: NoiseModel | None = None
) -> TagPoseEstimate:
    """:func:`estimate_tag_poses` for one detection.

    Raises
    ------
    TagPoseError
        If the corners give no pose (the message names the tag).
    """
    estimate = estimate_tag_poses(
        [detection.tag_id], detection.corners_px[None], [size], camera, noise
    )[0]
    if estimate is None:
        raise TagPoseError(
            f"tag {detection.family}:{detection.tag_id}: corners give no pose (outside the "
            f"camera model, degenerate or behind the camera): {detection.corners_px.tolist()}"
        )
    return estimate


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def estimate_joint_pose(
    estimates: Sequence[TagPoseEstimate],
    corners_px: npt.ArrayLike,
    T_map_tags: Sequence[SE3],
    camera: CameraModel,
    noise: NoiseModel | None = None,
    T_base_cam: SE3 | None = None,
) -> JointPoseEstimate | None:
    """``T_map_cam`` from all corners of ``M >= 1`` tags of known map pose (joint PnP).

    Minimizes the pixel reprojection error of all ``4M`` corners through the camera model
    (:func:`refine_poses`) in a frame ``clu`` at the corners' centroid with map axes. Of the
    ``2M`` starts (both branches of every tag, moved to the map) the one that fits all corners
    best and the best one turned >= 5 deg from it are refined: the best minimum and its
    alternative. The covariance is :func:`pose_covariance` of the stacked Jacobian (with the
    valley to the alternative), moved to ``T_map_cam`` (and ``T_map_base``) with
    :mod:`tagloc.tags.covariance`. Tag map uncertainty is not included.

    Parameters
    ----------
    estimates : sequence of M TagPoseEstimate
        Single-tag estimates of the tags (their branches are the starts; sizes from them).
    corners_px : (M, 4, 2) float
        The tags' corners.
    T_map_tags : sequence of M SE3
        Their surveyed poses.
    camera : CameraModel
    noise : NoiseModel, optional
    T_base_cam : SE3, optional
        Extrinsics, for ``T_map_base``.

    Returns
    -------
    JointPoseEstimate or None
        None if no start gives a pose.
    """
    noise = noise or NoiseModel()
    m = len(estimates)
    pixels = np.asarray(corners_px, dtype=np.float64).reshape(1, 4 * m, 2)
    T_map_tag = SE3.stack(list(T_map_tags))
    sizes = np.array([e.size for e in estimates])
    points_map = T_map_tag.act(sizes[:, None, None] * tag_object_points(1.0)).reshape(-1, 3)
    T_map_clu = SE3.from_trusted(np.eye(3), points_map.mean(axis=0))
    points_clu = (points_map - T_map_clu.translation)[None]
    # starts: T_cam_clu = T_cam_tag @ T_tag_map @ T_map_clu for both branches of every tag
    T_cam_tag = SE3.stack([e.T_cam_tag for e in estimates] + [e.T_cam_tag_alt for e in estimates])
    T_tag_clu = SE3.stack([T_map_tag, T_map_tag]).inverse() @ T_map_clu
    starts = T_cam_tag @ T_tag_clu
    R_s, t_s = starts.rotation.matrix, starts.translation
    # refine two: the start that fits all corners best and the best one turned >= 5 deg from it
    sse0 = _sse(
        camera, R_s, t_s, np.repeat(points_clu, 2 * m, axis=0), np.repeat(pixels, 2 * m, axis=0)
    )
    first = int(np.argmin(sse0))
    cos_rel = (np.einsum("ij,kij->k", R_s[first], R_s) - 1.0) / 2.0
    second = int(np.argmin(np.where(cos_rel < np.cos(np.deg2rad(5.0)), sse0, np.inf)))
    pair = [first, second]
    valid = np.array([[np.isfinite(sse0[first]), np.isfinite(sse0[second]) and second != first]])
    extent_px = np.ptp(pixels[0], axis=0)
    br = solve_branches(
        R_s[pair][None],
        t_s[pair][None],
        valid,
        points_clu,
        pixels,
        camera,
        noise,
        np.array([np.hypot(*extent_px)]),
        np.array([np.mean([e.view_angle_rad for e in estimates])]),
    )
    if not np.isfinite(br.cov[0, 0]).all():
        return None
    poses, covs = [], []
    for b in (0, 1):
        T_cam_clu = _as_se3(br.R[0, b], br.t[0, b])
        T_map_cam, cov = map_cam_from_tag(T_cam_clu, br.cov[0, b], T_map_clu)
        poses.append(T_map_cam)
        covs.append(cov)
    T_map_base = cov_map_base = None
    if T_base_cam is not None:
        T_map_base, cov_map_base = map_base_from_cam(poses[0], covs[0], T_base_cam)
    err = np.sqrt(br.sse_px2[0] / (4 * m))
    return JointPoseEstimate(
        tuple(e.tag_id for e in estimates),
        poses[0],
        covs[0],
        float(err[0]),
        poses[1],
        covs[1],
        float(err[1]),
        br.cov_rot_laplace[0, 0],
        br.cov_rot_laplace[0, 1],
        4 * m,
        T_map_base,
        cov_map_base,
    )
