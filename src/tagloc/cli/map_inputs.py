"""What ``tagloc map build`` reads from its options: tag sizes, anchors, exclusions, the
map-build configuration, and the survey of a bag (thin glue; the algorithms are in
:mod:`tagloc.mapping`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from tagloc.cli.options import OptionError

if TYPE_CHECKING:
    from tagloc.geometry import SE3
    from tagloc.mapping import MapBuildConfig, Survey
    from tagloc.mapping.anchors import Anchor
    from tagloc.mapping.exclude import Exclusion
    from tagloc.tags.tagmap import TagMap

#: Largest tag edge accepted (``--tag-size``, ``--size``), m.
MAX_TAG_EDGE_M = 100.0

#: The lidar topic ``--lidar-topic`` defaults to (used only when the bag has it).
DEFAULT_LIDAR_TOPIC = "/lidar/points"


def _read_text(path: Path, what: str) -> str:
    from tagloc.mapping import MappingError

    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MappingError(f"{path}: cannot read the {what} ({exc.__class__.__name__})") from None


def _pairs(values: list[str], option: str, convert: type) -> dict[str, object]:
    from tagloc.mapping import MappingError

    out: dict[str, object] = {}
    for value in values:
        key, sep, raw = value.partition("=")
        try:
            if not sep or not key:
                raise ValueError
            out[key] = convert(raw)
        except ValueError:
            raise MappingError(f"{option} {value!r}: expected KEY=VALUE") from None
    return out


def parse_tag_sizes(values: list[str]) -> dict[int, float]:
    """``--size ID=EDGE_M`` (repeatable) as ``{id: edge}``; ids >= 0, finite positive edges."""
    from tagloc.mapping import MappingError

    sizes: dict[int, float] = {}
    for value in values:
        key, _, raw = value.partition("=")
        try:
            tag_id, edge = int(key), float(raw)
        except ValueError:
            raise MappingError(f"--size {value!r}: expected ID=EDGE_M with an integer id") from None
        if tag_id < 0 or not 0.0 < edge <= MAX_TAG_EDGE_M:
            wanted = f"an id >= 0 and an edge > 0 and <= {MAX_TAG_EDGE_M:g} m"
            raise OptionError(f"--size {value!r}: expected {wanted}")
        sizes[tag_id] = edge
    return sizes


def parse_anchor_sigma(value: str | None) -> dict[str, float]:
    """``--anchor-sigma POS_M,ROT_DEG`` as the builder's default anchor sigmas."""
    from tagloc.mapping import MappingError

    if value is None:
        return {}
    try:
        pos, rot = (float(v) for v in value.split(","))
    except ValueError:
        raise MappingError(f"--anchor-sigma {value!r}: expected POS_M,ROT_DEG") from None
    if not (0.0 < pos <= 10.0 and 0.0 < rot <= 90.0):
        raise OptionError(f"--anchor-sigma {value!r}: expected 0 < POS_M <= 10, 0 < ROT_DEG <= 90")
    return {"anchor_sigma_m": pos, "anchor_sigma_rad": math.radians(rot)}


def parse_exclusion(text: str) -> Exclusion:
    """``tag:ID``, ``tag:ID@T0-T1`` or ``time:T0-T1`` (seconds from the survey start)."""
    from tagloc.mapping import MappingError
    from tagloc.mapping.exclude import Exclusion

    kind, _, rest = text.partition(":")
    try:
        if kind == "tag":
            tag, at, window = rest.partition("@")
            t0, t1 = _range(window) if at else (None, None)  # "tag:5@" is no window: an error
            tag_id: int | None = int(tag)
        elif kind == "time":
            tag_id, (t0, t1) = None, _range(rest)
        else:
            raise ValueError(kind)
    except ValueError:
        raise MappingError(
            f"--exclude {text!r}: expected tag:ID, tag:ID@T0-T1 or time:T0-T1 (seconds from the "
            "survey start)"
        ) from None
    return Exclusion(tag_id, t0, t1, text)


def _range(text: str) -> tuple[float, float]:
    t0, sep, t1 = text.partition("-")
    if not sep:
        raise ValueError(text)
    a, b = float(t0), float(t1)
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ValueError(text)
    return a, b


def build_config(
    path: Path | None, base: MapBuildConfig, update: dict[str, object]
) -> MapBuildConfig:
    """``base`` updated by the ``--config`` YAML (MapBuildConfig fields), then by options."""
    from tagloc.config import parse_yaml_mapping, read_text_file, validate
    from tagloc.mapping import MapBuildConfig

    data = base.model_dump()
    if path is not None:
        text = read_text_file(path, "build configuration")  # bounded, UTF-8
        data = _merged(data, parse_yaml_mapping(text, str(path)))
    data = _merged(data, update)
    return validate(MapBuildConfig, data, str(path) if path is not None else "options")


