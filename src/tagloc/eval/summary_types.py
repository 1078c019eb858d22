"""The records of an evaluation: each estimator's scores, the pass/fail checks, the summary the
report states (``summary.json``) and the series the plots draw; :mod:`tagloc.eval.summary`
computes them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tagloc.eval.fixstats import AcceptanceBin, FixCounts, SuspectSource
from tagloc.eval.protocol import EvalConfig, KidnapRecovery, Reliability
from tagloc.eval.refusals import FixDecisions
from tagloc.eval.rides import RideRow
from tagloc.eval.supervision import CorrectionBounds, LadderSummary
from tagloc.eval.trajectories import CorrectionJumps, PoseErrors, RelativeError, RunTrajectories

__all__ = ["Check", "EstimatorScore", "EvalSummary", "Evaluation"]


@dataclass(frozen=True, slots=True)
class EstimatorScore:
    """Scores of one estimate of ``T_map_base`` (NaN / None where truth is unknown).

    Attributes
    ----------
    ate_rmse_m, ate_mean_m, ate_median_m, ate_max_m : float
        Translation APE statistics (unaligned), metres.
    rotation_rmse_deg : float
        RMSE of the rotation-angle error, degrees.
    rpe : RelativeError or None
        RPE per ``rpe_delta_m`` of truth path.
    largest_jump_m, largest_jump_deg : float
        Largest change of ``T_map_base`` between consecutive stamps caused by the correction,
        (re)initialization snaps excluded (0 for odometry, which has no correction).
    false_fixes_accepted : int or None
        Fixes from false detections applied (None for odometry, or when unknown).
    reliability : Reliability or None
        The per-opportunity protocol for this estimate (None for odometry or without truth).
    """

    ate_rmse_m: float
    ate_mean_m: float
    ate_median_m: float
    ate_max_m: float
    rotation_rmse_deg: float
    rpe: RelativeError | None
    largest_jump_m: float
    largest_jump_deg: float
    false_fixes_accepted: int | None
    reliability: Reliability | None


@dataclass(frozen=True, slots=True)
class Check:
    """One pass/fail line of the report: ``value`` against ``target`` (``passed`` None when the
    value is unknown, e.g. no ground truth)."""

    name: str
    value: float
    target: str
    passed: bool | None


@dataclass(frozen=True, slots=True)
class EvalSummary:
    """Everything the report states, machine-readable (``summary.json``).

    Attributes
    ----------
    name : str
        Scenario or bag name.
    has_truth : bool
    n_stamps : int
    duration_s, distance_m : float
        Run duration; path length of the truth (else of the odometry), metres.
    estimators : dict of str -> EstimatorScore
        ``"odometry"``, ``"fused"``, ``"baseline"``.
    fixes : FixCounts
    fix_decisions : FixDecisions
        The attempts by decision and reason, per camera, and the hint of a dominant refusal.
    acceptance_vs_range, acceptance_vs_angle : list of AcceptanceBin
        Range bins in metres, angle bins in degrees.
    n_unknown_range, n_unknown_angle : int
        Attempts without a finite value (refused by a per-observation gate: no pose kept).
    suspect_sources : list of SuspectSource
    kidnaps : list of KidnapRecovery
    cap_translation_m, cap_rotation_deg : float
        The filter's configured correction cap per update (NaN if not recorded).
    n_jump_steps_over_cap : int
        Stamp steps whose fused correction jump exceeds the translation cap.
    ladder : LadderSummary
        Time at each level of the degradation ladder, and its transitions.
    bounds : CorrectionBounds
        The unclipped estimate's largest jump beside the published one, and how often the cap
        and the speed limit bound a publication.
    checks : list of Check
    config : EvalConfig
    rides : list of RideRow
        The timeline of the run's elevator rides (:mod:`tagloc.eval.rides`; empty without).
    """

    name: str
    has_truth: bool
    n_stamps: int
    duration_s: float
    distance_m: float
    estimators: dict[str, EstimatorScore]
    fixes: FixCounts
    fix_decisions: FixDecisions
    acceptance_vs_range: list[AcceptanceBin]
    acceptance_vs_angle: list[AcceptanceBin]
    n_unknown_range: int
    n_unknown_angle: int
    suspect_sources: list[SuspectSource]
    kidnaps: list[KidnapRecovery]
    cap_translation_m: float
    cap_rotation_deg: float
    n_jump_steps_over_cap: int
    ladder: LadderSummary
    bounds: CorrectionBounds
    checks: list[Check]
    config: EvalConfig
    rides: list[RideRow] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """Whether no check failed (unknown checks do not fail)."""
        return all(c.passed is not False for c in self.checks)


@dataclass(frozen=True, slots=True, eq=False)
class Evaluation:
    """The summary plus the series the plots draw."""

    summary: EvalSummary
    trajectories: RunTrajectories
    errors: dict[str, PoseErrors]
    jumps: dict[str, CorrectionJumps]
    #: ``(t_s, level)`` of the ladder as a step function (None without a ladder record).
    ladder_steps: tuple[np.ndarray, np.ndarray] | None = None
