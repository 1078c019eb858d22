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
"""

from __future__ import annotations

import itertools
import json
import os
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Annotated, Any, TypeVar

import numpy as np
import numpy.typing as npt
import pydantic
import yaml
from pydantic import Field, field_validator

from tagloc.config import (
    FieldPathError,
    StrictModel,
    check_unit_quat,
    clip_message,
    one_line,
    parse_yaml_mapping,
    read_text_file,
    short_repr,
)
from tagloc.errors import ConfigError, TaglocError
from tagloc.fileutil import atomic_write_text
from tagloc.geometry import SE3
from tagloc.tags.families import FAMILIES

FORMAT_VERSION = 1
DEFAULT_FAMILY = "tag36h11"
MAP_FRAME = "map"
#: Sanity bounds: sizes in [1 mm, 5 m] catch millimetres typed as metres; coordinates +-100 km.
MIN_TAG_SIZE_M, MAX_TAG_SIZE_M, MAX_COORD_M = 1e-3, 5.0, 1e5
#: Largest covariance entry of a tag pose (m^2, rad^2): beyond it, products overflow downstream.
MAX_COVARIANCE = 1e4
_FRAME_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_./-]*")
_FLOOR_NAME = re.compile(r"[A-Za-z0-9_.+-]{1,64}")
_AXES = ("x", "y", "z", "rx", "ry", "rz")
_INFLATIONS = (0.0, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1)
ModelT = TypeVar("ModelT", bound=pydantic.BaseModel)
Path_ = tuple[str | int, ...]


class TagMapError(ConfigError):
    """A tag map that cannot be read or fails validation; the message names file, entry, field."""


class TagMapLookupError(TaglocError, LookupError):
    """A tag or frame that the map does not have."""


def _not_bool(value: object) -> object:
    if isinstance(value, bool):
        raise ValueError("must be a number, not true/false")
    return value


Real = Annotated[float, pydantic.BeforeValidator(_not_bool)]
Row6 = tuple[Real, Real, Real, Real, Real, Real]


class AnchorSigma(StrictModel):
    """Standard deviation of a surveyed anchor pose, per axis: metres and degrees."""

    position_m: Real = Field(gt=0.0, le=10.0)
    rotation_deg: Real = Field(gt=0.0, le=90.0)


class TagEntry(StrictModel):
    """One tag: identity, printed size, and its pose ``T_frame_tag`` in ``frame``.

    Fields are those of the file format (module docstring); ``quat_xyzw`` is stored with
    ``w >= 0``; ``covariance`` holds 6 rows over ``[x, y, z, rx, ry, rz]`` (m, rad). Direct
    construction raises pydantic's ``ValidationError`` (a ``ValueError``) on bad values;
    :meth:`from_pose` raises :class:`TagMapError`.
    """

    id: int = Field(strict=True)
    family: str = DEFAULT_FAMILY
    size: Real
    frame: str = MAP_FRAME
    #: The storey a ``map`` tag is on (a name of the map's ``floors`` table), or None.
    floor: str | None = None
    position: tuple[Real, Real, Real]
    quat_xyzw: tuple[Real, Real, Real, Real]
    anchor: bool = Field(default=False, strict=True)
    anchor_sigma: AnchorSigma | None = None
    observations: int | None = Field(default=None, strict=True)
    note: str = ""
    covariance: tuple[Row6, Row6, Row6, Row6, Row6, Row6] | None = None

    @field_validator("position", "quat_xyzw", mode="before")
    @classmethod
    def _length(cls, value: Any, info: pydantic.ValidationInfo) -> Any:
        names = "[x, y, z]" if info.field_name == "position" else "[x, y, z, w]"
        if isinstance(value, list | tuple) and len(value) != names.count(",") + 1:
            raise ValueError(f"must be {names.count(',') + 1} numbers {names}, got {len(value)}")
        return value

    @field_validator("quat_xyzw")
    @classmethod
    def _unit_quat(cls, value: tuple[float, float, float, float]) -> tuple[float, ...]:
        return _canonical_sign(check_unit_quat(value))

    @field_validator("covariance", mode="before")
    @classmethod
    def _six_rows(cls, value: Any) -> Any:
        value = value.tolist() if isinstance(value, np.ndarray) else value
        if not isinstance(value, list | tuple):
            return value  # None, or rejected by the field type
        if not any(isinstance(v, list | tuple) for v in value) and len(value) == 36:
            return [value[6 * i : 6 * i + 6] for i in range(6)]
        if len(value) != 6:
            raise ValueError(f"must be 6 rows of 6 numbers or 36 numbers, got {len(value)} items")
        for i, row in enumerate(value):
            if not isinstance(row, list | tuple) or len(row) != 6:
                raise FieldPathError((i,), f"must be a row of 6 numbers, got {short_repr(row)}")
        return value

    @pydantic.model_validator(mode="after")
    def _check(self) -> TagEntry:
        problem = _entry_problem(self)
        if problem is not None:
            raise FieldPathError(*problem)
        return self

    @property
    def key(self) -> tuple[str, int]:
        """``(family, id)``: unique within a map, and the map's sort order."""
        return (self.family, self.id)

    def T_frame_tag(self) -> SE3:
        """Pose of the tag in its ``frame`` (maps points from the tag frame into ``frame``)."""
        return SE3.from_quat(self.quat_xyzw, self.position)

    def covariance_matrix(self) -> npt.NDArray[np.float64] | None:
        """``(6, 6)`` covariance of ``T_frame_tag`` (right perturbation, ``[x..rz]``), or None."""
        return None if self.covariance is None else np.array(self.covariance, dtype=np.float64)

    @classmethod
    def from_pose(cls, tag_id: int, T_frame_tag: SE3, size: float, **fields: Any) -> TagEntry:
        """The entry of tag ``tag_id`` at ``T_frame_tag`` (one pose) with black-border ``size``.

        ``fields`` are the other fields by name (``family``, ``frame``, ``anchor``,
        ``observations``, ``note``, ``covariance`` as a ``(6, 6)`` array).

        Raises
        ------
        TagMapError
            One line naming the tag and field, e.g. ``tag 17: size: must be > 0``.
        """
        position = tuple(float(v) for v in T_frame_tag.translation)
        quat_xyzw = tuple(float(v) for v in T_frame_tag.as_quat())
        data = {"id": tag_id, "size": size, "position": position, "quat_xyzw": quat_xyzw, **fields}
        data = {k: int(v) if isinstance(v, np.integer) else v for k, v in data.items()}  # numpy ids
        return _validated(cls, data, f"tag {tag_id}")

    def with_pose(self, T_frame_tag: SE3, covariance: npt.ArrayLike | None = None) -> TagEntry:
        """This entry at a new pose with a new covariance (None: none), all else kept."""
        kept = self.model_dump(exclude={"id", "size", "position", "quat_xyzw", "covariance"})
        cov = None if covariance is None else np.asarray(covariance, dtype=np.float64)
        return TagEntry.from_pose(self.id, T_frame_tag, self.size, covariance=cov, **kept)


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


