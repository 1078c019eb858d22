"""Compare trajectories given as stamped poses (e.g. read from TUM files): ATE and RPE via evo.

Stamps are associated as ``evo_ape`` does (``evo.core.sync.associate_trajectories``, nearest
stamp within ``max_diff_s``), so the ATE equals ``evo_ape tum truth.tum est.tum`` on the same
files; with identical stamps (tagloc's own exports) every pose is matched.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.eval.metrics import EvaluationError, TrajectoryError, _to_evo, absolute_trajectory_error
from tagloc.eval.trajectories import RelativeError, relative_pose_error
from tagloc.geometry import SE3


@dataclass(frozen=True, slots=True)
class TrajectoryComparison:
    """ATE and RPE of one estimate against a reference.

    Attributes
    ----------
    n_matched : int
        Pose pairs associated by stamp.
    ate : TrajectoryError
        Translation APE, metres (unaligned unless asked).
    rpe : RelativeError or None
        Per ``delta_m`` of reference path (None if the path is shorter).
    """

    n_matched: int
    ate: TrajectoryError
    rpe: RelativeError | None


def compare_trajectories(
    stamps_ref_ns: npt.NDArray[np.int64],
    T_map_base_ref: SE3,
    stamps_est_ns: npt.NDArray[np.int64],
    T_map_base_est: SE3,
    *,
    max_diff_s: float = 0.01,
    delta_m: float = 1.0,
    align: bool = False,
) -> TrajectoryComparison:
    """Associate by stamp, then ATE (evo APE) and RPE (evo RPE) of the estimate.

    Parameters
    ----------
    stamps_ref_ns, stamps_est_ns : (N,), (M,) int64
    T_map_base_ref, T_map_base_est : SE3 batches of N and M
        Poses of the base in the same fixed frame.
    max_diff_s : float
        Largest stamp difference of an associated pair, seconds (evo's default 0.01 s).
    delta_m : float
        RPE pair spacing along the reference path, metres.
    align : bool
        Rigidly align the estimate onto the reference first (``evo_ape -a``).

    Raises
    ------
    EvaluationError
        If fewer than 2 poses can be associated.
    """
    from evo.core import sync

    traj_ref = _to_evo(stamps_ref_ns, T_map_base_ref, "reference")
    traj_est = _to_evo(stamps_est_ns, T_map_base_est, "estimate")
    try:
        ref, est = sync.associate_trajectories(traj_ref, traj_est, max_diff=max_diff_s)
    except sync.SyncException as exc:
        raise EvaluationError(f"cannot associate the trajectories by stamp: {exc}") from None
    if ref.num_poses < 2:
        raise EvaluationError(f"only {ref.num_poses} poses associated within {max_diff_s} s")
    stamps_ns = np.round(np.asarray(ref.timestamps) * 1e9).astype(np.int64)
    T_ref = SE3.from_matrix(np.asarray(ref.poses_se3), normalize=True)
    T_est = SE3.from_matrix(np.asarray(est.poses_se3), normalize=True)
    return TrajectoryComparison(
        n_matched=int(ref.num_poses),
        ate=absolute_trajectory_error(stamps_ns, T_ref, T_est, align=align),
        rpe=relative_pose_error(stamps_ns, T_ref, T_est, delta_m=delta_m),
    )
