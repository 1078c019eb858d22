"""The map <-> elevator-cab handoff: which frame the robot is localized in, with hysteresis.

Inside a moving cab the map is the wrong frame (the cab's walls move with the robot and the floor
is unknown until the doors open), so the node localizes the robot relative to the cab there.
:class:`CabHandoff` decides when, from three inputs, each optional:

- the camera frames: which known tags they hold (tags of a cab frame, tags of the map frame);
- the building's door topic (:class:`~tagloc.messages.ElevatorStateMsg`): once a message of a
  cab arrived, its door state is taken as given; without one the doors are inferred from the
  tags (a landing's tags are visible only through open doors) and the odometry;
- the odometry's travelled distance (a robot that walked a metre left the cab).

=============  ==================================================================================
state          entered when
=============  ==================================================================================
``in_map``     start; from ``boarding`` when no cab tag was seen for ``lost_s`` (walked past);
               from ``alighting`` after ``exit_m`` of travel, or ``exit_s`` without a cab tag
               while landing tags are seen
``boarding``   cab tags seen over ``board_dwell_s`` (gaps below ``lost_s``)
``in_cab``     the doors closed (the door topic; inferred: cab tags seen and no map-frame tag
               for ``closed_after_s``): riding, the floor unknown
``alighting``  the doors opened (the door topic; inferred: map-frame tags seen over
               ``open_dwell_s``, or ``exit_m`` of travel); back to ``in_cab`` if they close
               again before the robot left (a stop at another floor)
=============  ==================================================================================

One glimpse never flips the state: every inferred move needs a dwell. Each move is a
:class:`CabTransition` (an output of the node, logged at INFO) with its reason.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import StrEnum

from pydantic import Field, model_validator

from tagloc.config import FieldPathError, StrictModel
from tagloc.units import S_NS

__all__ = ["CabHandoff", "CabState", "CabTransition", "ElevatorConfig"]

logger = logging.getLogger(__name__)


class ElevatorConfig(StrictModel):
    """``localizer.yaml``: ``elevators``: the cab frames, the handoff's dwell times, floors.

    Units: seconds, metres.
    """

    #: Frames of the tag map that are elevator cabs (tags inside a cab, posed in its frame). A
    #: tag map with a frame that is neither the map frame nor listed here is refused at start-up.
    cab_frames: tuple[str, ...] = Field(("elevator_cab",), max_length=100)
    #: Cab tags seen over this long (no gap above ``lost_s``): the robot is boarding.
    board_dwell_s: float = Field(0.5, ge=0, le=60)
    #: Inferred doors: cab tags seen and no map-frame tag for this long: the doors are closed.
    closed_after_s: float = Field(2.0, gt=0, le=600)
    #: Inferred doors: map-frame tags seen over this long while in the cab: the doors are open.
    open_dwell_s: float = Field(0.2, ge=0, le=60)
    #: Boarding: no cab tag for this long and the robot walked past the cab.
    lost_s: float = Field(3.0, gt=0, le=600)
    #: Alighting: no cab tag for this long while map-frame tags are seen: out of the cab.
    exit_s: float = Field(1.5, gt=0, le=600)
    #: Alighting (or a cab without doors news): travelled this far since the doors opened: out.
    exit_m: float = Field(1.0, gt=0, le=100)
    #: Accepted fixes of a floor's tags, none of another floor between, that give the floor
    #: after a ride (when it is unknown).
    floor_confirm_fixes: int = Field(3, ge=1, le=1000)
    #: The same while the floor is known (a robot carried to another floor without a ride).
    floor_change_fixes: int = Field(10, ge=1, le=10_000)
    #: 1-sigma of z added to the published pose's covariance while the floor is unknown (m).
    unknown_floor_sigma_m: float = Field(10.0, gt=0, le=1e4)
    #: On exit, set the pose in ``map`` to the one carried from the cab: the robot's pose in the
    #: cab (the cab's tags) composed with the cab's pose measured when the doors closed (a shaft
    #: is vertical). False: the landing's tags alone re-acquire it.
    carry_through_ride: bool = True
    #: Start the cab's estimate at the cab's first tag from the map estimate composed with the
    #: cab's pose in the floor's frame (measured by the earlier rides' boardings), with the
    #: covariance of both; its tags then correct it. False: the cab's tags alone start it.
    cab_start_prior: bool = True
    #: While the cab's estimate rests on that start, cab fixes from farther than this (m) are
    #: weighed as far landing fixes are (``landing_tilt_sigma_rad``); a nearer one ends it.
    cab_near_m: float = Field(1.2, gt=0, le=100)
    #: After an exit, landing tags' fixes from farther than this (m) are weighed for the error
    #: one view shares (``landing_tilt_sigma_rad``, ``landing_viewpoint_m``); a fix from
    #: within it ends the settling.
    landing_near_m: float = Field(3.0, gt=0, le=100)
    #: The settling ends after this much travel since the exit (m).
    landing_settle_m: float = Field(10.0, ge=0, le=1000)
    #: 1-sigma of a far single tag's orientation about its vertical axis (rad): the fix's base
    #: moves sideways by the range times it; its range is off by as much.
    landing_tilt_sigma_rad: float = Field(0.15, ge=0, le=1.0)
    #: Fixes of one tag within this much travel (m) share one view: the n-th counts 1/n.
    landing_viewpoint_m: float = Field(1.0, gt=0, le=100)

    @model_validator(mode="after")
    def _frames(self) -> ElevatorConfig:
        if len(set(self.cab_frames)) != len(self.cab_frames):
            raise FieldPathError(("cab_frames",), "lists a frame twice")
        if any(not f for f in self.cab_frames):
            raise FieldPathError(("cab_frames",), "holds an empty frame name")
        return self


class CabState(StrEnum):
    """Where the robot is with respect to an elevator cab (module docstring)."""

    IN_MAP = "in_map"
    BOARDING = "boarding"
    IN_CAB = "in_cab"
    ALIGHTING = "alighting"

    @property
    def in_cab(self) -> bool:
        """Localized relative to a cab (every state but ``in_map``)."""
        return self is not CabState.IN_MAP


@dataclass(frozen=True, slots=True)
class CabTransition:
    """One move of the handoff (an output of the node)."""

    stamp_ns: int
    from_state: CabState
    to_state: CabState
    cab_frame: str
    reason: str

    def to_dict(self) -> dict[str, object]:
        return {
            "stamp_ns": self.stamp_ns, "kind": "cab", "from": str(self.from_state),
            "to": str(self.to_state), "cab_frame": self.cab_frame, "reason": self.reason,
        }  # fmt: skip


def _ns(seconds: float) -> int:
    return round(seconds * S_NS)


class _Streak:
    """Sightings with gaps below ``max_gap_ns``: since when, and the latest."""

    def __init__(self, max_gap_ns: int) -> None:
        self.max_gap_ns = max_gap_ns
        self.first: int | None = None
        self.last: int | None = None

    def seen(self, stamp_ns: int) -> None:
        if self.last is None or stamp_ns - self.last > self.max_gap_ns:
            self.first = stamp_ns
        self.last = stamp_ns if self.last is None else max(self.last, stamp_ns)

    def duration_ns(self, now_ns: int) -> int:
        """How long the streak has lasted at ``now_ns`` (-1: none, or broken)."""
        if self.first is None or self.last is None or now_ns - self.last > self.max_gap_ns:
            return -1
        return self.last - self.first

    def silent_ns(self, now_ns: int) -> float:
        """Since the last sighting (``inf``: never)."""
        return float("inf") if self.last is None else float(now_ns - self.last)


class CabHandoff:
    """The handoff's state machine (module docstring). Feed :meth:`frame`, :meth:`door` and
    :meth:`odometry` in stamp order; each returns the move it caused, if any."""

    def __init__(self, config: ElevatorConfig) -> None:
        self.config = c = config
        self._board, self._closed = _ns(c.board_dwell_s), _ns(c.closed_after_s)
        self._open, self._lost, self._exit = _ns(c.open_dwell_s), _ns(c.lost_s), _ns(c.exit_s)
        self.state = CabState.IN_MAP
        self._entered_ns = -(2**62)  # when the state was entered
        self.cab_frame = ""
        self._cab: dict[str, _Streak] = {}
        # the map-frame streak breaks after closed_after_s without a sighting
        self._map = _Streak(self._closed)
        self._doors: dict[str, tuple[int, bool]] = {}  # cab -> (stamp, open) from the topic
        self._odometer_m = 0.0
        self._moved_from_m = 0.0  # odometer when the state was entered
        self.transitions = 0

    # ----- inputs ----------------------------------------------------------------------------
    def frame(
        self, stamp_ns: int, cab_frames: frozenset[str], map_seen: bool
    ) -> CabTransition | None:
        """A camera frame: the cab frames of its known tags, and whether it holds a map tag."""
        for cab in cab_frames:
            self._cab.setdefault(cab, _Streak(self._lost)).seen(stamp_ns)
        if map_seen:
            self._map.seen(stamp_ns)
        return self._judge(stamp_ns)

    def door(self, stamp_ns: int, cab_frame: str, door_open: bool) -> CabTransition | None:
        """The building's door state of ``cab_frame``'s cab."""
        self._doors[cab_frame] = (stamp_ns, door_open)
        return self._judge(stamp_ns)

    def odometry(self, stamp_ns: int, odometer_m: float) -> CabTransition | None:
        """An odometry sample: the distance travelled so far."""
        self._odometer_m = odometer_m
        return self._judge(stamp_ns)

    def restart(self) -> None:
        """The clock jumped back: sightings and door news of the old timeline are forgotten
        (the state is kept: the robot did not move)."""
        self._cab.clear()
        self._map = _Streak(self._closed)
        self._doors.clear()
        self._moved_from_m = self._odometer_m

    # ----- the state machine -----------------------------------------------------------------
    def _door_open(self) -> bool | None:
        news = self._doors.get(self.cab_frame)
        return None if news is None else news[1]

    def _judge(self, now: int) -> CabTransition | None:
        c, state = self.config, self.state
        moved = self._odometer_m - self._moved_from_m
        if state is CabState.IN_MAP:
            for cab, streak in sorted(self._cab.items()):
                if streak.duration_ns(now) >= self._board:
                    self.cab_frame = cab
                    why = f"tags of {cab} seen for {c.board_dwell_s:g} s"
                    return self._move(now, CabState.BOARDING, why)
            return None
        mine = self._cab.get(self.cab_frame)
        cab_silent = float("inf") if mine is None else mine.silent_ns(now)
        door = self._door_open()
        closed = f"no map-frame tag for {c.closed_after_s:g} s"
        if state is CabState.BOARDING:
            if cab_silent > self._lost:
                why = f"no cab tag for {c.lost_s:g} s: walked past the cab"
                return self._move(now, CabState.IN_MAP, why)
            if door is False:
                return self._move(now, CabState.IN_CAB, "doors closed (door topic)")
            if door is None and self._closed_inferred(now, cab_silent):
                return self._move(now, CabState.IN_CAB, f"{closed}: doors closed (inferred)")
            return None
        if state is CabState.IN_CAB:
            if door is True:
                return self._move(now, CabState.ALIGHTING, "doors open (door topic)")
            first = self._map.first
            if door is None and self._map.duration_ns(now) >= self._open and (
                first is not None and first >= self._entered_ns
            ):
                why = f"map-frame tags seen for {c.open_dwell_s:g} s: doors open (inferred)"
                return self._move(now, CabState.ALIGHTING, why)
            if door is None and moved >= c.exit_m:
                why = f"moved {moved:.2f} m: doors open (inferred)"
                return self._move(now, CabState.ALIGHTING, why)
            return None
        # alighting: out once the robot walked off (or turned its back on the cab in the lobby)
        if moved >= c.exit_m:
            return self._move(now, CabState.IN_MAP, f"moved {moved:.2f} m from the doors")
        if cab_silent > self._exit and self._map.silent_ns(now) <= self._exit:
            why = f"no cab tag for {c.exit_s:g} s, map-frame tags seen"
            return self._move(now, CabState.IN_MAP, why)
        if door is False:
            return self._move(now, CabState.IN_CAB, "doors closed again (door topic)")
        if door is None and self._closed_inferred(now, cab_silent):
            return self._move(now, CabState.IN_CAB, f"{closed}: doors closed again (inferred)")
        return None

    def _closed_inferred(self, now: int, cab_silent: float) -> bool:
        """Cab tags in view and no map-frame tag for ``closed_after_s``, in this state."""
        return (
            cab_silent <= self._lost
            and self._map.silent_ns(now) >= self._closed
            and now - self._entered_ns >= self._closed
        )

    def _move(self, now: int, to: CabState, reason: str) -> CabTransition:
        move = CabTransition(now, self.state, to, self.cab_frame, reason)
        logger.info(
            "%d cab handoff %s -> %s (%s): %s", now, self.state, to, self.cab_frame, reason
        )
        self.state, self._entered_ns = to, now
        self._moved_from_m = self._odometer_m
        if to is CabState.IN_MAP:
            self._cab.clear()
            self.cab_frame = ""
        self.transitions += 1
        return move