# ----- validation ------------------------------------------------------------------------------
def _validated(model: type[ModelT], data: dict[str, Any], source: str) -> ModelT:
    """``model.model_validate(data)``, failures as one line ``source: tags[4] (id 17): field``.

    Like :func:`tagloc.config.format_validation_error`, but the entry is named by index and id,
    and an unknown key is reported before the missing field it is probably a typo of.
    """
    try:
        return model.model_validate(data)
    except pydantic.ValidationError as exc:
        errors = exc.errors(include_url=False)
        first = next((e for e in errors if e["type"] == "extra_forbidden"), errors[0])
        loc, message = list(first["loc"]), first["msg"].removeprefix("Value error, ")
        if isinstance(error := first.get("ctx", {}).get("error"), FieldPathError):
            loc, message = loc + list(error.path), str(error)
        message = clip_message(message)
        parts = [source]
        if len(loc) > 1 and loc[0] == "tags" and isinstance(loc[1], int):
            tags = data.get("tags")
            item = tags[loc[1]] if isinstance(tags, list | tuple) else None
            tag_id = item.get("id") if isinstance(item, dict) else getattr(item, "id", None)
            parts.append(f"tags[{loc[1]}]" + (f" (id {tag_id})" if type(tag_id) is int else ""))
            loc = loc[2:]
        if loc:
            parts.append("".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc)[1:])
        n = len(errors) - 1
        more = f" (and {n} more error{'s' * (n > 1)})" if n else ""
        line = ": ".join([*parts, message[:1].lower() + message[1:]]) + more
        raise TagMapError(one_line(line)) from None


