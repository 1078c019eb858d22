"""Which floor the robot is on: known from the tags the filter accepts, lost in a moving cab.

:class:`FloorBook` keeps the current floor of a building of several floors (the tag map's floor
table: name -> height of the floor in ``map``, m). The floor is *known* once
``floor_confirm_fixes`` accepted fixes of one floor's tags came with none of another floor's
between them; it becomes *unknown* when the cab's doors close (:meth:`FloorBook.lose`) and known
again from the landing's tags when they open. While it is known, a floor change needs
``floor_change_fixes`` such fixes (a robot carried to another floor, not riding). A floor never
changes without tags of the new floor: each change is a :class:`FloorChange`, the one
discontinuity of the published ``map -> odom`` (by the difference of the floors' heights), which
the node declares as an event.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["FloorBook", "FloorChange"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class FloorChange:
    """The floor became known or changed (``from_floor`` None: the first floor known).

    Attributes
    ----------
    stamp_ns : int
        Stamp of the fix that decided it.
    from_floor, to_floor : str or None, str
    dz_m : float
        Height of ``to_floor`` minus that of ``from_floor`` (0 for the first floor).
    tag_ids : tuple of int
        The tags whose accepted fixes gave the floor.
    reason : str
    """

    stamp_ns: int
    from_floor: str | None
    to_floor: str
    dz_m: float
    tag_ids: tuple[int, ...]
    reason: str

    @property
    def changed(self) -> bool:
        """A floor change (not the first floor, nor the same floor found again)."""
        return self.from_floor is not None and self.from_floor != self.to_floor


class FloorBook:
    """The current floor (module docstring).

    Parameters
    ----------
    heights_m : mapping of str to float
        Each floor's height in ``map`` (m).
    confirm_fixes, change_fixes : int
        Accepted fixes of one floor that give it while it is unknown / known.
    """

    def __init__(
        self, heights_m: Mapping[str, float], confirm_fixes: int, change_fixes: int
    ) -> None:
        self.heights_m = dict(heights_m)
        self._confirm, self._change = confirm_fixes, change_fixes
        #: The last floor known (kept while unknown: the floor the ride started from).
        self.floor: str | None = None
        self.known = False
        self._candidate: str | None = None
        self._tags: list[int] = []
        self.changes = 0

    @property
    def height_m(self) -> float:
        """Height of the last known floor (0 before any)."""
        return 0.0 if self.floor is None else self.heights_m[self.floor]

    def lose(self) -> None:
        """The floor is unknown from now (the doors closed on a ride)."""
        self.known = False
        self._candidate, self._tags = None, []

    def accepted(self, stamp_ns: int, floor: str, tag_id: int) -> FloorChange | None:
        """The filter accepted a fix of tag ``tag_id`` on ``floor``; the change it completes."""
        if floor not in self.heights_m:
            return None
        if self.known and floor == self.floor:
            self._candidate, self._tags = None, []
            return None
        if floor != self._candidate:
            self._candidate, self._tags = floor, []
        self._tags.append(tag_id)
        need = self._change if self.known else self._confirm
        if len(self._tags) < need:
            return None
        old = self.floor
        dz = 0.0 if old is None else self.heights_m[floor] - self.heights_m[old]
        if old is None:
            why = f"first floor: {need} accepted fixes of its tags"
        elif not self.known:
            why = f"after a ride: {need} accepted fixes of the landing's tags"
        else:
            why = f"{need} accepted fixes of another floor's tags without a ride: carried there?"
        change = FloorChange(stamp_ns, old, floor, dz, tuple(dict.fromkeys(self._tags)), why)
        self.floor, self.known = floor, True
        self._candidate, self._tags = None, []
        if change.changed:
            self.changes += 1
        logger.info("%d floor %s -> %s (dz %+.3f m): %s", stamp_ns, old, floor, dz, why)
        return change
