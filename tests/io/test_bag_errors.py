"""Bad input to BagSource: missing and damaged files, topics, bad content (skip or error).

Bad content is written straight with ``rosbags`` (tagloc's own records refuse it): valid records
are encoded with the writer's encoder, then a field of the ROS message is broken.
"""

from __future__ import annotations

import bz2
import logging
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from tagloc.geometry import SE3
from tagloc.io import (
    BagFormatError,
    BagSink,
    BagSource,
    BagTopicError,
    GroundTruthMsg,
    ImageMsg,
    InputNotFoundError,
    OdometryMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.io.convert import make_typestore
from tagloc.io.encode import RosEncoder
from tagloc.tags.detection import TagDetection

S = 1_000_000_000
ENC = RosEncoder(2)
SQUARE = np.array([[10.0, 10.0], [30.0, 10.0], [30.0, 30.0], [10.0, 30.0]])  # tl, tr, br, bl


def raw_bag(path: Path, items: list[tuple[str, str, Any, int]]) -> Path:
    """An MCAP of ``(topic, msgtype, ros message, log time)``, serialized as is."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = make_typestore(2)
    conns: dict[str, Any] = {}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, msgtype, msg, log_ns in items:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], log_ns, store.serialize_cdr(msg, msgtype))
    return path


def odom(stamp_ns: int, **changes: float) -> tuple[str, str, Any, int]:
    msg = ENC.encode(OdometryMsg(stamp_ns, "odom", "base", SE3.identity(), np.eye(6)), 0)
    for name, value in changes.items():
        target = msg.pose.pose.orientation if name.startswith("q") else msg.pose.pose.position
        setattr(target, name[-1], value)
    return "/odom", "nav_msgs/msg/Odometry", msg, stamp_ns


def tags(
    stamp_ns: int, corners: Any, family: str = "tag36h11", n: int = 1
) -> tuple[str, str, Any, int]:
    det = TagDetection(4, "tag36h11", SQUARE)
    msg = ENC.encode(TagDetectionsMsg(stamp_ns, "cam", (det,) * n), 0)
    for d in msg.detections:
        d.family = family
        for point, (u, v) in zip(d.corners, corners, strict=True):
            point.x, point.y = u, v
    return "/tags", "apriltag_msgs/msg/AprilTagDetectionArray", msg, stamp_ns


# ----- files --------------------------------------------------------------------------------------
def test_missing_path(tmp_path: Path) -> None:
    with pytest.raises(InputNotFoundError, match=r"nope\.bag: no such bag") as info:
        BagSource(tmp_path / "nope.bag")
    assert isinstance(info.value, FileNotFoundError)


def test_unknown_extension_and_directory_without_metadata(tmp_path: Path) -> None:
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(BagFormatError, match=r"x\.txt: unknown bag extension '\.txt'"):
        BagSource(tmp_path / "x.txt")
    with pytest.raises(BagFormatError, match=r"without metadata\.yaml is not a ROS 2 bag"):
        BagSource(tmp_path)


@pytest.mark.parametrize(("fmt", "name", "damaged"), [
    ("mcap", "a.mcap", "a.mcap"), ("ros1", "a.bag", "a.bag"), ("ros2", "a", "a/a.db3"),
])  # fmt: skip
def test_truncated_bag_is_one_clear_error(
    tmp_path: Path, fmt: Any, name: str, damaged: str
) -> None:
    with BagSink(tmp_path / name, fmt) as sink:
        for i in range(200):
            sink.write("/truth", GroundTruthMsg(i * S, "map", SE3.identity()))
    data = (tmp_path / damaged).read_bytes()
    (tmp_path / damaged).write_bytes(data[: len(data) // 2])
    with pytest.raises(BagFormatError) as info:
        list(BagSource(tmp_path / name))
    text = str(info.value)
    assert "\n" not in text and text.startswith(f"{tmp_path / name}: cannot open as ")


def test_damage_found_while_reading_stops_with_one_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """rosbags reads lazily: a bad chunk deep in a large file surfaces during iteration."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import ReaderError

    path = raw_bag(tmp_path / "a.mcap", [odom(S), odom(2 * S)])
    real = AnyReader.messages

    def damaged(self: Any, *args: Any, **kwargs: Any) -> Any:
        yield next(real(self, *args, **kwargs))
        raise ReaderError("Invalid chunk record length 3 or nested chunk.")

    monkeypatch.setattr(AnyReader, "messages", damaged)
    got = []
    with pytest.raises(
        BagFormatError, match=r"a\.mcap: damaged data, reading stopped \(Invalid chunk"
    ):
        got.extend(BagSource(path))
    assert len(got) == 1


def test_bz2_compressed_file_is_decompressed_once_into_a_cache(tmp_path: Path) -> None:
    with BagSink(tmp_path / "a.bag", "ros1") as sink:
        sink.write("/truth", GroundTruthMsg(S, "map", SE3.identity()))
    packed = tmp_path / "a.bag.bz2"
    packed.write_bytes(bz2.compress((tmp_path / "a.bag").read_bytes()))
    before = packed.read_bytes()
    cache = tmp_path / "cache"
    assert len(list(BagSource(packed, cache_dir=cache))) == 1
    (cached,) = cache.rglob("a.bag")
    mtime = cached.stat().st_mtime_ns
    assert len(list(BagSource(packed, cache_dir=cache))) == 1
    assert cached.stat().st_mtime_ns == mtime and packed.read_bytes() == before
    (tmp_path / "b.bag.bz2").write_bytes(before[: len(before) // 2])
    with pytest.raises(BagFormatError, match=r"b\.bag\.bz2: cannot decompress"):
        BagSource(tmp_path / "b.bag.bz2", cache_dir=cache)
    assert not list(cache.rglob("b.bag*"))


def test_bz2_bomb_is_refused_before_it_fills_the_disk(tmp_path: Path) -> None:
    packed = tmp_path / "bomb.bag.bz2"
    packed.write_bytes(bz2.compress(bytes(65 * 2**20)))  # 65 MiB of zeros in ~200 bytes
    cache = tmp_path / "cache"
    with pytest.raises(
        BagFormatError, match=r"^\S*bomb\.bag\.bz2: decompresses to more than 67108864 bytes"
    ):
        BagSource(packed, cache_dir=cache)
    assert not [p for p in cache.rglob("*") if p.is_file()]


# ----- topics -------------------------------------------------------------------------------------
def test_missing_topic_lists_what_the_bag_has(tmp_path: Path) -> None:
    path = raw_bag(tmp_path / "a.mcap", [odom(S)])
    with pytest.raises(
        BagTopicError, match=r"no topic '/tf'; the bag has /odom \(nav_msgs/msg/Odometry, 1\)"
    ):
        BagSource(path, ["/tf"])


def test_unsupported_type_on_a_requested_topic(tmp_path: Path) -> None:
    store = make_typestore(2)
    text = store.types["std_msgs/msg/String"](data="hello")
    path = raw_bag(tmp_path / "a.mcap", [odom(S), ("/chat", "std_msgs/msg/String", text, S)])
    with pytest.raises(
        BagFormatError, match="'/chat' has type std_msgs/msg/String, which tagloc does not read"
    ):
        BagSource(path, ["/chat"])
    assert BagSource(path).topics == {"/odom": OdometryMsg}  # left out by default
    only = raw_bag(tmp_path / "b.mcap", [("/chat", "std_msgs/msg/String", text, S)])
    with pytest.raises(BagTopicError, match="no topic of a type tagloc reads"):
        BagSource(only)


# ----- content ------------------------------------------------------------------------------------
def test_nan_odometry_is_a_counted_skip_or_an_error(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = raw_bag(
        tmp_path / "a.mcap",
        [odom(S), odom(2 * S, x=math.nan), odom(3 * S, qw=math.inf), odom(4 * S)],
    )
    source = BagSource(path)
    with caplog.at_level(logging.WARNING, logger="tagloc.io.bag_reader"):
        stamps = [m.stamp_ns for _, m in source]
    assert stamps == [S, 4 * S] and source.skipped == {"non_finite": 2}
    assert (
        sum("skipped (non_finite)" in r.message for r in caplog.records) == 1
    )  # once, then counted
    assert "skipped {'non_finite': 2}" in caplog.records[-1].message
    with pytest.raises(
        BagFormatError, match=r"a\.mcap: /odom message 1: non_finite: pose holds NaN"
    ):
        list(BagSource(path, on_bad="error"))


def test_duplicate_and_backwards_stamps_are_counted(tmp_path: Path) -> None:
    items = [odom(S), odom(S), odom(3 * S), odom(2 * S), odom(4 * S)]
    items[3] = (*items[3][:3], 3 * S)  # logged in order, header stamp goes back
    source = BagSource(raw_bag(tmp_path / "a.mcap", items))
    assert [m.stamp_ns for _, m in source] == [S, 3 * S, 4 * S]
    assert source.skipped == {"duplicate_stamp": 1, "stamp_backwards": 1}
    with pytest.raises(BagFormatError, match="message 1: duplicate_stamp"):
        list(BagSource(tmp_path / "a.mcap", on_bad="error"))


def test_transform_stamps_are_checked_per_child_frame(tmp_path: Path) -> None:
    def tf(stamp: int, child: str, topic: str = "/tf") -> tuple[str, str, Any, int]:
        msg = ENC.encode(
            TransformMsg(stamp, "map", child, SE3.identity(), topic == "/tf_static"), 0
        )
        log_ns.append(log_ns[-1] + 1)
        return topic, "tf2_msgs/msg/TFMessage", msg, log_ns[-1]

    log_ns = [S]
    items = [
        tf(S, "a"),
        tf(S, "b"),
        tf(2 * S, "a"),
        tf(S, "b"),
        tf(0, "c", "/tf_static"),
        tf(0, "c", "/tf_static"),
    ]
    source = BagSource(raw_bag(tmp_path / "a.mcap", items))
    got = [(t, m.child, m.stamp_ns) for t, m in source]  # type: ignore[union-attr]
    assert got == [
        ("/tf", "a", S),
        ("/tf", "b", S),
        ("/tf", "a", 2 * S),
        ("/tf_static", "c", 0),
        ("/tf_static", "c", 0),
    ]
    assert source.skipped == {"duplicate_stamp": 1}


def test_quaternions_are_renormalized_within_tolerance(tmp_path: Path) -> None:
    path = raw_bag(
        tmp_path / "a.mcap", [odom(S, qw=1.0 + 1e-5), odom(2 * S, qw=1.01), odom(3 * S, qw=0.0)]
    )
    source = BagSource(path)
    (only,) = list(source)
    assert only[1].T_parent_child.allclose(SE3.identity(), atol=1e-15)  # type: ignore[union-attr]
    assert source.skipped == {"bad_quaternion": 2}
    assert len(list(BagSource(path, quat_tol=0.02))) == 2


def test_raw_images_are_converted_to_mono8_or_bgr8(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, (5, 7, 3), np.uint8)
    msg_rgb = ENC.encode(ImageMsg(S, "cam", rgb, "bgr8"), 0)
    msg_rgb.encoding = "rgb8"
    gray = rng.integers(0, 256, (5, 7), np.uint8)
    padded = np.zeros((5, 12), np.uint8)
    padded[:, :7] = gray
    msg_pad = ENC.encode(ImageMsg(2 * S, "cam", padded, "mono8"), 0)
    msg_pad.width, msg_pad.encoding = 7, "8UC1"
    msg_16 = ENC.encode(ImageMsg(3 * S, "cam", gray, "mono8"), 0)
    msg_16.encoding = "mono16"
    t = "sensor_msgs/msg/Image"
    source = BagSource(
        raw_bag(tmp_path / "a.mcap", [("/img", t, m, S) for m in (msg_rgb, msg_pad, msg_16)])
    )
    (_, a), (_, b) = list(source)
    assert a.encoding == "bgr8" and np.array_equal(a.image, rgb[..., ::-1])  # type: ignore[union-attr]
    assert b.encoding == "mono8" and np.array_equal(b.image, gray)  # type: ignore[union-attr]
    assert source.skipped == {"unsupported_encoding": 1}


def test_compressed_images_are_decoded_with_opencv(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    bgr = rng.integers(0, 256, (8, 10, 3), np.uint8)
    gray = rng.integers(0, 256, (8, 10), np.uint8)
    store = make_typestore(2)
    T = store.types

    def compressed(stamp: int, fmt: str, data: bytes) -> tuple[str, str, Any, int]:
        header = T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](stamp // S, 0), "cam")
        msg = T["sensor_msgs/msg/CompressedImage"](header, fmt, np.frombuffer(data, np.uint8))
        return "/img/compressed", "sensor_msgs/msg/CompressedImage", msg, stamp

    png = cv2.imencode(".png", bgr)[1].tobytes()
    png_gray = cv2.imencode(".png", gray)[1].tobytes()
    jpeg = cv2.imencode(".jpg", gray)[1].tobytes()
    items = [
        compressed(S, "png", png),
        compressed(2 * S, "png", png_gray),
        compressed(3 * S, "jpeg", jpeg),
        compressed(4 * S, "jpeg", b"not an image"),
        compressed(5 * S, "png", b""),  # OpenCV raises on an empty buffer
    ]
    source = BagSource(raw_bag(tmp_path / "a.mcap", items))
    a, b, c = (m for _, m in source)
    assert a.encoding == "bgr8" and np.array_equal(a.image, bgr)  # type: ignore[union-attr]
    assert b.encoding == "mono8" and np.array_equal(b.image, gray)  # type: ignore[union-attr]
    assert c.encoding == "mono8" and c.image.shape == (8, 10)  # type: ignore[union-attr]
    assert source.skipped == {"undecodable": 2}


def test_tag_corner_order_and_family_options(tmp_path: Path) -> None:
    ccw = SQUARE[[3, 2, 1, 0]]  # bl, br, tr, tl: how the AprilTag 3 library lists them
    path = raw_bag(tmp_path / "a.mcap", [tags(S, ccw, family="36h11")])
    with pytest.raises(
        BagFormatError, match=r"corner_order='tl_tr_br_bl' run counter-clockwise.*'bl_br_tr_tl'"
    ):
        list(BagSource(path, on_bad="skip"))  # a wrong option is never skipped silently
    ((_, msg),) = list(BagSource(path, corner_order="bl_br_tr_tl", pixel_offset=0.5))
    assert isinstance(msg, TagDetectionsMsg) and msg.detections[0].family == "tag36h11"
    assert np.array_equal(msg.detections[0].corners_px, SQUARE - 0.5)

    empty = raw_bag(tmp_path / "b.mcap", [tags(S, SQUARE, family="")])
    with pytest.raises(
        BagFormatError, match=r"/tags message 0: tag family is empty.*default_family="
    ):
        list(BagSource(empty))
    ((_, msg),) = list(BagSource(empty, default_family="tag36h11"))
    assert msg.detections[0].family == "tag36h11"  # type: ignore[union-attr]


def test_bad_detections_are_dropped_and_the_array_kept(tmp_path: Path) -> None:
    bowtie = SQUARE[[0, 2, 1, 3]]
    items = [
        tags(S, bowtie, n=2),
        tags(2 * S, SQUARE, family="tagCircle21h7"),
        tags(3 * S, SQUARE, family="tf36h11"),
    ]
    source = BagSource(raw_bag(tmp_path / "a.mcap", items))
    counts = [len(m.detections) for _, m in source]  # type: ignore[union-attr]
    assert counts == [0, 0, 1]
    assert source.skipped == {"bad_detection": 2, "unknown_family": 1}
    with pytest.raises(
        BagFormatError, match="message 0: bad_detection: tag tag36h11:4 corners_px: not a convex"
    ):
        list(BagSource(tmp_path / "a.mcap", on_bad="error"))


def test_invalid_record_fields_are_counted(tmp_path: Path) -> None:
    msg = ENC.encode(TransformMsg(S, "map", "odom", SE3.identity()), 0)
    msg.transforms[0].child_frame_id = ""
    source = BagSource(raw_bag(tmp_path / "a.mcap", [("/tf", "tf2_msgs/msg/TFMessage", msg, S)]))
    assert list(source) == [] and source.skipped == {"invalid_record": 1}
