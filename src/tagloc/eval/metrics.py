"""Absolute trajectory error (ATE): the translation part of ``evo_ape``, computed here.

Both trajectories are batched :class:`~tagloc.geometry.SE3` poses of ``base`` in a common fixed
frame (``T_map_base`` ground truth ``Q_i`` vs an estimate ``P_i``) at the same integer-nanosecond
stamps. The per-pose error is

``e_i = |t(P_i) - t(Q_i)|``   (metres; ``evo_ape`` ``--pose_relation trans_part``)

optionally after aligning the estimate onto the reference (:mod:`tagloc.eval.alignment`:
SE(3) Umeyama as ``evo_ape -a``, Sim(3) as ``-as``). The summary is
``rmse = sqrt(1/n sum e_i^2)``, the mean, the median and the max. Without alignment the ATE is the
error a user of the estimate actually sees when the frames coincide at the start (as ``odom`` and
``map`` do in the simulator).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tagloc.eval.alignment import umeyama_alignment
from tagloc.eval.errors import EvaluationError
from tagloc.geometry import SE3

__all__ = [
    "EvaluationError",
    "TrajectoryError",
    "absolute_trajectory_error",
    "endpoint_drift",
    "paired_ate",
]


@dataclass(frozen=True, slots=True)
class TrajectoryError:
    """Summary of a translation-error series (metres).

    Attributes
    ----------
    rmse, mean, median, max : float
        Statistics of the per-pose translation error, metres.
    errors_m : (N,) float
        The per-pose translation error, metres.
    aligned : bool
        Whether the estimate was aligned to the reference first.
    scale : float
        The scale of the alignment (1.0 unless ``correct_scale``).
    """

    rmse: float
    mean: float
    median: float
    max: float
    errors_m: NDArray[np.float64]
    aligned: bool
    scale: float = 1.0


def _positions(T_ref_base: SE3, name: str) -> NDArray[np.float64]:
    xyz = np.asarray(T_ref_base.translation, dtype=np.float64)
    if xyz.ndim != 2:
        raise EvaluationError(f"{name}: expected a batch of poses, got a single pose")
    if not np.all(np.isfinite(xyz)):
        raise EvaluationError(f"{name}: trajectory contains NaN or inf")
    return xyz


def absolute_trajectory_error(
    stamps_ns: NDArray[np.int64],
    T_map_base_ref: SE3,
    T_map_base_est: SE3,
    *,
    align: bool = False,
    correct_scale: bool = False,
) -> TrajectoryError:
    """ATE (translation part) of an estimate against a reference (module docstring).

    Parameters
    ----------
    stamps_ns : (N,) int64
        Common stamps of both trajectories, nanoseconds, strictly increasing.
    T_map_base_ref, T_map_base_est : SE3 batches of N poses
        Reference (ground truth) and estimate, both ``base`` in the same fixed frame.
    align : bool
        Align the estimate onto the reference first (Umeyama; ``evo_ape -a``).
    correct_scale : bool
        With ``align``, also solve for a scale (``evo_ape -as``).

    Raises
    ------
    EvaluationError
        Lengths differ, stamps are not strictly increasing, poses are not finite, or the
        alignment is degenerate (a static or straight track).
    """
    stamps = np.asarray(stamps_ns)
    if len(T_map_base_ref) != len(stamps) or len(T_map_base_est) != len(stamps):
        raise EvaluationError(
            f"trajectory lengths differ: {len(stamps)} stamps, {len(T_map_base_ref)} reference "
            f"poses, {len(T_map_base_est)} estimated poses"
        )
    if len(stamps) < 2 or np.any(np.diff(stamps) <= 0):
        raise EvaluationError("stamps_ns must hold at least 2 strictly increasing stamps")
    return paired_ate(T_map_base_ref, T_map_base_est, align=align, correct_scale=correct_scale)


def paired_ate(
    T_map_base_ref: SE3, T_map_base_est: SE3, *, align: bool = False, correct_scale: bool = False
) -> TrajectoryError:
    """ATE of poses paired row by row (already associated: no stamps checked).

    Raises
    ------
    EvaluationError
        Lengths differ, poses are not finite, or the alignment is degenerate.
    """
    if len(T_map_base_ref) != len(T_map_base_est):
        raise EvaluationError(
            f"{len(T_map_base_ref)} reference vs {len(T_map_base_est)} estimated poses"
        )
    xyz_ref = _positions(T_map_base_ref, "reference")
    xyz_est = _positions(T_map_base_est, "estimate")
    scale = 1.0
    if align:
        alignment = umeyama_alignment(xyz_est, xyz_ref, with_scale=correct_scale)
        xyz_est = alignment.apply_to_positions(xyz_est)
        scale = alignment.scale
    errors = np.linalg.norm(xyz_est - xyz_ref, axis=1)
    return TrajectoryError(
        rmse=math.sqrt(float(np.mean(errors**2))),
        mean=float(np.mean(errors)),
        median=float(np.median(errors)),
        max=float(np.max(errors)),
        errors_m=errors,
        aligned=align,
        scale=scale,
    )


def endpoint_drift(T_map_base_ref: SE3, T_map_base_est: SE3) -> tuple[float, float]:
    """Translation (metres) and yaw (radians, wrapped to [-pi, pi)) error at the last pose."""
    T_ref_end = T_map_base_ref[-1]
    T_est_end = T_map_base_est[-1]
    T_ref_est = T_ref_end.inverse() @ T_est_end
    delta = np.asarray(T_est_end.translation) - np.asarray(T_ref_end.translation)
    R = np.asarray(T_ref_est.rotation.as_matrix())
    yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    return float(np.linalg.norm(delta)), yaw
