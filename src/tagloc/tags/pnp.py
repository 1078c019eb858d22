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

Both run the two halves of :mod:`tagloc.tags._branches`: ``refine_branches`` refines every
candidate (``refine_poses``, :mod:`tagloc.tags._refine`) and keeps the best minimum and the best
*other* minimum (else the worst raw candidate); :func:`finish_branches` measures the valley
between them and computes both covariances. Each public function is a refine stage
(:func:`refine_tag_problems`, :func:`refine_joint_problem`), :func:`finish_branches` and an
assembly stage (:func:`tag_estimates`, :func:`joint_estimate`); :func:`finish_branches` takes
the problems of both stages at once, which :func:`~tagloc.tags.observation.observe_tags` uses
(:mod:`tagloc.tags._frame`). The result types are in :mod:`tagloc.tags.estimates`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.geometry.small_batch import row_norms
from tagloc.tags._branches import Branches, Refined, finish_branches, refine_branches
from tagloc.tags._refine import _sse
from tagloc.tags.covariance import NoiseModel, map_base_from_cam, map_cam_from_tag
from tagloc.tags.detection import TagDetection, tag_object_points
from tagloc.tags.errors import TagError
from tagloc.tags.estimates import JointPoseEstimate, TagPoseEstimate, _ratio

__all__ = [
    "JointPoseEstimate",
    "JointProblem",
    "TagPoseError",
    "TagPoseEstimate",
    "TagProblems",
    "estimate_joint_pose",
    "estimate_tag_pose",
    "estimate_tag_poses",
    "finish_branches",
    "joint_estimate",
    "refine_joint_problem",
    "refine_tag_problems",
    "tag_estimates",
]

_EYE3 = np.eye(3)


class TagPoseError(TagError, ValueError):
    """A tag whose corners give no pose (outside the camera model, degenerate, behind)."""


def _ippe_square(
    normalized: FloatArray, points_tag: FloatArray, R: FloatArray, t: FloatArray
) -> None:
    """Both IPPE_SQUARE solutions of one tag into ``R`` (2, 3, 3), ``t`` (2, 3) (left as they
    are, NaN, if there is none)."""
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            points_tag, normalized, _EYE3, None, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
    except cv2.error:
        return
    for i in range(min(int(n), 2)):
        R[i] = cv2.Rodrigues(rvecs[i])[0]
        t[i] = np.ravel(tvecs[i])
    if int(n) == 1:
        R[1], t[1] = R[0], t[0]


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
    problems = refine_tag_problems(tag_ids, corners_px, sizes, camera, noise)
    if problems is None:
        return []
    return tag_estimates(problems, finish_branches(camera, noise, [problems.refined])[0])


