"""The real dupont drive (``../shared/data/dupont/tag_detections.bag.bz2``), read with BagSource.

ROS 1 bag compressed whole with bzip2; ``apriltag_msgs/ApriltagArrayStamped`` defined only by the
bag's connection headers (``AnyReader`` registers them); empty ``family`` fields; corners listed
counter-clockwise on screen. ``corner_order="bl_br_tr_tl"`` below is *a* counter-clockwise order
that passes the winding check, not a claim about which corner is which (that is determined from
the data elsewhere).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from tagloc.io import (
    BagFormatError,
    BagSink,
    BagSource,
    Message,
    OdometryMsg,
    TagDetectionsMsg,
)

DUPONT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "dupont"
BAG = DUPONT / "tag_detections.bag.bz2"
LEFT, RIGHT, ODOM = "/fla/ovc_node/left/tags", "/fla/ovc_node/right/tags", "/fla/vio/odom"
OPTIONS = {"corner_order": "bl_br_tr_tl", "default_family": "tag36h11"}


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not BAG.is_file():
        pytest.skip(f"dupont data set not found at {BAG.resolve()} (../shared/data/dupont)")
    return tmp_path_factory.mktemp("bag-cache")


@pytest.fixture(scope="module")
def stream(cache: Path) -> tuple[BagSource, list[tuple[str, Message]]]:
    source = BagSource(BAG, cache_dir=cache, **OPTIONS)  # type: ignore[arg-type]
    return source, list(source)


def test_topics_types_counts_and_time_span(
    stream: tuple[BagSource, list[tuple[str, Message]]],
) -> None:
    source, items = stream
    assert {n: (t.msgtype, t.msgcount) for n, t in source.bag_topics.items()} == {
        LEFT: ("apriltag_msgs/msg/ApriltagArrayStamped", 4500),
        RIGHT: ("apriltag_msgs/msg/ApriltagArrayStamped", 4500),
        ODOM: ("nav_msgs/msg/Odometry", 4500),
    }
    assert source.topics == {LEFT: TagDetectionsMsg, RIGHT: TagDetectionsMsg, ODOM: OdometryMsg}
    assert Counter(t for t, _ in items) == {LEFT: 4500, RIGHT: 4500, ODOM: 4500}
    assert source.skipped == {}
    assert source.start_ns == 1_541_777_802_116_735_208
    assert abs((source.end_ns - source.start_ns) * 1e-9 - 224.949) < 1e-3
    for topic in (LEFT, RIGHT, ODOM):
        stamps = np.array([m.stamp_ns for t, m in items if t == topic])
        assert (np.diff(stamps) > 0).all()
        assert 0.049 < np.median(np.diff(stamps)) * 1e-9 < 0.051  # 20 Hz, all three in lock step


def test_detections_have_ids_and_four_corners(
    stream: tuple[BagSource, list[tuple[str, Message]]],
) -> None:
    _, items = stream
    per_topic: Counter[str] = Counter()
    ids: Counter[int] = Counter()
    outside = 0
    for topic, msg in items:
        if isinstance(msg, TagDetectionsMsg):
            assert msg.frame_id == {LEFT: "fla/left_cam", RIGHT: "fla/right_cam"}[topic]
            per_topic[topic] += len(msg.detections)
            for det in msg.detections:
                assert det.family == "tag36h11" and det.corners_px.shape == (4, 2)
                inside = (det.corners_px >= -0.5) & (det.corners_px < [1279.5, 1023.5])
                outside += not inside.all()  # a few corners extrapolated past the image edge
                ids[det.tag_id] += 1
    assert per_topic == {LEFT: 1876, RIGHT: 1759}
    assert outside == 6
    assert len(ids) == 21 and 381 in ids and ids[381] == 1 and ids.most_common(1) == [(6, 1012)]


def test_odometry_frames_and_covariance(
    stream: tuple[BagSource, list[tuple[str, Message]]],
) -> None:
    _, items = stream
    odom = [m for t, m in items if t == ODOM]
    assert all(isinstance(m, OdometryMsg) for m in odom)
    assert {(m.frame_id, m.child_frame_id) for m in odom} == {("vision", "odom")}  # type: ignore[union-attr]
    covs = np.array([m.cov for m in odom])  # type: ignore[union-attr]
    assert np.allclose(covs, covs.transpose(0, 2, 1), atol=1e-12)
    assert (np.linalg.eigvalsh(covs) > -1e-9).all()
    path = np.array([m.T_parent_child.translation for m in odom])  # type: ignore[union-attr]
    assert 100.0 < np.linalg.norm(np.diff(path, axis=0), axis=1).sum() < 200.0  # ~141 m drive


def test_default_options_fail_loudly(cache: Path) -> None:
    with pytest.raises(BagFormatError, match=r"left/tags message 0: tag family is empty"):
        list(BagSource(BAG, cache_dir=cache))
    with pytest.raises(BagFormatError, match="counter-clockwise on screen"):
        list(BagSource(BAG, cache_dir=cache, default_family="tag36h11"))


def test_copy_to_mcap_and_back(
    stream: tuple[BagSource, list[tuple[str, Message]]], tmp_path: Path
) -> None:
    _, items = stream
    with BagSink(tmp_path / "dupont.mcap") as sink:
        for topic, msg in items:
            sink.write(topic, msg)
    back = list(BagSource(tmp_path / "dupont.mcap"))  # tagloc corner order, as written
    assert len(back) == len(items)
    for (t, a), (u, b) in zip(items, back, strict=True):
        assert t == u and a.stamp_ns == b.stamp_ns
        if isinstance(a, OdometryMsg):
            assert isinstance(b, OdometryMsg)
            assert a.T_parent_child.allclose(b.T_parent_child, atol=1e-12)
            assert np.allclose(a.cov, b.cov, rtol=0.0, atol=1e-12 * np.abs(a.cov).max())
        else:
            assert isinstance(a, TagDetectionsMsg) and isinstance(b, TagDetectionsMsg)
            assert [d.tag_id for d in a.detections] == [d.tag_id for d in b.detections]
            for d, e in zip(a.detections, b.detections, strict=True):
                assert np.array_equal(d.corners_px, e.corners_px)
