"""Records -> BagSink -> BagSource -> the same records, for every output format; atomic output.

Tolerances: poses 1e-12 (matrix entries) and covariances 1e-12 relative, through the quaternion
and the parent-frame rotation of ROS; stamps, frames, images, camera infos and corners exactly;
decision margins through float32 (ROS 2) or absent (ROS 1: NaN).
"""

from __future__ import annotations

import gc
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tagloc.geometry import SE3
from tagloc.io import (
    BagSink,
    BagSource,
    BagWriteError,
    CameraInfoMsg,
    GroundTruthMsg,
    ImageMsg,
    Message,
    MessageSink,
    MessageSource,
    OdometryMsg,
    PoseWithCovarianceMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.tags.detection import TagDetection

S = 1_000_000_000
FORMATS = [
    ("mcap", {}, "out.mcap"),
    ("ros2", {"storage": "sqlite3"}, "out_bag"),
    ("ros2", {"storage": "mcap"}, "out_bag"),
    ("ros1", {}, "out.bag"),
]


def make_records(seed: int = 0, n: int = 4) -> list[tuple[str, Message]]:
    """``n`` rounds of one record of every kind, stamps 10 ms apart (some with odd ns)."""
    rng = np.random.default_rng(seed)
    out: list[tuple[str, Message]] = []
    T_base_cam = SE3.random(rng)
    for i in range(n):
        stamp = 1_700_000_000 * S + i * 10_000_000 + 7 * i
        T = SE3.random(rng, translation_scale=10.0)
        A = rng.normal(size=(6, 6))
        cov = A @ A.T
        corners = np.array([[10.0, 10.0], [30.5, 11.0], [31.0, 29.5], [9.5, 30.0]]) + i
        detections = (
            TagDetection(3 + i, "tag36h11", corners, hamming=i % 2, decision_margin=12.3 + i),
            TagDetection(7, "tag25h9", corners + 50.0),
        )
        K = [50.0, 0, 32, 0, 51.0, 24, 0, 0, 1]
        info = {"width": 64, "height": 48, "distortion_model": "equidistant",
                "D": rng.normal(size=4) * 0.01, "K": K}  # fmt: skip
        mono, bgr = (
            rng.integers(0, 256, (6, 9), np.uint8),
            rng.integers(0, 256, (6, 9, 3), np.uint8),
        )
        out += [
            ("/odom", OdometryMsg(stamp, "odom", "base_link", T, cov, rng.normal(size=6))),
            ("/tf", TransformMsg(stamp, "map", "odom", T.inverse())),
            ("/tf_static", TransformMsg(stamp, "base_link", "camera", T_base_cam, static=True)),
            ("/fix", PoseWithCovarianceMsg(stamp, "map", T, 1e-3 * cov)),
            ("/truth", GroundTruthMsg(stamp, "map", T @ T_base_cam)),
            ("/cam/mono", ImageMsg(stamp, "camera", mono, "mono8")),
            ("/cam/bgr", ImageMsg(stamp, "camera", bgr, "bgr8")),
            ("/cam/info", CameraInfoMsg(stamp, "camera", info)),
            ("/cam/tags", TagDetectionsMsg(stamp, "camera", detections if i % 3 else ())),
        ]  # fmt: skip
    return out


def assert_same(a: Message, b: Message, ros1: bool) -> None:
    """Field-by-field equality within the round-trip tolerances (module docstring)."""
    assert type(a) is type(b) and a.stamp_ns == b.stamp_ns
    for name in a.__slots__:  # type: ignore[union-attr]
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, SE3):
            assert np.abs(x.as_matrix() - y.as_matrix()).max() <= 1e-12, name
        elif name == "cov":
            assert np.abs(x - y).max() <= 1e-12 * np.abs(x).max(), name
        elif name == "twist" and x is None:
            assert np.array_equal(y, np.zeros(6))
        elif isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), name
        elif name == "detections":
            assert len(x) == len(y)
            for d, e in zip(x, y, strict=True):
                assert (d.tag_id, d.family, d.hamming) == (e.tag_id, e.family, e.hamming)
                assert np.array_equal(d.corners_px, e.corners_px)
                margin = math.nan if ros1 else float(np.float32(d.decision_margin))
                assert e.decision_margin == margin or (
                    math.isnan(margin) and math.isnan(e.decision_margin)
                )
        elif name == "info":
            expected = {**x, "R": (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0), "binning_x": 0, "binning_y": 0,
                        "P": (*x["K"][:3], 0.0, *x["K"][3:6], 0.0, *x["K"][6:], 0.0),
                        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0,
                                "do_rectify": False}}  # fmt: skip
            assert {k: (dict(v) if k == "roi" else v) for k, v in y.items()} == expected
        else:
            assert x == y, name


def write(path: Path, records: list[tuple[str, Message]], fmt: Any, **kw: Any) -> None:
    sink: MessageSink
    with BagSink(path, fmt, **kw) as sink:
        for topic, msg in records:
            sink.write(topic, msg)


@pytest.mark.parametrize(("fmt", "kw", "name"), FORMATS)
def test_round_trip_every_record(tmp_path: Path, fmt: Any, kw: dict[str, Any], name: str) -> None:
    records = make_records()
    write(tmp_path / name, records, fmt, **kw)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no temporary left behind
    source: MessageSource = BagSource(tmp_path / name)
    back = list(source)
    assert [t for t, _ in back] == [t for t, _ in records]  # log-time order = write order here
    for (_, a), (_, b) in zip(records, back, strict=True):
        assert_same(a, b, ros1=fmt == "ros1")
    assert source.topics["/tf_static"] is TransformMsg
    assert all(m.static for t, m in back if t == "/tf_static")  # type: ignore[union-attr]
    assert source.skipped == {}


