"""The node's lidar fix source on a synthetic scene: scans of wall segments around the simulated
drive (points of the premap within range, seen from the true pose, with noise), fed beside the
scenario's odometry and tags. Oracle: the simulator's ground truth.

These exercise the plumbing (frames, skips, the ladder's lidar source, the cab rule) on 30 s;
the simulator's ray-cast scans are exercised by the scenario tests.
"""

from __future__ import annotations

import dataclasses
import functools
import heapq
import math
from collections.abc import Iterator

import numpy as np
import pytest

from tagloc.errors import ConfigError
from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.geometry import SE3
from tagloc.localize import LocalizerConfig
from tagloc.localize.fix import LocalizeError
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import RunRecorder
from tagloc.messages import Message, PointCloudMsg, TagDetectionsMsg, TransformMsg
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.supervise import FixSourceSpec
from tagloc.tags import TagEntry, TagMap

S = 1_000_000_000
DURATION_S = 30.0
T_BASE_LIDAR = SE3.exp([0.1, 0.0, 0.45, 0.0, 0.0, 0.0])


@functools.cache
def _source() -> ScenarioSource:
    return ScenarioSource(build_scenario("default", seed=2, duration_s=DURATION_S))


@functools.cache
def _premap() -> np.ndarray:
    """Wall segments (2 m long, 2 m tall, random yaw) every 3 m over the drive's extent,
    sampled every 10 cm: structure in every direction."""
    rng = np.random.default_rng(0)
    xy = np.asarray(_source().scenario.drive.T_map_base.translation)[:, :2]
    lo, hi = xy.min(axis=0) - 8.0, xy.max(axis=0) + 8.0
    segments = []
    for cx in np.arange(lo[0], hi[0], 3.0):
        for cy in np.arange(lo[1], hi[1], 3.0):
            c = np.array([cx, cy]) + rng.uniform(-1.0, 1.0, 2)
            d = np.array([math.cos(a := rng.uniform(0, math.pi)), math.sin(a)])
            if np.min(np.linalg.norm(xy[::50] - c, axis=1)) < 0.8:
                continue  # keep the route free
            s, z = np.meshgrid(np.arange(-1.0, 1.0, 0.1), np.arange(0.0, 2.0, 0.1))
            pts = c + s.reshape(-1, 1) * d
            segments.append(np.column_stack([pts, z.reshape(-1)]))
    return np.concatenate(segments)


def _scan(T_map_base: SE3, rng: np.random.Generator) -> np.ndarray:
    """Premap points within 10 m of the base, in the lidar frame, 1 cm noise, 3000 at most."""
    premap = _premap()
    near = premap[np.linalg.norm(premap[:, :2] - T_map_base.translation[:2], axis=1) < 10.0]
    near = near[rng.permutation(len(near))[:3000]]
    points_lidar = (T_map_base @ T_BASE_LIDAR).inverse().act(near)
    return points_lidar + rng.normal(0.0, 0.01, points_lidar.shape)


