"""Fuzzed configuration files: tags.yaml, world.yaml, localizer.yaml (damage: ``fuzz_helpers``).

Whatever the damage, a reader either returns a value that later code can use (a tag map that
writes and reads back, a world that drives, a localizer configuration that runs the filter), or
raises a :class:`TaglocError` whose message is one short line naming the file. Anything else (a
traceback, a RecursionError, a MemoryError) fails the test.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from fuzz_helpers import (
    EDITS,
    FUZZ,
    NASTY,
    S,
    damaged,
    leaf_paths,
    load_or_refuse,
    replaced,
    value_damage,
)
from hypothesis import event, given, settings
from hypothesis import strategies as st

from tagloc.errors import TaglocError
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.lidar.fix import lidar_fix
from tagloc.lidar.registration import Target
from tagloc.localize import (
    FixQuality,
    LocalizerConfig,
    MapOdomFilter,
    TagFix,
    load_localizer_config,
)
from tagloc.localize.node import LocalizerNode
from tagloc.messages import OdometryMsg, PointCloudMsg, TransformMsg
from tagloc.sim import load_default_world, load_world, simulate_drive
from tagloc.sim.coverage import route_coverage
from tagloc.sim.scenarios import tag_map_from_world
from tagloc.tags import TagMap, load_tag_map, make_detector

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
    data = damaged(TAGS_TEXT.encode(), edits)
    _use_tag_map(load_or_refuse(load_tag_map, tmp_path / "tags.yaml", data))


@FUZZ
@given(data=st.data())
def test_tags_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text = value_damage(TAGS_TEXT, data)
    _use_tag_map(load_or_refuse(load_tag_map, tmp_path / "tags.yaml", text.encode()))


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
    load_or_refuse(_drive_world, tmp_path / "world.yaml", damaged(SMALL_WORLD.encode(), edits))


@FUZZ
@given(data=st.data())
def test_world_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text = value_damage(SMALL_WORLD, data)
    load_or_refuse(_drive_world, tmp_path / "world.yaml", text.encode())


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


TAG_MAP = TagMap.from_yaml_text(TAGS_TEXT)
_TAG = TAG_MAP.in_frame("map")[0].T_frame_tag().translation
_RNG = np.random.default_rng(11)
#: A 6 m x 4 m x 2.5 m room around the first tag (floor, walls, a box): the premap.
ROOM = np.concatenate([
    np.column_stack([_RNG.uniform(-3, 3, 2000), _RNG.uniform(-2, 2, 2000), np.zeros(2000)]),
    np.column_stack([np.full(800, 3.0), _RNG.uniform(-2, 2, 800), _RNG.uniform(0, 2.5, 800)]),
    np.column_stack([_RNG.uniform(-3, 3, 800), np.full(800, 2.0), _RNG.uniform(0, 2.5, 800)]),
    np.column_stack([_RNG.uniform(-3, 3, 800), np.full(800, -2.0), _RNG.uniform(0, 2.5, 800)]),
    np.column_stack([np.full(300, -1.0), _RNG.uniform(-0.5, 0.5, 300), _RNG.uniform(0, 1, 300)]),
]) + np.array([_TAG[0], _TAG[1], 0.0])  # fmt: skip


def _use_every_section(path: Path) -> None:
    """The odometry run of :func:`_use_localizer`, then what the node builds from the other
    sections: the node itself (supervisor, gates, the premap prepared with ``lidar``'s
    registration settings) fed 2 s of odometry and sweeps, one lidar fix (small_gicp with the
    file's threads, neighbours, iterations) and the tag detector (the AprilTag library)."""
    _use_localizer(path)
    config = load_localizer_config(path)
    try:  # a valid file that does not fit the tag map (a map frame it lacks): one line
        node = LocalizerNode(TAG_MAP, config, premap=ROOM)
    except TaglocError as exc:
        assert "\n" not in str(exc) and len(str(exc)) < 400, str(exc)
        event(f"node refused: {type(exc).__name__}")
        return
    f, frame = config.frames, config.lidar.frame_id
    node.feed("/tf_static", TransformMsg(0, f.base_frame, frame, SE3.identity(), static=True))
    T_map_base = SE3.from_matrix(np.eye(4)) @ SE3.exp(np.array([_TAG[0], _TAG[1], 0.5, 0, 0, 0]))
    sweep = (ROOM - T_map_base.translation)[::4].astype(np.float32)
    for k, stamp in enumerate(range(0, 2 * S, S // 50)):
        node.feed("/odom", OdometryMsg(stamp, f.odom_frame, f.base_frame, SE3.identity(),
                                       np.eye(6) * 1e-4))  # fmt: skip
        if k % 10 == 5:
            node.feed("/lidar/points", PointCloudMsg(stamp, frame, sweep))
    node.finish()
    target = Target.from_points(ROOM, config.lidar.fix.registration)
    fix = lidar_fix(sweep, target, T_map_base, config.lidar.fix)
    assert np.isfinite(fix.T_map_base.as_matrix()).all() and np.isfinite(fix.information).all()
    make_detector(config.tags.backend, config.tags.family)


def test_the_undamaged_localizer_yaml_runs_every_section(tmp_path: Path) -> None:
    """The baseline of the fuzz tests below: nothing refused, every section used."""
    (tmp_path / "localizer.yaml").write_text(LOCALIZER_TEXT)
    _use_every_section(tmp_path / "localizer.yaml")


@FUZZ
@given(edits=EDITS)
def test_localizer_yaml_bytes(tmp_path: Path, edits: Any) -> None:
    data = damaged(LOCALIZER_TEXT.encode(), edits)
    load_or_refuse(_use_every_section, tmp_path / "localizer.yaml", data)


@FUZZ
@given(data=st.data())
def test_localizer_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text = value_damage(LOCALIZER_TEXT, data)
    load_or_refuse(_use_every_section, tmp_path / "localizer.yaml", text.encode())


SECTIONS = [name for name in LocalizerConfig.model_fields if name != "version"]


@pytest.mark.parametrize("section", SECTIONS)
@settings(FUZZ, max_examples=12)
@given(data=st.data())
def test_localizer_yaml_values_per_section(
    tmp_path: Path, section: str, data: st.DataObject
) -> None:
    """Value damage inside each section in turn (the whole-file test picks sections by their
    share of the leaves: this one gives every section its examples)."""
    doc = yaml.safe_load(LOCALIZER_TEXT)
    leaf = data.draw(st.sampled_from(leaf_paths(doc[section])), label="path")
    doc = replaced(doc, (section, *leaf), data.draw(NASTY, label="value"))
    text = yaml.safe_dump(doc, sort_keys=False)
    load_or_refuse(_use_every_section, tmp_path / "localizer.yaml", text.encode())
