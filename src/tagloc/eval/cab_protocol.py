"""The reliability protocol's cab opportunities: the node's estimate relative to an elevator
cab against the simulator's truth (:mod:`tagloc.eval.protocol`, whose module docstring states
the rule).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.eval.trajectories import PoseErrors, pose_errors
from tagloc.geometry import SE3
from tagloc.localize.run import CabEstimate, CameraFrameRecord, FixAttempt

__all__ = ["CabErrors", "cab_successes"]


@dataclass(frozen=True, slots=True)
class CabErrors:
    """The node's estimates relative to elevator cabs, judged against the simulator's truth.

    Attributes
    ----------
    cab_frames : frozenset of str
        The tag map's cab frames (their tags' opportunities are the cab's).
    stamps_ns : (M,) int64
        Odometry stamps of the published :class:`~tagloc.localize.run.CabEstimate` s.
    cab_frame : tuple of str
        The cab of each.
    errors : PoseErrors
        Of each ``T_<cab>_base`` against the truth of the base in that cab at its stamp.
    accepted_at : mapping of int to int
        Camera stamp -> fixes of a cab's tags accepted from that frame.
    """

    cab_frames: frozenset[str]
    stamps_ns: npt.NDArray[np.int64]
    cab_frame: tuple[str, ...]
    errors: PoseErrors
    accepted_at: Mapping[int, int]

    @classmethod
    def of(
        cls, cab_frames: Iterable[str], estimates: Sequence[CabEstimate], T_cab_base_truth: SE3,
        fixes: Iterable[FixAttempt],
    ) -> CabErrors:  # fmt: skip
        """From a run's cab estimates, their truth (a batch of the same length) and its fix
        attempts."""
        accepted = Counter(a.stamp_ns for a in fixes if a.accepted and not a.in_map)
        if estimates:
            errors = pose_errors(T_cab_base_truth, SE3.stack([c.T_cab_base for c in estimates]))
        else:
            errors = PoseErrors(np.zeros(0), np.zeros(0))
        return cls(
            frozenset(cab_frames), np.array([c.stamp_ns for c in estimates], dtype=np.int64),
            tuple(c.cab_frame for c in estimates), errors, dict(accepted),
        )  # fmt: skip


def cab_successes(
    frames: Sequence[CameraFrameRecord], in_cab: npt.NDArray[np.bool_],
    row_stamps_ns: npt.NDArray[np.int64], cab: CabErrors | None, position_tol_m: float,
    rotation_tol_deg: float,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:  # fmt: skip
    """Per frame of ``in_cab``: a cab fix accepted from it; that, and the estimate relative
    to the cab of its nearest cab tag at the frame's row (``row_stamps_ns``: the odometry stamp
    the map's protocol judges) within tolerance. False off ``in_cab`` and without ``cab``."""
    accepted = np.zeros(len(frames), dtype=bool)
    good = np.zeros(len(frames), dtype=bool)
    if cab is None:
        return accepted, good
    e = cab.errors
    ok = (e.translation_m <= position_tol_m) & (e.rotation_deg <= rotation_tol_deg)
    at: dict[tuple[int, str], int] = {
        (int(s), f): i for i, (s, f) in enumerate(zip(cab.stamps_ns, cab.cab_frame, strict=True))
    }
    for i in np.flatnonzero(in_cab).tolist():
        f = frames[i]
        accepted[i] = cab.accepted_at.get(f.stamp_ns, 0) > 0
        seen = [(m, name) for name, m in f.nearest_by_frame if name in cab.cab_frames]
        k = at.get((int(row_stamps_ns[i]), min(seen)[1])) if seen else None
        good[i] = accepted[i] and k is not None and bool(ok[k])
    return accepted, good
