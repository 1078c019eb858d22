"""Fix attempts and frame records held until final, then handed on in order.

A batch decision of the filter (start-up, kidnap, re-acquisition after a gap) may revise the
decision of fixes it buffered earlier, within the consistency (or kidnap) window. So the node
holds each :class:`~tagloc.localize.run.FixAttempt` and :class:`~tagloc.localize.run.
CameraFrameRecord` until its stamp is older than that window, relabels held fixes when a batch
uses them (or when a buffered one is discarded), and then hands them on, in the order they were
made: each fix's decision leaves once. Memory: the records of the
last window only.
"""

from __future__ import annotations

import dataclasses
from collections import Counter, deque
from collections.abc import Callable, Iterable

from tagloc.localize.events import EventKind
from tagloc.localize.fix import PartialFix, TagFix
from tagloc.localize.run import CameraFrameRecord, FixAttempt

__all__ = ["HeldRecords"]

Record = FixAttempt | CameraFrameRecord


class HeldRecords:
    """The held records (module docstring); ``emit`` receives each final record."""

    def __init__(self, emit: Callable[[Record], None]) -> None:
        self._emit = emit
        self._held: deque[Record] = deque()
        self._by_fix: dict[int, tuple[int, int]] = {}  # id(fix) -> serial of its attempt, owner
        self._serial0 = 0  # serial of _held[0]
        self._accepted_at: Counter[int] = Counter()  # accepted fixes per frame stamp, released

    def hold(
        self, record: Record, fix: TagFix | PartialFix | None = None, owner: int = 0
    ) -> None:
        """Hold ``record`` (the attempt of ``fix``, when it is one the filter decided on, from
        fix source number ``owner``)."""
        if fix is not None:
            self._by_fix[id(fix)] = (self._serial0 + len(self._held), owner)
        self._held.append(record)

    def relabel(
        self, batch: Iterable[tuple[TagFix, EventKind]]
    ) -> list[tuple[TagFix, EventKind, int]]:
        """Give the held attempts of ``batch``'s fixes their final decision; return the fixes
        whose decision changed, each with its owner (a batch seen again changes nothing)."""
        done = []
        for fix, kind in batch:
            serial, owner = self._by_fix.get(id(fix), (-1, 0))
            if serial < self._serial0:
                continue
            i = serial - self._serial0
            a = self._held[i]
            if (
                isinstance(a, FixAttempt)
                and a.T_map_base is fix.T_map_base
                and a.decision != kind.value
            ):
                self._held[i] = dataclasses.replace(a, decision=kind.value)
                done.append((fix, kind, owner))
        return done

    def discard(self, stamp_ns: int, source: str) -> None:
        """A fix held for consistency left the window unused: its held attempt (pending, of
        ``source`` at ``stamp_ns``) gets that decision."""
        pending, final = EventKind.PENDING_CONSISTENCY.value, EventKind.DISCARDED_CANDIDATE.value
        for i, a in enumerate(self._held):
            if (
                isinstance(a, FixAttempt)
                and a.in_map
                and a.stamp_ns == stamp_ns
                and a.source == source
                and a.decision == pending
            ):
                self._held[i] = dataclasses.replace(a, decision=final)
                return

    def release(self, horizon_ns: int | None) -> None:
        """Hand on the records stamped before ``horizon_ns`` (all with None), in order; a frame
        record gets the count of its accepted fixes of the map."""
        while self._held and (horizon_ns is None or self._held[0].stamp_ns < horizon_ns):
            record = self._held.popleft()
            self._serial0 += 1
            if isinstance(record, FixAttempt):
                # the frame counts the map's fixes: a lidar fix is no camera frame's, a cab's
                # is decided by another filter (and held after its frame's record)
                if record.accepted and record.tag_ids and record.in_map:
                    self._accepted_at[record.stamp_ns] += 1
            else:
                n = self._accepted_at.pop(record.stamp_ns, 0)
                record = dataclasses.replace(record, n_fixes_accepted=n)
            self._emit(record)
        if len(self._by_fix) > 4 * len(self._held) + 64:
            self._by_fix = {k: v for k, v in self._by_fix.items() if v[0] >= self._serial0}
