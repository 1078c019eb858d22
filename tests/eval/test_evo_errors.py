"""Degenerate alignments and bad RPE spacings are one EvaluationError each."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.eval.metrics import EvaluationError, absolute_trajectory_error
from tagloc.eval.trajectories import relative_pose_error
from tagloc.geometry import SE3

N = 50
STAMPS_NS = np.arange(N, dtype=np.int64) * 100_000_000


def _track(xyz: np.ndarray) -> SE3:
    return SE3.from_rotvec(np.zeros((len(xyz), 3)), xyz)


@pytest.mark.parametrize("kind", ["static", "straight"])
def test_aligning_a_degenerate_track_is_an_evaluation_error(kind: str) -> None:
    xyz = np.zeros((N, 3)) if kind == "static" else np.c_[np.linspace(0, 5, N), np.zeros((N, 2))]
    T = _track(xyz)
    with pytest.raises(EvaluationError, match="cannot align the estimate onto the reference"):
        absolute_trajectory_error(STAMPS_NS, T, T, align=True)
    assert absolute_trajectory_error(STAMPS_NS, T, T).rmse == 0.0  # unaligned still works


@pytest.mark.parametrize("delta_m", [-1.0, 0.0, float("nan"), float("inf")])
def test_a_bad_rpe_spacing_is_an_evaluation_error(delta_m: float) -> None:
    T = _track(np.c_[np.linspace(0, 5, N), np.zeros((N, 2))])
    with pytest.raises(EvaluationError, match="RPE pair spacing"):
        relative_pose_error(STAMPS_NS, T, T, delta_m=delta_m)
