"""What the robot's sensors can see at one instant in a building of floors: one storey and the cabs.

At time ``t`` the robot stands on a floor (its height equals the floor's) or in a cab between two
(:class:`~tagloc.sim.ride.RidePlan`). The scene of that instant (:func:`scene_at`) holds:

- on a floor: that floor's walls, tags and people; every cab standing at that floor, with its
  walls, its tags (at the cab's pose), its passengers, and its door across the opening unless the
  door is open (:meth:`~tagloc.sim.elevator.DoorTimeline.is_open`); for a cab elsewhere, the
  shaft's closed landing door across the opening;
- in a cab between floors: only that cab (walls, the closed door, its tags, its passengers).

Nothing of another floor is ever in view (floors and ceilings are opaque). Walls are planar
segments in ``map`` with heights above the scene's floor ``z_ref``; tags have their true pose in
``map`` at ``t``. A world's top-level ``people`` in a building are the cabs' passengers: each
rides the cab whose footprint holds its first position (x, y in ``map``, the cab at the start).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagloc.geometry import SE3
from tagloc.sim.building import cab_walls
from tagloc.sim.elevator import FLOOR_TOLERANCE_M
from tagloc.sim.people import Person
from tagloc.sim.ride import RidePlan, cab_contains
from tagloc.sim.world import World
from tagloc.sim.world_parts import Tag, Wall

__all__ = ["FloorScene", "SceneCache", "scene_at"]


@dataclass(frozen=True, slots=True, eq=False)
class FloorScene:
    """One instant's scene (module docstring).

    Attributes
    ----------
    floor : str or None
        The robot's floor; None in a cab between floors.
    z_ref : float
        Height in ``map`` of what the robot stands on (a floor, or the cab's floor), m.
    walls : tuple of Wall
        Planar in ``map``; heights above ``z_ref``.
    tags : tuple of (Tag, SE3)
        Each tag in view candidates with its true ``T_map_tag`` at this instant.
    people : tuple of Person
        The floor's people and the passengers of the cabs in the scene.
    key : tuple
        Equal keys, equal scenes (cabs at rest): what :class:`SceneCache` caches on.
    """

    floor: str | None
    z_ref: float
    walls: tuple[Wall, ...]
    tags: tuple[tuple[Tag, SE3], ...]
    people: tuple[Person, ...]
    key: tuple[object, ...]


def _passengers(world: World) -> dict[str, tuple[Person, ...]]:
    out: dict[str, list[Person]] = {s.name: [] for s in world.elevators}
    for person in world.people:
        xy = person.waypoints()[:1, 1:3]
        for shaft in world.elevators:
            if cab_contains(shaft, xy):
                out[shaft.name].append(person)
                break
    return {k: tuple(v) for k, v in out.items()}


def scene_at(world: World, plan: RidePlan, t_s: float, xy: np.ndarray) -> FloorScene:
    """The scene at route time ``t_s`` of a robot at planar ``xy`` (2,) (module docstring)."""
    return SceneCache(world, plan).at(t_s, xy)


class SceneCache:
    """:func:`scene_at` for one drive, reusing the scenes of cabs at rest."""

    def __init__(self, world: World, plan: RidePlan) -> None:
        self.world, self.plan = world, plan
        self._floors = {f.name: f for f in world.all_floors()}
        self._floor_tags = {
            name: tuple((t, world.T_map_tag(t)) for t in f.tags) for name, f in self._floors.items()
        }
        self._cab_tags = {
            s.name: tuple(t for t in world.tags if t.frame == s.frame) for s in world.elevators
        }
        self._shafts = {s.name: s for s in world.elevators}
        self._passengers = _passengers(world)
        self._cache: dict[tuple[object, ...], FloorScene] = {}

    def at(self, t_s: float, xy: np.ndarray) -> FloorScene:
        plan = self.plan
        t = np.array([min(max(t_s, 0.0), plan.total_duration_s)])
        z = float(plan.robot_z.z(t)[0])
        floor = None if plan.robot_z.moving(t)[0] else plan.floor_of(z)
        inside = plan.cab_of(t, np.asarray(xy, dtype=np.float64).reshape(1, 2))[0]
        states = []
        for cab in plan.cabs:
            cab_z = float(cab.z.z(t)[0])
            here = abs(cab_z - z) <= FLOOR_TOLERANCE_M and (floor is not None or cab.name == inside)
            moving = bool(cab.z.moving(t)[0])
            states.append((cab.name, here, bool(cab.doors.is_open(t)[0]), cab_z if moving else 0))
        key = (floor, tuple(states))
        if floor is not None and key in self._cache:
            return self._cache[key]
        scene = self._build(floor, z, states)
        if floor is not None:
            self._cache[key] = scene
        return scene

    def _build(
        self, floor: str | None, z: float, states: list[tuple[str, bool, bool, float]]
    ) -> FloorScene:
        walls: list[Wall] = []
        tags: list[tuple[Tag, SE3]] = []
        people: list[Person] = []
        if floor is not None:
            walls += self._floors[floor].walls
            tags += self._floor_tags[floor]
            people += self._floors[floor].people
        for name, here, door_open, _ in states:
            shaft = self._shafts[name]
            T_map_cab = shaft.T_map_cab(z)
            if here:
                walls += cab_walls(shaft, T_map_cab, door_closed=not door_open)
                tags += [(t, T_map_cab @ t.T_frame_tag()) for t in self._cab_tags[name]]
                people += self._passengers[name]
            elif floor is not None and floor in shaft.floors:
                a, b = shaft.door_cab()
                start, end = (tuple(T_map_cab.act([*p, 0.0])[:2]) for p in (a, b))
                walls.append(Wall(start=start, end=end, height=shaft.height))
        key = (floor, tuple(states))
        return FloorScene(floor, z, tuple(walls), tuple(tags), tuple(people), key)
