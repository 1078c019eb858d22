"""When the fix policy stops trusting a source or the state: suspect sources, kidnaps, gaps.

A fix the chi-square gate refuses says one of two things. Either its source is wrong (a tag
moved or mis-surveyed since the survey: its fixes are gated again and again, the same way, while
other sources are accepted) and the source is flagged suspect
(:class:`~tagloc.localize.gating.SourceMonitor`); or the state is wrong (the robot was carried
away: fixes of several sources, or many of one far from the estimate, agree with each other and
not with the state) and the state is re-initialized from them (the kidnap test, a
:class:`~tagloc.localize.gating.ConsistencyBuffer`). :class:`RecoveryBooks` keeps both books.

Without accepted fixes for long (:class:`GapRule`: a time or a distance travelled) the state is
unconfirmed: the policy holds fixes again until ``k`` consistent ones re-acquire it.
:class:`~tagloc.localize.policy.FixPolicy` acts on these verdicts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tagloc.localize.candidate import Candidate, Pose, pair_d2
from tagloc.localize.config import KidnapConfig, SuspectConfig
from tagloc.localize.gating import ConsistencyBuffer, CorrectionCap, PairNoise, SourceMonitor
from tagloc.units import S_NS

__all__ = ["GapRule", "KidnapRule", "RecoveryBooks", "SuspectRule"]



@dataclass(frozen=True, slots=True)
class KidnapRule:
    """Re-initialize from ``n_fixes`` gated, mutually consistent fixes of at least
    ``min_sources`` sources within ``window_ns``, with no accepted fix among them (``n_fixes``
    0: never); or from ``n_fixes_one_source`` such fixes of one source (0: never), each putting
    the base at least ``one_source_min_jump_m`` from the estimate."""

    n_fixes: int
    min_sources: int
    window_ns: int
    n_fixes_one_source: int = 0
    one_source_min_jump_m: float = 1.0

    @classmethod
    def from_config(cls, kidnap: KidnapConfig) -> KidnapRule:
        """From ``localizer.yaml``'s ``kidnap`` (disabled: both counts 0)."""
        on = kidnap.enabled
        return cls(
            kidnap.n_fixes if on else 0, kidnap.min_sources, round(kidnap.window_s * S_NS),
            kidnap.n_fixes_one_source if on else 0, kidnap.one_source_min_jump_m,
        )  # fmt: skip


@dataclass(frozen=True, slots=True)
class SuspectRule:
    """Flag a source after ``min_gated`` gated fixes in a row that are wrong the same way
    (consecutive ones at most ``window_ns`` apart, implying corrections within ``spread`` of
    each other and passing the pairwise gate) while other sources are accepted; clear it after
    ``clear_after`` fixes in a row that pass the gate."""

    min_gated: int
    clear_after: int
    spread: CorrectionCap
    window_ns: int

    @classmethod
    def from_config(cls, suspect: SuspectConfig, kidnap: KidnapConfig) -> SuspectRule:
        """From ``suspect`` (the spread in degrees) and the window of ``kidnap``."""
        spread = CorrectionCap(  # a bound on the spread, not a published cap
            suspect.max_spread_m, math.radians(suspect.max_spread_deg)
        )
        return cls(suspect.min_gated, suspect.clear_after, spread, round(kidnap.window_s * S_NS))


