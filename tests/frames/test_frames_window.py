"""The bounded window, out-of-order and duplicate samples, and batched insertion."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tagloc.errors import ExtrapolationError
from tagloc.frames import StaleSampleError, TransformBuffer
from tagloc.geometry import SE3

MS = 1_000_000
S = 1_000_000_000


def _random_poses(rng: np.random.Generator, n: int | None = None) -> SE3:
    quat_xyzw = Rotation.random(n, random_state=rng).as_quat()
    return SE3.from_quat(quat_xyzw, rng.normal(size=(3,) if n is None else (n, 3)))


def _shifted(x: float) -> SE3:
    return SE3.from_rotvec([0.0, 0.0, 0.1 * x], [x, 0.0, 0.0])


def test_long_stream_keeps_memory_bounded() -> None:
    """120 s of 1 kHz odometry through a 10 s window: 10 s of samples, constant storage."""
    buffer = TransformBuffer()  # 10 s window
    poses = _random_poses(np.random.default_rng(0), 16)
    T = [poses[i] for i in range(16)]
    nbytes = {}
    for k in range(120_001):
        buffer.set_transform("odom", "base_link", k * MS, T[k % 16])
        if k in (30_000, 60_000, 120_000):
            nbytes[k] = buffer.nbytes
    assert buffer.num_samples("odom", "base_link") == 10_001  # both window ends kept
    assert buffer.stamp_range("odom", "base_link") == (110 * S, 120 * S)
    bytes_per_sample = 8 + 7 * 8
    assert nbytes[120_000] <= 2 * 10_002 * bytes_per_sample
    assert nbytes[60_000] == nbytes[120_000]  # steady state: no growth
    with pytest.raises(ExtrapolationError):
        buffer.lookup("odom", "base_link", 110 * S - 1)


def test_long_batched_stream_keeps_memory_bounded() -> None:
    buffer = TransformBuffer(window_ns=2 * S)
    poses = _random_poses(np.random.default_rng(1), 500)
    for chunk in range(200):  # 100 s at 1 kHz in chunks of 500 samples
        stamps = (chunk * 500 + np.arange(500, dtype=np.int64)) * MS
        buffer.set_transforms("odom", "base_link", stamps, poses)
    assert buffer.num_samples("odom", "base_link") == 2001
    assert buffer.nbytes <= 2 * (2001 + 500) * 64


def test_window_boundary_is_inclusive() -> None:
    buffer = TransformBuffer(window_ns=100)
    buffer.set_transform("a", "b", 0, _shifted(0))
    buffer.set_transform("a", "b", 1, _shifted(1))
    buffer.set_transform("a", "b", 100, _shifted(100))
    assert buffer.stamp_range("a", "b") == (0, 100)  # 0 == newest - window: kept
    buffer.set_transform("a", "b", 101, _shifted(101))
    assert buffer.stamp_range("a", "b") == (1, 101)
    assert buffer.num_samples("a", "b") == 3


def test_out_of_order_sample_is_inserted_in_place() -> None:
    buffer = TransformBuffer()
    buffer.set_transform("a", "b", 0, _shifted(0.0))
    buffer.set_transform("a", "b", 20 * MS, _shifted(2.0))
    buffer.set_transform("a", "b", 10 * MS, _shifted(5.0))  # late
    buffer.set_transform("a", "b", -5 * MS, _shifted(-1.0))  # late, before the oldest
    assert buffer.num_samples("a", "b") == 4
    assert buffer.stamp_range("a", "b") == (-5 * MS, 20 * MS)
    np.testing.assert_allclose(buffer.lookup("a", "b", 10 * MS).translation, [5.0, 0, 0])
    np.testing.assert_allclose(buffer.lookup("a", "b", 15 * MS).translation, [3.5, 0, 0])
    np.testing.assert_allclose(buffer.lookup("a", "b", -5 * MS).translation, [-1.0, 0, 0])


def test_random_arrival_order_equals_sorted_insertion() -> None:
    rng = np.random.default_rng(2)
    stamps = np.cumsum(rng.integers(1, 5 * MS, size=400))
    poses = _random_poses(rng, 400)
    in_order, shuffled = TransformBuffer(), TransformBuffer()
    for i in range(400):
        in_order.set_transform("a", "b", int(stamps[i]), poses[i])
    for i in rng.permutation(400).tolist():
        shuffled.set_transform("a", "b", int(stamps[i]), poses[i])
    assert shuffled.num_samples("a", "b") == 400
    query = rng.integers(stamps[0], stamps[-1], size=300)
    np.testing.assert_allclose(
        shuffled.lookup_many("a", "b", query).as_matrix(),
        in_order.lookup_many("a", "b", query).as_matrix(),
        atol=1e-12,
    )


def test_duplicate_stamp_replaces_the_sample() -> None:
    buffer = TransformBuffer()
    buffer.set_transform("map", "odom", 0, _shifted(0.0))
    buffer.set_transform("map", "odom", 10, _shifted(1.0))
    buffer.set_transform("map", "odom", 10, _shifted(3.0))  # corrected value, same stamp
    buffer.set_transform("map", "odom", 0, _shifted(-1.0))
    assert buffer.num_samples("map", "odom") == 2
    np.testing.assert_allclose(buffer.lookup("map", "odom", 10).translation, [3.0, 0, 0])
    np.testing.assert_allclose(buffer.lookup("map", "odom", 0).translation, [-1.0, 0, 0])
    # In a batch, and against samples already buffered, the later one wins as well.
    batch = SE3.stack([_shifted(7.0), _shifted(8.0), _shifted(9.0)])
    buffer.set_transforms("map", "odom", np.array([10, 5, 10]), batch)
    assert buffer.num_samples("map", "odom") == 3
    np.testing.assert_allclose(buffer.lookup("map", "odom", 10).translation, [9.0, 0, 0])
    np.testing.assert_allclose(buffer.lookup("map", "odom", 5).translation, [8.0, 0, 0])


def test_batch_equals_sequential_inserts_in_any_order() -> None:
    rng = np.random.default_rng(3)
    stamps = rng.integers(0, 3 * S, size=600)  # unsorted, some repeated, longer than the window
    stamps = np.maximum.accumulate(stamps) - rng.integers(0, 500 * MS, size=600)
    poses = _random_poses(rng, 600)
    sequential, batched = TransformBuffer(window_ns=S), TransformBuffer(window_ns=S)
    for i in range(600):
        sequential.set_transform("a", "b", int(stamps[i]), poses[i])
    batched.set_transforms("a", "b", stamps[:100], poses[:100])
    batched.set_transforms("a", "b", stamps[100:], poses[100:])
    assert batched.stamp_range("a", "b") == sequential.stamp_range("a", "b")
    assert batched.num_samples("a", "b") == sequential.num_samples("a", "b")
    lo, hi = sequential.stamp_range("a", "b")
    query = np.unique(np.concatenate([stamps[stamps >= lo], rng.integers(lo, hi, size=100)]))
    np.testing.assert_allclose(
        batched.lookup_many("a", "b", query).as_matrix(),
        sequential.lookup_many("a", "b", query).as_matrix(),
        atol=1e-12,
    )


def test_stale_sample_is_refused_and_batches_are_all_or_nothing() -> None:
    buffer = TransformBuffer(window_ns=S)
    buffer.set_transform("odom", "base_link", 5 * S, _shifted(0.0))
    buffer.set_transform("odom", "base_link", 4 * S, _shifted(0.0))  # exactly the window: ok
    with pytest.raises(StaleSampleError, match=r"oldest accepted stamp is 4\.000000000 s"):
        buffer.set_transform("odom", "base_link", 4 * S - 1, _shifted(0.0))
    stamps = np.array([6 * S, 7 * S, 5 * S + 1], dtype=np.int64)  # the last is stale after 7 s
    with pytest.raises(StaleSampleError, match=r"sample 2 of the batch"):
        buffer.set_transforms("odom", "base_link", stamps, SE3.stack([_shifted(1.0)] * 3))
    assert buffer.stamp_range("odom", "base_link") == (4 * S, 5 * S)  # unchanged
    assert buffer.num_samples("odom", "base_link") == 2


def test_failed_batch_on_a_new_edge_leaves_no_edge() -> None:
    buffer = TransformBuffer(window_ns=S)
    stamps = np.array([5 * S, 3 * S], dtype=np.int64)  # the second is stale after the first
    with pytest.raises(StaleSampleError, match="sample 1 of the batch"):
        buffer.set_transforms("odom", "base_link", stamps, SE3.stack([_shifted(0.0)] * 2))
    assert buffer.frames == ()
    buffer.set_transform("odom", "base_link", 3 * S, _shifted(1.0))
    assert buffer.stamp_range("odom", "base_link") == (3 * S, 3 * S)