@dataclass(frozen=True, slots=True)
class TagProblems:
    """A frame's single-tag problems, refined but without valley and covariances.

    :func:`estimate_tag_poses` is :func:`refine_tag_problems`, then
    :func:`~tagloc.tags._branches.finish_branches` (possibly together with a joint problem),
    then :func:`tag_estimates`.

    Attributes
    ----------
    tag_ids : tuple of M int
    sizes : (M,) float
    refined : Refined
        Both branches of every tag (``refined.sse_px2[:, 0]`` is inf where there is no pose).
    """

    tag_ids: tuple[int, ...]
    sizes: FloatArray
    refined: Refined

    @property
    def reproj_err_px(self) -> FloatArray:
        """(M,) the best branch's RMS corner error, as :class:`TagPoseEstimate` will have it."""
        return np.asarray(np.sqrt(self.refined.sse_px2 / 4.0)[:, 0])


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def refine_tag_problems(
    tag_ids: Sequence[int],
    corners_px: npt.ArrayLike,
    sizes: npt.ArrayLike,
    camera: CameraModel,
    noise: NoiseModel,
) -> TagProblems | None:
    """Steps 1-3 of :func:`estimate_tag_poses` (same parameters); None for no tags."""
    corners = np.asarray(corners_px, dtype=np.float64).reshape(-1, 4, 2)
    size = np.asarray(sizes, dtype=np.float64).reshape(-1)
    m = len(corners)
    if m == 0:
        return None
    objects = np.abs(size)[:, None, None] * tag_object_points(1.0)
    # 1-2. undistort, IPPE (both solutions)
    with np.errstate(all="ignore"):
        normalized = camera.undistort(corners.reshape(-1, 2)).reshape(m, 4, 2)
    R0, t0 = np.full((m, 2, 3, 3), np.nan), np.full((m, 2, 3), np.nan)
    for i in np.flatnonzero(np.isfinite(normalized).all(axis=(1, 2)) & (size > 0)):
        _ippe_square(normalized[i], objects[i], R0[i], t0[i])
    valid = np.isfinite(R0).all(axis=(2, 3)) & np.isfinite(t0).all(axis=2)
    valid &= np.where(valid, t0[..., 2], 0.0) > 0.0
    # 3. refine both, rank (the valley and covariances are finish_branches')
    diagonal_px = 0.5 * (
        row_norms(corners[:, 2] - corners[:, 0]) + row_norms(corners[:, 3] - corners[:, 1])
    )
    refined = refine_branches(R0, t0, valid, objects, corners, camera, noise, diagonal_px)
    return TagProblems(tuple(int(i) for i in tag_ids), size, refined)


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def tag_estimates(problems: TagProblems, br: Branches) -> list[TagPoseEstimate | None]:
    """The estimates of :func:`estimate_tag_poses` from the finished ``problems``."""
    size = problems.sizes
    range_m = row_norms(br.t[:, 0])
    err = np.sqrt(br.sse_px2 / 4.0)
    ok = np.asarray(np.isfinite(br.cov[:, 0]).all(axis=(1, 2)), dtype=bool)
    T_best, T_alt = br.T_best, br.T_alt
    return [
        TagPoseEstimate(
            tag_id,
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
        for i, tag_id in enumerate(problems.tag_ids)
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
    (``refine_poses``) in a frame ``clu`` at the corners' centroid with map axes. Of the
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
    problem = refine_joint_problem(
        tuple(e.tag_id for e in estimates),
        SE3.stack([e.T_cam_tag for e in estimates] + [e.T_cam_tag_alt for e in estimates]),
        [e.size for e in estimates],
        [e.view_angle_rad for e in estimates],
        corners_px,
        T_map_tags,
        camera,
        noise,
    )
    return joint_estimate(problem, finish_branches(camera, noise, [problem.refined])[0], T_base_cam)


@dataclass(frozen=True, slots=True)
class JointProblem:
    """A joint PnP problem refined but without valley and covariances
    (:func:`refine_joint_problem`; finished by :func:`joint_estimate`).

    Attributes
    ----------
    tag_ids : tuple of M int
    T_map_clu : SE3
        The solving frame: map axes at the corners' centroid.
    refined : Refined
        One problem of ``4M`` corners.
    """

    tag_ids: tuple[int, ...]
    T_map_clu: SE3
    refined: Refined


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def refine_joint_problem(
    tag_ids: tuple[int, ...],
    T_cam_tag_both: SE3,
    sizes: Sequence[float],
    view_angles: Sequence[float],
    corners_px: npt.ArrayLike,
    T_map_tags: Sequence[SE3],
    camera: CameraModel,
    noise: NoiseModel,
) -> JointProblem:
    """The refinement of :func:`estimate_joint_pose` from the tags' branches: ``T_cam_tag_both``
    (2M) holds the M best branches, then the M alternatives; ``sizes`` and ``view_angles`` (M)
    are the tags' (``TagPoseEstimate.size``, ``.view_angle_rad``)."""
    m = len(tag_ids)
    pixels = np.asarray(corners_px, dtype=np.float64).reshape(1, 4 * m, 2)
    T_map_tag = SE3.stack(list(T_map_tags))
    points_map = T_map_tag.act(np.array(sizes)[:, None, None] * tag_object_points(1.0))
    points_map = points_map.reshape(-1, 3)
    T_map_clu = SE3.from_trusted(np.eye(3), points_map.mean(axis=0))
    points_clu = (points_map - T_map_clu.translation)[None]
    # starts: T_cam_clu = T_cam_tag @ T_tag_map @ T_map_clu for both branches of every tag
    T_tag_clu = SE3.stack([T_map_tag, T_map_tag]).inverse() @ T_map_clu
    starts = T_cam_tag_both @ T_tag_clu
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
    refined = refine_branches(
        R_s[pair][None],
        t_s[pair][None],
        valid,
        points_clu,
        pixels,
        camera,
        noise,
        np.array([np.hypot(*extent_px)]),
        np.array([np.mean(view_angles)]),
    )
    return JointProblem(tag_ids, T_map_clu, refined)


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def joint_estimate(
    problem: JointProblem, br: Branches, T_base_cam: SE3 | None = None
) -> JointPoseEstimate | None:
    """The result of :func:`estimate_joint_pose` from the finished ``problem``."""
    if not np.isfinite(br.cov[0, 0]).all():
        return None
    poses, covs = [], []
    for b in (0, 1):
        T_cam_clu = SE3.from_trusted(br.R[0, b], br.t[0, b])
        T_map_cam, cov = map_cam_from_tag(T_cam_clu, br.cov[0, b], problem.T_map_clu)
        poses.append(T_map_cam)
        covs.append(cov)
    T_map_base = cov_map_base = None
    if T_base_cam is not None:
        T_map_base, cov_map_base = map_base_from_cam(poses[0], covs[0], T_base_cam)
    m = len(problem.tag_ids)
    err = np.sqrt(br.sse_px2[0] / (4 * m))
    return JointPoseEstimate(
        problem.tag_ids,
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