def _entry_problem(tag: TagEntry) -> tuple[Path_, str] | None:
    """``(field path, message)`` of the first thing wrong with ``tag`` (types already valid)."""
    num_ids = FAMILIES[tag.family].num_ids if tag.family in FAMILIES else 0
    if tag.id < 0 or (tag.observations or 0) < 0:
        return ("id" if tag.id < 0 else "observations",), "must be >= 0"
    if tag.family not in FAMILIES:
        return ("family",), f"unknown family {short_repr(tag.family)}; known: {', '.join(FAMILIES)}"
    if tag.id >= num_ids:
        return ("id",), f"{tag.id} is out of range for {tag.family} (0..{num_ids - 1})"
    if tag.size <= 0:
        return ("size",), "must be > 0"
    if tag.anchor_sigma is not None and not tag.anchor:
        return ("anchor_sigma",), "only an anchor (anchor: true) has an anchor_sigma"
    if not MIN_TAG_SIZE_M <= tag.size <= MAX_TAG_SIZE_M:
        bounds = f"[{MIN_TAG_SIZE_M:g}, {MAX_TAG_SIZE_M:g}]"
        return ("size",), f"{tag.size:g} is outside {bounds}: sizes are metres, not millimetres"
    if not _FRAME_NAME.fullmatch(tag.frame):
        return ("frame",), f"bad frame name {short_repr(tag.frame)} (letters, digits, _ . / -)"
    if tag.floor is not None and tag.frame != MAP_FRAME:
        return ("floor",), f"only a map tag is on a floor (this one is in {tag.frame})"
    if tag.floor is not None and not _FLOOR_NAME.fullmatch(tag.floor):
        return ("floor",), f"bad floor name {short_repr(tag.floor)} (letters, digits, _ . + -)"
    for k, coordinate in enumerate(tag.position):
        if abs(coordinate) > MAX_COORD_M:
            return ("position", k), f"{coordinate:g} m is beyond +-{MAX_COORD_M:g} m"
    if not tag.note.isprintable():
        return ("note",), "must be printable text on one line (no newlines, tabs)"
    problem = None if tag.covariance is None else _covariance_problem(np.array(tag.covariance))
    return None if problem is None else (("covariance", *problem[0]), problem[1])


def _covariance_problem(cov: npt.NDArray[np.float64]) -> tuple[Path_, str] | None:
    """``(path, message)`` if ``cov`` (6, 6) is not symmetric PSD, else None.

    PSD is tested on the correlation matrix (units cancel): its least eigenvalue >= -1e-9.
    """
    variances = np.diag(cov)
    if (big := float(np.abs(cov).max())) > MAX_COVARIANCE:
        row, col = divmod(int(np.argmax(np.abs(cov))), 6)
        return (row, col), f"{big:.3g} is beyond {MAX_COVARIANCE:g} (a 100 m or rad sigma)"
    for i, j in itertools.combinations_with_replacement(range(6), 2):
        a, b = cov[i, j], cov[j, i]
        if i == j and a < 0:
            return (i, i), f"variance of {_AXES[i]} must be >= 0, got {a:.3g}"
        if abs(a - b) > 1e-9 * max(abs(a), abs(b)):
            return (i, j), f"not symmetric: {a:.6g}, but covariance[{j}][{i}] = {b:.6g}"
        if i != j and a != 0 and variances[i] * variances[j] == 0:
            return (i, j), f"{_AXES[i]}-{_AXES[j]} covariance {a:.3g} with a zero variance"
    scale = np.sqrt(np.where(variances > 0, variances, 1.0))
    least = float(np.linalg.eigvalsh(cov / np.outer(scale, scale))[0])
    if least < -1e-9:
        return (), f"not positive semi-definite (correlation matrix eigenvalue {least:.3g})"
    return None


