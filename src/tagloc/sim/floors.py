"""Buildings of several floors and their elevator shafts (the ``floors`` and ``elevators`` of a
world file; :mod:`tagloc.sim.world` checks how they refer to each other).

A :class:`Floor` is a storey: its ``name``, the height of its floor in ``map`` (``height_m``, z up)
and its walls, tags and checkpoints. On a floor, ``x`` and ``y`` are ``map`` coordinates and every
height (a wall's, a tag's ``wall.height`` or ``pose.position`` z) is measured from that floor, so a
storey can be copied to another height unchanged. A world file without ``floors`` is one floor
named ``"0"`` at z = 0 made of its top-level walls, tags and checkpoints.

A :class:`Shaft` is an elevator: its cab (a rectangular room, footprint, door and wall material
as the single-floor :class:`~tagloc.sim.world_parts.Elevator`) with its own frame (``frame``,
``elevator_cab`` by default; one frame per cab), standing at ``pose_in_map`` (planar; its z is the
cab's floor, the height of the floor it is at or between two while it moves), serving ``floors``
(names), starting at ``start_floor`` (default: the first served), doors closed. Kinematics: the cab
moves along z with a trapezoidal speed profile (``accel_mps2`` up to ``speed_mps``, cruise, the
same deceleration; a triangle on short trips); doors take ``door_open_s`` to open and
``door_close_s`` to close; they stay open ``dwell_s`` after the last passenger entered or left.
Tags inside the cab are listed in the world's top-level ``tags`` with ``frame:`` the cab's frame
(position in that frame, z above the cab floor); a multi-floor world's top-level ``tags`` hold only
such cab tags.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field, model_validator

from tagloc.config import FieldPathError, StrictModel
from tagloc.geometry import SE3
from tagloc.sim.people import Person
from tagloc.sim.world_parts import Checkpoint, Elevator, FrameName, Tag, Wall

__all__ = ["DEFAULT_CAB_FRAME", "IMPLICIT_FLOOR", "Floor", "Shaft", "travel_time_s"]

#: The cab frame of a shaft that names none (and of a single-floor world's ``elevator``).
DEFAULT_CAB_FRAME = "elevator_cab"
#: The name of the one floor of a world file without ``floors``.
IMPLICIT_FLOOR = "0"
FloorName = str


class Floor(StrictModel):
    """One storey (see the module docstring): heights are above this floor."""

    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.+-]+$")
    height_m: float = Field(ge=-1000.0, le=1000.0)
    walls: tuple[Wall, ...] = ()
    tags: tuple[Tag, ...] = ()
    checkpoints: tuple[Checkpoint, ...] = ()
    #: People walking about on this floor (lidar occluders; :mod:`tagloc.sim.people`).
    people: tuple[Person, ...] = ()

    @model_validator(mode="after")
    def _map_tags(self) -> Floor:
        for j, tag in enumerate(self.tags):
            if tag.frame != "map":
                raise FieldPathError(
                    ("tags", j, "frame"),
                    f"a floor's tags are in map; list cab tags ({tag.frame}) in the top-level tags",
                )
        return self


class Shaft(Elevator):
    """An elevator shaft and its moving cab (see the module docstring).

    ``pose_in_map`` places the cab frame (x, y, yaw) on every floor it serves.
    """

    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$")
    frame: FrameName = DEFAULT_CAB_FRAME
    floors: tuple[FloorName, ...] = Field(min_length=1)
    start_floor: FloorName | None = None
    speed_mps: float = Field(default=1.0, gt=0.0, le=10.0)
    accel_mps2: float = Field(default=0.8, gt=0.0, le=5.0)
    door_open_s: float = Field(default=2.0, ge=0.0, le=60.0)
    door_close_s: float = Field(default=2.5, ge=0.0, le=60.0)
    dwell_s: float = Field(default=2.0, ge=0.0, le=600.0)

    @model_validator(mode="after")
    def _floors(self) -> Shaft:
        for k, name in enumerate(self.floors):
            if name in self.floors[:k]:
                raise FieldPathError(("floors", k), f"floor {name!r} listed twice")
        if self.frame == "map":
            raise FieldPathError(("frame",), "a cab needs its own frame, not map")
        if self.start_floor is not None and self.start_floor not in self.floors:
            raise FieldPathError(
                ("start_floor",), f"{self.start_floor!r} is not one of the floors it serves"
            )
        return self

    def T_map_cab(self, z: float = 0.0) -> SE3:
        """Pose of the cab frame in ``map`` with the cab floor at height ``z``."""
        T = Elevator.T_map_cab(self)
        return SE3(rotation=T.rotation, translation=np.array([*T.translation[:2], z]))

    @property
    def first_floor(self) -> str:
        """Where the cab stands at the start."""
        return self.start_floor if self.start_floor is not None else self.floors[0]


def travel_time_s(distance_m: float, speed_mps: float, accel_mps2: float) -> float:
    """Duration of a trapezoidal (or, when short, triangular) move of ``distance_m`` from rest
    to rest."""
    d = abs(distance_m)
    if d * accel_mps2 >= speed_mps**2:
        return speed_mps / accel_mps2 + d / speed_mps
    return 2.0 * math.sqrt(d / accel_mps2)
