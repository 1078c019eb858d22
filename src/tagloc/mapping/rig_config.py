"""The small parsers of a tagSLAM-style rig description: ``camera_poses.yaml``, ``tagslam.yaml``.

They take *text* (the CLI reads the files), like :meth:`TagMap.from_yaml_text`, and refuse with
one :class:`~tagloc.mapping.survey.MappingError` line naming the field.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from pydantic import ConfigDict

from tagloc.config import StrictModel, clip_message, parse_yaml_mapping
from tagloc.errors import TaglocError
from tagloc.geometry import SE3
from tagloc.mapping.survey import MappingError

__all__ = ["RigConfig", "TagRemap", "parse_camera_poses", "parse_tagslam"]


@dataclass(frozen=True, slots=True)
class TagRemap:
    """Detections of ``tag_id`` stamped in ``[start_ns, end_ns]`` are of another physical tag
    with the same printed id: they are mapped as ``remap_id`` (tagSLAM's ``tag_id_remap``)."""

    tag_id: int
    remap_id: int
    start_ns: int
    end_ns: int


class RigConfig(StrictModel):
    """What a tagSLAM configuration says about the rig and the map (finite values only)."""

    model_config = ConfigDict(arbitrary_types_allowed=True)

    anchors: dict[int, SE3]
    T_body_odom: SE3 | None
    ignore_tags: frozenset[int]
    default_tag_size: float | None
    tag_sizes: dict[int, float]
    tag_remaps: tuple[TagRemap, ...] = ()


def _pose(node: object, where: str) -> SE3:
    try:
        assert isinstance(node, Mapping)
        p, r = node["position"], node["rotation"]
        return SE3.from_rotvec(
            [float(r["x"]), float(r["y"]), float(r["z"])],
            [float(p["x"]), float(p["y"]), float(p["z"])],
        )
    except (AssertionError, KeyError, TypeError, ValueError) as exc:
        raise MappingError(
            f"{where}: expected position {{x, y, z}} and rotation {{x, y, z}} (rotation vector, "
            f"rad) ({type(exc).__name__}: {clip_message(str(exc))})"
        ) from None


def parse_camera_poses(text: str, source: str) -> dict[str, SE3]:
    """``camera_poses.yaml`` (``camN: {pose: {position, rotation}}``) -> ``T_body_camN``."""
    data = parse_yaml_mapping(text, source)
    return {
        str(name): _pose(
            entry.get("pose") if isinstance(entry, Mapping) else None, f"{source}: {name}.pose"
        )
        for name, entry in data.items()
    }


def parse_tagslam(text: str, source: str) -> RigConfig:
    """Anchors (tags with a ``pose``), ``T_body_odom``, ignored ids and sizes of a tagslam.yaml.

    Raises
    ------
    ConfigError
        The text is not a YAML mapping (see :func:`tagloc.config.parse_yaml_mapping`).
    MappingError
        One line naming the body or tag whose layout or values are wrong (a size that is not a
        positive number of metres included).
    """
    data = parse_yaml_mapping(text, source)
    anchors: dict[int, SE3] = {}
    sizes: dict[int, float] = {}
    ignore: set[int] = set()
    T_body_odom, default_size = None, None
    where = f"{source}: bodies"
    try:
        for b, body in enumerate(data.get("bodies") or []):
            for name, spec in dict(body).items():
                where = f"{source}: bodies[{b}].{name}"
                if spec.get("odom_topic") is not None:
                    ignore |= {int(i) for i in spec.get("ignore_tags") or []}
                    if "T_body_odom" in spec:
                        T_body_odom = _pose(spec["T_body_odom"], f"{where}.T_body_odom")
                if spec.get("is_static"):
                    default_size = spec.get("default_tag_size", default_size)
                    for t, tag in enumerate(spec.get("tags") or []):
                        where = f"{source}: bodies[{b}].{name}.tags[{t}]"
                        sizes[int(tag["id"])] = _size(tag.get("size", default_size), where)
                        if "pose" in tag:
                            anchors[int(tag["id"])] = _pose(tag["pose"], f"{where}.pose")
        default_size = None if default_size is None else _size(default_size, where)
    except TaglocError:
        raise
    except (AttributeError, KeyError, TypeError, ValueError, OverflowError) as exc:
        detail = clip_message(f"{type(exc).__name__}: {exc}")
        raise MappingError(f"{where}: not the tagSLAM layout ({detail})") from None
    return RigConfig(
        anchors=anchors,
        T_body_odom=T_body_odom,
        ignore_tags=frozenset(ignore),
        default_tag_size=default_size,
        tag_sizes=sizes,
        tag_remaps=_tag_remaps(data.get("tag_id_remap") or [], f"{source}: tag_id_remap"),
    )


def _size(value: object, where: str) -> float:
    """A tag edge length, metres: a positive finite number."""
    size = float(value)  # type: ignore[arg-type]  # TypeError/ValueError: reported by the caller
    if not (math.isfinite(size) and size > 0):
        raise MappingError(f"{where}: size {size} is not a positive number of metres")
    return size


def _tag_remaps(entries: object, where: str) -> tuple[TagRemap, ...]:
    """tagSLAM's ``tag_id_remap: [{id, remaps: [{remap_id, start_time, end_time}]}]`` (times in
    seconds since the epoch, as the bag's stamps)."""
    if not isinstance(entries, list):
        raise MappingError(f"{where}: expected a list")
    out = []
    for i, entry in enumerate(entries):
        try:
            for j, r in enumerate(entry["remaps"]):
                start, end = round(float(r["start_time"]) * 1e9), round(float(r["end_time"]) * 1e9)
                if end < start:
                    raise MappingError(f"{where}[{i}].remaps[{j}]: end_time before start_time")
                out.append(TagRemap(int(entry["id"]), int(r["remap_id"]), start, end))
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise MappingError(f"{where}[{i}]: expected id and remaps of remap_id, start_time, "
                               f"end_time ({exc.__class__.__name__}: "
                               f"{clip_message(str(exc))})") from None  # fmt: skip
    return tuple(out)