def test_topics_can_be_selected_and_renamed(tmp_path: Path) -> None:
    write(tmp_path / "a.mcap", make_records(), "mcap")
    source = BagSource(tmp_path / "a.mcap", {"/odom": "odometry", "/cam/tags": "tags"})
    assert source.topics == {"odometry": OdometryMsg, "tags": TagDetectionsMsg}
    assert {t for t, _ in source} == {"odometry", "tags"}
    assert source.bag_topics["/odom"].msgtype == "nav_msgs/msg/Odometry"
    assert source.bag_topics["/cam/tags"].msgcount == 4
    only = BagSource(tmp_path / "a.mcap", "/truth")  # one topic as a plain string
    assert len(list(only)) == 4 and len(list(only)) == 4  # a source can be iterated again


def test_log_time_can_differ_from_the_stamp(tmp_path: Path) -> None:
    T = SE3.identity()
    with BagSink(tmp_path / "a.mcap") as sink:
        sink.write("/truth", GroundTruthMsg(5 * S, "map", T), log_time_ns=9 * S)
        sink.write("/truth", GroundTruthMsg(6 * S, "map", T), log_time_ns=10 * S)
    assert [m.stamp_ns for _, m in BagSource(tmp_path / "a.mcap")] == [5 * S, 6 * S]
    assert [m.stamp_ns for _, m in BagSource(tmp_path / "a.mcap", stamp="log")] == [9 * S, 10 * S]


def _copy(reader: Any, writer: Any, digest: str) -> None:
    """Every connection and message of a rosbags reader into a writer (its own compression);
    ``digest``: the writer's name for the message definition's hash."""
    with reader, writer:
        conns = {
            c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data,
                                        **{digest: c.digest})
            for c in reader.connections
        }  # fmt: skip
        for conn, stamp, raw in reader.messages():
            writer.write(conns[conn.id], stamp, raw)


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_ros1_compressed_chunks_are_read(tmp_path: Path, compression: str) -> None:
    from rosbags.rosbag1 import Reader, Writer

    records = make_records(seed=1)
    write(tmp_path / "plain.bag", records, "ros1")
    out = Writer(tmp_path / "packed.bag")
    out.set_compression(Writer.CompressionFormat[compression.upper()])
    _copy(Reader(tmp_path / "plain.bag"), out, "md5sum")
    back = list(BagSource(tmp_path / "packed.bag"))
    assert len(back) == len(records)
    for (_, a), (_, b) in zip(records, back, strict=True):
        assert_same(a, b, ros1=True)


def test_ros2_zstd_compressed_bag_is_read(tmp_path: Path) -> None:
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, Writer

    records = make_records(seed=2)
    write(tmp_path / "plain", records, "ros2")
    out = Writer(tmp_path / "packed", version=Writer.VERSION_LATEST)
    out.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    _copy(Reader(tmp_path / "plain"), out, "rihs01")
    back = list(BagSource(tmp_path / "packed"))
    for (_, a), (_, b) in zip(records, back, strict=True):
        assert_same(a, b, ros1=False)


@pytest.mark.parametrize(("fmt", "kw", "name"), FORMATS)
def test_an_exception_leaves_no_output(
    tmp_path: Path, fmt: Any, kw: dict[str, Any], name: str
) -> None:
    with pytest.raises(RuntimeError, match="crash"), BagSink(tmp_path / name, fmt, **kw) as sink:
        for topic, msg in make_records()[:5]:
            sink.write(topic, msg)
        raise RuntimeError("crash")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("fmt", "kw", "name"), FORMATS)
def test_overwrite_replaces_only_on_close(
    tmp_path: Path, fmt: Any, kw: dict[str, Any], name: str
) -> None:
    target = tmp_path / name
    write(target, make_records(seed=3, n=1), fmt, **kw)
    with pytest.raises(BagWriteError, match="exists already; pass overwrite=True"):
        BagSink(target, fmt, **kw)
    with pytest.raises(RuntimeError), BagSink(target, fmt, overwrite=True, **kw) as sink:
        sink.write(*make_records(seed=4, n=1)[0])
        raise RuntimeError("crash")
    assert len(list(BagSource(target))) == 9  # the old bag, untouched
    write(target, make_records(seed=4, n=2), fmt, overwrite=True, **kw)
    assert len(list(BagSource(target))) == 18
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_writer_rejects_records_that_do_not_fit(tmp_path: Path) -> None:
    T = SE3.identity()
    sink = BagSink(tmp_path / "a.mcap")
    sink.write("/truth", GroundTruthMsg(1, "map", T))
    with pytest.raises(BagWriteError, match="/truth: carries GroundTruthMsg, got TransformMsg"):
        sink.write("/truth", TransformMsg(2, "map", "odom", T))
    with pytest.raises(BagWriteError, match="static=True transform map -> odom on a topic not"):
        sink.write("/tf", TransformMsg(2, "map", "odom", T, static=True))
    with pytest.raises(BagWriteError, match="static=False transform map -> odom on a topic named"):
        sink.write("/tf_static", TransformMsg(2, "map", "odom", T))
    with pytest.raises(BagWriteError, match="not a tagloc record: dict"):
        sink.write("/x", {})  # type: ignore[arg-type]
    sink.close()
    sink.close()
    with pytest.raises(BagWriteError, match="write after close"):
        sink.write("/truth", GroundTruthMsg(3, "map", T))
    assert len(list(BagSource(tmp_path / "a.mcap"))) == 1


def test_an_unclosed_sink_cleans_up_when_collected(tmp_path: Path) -> None:
    sink = BagSink(tmp_path / "a.bag", "ros1")
    sink.write(*make_records(n=1)[0])
    del sink
    gc.collect()
    assert list(tmp_path.iterdir()) == []
