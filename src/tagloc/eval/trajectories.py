"""The trajectories of a run compared in the report, their errors, RPE and correction jumps.

Four estimates of ``T_map_base`` share the run's odometry stamps:

- ``truth``: the simulator's ground truth (absent for a bag without a truth topic);
- ``odometry``: odometry alone, ``T_map_base = T_odom_base`` (``odom`` coincides with ``map``
  at the start, as in the simulator);
- ``fused``: the filter's published correction, ``T_map_odom @ T_odom_base``;
- ``baseline``: the naive snap-to-every-fix baseline (:mod:`tagloc.localize.baseline`).

Their RPE is :mod:`tagloc.eval.rpe` (re-exported here).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.eval.errors import EvaluationError
from tagloc.eval.rpe import RelativeError, relative_pose_error
from tagloc.geometry import SE3
from tagloc.localize.baseline import BaselineRun, naive_snap_baseline
from tagloc.localize.run import LocalizationRun

__all__ = [
    "SNAP_EVENT_KINDS",
    "CorrectionJumps",
    "PoseErrors",
    "RelativeError",
    "RunTrajectories",
    "baseline_jumps",
    "correction_jumps",
    "fused_jumps",
    "pose_errors",
    "relative_pose_error",
    "run_trajectories",
]

#: Event kinds at which a correction snaps by design (excluded from the largest jump): a
#: (re)initialization, and a declared floor change (the correction moves by the floors' heights).
SNAP_EVENT_KINDS = ("initialized", "reinitialized_kidnap", "floor_changed")


@dataclass(frozen=True, slots=True, eq=False)
class RunTrajectories:
    """The estimates of ``T_map_base`` compared (module docstring), all at ``stamps_ns``."""

    stamps_ns: npt.NDArray[np.int64]
    T_map_base_truth: SE3 | None
    T_map_base_odometry: SE3
    T_map_base_fused: SE3
    T_map_base_baseline: SE3
    baseline: BaselineRun

    def estimates(self) -> dict[str, SE3]:
        """``{"odometry": ..., "fused": ..., "baseline": ...}``, in that order."""
        return {
            "odometry": self.T_map_base_odometry,
            "fused": self.T_map_base_fused,
            "baseline": self.T_map_base_baseline,
        }


def run_trajectories(run: LocalizationRun) -> RunTrajectories:
    """Build the compared trajectories of ``run`` (the baseline is computed here)."""
    baseline = naive_snap_baseline(run.stamps_ns, run.T_odom_base, run.fixes)
    return RunTrajectories(
        stamps_ns=np.asarray(run.stamps_ns, dtype=np.int64),
        T_map_base_truth=run.T_map_base_truth,
        T_map_base_odometry=run.T_odom_base,
        T_map_base_fused=run.T_map_base,
        T_map_base_baseline=baseline.T_map_base,
        baseline=baseline,
    )


@dataclass(frozen=True, slots=True)
class PoseErrors:
    """Per-stamp error of an estimate against the reference.

    Attributes
    ----------
    translation_m : (N,) float
        ``|t_est - t_ref|``, metres.
    rotation_deg : (N,) float
        Angle of ``R_ref^T R_est``, degrees, in ``[0, 180]``.
    """

    translation_m: FloatArray
    rotation_deg: FloatArray


def pose_errors(T_map_base_ref: SE3, T_map_base_est: SE3) -> PoseErrors:
    """Translation (m) and rotation-angle (deg) error of each estimated pose (same length)."""
    if len(T_map_base_ref) != len(T_map_base_est):
        raise EvaluationError(
            f"pose_errors: {len(T_map_base_ref)} reference vs {len(T_map_base_est)} poses"
        )
    translation_m = np.linalg.norm(
        np.asarray(T_map_base_est.translation) - np.asarray(T_map_base_ref.translation), axis=-1
    )
    return PoseErrors(
        translation_m=translation_m,
        rotation_deg=_rotation_angle_deg(
            np.asarray(T_map_base_ref.rotation.matrix), np.asarray(T_map_base_est.rotation.matrix)
        ),
    )


def _rotation_angle_deg(R_map_ref: FloatArray, R_map_est: FloatArray) -> FloatArray:
    """Angle of ``R_ref^T R_est`` for batches of rotation matrices, degrees."""
    trace = np.einsum("...ij,...ij->...", R_map_ref, R_map_est)  # trace(R_ref^T R_est)
    angle_deg: FloatArray = np.degrees(np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0)))
    return angle_deg


@dataclass(frozen=True, slots=True)
class CorrectionJumps:
    """How much the published ``map -> odom`` correction moved the base between stamps.

    The jump of step ``k`` (rows ``k`` to ``k + 1``) is the change of ``T_map_base`` at the same
    odometry, ``(T_map_odom[k] @ T_odom_base[k+1])^-1 @ (T_map_odom[k+1] @ T_odom_base[k+1])``.

    Attributes
    ----------
    translation_m, rotation_deg : (N - 1,) float
        Per step; 0 for the excluded steps (snaps by design, before the first correction).
    largest_translation_m, largest_rotation_deg : float
        Over the kept steps.
    largest_at_ns : int
        Stamp (row ``k + 1``) of the largest translation jump; -1 if none.
    n_excluded : int
        Steps excluded as (re)initialization snaps.
    """

    translation_m: FloatArray
    rotation_deg: FloatArray
    largest_translation_m: float
    largest_rotation_deg: float
    largest_at_ns: int
    n_excluded: int


def correction_jumps(
    stamps_ns: npt.NDArray[np.int64],
    T_map_odom: SE3,
    T_odom_base: SE3,
    initialized: npt.NDArray[np.bool_],
    snap_stamps_ns: Sequence[int] = (),
) -> CorrectionJumps:
    """Jumps of a published correction series, excluding snaps by design.

    Parameters
    ----------
    stamps_ns : (N,) int64
    T_map_odom, T_odom_base : SE3 batches of N
    initialized : (N,) bool
        Steps into or within uninitialized rows are excluded (the first snap is not a jump).
    snap_stamps_ns : sequence of int
        Stamps of (re)initializations; the step into the first row at or after each is excluded.
    """
    n = len(stamps_ns)
    if n < 2:
        empty = np.zeros(0)
        return CorrectionJumps(empty, empty, 0.0, 0.0, -1, 0)
    T_odom_base_next = T_odom_base[1:]
    step = (T_map_odom[:-1] @ T_odom_base_next).inverse() @ (T_map_odom[1:] @ T_odom_base_next)
    translation = np.linalg.norm(np.asarray(step.translation), axis=1)
    rotation = _rotation_angle_deg(
        np.broadcast_to(np.eye(3), (n - 1, 3, 3)), np.asarray(step.rotation.matrix)
    )
    keep = np.asarray(initialized[:-1], dtype=bool).copy()
    rows = np.searchsorted(stamps_ns, np.asarray(snap_stamps_ns, dtype=np.int64), side="left")
    snap_steps = rows[(rows >= 1) & (rows < n)] - 1
    n_excluded = int(np.count_nonzero(keep[snap_steps]))
    keep[snap_steps] = False
    translation = np.where(keep, translation, 0.0)
    rotation = np.where(keep, rotation, 0.0)
    k = int(np.argmax(translation))
    return CorrectionJumps(
        translation_m=translation,
        rotation_deg=rotation,
        largest_translation_m=float(translation[k]),
        largest_rotation_deg=float(rotation.max()),
        largest_at_ns=int(stamps_ns[k + 1]) if translation[k] > 0 else -1,
        n_excluded=n_excluded,
    )


def fused_jumps(run: LocalizationRun) -> CorrectionJumps:
    """Jumps of the filter's published correction; (re)initialization events excluded."""
    snaps = [e.stamp_ns for e in run.events if str(e.kind) in SNAP_EVENT_KINDS]
    return correction_jumps(run.stamps_ns, run.T_map_odom, run.T_odom_base, run.initialized, snaps)


def baseline_jumps(run: LocalizationRun, baseline: BaselineRun) -> CorrectionJumps:
    """Jumps of the baseline's correction: its first snap, and its first snap after each kidnap
    (the baseline's re-initialization), excluded, as the filter's (re)initializations are."""
    snap_stamps = np.array([a.stamp_ns for a in baseline.snaps], dtype=np.int64)
    after_kidnap = [
        int(snap_stamps[i])
        for i in np.searchsorted(snap_stamps, np.asarray(run.kidnaps_ns, dtype=np.int64))
        if i < len(snap_stamps)
    ]
    return correction_jumps(
        run.stamps_ns, baseline.T_map_odom, run.T_odom_base, baseline.initialized, after_kidnap
    )
