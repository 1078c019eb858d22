"""World files: a simulated building (walls, tags, elevator cab, checkpoints, route) and its robot.

A world is a YAML file (``version: 1``) validated by the pydantic models below (unknown keys are
errors). Every failure becomes one :class:`~tagloc.errors.ConfigError` line naming the file and the
field path, e.g. ``world.yaml: tags[3].size: field required``. The built-in example,
``tagloc/sim/worlds/office.yaml`` (:func:`load_default_world`), documents every field in comments.

Frames: ``map`` (z up, floor at z = 0) and ``elevator_cab`` (origin at the centre of the cab floor,
z up, its pose in ``map`` given by ``elevator.pose_in_map``). A tag frame has its origin at the tag
centre, z out of the printed face towards a viewer, x to the viewer's right, y up (for a tag on a
wall); ``size`` is the black-border edge in metres.
"""

from __future__ import annotations

import os
from importlib import resources
from typing import Literal

import numpy as np
import yaml
from pydantic import Field, model_validator

from tagloc.config import (
    FieldPathError,
    StrictModel,
    parse_yaml_mapping,
    read_text_file,
    short_repr,
    validate,
)
from tagloc.errors import SimulationError
from tagloc.geometry import SE3
from tagloc.sim.building import cab_walls, check_building, check_legacy, implicit_floor
from tagloc.sim.floors import DEFAULT_CAB_FRAME, Floor, Shaft
from tagloc.sim.odometry import ODOMETRY_MODELS
from tagloc.sim.people import Person
from tagloc.sim.ride import plan_rides
from tagloc.sim.robot import Robot
from tagloc.sim.route import RouteConfig
from tagloc.sim.route_budget import check_route_budget
from tagloc.sim.trajectory import RoutePlan, plan_from_config
from tagloc.sim.world_parts import (
    TAG_FAMILY_SIZES,
    Checkpoint,
    Coordinate,
    Elevator,
    PlanarPose,
    Tag,
    TagFamily,
    TagPose,
    Vec2,
    Vec3,
    Wall,
    WallMount,
)

__all__ = [
    "BUILTIN_WORLDS", "TAG_FAMILY_SIZES", "Checkpoint", "Coordinate", "Elevator", "Floor",
    "PlanarPose", "Shaft", "Tag", "TagFamily", "TagPose", "Vec2", "Vec3", "Wall", "WallMount",
    "World", "load_builtin_world", "load_default_world", "load_world",
]  # fmt: skip


