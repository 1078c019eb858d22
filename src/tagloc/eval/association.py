"""Pair the poses of two trajectories by stamp, as ``evo_ape`` / ``evo_rpe`` do.

Nearest-stamp association (``evo.core.sync.associate_trajectories`` with its default
``nearest_time`` method and no time offset):

1. the trajectory with fewer poses is the *short* one (the estimate when both are as long), so
   none of its poses is lost to the association;
2. each stamp ``s`` of the short trajectory is paired with the nearest stamp of the long one if
   it is within ``max_diff``; when ``s`` lies between two stamps ``l_k < s <= l_(k+1)`` at equal
   distance the earlier one wins; a stamp of the long trajectory may serve several short ones;
3. the pairs keep the short trajectory's order.

Stamps are integer nanoseconds here (evo compares float seconds, which at epoch stamps resolve
about 0.2 us): pairs differ only for a stamp difference within a few hundred nanoseconds of
``max_diff``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

IntArray = npt.NDArray[np.int64]


def _nearest(
    stamps_short_ns: IntArray, stamps_long_ns: IntArray, max_diff_ns: int
) -> tuple[IntArray, IntArray]:
    """Indices ``(i_short, i_long)`` of the associated pairs (step 2 of the module docstring)."""
    short, long_ = stamps_short_ns, stamps_long_ns
    if np.any(np.diff(long_) < 0):  # unsorted: the nearest stamp by a full search (in chunks)
        best = np.concatenate([
            np.argmin(np.abs(long_[None, :] - chunk[:, None]), axis=1)
            for chunk in np.array_split(short, max(1, len(short) // 256))
        ])  # fmt: skip
        ok = np.abs(long_[best] - short) <= max_diff_ns
        return np.flatnonzero(ok).astype(np.int64), best[ok].astype(np.int64)
    upper = np.minimum(np.searchsorted(long_, short, side="right"), len(long_) - 1)
    diff_ub = long_[upper] - short
    diff_lb = np.where(upper > 0, short - long_[np.maximum(upper - 1, 0)], np.iinfo(np.int64).max)
    take_ub = (diff_ub <= max_diff_ns) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_diff_ns) & (diff_lb <= diff_ub)
    inside = (short >= long_[0] - max_diff_ns) & (short <= long_[-1] + max_diff_ns)
    keep = inside & (take_ub | take_lb)
    best = np.where(take_ub, upper, upper - 1)
    return np.flatnonzero(keep).astype(np.int64), best[keep].astype(np.int64)


def associate_stamps(
    stamps_ref_ns: npt.ArrayLike, stamps_est_ns: npt.ArrayLike, max_diff_ns: int
) -> tuple[IntArray, IntArray]:
    """Indices into the reference and the estimate of the stamp-associated pose pairs.

    Parameters
    ----------
    stamps_ref_ns, stamps_est_ns : (N,), (M,) int64
        Stamps of the two trajectories, nanoseconds.
    max_diff_ns : int
        Largest stamp difference of a pair, nanoseconds (evo's default is 10 ms).

    Returns
    -------
    i_ref, i_est : (K,) int64
        ``stamps_ref_ns[i_ref[k]]`` is paired with ``stamps_est_ns[i_est[k]]``; ``K`` may be 0.
    """
    ref = np.asarray(stamps_ref_ns, dtype=np.int64).reshape(-1)
    est = np.asarray(stamps_est_ns, dtype=np.int64).reshape(-1)
    if len(ref) == 0 or len(est) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    if len(est) > len(ref):  # the reference is the short one
        i_ref, i_est = _nearest(ref, est, int(max_diff_ns))
        return i_ref, i_est
    i_est, i_ref = _nearest(est, ref, int(max_diff_ns))
    return i_ref, i_est
