"""Score a :class:`~tagloc.localize.run.LocalizationRun`: the numbers of the report.

:func:`evaluate` reads as the list of what is measured: the compared trajectories (truth,
odometry only, fused, naive baseline), ATE (translation, unaligned, as ``evo_ape``: ``odom`` and
``map`` coincide at the start) and RPE per metre for each, the reliability protocol, acceptance
against range and angle, false fixes, suspect sources, kidnap recovery, the largest correction
jump, what the degradation ladder and the correction's bounds did, and the pass/fail checks.
:func:`summary_to_dict` gives the stable, JSON-ready form written as ``summary.json``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from tagloc.eval.elevator import apply_ride_checks, cab_errors, cab_frames_of
from tagloc.eval.fixstats import (
    acceptance_vs_angle,
    acceptance_vs_range,
    fix_counts,
    suspect_sources,
)
from tagloc.eval.metrics import EvaluationError, absolute_trajectory_error
from tagloc.eval.protocol import (
    EvalConfig,
    reliability_protocol,
    relocalization_times,
)
from tagloc.eval.refusals import fix_decisions
from tagloc.eval.rides import ride_rows
from tagloc.eval.summary_types import Check, EstimatorScore, EvalSummary, Evaluation
from tagloc.eval.supervision import (
    correction_bounds,
    ladder_steps,
    ladder_summary,
)
from tagloc.eval.trajectories import (
    CorrectionJumps,
    PoseErrors,
    RunTrajectories,
    baseline_jumps,
    fused_jumps,
    pose_errors,
    relative_pose_error,
    run_trajectories,
)
from tagloc.localize.run import LocalizationRun

#: Version of the ``summary.json`` layout; bumped when a key changes meaning or disappears.
SUMMARY_SCHEMA_VERSION = 1

ESTIMATORS = ("odometry", "fused", "baseline")


def evaluate(run: LocalizationRun, config: EvalConfig | None = None) -> Evaluation:
    """Score ``run`` (module docstring).

    Raises
    ------
    EvaluationError
        If the run's trajectories cannot be compared (NaN poses, non-increasing stamps).
    """
    cfg = config or EvalConfig()
    stamps = np.asarray(run.stamps_ns)
    if len(stamps) < 2 or np.any(np.diff(stamps) <= 0):
        raise EvaluationError(f"{run.name}: stamps_ns must hold >= 2 strictly increasing stamps")
    # 1. the trajectories compared, and the correction jumps of the two correctors
    traj = run_trajectories(run)
    jumps = {"fused": fused_jumps(run), "baseline": baseline_jumps(run, traj.baseline)}
    # 2. errors against truth, when known
    truth = traj.T_map_base_truth
    errors = (
        {} if truth is None else {k: pose_errors(truth, v) for k, v in traj.estimates().items()}
    )
    # 3. what became of the fixes
    counts = fix_counts(run.fixes, cfg.opportunity_range_m)
    by_range, unknown_range = acceptance_vs_range(run.fixes, cfg.range_bin_edges_m)
    by_angle, unknown_angle = acceptance_vs_angle(run.fixes, cfg.angle_bin_edges_deg)
    listed = run.metadata.get("suspect_sources", [])
    suspects = suspect_sources(
        run.events, run.fixes, list(listed) if isinstance(listed, list) else []
    )
    kidnaps = (
        relocalization_times(
            run.kidnaps_ns, run.frames, run.fixes, traj.stamps_ns, errors["fused"], cfg
        )
        if errors
        else []
    )
    # 4. per-estimator scores
    baseline_per_frame = _snaps_per_frame(run, traj)
    estimators = {
        name: _score(run, traj, name, errors.get(name), jumps.get(name), cfg, baseline_per_frame)
        for name in ESTIMATORS
    }
    cap_m = _float(run.metadata.get("cap_translation_m"))
    summary = EvalSummary(
        name=run.name,
        has_truth=truth is not None,
        n_stamps=len(traj.stamps_ns),
        duration_s=float(traj.stamps_ns[-1] - traj.stamps_ns[0]) * 1e-9,
        distance_m=_path_length_m(truth if truth is not None else traj.T_map_base_odometry),
        estimators=estimators,
        fixes=counts,
        fix_decisions=fix_decisions(run.fixes),
        acceptance_vs_range=by_range,
        acceptance_vs_angle=by_angle,
        n_unknown_range=unknown_range,
        n_unknown_angle=unknown_angle,
        suspect_sources=suspects,
        kidnaps=kidnaps,
        cap_translation_m=cap_m,
        cap_rotation_deg=_float(run.metadata.get("cap_rotation_deg")),
        n_jump_steps_over_cap=int(np.count_nonzero(jumps["fused"].translation_m > cap_m + 1e-9))
        if math.isfinite(cap_m)
        else 0,
        ladder=ladder_summary(run),
        bounds=correction_bounds(run),
        checks=[],
        config=cfg,
        rides=ride_rows(run),
    )
    checks = apply_ride_checks(run, _checks(summary), Check)  # a run through elevator rides
    summary = dataclasses.replace(summary, checks=checks)
    steps = ladder_steps(run) if run.ladder else None
    return Evaluation(
        summary=summary, trajectories=traj, errors=errors, jumps=jumps, ladder_steps=steps
    )


def _score(
    run: LocalizationRun,
    traj: RunTrajectories,
    name: str,
    errors: PoseErrors | None,
    jumps: CorrectionJumps | None,
    cfg: EvalConfig,
    baseline_per_frame: list[int],
) -> EstimatorScore:
    """One estimator's :class:`EstimatorScore`."""
    nan = math.nan
    estimate = traj.estimates()[name]
    ate = rpe = reliability = None
    if errors is not None and traj.T_map_base_truth is not None:
        ate = absolute_trajectory_error(traj.stamps_ns, traj.T_map_base_truth, estimate)
        rpe = relative_pose_error(
            traj.stamps_ns, traj.T_map_base_truth, estimate, delta_m=cfg.rpe_delta_m
        )
        if name != "odometry":  # a cab-only frame is judged against the cab (the baseline has none)
            reliability = reliability_protocol(
                run.frames, traj.stamps_ns, errors, cfg,
                accepted_per_frame=baseline_per_frame if name == "baseline" else None,
                cab_frames=cab_frames_of(run), cab=cab_errors(run) if name == "fused" else None,
            )  # fmt: skip
    false_accepted = None
    if name != "odometry" and any(a.false_detection is not None for a in run.fixes):
        false_accepted = (
            traj.baseline.false_fixes_accepted
            if name == "baseline"
            else sum(a.accepted and a.false_detection is True for a in run.fixes)
        )
    return EstimatorScore(
        ate_rmse_m=ate.rmse if ate else nan,
        ate_mean_m=ate.mean if ate else nan,
        ate_median_m=ate.median if ate else nan,
        ate_max_m=ate.max if ate else nan,
        rotation_rmse_deg=float(np.sqrt(np.mean(errors.rotation_deg**2))) if errors else nan,
        rpe=rpe,
        largest_jump_m=jumps.largest_translation_m if jumps else 0.0,
        largest_jump_deg=jumps.largest_rotation_deg if jumps else 0.0,
        false_fixes_accepted=false_accepted,
        reliability=reliability,
    )


