"""PointCloudMsg <-> sensor_msgs/PointCloud2: round trip in every format, other drivers' layouts,
damaged clouds.

Tolerances: points, intensities and time offsets exactly (float32 in, float32 out; NaN rows
stay NaN); time fields of other drivers (integer ns, absolute float64 ns or s) to 1 us.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_bag_errors import raw_bag
from test_bag_roundtrip import FORMATS

from tagloc.io import BagFormatError, BagSink, BagSource, PointCloudMsg, RecordError
from tagloc.io.encode import RosEncoder

S = 1_000_000_000
PC2 = "sensor_msgs/msg/PointCloud2"


def cloud(rng: np.random.Generator, stamp_ns: int, n: int = 50, full: bool = True) -> PointCloudMsg:
    points = rng.normal(size=(n, 3)).astype(np.float32) * 5
    if n > 3:
        points[3] = np.nan  # a beam without return
    intensity = rng.uniform(0, 255, n).astype(np.float32) if full else None
    offsets = np.sort(rng.uniform(0, 0.1, n)).astype(np.float32) if full else None
    return PointCloudMsg(stamp_ns, "lidar", points, intensity, offsets)


def same(a: PointCloudMsg, b: PointCloudMsg) -> None:
    assert (a.stamp_ns, a.frame_id) == (b.stamp_ns, b.frame_id)
    assert b.points.dtype == np.float32 and np.array_equal(a.points, b.points, equal_nan=True)
    for name in ("intensity", "time_offset_s"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None and y is None) or (y.dtype == np.float32 and np.array_equal(x, y)), name


@pytest.mark.parametrize(("fmt", "kw", "name"), FORMATS)
def test_point_clouds_round_trip(tmp_path: Path, fmt: Any, kw: dict[str, Any], name: str) -> None:
    rng = np.random.default_rng(3)
    records = [cloud(rng, S + i * S // 10, n=(50, 0, 7)[i % 3], full=i != 2) for i in range(4)]
    with BagSink(tmp_path / name, fmt, **kw) as sink:
        for msg in records:
            sink.write("/lidar/points", msg, log_time_ns=msg.stamp_ns + S // 10)
    source = BagSource(tmp_path / name)
    assert source.bag_topics["/lidar/points"].msgtype == PC2
    assert source.topics == {"/lidar/points": PointCloudMsg}
    back = [m for _, m in source]
    assert len(back) == len(records) and source.skipped == {}
    for a, b in zip(records, back, strict=True):
        assert isinstance(b, PointCloudMsg)
        same(a, b)


def encoded(msg: PointCloudMsg) -> Any:
    return RosEncoder(2).encode(msg, 0)


def relayout(msg: PointCloudMsg, fields: list[tuple[str, str, Any]], bigendian: bool) -> Any:
    """The ROS message of ``msg`` with another driver's fields ``(name, dtype, values)``,
    padded to 32-byte points and 4 bytes of row padding."""
    ros = encoded(msg)
    order = ">" if bigendian else "<"
    dtype = np.dtype(
        {
            "names": [f[0] for f in fields],
            "formats": [order + f[1] for f in fields],
            "offsets": [8 * i for i in range(len(fields))],
            "itemsize": 8 * len(fields),
        }
    )
    packed = np.zeros(len(msg.points), dtype)
    codes = {"f4": 7, "f8": 8, "u4": 6, "u1": 2}
    for name, _, values in fields:
        packed[name] = values
    ros.fields = [
        type(ros.fields[0])(name, 8 * i, codes[kind], 1) for i, (name, kind, _) in enumerate(fields)
    ]
    ros.point_step, ros.is_bigendian = dtype.itemsize, bigendian
    ros.row_step = dtype.itemsize * len(msg.points) + 4
    ros.data = np.concatenate([packed.view(np.uint8).reshape(-1), np.zeros(4, np.uint8)])
    return ros


@pytest.mark.parametrize(
    ("time_field", "kind", "to_values"),
    [
        ("t", "u4", lambda t, stamp: np.round(t * 1e9)),  # Ouster: ns after the stamp
        ("time", "f4", lambda t, stamp: t),  # Velodyne: s after the stamp
        ("offset_time", "u4", lambda t, stamp: np.round(t * 1e9)),
        ("timestamp", "f8", lambda t, stamp: stamp + t * 1e9),  # Livox driver 2: absolute ns
        ("timestamp", "f8", lambda t, stamp: stamp * 1e-9 + t),  # Hesai: absolute s
    ],
)
@pytest.mark.parametrize("bigendian", [False, True])
def test_other_drivers_time_fields_and_layouts(
    tmp_path: Path, time_field: str, kind: str, to_values: Any, bigendian: bool
) -> None:
    rng = np.random.default_rng(5)
    msg = cloud(rng, 1_700_000_000 * S, n=20)
    assert msg.time_offset_s is not None and msg.intensity is not None
    t = msg.time_offset_s.astype(np.float64)
    fields = [
        ("x", "f8", msg.points[:, 0]),
        ("y", "f4", msg.points[:, 1]),
        ("z", "f4", msg.points[:, 2]),
        ("intensity", "u1", np.round(msg.intensity)),
        (time_field, kind, to_values(t, float(msg.stamp_ns))),
    ]
    ros = relayout(msg, fields, bigendian)
    source = BagSource(raw_bag(tmp_path / "a.mcap", [("/points", PC2, ros, msg.stamp_ns)]))
    [(_, back)] = list(source)
    assert isinstance(back, PointCloudMsg) and back.time_offset_s is not None
    assert back.stamp_ns == msg.stamp_ns
    assert np.array_equal(back.points, msg.points, equal_nan=True)
    assert np.array_equal(back.intensity, np.round(msg.intensity))  # type: ignore[arg-type]
    assert np.abs(back.time_offset_s - t).max() < 1e-6


def test_a_stamp_at_the_sweep_end_is_moved_to_the_first_point(tmp_path: Path) -> None:
    msg = cloud(np.random.default_rng(6), 10 * S, n=10)
    assert msg.time_offset_s is not None
    ros = encoded(msg)
    ros.header.stamp.sec = 11  # stamped 1 s late: offsets would be negative
    offsets = msg.time_offset_s.astype(np.float64) - 1.0
    ros = relayout(msg, [("x", "f4", msg.points[:, 0]), ("y", "f4", msg.points[:, 1]),
                         ("z", "f4", msg.points[:, 2]), ("t", "f4", offsets)], False)  # fmt: skip
    ros.header.stamp.sec = 11
    [(_, back)] = list(BagSource(raw_bag(tmp_path / "a.mcap", [("/p", PC2, ros, 11 * S)])))
    assert isinstance(back, PointCloudMsg) and back.time_offset_s is not None
    first = float(np.float32(offsets).min())
    assert abs(back.stamp_ns - (11 * S + first * 1e9)) <= 1
    assert back.time_offset_s.min() == 0.0
    expected = np.float32(offsets).astype(np.float64) - first
    assert np.abs(back.time_offset_s - expected).max() < 1e-6


def test_truncated_or_garbled_clouds_are_one_line_naming_topic_and_message(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    good, short, garbled, noxyz = (encoded(cloud(rng, (i + 1) * S)) for i in range(4))
    short.data = short.data[:-5]
    garbled.fields[2].offset = 200  # z lies outside the 20-byte point
    noxyz.fields = noxyz.fields[:2]
    items = [
        ("/lidar/points", PC2, m, (i + 1) * S) for i, m in enumerate((good, short, garbled, noxyz))
    ]
    path = raw_bag(tmp_path / "a.mcap", items)
    source = BagSource(path)
    assert len(list(source)) == 1 and source.skipped == {"bad_point_cloud": 3}
    with pytest.raises(BagFormatError) as info:
        list(BagSource(path, on_bad="error"))
    text = str(info.value)
    assert "\n" not in text and "/lidar/points message 1" in text and "data too short" in text


def test_the_record_checks_its_arrays() -> None:
    points = np.zeros((4, 3), np.float32)
    msg = PointCloudMsg(0, "lidar", points)
    assert not msg.points.flags.writeable and msg.points is not points
    with pytest.raises(RecordError, match=r"PointCloudMsg.points: expected shape \(N, 3\)"):
        PointCloudMsg(0, "lidar", np.zeros((4, 2)))
    with pytest.raises(RecordError, match=r"PointCloudMsg.intensity: expected shape \(4,\)"):
        PointCloudMsg(0, "lidar", points, np.zeros(3))
    with pytest.raises(RecordError, match="time_offset_s: must be finite and >= 0"):
        PointCloudMsg(0, "lidar", points, None, np.array([0.0, 0.1, -0.01, 0.2]))
    with pytest.raises(RecordError, match="stamp_ns"):
        PointCloudMsg(-1, "lidar", points)


def test_size_claims_and_time_extremes_are_skipped(tmp_path: Path) -> None:
    """A cloud announcing more points than a sweep may hold is skipped before any point is
    copied; a time field at its type's maximum (uint32 ns: 4.3 s, fine; uint64 ns, float32 s)
    is checked against the sweep's span; points beyond the range limit are no returns."""
    from tagloc.io.convert_cloud import MAX_POINT_RANGE_M, MAX_SWEEP_POINTS

    rng = np.random.default_rng(8)
    huge = encoded(cloud(rng, S))
    huge.height, huge.width = 1, MAX_SWEEP_POINTS + 1  # claims 2 M points, holds 50
    huge.row_step = huge.point_step * huge.width
    msgs = [huge]
    for kind, top in (("u4", np.iinfo(np.uint32).max), ("f4", np.finfo(np.float32).max),
                      ("f8", np.finfo(np.float64).max)):  # fmt: skip
        base = cloud(rng, 2 * S, n=5)
        t = np.zeros(5)
        t[-1] = top
        xyz = [(axis, "f4", base.points[:, k]) for k, axis in enumerate("xyz")]
        msgs.append(relayout(base, [*xyz, ("t", kind, t)], False))
    far = cloud(rng, 3 * S, n=6)
    points = far.points.copy()
    points[1] = (2 * MAX_POINT_RANGE_M, 0.0, 0.0)
    points[2] = (np.finfo(np.float32).max, 1.0, 1.0)
    msgs.append(encoded(PointCloudMsg(3 * S, "lidar", points)))
    items = [("/lidar/points", PC2, m, (i + 1) * S) for i, m in enumerate(msgs)]
    source = BagSource(raw_bag(tmp_path / "a.mcap", items), ["/lidar/points"])
    back = [m for _, m in source]
    assert source.skipped == {"bad_point_cloud": 3}  # the huge one, float32 and float64 max
    assert len(back) == 2 and isinstance(back[0], PointCloudMsg)
    assert back[0].time_offset_s is not None
    assert back[0].time_offset_s.max() == pytest.approx(4.294967295)
    assert isinstance(back[1], PointCloudMsg)
    assert np.isnan(back[1].points[1:3]).all() and np.isfinite(back[1].points[[0, 4, 5]]).all()


