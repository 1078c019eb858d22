"""Gates and policies of the ``map -> odom`` filter, as plain objects it composes.

- :func:`chi2_threshold`: the Mahalanobis gate ``d2 = nu^T S^-1 nu <= chi2.ppf(q, dof)``.
- :class:`QualityLimits`: refuse a fix on its own quality (reprojection error, ambiguity,
  range) before it can touch the state or the published correction.
- :class:`ConsistencyBuffer`: hold fixes until ``k`` of them are *mutually* consistent (start-up,
  after a gap, and the kidnap test). Each fix implies a correction ``T_map_odom_i = T_map_base_i
  @ T_odom_base(t_i)^-1`` with covariance ``C_i = Ad(T_odom_base) R_i Ad(T_odom_base)^T`` (right
  tangent); two agree when ``e = X_i (-) X_j`` passes the chi-square gate with
  ``S = J_i C_i J_i^T + J_j C_j J_j^T + Q_ij`` (``Q_ij``: the random walk between their stamps).
- :class:`SourceMonitor`: per-source innovation statistics; flags a source (a moved tag) whose
  fixes are repeatedly gated while other sources are accepted.
- :class:`CorrectionCap`: clip the jump of the published correction per update.

:class:`~tagloc.localize.candidate.Candidate` (a fix as the estimator uses it) and the pairwise
test :func:`~tagloc.localize.candidate.pair_d2` live in :mod:`tagloc.localize.candidate` and are
re-exported here.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from tagloc._types import FloatArray
from tagloc.geometry import SE2, SE3, SO3
from tagloc.localize.candidate import Candidate, Pose, mahalanobis_sq, pair_d2
from tagloc.localize.events import EventKind
from tagloc.localize.fix import FixQuality

__all__ = [
    "Candidate", "ConsistencyBuffer", "CorrectionCap", "PairNoise", "Pose", "QualityLimits",
    "SourceMonitor", "SourceStats", "chi2_threshold", "mahalanobis_sq", "pair_d2",
]  # fmt: skip

@functools.lru_cache(maxsize=64)
def chi2_threshold(quantile: float, dof: int) -> float:
    """``chi2.ppf(quantile, dof)``: the gate on a squared Mahalanobis distance of ``dof``."""
    return float(chi2.ppf(quantile, dof))


@dataclass(frozen=True, slots=True)
class QualityLimits:
    """Limits on a fix's own quality; ``None`` disables one."""

    max_reproj_err_px: float
    max_ambiguity_ratio: float | None
    max_range_m: float | None

    def check(self, quality: FixQuality) -> tuple[EventKind, float, float, str] | None:
        """``None`` if the fix may be used, else ``(kind, value, limit, detail)``."""
        if not quality.reproj_err_px <= self.max_reproj_err_px:  # NaN is refused too
            return (
                EventKind.GATED_REPROJ, quality.reproj_err_px, self.max_reproj_err_px,
                f"reprojection error {quality.reproj_err_px:.3g} px",
            )  # fmt: skip
        ratio, limit = quality.ambiguity_ratio, self.max_ambiguity_ratio
        if limit is not None and ratio > limit:
            return EventKind.GATED_QUALITY, ratio, limit, f"ambiguity ratio {ratio:.3g}"
        rng, max_rng = quality.range_m, self.max_range_m
        if max_rng is not None and rng > max_rng:
            return EventKind.GATED_QUALITY, rng, max_rng, f"range {rng:.3g} m"
        return None


#: ``Q_ij``: random-walk covariance between two candidates (right tangent of the later one).
PairNoise = Callable[[Candidate, Candidate], FloatArray]


