"""Small pieces of the on-site evaluation: error statistics and the fused pose at any stamp."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.geometry import SE3
from tagloc.localize.run import LocalizationRun

__all__ = ["ErrorStats", "error_stats", "fused_pose_at", "truth_pose_at"]


@dataclass(frozen=True, slots=True)
class ErrorStats:
    """Median, 95th percentile and max of a set of errors (NaN when empty)."""

    n: int
    median: float
    p95: float
    max: float

    def to_dict(self) -> dict[str, float | int]:
        return {"n": self.n, "median": self.median, "p95": self.p95, "max": self.max}


def error_stats(values: npt.ArrayLike) -> ErrorStats:
    """:class:`ErrorStats` of the finite ``values``."""
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        return ErrorStats(0, math.nan, math.nan, math.nan)
    return ErrorStats(int(v.size), float(np.median(v)), float(np.percentile(v, 95)), float(v.max()))


def fused_pose_at(
    run: LocalizationRun, stamps_ns: npt.ArrayLike
) -> tuple[SE3, npt.NDArray[np.bool_]]:
    """The run's fused ``T_map_base`` at ``stamps_ns``: the odometry interpolated between its
    samples, composed with the correction published at the sample before (as a consumer of
    ``map -> odom`` would). Second value: where it is defined (inside the run, initialized)."""
    stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    s = run.stamps_ns
    i = np.clip(np.searchsorted(s, stamps, side="right") - 1, 0, len(s) - 1)
    j = np.minimum(i + 1, len(s) - 1)
    span = np.maximum(s[j] - s[i], 1)
    alpha = np.clip((stamps - s[i]) / span, 0.0, 1.0)
    T_odom_base = run.T_odom_base[i].interpolate_rt(run.T_odom_base[j], alpha)
    valid = (stamps >= s[0]) & (stamps <= s[-1]) & run.initialized[i]
    return run.T_map_odom[i] @ T_odom_base, valid


def truth_pose_at(run: LocalizationRun, stamps_ns: npt.ArrayLike) -> SE3 | None:
    """Ground truth ``T_map_base`` interpolated at ``stamps_ns`` (None without truth)."""
    if run.T_map_base_truth is None:
        return None
    stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    s = run.stamps_ns
    i = np.clip(np.searchsorted(s, stamps, side="right") - 1, 0, len(s) - 1)
    j = np.minimum(i + 1, len(s) - 1)
    alpha = np.clip((stamps - s[i]) / np.maximum(s[j] - s[i], 1), 0.0, 1.0)
    return run.T_map_base_truth[i].interpolate_rt(run.T_map_base_truth[j], alpha)
