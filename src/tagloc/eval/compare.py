"""Compare trajectories given as stamped poses (e.g. read from TUM files): ATE and RPE.

Stamps are associated as ``evo_ape`` does (:mod:`tagloc.eval.association`: nearest stamp within
``max_diff_s``), then the ATE (:mod:`tagloc.eval.metrics`) and the RPE per metre of reference
path (:mod:`tagloc.eval.rpe`) are computed on the pairs, so the ATE equals
``evo_ape tum truth.tum est.tum`` on the same files; with identical stamps (tagloc's own exports)
every pose is matched.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.eval.association import associate_stamps
from tagloc.eval.errors import EvaluationError
from tagloc.eval.metrics import TrajectoryError, paired_ate
from tagloc.eval.rpe import RelativeError, relative_pose_error
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


def _batch(stamps_ns: npt.ArrayLike, T_map_base: SE3, name: str) -> npt.NDArray[np.int64]:
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    if len(T_map_base.batch_shape) != 1 or len(T_map_base) != len(stamps):
        raise EvaluationError(f"{name}: expected a batch of {len(stamps)} poses, one per stamp")
    return stamps


def compare_trajectories(
    stamps_ref_ns: npt.NDArray[np.int64],
    T_map_base_ref: SE3,
    stamps_est_ns: npt.NDArray[np.int64],
    T_map_base_est: SE3,
    *,
    max_diff_s: float = 0.01,
    delta_m: float = 1.0,
    align: bool = False,
    correct_scale: bool = False,
) -> TrajectoryComparison:
    """Associate by stamp, then ATE and RPE (per ``delta_m`` of reference path) of the estimate.

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
        Align the estimate onto the reference first (``evo_ape -a``).
    correct_scale : bool
        With ``align``, also solve for a scale (``evo_ape -as``).

    Raises
    ------
    EvaluationError
        If fewer than 2 poses can be associated.
    """
    stamps_ref = _batch(stamps_ref_ns, T_map_base_ref, "reference")
    stamps_est = _batch(stamps_est_ns, T_map_base_est, "estimate")
    i_ref, i_est = associate_stamps(stamps_ref, stamps_est, round(max_diff_s * 1e9))
    if len(i_ref) < 2:
        raise EvaluationError(f"only {len(i_ref)} poses associated within {max_diff_s} s")
    T_ref, T_est = T_map_base_ref[i_ref], T_map_base_est[i_est]
    return TrajectoryComparison(
        n_matched=len(i_ref),
        ate=paired_ate(T_ref, T_est, align=align, correct_scale=correct_scale),
        rpe=relative_pose_error(stamps_ref[i_ref], T_ref, T_est, delta_m=delta_m),
    )
