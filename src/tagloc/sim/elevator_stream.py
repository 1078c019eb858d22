"""The building's elevator state as a stream: :class:`~tagloc.messages.ElevatorStateMsg` s.

A building that provides it publishes, for every cab, its door (open or not) and the floor it
stands at (None while it moves): at ``RATE_HZ`` and at once on every change, stamped with the
odometry stamps of the drive (the building's clock is the robot's).
"""

from __future__ import annotations

from dataclasses import dataclass

from tagloc.messages import ElevatorStateMsg
from tagloc.sim.drive import Drive
from tagloc.sim.ride import RidePlan

__all__ = ["RATE_HZ", "elevator_messages"]

#: How often a cab's state is published when nothing changes, Hz.
RATE_HZ = 2.0


@dataclass(frozen=True, slots=True)
class _State:
    door_open: bool
    floor: str | None


def elevator_messages(drive: Drive) -> list[ElevatorStateMsg]:
    """Every cab's state messages over ``drive`` (module docstring), in stamp order; empty for
    a drive without moving cabs."""
    plan = drive.plan
    if not isinstance(plan, RidePlan):
        return []
    stamps = drive.stamps_ns
    t_s = drive.route_s(stamps)
    period_ns = round(1e9 / RATE_HZ)
    out: list[tuple[int, int, ElevatorStateMsg]] = []
    for c, cab in enumerate(plan.cabs):
        doors = cab.doors.is_open(t_s)
        floors = plan.cab_floor_at(t_s, cab.name)
        last: _State | None = None
        last_ns = 0
        for i, stamp in enumerate(stamps.tolist()):
            state = _State(bool(doors[i]), floors[i])
            if state != last or stamp - last_ns >= period_ns:
                out.append(
                    (stamp, c, ElevatorStateMsg(stamp, cab.frame, state.door_open, state.floor))
                )
                last, last_ns = state, stamp
    out.sort(key=lambda item: (item[0], item[1]))
    return [msg for _, _, msg in out]
