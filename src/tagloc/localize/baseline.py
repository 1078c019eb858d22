"""The naive baseline the filter is judged against: snap ``map -> odom`` to every single-tag fix.

What a first implementation does: each single-tag fix that passes the per-observation gates
(every :class:`~tagloc.localize.run.FixAttempt` whose decision does not start with
``"rejected:"``, i.e. every fix the pipeline offered to the filter) replaces the correction
outright, ``T_map_odom = T_map_base_fix @ T_odom_base(t_fix)^-1``, and the correction is held
until the next fix. No covariance, no chi-square gate, no k-consistency, no cap. Before its
first fix the baseline publishes the identity (``odom`` taken as ``map``, as at start-up).

The odometry ``T_odom_base(t_fix)`` is interpolated (slerp on rotation, linear on translation)
between the run's odometry samples that bracket the fix stamp; a fix takes effect from the
first odometry stamp at or after its own stamp (the row at which the pipeline applies it too).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.geometry import SE3
from tagloc.localize.fix import LocalizeError
from tagloc.localize.run import FixAttempt

__all__ = ["BaselineRun", "naive_snap_baseline", "offered_single_tag_fixes"]


@dataclass(frozen=True, slots=True, eq=False)
class BaselineRun:
    """The baseline's published series over a run's odometry stamps.

    Attributes
    ----------
    T_map_odom : SE3 batch of N
        The snapped correction in force at each stamp (identity before the first fix).
    T_map_base : SE3 batch of N
        ``T_map_odom @ T_odom_base``: the baseline's estimate of the base in the map.
    initialized : (N,) bool
        Whether a fix had been snapped to at or before each stamp.
    snaps : tuple of FixAttempt
        The fixes snapped to, in stamp order.
    snap_rows : (M,) int
        For each snap, the row (index into the stamps) from which it is in force.
    """

    T_map_odom: SE3
    T_map_base: SE3
    initialized: npt.NDArray[np.bool_]
    snaps: tuple[FixAttempt, ...]
    snap_rows: npt.NDArray[np.intp]

    @property
    def false_fixes_accepted(self) -> int:
        """Snaps built from a detection known to be false (simulator truth)."""
        return sum(a.false_detection is True for a in self.snaps)


def offered_single_tag_fixes(fixes: Sequence[FixAttempt]) -> list[FixAttempt]:
    """The single-tag fixes (``source`` ``"tag:<id>"``) of map tags that passed the
    per-observation gates (decision not ``"rejected:..."``), in stamp order (stable for equal
    stamps). A cab tag's fix is a pose in the cab, not in the map: never snapped to."""
    offered = [
        a for a in fixes
        if a.in_map and not a.decision.startswith("rejected:") and a.source.startswith("tag:")
    ]  # fmt: skip
    return sorted(offered, key=lambda a: a.stamp_ns)


def naive_snap_baseline(
    stamps_ns: npt.NDArray[np.int64], T_odom_base: SE3, fixes: Sequence[FixAttempt]
) -> BaselineRun:
    """Snap the correction to every offered single-tag fix and hold it between fixes.

    Parameters
    ----------
    stamps_ns : (N,) int64
        Odometry stamps, nanoseconds, strictly increasing.
    T_odom_base : SE3 batch of N
        Odometry at those stamps.
    fixes : sequence of FixAttempt
        All fix attempts of the run; :func:`offered_single_tag_fixes` selects the ones used.
        Fixes outside ``[stamps_ns[0], stamps_ns[-1]]`` are ignored.

    Returns
    -------
    BaselineRun

    Raises
    ------
    LocalizeError
        If the stamps and odometry lengths differ or the stamps do not increase strictly.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    n = len(stamps)
    if len(T_odom_base) != n or n == 0:
        raise LocalizeError(f"baseline: {n} stamps but {len(T_odom_base)} odometry poses")
    if np.any(np.diff(stamps) <= 0):
        raise LocalizeError("baseline: stamps_ns must increase strictly")
    # 1. the fixes used, within the odometry's time span
    snaps = [a for a in offered_single_tag_fixes(fixes) if stamps[0] <= a.stamp_ns <= stamps[-1]]
    # 2. each fix's correction T_map_odom = T_map_base_fix @ T_odom_base(t_fix)^-1
    corrections = [
        a.T_map_base @ _odom_at(stamps, T_odom_base, a.stamp_ns).inverse() for a in snaps
    ]
    # 3. in force from the first odometry row at or after the fix; the last one of a row wins
    rows = np.searchsorted(stamps, [a.stamp_ns for a in snaps], side="left").astype(np.intp)
    latest = np.full(n, -1, dtype=np.intp)
    np.maximum.at(latest, rows, np.arange(len(snaps)))  # the last snap of a row wins
    latest = np.maximum.accumulate(latest)
    initialized = latest >= 0
    matrices = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    if snaps:
        stacked = np.asarray(SE3.stack(corrections).as_matrix())
        matrices[initialized] = stacked[latest[initialized]]
    T_map_odom = SE3.from_matrix(matrices)
    return BaselineRun(
        T_map_odom=T_map_odom,
        T_map_base=T_map_odom @ T_odom_base,
        initialized=initialized,
        snaps=tuple(snaps),
        snap_rows=rows,
    )


def _odom_at(stamps: npt.NDArray[np.int64], T_odom_base: SE3, stamp_ns: int) -> SE3:
    """``T_odom_base`` interpolated at ``stamp_ns`` (inside the stamps' span)."""
    j = int(np.searchsorted(stamps, stamp_ns, side="left"))
    if stamps[j] == stamp_ns or j == 0:
        return T_odom_base[j]
    alpha = (stamp_ns - int(stamps[j - 1])) / (int(stamps[j]) - int(stamps[j - 1]))
    return T_odom_base[j - 1].interpolate_rt(T_odom_base[j], alpha)
