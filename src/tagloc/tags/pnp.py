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

Joint PnP (:func:`estimate_joint_pose`, in :mod:`tagloc.tags.joint_pnp` and re-exported here):
the same refinement on all corners of all tags of known map pose, started from the best-fitting
branches of the tags, solved in a frame at the corners' centroid (map axes) so that the
covariance's natural origin is where the tags are.

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
from tagloc.geometry.small_batch import row_norms
from tagloc.tags._branches import Branches, Refined, finish_branches, refine_branches
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.detection import TagDetection, tag_object_points
from tagloc.tags.errors import TagError
from tagloc.tags.estimates import JointPoseEstimate, TagPoseEstimate, _ratio
from tagloc.tags.joint_pnp import (
    JointProblem,
    estimate_joint_pose,
    joint_estimate,
    refine_joint_problem,
)

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
