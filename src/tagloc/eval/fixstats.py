"""Statistics of the fix attempts and filter events of a run.

- acceptance of fixes against range and viewing angle (binned);
- false fixes (built from injected false detections, simulator truth) offered and accepted;
- true fixes in range accepted (the glint scenario's ">= 98%" check);
- moved / suspect sources (a tag the filter flagged as moved) and their rejected fixes.

A fix counts as *accepted* when :attr:`FixAttempt.accepted` (accepted, initialized from, or
re-initialized from after a kidnap); *offered* when it passed the per-observation gates (its
decision does not start with ``"rejected:"``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tagloc.localize.events import FilterEvent
from tagloc.localize.run import FixAttempt


@dataclass(frozen=True, slots=True)
class AcceptanceBin:
    """Fix attempts whose value falls in ``[low, high)``.

    Attributes
    ----------
    low, high : float
        Bin edges (metres for range, degrees for angle); the last bin is open above.
    n_attempts : int
        Every attempt (also those rejected before the filter).
    n_offered : int
        Attempts that passed the per-observation gates.
    n_accepted : int
    """

    low: float
    high: float
    n_attempts: int
    n_offered: int
    n_accepted: int

    @property
    def acceptance(self) -> float:
        """``n_accepted / n_attempts`` (NaN for an empty bin)."""
        return self.n_accepted / self.n_attempts if self.n_attempts else math.nan


def acceptance_by(
    fixes: Sequence[FixAttempt], values: Sequence[float], edges: Sequence[float]
) -> tuple[list[AcceptanceBin], int]:
    """Bin attempts by ``values`` (one per fix) on ``edges``; the last bin is ``[edges[-1], inf)``.

    Returns the bins and the number of attempts whose value is unknown (NaN) or below
    ``edges[0]``; ``+inf`` falls in the last bin.
    """
    value = np.asarray(values, dtype=np.float64)
    offered = np.array([not a.decision.startswith("rejected:") for a in fixes], dtype=bool)
    accepted = np.array([a.accepted for a in fixes], dtype=bool)
    lows = list(edges)
    highs = [*lows[1:], math.inf]
    bins = []
    for low, high in zip(lows, highs, strict=True):
        inside = (value >= low) & ((value < high) | (high == math.inf))  # +inf: last bin
        bins.append(
            AcceptanceBin(
                low=float(low),
                high=float(high),
                n_attempts=int(np.count_nonzero(inside)),
                n_offered=int(np.count_nonzero(inside & offered)),
                n_accepted=int(np.count_nonzero(inside & accepted)),
            )
        )
    unknown = int(np.count_nonzero(np.isnan(value) | (value < lows[0]))) if len(fixes) else 0
    return bins, unknown


def acceptance_vs_range(
    fixes: Sequence[FixAttempt], edges_m: Sequence[float]
) -> tuple[list[AcceptanceBin], int]:
    """Acceptance against :attr:`FixAttempt.range_m` (camera to nearest tag, m)."""
    return acceptance_by(fixes, [a.range_m for a in fixes], edges_m)


def acceptance_vs_angle(
    fixes: Sequence[FixAttempt], edges_deg: Sequence[float]
) -> tuple[list[AcceptanceBin], int]:
    """Acceptance against :attr:`FixAttempt.view_angle_rad`, binned in degrees (0 = head-on)."""
    return acceptance_by(fixes, [math.degrees(a.view_angle_rad) for a in fixes], edges_deg)


@dataclass(frozen=True, slots=True)
class FixCounts:
    """Counts over all fix attempts of a run.

    Attributes
    ----------
    n_attempts, n_offered, n_accepted : int
    n_false_attempts : int
        Attempts built from a detection known to be false.
    n_false_offered : int
        Of those, passed the per-observation gates (what the naive baseline snaps to).
    n_false_accepted : int
        Of those, accepted by the filter: the number that must be 0.
    n_true_in_range, n_true_in_range_accepted : int
        Attempts known to be true with ``range_m <= range_m`` (the opportunity range), and of
        those accepted.
    truth_known : bool
        Whether any attempt carries simulator truth (``false_detection`` not None).
    """

    n_attempts: int
    n_offered: int
    n_accepted: int
    n_false_attempts: int
    n_false_offered: int
    n_false_accepted: int
    n_true_in_range: int
    n_true_in_range_accepted: int
    truth_known: bool

    @property
    def true_in_range_acceptance(self) -> float:
        """``n_true_in_range_accepted / n_true_in_range`` (NaN when none)."""
        return (
            self.n_true_in_range_accepted / self.n_true_in_range
            if self.n_true_in_range
            else math.nan
        )


def fix_counts(fixes: Sequence[FixAttempt], range_m: float) -> FixCounts:
    """Count attempts, false fixes and true fixes in range (see :class:`FixCounts`)."""
    offered = [a for a in fixes if not a.decision.startswith("rejected:")]
    false = [a for a in fixes if a.false_detection is True]
    true_in_range = [a for a in fixes if a.false_detection is False and a.range_m <= range_m]
    return FixCounts(
        n_attempts=len(fixes),
        n_offered=len(offered),
        n_accepted=sum(a.accepted for a in fixes),
        n_false_attempts=len(false),
        n_false_offered=sum(not a.decision.startswith("rejected:") for a in false),
        n_false_accepted=sum(a.accepted for a in false),
        n_true_in_range=len(true_in_range),
        n_true_in_range_accepted=sum(a.accepted for a in true_in_range),
        truth_known=any(a.false_detection is not None for a in fixes),
    )


@dataclass(frozen=True, slots=True)
class SuspectSource:
    """A fix source (a tag) the filter flagged as suspect, e.g. moved after the map was made.

    Attributes
    ----------
    source : str
        ``"tag:<id>"``.
    first_flagged_ns : int
        Stamp of its first ``suspect_source`` event (-1 if only listed in the run's metadata).
    n_rejected : int
        Its fixes rejected as suspect (``rejected_suspect``) or gated by chi-square.
    n_accepted : int
        Its fixes accepted nonetheless (before being flagged, or after being cleared).
    cleared : bool
        Whether a ``source_cleared`` event followed.
    """

    source: str
    first_flagged_ns: int
    n_rejected: int
    n_accepted: int
    cleared: bool


def suspect_sources(
    events: Sequence[FilterEvent],
    fixes: Sequence[FixAttempt],
    listed: Sequence[str] = (),
) -> list[SuspectSource]:
    """The sources flagged by ``suspect_source`` events (plus ``listed`` ones), in order."""
    flagged: dict[str, int] = {}
    cleared: set[str] = set()
    for event in events:
        if str(event.kind) == "suspect_source":
            flagged.setdefault(event.source, event.stamp_ns)
        elif str(event.kind) == "source_cleared":
            cleared.add(event.source)
    for source in listed:
        flagged.setdefault(str(source), -1)
    out = []
    for source, first in flagged.items():
        own = [a for a in fixes if a.source == source]
        out.append(
            SuspectSource(
                source=source,
                first_flagged_ns=int(first),
                n_rejected=sum(a.decision in ("rejected_suspect", "gated_chi2") for a in own),
                n_accepted=sum(a.accepted for a in own),
                cleared=source in cleared,
            )
        )
    return out