class ConsistencyBuffer:
    """Fixes waiting for a set of mutually consistent ones.

    Parameters
    ----------
    k : int
        Set size that resolves the buffer.
    window_ns : int
        Fixes older than the newest stamp minus this leave the buffer (:meth:`expire`).
    threshold : float
        Chi-square gate on the pairwise squared Mahalanobis distance.
    min_sources : int
        Distinct ``fix.source`` values the set must hold.
    pair_noise : callable
        ``Q_ij`` for two candidates (the process noise of the filter between their stamps).

    Notes
    -----
    The set is grown greedily from the newest fix through the compatible ones, newest first:
    with the small ``k`` used (3-5) and a window of a few seconds this finds the set whenever
    one exists in practice, at ``O(n)`` pair tests per fix (pairs are cached).
    """

    def __init__(
        self, k: int, window_ns: int, threshold: float, min_sources: int, pair_noise: PairNoise
    ) -> None:
        self._k, self._window, self._threshold = k, window_ns, threshold
        self._min_sources, self._pair_noise = min_sources, pair_noise
        self._items: list[Candidate] = []
        self._d2: dict[tuple[int, int], float] = {}

    def __len__(self) -> int:
        return len(self._items)

    def _pair_d2(self, a: Candidate, b: Candidate) -> float:
        key = (id(a), id(b)) if id(a) < id(b) else (id(b), id(a))
        d2 = self._d2.get(key)
        if d2 is None:
            d2 = self._d2[key] = pair_d2(a, b, self._pair_noise(a, b))
        return d2

    def consistent(self, a: Candidate, b: Candidate) -> bool:
        """True when ``a`` and ``b`` imply the same correction within the gate."""
        return self._pair_d2(a, b) <= self._threshold

    def expire(self, now_ns: int) -> list[Candidate]:
        """Remove and return the fixes older than ``now_ns`` minus the window."""
        old = [c for c in self._items if c.stamp_ns < now_ns - self._window]
        if old:
            self._forget(old)
        return old

    def remove_source(self, source: str) -> list[Candidate]:
        """Remove and return the fixes of ``source``."""
        gone = [c for c in self._items if c.fix.source == source]
        self._forget(gone)
        return gone

    def clear(self) -> list[Candidate]:
        """Remove and return every fix."""
        gone, self._items, self._d2 = self._items, [], {}
        return gone

    def _forget(self, gone: Sequence[Candidate]) -> None:
        ids = {id(c) for c in gone}
        self._items = [c for c in self._items if id(c) not in ids]
        self._d2 = {k: v for k, v in self._d2.items() if not (k[0] in ids or k[1] in ids)}

    def add(self, candidate: Candidate) -> list[Candidate] | None:
        """Buffer ``candidate``; return a consistent set containing it (removed from the
        buffer, oldest first) when one of ``k`` fixes from ``min_sources`` sources exists."""
        self._items.append(candidate)
        others = sorted(
            (c for c in self._items if c is not candidate and self.consistent(candidate, c)),
            key=lambda c: -c.stamp_ns,
        )
        chosen = [candidate]
        for other in others:
            if all(self.consistent(other, c) for c in chosen[1:]):
                chosen.append(other)
        if len(chosen) < self._k or len({c.fix.source for c in chosen}) < self._min_sources:
            return None
        self._forget(chosen)
        return sorted(chosen, key=lambda c: c.stamp_ns)


@dataclass(slots=True)
class SourceStats:
    """Innovation statistics of one source (``nis``: ``d2`` of its fixes against the state)."""

    accepted: int = 0
    gated: int = 0
    rejected_suspect: int = 0
    nis_sum: float = 0.0
    nis_count: int = 0
    streak_gated: int = 0
    accepted_total_at_streak: int = 0
    suspect: bool = False
    clear_streak: int = 0

    @property
    def mean_nis(self) -> float:
        """Mean ``d2`` of its tested fixes (about the dof for an honest source); NaN if none."""
        return self.nis_sum / self.nis_count if self.nis_count else math.nan


