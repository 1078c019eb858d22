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

import math
import os
from importlib import resources
from typing import Annotated, Literal

import numpy as np
import yaml
from pydantic import Field, field_validator, model_validator

from tagloc.config import (
    FieldPathError,
    StrictModel,
    check_unit_quat,
    parse_yaml_mapping,
    read_text_file,
    short_repr,
    validate,
)
from tagloc.errors import SimulationError
from tagloc.geometry import SE3, SO3
from tagloc.sim.odometry import ODOMETRY_MODELS
from tagloc.sim.people import Person
from tagloc.sim.robot import Robot
from tagloc.sim.route import MAX_COORDINATE_M, RouteConfig
from tagloc.sim.route_budget import check_route_budget

#: A coordinate in ``map`` or ``elevator_cab``, metres (a building, not a planet).
Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M)]
Vec2 = tuple[Coordinate, Coordinate]
Vec3 = tuple[Coordinate, Coordinate, Coordinate]
#: Codes per AprilTag family: valid ids are ``0 .. n - 1``.
TAG_FAMILY_SIZES = {
    "tag36h11": 587,
    "tag25h9": 35,
    "tag16h5": 30,
    "tagCircle21h7": 38,
    "tagCircle49h12": 65535,
    "tagStandard41h12": 2115,
    "tagStandard52h13": 48714,
    "tagCustom48h12": 42211,
}
TagFamily = Literal[
    "tag36h11",
    "tag25h9",
    "tag16h5",
    "tagCircle21h7",
    "tagCircle49h12",
    "tagStandard41h12",
    "tagStandard52h13",
    "tagCustom48h12",
]


