"""Gates on one tag observation, and the IPPE ambiguity policy; every rejection has a reason.

Gates (:func:`check_detection` before PnP, :func:`check_estimate` after) compare one number with
one limit of :class:`GateConfig` and return a :class:`Rejection` (or None) whose
:class:`RejectReason` downstream code counts. They never raise on bad data.

The ambiguity policy (:func:`resolve_ambiguity`) chooses between the two IPPE branches, or
rejects, from combined evidence in chi-square units (``2 ln`` of a likelihood ratio):

- **Data**: ``(SSE_alt - SSE_best) / sigma_px^2``. With Gaussian pixel noise the SSE of the true
  branch is ~ chi-square(8 - 6 = 2 dof) ``* sigma^2``, so a wrong branch is chosen *and* passes
  a threshold ``L`` with probability below ``P(chi2_2 > L) = exp(-L / 2)`` -- whatever the ratio
  ``err_best / err_alt`` is (flips happen at ratios 0.03 to 1 at range: a ratio gate cannot
  tell a lucky wrong fit from a right one; the noise model can).
- **Prior** (:class:`~tagloc.tags.prior.OrientationPrior`, evaluated there): a predicted
  ``R_cam_tag`` (prior ``T_map_cam`` and the tag's map pose) and/or gravity (the camera's up
  direction from the extrinsics of an upright robot, and the tag's up axis). The mirrored
  branch tilts the normal by about twice the viewing angle, which a few-degree prior sees even
  where the pixels cannot. Its term is the difference of the two branches' chi-squares against
  the prior, each with the branch's own likelihood lobe added (its Laplace rotation
  covariance, widened along a low valley to the other branch: two face-on branches straddling
  the truth are then both "near" the prior and stay ambiguous).
- **Joint PnP** over several tags is the strongest evidence (it has its own alternative and is
  decided by this same function), see :func:`tagloc.tags.observation.observe_tags`.

The branch with the higher posterior is chosen; it is accepted only if its log-odds reach
``GateConfig.ambiguity_log_odds`` (AMBIGUOUS otherwise) and it agrees with the prior
(PRIOR_CONFLICT otherwise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from pydantic import BaseModel, ConfigDict, Field

from tagloc.tags.detection import TagDetection
from tagloc.tags.pnp import TagPoseEstimate
from tagloc.tags.prior import (
    OrientationPrior,
    PriorEvidence,
    prior_evidence,
    prior_evidences,
    tag_prior_evidence,
    tag_prior_evidences,
)

__all__ = [
    "AmbiguityDecision",
    "GateConfig",
    "OrientationPrior",
    "PriorEvidence",
    "RejectReason",
    "Rejection",
    "check_detection",
    "check_estimate",
    "prior_evidence",
    "prior_evidences",
    "resolve_ambiguity",
    "tag_prior_evidence",
    "tag_prior_evidences",
]


class RejectReason(StrEnum):
    """Why an observation was not used (values are stable strings for counters and logs)."""

    UNKNOWN_TAG = "unknown_tag"  #: id not in the tag map (or no size known)
    HAMMING = "hamming"  #: decoder corrected too many bits
    DECISION_MARGIN = "decision_margin"  #: AprilTag decision margin too low
    DEGENERATE = "degenerate"  #: corners give no pose (outside the model, collinear, behind)
    REPROJECTION = "reprojection"  #: best pose does not explain the corners
    AMBIGUOUS = "ambiguous"  #: the two IPPE branches are not separated by the evidence
    PRIOR_CONFLICT = "prior_conflict"  #: the chosen branch contradicts the prior
    RANGE = "range"  #: tag too far (depth error grows ~ d^2)
    VIEW_ANGLE = "view_angle"  #: tag seen too obliquely


class GateConfig(BaseModel):
    """Limits of the observation gates (``localizer.yaml``: ``gates``).

    Attributes
    ----------
    max_reproj_err_px : float
        RMS corner reprojection error of the chosen pose (default 2.0 px: pure noise of 0.5 px
        gives < 0.93 px in 99.9 % of views; the rest is room for real-image corner bias).
    max_range_m : float
        Largest camera-to-tag distance (default 8.0 m).
    max_view_angle_deg : float
        Largest angle between the tag normal and the ray to the camera (default 75 deg).
    min_decision_margin : float
        Smallest AprilTag 3 decision margin (default 20); skipped when the detection has none
        (NaN, e.g. ArUco).
    max_hamming : int
        Most corrected bits (default 1).
    ambiguity_log_odds : float
        Evidence required for the chosen IPPE branch, ``2 ln(p_chosen / p_other)`` (default
        18.4 = odds of 10^4: from the pixels alone a wrong branch passes with probability
        < 1e-4 when ``sigma_px`` is not below the real noise; none did in 10^5 simulated views).
    prior_gate_chi2 : float
        Largest prior chi-square of the chosen branch (default 16.3: 99.9 % of chi-square with
        3 dof).
    """

    # StrictModel's settings, spelled out: localize's GatesConfig derives from StrictModel and
    # from this class, an order that cannot hold if this class were a StrictModel too.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    max_reproj_err_px: float = Field(2.0, gt=0.0, le=1e4)
    max_range_m: float = Field(8.0, gt=0.0, le=1e4)
    max_view_angle_deg: float = Field(75.0, gt=0.0, le=90.0)
    min_decision_margin: float = Field(20.0, ge=0.0, le=1e4)
    max_hamming: int = Field(1, ge=0, le=16)
    ambiguity_log_odds: float = Field(18.4, ge=0.0, le=1e6)
    prior_gate_chi2: float = Field(16.3, gt=0.0, le=1e9)


@dataclass(frozen=True, slots=True)
class Rejection:
    """One rejected observation: which tag (None for the joint estimate), why, and the numbers.

    Attributes
    ----------
    tag_id : int or None
    reason : RejectReason
    detail : str
        One line for logs, naming the value and the limit.
    value, limit : float
        The measured number and the limit it broke (NaN where there is none).
    """

    tag_id: int | None
    reason: RejectReason
    detail: str
    value: float = math.nan
    limit: float = math.nan


def _reject(
    tag_id: int | None, reason: RejectReason, what: str, value: float, limit: float, unit: str = ""
) -> Rejection:
    return Rejection(
        tag_id,
        reason,
        f"{what} {value:.4g}{unit} (limit {limit:.4g}{unit})",
        float(value),
        float(limit),
    )


def check_detection(detection: TagDetection, config: GateConfig) -> Rejection | None:
    """Decoder-quality gates: hamming, then decision margin (skipped when NaN)."""
    tag_id = detection.tag_id
    if detection.hamming > config.max_hamming:
        return _reject(
            tag_id, RejectReason.HAMMING, "hamming", detection.hamming, config.max_hamming, " bits"
        )
    margin = detection.decision_margin
    if not math.isnan(margin) and margin < config.min_decision_margin:
        return _reject(
            tag_id,
            RejectReason.DECISION_MARGIN,
            "decision margin",
            margin,
            config.min_decision_margin,
        )
    return None


def check_estimate(estimate: TagPoseEstimate, config: GateConfig) -> Rejection | None:
    """Pose gates on the chosen pose: reprojection error, range, viewing angle."""
    tag_id = estimate.tag_id
    if not estimate.reproj_err_px <= config.max_reproj_err_px:
        return _reject(
            tag_id,
            RejectReason.REPROJECTION,
            "reprojection error",
            estimate.reproj_err_px,
            config.max_reproj_err_px,
            " px",
        )
    if not estimate.range_m <= config.max_range_m:
        return _reject(
            tag_id, RejectReason.RANGE, "range", estimate.range_m, config.max_range_m, " m"
        )
    angle_deg = math.degrees(estimate.view_angle_rad)
    if not angle_deg <= config.max_view_angle_deg:
        return _reject(
            tag_id,
            RejectReason.VIEW_ANGLE,
            "view angle",
            angle_deg,
            config.max_view_angle_deg,
            " deg",
        )
    return None


@dataclass(frozen=True, slots=True)
class AmbiguityDecision:
    """Outcome of :func:`resolve_ambiguity`.

    Attributes
    ----------
    choose_alt : bool
        True if the branch with the *higher* reprojection error won (through the prior).
    log_odds : float
        ``2 ln(p_chosen / p_other)``, data plus prior (>= 0; ``inf`` without alternative).
    data_log_odds, prior_log_odds : float
        The two parts, for the best branch over the alternative (prior 0 without prior).
    reason : RejectReason or None
        None if accepted, else AMBIGUOUS or PRIOR_CONFLICT.
    detail : str
    """

    choose_alt: bool
    log_odds: float
    data_log_odds: float
    prior_log_odds: float
    reason: RejectReason | None
    detail: str


def resolve_ambiguity(
    sse_px2: float,
    sse_alt_px2: float,
    sigma_px: float,
    min_log_odds: float,
    prior: PriorEvidence | None = None,
    prior_gate_chi2: float = math.inf,
) -> AmbiguityDecision:
    """Choose an IPPE branch from data and prior evidence, or reject (pure function).

    The two branches are two hypotheses. Their log-odds, in chi-square units, are
    ``(sse_alt - sse) / sigma^2`` from the pixels plus ``prior.chi2_alt - prior.chi2`` from the
    prior; the likelier branch is chosen if the magnitude reaches ``min_log_odds`` and its
    innovation chi-square against the prior stays within ``prior_gate_chi2``.

    Parameters
    ----------
    sse_px2, sse_alt_px2 : float
        Sums of squared pixel residuals of the best and the alternative branch
        (``sse_alt_px2 >= sse_px2``; ``inf`` if there is no alternative).
    sigma_px : float
        Corner noise, pixels (:attr:`NoiseModel.sigma_px`). Must not be below the real noise,
        or the data evidence is overstated.
    min_log_odds : float
        Evidence needed to accept, chi-square units (:attr:`GateConfig.ambiguity_log_odds`).
    prior : PriorEvidence, optional
        :func:`prior_evidence` of the two branches; None for no prior.
    prior_gate_chi2 : float
        Largest innovation chi-square the chosen branch may have against the prior.

    Returns
    -------
    AmbiguityDecision
        ``reason`` is None (accepted), AMBIGUOUS (odds below ``min_log_odds``) or
        PRIOR_CONFLICT (the branch the evidence favours is inconsistent with the prior).
    """
    unique = not math.isfinite(sse_alt_px2)
    data = math.inf if unique else (sse_alt_px2 - sse_px2) / sigma_px**2
    prior_term = 0.0 if (prior is None or unique) else prior.chi2_alt - prior.chi2
    total = data + prior_term
    choose_alt = total < 0.0
    log_odds = abs(total)
    branch = "alternative" if choose_alt else "best"
    parts = f"data {data:.3g} + prior {prior_term:.3g}"
    if prior is not None:
        innovation = prior.innovation_chi2_alt if choose_alt else prior.innovation_chi2
        if not innovation <= prior_gate_chi2:
            detail = f"{branch} branch prior chi2 {innovation:.3g} (limit {prior_gate_chi2:.3g})"
            return AmbiguityDecision(
                choose_alt, log_odds, data, prior_term, RejectReason.PRIOR_CONFLICT, detail
            )
    if not log_odds >= min_log_odds:
        detail = f"branch log-odds {log_odds:.3g} = |{parts}| (limit {min_log_odds:.3g})"
        return AmbiguityDecision(
            choose_alt, log_odds, data, prior_term, RejectReason.AMBIGUOUS, detail
        )
    return AmbiguityDecision(choose_alt, log_odds, data, prior_term, None, f"{branch}: {parts}")
