"""From one frame's detections to gated tag poses and a joint camera pose: :func:`observe_tags`.

Steps (each rejection is a counted :class:`~tagloc.tags.gates.Rejection`, never an exception):

1. Unknown ids (no size, or not in the tag map) and decoder gates (hamming, decision margin).
2. PnP for all remaining tags at once (:func:`~tagloc.tags.pnp.estimate_tag_poses`).
3. Per tag: degenerate corners, reprojection, the ambiguity policy (data + prior), then range
   and viewing angle on the chosen branch; the accepted covariance folds in the posterior
   weight of the other branch (:func:`~tagloc.tags.covariance.ambiguity_mixture`).
4. With >= 2 tags of known map pose whose corners fit (ambiguous ones included: their corners
   are fine, only their single-tag pose is not): joint PnP (:func:`estimate_joint_pose`) for
   ``T_map_cam`` (and ``T_map_base``), through the same reprojection gate and policy.
"""

from __future__ import annotations

import dataclasses
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
    prior_evidence,
    resolve_ambiguity,
    tag_prior_evidences,
)
from tagloc.tags.pnp import (
    JointPoseEstimate,
    TagPoseEstimate,
    estimate_joint_pose,
    estimate_tag_poses,
)

FloatArray = npt.NDArray[np.float64]
_LOG = logging.getLogger(__name__)
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


def _safe_estimates(
    tags: list[tuple[TagDetection, float]], camera: CameraModel, noise: NoiseModel
) -> list[TagPoseEstimate | None]:
    """Batched PnP; if the batch fails, one tag at a time so that one bad tag costs only itself."""
    ids = [det.tag_id for det, _ in tags]
    corners = np.array([det.corners_px for det, _ in tags]).reshape(-1, 4, 2)
    sizes = [size for _, size in tags]
    try:
        return estimate_tag_poses(ids, corners, sizes, camera, noise)
    except (TaglocError, ValueError, np.linalg.LinAlgError, cv2.error):
        out: list[TagPoseEstimate | None] = []
        for i in range(len(tags)):
            try:
                out += estimate_tag_poses(
                    ids[i : i + 1], corners[i : i + 1], sizes[i : i + 1], camera, noise
                )
            except (TaglocError, ValueError, np.linalg.LinAlgError, cv2.error) as exc:
                _LOG.debug("tag %d: no pose (%s)", ids[i], exc)
                out.append(None)
        return out


def _tag_prior(prior: PosePrior, T_map_tag: SE3 | None) -> OrientationPrior:
    """The prior of one tag: its map rotation and up axis if surveyed, else upright (``+y``)."""
    if T_map_tag is None:
        return prior.for_object(None, np.array([0.0, 1.0, 0.0]))
    R_map_tag = T_map_tag.rotation.matrix
    return prior.for_object(R_map_tag, R_map_tag[2].copy())  # R_map_tag^T e_z


def _tag_evidences(
    prior: PosePrior | None,
    tag_poses: Mapping[int, SE3] | None,
    estimates: Sequence[TagPoseEstimate],
) -> list[PriorEvidence | None]:
    """The prior's evidence on both branches of every estimate (one numpy pass for all)."""
    if prior is None:
        return [None] * len(estimates)
    priors = [
        _tag_prior(prior, None if tag_poses is None else tag_poses[est.tag_id]) for est in estimates
    ]
    return list(tag_prior_evidences(priors, estimates))


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
    joint: JointPoseEstimate, config: GateConfig, noise: NoiseModel, prior: PosePrior | None
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
    evidence = None
    if prior is not None:
        # R_cam_map's right tangent is -R_map_cam times T_map_cam's rotation tangent
        R, R_alt = joint.T_map_cam.rotation.matrix, joint.T_map_cam_alt.rotation.matrix
        evidence = prior_evidence(
            prior.for_object(np.eye(3), _E_Z),
            R.T,
            R_alt.T,
            joint.cov_rot_laplace,
            joint.cov_rot_laplace_alt,
            R @ joint.cov_map_cam[3:, 3:] @ R.T,
            R_alt @ joint.cov_map_cam_alt[3:, 3:] @ R_alt.T,
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
    return joint.swapped() if decision.choose_alt else joint


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
    rejections: list[Rejection] = []
    # 1. unknown ids, decoder gates
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
    # 2. PnP, all tags at once
    estimates = _safe_estimates(usable, camera, noise) if usable else []
    # 3. per tag: no pose, reprojection; then the policy (the prior on all tags in one pass)
    fitted: list[tuple[TagPoseEstimate, TagDetection]] = []
    outcomes: list[Rejection | int] = []  # in detection order: a rejection or a fitted index
    for (det, _), est in zip(usable, estimates, strict=True):
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
        fitted.append((est, det))
    evidences = _tag_evidences(prior, tag_poses, [est for est, _ in fitted])
    accepted: list[TagPoseEstimate] = []
    for outcome in outcomes:
        decided: TagPoseEstimate | Rejection
        if isinstance(outcome, int):
            decided = _decide_tag(fitted[outcome][0], config, noise, evidences[outcome])
        else:
            decided = outcome
        if isinstance(decided, Rejection):
            rejections.append(decided)
        else:
            accepted.append(decided)
    # 4. joint PnP over the known tags that fit (an id seen twice is a mirror or a misread)
    joint: JointPoseEstimate | None = None
    seen = Counter(est.tag_id for est, _ in fitted)
    known = [(est, det) for est, det in fitted if tag_poses is not None and seen[est.tag_id] == 1]
    if tag_poses is not None and len(known) >= 2:
        result = estimate_joint_pose(
            [est for est, _ in known],
            np.array([det.corners_px for _, det in known]),
            [tag_poses[est.tag_id] for est, _ in known],
            camera,
            noise,
            T_base_cam,
        )
        if result is None:
            rejections.append(Rejection(None, RejectReason.DEGENERATE, "joint PnP failed"))
        else:
            outcome_j = _decide_joint(result, config, noise, prior)
            if isinstance(outcome_j, Rejection):
                rejections.append(outcome_j)
            else:
                joint = outcome_j
                if T_base_cam is not None and joint.T_map_base is None:  # the alternative won
                    T_map_base, cov = map_base_from_cam(
                        joint.T_map_cam, joint.cov_map_cam, T_base_cam
                    )
                    joint = dataclasses.replace(joint, T_map_base=T_map_base, cov_map_base=cov)
    return ObservationResult(tuple(accepted), tuple(rejections), joint)
