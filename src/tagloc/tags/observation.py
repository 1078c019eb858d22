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

import dataclasses
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.tags._frame import estimate_frame, joint_rows
from tagloc.tags.covariance import NoiseModel, ambiguity_mixture, map_base_from_cam
from tagloc.tags.detection import TagDetection
from tagloc.tags.gates import (
    GateConfig,
    OrientationPrior,
    PriorEvidence,
    Rejection,
    RejectReason,
    check_detection,
    check_estimate,
    prior_evidences,
    resolve_ambiguity,
)
from tagloc.tags.pnp import JointPoseEstimate, TagPoseEstimate, estimate_joint_pose

_E_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, slots=True)
class PosePrior:
    """What is known of the camera's orientation before this frame (for the ambiguity policy).

    Attributes
    ----------
    T_map_cam : SE3 or None
        Predicted camera pose (e.g. the fusion filter's), of which only the rotation is used.
    rotation_sigma_rad : float
        Per-axis 1-sigma of that rotation (default 0.05 rad = 2.9 deg).
    up_cam : (3,) float or None
        The map's up direction (``+z``) in the camera frame; :meth:`upright` derives it.
    up_sigma_rad : float
        1-sigma of ``up_cam`` (robot tilt; default 0.05 rad).
    """

    T_map_cam: SE3 | None = None
    rotation_sigma_rad: float = 0.05
    up_cam: FloatArray | None = None
    up_sigma_rad: float = 0.05

    @classmethod
    def upright(
        cls,
        T_base_cam: SE3,
        up_sigma_rad: float = 0.05,
        T_map_cam: SE3 | None = None,
        rotation_sigma_rad: float = 0.05,
    ) -> PosePrior:
        """Gravity prior of an upright robot (base ``+z`` = map up, REP-103): ``R_base_cam^T
        e_z``; optionally with a predicted ``T_map_cam``."""
        up_cam = T_base_cam.rotation.inverse().act(_E_Z)
        return cls(T_map_cam, rotation_sigma_rad, up_cam, up_sigma_rad)

    def for_object(self, R_map_obj: FloatArray | None, up_obj: FloatArray) -> OrientationPrior:
        """The :class:`OrientationPrior` of ``R_cam_obj`` for an object of map rotation
        ``R_map_obj`` (None if unknown: gravity only) whose up axis is ``up_obj``."""
        R_cam_obj = None
        if self.T_map_cam is not None and R_map_obj is not None:
            R_cam_obj = self.T_map_cam.rotation.matrix.T @ R_map_obj
        return OrientationPrior(
            R_cam_obj, self.rotation_sigma_rad, self.up_cam, up_obj, self.up_sigma_rad
        )


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


def _tag_prior(prior: PosePrior, T_map_tag: SE3 | None) -> OrientationPrior:
    """The prior of one tag: its map rotation and up axis if surveyed, else upright (``+y``)."""
    if T_map_tag is None:
        return prior.for_object(None, np.array([0.0, 1.0, 0.0]))
    R_map_tag = T_map_tag.rotation.matrix
    return prior.for_object(R_map_tag, R_map_tag[2].copy())  # R_map_tag^T e_z


