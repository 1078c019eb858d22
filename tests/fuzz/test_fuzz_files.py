"""Fuzzed input files: tags.yaml, world.yaml, localizer.yaml, Kalibr camera files, TUM files.

Two kinds of damage: bytes (inserted, deleted, replaced, truncated; with YAML tokens such as
anchors, aliases, brackets, tabs and invalid UTF-8 among the inserts), and values (a field of a
valid document replaced by NaN, 1e308, a huge integer, a string, a list, a nested mapping...).
Whatever the damage, a reader either returns a value that later code can use, or raises a
:class:`TaglocError` whose message is one short line naming the file. Anything else (a
traceback, a RecursionError, a MemoryError) fails the test.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from tagloc.config import MAX_QUOTED_CHARS
from tagloc.errors import TaglocError
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.io import load_kalibr_cameras, read_tum
from tagloc.localize import (
    FixQuality,
    LocalizerConfig,
    MapOdomFilter,
    TagFix,
    load_localizer_config,
)
from tagloc.sim import load_default_world, load_world, simulate_drive
from tagloc.sim.coverage import route_coverage
from tagloc.sim.scenarios import tag_map_from_world
from tagloc.tags import TagMap, load_tag_map

FUZZ = settings(
    max_examples=35,
    database=None,
    derandomize=True,  # the same examples on every run; campaigns raise max_examples instead
    deadline=None,  # the shared test machine is slow at times; the suite's time is bounded by
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
TOKENS = [
    b"&a ", b"*a", b"<<: *a", b"[", b"]", b"{", b"}", b": ", b"- ", b"\n", b"\t", b"  ", b"#",
    b"'", b'"', b"!!binary ", b"!!python/object ", b"? ", b"|", b">", b"---\n", b"...\n",
    b"nan", b".inf", b"1e308", b"-1e308", b"0x" + b"f" * 40, b"9" * 30, b"\xff", b"\xc3",
    b"\x00", b"\xef\xbb\xbf", b"~", b"null", b"true", b"2001-02-31",
]  # fmt: skip
_edit = st.tuples(
    st.integers(0, 2**20),
    st.integers(0, 12),
    st.one_of(st.binary(max_size=6), st.sampled_from(TOKENS)),
)
EDITS = st.tuples(
    st.lists(_edit, min_size=1, max_size=5), st.one_of(st.none(), st.integers(0, 2**20))
)
S = 1_000_000_000
NASTY = st.one_of(
    st.sampled_from([1e308, -1e308, 1e300, 1e-300, 1e-9, 2**63 - 1, 10**18]),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, 0, -1, 2**63, -(2**63),
                     2**64 - 1, True, None, "", "x" * 300, [], {}, [[[[]]]], {"a": {"b": 1}}]),
    st.floats(),
    st.integers(-(2**64), 2**64),
    st.text(max_size=20),
    st.lists(st.floats(allow_nan=True), max_size=8),
)  # fmt: skip


def _damaged(data: bytes, edits: tuple[list[tuple[int, int, bytes]], int | None]) -> bytes:
    changes, cut = edits
    for position, deleted, inserted in changes:
        at = position % (len(data) + 1)
        data = data[:at] + inserted + data[at + deleted :]
    return data if cut is None else data[: cut % (len(data) + 1)]


def _leaf_paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path into a parsed document (mappings and lists), inner nodes included."""
    paths = [prefix] if prefix else []
    items = (
        node.items()
        if isinstance(node, dict)
        else enumerate(node)
        if isinstance(node, list)
        else []
    )
    for key, child in items:
        paths += _leaf_paths(child, (*prefix, key))
    return paths


def _replaced(doc: Any, path: tuple[Any, ...], value: Any) -> Any:
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return doc


def _expect_one_line(exc: TaglocError, path: Path) -> None:
    message = str(exc)
    assert "\n" not in message, message
    assert message.startswith(f"{path}: "), message
    assert len(message) < len(str(path)) + 400 + 2 * MAX_QUOTED_CHARS, message


def _load_or_refuse(loader: Any, path: Path, data: bytes) -> Any:
    path.write_bytes(data)
    try:
        value = loader(path)
    except TaglocError as exc:
        _expect_one_line(exc, path)
        event(f"refused: {type(exc).__name__}")
        return None
    event("accepted")
    return value


def _value_damage(text: str, data: st.DataObject) -> str:
    doc = yaml.safe_load(text)
    path = data.draw(st.sampled_from(_leaf_paths(doc)), label="path")
    return yaml.safe_dump(_replaced(doc, path, data.draw(NASTY, label="value")), sort_keys=False)


# ----- tags.yaml ----------------------------------------------------------------------------------
TAGS_TEXT = tag_map_from_world(load_default_world()).to_yaml_text()


def _use_tag_map(tag_map: TagMap | None) -> None:
    if tag_map is None:
        return
    tag_map.summary()
    for entry in tag_map:
        assert np.all(np.isfinite(entry.T_frame_tag().as_matrix()))
        entry.covariance_matrix()
    text = tag_map.to_yaml_text()  # the writer's output reads back, and is stable (it rounds)
    assert TagMap.from_yaml_text(text).to_yaml_text() == text


