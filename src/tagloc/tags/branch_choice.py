"""The choice between a tag pose's two IPPE branches: the orientation prior and the decisions.

:class:`PosePrior` is what is known of the camera's orientation before a frame;
:func:`evidences` turns it into evidence on both branches of every estimate (and of the joint
one) in one pass; :func:`decide_tag` and :func:`decide_joint` apply the ambiguity policy
(:func:`~tagloc.tags.gates.resolve_ambiguity`) and the pose gates. Used by
:func:`tagloc.tags.observation.observe_tags`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.tags.covariance import NoiseModel, ambiguity_mixture, map_base_from_cam
from tagloc.tags.gates import (
    AmbiguityDecision,
    GateConfig,
    OrientationPrior,
    PriorEvidence,
    Rejection,
    RejectReason,
    check_estimate,
    prior_evidences,
    resolve_ambiguity,
)
from tagloc.tags.pnp import JointPoseEstimate, TagPoseEstimate

__all__ = ["PosePrior", "decide_joint", "decide_tag", "evidences"]

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


def _tag_prior(prior: PosePrior, T_map_tag: SE3 | None) -> OrientationPrior:
    """The prior of one tag: its map rotation and up axis if surveyed, else upright (``+y``)."""
    if T_map_tag is None:
        return prior.for_object(None, np.array([0.0, 1.0, 0.0]))
    R_map_tag = T_map_tag.rotation.matrix
    return prior.for_object(R_map_tag, R_map_tag[2].copy())  # R_map_tag^T e_z


def evidences(
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


def decide_tag(
    est: TagPoseEstimate, config: GateConfig, noise: NoiseModel, evidence: PriorEvidence | None
) -> TagPoseEstimate | Rejection:
    """Ambiguity policy, then the pose gates on the chosen branch (reprojection passed)."""
    decision = _ambiguity(est.sse_px2, est.sse_alt_px2, est.tag_id, "", config, noise, evidence)
    if isinstance(decision, Rejection):
        return decision
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


def decide_joint(
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
    decision = _ambiguity(joint.sse_px2, joint.sse_alt_px2, None, "joint: ", config, noise,
                          evidence)  # fmt: skip
    if isinstance(decision, Rejection):
        return decision
    if not decision.choose_alt:
        return joint
    joint = joint.swapped()
    if T_base_cam is None:
        return joint
    T_map_base, cov = map_base_from_cam(joint.T_map_cam, joint.cov_map_cam, T_base_cam)
    return dataclasses.replace(joint, T_map_base=T_map_base, cov_map_base=cov)


def _ambiguity(
    sse_px2: float, sse_alt_px2: float, tag_id: int | None, label: str, config: GateConfig,
    noise: NoiseModel, evidence: PriorEvidence | None,
) -> AmbiguityDecision | Rejection:  # fmt: skip
    """The ambiguity policy's branch choice, or its rejection (``label`` leads the detail)."""
    decision = resolve_ambiguity(sse_px2, sse_alt_px2, noise.sigma_px, config.ambiguity_log_odds,
                                 evidence, config.prior_gate_chi2)  # fmt: skip
    if decision.reason is None:
        return decision
    return Rejection(tag_id, decision.reason, label + decision.detail, decision.log_odds,
                     config.ambiguity_log_odds)  # fmt: skip
