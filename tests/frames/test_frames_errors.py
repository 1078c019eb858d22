"""Every error the buffer raises, with the message content that makes it actionable."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.errors import (
    DisconnectedFramesError,
    ExtrapolationError,
    FrameTreeError,
    GeometryError,
    TaglocError,
    TransformLookupError,
    UnknownFrameError,
)
from tagloc.frames import StaleSampleError, StampError, TransformBuffer
from tagloc.geometry import SE3

S = 1_000_000_000


@pytest.fixture
def buffer() -> TransformBuffer:
    buffer = TransformBuffer()
    for stamp in (10 * S, 11 * S, 12 * S):
        buffer.set_transform("map", "odom", stamp, SE3.identity())
    for stamp in (10 * S + 500_000_000, 12 * S + 250_000_000):
        buffer.set_transform("odom", "base_link", stamp, SE3.identity())
    buffer.set_static("base_link", "camera", SE3.identity())
    buffer.set_static("world", "elevator_cab", SE3.identity())
    return buffer


def test_unknown_frame_lists_known_frames_and_suggests(buffer: TransformBuffer) -> None:
    with pytest.raises(UnknownFrameError) as info:
        buffer.lookup("map", "camra", 11 * S)
    message = str(info.value)
    assert "unknown frame 'camra'" in message
    assert "'base_link', 'camera', 'elevator_cab', 'map', 'odom', 'world'" in message
    assert "did you mean 'camera'?" in message
    assert isinstance(info.value, TransformLookupError)
    assert isinstance(info.value, LookupError)
    with pytest.raises(UnknownFrameError, match="known frames: none yet"):
        TransformBuffer().lookup("map", "odom", 0)
    with pytest.raises(UnknownFrameError, match="unknown frame 'nowhere'"):
        buffer.lookup_many("nowhere", "map", np.array([0]))


def test_disconnected_trees_name_both_roots(buffer: TransformBuffer) -> None:
    with pytest.raises(DisconnectedFramesError) as info:
        buffer.lookup("camera", "elevator_cab", 11 * S)
    message = str(info.value)
    assert "'camera' is in the tree rooted at 'map'" in message
    assert "'elevator_cab' in the tree rooted at 'world'" in message


def test_extrapolation_after_newest_names_edge_range_and_gap(buffer: TransformBuffer) -> None:
    with pytest.raises(ExtrapolationError) as info:
        buffer.lookup("map", "camera", 12 * S + 300_000_000)
    message = str(info.value)
    assert "T_map_camera at 12.300000000 s (12300000000 ns)" in message
    assert "edge 'odom' -> 'base_link' holds 10.500000000 s (10500000000 ns) to " in message
    assert "12.250000000 s (12250000000 ns)" in message
    assert "the stamp is 0.050000000 s after the newest sample" in message
    assert "edge 'map' -> 'odom' holds 10.000000000 s (10000000000 ns) to 12.000000000 s" in (
        message
    )  # both failing edges are named
    assert "tolerance 0.000000000 s (0 ns)" in message


def test_extrapolation_before_oldest_names_only_the_failing_edge(
    buffer: TransformBuffer,
) -> None:
    with pytest.raises(ExtrapolationError) as info:
        buffer.lookup("camera", "map", 10 * S + 100_000_000)
    message = str(info.value)
    assert "T_camera_map" in message
    assert "'odom' -> 'base_link'" in message
    assert "'map' -> 'odom'" not in message
    assert "the stamp is 0.400000000 s before the oldest sample" in message


def test_extrapolation_in_lookup_many_counts_stamps(buffer: TransformBuffer) -> None:
    stamps = np.array([11 * S, 13 * S, 14 * S, 9 * S])
    with pytest.raises(ExtrapolationError) as info:
        buffer.lookup_many("map", "base_link", stamps)
    message = str(info.value)
    assert "at 4 stamps from 9.000000000 s (9000000000 ns) to 14.000000000 s" in message
    assert "3 stamps fall outside, the first at 13.000000000 s (13000000000 ns)" in message


def test_negative_stamps_format_exactly() -> None:
    buffer = TransformBuffer()
    buffer.set_transform("a", "b", -1_500_000_001, SE3.identity())
    with pytest.raises(ExtrapolationError, match=r"holds -1\.500000001 s \(-1500000001 ns\)"):
        buffer.lookup("a", "b", 0)


def test_second_parent_names_the_existing_parent(buffer: TransformBuffer) -> None:
    with pytest.raises(FrameTreeError) as info:
        buffer.set_transform("map", "base_link", 11 * S, SE3.identity())
    assert "frame 'base_link' already has parent 'odom'" in str(info.value)
    assert "cannot also attach it to 'map'" in str(info.value)
    with pytest.raises(FrameTreeError, match="already has parent 'base_link'"):
        buffer.set_static("odom", "camera", SE3.identity())


def test_self_edge_and_cycle(buffer: TransformBuffer) -> None:
    with pytest.raises(FrameTreeError, match="self-edge 'map' -> 'map'"):
        buffer.set_static("map", "map", SE3.identity())
    with pytest.raises(FrameTreeError) as info:
        buffer.set_static("camera", "map", SE3.identity())
    assert "would close a cycle: 'camera' is already below 'map'" in str(info.value)
    assert "('map' -> 'odom' -> 'base_link' -> 'camera')" in str(info.value)
    assert buffer.can_transform("map", "camera", 11 * S)  # the tree is unchanged
    assert buffer.frames == ("base_link", "camera", "elevator_cab", "map", "odom", "world")


def test_edge_kind_cannot_change(buffer: TransformBuffer) -> None:
    with pytest.raises(FrameTreeError, match="edge 'base_link' -> 'camera' is static"):
        buffer.set_transform("base_link", "camera", 11 * S, SE3.identity())
    with pytest.raises(FrameTreeError, match="edge 'map' -> 'odom' is dynamic"):
        buffer.set_static("map", "odom", SE3.identity())


@pytest.mark.parametrize("name", ["", 3, None])
def test_bad_frame_names(name: object) -> None:
    with pytest.raises(FrameTreeError, match="non-empty frame name"):
        TransformBuffer().set_static(name, "b", SE3.identity())  # type: ignore[arg-type]


def test_nan_and_inf_transforms_are_refused() -> None:
    with np.errstate(over="ignore", invalid="ignore"):
        big = SE3.from_rotvec([0.0, 0.0, 0.5], [1e308, 0.0, 0.0])
        T_inf = big @ big  # translation overflows
        T_nan = SE3.from_rotvec([0.0, 0.0, 1.0], [0.0, 0.0, 0.0]) @ T_inf  # 0 * inf
    assert not np.isfinite(T_inf.translation).all()
    assert np.isnan(T_nan.translation).any()
    buffer = TransformBuffer()
    for T in (T_inf, T_nan):
        with pytest.raises(GeometryError, match=r"edge 'odom' -> 'base_link'.*NaN or inf"):
            buffer.set_transform("odom", "base_link", 0, T)
        with pytest.raises(GeometryError, match="NaN or inf"):
            buffer.set_static("base_link", "camera", T)
        batch = SE3.stack([SE3.identity(), T])
        with pytest.raises(GeometryError, match=r"NaN or inf \(first at index 1\)"):
            buffer.set_transforms("odom", "base_link", np.array([0, 1]), batch)
    assert buffer.frames == ()  # nothing was attached


def test_wrong_transform_types_and_shapes() -> None:
    buffer = TransformBuffer()
    with pytest.raises(GeometryError, match="expected an SE3, got ndarray"):
        buffer.set_transform("a", "b", 0, np.eye(4))  # type: ignore[arg-type]
    batch = SE3.stack([SE3.identity(), SE3.identity()])
    with pytest.raises(GeometryError, match="got a batch of 2 \\(use set_transforms\\)"):
        buffer.set_transform("a", "b", 0, batch)
    with pytest.raises(GeometryError, match="3 stamps but 2 transforms"):
        buffer.set_transforms("a", "b", np.array([0, 1, 2]), batch)


@pytest.mark.parametrize("stamp", [1.5, 1e9, True, "10", np.float64(3.0), 2**63])
def test_non_integer_stamps(stamp: object) -> None:
    buffer = TransformBuffer()
    buffer.set_transform("a", "b", 0, SE3.identity())
    for call in (
        lambda: buffer.set_transform("a", "b", stamp, SE3.identity()),  # type: ignore[arg-type]
        lambda: buffer.lookup("a", "b", stamp),  # type: ignore[arg-type]
        lambda: buffer.can_transform("a", "b", stamp),  # type: ignore[arg-type]
    ):
        with pytest.raises(StampError, match="stamp_ns") as info:
            call()
        assert isinstance(info.value, TypeError)
        assert isinstance(info.value, TaglocError)


def test_float_stamp_message_hints_at_seconds() -> None:
    with pytest.raises(StampError, match=r"got float 1\.5 \(seconds\? use int\(round"):
        TransformBuffer().lookup("a", "b", 1.5)  # type: ignore[arg-type]


def test_stamp_arrays() -> None:
    buffer = TransformBuffer()
    buffer.set_transforms(
        "a", "b", np.array([0, 10], dtype=np.int32), SE3.stack([SE3.identity()] * 2)
    )
    buffer.set_transform("a", "b", np.int64(20), SE3.identity())  # numpy integers are fine
    buffer.lookup_many("a", "b", np.array([1, 2], dtype=np.uint16))
    for stamps, pattern in (
        (np.array([0.0, 1.0]), "integer \\(int64\\) array .* got dtype float64"),
        (np.array([True, False]), "got dtype bool"),
        (np.zeros((2, 2), dtype=np.int64), "1-D array, got shape \\(2, 2\\)"),
        (np.array([], dtype=np.int64), "non-empty"),
        (np.array([2**63], dtype=np.uint64), "outside the int64 range"),
    ):
        with pytest.raises(StampError, match=pattern):
            buffer.lookup_many("a", "b", stamps)


def test_stale_sample_names_edge_and_window() -> None:
    buffer = TransformBuffer()
    buffer.set_transform("odom", "base_link", 20 * S, SE3.identity())
    with pytest.raises(StaleSampleError) as info:
        buffer.set_transform("odom", "base_link", 9 * S, SE3.identity())
    message = str(info.value)
    assert "edge 'odom' -> 'base_link': sample at 9.000000000 s (9000000000 ns)" in message
    assert "newest is 20.000000000 s" in message
    assert "window 10.000000000 s (10000000000 ns)" in message
    assert isinstance(info.value, ValueError)


def test_edge_inspection_errors(buffer: TransformBuffer) -> None:
    with pytest.raises(TransformLookupError, match="'base_link' -> 'camera' is static"):
        buffer.stamp_range("base_link", "camera")
    with pytest.raises(TransformLookupError, match="no edge 'map' -> 'base_link': its parent is"):
        buffer.latest_stamp("map", "base_link")
    with pytest.raises(TransformLookupError, match="no edge 'odom' -> 'map': it is a root"):
        buffer.num_samples("odom", "map")
    with pytest.raises(UnknownFrameError, match="unknown frame 'odm' in edge 'odm' -> 'base"):
        buffer.stamp_range("odm", "base_link")


def test_can_transform_is_false_for_every_lookup_failure(buffer: TransformBuffer) -> None:
    assert buffer.can_transform("map", "camera", 11 * S)
    assert not buffer.can_transform("map", "nowhere", 11 * S)
    assert not buffer.can_transform("camera", "elevator_cab", 11 * S)
    assert not buffer.can_transform("map", "camera", 13 * S)


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"window_ns": 0}, ValueError),
        ({"extrapolation_tolerance_ns": -1}, ValueError),
        ({"window_ns": 10.0}, StampError),
    ],
)
def test_bad_buffer_parameters(kwargs: dict[str, object], error: type[Exception]) -> None:
    with pytest.raises(error):
        TransformBuffer(**kwargs)  # type: ignore[arg-type]


def test_every_error_is_a_tagloc_error() -> None:
    for cls in (
        StampError,
        StaleSampleError,
        UnknownFrameError,
        DisconnectedFramesError,
        ExtrapolationError,
        FrameTreeError,
        GeometryError,
    ):
        assert issubclass(cls, TaglocError)