class World(StrictModel):
    """A simulated building and the robot that drives through it (see the module docstring)."""

    version: Literal[1]
    name: str = Field(default="", max_length=200)
    walls: tuple[Wall, ...] = ()
    tags: tuple[Tag, ...] = ()
    elevator: Elevator | None = None
    checkpoints: tuple[Checkpoint, ...] = ()
    #: Storeys (:mod:`tagloc.sim.floors`); none: the top-level walls, tags, checkpoints are one.
    floors: tuple[Floor, ...] = ()
    #: Elevator shafts whose cabs move between floors (:mod:`tagloc.sim.floors`).
    elevators: tuple[Shaft, ...] = ()
    route: RouteConfig
    robot: Robot
    #: People walking about (lidar occluders only; :mod:`tagloc.sim.people`).
    people: tuple[Person, ...] = ()

    @model_validator(mode="after")
    def _cross_references(self) -> World:
        if self.has_floors:
            check_building(self.all_floors(), self.elevators, self.tags, self.elevator)
            if self.walls or self.checkpoints:
                field = "walls" if self.walls else "checkpoints"
                raise FieldPathError((field,), "with floors, walls and checkpoints go in a floor")
        else:
            check_legacy(self.tags, self.checkpoints, self.elevator)
        names = self.checkpoints_xy()
        for j, wp in enumerate(self.route.waypoints):
            if isinstance(wp.at, str) and wp.at not in names:
                known = ", ".join(list(names)[:12]) + (", ..." if len(names) > 12 else "")
                raise FieldPathError(
                    ("route", "waypoints", j),
                    f"unknown checkpoint {short_repr(wp.at)} (known: {known or 'none'})",
                )
            if wp.ride is not None and not self.elevators:
                raise FieldPathError(
                    ("route", "waypoints", j, "ride"), "the world has no elevators to ride"
                )
        return self

    @model_validator(mode="after")
    def _drivable(self) -> World:
        """Every later command drives the route: refuse one that cannot be driven affordably."""
        robot = self.robot
        check_route_budget(
            self.route, self.checkpoints_xy(), robot.odom_rate_hz, robot.camera.rate_hz,
            plan=self.plan_route if self.has_floors else None,
        )  # fmt: skip
        return self

    @property
    def has_floors(self) -> bool:
        """Whether the world is a building of floors and shafts (``floors`` or ``elevators``)."""
        return bool(self.floors or self.elevators)

    def all_floors(self) -> tuple[Floor, ...]:
        """The floors; for a world file without ``floors``, one named ``"0"`` at z = 0 made of
        its top-level walls, map-frame tags and checkpoints."""
        if self.floors:
            return self.floors
        return (implicit_floor(self.walls, self.tags, self.checkpoints),)

    def floor_heights(self) -> dict[str, float]:
        """Floor name -> height of its floor in ``map``, m."""
        return {f.name: f.height_m for f in self.all_floors()}

    def shafts(self) -> tuple[Shaft, ...]:
        """The elevators; a single-floor world's ``elevator`` as a shaft named ``elevator``
        (frame ``elevator_cab``, serving floor ``"0"``, never moving)."""
        if self.elevators or self.elevator is None:
            return self.elevators
        fields = self.elevator.model_dump()
        return (Shaft(**fields, name="elevator", frame=DEFAULT_CAB_FRAME, floors=("0",)),)

    def plan_route(self) -> RoutePlan:
        """The planned route (:class:`~tagloc.sim.ride.RidePlan` for a world with floors)."""
        if not self.has_floors:
            return plan_from_config(self.route, self.checkpoints_xy())
        table = {
            cp.name: ((cp.x, cp.y), floor.name)
            for floor in self.all_floors()
            for cp in floor.checkpoints
        }
        return plan_rides(self.route, self.all_floors(), self.elevators, table)

    def checkpoints_xy(self) -> dict[str, Vec2]:
        """Checkpoint name -> ``(x, y)`` in ``map`` (of every floor)."""
        checkpoints = [cp for f in self.floors for cp in f.checkpoints] or self.checkpoints
        return {cp.name: (cp.x, cp.y) for cp in checkpoints}

    def all_tags(self) -> tuple[tuple[Tag, str | None], ...]:
        """Every tag with its floor's name (None for a cab's tag)."""
        if not self.floors:
            return tuple((t, "0" if t.frame == "map" else None) for t in self.tags)
        floor_tags = tuple((t, f.name) for f in self.floors for t in f.tags)
        return (*floor_tags, *((t, None) for t in self.tags))

    def find_tag(self, tag_id: int, family: str = "tag36h11") -> Tag:
        """The tag with this id and family. Raises ``SimulationError`` if there is none."""
        for tag, _ in self.all_tags():
            if tag.id == tag_id and tag.family == family:
                return tag
        raise SimulationError(f"world {self.name!r} has no tag {family}:{tag_id}")

    def shaft_of(self, frame: str) -> Shaft:
        """The shaft whose cab has ``frame``. Raises ``SimulationError``."""
        for shaft in self.shafts():
            if shaft.frame == frame:
                return shaft
        raise SimulationError(f"tag frame {frame} is no elevator cab's of world {self.name!r}")

    def T_map_tag(self, tag: Tag) -> SE3:
        """Pose of ``tag`` in ``map``: a floor's tag at its floor's height, a cab's tag with its
        cab standing at its first floor (``shaft.first_floor``)."""
        if not self.has_floors:
            if tag.frame == "map":
                return tag.T_frame_tag()
            if self.elevator is None:
                raise SimulationError(f"tag {tag.id} is in {tag.frame} but there is no elevator")
            return self.elevator.T_map_cab() @ tag.T_frame_tag()
        heights = self.floor_heights()
        if tag.frame == "map":
            floor = next((f for t, f in self.all_tags() if t is tag), None)
            z = heights.get(floor, 0.0) if floor is not None else 0.0
            T = tag.T_frame_tag()
            return SE3(rotation=T.rotation, translation=T.translation + np.array([0.0, 0.0, z]))
        shaft = self.shaft_of(tag.frame)
        return shaft.T_map_cab(heights.get(shaft.first_floor, 0.0)) @ tag.T_frame_tag()

    def walls_in_map(self, floor: str | None = None) -> tuple[Wall, ...]:
        """The walls of ``floor`` (default: the first) plus the cab's walls of every elevator
        standing there at the start (with its door open), all in ``map`` (heights above that
        floor). A single-floor world: the building's walls and the elevator cab's."""
        if not self.has_floors:
            if self.elevator is None:
                return self.walls
            return (*self.walls, *cab_walls(self.elevator, self.elevator.T_map_cab()))
        chosen = next((f for f in self.all_floors() if f.name == floor), self.all_floors()[0])
        cabs = [
            w for s in self.elevators if s.first_floor == chosen.name
            for w in cab_walls(s, s.T_map_cab())
        ]  # fmt: skip
        return (*chosen.walls, *cabs)

    @classmethod
    def from_yaml_text(cls, text: str, source: str = "<string>") -> World:
        """Parse and validate a world from YAML text; ``source`` names it in error messages.

        Raises
        ------
        ConfigError
            One line: ``source: field.path: problem`` (or ``source: line L, column C: ...``).
        """
        data = parse_yaml_mapping(text, source)
        return validate(cls, data, source, union_tags=ODOMETRY_MODELS)

    def to_yaml_text(self) -> str:
        """This world as YAML text (normalized: defaults filled in, waypoints as mappings)."""
        return yaml.safe_dump(self.model_dump(mode="json", exclude_none=True), sort_keys=False)


def load_world(path: str | os.PathLike[str]) -> World:
    """Read and validate a world file. Raises ``ConfigError`` (one line) on any problem."""
    text = read_text_file(path, "world file")
    return World.from_yaml_text(text, source=os.fspath(path))


def load_default_world() -> World:
    """The built-in office world, ``tagloc/sim/worlds/office.yaml``."""
    return load_builtin_world("office")


#: The built-in worlds (``tagloc/sim/worlds/<name>.yaml``); each file documents itself.
BUILTIN_WORLDS = (
    "office", "glass_corridor", "mirrored_lobby", "long_corridor", "sparse_building", "tower",
)  # fmt: skip


def load_builtin_world(name: str) -> World:
    """A built-in world by name (one of :data:`BUILTIN_WORLDS`).

    Raises
    ------
    SimulationError
        For an unknown name.
    """
    if name not in BUILTIN_WORLDS:
        raise SimulationError(
            f"no built-in world {short_repr(name)} (known: {', '.join(BUILTIN_WORLDS)})"
        )
    path = f"worlds/{name}.yaml"
    text = resources.files("tagloc.sim").joinpath(path).read_text(encoding="utf-8")
    return World.from_yaml_text(text, source=f"tagloc/sim/{path}")
