"""From one frame's detections to gated tag poses and a joint camera pose: :func:`observe_tags`.

Steps (each rejection is a counted :class:`~tagloc.tags.gates.Rejection`, never an exception):

1. Unknown ids (no size, or not in the tag map) and decoder gates (hamming, decision margin).
2. PnP for all remaining tags at once (:func:`~tagloc.tags.pnp.estimate_tag_poses`).
3. Per tag: degenerate corners, reprojection.
4. With >= 2 tags of known map pose whose corners fit (ambiguous ones included: their corners
   are fine, only their single-tag pose is not): joint PnP (:func:`estimate_joint_pose`) for
   ``T_map_cam`` (and ``T_map_base``). Steps 2 and 4 share one pass for their covariances
   (:mod:`tagloc.tags._frame`; the numbers are those of the two calls).
5. The orientation prior on every tag that fits and on the joint estimate, in one pass.
6. Per tag the ambiguity policy (data + prior), then range and viewing angle on the chosen
   branch; the accepted covariance folds in the posterior weight of the other branch
   (:func:`~tagloc.tags.covariance.ambiguity_mixture`). The joint estimate goes through the
   same reprojection gate and policy.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.tags._frame import estimate_frame, joint_rows
from tagloc.tags.branch_choice import PosePrior, decide_joint, decide_tag, evidences
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.detection import TagDetection
from tagloc.tags.gates import (
    GateConfig,
    Rejection,
    RejectReason,
    check_detection,
    check_estimate,
)
from tagloc.tags.pnp import JointPoseEstimate, TagPoseEstimate, estimate_joint_pose

__all__ = ["ObservationResult", "PosePrior", "observe_tags"]


@dataclass(frozen=True, slots=True)
class ObservationResult:
    """Outcome of :func:`observe_tags` for one frame.

    Attributes
    ----------
    accepted : tuple of TagPoseEstimate
        Accepted tags with the chosen branch as ``T_cam_tag`` and the ambiguity folded into
        ``cov_cam_tag``.
    rejections : tuple of Rejection
        Every rejected detection (and the joint estimate, ``tag_id=None``), with reasons.
    joint : JointPoseEstimate or None
        The accepted joint estimate over >= 2 tags of known map pose.
    """

    accepted: tuple[TagPoseEstimate, ...]
    rejections: tuple[Rejection, ...]
    joint: JointPoseEstimate | None

    def counts(self) -> Counter[RejectReason]:
        """Rejections per reason."""
        return Counter(r.reason for r in self.rejections)


def _size_of(tag_sizes: Mapping[int, float] | float, tag_id: int) -> float | None:
    if isinstance(tag_sizes, Mapping):
        size = tag_sizes.get(tag_id)
        return None if size is None else float(size)
    return float(tag_sizes)


def observe_tags(
    detections: Sequence[TagDetection],
    camera: CameraModel,
    tag_sizes: Mapping[int, float] | float,
    gate_config: GateConfig | None = None,
    *,
    tag_poses: Mapping[int, SE3] | None = None,
    T_base_cam: SE3 | None = None,
    prior: PosePrior | None = None,
    noise: NoiseModel | None = None,
) -> ObservationResult:
    """Gate, solve and disambiguate the tags of one frame (steps in the module docstring).

    Parameters
    ----------
    detections : sequence of TagDetection
        One frame's detections, raw-image corners.
    camera : CameraModel
        The model of that raw image.
    tag_sizes : mapping tag_id -> float, or float
        Black-border edge lengths, metres (one number for all tags).
    gate_config : GateConfig, optional
    tag_poses : mapping tag_id -> SE3, optional
        ``T_map_tag`` of surveyed tags (e.g. from a ``TagMap``: the entries in frame ``map``).
        When given, ids outside it are UNKNOWN_TAG, each tag's up axis comes from its pose, and
        >= 2 of them (each seen once) give a joint estimate. Ids are per family: pass the
        detections of the map's family.
    T_base_cam : SE3, optional
        Extrinsics; the joint estimate then also carries ``T_map_base``.
    prior : PosePrior, optional
        Orientation evidence for the ambiguity policy.
    noise : NoiseModel, optional

    Returns
    -------
    ObservationResult
        Never raises for a bad detection: it becomes a counted rejection.
    """
    config = gate_config or GateConfig()
    noise = noise or NoiseModel()
    # 1. unknown ids, decoder gates
    usable, rejections = _usable(detections, tag_sizes, tag_poses, config)
    # 2. PnP, all tags at once (and the joint PnP over the tags step 4 will take)
    estimates, guess = estimate_frame(
        usable, camera, noise, config.max_reproj_err_px, tag_poses, T_base_cam
    )
    # 3. per tag: no pose, reprojection
    fitted, outcomes = _fitting(usable, estimates, config)
    # 4. joint PnP over the known tags that fit (an id seen twice is a mirror or a misread)
    rows: tuple[int, ...] = ()
    if tag_poses is not None:
        errors = [math.inf if est is None else est.reproj_err_px for est in estimates]
        rows = joint_rows([det.tag_id for det, _ in usable], errors, config.max_reproj_err_px)
    result: JointPoseEstimate | None = None
    if tag_poses is not None and len(rows) >= 2:
        if guess is not None and guess.rows == rows:  # step 2 guessed these tags
            result = guess.estimate
        else:
            by_row = dict(fitted)  # the rows fit, so each has its estimate there
            known = [by_row[i] for i in rows]
            result = estimate_joint_pose(
                known,
                np.array([usable[i][0].corners_px for i in rows]),
                [tag_poses[est.tag_id] for est in known],
                camera,
                noise,
                T_base_cam,
            )
    # 5. the prior on every tag that fits and on the joint estimate
    tag_evidence, joint_evidence = evidences(prior, tag_poses, [e for _, e in fitted], result)
    # 6. the policies: tags in detection order, then the joint estimate
    accepted: list[TagPoseEstimate] = []
    for outcome in outcomes:
        decided: TagPoseEstimate | Rejection
        if isinstance(outcome, int):
            decided = decide_tag(fitted[outcome][1], config, noise, tag_evidence[outcome])
        else:
            decided = outcome
        if isinstance(decided, Rejection):
            rejections.append(decided)
        else:
            accepted.append(decided)
    joint: JointPoseEstimate | None = None
    if tag_poses is not None and len(rows) >= 2:
        if result is None:
            rejections.append(Rejection(None, RejectReason.DEGENERATE, "joint PnP failed"))
        else:
            outcome_j = decide_joint(result, config, noise, joint_evidence, T_base_cam)
            if isinstance(outcome_j, Rejection):
                rejections.append(outcome_j)
            else:
                joint = outcome_j
    return ObservationResult(tuple(accepted), tuple(rejections), joint)


def _fitting(
    usable: Sequence[tuple[TagDetection, float]],
    estimates: Sequence[TagPoseEstimate | None],
    config: GateConfig,
) -> tuple[list[tuple[int, TagPoseEstimate]], list[Rejection | int]]:
    """Step 3 of :func:`observe_tags`: ``(index into usable, estimate)`` of the tags with a pose
    that fits their corners, and per usable tag in order its rejection or its index into them."""
    fitted: list[tuple[int, TagPoseEstimate]] = []
    outcomes: list[Rejection | int] = []
    for i, ((det, _), est) in enumerate(zip(usable, estimates, strict=True)):
        if est is None:
            outcomes.append(
                Rejection(
                    det.tag_id,
                    RejectReason.DEGENERATE,
                    "corners give no pose (outside the camera model, "
                    "degenerate or behind the camera)",
                )
            )
            continue
        rejection = check_estimate(est, config)
        if rejection is not None and rejection.reason is RejectReason.REPROJECTION:
            outcomes.append(rejection)
            continue
        outcomes.append(len(fitted))
        fitted.append((i, est))
    return fitted, outcomes


def _usable(
    detections: Sequence[TagDetection],
    tag_sizes: Mapping[int, float] | float,
    tag_poses: Mapping[int, SE3] | None,
    config: GateConfig,
) -> tuple[list[tuple[TagDetection, float]], list[Rejection]]:
    """Step 1 of :func:`observe_tags`: ``(detection, size)`` of the tags that pass, and the
    rejections of the others (unknown ids, decoder gates)."""
    rejections: list[Rejection] = []
    usable: list[tuple[TagDetection, float]] = []
    for det in detections:
        size = _size_of(tag_sizes, det.tag_id)
        if size is None or (tag_poses is not None and det.tag_id not in tag_poses):
            rejections.append(
                Rejection(
                    det.tag_id,
                    RejectReason.UNKNOWN_TAG,
                    f"tag {det.family}:{det.tag_id} is not in the tag map",
                )
            )
            continue
        rejection = check_detection(det, config)
        if rejection is not None:
            rejections.append(rejection)
        else:
            usable.append((det, size))
    return usable, rejections
