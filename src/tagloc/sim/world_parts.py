"""The parts of a world file: walls, tags and their mounts, the elevator cab, checkpoints.

See :mod:`tagloc.sim.world` for the file and its frames; these models are re-exported there.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from tagloc.config import FieldPathError, StrictModel, check_unit_quat
from tagloc.geometry import SE3, SO3
from tagloc.sim.route import MAX_COORDINATE_M

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


#: A frame name: ``map`` or an elevator cab's frame (letters, digits, ``_ . / -``).
FrameName = Annotated[
    str, Field(min_length=1, max_length=200, pattern=r"^[A-Za-z_][A-Za-z0-9_./-]*$")
]


class Tag(StrictModel):
    """One tag: exactly one of ``pose`` or ``wall``, in ``frame`` (``map`` or a cab's frame,
    ``elevator_cab`` by default; :mod:`tagloc.sim.floors`)."""

    id: int = Field(ge=0)
    family: TagFamily = "tag36h11"
    size: float = Field(gt=0.0, le=5.0)
    pose: TagPose | None = None
    wall: WallMount | None = None
    frame: FrameName = "map"
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
        """Pose of the tag in its own ``frame`` (``map``, or its cab's frame; on a floor of a
        multi-floor world, z is above that floor: see ``World.T_map_tag``).

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

    def door_cab(self) -> tuple[Vec2, Vec2]:
        """The door opening's segment in ``elevator_cab`` (where the closed door stands)."""
        hx, hy, hd = self.footprint[0] / 2, self.footprint[1] / 2, self.door_width / 2
        return {
            "+x": ((hx, -hd), (hx, hd)),
            "-x": ((-hx, hd), (-hx, -hd)),
            "+y": ((hd, hy), (-hd, hy)),
            "-y": ((-hd, -hy), (hd, -hy)),
        }[self.door_side]

    def door_normal_cab(self) -> Vec2:
        """Unit vector out of the door, in ``elevator_cab``."""
        return {"+x": (1.0, 0.0), "-x": (-1.0, 0.0), "+y": (0.0, 1.0), "-y": (0.0, -1.0)}[
            self.door_side
        ]


class Checkpoint(StrictModel):
    """A named floor position (m) in ``map``."""

    name: str = Field(min_length=1, max_length=200, pattern=r"^[A-Za-z0-9_.-]+$")
    x: Coordinate
    y: Coordinate
    note: str | None = None
