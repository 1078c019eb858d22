"""The filter's event log: every decision it takes is one :class:`FilterEvent`.

Per-fix decisions (each fix gets exactly one on arrival; a fix buffered as
``PENDING_CONSISTENCY`` gets exactly one more when it is resolved):

- ``ACCEPTED``: applied as a filter update.
- ``GATED_CHI2``: its Mahalanobis distance to the state exceeds the chi-square quantile.
- ``GATED_REPROJ``: its own reprojection error is above the limit (never used at all).
- ``GATED_QUALITY``: another quality limit (IPPE ambiguity ratio, range).
- ``REJECTED_SUSPECT``: its source is flagged suspect (a moved tag); not applied.
- ``NO_ODOMETRY``: ``T_odom_base`` at its stamp is not in the buffer.
- ``PENDING_CONSISTENCY``: buffered until ``k`` mutually consistent fixes arrive (start-up,
  after a gap).
- ``DISCARDED_CANDIDATE``: a pending fix that left the window without joining a consistent set.
- ``UNUSED_NO_STATE``: a partial fix (one that measures only some directions, e.g. lidar)
  before the state exists: it cannot start the filter.

Filter-level decisions (one event each): ``INITIALIZED`` (state created from ``k`` consistent
fixes, or an explicit prior), ``REINITIALIZED_KIDNAP``, ``GAP`` (no accepted fix for too long:
re-acquisition starts), ``CAPPED`` (the published correction was clipped; the remainder is
carried), ``SUSPECT_SOURCE`` and ``SOURCE_CLEARED``; and the node's ``FLOOR_CHANGED`` (the
floor became known or changed: the one declared discontinuity of the published correction,
exempt from the cap and the speed limit, :mod:`tagloc.localize.floors`).
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from enum import StrEnum

logger = logging.getLogger(__name__)


class EventKind(StrEnum):
    """What the filter decided (see the module docstring)."""

    ACCEPTED = "accepted"
    GATED_CHI2 = "gated_chi2"
    GATED_REPROJ = "gated_reproj"
    GATED_QUALITY = "gated_quality"
    REJECTED_SUSPECT = "rejected_suspect"
    NO_ODOMETRY = "no_odometry"
    PENDING_CONSISTENCY = "pending_consistency"
    DISCARDED_CANDIDATE = "discarded_candidate"
    UNUSED_NO_STATE = "unused_no_state"
    INITIALIZED = "initialized"
    REINITIALIZED_KIDNAP = "reinitialized_kidnap"
    GAP = "gap"
    CAPPED = "capped"
    SUSPECT_SOURCE = "suspect_source"
    SOURCE_CLEARED = "source_cleared"
    FLOOR_CHANGED = "floor_changed"


#: Decisions that apply a fix (accepted, or used to (re)initialize the state).
APPLIED = frozenset({"accepted", "initialized", "reinitialized_kidnap"})

#: Kinds that are decisions on one fix (the rest are the filter's own): the streaming node
#: hands these on once, final, as the fix's :class:`~tagloc.localize.run.FixAttempt`.
FIX_DECISIONS = frozenset(
    {
        EventKind.ACCEPTED, EventKind.GATED_CHI2, EventKind.GATED_REPROJ, EventKind.GATED_QUALITY,
        EventKind.REJECTED_SUSPECT, EventKind.NO_ODOMETRY, EventKind.PENDING_CONSISTENCY,
        EventKind.DISCARDED_CANDIDATE, EventKind.UNUSED_NO_STATE,
    }
)  # fmt: skip

#: Kinds logged at INFO (state changes an operator wants to see); WARNING for suspects.
_INFO = {
    EventKind.INITIALIZED,
    EventKind.REINITIALIZED_KIDNAP,
    EventKind.GAP,
    EventKind.SOURCE_CLEARED,
    EventKind.FLOOR_CHANGED,
}


@dataclass(frozen=True, slots=True)
class FilterEvent:
    """One decision of the filter.

    Attributes
    ----------
    stamp_ns : int
        Stamp of the fix decided on (or of the filter step for filter-level events).
    kind : EventKind
    source : str
        The fix's source (``"tag:17"``); for (re)initialization the sources used, joined by
        ``"+"``; empty when no source applies.
    d2 : float or None
        Squared Mahalanobis distance tested, when one was.
    threshold : float or None
        The limit ``d2`` (or the quality value) was compared with.
    detail : str
        Human-readable context (the quality value, the remainder of a capped correction, ...).
    """

    stamp_ns: int
    kind: EventKind
    source: str = ""
    d2: float | None = None
    threshold: float | None = None
    detail: str = ""


class EventLog:
    """Events in order, with exact counts by kind and by source.

    Parameters
    ----------
    max_events : int
        Events kept for inspection (the oldest are dropped beyond it); the counts stay exact.
    """

    def __init__(self, max_events: int = 100_000) -> None:
        self._events: deque[FilterEvent] = deque(maxlen=max_events)
        self._by_kind: Counter[EventKind] = Counter()
        self._by_source: dict[str, Counter[EventKind]] = {}
        #: Called with every event as it is appended (the streaming node's sinks).
        self.listeners: list[Callable[[FilterEvent], None]] = []

    def append(self, event: FilterEvent) -> FilterEvent:
        """Record ``event`` (and log it) and return it."""
        self._events.append(event)
        self._by_kind[event.kind] += 1
        self._by_source.setdefault(event.source, Counter())[event.kind] += 1
        for listener in self.listeners:
            listener(event)
        level = (
            logging.WARNING
            if event.kind is EventKind.SUSPECT_SOURCE
            else logging.INFO
            if event.kind in _INFO
            else logging.DEBUG
        )
        if logger.isEnabledFor(level):
            d2 = "" if event.d2 is None else f" d2={event.d2:.3g}/{event.threshold:.3g}"
            logger.log(
                level, "%d %s %s%s %s", event.stamp_ns, event.kind, event.source, d2, event.detail
            )
        return event

    def counts_by_kind(self) -> Counter[EventKind]:
        """Number of events of each kind since the start (a copy)."""
        return Counter(self._by_kind)

    def counts_by_source(self) -> dict[str, Counter[EventKind]]:
        """For each source, the number of events of each kind (copies)."""
        return {source: Counter(c) for source, c in self._by_source.items()}

    def count(self, kind: EventKind, source: str | None = None) -> int:
        """Events of ``kind`` (from ``source`` only, if given)."""
        if source is None:
            return self._by_kind[kind]
        return self._by_source.get(source, Counter())[kind]

    def of_kind(self, kind: EventKind) -> list[FilterEvent]:
        """The kept events of ``kind``, in order."""
        return [e for e in self._events if e.kind is kind]

    @property
    def events(self) -> tuple[FilterEvent, ...]:
        """The kept events, oldest first."""
        return tuple(self._events)

    @property
    def last(self) -> FilterEvent | None:
        """The newest event, if any."""
        return self._events[-1] if self._events else None

    def __len__(self) -> int:
        return len(self._events)

    def __iter__(self) -> Iterator[FilterEvent]:
        return iter(tuple(self._events))
