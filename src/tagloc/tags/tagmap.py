"""The tag map: every tag's id, family, printed size and pose, as a reviewable ``tags.yaml``.

A :class:`TagMap` holds :class:`TagEntry` items sorted by ``(family, id)``. An entry's pose is
``T_frame_tag``: the tag frame (origin at the tag centre, z out of the printed face towards a
viewer, x to the viewer's right, y up; ``size`` is the black-border edge in metres) expressed in
``frame``: ``map`` (static) or a *moving* frame declared in the map's ``frames`` list, such as
``elevator_cab`` (its own pose in ``map`` comes from elsewhere; an undeclared frame is an error).

File format (version 1): ``version: 1``, ``frames: [map, ...]`` and ``tags:``, one block per tag
with its keys in this order: ``id``, ``family`` (default tag36h11), ``size``, ``frame`` (default
map), ``position: [x, y, z]`` (m), ``quat_xyzw: [x, y, z, w]`` (unit within 1e-6, never
normalized on load), and optionally ``anchor: true`` (surveyed pose, a prior of the map
builder), ``anchor_sigma: {position_m, rotation_deg}`` (the survey's standard deviation per axis,
metres and degrees; only on anchors; without it the builder's default), ``observations``
(count from the builder), ``note`` (one line) and ``covariance`` (6x6 of the right
perturbation ``T_frame_tag (+) [x, y, z, rx, ry, rz]``, m and rad; 6 rows of 6 numbers, or 36
numbers; symmetric positive semi-definite; the builder writes each tag's marginal covariance, and
its note gives the sigmas in cm and degrees).

Saving is stable (same map, same bytes): positions and sizes with 6 decimals (micrometres),
quaternions with 9 (normalized, ``w >= 0``), covariances with 3 significant digits (symmetrized;
should rounding make a near-singular covariance indefinite, its diagonal is inflated by the
smallest of 0.1 % ... 10 % that keeps it PSD). So ``load(save(m))`` is ``m`` to that precision
and ``save(load(save(m))) == save(m)``. Saving rewrites the file; hand comments are not kept.

A loading failure is one :class:`TagMapError` line naming file, entry (index and id) and field:
``tags.yaml: tags[4] (id 17): size: must be > 0``.

The entry is :mod:`tagloc.tags.tag_entry`'s, the format's bounds and shared checks
:mod:`tagloc.tags.tagmap_checks`', the writing of the text :mod:`tagloc.tags.tagmap_text`'s.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import pydantic
from pydantic import Field, field_validator

from tagloc.config import FieldPathError, StrictModel, parse_yaml_mapping, read_text_file
from tagloc.errors import ConfigError
from tagloc.fileutil import atomic_write_text
from tagloc.geometry import SE3
from tagloc.tags.tag_entry import TagEntry
from tagloc.tags.tagmap_checks import (
    _FLOOR_NAME,
    _FRAME_NAME,
    DEFAULT_FAMILY,
    FORMAT_VERSION,
    MAP_FRAME,
    MAX_COORD_M,
    Real,
    TagMapError,
    TagMapLookupError,
    _validated,
)
from tagloc.tags.tagmap_text import _HEADER, _entry_lines, _height, _plain

__all__ = [
    "DEFAULT_FAMILY",
    "TagEntry",
    "TagMap",
    "TagMapError",
    "TagMapLookupError",
    "load_tag_map",
    "save_tag_map",
]


class _TagMapModel(StrictModel):
    """Checks across entries (declared frames, unique ``(family, id)``); sorts frames and tags."""

    version: int | None = Field(default=None, strict=True)
    frames: tuple[str, ...] = (MAP_FRAME,)
    floors: dict[str, Real] | None = None
    tags: tuple[TagEntry, ...] = ()

    @field_validator("floors")
    @classmethod
    def _floors(cls, value: dict[str, float] | None) -> dict[str, float] | None:
        for name, height in (value or {}).items():
            if not _FLOOR_NAME.fullmatch(name):
                raise FieldPathError((name,), "bad floor name (letters, digits, _ . + -)")
            if not abs(height) <= MAX_COORD_M:
                raise FieldPathError((name,), f"{height:g} m is beyond +-{MAX_COORD_M:g} m")
        return value

    @field_validator("version")
    @classmethod
    def _version(cls, value: int | None) -> int | None:
        if value not in (None, FORMAT_VERSION):
            raise ValueError(f"unsupported version {value} (this tagloc reads {FORMAT_VERSION})")
        return value

    @field_validator("frames")
    @classmethod
    def _frames(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        for k, name in enumerate(value):
            if not _FRAME_NAME.fullmatch(name):
                raise FieldPathError((k,), f"bad frame name {name!r} (letters, digits, _ . / -)")
            if name in value[:k]:
                raise FieldPathError((k,), f"duplicate frame {name!r}")
        return (MAP_FRAME, *sorted(set(value) - {MAP_FRAME}))

    @field_validator("tags")
    @classmethod
    def _tags(
        cls, value: tuple[TagEntry, ...], info: pydantic.ValidationInfo
    ) -> tuple[TagEntry, ...]:
        frames, first = info.data.get("frames"), dict[tuple[str, int], int]()
        for k, tag in enumerate(value):
            if tag.key in first:
                where = f"also tags[{first[tag.key]}]"
                raise FieldPathError((k, "id"), f"duplicate {tag.family} id {tag.id} ({where})")
            first[tag.key] = k
            if frames is not None and tag.frame not in frames:
                raise FieldPathError(
                    (k, "frame"),
                    f"unknown frame {tag.frame!r}; declared: {', '.join(frames)} "
                    "(list moving frames in the top-level 'frames')",
                )
            floors = info.data.get("floors")
            if tag.floor is not None and tag.floor not in (floors or {}):
                known = ", ".join(floors or {}) or "none: add a top-level 'floors' table"
                raise FieldPathError((k, "floor"), f"unknown floor {tag.floor!r} (floors: {known})")
        return tuple(sorted(value, key=lambda tag: tag.key))


class _TagMapFile(_TagMapModel):
    version: int = Field(strict=True)  # required in files


@dataclass(frozen=True, slots=True)
class TagMap:
    """The tag map: the allowed ``frames`` (``map`` first) and ``tags`` sorted by (family, id).

    Constructing one validates it (:class:`TagMapError`) and sorts frames and tags. Iterating
    yields the entries; lookups take ``(tag_id, family)``, the family defaulting to tag36h11.
    """

    frames: tuple[str, ...] = (MAP_FRAME,)
    tags: tuple[TagEntry, ...] = ()
    #: Floor name -> height of that floor in ``map`` (m), for a building of several; or None.
    floors: dict[str, float] | None = None
    _index: dict[tuple[str, int], TagEntry] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        data = {"frames": self.frames, "tags": self.tags, "floors": self.floors}
        model = _validated(_TagMapModel, data, "tag map")
        object.__setattr__(self, "frames", model.frames)
        object.__setattr__(self, "tags", model.tags)
        object.__setattr__(self, "floors", model.floors)
        object.__setattr__(self, "_index", {tag.key: tag for tag in model.tags})

    @classmethod
    def from_entries(
        cls,
        entries: Iterable[TagEntry],
        frames: Iterable[str] | None = None,
        floors: dict[str, float] | None = None,
    ) -> TagMap:
        """A map of ``entries``; ``frames`` defaults to ``map`` plus every frame they use."""
        tags = tuple(entries)
        frame_names = {MAP_FRAME, *(t.frame for t in tags)} if frames is None else frames
        return cls(frames=tuple(frame_names), tags=tags, floors=floors)

    def __iter__(self) -> Iterator[TagEntry]:
        return iter(self.tags)

    def __len__(self) -> int:
        return len(self.tags)

    def get(self, tag_id: int, family: str = DEFAULT_FAMILY) -> TagEntry | None:
        """The entry of tag ``tag_id`` of ``family``, or None if the map has no such tag."""
        return self._index.get((family, tag_id))

    def T_frame_tag(self, tag_id: int, family: str = DEFAULT_FAMILY) -> SE3:
        """Pose of the tag in its entry's ``frame``. Raises :class:`TagMapLookupError`."""
        entry = self.get(tag_id, family)
        if entry is None:
            raise TagMapLookupError(f"the tag map has no {family} tag with id {tag_id}")
        return entry.T_frame_tag()

    def ids(self, family: str = DEFAULT_FAMILY) -> tuple[int, ...]:
        """Sorted ids of the tags of ``family``."""
        return tuple(tag.id for tag in self.tags if tag.family == family)

    def sizes(self, family: str = DEFAULT_FAMILY) -> dict[int, float]:
        """Tag id -> black-border edge (m), for the tags of ``family``."""
        return {tag.id: tag.size for tag in self.tags if tag.family == family}

    @property
    def families(self) -> tuple[str, ...]:
        """The families present, sorted."""
        return tuple(sorted({tag.family for tag in self.tags}))

    @property
    def anchors(self) -> tuple[TagEntry, ...]:
        """The entries marked ``anchor: true`` (surveyed poses)."""
        return tuple(tag for tag in self.tags if tag.anchor)

    def in_frame(self, frame: str) -> tuple[TagEntry, ...]:
        """The entries whose pose is in ``frame``. Raises :class:`TagMapLookupError` if unknown."""
        if frame not in self.frames:
            known = ", ".join(self.frames)
            raise TagMapLookupError(f"the tag map has no frame {frame!r} (frames: {known})")
        return tuple(tag for tag in self.tags if tag.frame == frame)

    def summary(self) -> str:
        """One line: ``30 tags (tag36h11: 30); frames: map (26), elevator_cab (4); anchors: 3``."""
        families = ", ".join(f"{f}: {len(self.ids(f))}" for f in self.families) or "none"
        frames = ", ".join(f"{f} ({len(self.in_frame(f))})" for f in self.frames)
        return f"{len(self)} tags ({families}); frames: {frames}; anchors: {len(self.anchors)}"

    @classmethod
    def from_yaml_text(cls, text: str, source: str = "<string>") -> TagMap:
        """Parse and validate ``tags.yaml`` text; ``source`` names it in error messages.

        Raises
        ------
        TagMapError
            One line, ``source: tags[4] (id 17): size: must be > 0``, or a YAML error.
        """
        try:
            data = parse_yaml_mapping(text, source)
        except ConfigError as exc:
            raise TagMapError(str(exc)) from None
        model = _validated(_TagMapFile, data, source)
        return cls(frames=model.frames, tags=model.tags, floors=model.floors)

    def to_yaml_text(self) -> str:
        """The map as ``tags.yaml`` text: header comment, fixed layout, stable bytes."""
        lines = [*_HEADER, f"version: {FORMAT_VERSION}"]
        lines.append(f"frames: [{', '.join(_plain(f) for f in self.frames)}]")
        if self.floors is not None:
            lines.append("# floors: floor name -> height of its floor in map (m); a tag's floor.")
            table = ", ".join(f"{json.dumps(k)}: {_height(v)}" for k, v in self.floors.items())
            lines.append(f"floors: {{{table}}}")
        lines.append("tags:" if self.tags else "tags: []")
        for tag in self.tags:
            lines += ["", *_entry_lines(tag)]
        return "\n".join(lines) + "\n"


def load_tag_map(path: str | os.PathLike[str]) -> TagMap:
    """Read and validate a tag map file. Raises :class:`TagMapError` (one line)."""
    text = read_text_file(path, "tag map", error=TagMapError)
    return TagMap.from_yaml_text(text, source=os.fspath(path))


def save_tag_map(tag_map: TagMap, path: str | os.PathLike[str]) -> None:
    """Write ``tag_map`` to ``path`` atomically (a temporary file, then a rename)."""
    atomic_write_text(path, tag_map.to_yaml_text())