def _stream(bad: dict[int, str] | None = None, cab: tuple[float, float] | None = None,
            cab_id: int = 99) -> Iterator[tuple[str, Message]]:  # fmt: skip
    """The scenario's stream with a static ``base_link -> lidar`` and 10 Hz sweeps; sweep ``i``
    in ``bad`` is replaced by a broken one (``frame``, ``nan``, ``empty``); camera frames within
    ``cab`` (s) see only tag ``cab_id``."""
    src = _source()
    drive = src.scenario.drive
    t0 = int(drive.stamps_ns[0])
    rng = np.random.default_rng(1)

    def clouds() -> Iterator[tuple[int, int, tuple[str, Message]]]:
        yield t0, 0, ("/tf_static", TransformMsg(t0, "base_link", "lidar", T_BASE_LIDAR, True))
        for i, stamp in enumerate(range(t0 + S // 20, int(drive.stamps_ns[-1]), S // 10)):
            k = int(np.searchsorted(drive.stamps_ns, stamp))
            points = _scan(drive.T_map_base[k], rng)
            frame = "lidar"
            kind = (bad or {}).get(i)
            if kind == "frame":
                frame = "camera_optical"
            elif kind == "nan":
                points = np.full_like(points, np.nan)
            elif kind == "empty":
                points = np.zeros((0, 3))
            yield int(drive.stamps_ns[k]), 1, ("/lidar/points", PointCloudMsg(
                int(drive.stamps_ns[k]), frame, points.astype(np.float32)))  # fmt: skip

    def camera() -> Iterator[tuple[int, int, tuple[str, Message]]]:
        for topic, msg in src:
            if cab is not None and isinstance(msg, TagDetectionsMsg) and msg.detections:
                t = (msg.stamp_ns - t0) / S
                if cab[0] <= t < cab[1]:
                    dets = tuple(dataclasses.replace(d, tag_id=cab_id) for d in msg.detections)
                    msg = TagDetectionsMsg(msg.stamp_ns, msg.frame_id, dets)
            yield msg.stamp_ns, 2, (topic, msg)

    for _, _, item in heapq.merge(clouds(), camera(), key=lambda x: (x[0], x[1])):
        yield item


@functools.cache
def _nominal(lidar: bool) -> tuple[LocalizerNode, RunRecorder]:
    return _run(lidar)


def _run(
    lidar: bool, tag_map: TagMap | None = None, **kw: object
) -> tuple[LocalizerNode, RunRecorder]:
    src = _source()
    cfg = calibrated_config(src.scenario, scenario_config())
    recorder = RunRecorder("lidar")
    node = LocalizerNode(
        tag_map or src.scenario.tag_map, cfg, [recorder], frame_truth=src.frame_truth,
        premap=_premap() if lidar else None,
    )  # fmt: skip
    for topic, msg in _stream(**kw):  # type: ignore[arg-type]
        node.feed(topic, msg)
    node.finish()
    return node, recorder


def _errors_m(recorder: RunRecorder) -> np.ndarray:
    run = recorder.run({})
    assert run.T_map_base_truth is not None
    ok = run.initialized
    d = np.asarray(run.T_map_base.translation - run.T_map_base_truth.translation)[ok]
    return np.linalg.norm(d[:, :2], axis=1)


def test_lidar_fixes_are_accepted_and_tighten_the_estimate() -> None:
    node, rec = _nominal(True)
    tags_node, tags_rec = _nominal(False)
    run = rec.run({})
    lidar = [a for a in run.fixes if a.source == "lidar"]
    accepted = sum(a.accepted for a in lidar)
    assert accepted >= 0.9 * len(lidar) > 100  # 5 Hz over ~ 25 s after initialization
    assert node.supervisor.sources["lidar"] == FixSourceSpec("lidar", "lidar", "lidar")
    assert "lidar" not in tags_node.supervisor.sources
    rmse, rmse_tags = (float(np.sqrt(np.mean(_errors_m(r) ** 2))) for r in (rec, tags_rec))
    assert rmse < 0.8 * rmse_tags, (rmse, rmse_tags)
    assert rmse < 0.03
    assert int(node.supervisor.level) == 1  # lidar nominal at the end


def test_no_static_transform_is_a_counted_skip() -> None:
    src = _source()
    cfg = calibrated_config(src.scenario, scenario_config())
    node = LocalizerNode(src.scenario.tag_map, cfg, premap=_premap())
    for topic, msg in _stream():
        if msg.stamp_ns > int(src.scenario.drive.stamps_ns[0]) + 8 * S:
            break
        if topic != "/tf_static" or msg.child != "lidar":  # type: ignore[union-attr]
            node.feed(topic, msg)
    node.finish()
    assert node.skipped["lidar_no_tf"] > 10
    assert node.filter.initialized  # tags carried on


def test_premap_elsewhere_is_refused() -> None:
    src = _source()
    with pytest.raises(LocalizeError, match="premap does not overlap the tag map"):
        LocalizerNode(src.scenario.tag_map, premap=_premap() + np.array([500.0, 0.0, 0.0]))
    with pytest.raises(LocalizeError, match="premap must be"):
        LocalizerNode(src.scenario.tag_map, premap=np.zeros((5, 3)))


def test_lidar_section_errors_are_one_line() -> None:
    with pytest.raises(ConfigError, match=r"lidar\.max_rate_hz") as info:
        LocalizerConfig.from_yaml_text("lidar: {max_rate_hz: -1}", "localizer.yaml")
    assert "\n" not in str(info.value)
    with pytest.raises(ConfigError, match=r"lidar\.fix\.bogus"):
        LocalizerConfig.from_yaml_text("lidar: {fix: {bogus: 1}}", "localizer.yaml")


def test_bad_clouds_are_skipped_and_lidar_is_ignored_in_the_elevator_cab() -> None:
    src = _source()
    entries = list(src.scenario.tag_map)
    cab_tag = TagEntry.from_pose(99, SE3.identity(), entries[0].size, frame="elevator_cab")
    tag_map = TagMap(frames=("map", "elevator_cab"), tags=(*entries, cab_tag))
    bad = {60: "frame", 80: "nan", 100: "empty", 101: "nan"}  # 6 s to 10 s in
    node, rec = _run(True, tag_map=tag_map, cab=(20.0, 25.0), bad=bad)
    # a broken cloud: one counted skip each, the node goes on
    assert node.skipped["lidar_wrong_frame"] == 1
    assert node.skipped["lidar_empty"] == 3
    t0 = int(src.scenario.drive.stamps_ns[0])
    lidar = [(a.stamp_ns - t0) / S for a in rec.run({}).fixes if a.source == "lidar"]
    assert node.skipped["in_cab"] >= 20  # 5 s at 5 Hz, less the frames without tags
    assert not [t for t in lidar if 20.2 < t < 24.9]
    assert [t for t in lidar if t > 26.0]  # out of the cab: lidar again