@FUZZ
@given(edits=EDITS)
def test_tags_yaml_bytes(tmp_path: Path, edits: Any) -> None:
    data = _damaged(TAGS_TEXT.encode(), edits)
    _use_tag_map(_load_or_refuse(load_tag_map, tmp_path / "tags.yaml", data))


@FUZZ
@given(data=st.data())
def test_tags_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text = _value_damage(TAGS_TEXT, data)
    _use_tag_map(_load_or_refuse(load_tag_map, tmp_path / "tags.yaml", text.encode()))


# ----- world.yaml ---------------------------------------------------------------------------------
SMALL_WORLD = """\
version: 1
name: small
walls:
  - {start: [0, 0], end: [10, 0]}
tags:
  - {id: 0, size: 0.16, wall: {x: 5.0, y: 0.0, yaw_deg: 90, height: 0.5}}
  - {id: 1, size: 0.16, pose: {position: [8.0, 0.0, 0.5], quat_xyzw: [0.5, 0.5, 0.5, 0.5]}}
elevator:
  pose_in_map: {x: 5.0, y: 5.0, yaw_deg: 0}
  footprint: [2.0, 2.0]
checkpoints:
  - {name: a, x: 2.0, y: 2.0}
  - {name: b, x: 8.0, y: 2.0}
route:
  speed: 1.0
  corner_radius: 0.5
  waypoints: [a, b, [8.0, 3.0], {at: a, dwell: 1.0}]
robot:
  odometry: {model: legged, seed: 3}
  odom_rate_hz: 50
  camera:
    intrinsics: {fx: 400.0, fy: 400.0, cx: 319.5, cy: 239.5, width: 640, height: 480}
    distortion: {model: radtan, coefficients: [0.01, -0.01, 0.0, 0.0]}
    rate_hz: 10
    T_base_cam: {position: [0.2, 0.0, 0.4], rpy_deg: [0.0, 0.0, 0.0]}
"""


def _drive_world(path: Path) -> None:
    """What ``world coverage``, ``sim record`` and ``map build --sim`` do first."""
    world = load_world(path)
    for tag in world.tags:
        world.T_map_tag(tag)
    world.walls_in_map()
    world.robot.camera.camera_model()
    drive = simulate_drive(world)
    assert np.all(np.isfinite(drive.T_odom_base.translation))
    route_coverage(world, stride=10)


@FUZZ
@given(edits=EDITS)
def test_world_yaml_bytes(tmp_path: Path, edits: Any) -> None:
    _load_or_refuse(_drive_world, tmp_path / "world.yaml", _damaged(SMALL_WORLD.encode(), edits))


@FUZZ
@given(data=st.data())
def test_world_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text = _value_damage(SMALL_WORLD, data)
    _load_or_refuse(_drive_world, tmp_path / "world.yaml", text.encode())


# ----- localizer.yaml -----------------------------------------------------------------------------
LOCALIZER_TEXT = LocalizerConfig().to_yaml_text()


