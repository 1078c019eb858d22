"""The extrapolation tolerance at both ends of an edge's buffered range."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.errors import ExtrapolationError
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3

MS = 1_000_000
TOL = 50 * MS


def _at(x: float) -> SE3:
    return SE3.from_rotvec([0.0, 0.1 * x, 0.0], [x, 2.0 * x, 0.0])


@pytest.fixture
def buffer() -> TransformBuffer:
    buffer = TransformBuffer(extrapolation_tolerance_ns=TOL)
    for k in range(11):  # samples at 1.000 s .. 1.100 s
        buffer.set_transform("odom", "base_link", 1000 * MS + 10 * k * MS, _at(float(k)))
    return buffer


@pytest.mark.parametrize(
    ("stamp", "held"),
    [(1100 * MS + TOL, 10.0), (1100 * MS + 1, 10.0), (1000 * MS - TOL, 0.0), (1000 * MS - 1, 0.0)],
)
def test_within_tolerance_holds_the_end_sample(
    buffer: TransformBuffer, stamp: int, held: float
) -> None:
    got = buffer.lookup("odom", "base_link", stamp)
    np.testing.assert_allclose(got.as_matrix(), _at(held).as_matrix(), atol=1e-12)
    assert buffer.can_transform("odom", "base_link", stamp)
    many = buffer.lookup_many("odom", "base_link", np.array([stamp, 1050 * MS]))
    np.testing.assert_allclose(many[0].as_matrix(), _at(held).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(many[1].translation, [5.0, 10.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("stamp", [1100 * MS + TOL + 1, 1000 * MS - TOL - 1])
def test_beyond_tolerance_fails(buffer: TransformBuffer, stamp: int) -> None:
    assert not buffer.can_transform("odom", "base_link", stamp)
    with pytest.raises(ExtrapolationError, match=r"tolerance 0\.050000000 s \(50000000 ns\)"):
        buffer.lookup("odom", "base_link", stamp)
    with pytest.raises(ExtrapolationError, match=r"1 stamps fall outside"):
        buffer.lookup_many("odom", "base_link", np.array([1050 * MS, stamp]))


def test_zero_tolerance_by_default() -> None:
    buffer = TransformBuffer()
    buffer.set_transform("a", "b", 0, _at(0.0))
    buffer.set_transform("a", "b", 10, _at(1.0))
    assert buffer.can_transform("a", "b", 10)
    assert buffer.can_transform("a", "b", 0)
    for stamp in (11, -1):
        assert not buffer.can_transform("a", "b", stamp)
        with pytest.raises(ExtrapolationError):
            buffer.lookup("a", "b", stamp)


def test_single_sample_edge() -> None:
    buffer = TransformBuffer(extrapolation_tolerance_ns=5)
    buffer.set_transform("a", "b", 100, _at(3.0))
    for stamp in (95, 100, 105):
        np.testing.assert_allclose(
            buffer.lookup("a", "b", stamp).as_matrix(), _at(3.0).as_matrix(), atol=1e-12
        )
    many = buffer.lookup_many("a", "b", np.array([95, 105]))
    np.testing.assert_allclose(many.translation, [[3.0, 6.0, 0.0]] * 2, atol=1e-12)
    for stamp in (94, 106):
        with pytest.raises(ExtrapolationError):
            buffer.lookup("a", "b", stamp)


def test_tolerance_applies_per_edge_in_a_chain() -> None:
    """map -> odom published at 1 Hz and late; odom -> base_link at 100 Hz."""
    buffer = TransformBuffer(extrapolation_tolerance_ns=TOL)
    buffer.set_transform("map", "odom", 0, _at(1.0))
    buffer.set_transform("map", "odom", 1000 * MS, _at(2.0))
    for k in range(0, 106):
        buffer.set_transform("odom", "base_link", 10 * k * MS, _at(0.01 * k))
    stamp = 1030 * MS  # map -> odom held (within tolerance), odom -> base_link interpolated
    expected = _at(2.0) @ _at(1.03)
    got = buffer.lookup("map", "base_link", stamp)
    np.testing.assert_allclose(got.as_matrix(), expected.as_matrix(), atol=1e-12)
    with pytest.raises(ExtrapolationError) as info:
        buffer.lookup("map", "base_link", 1051 * MS)
    message = str(info.value)
    assert "edge 'map' -> 'odom'" in message
    assert "'odom' -> 'base_link'" not in message  # that edge holds 1.051 s
