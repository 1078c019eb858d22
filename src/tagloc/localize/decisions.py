"""The node's one output path for fixes: each offered fix decided by the filter, booked with
the supervisor, and handed on once final.

For every :class:`~tagloc.localize.sources.SourceResult`: the refused observations are held, then
each offered fix is decided by the filter (:meth:`MapOdomFilter.update` or
:meth:`~MapOdomFilter.update_partial`) and its :class:`~tagloc.localize.run.FixAttempt` held
with the decision; a batch decision of the filter (start-up, re-acquisition, kidnap) relabels
the held attempts it decided (:class:`~tagloc.localize.held.HeldRecords`), and every final
decision enters the supervisor's quality books of its source (NIS per measured direction); then
the frame's record is held and the records older than the hold window (the consistency and
kidnap windows and 1 s) are handed on. An accepted fix that measures every direction of the
filter is the last fix the supervisor's gap clock counts from. The fixes of an elevator cab's
tags, decided by the cab's own filter (:mod:`tagloc.localize.cab`), leave by the same path
(:meth:`FixDecisions.record`), their :attr:`~tagloc.localize.run.FixAttempt.frame` naming the
cab.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

from tagloc.localize.config import LocalizerConfig
from tagloc.localize.events import APPLIED, EventKind, FilterEvent
from tagloc.localize.fiducial import SourcedFix
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import TagFix
from tagloc.localize.held import HeldRecords, Record
from tagloc.localize.run import FixAttempt
from tagloc.localize.sources import FixSource, SourceResult
from tagloc.supervise import Supervisor
from tagloc.units import S_NS

__all__ = ["FixDecisions"]


class FixDecisions:
    """Decisions on the fixes of a node's sources (module docstring).

    Parameters
    ----------
    config : LocalizerConfig
    supervisor : Supervisor
    emit : callable
        Receives each record once final.
    """

    def __init__(
        self, config: LocalizerConfig, supervisor: Supervisor, emit: Callable[[Record], None]
    ) -> None:
        self._supervisor = supervisor
        self._held = HeldRecords(emit)
        windows = (config.gates.consistency_window_s, config.kidnap.window_s)
        self._held_ns = round((max(windows) + 1.0) * S_NS)
        self._last: tuple[int, float] | None = None  # the last accepted fix: stamp, odometer

    def since_last_fix(self, stamp_ns: int, odometer_m: float) -> tuple[float, float]:
        """Stream seconds and metres travelled since the last accepted fix (``inf`` before)."""
        if self._last is None:
            return math.inf, math.inf
        return (stamp_ns - self._last[0]) / S_NS, odometer_m - self._last[1]

    def apply(
        self, sources: Sequence[FixSource], index: int, result: SourceResult,
        flt: MapOdomFilter, odometer_m: float,
    ) -> None:  # fmt: skip
        """Decide and book the result of ``sources[index]`` (module docstring)."""
        source = sources[index]
        for attempt in result.refused:
            self._held.hold(attempt)
        for _ in range(result.failed):
            self._supervisor.on_fix(source.spec.name, False, math.nan, math.nan)
        for offer in result.offers:
            fix = offer.fix
            event = flt.update(fix) if isinstance(fix, TagFix) else flt.update_partial(fix)
            attempt = dataclasses.replace(offer.attempt, decision=event.kind.value, d2=event.d2)
            self._held.hold(attempt, fix, index)
            if event.kind is not EventKind.PENDING_CONSISTENCY:
                self._judged(source, event, offer.dof, offer.reproj_px, flt, odometer_m)
            for old, kind, owner in self._held.relabel(flt.last_batch):
                self._judged(sources[owner], FilterEvent(old.stamp_ns, kind), flt.dof,
                             old.quality.reproj_err_px, flt, odometer_m)  # fmt: skip
        if result.frame is not None:
            self._held.hold(result.frame)
        if result.release_ns is not None:
            self._held.release(result.release_ns - self._held_ns)

    def record(
        self, frame: str, sourced: SourcedFix, event: FilterEvent, flt: MapOdomFilter
    ) -> None:
        """Hold the attempt of a fix another filter decided (an elevator cab's, of the tags
        posed in ``frame``), with its decision; that filter's batch decision relabels the held
        attempts it used. The supervisor's books and the gap clock are the ``map -> odom``
        filter's alone, so they are not touched (the cab's component keeps its own)."""
        fix = sourced.fix
        q = fix.quality
        attempt = FixAttempt(
            fix.stamp_ns, fix.source, sourced.tag_ids, fix.T_map_base, fix.cov,
            event.kind.value, q.range_m, q.view_angle_rad, sourced.false_detection, event.d2,
            frame=frame,
        )  # fmt: skip
        self._held.hold(attempt, fix)
        self._held.relabel(flt.last_batch)

    def discarded(self, stamp_ns: int, source: str) -> None:
        """The filter discarded a fix it held for consistency (its attempt says so)."""
        self._held.discard(stamp_ns, source)

    def release_all(self) -> None:
        """Hand on every held record."""
        self._held.release(None)

    def reset(self) -> None:
        """The clock jumped back: held records handed on, no last fix."""
        self._held.release(None)
        self._last = None

    def _judged(
        self, source: FixSource, event: FilterEvent, dof: int, reproj_px: float,
        flt: MapOdomFilter, odometer_m: float,
    ) -> None:  # fmt: skip
        accepted = event.kind.value in APPLIED
        if accepted and dof >= flt.dof:
            stamp = event.stamp_ns if self._last is None else max(self._last[0], event.stamp_ns)
            self._last = (stamp, odometer_m)
        nis = math.nan if event.d2 is None or dof == 0 else event.d2 / dof
        self._supervisor.on_fix(source.spec.name, accepted, nis, reproj_px)