class RecoveryBooks:
    """The suspect-source and kidnap books (module docstring).

    Parameters
    ----------
    kidnap : KidnapRule
    suspect : SuspectRule
    threshold : float
        The chi-square gate of the pairwise tests.
    pair_noise : callable
        ``Q_ij`` of two fixes (the estimator's random walk between their stamps).

    Attributes
    ----------
    sources : SourceMonitor
        Per-source counts, innovation statistics and the suspect flags.
    """

    def __init__(
        self, kidnap: KidnapRule, suspect: SuspectRule, threshold: float, pair_noise: PairNoise
    ) -> None:
        self._rule, self._suspect, self._threshold = kidnap, suspect, threshold
        self._pair_noise = pair_noise
        self.sources = SourceMonitor(suspect.min_gated, suspect.clear_after)
        self._kidnap = ConsistencyBuffer(
            max(kidnap.n_fixes, 2), kidnap.window_ns, threshold, kidnap.min_sources, pair_noise
        )
        self._kidnap_one = (
            ConsistencyBuffer(kidnap.n_fixes_one_source, kidnap.window_ns, threshold, 1, pair_noise)
            if kidnap.n_fixes_one_source > 0
            else None
        )
        self._last_gated: dict[str, Candidate] = {}  # per source, for the suspect test

    def on_gated(self, cand: Candidate, d2: float, X: Pose) -> tuple[bool, list[Candidate] | None]:
        """Book a gated fix (``d2``: its distance to the state ``X``, the estimator's pose).

        Returns
        -------
        flagged : bool
            The fix made its source suspect (its fixes leave the kidnap books).
        found : list of Candidate or None
            A kidnap: the consistent gated fixes (oldest first) to re-initialize from.
        """
        source = cand.fix.source
        last = self._last_gated.get(source)
        self._last_gated[source] = cand
        if self.sources.on_gated(source, d2, self._same_way(last, cand)):
            self._kidnap.remove_source(source)
            if self._kidnap_one is not None:
                self._kidnap_one.remove_source(source)
            return True, None
        if self._rule.n_fixes <= 0:
            return False, None
        self._kidnap.expire(cand.stamp_ns)
        found = self._kidnap.add(cand)
        if found is None and self._kidnap_one is not None and self._far(cand, X):
            self._kidnap_one.expire(cand.stamp_ns)
            found = self._kidnap_one.add(cand)
        return False, found

    def on_accepted(self, source: str, d2: float) -> None:
        """Book an applied fix: its statistics, and the kidnap books start again."""
        self.sources.on_accepted(source, d2)
        self._clear_kidnap()

    def on_suspect_fix(self, source: str, passes_gate: bool) -> bool:
        """Book a (not applied) fix of a suspect source; True if this clears the source."""
        return self.sources.on_suspect_fix(source, passes_gate)

    def on_reinitialized(self, found: list[Candidate]) -> None:
        """The state was re-initialized from ``found``: they count as accepted, the gated runs
        are forgotten (the old state was wrong) and the kidnap books start again."""
        for cand in found:
            self.sources.on_accepted(cand.fix.source, None)
        self.sources.reset_streaks()
        self._clear_kidnap()

    def _clear_kidnap(self) -> None:
        self._kidnap.clear()
        if self._kidnap_one is not None:
            self._kidnap_one.clear()

    def _same_way(self, last: Candidate | None, cand: Candidate) -> bool:
        """Whether a gated fix is wrong the same way as its source's previous gated fix: recent
        (a moved tag repeats itself within seconds; one from minutes ago says nothing), the two
        corrections within the spread seen at the robot's pose, and passing the pair gate."""
        return (
            last is not None
            and cand.stamp_ns - last.stamp_ns <= self._suspect.window_ns
            and not self._suspect.spread.exceeds(
                (last.T_map_odom @ cand.A).inverse() @ cand.z  # type: ignore[operator]
            )
            and pair_d2(last, cand, self._pair_noise(last, cand)) <= self._threshold
        )

    def _far(self, cand: Candidate, X: Pose) -> bool:
        """Whether a fix puts the base at least ``one_source_min_jump_m`` from the state ``X``:
        only such a fix may re-localize from one tag alone (a kidnap moves the robot metres; a
        tag moved or mis-surveyed by less is flagged suspect instead)."""
        T = (X @ cand.A).inverse() @ cand.z  # type: ignore[operator]
        return float(np.linalg.norm(T.translation)) >= self._rule.one_source_min_jump_m


class GapRule:
    """A gap: no accepted fix for longer than ``gap_ns`` or over more than ``gap_m`` travelled
    (counted from the newest accepted fix or (re)initialization).

    Attributes
    ----------
    active : bool
        In a gap (until :meth:`restart`, or the policy ends it).
    """

    def __init__(self, gap_ns: int, gap_m: float) -> None:
        self._gap_ns, self._gap_m = gap_ns, gap_m
        self.active = False
        self._ref_stamp, self._ref_odometer = 0, 0.0

    def starts(self, stamp_ns: int, odometer_m: float) -> str | None:
        """Whether a fix at ``stamp_ns`` (odometer ``odometer_m``) begins a gap: its
        description (and the gap is :attr:`active`), or None."""
        travelled = odometer_m - self._ref_odometer
        if stamp_ns - self._ref_stamp <= self._gap_ns and travelled <= self._gap_m:
            return None
        self.active = True
        return (
            f"no accepted fix for {(stamp_ns - self._ref_stamp) / S_NS:.1f} s, "
            f"{travelled:.1f} m: waiting for consistent fixes"
        )

    def accepted(self, stamp_ns: int, odometer_m: float) -> None:
        """A fix at ``stamp_ns`` was applied (a late one does not move the reference back)."""
        self._ref_stamp = max(self._ref_stamp, stamp_ns)
        self._ref_odometer = odometer_m

    def restart(self, stamp_ns: int, odometer_m: float) -> None:
        """The state was (re)initialized or re-acquired at ``stamp_ns``: no gap."""
        self.active = False
        self._ref_stamp, self._ref_odometer = stamp_ns, odometer_m
