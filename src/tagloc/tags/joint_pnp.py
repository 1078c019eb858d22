"""Joint PnP: ``T_map_cam`` from all corners of the tags of known map pose in one frame.

The refinement of :mod:`tagloc.tags.pnp` on all ``4M`` corners at once, started from the tags'
single-tag branches moved to the map, solved in a frame ``clu`` at the corners' centroid with
map axes (the covariance's natural origin is where the tags are), finished by
:func:`~tagloc.tags._branches.finish_branches` and moved to ``T_map_cam`` / ``T_map_base`` with
:mod:`tagloc.tags.pose_chain`. Re-exported by :mod:`tagloc.tags.pnp`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.tags._branches import Branches, Refined, finish_branches, refine_branches
from tagloc.tags._refine import _sse
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.detection import tag_object_points
from tagloc.tags.estimates import JointPoseEstimate, TagPoseEstimate
from tagloc.tags.pose_chain import map_base_from_cam, map_cam_from_tag

__all__ = ["JointProblem", "estimate_joint_pose", "joint_estimate", "refine_joint_problem"]


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
