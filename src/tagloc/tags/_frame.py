"""PnP for one frame's tags, and the joint PnP of the tags it will use, finished in one pass.

:func:`~tagloc.tags.observation.observe_tags` needs the single-tag estimates first (the joint
PnP starts from their branches and takes the tags that fit) and then the joint estimate. Both
end in :func:`~tagloc.tags._branches.finish_branches` (valley and covariances), which costs the
same for one problem as for several. :func:`estimate_frame` therefore refines the tags, picks
the tags the joint PnP will take from their refined errors, refines the joint problem, and
finishes both together. The caller checks the guess against the tags its gates actually kept
(:attr:`JointGuess.rows`) and recomputes the joint estimate the usual way if they differ (a
tag whose covariance came out non-finite, say), so the results are those of
:func:`~tagloc.tags.pnp.estimate_tag_poses` followed by
:func:`~tagloc.tags.pnp.estimate_joint_pose`, bit for bit.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel
from tagloc.errors import TaglocError
from tagloc.geometry import SE3
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.detection import TagDetection
from tagloc.tags.pnp import (
    JointPoseEstimate,
    JointProblem,
    TagPoseEstimate,
    TagProblems,
    estimate_tag_poses,
    finish_branches,
    joint_estimate,
    refine_joint_problem,
    refine_tag_problems,
    tag_estimates,
)

_LOG = logging.getLogger(__name__)
#: What a bad tag can raise from PnP (it then costs only itself, see :func:`per_tag_estimates`).
PNP_ERRORS = (TaglocError, ValueError, np.linalg.LinAlgError, cv2.error)


@dataclass(frozen=True, slots=True)
class JointGuess:
    """The joint estimate over ``rows`` (indices into the frame's tags), or None if it failed."""

    rows: tuple[int, ...]
    estimate: JointPoseEstimate | None


def joint_rows(
    tag_ids: Sequence[int], reproj_err_px: Sequence[float], max_reproj_err_px: float
) -> tuple[int, ...]:
    """The tags the joint PnP takes: those that fit (finite error within the reprojection gate)
    whose id no other fitting tag has (a mirror or a misread)."""
    fits = [i for i, err in enumerate(reproj_err_px) if err <= max_reproj_err_px]
    seen = Counter(tag_ids[i] for i in fits)
    return tuple(i for i in fits if seen[tag_ids[i]] == 1)


def estimate_frame(
    tags: Sequence[tuple[TagDetection, float]],
    camera: CameraModel,
    noise: NoiseModel,
    max_reproj_err_px: float,
    tag_poses: Mapping[int, SE3] | None,
    T_base_cam: SE3 | None,
) -> tuple[list[TagPoseEstimate | None], JointGuess | None]:
    """Single-tag estimates of ``tags`` (``(detection, size)``) and, with ``tag_poses``, the
    joint estimate over :func:`joint_rows` of them (None if fewer than 2).

    Never raises for a bad tag: if the batched tag stage fails, the tags go through
    :func:`per_tag_estimates`; if the joint stage fails, the tags are kept and no guess is
    returned (the caller's own joint PnP then meets the error where it would have).
    """
    if not tags:
        return [], None
    ids = [det.tag_id for det, _ in tags]
    corners = np.array([det.corners_px for det, _ in tags]).reshape(-1, 4, 2)
    sizes = [size for _, size in tags]
    try:
        problems = refine_tag_problems(ids, corners, sizes, camera, noise)
    except PNP_ERRORS:
        return per_tag_estimates(tags, camera, noise), None
    assert problems is not None
    rows: tuple[int, ...] = ()
    if tag_poses is not None:
        rows = joint_rows(ids, problems.reproj_err_px.tolist(), max_reproj_err_px)
    if len(rows) >= 2:
        assert tag_poses is not None
        try:
            joint = _refine_joint(problems, rows, corners, tag_poses, camera, noise)
            both = finish_branches(camera, noise, [problems.refined, joint.refined])
        except PNP_ERRORS as exc:  # the tags are kept, finished alone below
            _LOG.debug("joint PnP of tags %s: %s", [ids[i] for i in rows], exc)
        else:
            estimates = tag_estimates(problems, both[0])
            try:
                return estimates, JointGuess(rows, joint_estimate(joint, both[1], T_base_cam))
            except PNP_ERRORS as exc:
                _LOG.debug("joint PnP of tags %s: %s", [ids[i] for i in rows], exc)
                return estimates, None
    try:
        finished = finish_branches(camera, noise, [problems.refined])
    except PNP_ERRORS:
        return per_tag_estimates(tags, camera, noise), None
    return tag_estimates(problems, finished[0]), None


def _refine_joint(
    problems: TagProblems,
    rows: tuple[int, ...],
    corners: npt.NDArray[np.float64],
    tag_poses: Mapping[int, SE3],
    camera: CameraModel,
    noise: NoiseModel,
) -> JointProblem:
    """:func:`refine_joint_problem` of the tags ``rows`` from their refined branches (what
    :func:`~tagloc.tags.pnp.estimate_joint_pose` starts from)."""
    refined, ids = problems.refined, problems.tag_ids
    both = list(rows)
    return refine_joint_problem(
        tuple(ids[i] for i in rows),
        SE3.from_trusted(
            np.concatenate([refined.R[both, 0], refined.R[both, 1]]),
            np.concatenate([refined.t[both, 0], refined.t[both, 1]]),
        ),
        [float(problems.sizes[i]) for i in rows],
        [float(refined.view_angle[i, 0]) for i in rows],
        corners[both],
        [tag_poses[ids[i]] for i in rows],
        camera,
        noise,
    )


def per_tag_estimates(
    tags: Sequence[tuple[TagDetection, float]], camera: CameraModel, noise: NoiseModel
) -> list[TagPoseEstimate | None]:
    """PnP one tag at a time (after the batch failed), so that one bad tag costs only itself."""
    out: list[TagPoseEstimate | None] = []
    for det, size in tags:
        try:
            out += estimate_tag_poses([det.tag_id], det.corners_px[None], [size], camera, noise)
        except PNP_ERRORS as exc:
            _LOG.debug("tag %d: no pose (%s)", det.tag_id, exc)
            out.append(None)
    return out