def test_a_large_sweep_is_thinned_on_reading(tmp_path: Path) -> None:
    """Oracle: points on a 5 cm lattice, 3 points per cube: the first of each cube is kept,
    with its own intensity and time (the sweep is over the thinning threshold)."""
    from tagloc.io.convert_cloud import SWEEP_KEEP_POINTS

    n_cubes = SWEEP_KEEP_POINTS // 2
    cubes = np.stack([np.arange(n_cubes) % 100, (np.arange(n_cubes) // 100) % 100,
                      np.arange(n_cubes) // 10_000], axis=1) * 0.05 + 0.01  # fmt: skip
    points = np.concatenate([cubes, cubes + 0.01, cubes + 0.02]).astype(np.float32)
    t = np.linspace(0.0, 0.1, len(points)).astype(np.float32)
    intensity = np.arange(len(points)).astype(np.float32)
    msg = PointCloudMsg(S, "lidar", points, intensity, t)
    [(_, back)] = list(BagSource(raw_bag(tmp_path / "a.mcap", [("/p", PC2, encoded(msg), S)])))
    assert isinstance(back, PointCloudMsg) and len(back.points) == n_cubes
    np.testing.assert_array_equal(back.points, points[:n_cubes])
    np.testing.assert_array_equal(back.intensity, intensity[:n_cubes])  # type: ignore[arg-type]
    np.testing.assert_array_equal(back.time_offset_s, t[:n_cubes])  # type: ignore[arg-type]