def _snaps_per_frame(run: LocalizationRun, traj: RunTrajectories) -> list[int]:
    """Baseline snaps per camera frame (by stamp), to score the baseline's reliability."""
    per_stamp: dict[int, int] = {}
    for a in traj.baseline.snaps:
        per_stamp[a.stamp_ns] = per_stamp.get(a.stamp_ns, 0) + 1
    return [per_stamp.get(f.stamp_ns, 0) for f in run.frames]


def _checks(s: EvalSummary) -> list[Check]:
    """The targets, as far as this run can show them."""
    cfg, fused = s.config, s.estimators["fused"]
    ate_target = f"<= {cfg.target_fused_ate_m:g}"
    if s.kidnaps:  # the truth jumps tens of metres at a kidnap: the relocalization check judges
        ate = Check("fused ATE RMSE (m)", fused.ate_rmse_m, ate_target + " (not judged: kidnap)",
                    None)  # fmt: skip
    else:
        ate = _check("fused ATE RMSE (m)", fused.ate_rmse_m, ate_target,
                     fused.ate_rmse_m <= cfg.target_fused_ate_m)  # fmt: skip
    checks = [ate]
    fraction = fused.reliability.fraction if fused.reliability else math.nan
    checks.append(
        _check("reliability (fraction of opportunities)", fraction,
               f">= {cfg.target_reliability:g}", fraction >= cfg.target_reliability)
    )  # fmt: skip
    false = math.nan if fused.false_fixes_accepted is None else float(fused.false_fixes_accepted)
    checks.append(
        _check("false fixes accepted", false, f"<= {cfg.target_false_fixes}",
               false <= cfg.target_false_fixes)
    )  # fmt: skip
    if math.isfinite(s.cap_translation_m):
        checks.append(
            _check("largest correction jump per odometry step (m)", fused.largest_jump_m,
                   f"<= cap {s.cap_translation_m:g}",
                   fused.largest_jump_m <= s.cap_translation_m + 1e-9)
        )  # fmt: skip
    if s.fixes.n_false_attempts:
        rate = s.fixes.true_in_range_acceptance
        checks.append(_check("true fixes in range accepted", rate, ">= 0.98", rate >= 0.98))
    for k in s.kidnaps:
        t = k.time_to_relocalize_s
        checks.append(
            _check(f"relocalized after kidnap at {k.kidnap_ns * 1e-9:.1f} s (s)", t,
                   f"<= {cfg.target_relocalize_s:g}", t <= cfg.target_relocalize_s)
        )  # fmt: skip
    return checks


