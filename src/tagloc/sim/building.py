"""How a world's floors, shafts and tags refer to each other (the checks behind ``World``).

Every failure is a :class:`~tagloc.config.FieldPathError` naming the field, so a world file's
error reads ``world.yaml: elevators[0].floors[2]: unknown floor '3' (floors: 0, 1, 2)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tagloc.config import FieldPathError
from tagloc.geometry import SE3
from tagloc.sim.floors import DEFAULT_CAB_FRAME, IMPLICIT_FLOOR, Floor, Shaft
from tagloc.sim.world_parts import Checkpoint, Elevator, Tag, Wall

__all__ = ["cab_walls", "check_building", "check_legacy", "implicit_floor"]

#: A cab tag may stand this far outside its footprint (m): on the outside of a wall.
_CAB_MARGIN_M = 0.05
#: Floors closer than this (m) are one floor.
_MIN_FLOOR_GAP_M = 0.5


def implicit_floor(
    walls: Sequence[Wall], tags: Sequence[Tag], checkpoints: Sequence[Checkpoint]
) -> Floor:
    """The one floor of a world file without ``floors``."""
    return Floor(
        name=IMPLICIT_FLOOR,
        height_m=0.0,
        walls=tuple(walls),
        tags=tuple(t for t in tags if t.frame == "map"),
        checkpoints=tuple(checkpoints),
    )


def cab_walls(cab: Elevator, T_map_cab: SE3, door_closed: bool = False) -> list[Wall]:
    """The cab's walls in ``map`` (planar), with the closed door across its opening."""
    segments = cab.walls_cab() + ([cab.door_cab()] if door_closed else [])
    return [
        Wall(
            start=tuple(T_map_cab.act([*a, 0.0])[:2]),
            end=tuple(T_map_cab.act([*b, 0.0])[:2]),
            material=cab.wall_material,
            height=cab.height,
        )
        for a, b in segments
    ]


def _where(prefix: tuple[str | int, ...], j: int) -> str:
    """``("floors", 0, "tags"), 3`` -> ``floors[0].tags[3]``."""
    text = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in (*prefix, j))
    return text[1:]


def _unique_tags(groups: Sequence[tuple[tuple[str | int, ...], Sequence[Tag]]]) -> None:
    seen: dict[tuple[str, int], str] = {}
    for prefix, tags in groups:
        for j, tag in enumerate(tags):
            where = _where(prefix, j)
            if (tag.family, tag.id) in seen:
                raise FieldPathError(
                    (*prefix, j, "id"),
                    f"duplicate tag id {tag.id} (also {seen[tag.family, tag.id]})",
                )
            seen[tag.family, tag.id] = where


def _cab_tag(j: int, tag: Tag, cab: Elevator | None, frame: str) -> None:
    if cab is None:
        raise FieldPathError(
            ("tags", j, "frame"), f"tag is in frame {frame} but the world has no elevator"
        )
    xyz = tag.T_frame_tag().translation
    if np.any(np.abs(xyz[:2]) > np.array(cab.footprint) / 2 + _CAB_MARGIN_M):
        raise FieldPathError(("tags", j), "tag lies outside the elevator cab footprint")
    if not 0.0 <= xyz[2] <= cab.height:
        raise FieldPathError(("tags", j), f"tag is below or above the {frame} cab")


def check_legacy(
    tags: Sequence[Tag], checkpoints: Sequence[Checkpoint], elevator: Elevator | None
) -> None:
    """A single-floor world: unique tags and checkpoints, cab tags in the cab."""
    _unique_tags([(("tags",), tags)])
    for j, tag in enumerate(tags):
        if tag.frame != "map":
            if tag.frame != DEFAULT_CAB_FRAME:
                raise FieldPathError(
                    ("tags", j, "frame"),
                    f"unknown frame {tag.frame!r} (map, or {DEFAULT_CAB_FRAME} with an elevator)",
                )
            _cab_tag(j, tag, elevator, tag.frame)
    _unique_checkpoints([(("checkpoints",), checkpoints)])


def _unique_checkpoints(
    groups: Sequence[tuple[tuple[str | int, ...], Sequence[Checkpoint]]],
) -> None:
    names: dict[str, str] = {}
    for prefix, checkpoints in groups:
        for j, cp in enumerate(checkpoints):
            if cp.name in names:
                raise FieldPathError(
                    (*prefix, j, "name"),
                    f"duplicate checkpoint {cp.name!r} (also {names[cp.name]})",
                )
            names[cp.name] = _where(prefix, j)


def check_building(
    floors: Sequence[Floor],
    shafts: Sequence[Shaft],
    cab_tags: Sequence[Tag],
    elevator: Elevator | None,
) -> None:
    """A world with floors and shafts (see the module docstring)."""
    if elevator is not None:
        raise FieldPathError(("elevator",), "with floors or elevators, list the cab in elevators")
    heights: dict[str, tuple[int, float]] = {}
    for k, floor in enumerate(floors):
        if floor.name in heights:
            raise FieldPathError(("floors", k, "name"), f"floor {floor.name!r} is listed twice")
        for other, (i, h) in heights.items():
            if abs(h - floor.height_m) < _MIN_FLOOR_GAP_M:
                raise FieldPathError(
                    ("floors", k, "height_m"),
                    f"{floor.height_m} m is within {_MIN_FLOOR_GAP_M} m of floor {other} "
                    f"(floors[{i}])",
                )
        heights[floor.name] = (k, floor.height_m)
    frames: dict[str, Shaft] = {}
    names: set[str] = set()
    for i, shaft in enumerate(shafts):
        if shaft.name in names:
            raise FieldPathError(("elevators", i, "name"), f"elevator {shaft.name!r} twice")
        names.add(shaft.name)
        if shaft.frame in frames:
            raise FieldPathError(
                ("elevators", i, "frame"), f"frame {shaft.frame!r} is another cab's: one per cab"
            )
        frames[shaft.frame] = shaft
        for k, name in enumerate(shaft.floors):
            if name not in heights:
                raise FieldPathError(
                    ("elevators", i, "floors", k),
                    f"unknown floor {name!r} (floors: {', '.join(heights)})",
                )
        if len(shaft.floors) < 2:
            raise FieldPathError(("elevators", i, "floors"), "a shaft serves at least two floors")
    for j, tag in enumerate(cab_tags):
        if tag.frame == "map":
            raise FieldPathError(("tags", j, "frame"), "with floors, map tags go in a floor's tags")
        _cab_tag(j, tag, frames.get(tag.frame), tag.frame)
    _unique_tags([*((("floors", k, "tags"), f.tags) for k, f in enumerate(floors)),
                  (("tags",), cab_tags)])  # fmt: skip
    _unique_checkpoints([(("floors", k, "checkpoints"), f.checkpoints)
                         for k, f in enumerate(floors)])  # fmt: skip