@dataclass(slots=True)
class SourceMonitor:
    """Per-source statistics and the suspect (moved tag) flag.

    A source is flagged when ``min_gated`` of its fixes in a row were gated and at least one fix
    of another source was accepted meanwhile (so the state is fine and the source is not: a
    moved or mis-surveyed tag). While suspect its fixes are not applied; it is cleared after
    ``clear_after`` consecutive fixes that pass the gate.
    """

    min_gated: int
    clear_after: int
    stats: dict[str, SourceStats] = field(default_factory=dict)
    accepted_total: int = 0

    def _get(self, source: str) -> SourceStats:
        return self.stats.setdefault(source, SourceStats())

    def is_suspect(self, source: str) -> bool:
        stats = self.stats.get(source)
        return stats is not None and stats.suspect

    @property
    def suspects(self) -> tuple[str, ...]:
        return tuple(sorted(s for s, st in self.stats.items() if st.suspect))

    def on_accepted(self, source: str, d2: float | None) -> None:
        stats = self._get(source)
        stats.accepted += 1
        stats.streak_gated = 0
        self.accepted_total += 1
        if d2 is not None:
            stats.nis_sum += d2
            stats.nis_count += 1

    def on_gated(self, source: str, d2: float, consistent: bool = True) -> bool:
        """Record a gated fix; True if this flags the source suspect.

        ``consistent``: whether the fix implies the same correction as the source's previous
        gated fix. A moved tag is wrong the same way every time; glints decoded under the
        tag's id are wrong at random, so an inconsistent fix restarts the run (glints never
        make a real tag suspect).
        """
        stats = self._get(source)
        stats.gated += 1
        stats.nis_sum += d2
        stats.nis_count += 1
        if not consistent:
            stats.streak_gated = 0
        if stats.streak_gated == 0:
            stats.accepted_total_at_streak = self.accepted_total
        stats.streak_gated += 1
        others_accepted = self.accepted_total > stats.accepted_total_at_streak
        if stats.streak_gated >= self.min_gated and others_accepted:
            stats.suspect, stats.clear_streak = True, 0
            return True
        return False

    def on_suspect_fix(self, source: str, passes_gate: bool) -> bool:
        """Record a (not applied) fix of a suspect source; True if this clears the source."""
        stats = self._get(source)
        stats.rejected_suspect += 1
        stats.clear_streak = stats.clear_streak + 1 if passes_gate else 0
        if stats.clear_streak >= self.clear_after:
            stats.suspect, stats.streak_gated = False, 0
            return True
        return False

    def reset_streaks(self) -> None:
        """Forget the gated runs (after a re-initialization the old state was wrong)."""
        for stats in self.stats.values():
            stats.streak_gated = 0


@dataclass(frozen=True, slots=True)
class CorrectionCap:
    """Largest jump of the published ``T_map_base`` per update (the robot's pose as planners see
    it): ``max_translation_m`` and ``max_rotation_rad``."""

    max_translation_m: float
    max_rotation_rad: float
    snap_on_initialize: bool = False

    def _scales(self, D: Pose) -> tuple[float, float]:
        """Factors (<= 1) that bring the translation and the rotation angle of ``D`` to the
        caps."""
        t = D.translation
        if isinstance(D, SE2):
            angle = abs(float(D.rotation_angle))
        else:  # angle from the trace: no scipy call on the common, unclipped path
            cos = 0.5 * (float(np.trace(D.rotation.matrix)) - 1.0)
            angle = math.acos(min(1.0, max(-1.0, cos)))
        norm_t = math.sqrt(float(t @ t))
        a_t = min(1.0, self.max_translation_m / norm_t) if norm_t > 0 else 1.0
        a_r = min(1.0, self.max_rotation_rad / angle) if angle > 0 else 1.0
        return a_t, a_r

    def exceeds(self, D: Pose) -> bool:
        """Whether the jump ``D`` (base frame) is beyond either cap."""
        return self._scales(D) != (1.0, 1.0)

    def clip(self, D: Pose) -> tuple[Pose, bool]:
        """Scale the translation and the rotation angle of the jump ``D`` (base frame) down to
        the caps, independently; return it and whether it was clipped."""
        a_t, a_r = self._scales(D)
        if a_t == 1.0 and a_r == 1.0:
            return D, False
        t = D.translation
        if isinstance(D, SE2):
            return SE2(a_t * t[0], a_t * t[1], a_r * float(D.rotation_angle)), True
        rotvec = D.rotation.as_rotvec()
        return SE3(rotation=SO3.from_rotvec(a_r * rotvec), translation=a_t * t), True
