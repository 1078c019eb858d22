"""The cab's estimate at boarding: started from the map estimate and the cab's placement.

The cab's tags are the cab's estimate's only fixes, and a single tag 2-3 m away cannot tell its
pose's two IPPE branches apart: from the tags alone the cab's estimate starts only once the
robot is near (seconds after boarding). A shaft is vertical, so the cab stands at the same pose
in every floor's frame, and the earlier rides measured it (:class:`~.ride_anchor.CabPlacement`).
So, while the floor is known and a ride placed the cab (:class:`CabStart`):

1. at the cab's first tag the cab's estimate is started from the map estimate carried into the
   cab, ``T_cab_odom = inv(T_floor_cab) @ T_floor_odom``, with the covariance of both
   (:meth:`~.ride_anchor.RideAnchor.cab_start`); it is started again at each frame of the cab's
   tags while it rests on that (the map estimate keeps taking the landing's fixes; the
   odometry's drift on the walk in is the map estimate's to correct);
2. the cab's fixes from farther than ``elevators.cab_near_m`` are weighed as far landing fixes
   are (:class:`~.ride_anchor.LandingSettle`: a far single tag's turn and range error, shared
   by the fixes of one view): its branch is chosen with the started estimate as the prior, it
   is judged by the filter's gates, it barely moves the estimate;
3. the first fix from nearer ends it: from there the cab's tags alone carry the cab's estimate
   (a wrong placement gives way to them through the filter's gates and kidnap test).
"""

from __future__ import annotations

import dataclasses
import logging

from tagloc.errors import TransformLookupError
from tagloc.localize.fiducial import FiducialFixSource, SourcedFix
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import LocalizeError
from tagloc.localize.floors import FloorFrame
from tagloc.localize.ride_anchor import LandingSettle, RideAnchor
from tagloc.supervise import ElevatorConfig

__all__ = ["CabStart"]

logger = logging.getLogger(__name__)


class CabStart:
    """One cab estimate's start (module docstring); a new one at each new cab estimate."""

    def __init__(self, config: ElevatorConfig) -> None:
        self._c = config
        self._settle: LandingSettle | None = None

    @property
    def resting(self) -> bool:
        """The cab's estimate rests on the cab's placement (no cab fix from near yet)."""
        return self._settle is not None and not self._settle.done

    def start(
        self, stamp_ns: int, cab: MapOdomFilter, main: MapOdomFilter, anchor: RideAnchor,
        floors: FloorFrame, source: FiducialFixSource, odometer_m: float,
    ) -> bool:  # fmt: skip
        """Start (or start again) ``cab`` at ``stamp_ns`` from ``main`` through the anchor's
        placement (the floor known: the caller's to check); True if it did."""
        if not self._c.cab_start_prior or (self._settle is not None and not self.resting):
            return False
        if self._settle is None and cab.initialized:  # the cab's tags started it: theirs
            return False
        start = anchor.cab_start(main, floors)
        if start is None:
            return False
        try:
            cab.initialize(stamp_ns, *start)
        except (TransformLookupError, LocalizeError):  # no odometry there, a bad covariance
            return False
        if self._settle is None:
            tags = {i: T.translation for i, T in source.T_map_tag.items()}
            near = self._c.model_copy(update={"landing_near_m": self._c.cab_near_m})
            self._settle = LandingSettle(near, odometer_m, tags)
            logger.info("%d cab estimate started from the cab's placement", stamp_ns)
        return True

    def weigh(self, sourced: SourcedFix, odometer_m: float) -> SourcedFix:
        """A cab fix as the cab's estimate takes it (module docstring, steps 2 and 3)."""
        if not self.resting or self._settle is None:
            return sourced
        fix = self._settle.weigh(sourced.fix, odometer_m)
        return sourced if fix is sourced.fix else dataclasses.replace(sourced, fix=fix)
