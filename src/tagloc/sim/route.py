"""The ``route`` section of a world file: waypoints (checkpoint names or ``[x, y]``), speeds, dwell.

Units: metres, seconds, radians. Checkpoint names are resolved against the world's checkpoints.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, Any

import numpy as np
from pydantic import BeforeValidator, Field, model_validator

from tagloc._types import FloatArray
from tagloc.config import FieldPathError, StrictModel, short_repr

#: Largest coordinate of a world, metres (a building, not a planet).
MAX_COORDINATE_M = 1e5
#: Longest dwell at a waypoint, seconds.
MAX_DWELL_S = 3600.0


def _check_target(value: Any) -> Any:
    """Accept a checkpoint name or a finite ``[x, y]`` pair (as a tuple), else raise."""
    if isinstance(value, str):
        return value
    if (
        isinstance(value, list | tuple)
        and len(value) == 2
        and all(
            isinstance(c, int | float)
            and not isinstance(c, bool)
            and math.isfinite(c)
            and abs(c) <= MAX_COORDINATE_M
            for c in value
        )
    ):
        return (float(value[0]), float(value[1]))
    raise ValueError(
        f"expected a checkpoint name or [x, y] in metres (|x|, |y| <= {MAX_COORDINATE_M:g}), "
        f"got {short_repr(value)}"
    )


class Ride(StrictModel):
    """Ride ``elevator`` (a shaft's name) to floor ``to`` (:mod:`tagloc.sim.ride`)."""

    elevator: str = Field(min_length=1, max_length=64)
    to: str = Field(min_length=1, max_length=64)


class Waypoint(StrictModel):
    """A route waypoint: ``at`` (checkpoint name or ``[x, y]`` in map), optional ``dwell`` (s);
    or ``ride: {elevator, to}``: walk into the cab from the current floor, ride it to floor
    ``to``, walk out (multi-floor worlds; :mod:`tagloc.sim.ride`)."""

    at: Annotated[str | tuple[float, float], BeforeValidator(_check_target)] | None = None
    dwell: float | None = Field(default=None, ge=0.0, le=MAX_DWELL_S)
    ride: Ride | None = None

    @model_validator(mode="before")
    @classmethod
    def _bare(cls, data: Any) -> Any:
        return data if isinstance(data, dict) else {"at": data}

    @model_validator(mode="after")
    def _one(self) -> Waypoint:
        if (self.at is None) == (self.ride is None):
            raise ValueError("give exactly one of 'at' or 'ride'")
        if self.ride is not None and self.dwell is not None:
            raise FieldPathError(("dwell",), "a ride's dwell is its elevator's dwell_s")
        return self


class RouteConfig(StrictModel):
    """The ``route`` section of a world file (units: m, s, rad; see the module docstring)."""

    waypoints: tuple[Waypoint, ...] = Field(min_length=2)
    speed: float = Field(ge=0.01, le=5.0)
    accel_max: float = Field(default=0.5, ge=0.01, le=20.0)
    yaw_rate_max: float = Field(default=0.8, ge=0.01, le=10.0)
    yaw_accel_max: float = Field(default=1.5, ge=0.01, le=100.0)
    corner_radius: float = Field(default=0.0, ge=0.0, le=100.0)
    dwell: float = Field(default=0.0, ge=0.0, le=MAX_DWELL_S)
    repeat: int = Field(default=1, ge=1, le=100)


def route_points(
    route: RouteConfig, checkpoints_xy: Mapping[str, tuple[float, float]]
) -> tuple[FloatArray, FloatArray]:
    """Resolve a route into ``(points_xy (M, 2), dwell_s (M,))``, repeated ``route.repeat`` times.

    Raises
    ------
    KeyError
        A waypoint names a checkpoint missing from ``checkpoints_xy`` (the world validates this).
    ValueError
        A ride waypoint (those routes are planned by :mod:`tagloc.sim.ride`).
    """
    if any(w.at is None for w in route.waypoints):
        raise ValueError("a route that rides an elevator is planned by tagloc.sim.ride")
    xy = [checkpoints_xy[w.at] if isinstance(w.at, str) else w.at for w in route.waypoints]
    dwell = [route.dwell if w.dwell is None else w.dwell for w in route.waypoints]
    return np.array(xy * route.repeat, dtype=np.float64), np.array(dwell * route.repeat)