def _use_localizer(path: Path) -> None:
    """Load, build the filter and run it over 2 s of odometry with one fix."""
    config = load_localizer_config(path)
    stamps = np.arange(0, 2 * S, S // 50)
    forward = np.zeros((len(stamps), 6))
    forward[:, 0], forward[:, 5] = np.linspace(0.0, 2.0, len(stamps)), 0.3
    buffer = TransformBuffer()
    buffer.set_transforms(
        config.frames.odom_frame, config.frames.base_frame, stamps, SE3.exp(forward)
    )
    flt = MapOdomFilter.from_config(config, buffer)
    flt.initialize(0, SE3.identity(), np.eye(6) * 1e-2)
    for stamp in stamps[::5].tolist():
        flt.predict(stamp)
    flt.update(TagFix(int(stamps[-1]), SE3.exp(forward[-1]), np.eye(6) * 1e-3, "tag:1",
                      FixQuality(0.4)))  # fmt: skip
    assert np.all(np.isfinite(flt.covariance)) and np.all(
        np.isfinite(flt.correction_at(2 * S).as_matrix())
    )


@FUZZ
@given(edits=EDITS)
def test_localizer_yaml_bytes(tmp_path: Path, edits: Any) -> None:
    data = _damaged(LOCALIZER_TEXT.encode(), edits)
    _load_or_refuse(_use_localizer, tmp_path / "localizer.yaml", data)


@FUZZ
@given(data=st.data())
def test_localizer_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text = _value_damage(LOCALIZER_TEXT, data)
    _load_or_refuse(_use_localizer, tmp_path / "localizer.yaml", text.encode())


# ----- Kalibr camera files ------------------------------------------------------------------------
CAMERAS_TEXT = """\
cam0:
  camera_model: pinhole
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  distortion_model: radtan
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  camera_model: pinhole
  intrinsics: [280.0, 280.0, 320.0, 240.0]
  distortion_model: equidistant
  distortion_coeffs: [0.01, -0.002, 0.0005, -0.0001]
  resolution: [640, 480]
"""


def _use_cameras(path: Path) -> None:
    for camera in load_kalibr_cameras(path).values():
        points = np.array([[0.0, 0.0, 1.0], [0.3, -0.2, 2.0]])
        camera.project(points)


@FUZZ
@given(edits=EDITS)
def test_camera_yaml_bytes(tmp_path: Path, edits: Any) -> None:
    _load_or_refuse(_use_cameras, tmp_path / "cameras.yaml", _damaged(CAMERAS_TEXT.encode(), edits))


@FUZZ
@given(data=st.data())
def test_camera_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text = _value_damage(CAMERAS_TEXT, data)
    _load_or_refuse(_use_cameras, tmp_path / "cameras.yaml", text.encode())


# ----- TUM files ----------------------------------------------------------------------------------
TUM_TEXT = (
    "# timestamp tx ty tz qx qy qz qw\n"
    "1.000000000 0.0 0.0 0.0 0.0 0.0 0.0 1.0\n"
    "1.100000000 0.1 0.0 0.0 0.0 0.0 0.0499792 0.9987503\n"
    "1.2 0.2 0.01 0.0 0 0 0.0998334 0.9950042\n"
    "1.30e0 3.0e-1 2e-2 0 0 0 0.1494381 0.9887711\n"
)
TUM_TOKENS = st.sampled_from(
    [b" ", b"\n", b"#", b"nan", b"inf", b"1e308", b"-1e308", b"1e999999999", b"-", b".", b"e",
     b"9" * 25, b"0", b"\xff", b"\t", b"\x00"]
)  # fmt: skip
TUM_EDITS = st.tuples(
    st.lists(
        st.tuples(st.integers(0, 2**20), st.integers(0, 8), TUM_TOKENS), min_size=1, max_size=6
    ),
    st.one_of(st.none(), st.integers(0, 2**20)),
)


def _use_tum(path: Path) -> None:
    stamps, poses = read_tum(path)
    assert np.all(np.diff(stamps) > 0) and stamps.dtype == np.int64
    assert np.all(np.isfinite(poses.as_matrix()))
    assert np.all(np.abs(poses.translation) <= 1e8)
    assert np.isfinite(np.sum(np.square(poses.translation)))  # an ATE over them cannot overflow


@FUZZ
@given(edits=TUM_EDITS)
def test_tum_bytes(tmp_path: Path, edits: Any) -> None:
    _load_or_refuse(_use_tum, tmp_path / "t.tum", _damaged(TUM_TEXT.encode(), edits))


# ----- tagSLAM rig files (camera_poses.yaml, tagslam.yaml) ---------------------------------------
TAGSLAM_TEXT = """\
bodies:
  - rig:
      odom_topic: /odom
      ignore_tags: [5, 6]
      T_body_odom: {position: {x: 0.1, y: 0, z: 0}, rotation: {x: 0, y: 0, z: 0.1}}
  - lab:
      is_static: true
      default_tag_size: 0.16
      tags:
        - {id: 1, size: 0.2, pose: {position: {x: 1, y: 2, z: 0}, rotation: {x: 0, y: 0, z: 1}}}
        - {id: 2}
tag_id_remap:
  - id: 20
    remaps: [{remap_id: 420, start_time: 10.0, end_time: 20.0}]
"""
CAMERA_POSES_TEXT = """\
cam0:
  pose: {position: {x: 0.1, y: 0, z: 0.2}, rotation: {x: 0, y: 0, z: 0}}
cam1:
  pose: {position: {x: -0.1, y: 0, z: 0.2}, rotation: {x: 0, y: 0, z: 3.14}}
"""


def _use_rig(path: Path) -> None:
    from tagloc.mapping.stream_survey import parse_camera_poses, parse_tagslam

    text = path.read_bytes().decode("utf-8", errors="replace")
    parser = parse_tagslam if path.name == "tagslam.yaml" else parse_camera_poses
    try:
        parser(text, str(path))
    except TaglocError as exc:
        _expect_one_line(exc, path)
        event(f"refused: {type(exc).__name__}")


@FUZZ
@given(data=st.data(), which=st.sampled_from(["tagslam.yaml", "camera_poses.yaml"]))
def test_rig_yaml_values(tmp_path: Path, data: st.DataObject, which: str) -> None:
    text = _value_damage(TAGSLAM_TEXT if which == "tagslam.yaml" else CAMERA_POSES_TEXT, data)
    (tmp_path / which).write_text(text)
    _use_rig(tmp_path / which)


@FUZZ
@given(edits=EDITS, which=st.sampled_from(["tagslam.yaml", "camera_poses.yaml"]))
def test_rig_yaml_bytes(tmp_path: Path, edits: Any, which: str) -> None:
    text = TAGSLAM_TEXT if which == "tagslam.yaml" else CAMERA_POSES_TEXT
    (tmp_path / which).write_bytes(_damaged(text.encode(), edits))
    _use_rig(tmp_path / which)
