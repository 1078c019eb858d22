"""One entry of the tag map (:class:`TagEntry`): a tag's identity, printed size and pose, with
the checks of its fields (the file format is in :mod:`tagloc.tags.tagmap`)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pydantic
from pydantic import Field, field_validator

from tagloc.config import FieldPathError, StrictModel, check_unit_quat, short_repr
from tagloc.geometry import SE3
from tagloc.tags.families import FAMILIES
from tagloc.tags.tagmap_checks import (
    _FLOOR_NAME,
    _FRAME_NAME,
    DEFAULT_FAMILY,
    MAP_FRAME,
    MAX_COORD_M,
    MAX_TAG_SIZE_M,
    MIN_TAG_SIZE_M,
    Path_,
    Real,
    Row6,
    _canonical_sign,
    _covariance_problem,
    _validated,
)


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
