"""Trajectory error metrics computed with evo (Grupp, 2017), the field's reference implementation.

Conventions: both trajectories are batched :class:`~tagloc.geometry.SE3` poses of ``base`` in a
common fixed frame (``T_map_base`` ground truth vs an estimate), sampled at the same
integer-nanosecond stamps. ATE is the RMSE of the translation error (metres), optionally after a
rigid (SE(3), Umeyama 1991) alignment of the estimate onto the reference; without alignment it
measures the error a user of the estimate actually sees when the frames coincide at the start (as
``odom`` and ``map`` do in the simulator).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tagloc.errors import TaglocError
from tagloc.geometry import SE3


class EvaluationError(TaglocError, ValueError):
    """Trajectories that cannot be compared (different lengths, stamps, NaN)."""


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
        Whether the estimate was rigidly aligned to the reference first.
    """

    rmse: float
    mean: float
    median: float
    max: float
    errors_m: NDArray[np.float64]
    aligned: bool


def _to_evo(stamps_ns: NDArray[np.int64], T_ref_base: SE3, name: str) -> object:
    from evo.core.trajectory import PoseTrajectory3D

    matrices = np.asarray(T_ref_base.as_matrix(), dtype=np.float64)
    if matrices.ndim != 3:
        raise EvaluationError(f"{name}: expected a batch of poses, got a single pose")
    if not np.all(np.isfinite(matrices)):
        raise EvaluationError(f"{name}: trajectory contains NaN or inf")
    return PoseTrajectory3D(
        poses_se3=list(matrices), timestamps=np.asarray(stamps_ns, dtype=np.float64) * 1e-9
    )


def absolute_trajectory_error(
    stamps_ns: NDArray[np.int64], T_map_base_ref: SE3, T_map_base_est: SE3, *, align: bool = False
) -> TrajectoryError:
    """ATE (translation part) of an estimate against a reference, via ``evo.core.metrics.APE``.

    Parameters
    ----------
    stamps_ns : (N,) int64
        Common stamps of both trajectories, nanoseconds, strictly increasing.
    T_map_base_ref, T_map_base_est : SE3 batches of N poses
        Reference (ground truth) and estimate, both ``base`` in the same fixed frame.
    align : bool
        Rigidly align (SE(3) Umeyama, no scale) the estimate onto the reference first.

    Raises
    ------
    EvaluationError
        Lengths differ, stamps are not strictly increasing, poses are not finite, or the
        alignment is degenerate (a static or straight track).
    """
    from evo.core import metrics
    from evo.core.geometry import GeometryException

    stamps = np.asarray(stamps_ns)
    if len(T_map_base_ref) != len(stamps) or len(T_map_base_est) != len(stamps):
        raise EvaluationError(
            f"trajectory lengths differ: {len(stamps)} stamps, {len(T_map_base_ref)} reference "
            f"poses, {len(T_map_base_est)} estimated poses"
        )
    if len(stamps) < 2 or np.any(np.diff(stamps) <= 0):
        raise EvaluationError("stamps_ns must hold at least 2 strictly increasing stamps")
    traj_ref = _to_evo(stamps, T_map_base_ref, "reference")
    traj_est = _to_evo(stamps, T_map_base_est, "estimate")
    if align:
        try:
            traj_est.align(traj_ref)  # type: ignore[attr-defined]
        except GeometryException as exc:
            raise EvaluationError(
                f"cannot align the estimate onto the reference ({exc}): the positions do not "
                "span enough space (a static or straight track); evaluate it without alignment"
            ) from None
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    try:
        ape.process_data((traj_ref, traj_est))
    except metrics.MetricsException as exc:
        raise EvaluationError(f"cannot compute the ATE: {exc}") from None
    errors = np.asarray(ape.error, dtype=np.float64)
    return TrajectoryError(
        rmse=float(np.sqrt(np.mean(errors**2))),
        mean=float(np.mean(errors)),
        median=float(np.median(errors)),
        max=float(np.max(errors)),
        errors_m=errors,
        aligned=align,
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