def _merged(base: dict[str, object], update: dict[str, object]) -> dict[str, object]:
    out = dict(base)
    for key, value in update.items():
        old = out.get(key)
        out[key] = (
            _merged(old, value) if isinstance(old, dict) and isinstance(value, dict) else value
        )
    return out


def camera_tag_topics(cameras_yaml: Path, given: list[str]) -> dict[str, str]:
    """``topic -> camera`` from ``--tag-topic CAM=TOPIC`` or the camchain's ``tagtopic`` keys."""
    from tagloc.config import parse_yaml_mapping

    if given:
        return {str(topic): cam for cam, topic in _pairs(given, "--tag-topic", str).items()}
    data = parse_yaml_mapping(_read_text(cameras_yaml, "camera file"), str(cameras_yaml))
    return {
        str(entry["tagtopic"]): str(name)
        for name, entry in data.items()
        if isinstance(entry, dict) and "tagtopic" in entry
    }


def bag_survey(
    bag: Path,
    cameras_yaml: Path,
    camera_poses: Path | None,
    tagslam: Path | None,
    tag_topics: list[str],
    odom_topic: str,
    corner_order: str,
    tag_size: float | None,
    sizes: dict[int, float],
    lidar_topic: str | None,
) -> tuple[Survey, dict[int, SE3 | Anchor]]:

    from tagloc.geometry import SE3
    from tagloc.io import BagSource, load_kalibr_cameras
    from tagloc.mapping import MappingError
    from tagloc.mapping.stream_survey import parse_camera_poses, parse_tagslam, survey_from_tagslam

    cameras = load_kalibr_cameras(cameras_yaml)
    topics = camera_tag_topics(cameras_yaml, tag_topics)
    if not topics:
        raise MappingError(
            f"{cameras_yaml}: no camera has a 'tagtopic'; give --tag-topic CAM=TOPIC"
        )
    unknown = sorted(set(topics.values()) - set(cameras))
    if unknown:
        raise MappingError(f"--tag-topic: camera {unknown[0]!r} is not in {cameras_yaml}")
    if camera_poses is not None:
        T_base_cam = parse_camera_poses(_read_text(camera_poses, "camera poses"), str(camera_poses))
    elif len(cameras) == 1:
        T_base_cam = {name: SE3.identity() for name in cameras}
    else:
        raise MappingError(f"{cameras_yaml}: several cameras: give --camera-poses (extrinsics)")
    rig = None
    if tagslam is not None:
        rig = parse_tagslam(_read_text(tagslam, "tagslam configuration"), str(tagslam))
    wanted = [*topics, odom_topic]
    source = BagSource(bag, wanted, corner_order=corner_order, default_family="tag36h11")
    if lidar_topic == DEFAULT_LIDAR_TOPIC and lidar_topic not in source.bag_topics:
        lidar_topic = None  # the default topic, and the bag has none: a tags-only survey
    if lidar_topic is not None:  # an explicit topic the bag lacks is an error (one line)
        statics = ["/tf_static"] if "/tf_static" in source.bag_topics else []
        source = BagSource(bag, [*wanted, lidar_topic, *statics], corner_order=corner_order,
                           default_family="tag36h11")  # fmt: skip
    survey = survey_from_tagslam(
        source,
        topics,
        odom_topic,
        cameras,
        T_base_cam,
        rig,
        tag_sizes=sizes,
        default_tag_size=tag_size,
        source=str(bag),
        lidar_topic=lidar_topic,
    )
    return survey, dict(rig.anchors) if rig else {}


def measured_anchors(tag_map: TagMap) -> dict[int, SE3 | Anchor]:
    """The entries of an anchors file, with their ``anchor_sigma`` where they give one."""
    from tagloc.mapping.anchors import Anchor

    out: dict[int, SE3 | Anchor] = {}
    for e in tag_map:
        sigma = e.anchor_sigma
        out[e.id] = (
            e.T_frame_tag()
            if sigma is None
            else Anchor(e.T_frame_tag(), sigma.position_m, sigma.rotation_deg)
        )
    return out
def product_paths(out: Path, premap_format: str) -> tuple[Path, Path, Path]:
    """``premap.<format>``, ``map.yaml`` and ``map.pgm`` beside the tag map."""
    return out.parent / f"premap.{premap_format}", out.parent / "map.yaml", out.parent / "map.pgm"
