"""Summary of a simulated drive: how far the odometry drifted from ground truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagloc.eval.metrics import (
    EvaluationError,
    TrajectoryError,
    absolute_trajectory_error,
    endpoint_drift,
)
from tagloc.sim import Drive


@dataclass(frozen=True, slots=True)
class DriveSummary:
    """Numbers a person wants after a drive (metres, seconds, degrees).

    ``odom_ate`` is unaligned (``odom`` coincides with ``map`` at the start, so this is the error a
    planner reading ``odom`` as ``map`` would see); ``odom_ate_aligned`` removes the best rigid
    alignment first, the number SLAM papers quote (a straight route cannot be aligned: then it is
    the unaligned error, with ``aligned`` False).
    """

    length_m: float
    duration_s: float
    n_poses: int
    n_camera_frames: int
    n_tags: int
    endpoint_drift_m: float
    endpoint_yaw_drift_deg: float
    drift_percent: float
    odom_ate: TrajectoryError
    odom_ate_aligned: TrajectoryError


def summarize_drive(drive: Drive) -> DriveSummary:
    """Compare the drive's odometry with its ground truth (ATE unaligned and aligned)."""
    length_m = float(drive.distance_m[-1])
    drift_m, drift_yaw = endpoint_drift(drive.T_map_base, drive.T_odom_base)
    odom_ate = absolute_trajectory_error(drive.stamps_ns, drive.T_map_base, drive.T_odom_base)
    try:
        odom_ate_aligned = absolute_trajectory_error(
            drive.stamps_ns, drive.T_map_base, drive.T_odom_base, align=True
        )
    except EvaluationError:  # a straight route: no rotation about it is observable
        odom_ate_aligned = odom_ate
    return DriveSummary(
        length_m=length_m,
        duration_s=float(drive.stamps_ns[-1] - drive.stamps_ns[0]) * 1e-9,
        n_poses=len(drive.stamps_ns),
        n_camera_frames=len(drive.camera_stamps_ns),
        n_tags=len(drive.world.tags),
        endpoint_drift_m=drift_m,
        endpoint_yaw_drift_deg=float(np.degrees(drift_yaw)),
        drift_percent=100.0 * drift_m / max(length_m, 1e-9),
        odom_ate=odom_ate,
        odom_ate_aligned=odom_ate_aligned,
    )