def _check(name: str, value: float, target: str, ok: bool) -> Check:
    return Check(name, float(value), target, bool(ok) if math.isfinite(value) else None)


def _float(value: object) -> float:
    return float(value) if isinstance(value, int | float) else math.nan


def _path_length_m(T_map_base: Any) -> float:
    xyz = np.asarray(T_map_base.translation)
    return float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum()) if len(xyz) > 1 else 0.0


def summary_to_dict(summary: EvalSummary) -> dict[str, Any]:
    """The JSON form of ``summary``: stable keys, NaN and infinities as ``null``.

    Top-level keys: ``schema_version``, ``name``, ``has_truth``, ``passed``, ``n_stamps``,
    ``duration_s``, ``distance_m``, ``estimators`` (``odometry`` / ``fused`` / ``baseline``),
    ``fixes``, ``fix_decisions``, ``acceptance_vs_range``, ``acceptance_vs_angle``,
    ``n_unknown_range``, ``n_unknown_angle``, ``suspect_sources``, ``kidnaps``,
    ``cap_translation_m``, ``cap_rotation_deg``, ``n_jump_steps_over_cap``, ``ladder``,
    ``bounds``, ``checks``, ``config``, ``rides`` (one row per elevator ride,
    :class:`~tagloc.eval.rides.RideRow`).
    """
    out: dict[str, Any] = {"schema_version": SUMMARY_SCHEMA_VERSION}
    for field in dataclasses.fields(summary):
        value = getattr(summary, field.name)
        if field.name == "config":
            out["config"] = value.model_dump(mode="json")
        else:
            out[field.name] = _jsonable(value)
        if field.name == "has_truth":
            out["passed"] = summary.passed
    out["fixes"]["true_in_range_acceptance"] = _jsonable(summary.fixes.true_in_range_acceptance)
    out["fix_decisions"] = summary.fix_decisions.to_dict()
    for key in ("acceptance_vs_range", "acceptance_vs_angle"):
        for row, b in zip(out[key], getattr(summary, key), strict=True):
            row["acceptance"] = _jsonable(b.acceptance)
    return out


def _jsonable(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


__all__ = [
    "ESTIMATORS",
    "Check",
    "EstimatorScore",
    "EvalSummary",
    "Evaluation",
    "evaluate",
    "summary_to_dict",
]