def _yaw_matrix(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class Wall(StrictModel):
    """A vertical wall: the segment ``start -> end`` on the floor (m), ``height`` (m)."""

    start: Vec2
    end: Vec2
    material: Literal["wall", "glass", "mirror"] = "wall"
    height: float = Field(default=2.5, gt=0.0, le=20.0)

    @model_validator(mode="after")
    def _not_degenerate(self) -> Wall:
        if math.dist(self.start, self.end) < 1e-6:
            raise FieldPathError(("end",), "wall has zero length (end == start)")
        return self


class TagPose(StrictModel):
    """Full pose of a tag in its frame: ``position`` (m) and unit ``quat_xyzw``."""

    position: Vec3
    quat_xyzw: tuple[float, float, float, float]

    @field_validator("quat_xyzw")
    @classmethod
    def _check_quat(
        cls, value: tuple[float, float, float, float]
    ) -> tuple[float, float, float, float]:
        return check_unit_quat(value)


class WallMount(StrictModel):
    """Upright tag on a wall: centre ``(x, y, height)``, horizontal face normal at ``yaw_deg``."""

    x: Coordinate
    y: Coordinate
    yaw_deg: float = Field(ge=-360.0, le=360.0)
    height: float = Field(gt=0.0, le=20.0)


class Tag(StrictModel):
    """One tag: exactly one of ``pose`` or ``wall``, in ``frame`` (``map`` or ``elevator_cab``)."""

    id: int = Field(ge=0)
    family: TagFamily = "tag36h11"
    size: float = Field(gt=0.0, le=5.0)
    pose: TagPose | None = None
    wall: WallMount | None = None
    frame: Literal["map", "elevator_cab"] = "map"
    note: str | None = None

    @model_validator(mode="after")
    def _check(self) -> Tag:
        if (self.pose is None) == (self.wall is None):
            raise ValueError("give exactly one of 'pose' or 'wall'")
        if self.id >= TAG_FAMILY_SIZES[self.family]:
            raise FieldPathError(
                ("id",),
                f"id {self.id} is out of range for {self.family} "
                f"(0..{TAG_FAMILY_SIZES[self.family] - 1})",
            )
        return self

    def T_frame_tag(self) -> SE3:
        """Pose of the tag in its own ``frame`` (``map`` or ``elevator_cab``).

        For ``wall: {x, y, yaw_deg, height}`` the tag axes in the frame are
        ``z = (cos yaw, sin yaw, 0)`` (face normal), ``y = (0, 0, 1)`` (up),
        ``x = y cross z = (-sin yaw, cos yaw, 0)`` (right as seen by a viewer facing the tag).
        """
        if self.pose is not None:
            return SE3.from_quat(self.pose.quat_xyzw, self.pose.position)
        assert self.wall is not None
        c, s = math.cos(math.radians(self.wall.yaw_deg)), math.sin(math.radians(self.wall.yaw_deg))
        R_frame_tag = np.array([[-s, 0.0, c], [c, 0.0, s], [0.0, 1.0, 0.0]])
        return SE3(
            rotation=SO3.from_matrix(R_frame_tag),
            translation=np.array([self.wall.x, self.wall.y, self.wall.height]),
        )


class PlanarPose(StrictModel):
    """``x``, ``y`` (m) and ``yaw_deg`` of a frame in ``map`` (z = 0, level)."""

    x: Coordinate
    y: Coordinate
    yaw_deg: float = Field(default=0.0, ge=-360.0, le=360.0)


class Elevator(StrictModel):
    """The elevator cab: a rectangular room with its own frame ``elevator_cab``.

    ``footprint`` is ``[size_x, size_y]`` (m), centred on the cab frame origin; the door is an
    opening of ``door_width`` centred on the side ``door_side`` of the rectangle.
    """

    pose_in_map: PlanarPose
    footprint: tuple[float, float]
    door_side: Literal["+x", "-x", "+y", "-y"] = "+x"
    door_width: float = Field(default=1.0, gt=0.0)
    height: float = Field(default=2.3, gt=0.0, le=20.0)
    wall_material: Literal["wall", "glass", "mirror"] = "wall"

    @model_validator(mode="after")
    def _check(self) -> Elevator:
        if min(self.footprint) <= 0 or max(self.footprint) > 100.0:
            raise FieldPathError(("footprint",), "sizes must be > 0 and <= 100 m")
        along = self.footprint[1] if self.door_side[1] == "x" else self.footprint[0]
        if self.door_width >= along:
            raise FieldPathError(
                ("door_width",),
                f"{self.door_width} m does not fit the {along} m side {self.door_side}",
            )
        return self

    def T_map_cab(self) -> SE3:
        """Pose of the ``elevator_cab`` frame in ``map``."""
        return SE3(
            rotation=SO3.from_matrix(_yaw_matrix(math.radians(self.pose_in_map.yaw_deg))),
            translation=np.array([self.pose_in_map.x, self.pose_in_map.y, 0.0]),
        )

    def walls_cab(self) -> list[tuple[Vec2, Vec2]]:
        """The cab's wall segments in ``elevator_cab`` (the door side split around the door)."""
        hx, hy, hd = self.footprint[0] / 2, self.footprint[1] / 2, self.door_width / 2
        sides = {
            "+x": ((hx, -hy), (hx, hy)),
            "-x": ((-hx, hy), (-hx, -hy)),
            "+y": ((hx, hy), (-hx, hy)),
            "-y": ((-hx, -hy), (hx, -hy)),
        }
        segments: list[tuple[Vec2, Vec2]] = []
        for side, (a, b) in sides.items():
            if side != self.door_side:
                segments.append((a, b))
                continue
            mid = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
            u = ((b[0] - a[0]) / math.dist(a, b), (b[1] - a[1]) / math.dist(a, b))
            segments.append((a, (mid[0] - hd * u[0], mid[1] - hd * u[1])))
            segments.append(((mid[0] + hd * u[0], mid[1] + hd * u[1]), b))
        return segments


class Checkpoint(StrictModel):
    """A named floor position (m) in ``map``."""

    name: str = Field(min_length=1, max_length=200, pattern=r"^[A-Za-z0-9_.-]+$")
    x: Coordinate
    y: Coordinate
    note: str | None = None


class World(StrictModel):
    """A simulated building and the robot that drives through it (see the module docstring)."""

    version: Literal[1]
    name: str = Field(default="", max_length=200)
    walls: tuple[Wall, ...] = ()
    tags: tuple[Tag, ...] = ()
    elevator: Elevator | None = None
    checkpoints: tuple[Checkpoint, ...] = ()
    route: RouteConfig
    robot: Robot
    #: People walking about (lidar occluders only; :mod:`tagloc.sim.people`).
    people: tuple[Person, ...] = ()

    @model_validator(mode="after")
    def _cross_references(self) -> World:
        seen: dict[tuple[str, int], int] = {}
        for j, tag in enumerate(self.tags):
            if (tag.family, tag.id) in seen:
                raise FieldPathError(
                    ("tags", j, "id"),
                    f"duplicate tag id {tag.id} (also tags[{seen[tag.family, tag.id]}])",
                )
            seen[tag.family, tag.id] = j
            if tag.frame == "elevator_cab":
                if self.elevator is None:
                    raise FieldPathError(
                        ("tags", j, "frame"),
                        "tag is in frame elevator_cab but the world has no elevator",
                    )
                xyz = tag.T_frame_tag().translation
                if np.any(np.abs(xyz[:2]) > np.array(self.elevator.footprint) / 2 + 0.05):
                    raise FieldPathError(("tags", j), "tag lies outside the elevator cab footprint")
        names: dict[str, int] = {}
        for j, cp in enumerate(self.checkpoints):
            if cp.name in names:
                raise FieldPathError(
                    ("checkpoints", j, "name"),
                    f"duplicate checkpoint {cp.name!r} (also checkpoints[{names[cp.name]}])",
                )
            names[cp.name] = j
        for j, wp in enumerate(self.route.waypoints):
            if isinstance(wp.at, str) and wp.at not in names:
                known = ", ".join(list(names)[:12]) + (", ..." if len(names) > 12 else "")
                raise FieldPathError(
                    ("route", "waypoints", j),
                    f"unknown checkpoint {short_repr(wp.at)} (known: {known or 'none'})",
                )
        return self

    @model_validator(mode="after")
    def _drivable(self) -> World:
        """Every later command drives the route: refuse one that cannot be driven affordably."""
        robot = self.robot
        check_route_budget(
            self.route, self.checkpoints_xy(), robot.odom_rate_hz, robot.camera.rate_hz
        )
        return self

    def checkpoints_xy(self) -> dict[str, Vec2]:
        """Checkpoint name -> ``(x, y)`` in ``map``."""
        return {cp.name: (cp.x, cp.y) for cp in self.checkpoints}

    def find_tag(self, tag_id: int, family: str = "tag36h11") -> Tag:
        """The tag with this id and family. Raises ``SimulationError`` if there is none."""
        for tag in self.tags:
            if tag.id == tag_id and tag.family == family:
                return tag
        raise SimulationError(f"world {self.name!r} has no tag {family}:{tag_id}")

    def T_map_tag(self, tag: Tag) -> SE3:
        """Pose of ``tag`` in ``map`` (cab tags go through ``elevator.T_map_cab()``)."""
        if tag.frame == "map":
            return tag.T_frame_tag()
        if self.elevator is None:
            raise SimulationError(f"tag {tag.id} is in elevator_cab but the world has no elevator")
        return self.elevator.T_map_cab() @ tag.T_frame_tag()

    def walls_in_map(self) -> tuple[Wall, ...]:
        """The building's walls plus the elevator cab's walls, all in ``map``."""
        if self.elevator is None:
            return self.walls
        T_map_cab = self.elevator.T_map_cab()
        cab = [
            Wall(
                start=tuple(T_map_cab.act([*a, 0.0])[:2]),
                end=tuple(T_map_cab.act([*b, 0.0])[:2]),
                material=self.elevator.wall_material,
                height=self.elevator.height,
            )
            for a, b in self.elevator.walls_cab()
        ]
        return (*self.walls, *cab)

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
    "office", "glass_corridor", "mirrored_lobby", "long_corridor", "sparse_building",
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