def _evidences(
    prior: PosePrior | None,
    tag_poses: Mapping[int, SE3] | None,
    estimates: Sequence[TagPoseEstimate],
    joint: JointPoseEstimate | None,
) -> tuple[list[PriorEvidence | None], PriorEvidence | None]:
    """The prior's evidence on both branches of every estimate and of the joint one (whose
    ``obj`` is the map), in one numpy pass."""
    if prior is None:
        return [None] * len(estimates), None
    priors = [
        _tag_prior(prior, None if tag_poses is None else tag_poses[est.tag_id]) for est in estimates
    ]
    R_best = [e.T_cam_tag.rotation.matrix for e in estimates]
    R_alt = [e.T_cam_tag_alt.rotation.matrix for e in estimates]
    laplace_best = [e.cov_rot_laplace for e in estimates]
    laplace_alt = [e.cov_rot_laplace_alt for e in estimates]
    cov_best = [e.cov_cam_tag[3:, 3:] for e in estimates]
    cov_alt = [e.cov_cam_tag_alt[3:, 3:] for e in estimates]
    if joint is not None:
        # R_cam_map's right tangent is -R_map_cam times T_map_cam's rotation tangent
        R, R_j_alt = joint.T_map_cam.rotation.matrix, joint.T_map_cam_alt.rotation.matrix
        priors.append(prior.for_object(np.eye(3), _E_Z))
        R_best.append(R.T)
        R_alt.append(R_j_alt.T)
        laplace_best.append(joint.cov_rot_laplace)
        laplace_alt.append(joint.cov_rot_laplace_alt)
        cov_best.append(R @ joint.cov_map_cam[3:, 3:] @ R.T)
        cov_alt.append(R_j_alt @ joint.cov_map_cam_alt[3:, 3:] @ R_j_alt.T)
    evidence = prior_evidences(priors, R_best, R_alt, laplace_best, laplace_alt, cov_best, cov_alt)
    tags: list[PriorEvidence | None] = list(evidence[: len(estimates)])
    return tags, (evidence[-1] if joint is not None else None)


def _decide_tag(
    est: TagPoseEstimate, config: GateConfig, noise: NoiseModel, evidence: PriorEvidence | None
) -> TagPoseEstimate | Rejection:
    """Ambiguity policy, then the pose gates on the chosen branch (reprojection passed)."""
    decision = resolve_ambiguity(
        est.sse_px2,
        est.sse_alt_px2,
        noise.sigma_px,
        config.ambiguity_log_odds,
        evidence,
        config.prior_gate_chi2,
    )
    if decision.reason is not None:
        return Rejection(
            est.tag_id,
            decision.reason,
            decision.detail,
            decision.log_odds,
            config.ambiguity_log_odds,
        )
    chosen = est.swapped() if decision.choose_alt else est
    rejection = check_estimate(chosen, config)
    if rejection is not None:
        return rejection
    cov = ambiguity_mixture(
        chosen.T_cam_tag,
        chosen.cov_cam_tag,
        chosen.T_cam_tag_alt,
        chosen.cov_cam_tag_alt,
        decision.log_odds,
    )
    return chosen.with_covariance(cov)


def _decide_joint(
    joint: JointPoseEstimate,
    config: GateConfig,
    noise: NoiseModel,
    evidence: PriorEvidence | None,
    T_base_cam: SE3 | None,
) -> JointPoseEstimate | Rejection:
    """Reprojection gate and ambiguity policy of a joint estimate (``obj`` = the map)."""
    if not joint.reproj_err_px <= config.max_reproj_err_px:
        return Rejection(
            None,
            RejectReason.REPROJECTION,
            f"joint reprojection error {joint.reproj_err_px:.3g} px "
            f"(limit {config.max_reproj_err_px:.3g} px)",
            joint.reproj_err_px,
            config.max_reproj_err_px,
        )
    decision = resolve_ambiguity(
        joint.sse_px2,
        joint.sse_alt_px2,
        noise.sigma_px,
        config.ambiguity_log_odds,
        evidence,
        config.prior_gate_chi2,
    )
    if decision.reason is not None:
        return Rejection(
            None,
            decision.reason,
            f"joint: {decision.detail}",
            decision.log_odds,
            config.ambiguity_log_odds,
        )
    if not decision.choose_alt:
        return joint
    joint = joint.swapped()
    if T_base_cam is None:
        return joint
    T_map_base, cov = map_base_from_cam(joint.T_map_cam, joint.cov_map_cam, T_base_cam)
    return dataclasses.replace(joint, T_map_base=T_map_base, cov_map_base=cov)


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
    evidences, joint_evidence = _evidences(prior, tag_poses, [est for _, est in fitted], result)
    # 6. the policies: tags in detection order, then the joint estimate
    accepted: list[TagPoseEstimate] = []
    for outcome in outcomes:
        decided: TagPoseEstimate | Rejection
        if isinstance(outcome, int):
            decided = _decide_tag(fitted[outcome][1], config, noise, evidences[outcome])
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
            outcome_j = _decide_joint(result, config, noise, joint_evidence, T_base_cam)
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