def _canonical_sign(q: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """``q`` or ``-q`` (the same rotation): ``w > 0``, or the first nonzero of x, y, z if w = 0."""
    sign = -1.0 if next((c for c in (q[3], *q[:3]) if c != 0.0), 0.0) < 0.0 else 1.0
    return (sign * q[0] + 0.0, sign * q[1] + 0.0, sign * q[2] + 0.0, sign * q[3] + 0.0)


# ----- writing ---------------------------------------------------------------------------------
_HEADER = (
    "# tagloc tag map. Check: `tagloc map check FILE`; compare two: `tagloc map diff A B`.",
    "# A tag's pose is T_frame_tag: the tag frame (origin at the tag centre, z out of the printed",
    "#   face towards a viewer, x to the viewer's right, y up) expressed in `frame`: `map`",
    "#   (static) or a moving frame listed in `frames` (e.g. elevator_cab).",
    "# size: black-border edge, metres. position: [x, y, z], metres (6 decimals = micrometres).",
    "# quat_xyzw: [x, y, z, w] (ROS/scipy order), unit norm within 1e-6, written with w >= 0.",
    "# covariance (optional): 6x6 rows of the right perturbation T_frame_tag (+) [x, y, z, rx,",
    "#   ry, rz] (metres, radians; translation first, as ROS PoseWithCovariance).",
    "# anchor: true = surveyed pose, a prior of the map builder; anchor_sigma: its standard",
    "#   deviation per axis {position_m, rotation_deg}. observations: builder count.",
    "# Tags are sorted by (family, id). Saving rewrites the file: comments are lost; use note.",
)


def _fixed(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _height(value: float) -> str:
    text = _fixed(value, 6).rstrip("0")
    return text + "0" if text.endswith(".") else text


def _sci(value: float) -> str:
    text = f"{value:.2e}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _plain(text: str) -> str:
    """``text`` as a YAML scalar: plain if it reads back as the same string, else quoted."""
    return text if yaml.safe_load(text) == text else json.dumps(text)


def _quat_for_file(quat_xyzw: tuple[float, float, float, float]) -> list[str]:
    """9 decimals of the quaternion, normalized if off by > 1e-8, sign chosen after rounding.

    Rounding can push a barely-unit quaternion past the tolerance; it is then normalized and
    rounded again (which stays within 1e-9), so the written values are a fixed point: loading
    and saving them again gives the same bytes.
    """

    def rounded(q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.array([float(_fixed(float(c), 9)) for c in q])

    q = np.array(quat_xyzw, dtype=float)
    if abs(np.linalg.norm(q) - 1.0) > 1e-8:
        q = q / np.linalg.norm(q)
    q = rounded(q)
    if abs(np.linalg.norm(q) - 1.0) > 1e-8:
        q = rounded(q / np.linalg.norm(q))
    x, y, z, w = (float(c) for c in q)
    return [_fixed(c, 9) for c in _canonical_sign((x, y, z, w))]


def _covariance_for_file(covariance: tuple[Row6, ...]) -> list[str]:
    """Rows of 3-significant-digit numbers that read back as a symmetric PSD matrix."""
    cov = np.array(covariance)
    cov = (cov + cov.T) / 2
    for inflation in _INFLATIONS:
        rows = [[_sci(float(v)) for v in row] for row in cov + inflation * np.diag(np.diag(cov))]
        if _covariance_problem(np.array(rows, dtype=float)) is None:
            return [f"      - [{', '.join(row)}]" for row in rows]
    raise AssertionError("unreachable: a PSD covariance stays PSD after inflating by 10 %")


def _entry_lines(tag: TagEntry) -> list[str]:
    size = _fixed(tag.size, 6).rstrip("0")
    lines = [
        f"  - id: {tag.id}",
        f"    family: {tag.family}",
        f"    size: {size}0" if size.endswith(".") else f"    size: {size}",
        f"    frame: {_plain(tag.frame)}",
        *([f"    floor: {json.dumps(tag.floor)}"] if tag.floor is not None else []),
        f"    position: [{', '.join(_fixed(v, 6) for v in tag.position)}]",
        f"    quat_xyzw: [{', '.join(_quat_for_file(tag.quat_xyzw))}]",
    ]
    if tag.anchor:
        lines.append("    anchor: true")
    if tag.anchor_sigma is not None:
        sigma = tag.anchor_sigma
        lines.append(
            f"    anchor_sigma: {{position_m: {sigma.position_m:.6g}, "
            f"rotation_deg: {sigma.rotation_deg:.6g}}}"
        )
    if tag.observations is not None:
        lines.append(f"    observations: {tag.observations}")
    if tag.note:
        lines.append(f"    note: {json.dumps(tag.note, ensure_ascii=False)}")
    if tag.covariance is not None:
        lines += ["    covariance:", *_covariance_for_file(tag.covariance)]
    return lines
