"""Seeded schedules of rides, and passengers, for the elevator scenarios.

:func:`random_ride_route` replaces a building's route by ``rides`` rides to random floors: from
the route's first waypoint, on each floor the robot walks to the floor's *lobby* (its checkpoint
nearest the shaft's landing), to one of the floor's other checkpoints at random and back, then
rides to a random other floor served by the shaft. :func:`pacing_passengers` puts people in a cab
who pace across it between the robot (in the middle) and the wall opposite the door, so that they
hide the cab's back-wall tags part of the time.
"""

from __future__ import annotations

import math

import numpy as np

from tagloc.sim.floors import Shaft
from tagloc.sim.people import Person
from tagloc.sim.ride import landing_and_centre
from tagloc.sim.route import RouteConfig, Waypoint
from tagloc.sim.world import World

__all__ = ["pacing_passengers", "random_ride_route"]


def random_ride_route(
    world: World, rides: int, seed: int, elevator: str | None = None
) -> RouteConfig:
    """The world's route with ``rides`` rides of ``elevator`` (default: the first shaft) to
    random floors (module docstring); speeds and dwell as the world's route."""
    shaft = next(s for s in world.elevators if elevator in (None, s.name))
    rng = np.random.default_rng([seed, 21])
    landing, _ = landing_and_centre(shaft)
    floors = {f.name: f for f in world.all_floors()}
    first = world.route.waypoints[0]
    table = {cp.name: f.name for f in world.all_floors() for cp in f.checkpoints}
    floor = table[first.at] if isinstance(first.at, str) else world.all_floors()[0].name
    waypoints: list[Waypoint] = [first]
    for k in range(rides + 1):
        names = [cp.name for cp in floors[floor].checkpoints]
        xy = {cp.name: (cp.x, cp.y) for cp in floors[floor].checkpoints}
        lobby = min(names, key=lambda n: math.dist(xy[n], landing))
        others = [n for n in names if n != lobby] or [lobby]
        visit = others[int(rng.integers(len(others)))]
        waypoints += [Waypoint(at=lobby), Waypoint(at=visit), Waypoint(at=lobby)]
        if k == rides:
            break
        choices = [f for f in shaft.floors if f != floor]
        floor = choices[int(rng.integers(len(choices)))]
        waypoints.append(Waypoint.model_validate({"ride": {"elevator": shaft.name, "to": floor}}))
    return world.route.model_copy(update={"waypoints": tuple(waypoints), "repeat": 1})


def pacing_passengers(
    shaft: Shaft, duration_s: float, count: int = 2, period_s: float = 7.0
) -> tuple[Person, ...]:
    """``count`` people pacing across ``shaft``'s cab (module docstring) for ``duration_s``,
    ``period_s`` a round trip, each on its own line and phase; ``x, y`` in ``map``."""
    p = shaft.pose_in_map
    yaw = math.radians(p.yaw_deg)
    nx, ny = shaft.door_normal_cab()
    half_depth = (shaft.footprint[0] if nx else shaft.footprint[1]) / 2
    half_width = (shaft.footprint[1] if nx else shaft.footprint[0]) / 2 - 0.3
    people = []
    for i in range(count):
        depth = -half_depth * (0.45 + 0.3 * i / max(count - 1, 1))  # between middle and back
        steps = int(duration_s / (period_s / 2)) + 2
        path = []
        for k in range(steps):
            side = half_width * (1 if (k + i) % 2 else -1)
            u, v = (depth * nx - side * ny, depth * ny + side * nx)  # cab frame
            x = p.x + math.cos(yaw) * u - math.sin(yaw) * v
            y = p.y + math.sin(yaw) * u + math.cos(yaw) * v
            path.append((k * period_s / 2 + i * period_s / (2 * count), x, y))
        people.append(Person(radius_m=0.2, height_m=1.7, path=tuple(path)))
    return tuple(people)
