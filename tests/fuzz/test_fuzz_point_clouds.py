"""Fuzzed point clouds and grids: PLY and PCD files, ``PointCloud2`` messages, map_server YAML and
PGM pairs (damage: ``fuzz_helpers`` and the size tokens below). A reader returns a usable value
(finite points within the stated bounds, a grid with the classes of the pixels) or raises one
short TaglocError line naming the file; no size claim makes it allocate more than
:data:`MEMORY_BOUND` (the inputs are a few kB, the bound is what a reader needs for them)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from fuzz_helpers import (
    EDITS,
    FUZZ,
    bounded_memory,
    damaged,
    load_or_refuse,
    value_damage,
)
from hypothesis import event, given
from hypothesis import strategies as st

from tagloc.errors import TaglocError
from tagloc.io import PointCloudMsg
from tagloc.io.convert import decode
from tagloc.io.convert_cloud import MAX_SWEEP_SPAN_S
from tagloc.io.decoded import Bad, DecodeOptions
from tagloc.io.encode import RosEncoder
from tagloc.io.map_server import read_map_server, write_map_server
from tagloc.io.pointcloud_files import (
    MAX_COORDINATE_M,
    read_pcd,
    read_ply,
    read_premap,
    write_pcd,
    write_ply,
)
from tagloc.lidar import OccupancyGrid

#: Most a reader may allocate on these inputs (a few kB, claiming up to 10^18 points), bytes.
MEMORY_BOUND = 16 * 2**20
SIZE_TOKENS = [
    b"999999999", b"1000000000000", b"18446744073709551615", b"9" * 40, b"-1", b"0", b"3",
    b" ", b"\n", b"POINTS ", b"COUNT ", b"SIZE ", b"WIDTH ", b"element vertex ", b"DATA binary\n",
    b"property double x\n", b"property list uchar int x\n", b"end_header\n", b"nan", b"\xff",
    b"\x7f\x7f\xff\xff", b"\x00\x00\xc0\x7f", b"P5", b"#",
]  # fmt: skip
_size_edit = st.tuples(
    st.integers(0, 2**16), st.integers(0, 12),
    st.one_of(st.binary(max_size=6), st.sampled_from(SIZE_TOKENS)),
)  # fmt: skip
SIZE_EDITS = st.tuples(
    st.lists(_size_edit, min_size=1, max_size=5), st.one_of(st.none(), st.integers(0, 2**16))
)
POINTS = np.random.default_rng(4).uniform(-20, 20, (60, 3))


def _cloud_file(tmp_path: Path, suffix: str) -> bytes:
    path = tmp_path / f"good{suffix}"
    (write_ply if suffix == ".ply" else write_pcd)(path, POINTS)
    return path.read_bytes()


def _usable(points: np.ndarray) -> None:
    assert points.ndim == 2 and points.shape[1] == 3 and points.dtype == np.float64
    assert np.isfinite(points).all() and (np.abs(points) <= MAX_COORDINATE_M).all()


def _read_cloud(path: Path) -> None:
    reader = read_ply if path.suffix == ".ply" else read_pcd
    with bounded_memory(MEMORY_BOUND):
        points = reader(path)
        premap = read_premap(path)
    _usable(points)
    _usable(premap)


@FUZZ
@given(suffix=st.sampled_from([".ply", ".pcd"]), edits=st.one_of(EDITS, SIZE_EDITS))
def test_point_cloud_file_bytes(tmp_path: Path, suffix: str, edits: Any) -> None:
    data = damaged(_cloud_file(tmp_path, suffix), edits)
    load_or_refuse(_read_cloud, tmp_path / f"premap{suffix}", data)


# ----- PointCloud2 messages -----------------------------------------------------------------------
FIELD_CHANGES = st.sampled_from(
    ["height", "width", "point_step", "row_step", "is_bigendian", "offset", "datatype", "data",
     "time"]
)  # fmt: skip
HUGE = st.one_of(
    st.sampled_from([0, 1, 3, 7, 255, 2**16, 2**31 - 1, 2**32 - 1]), st.integers(0, 2**32 - 1)
)


def _damaged_cloud(data: st.DataObject) -> Any:
    rng = np.random.default_rng(data.draw(st.integers(0, 100), label="seed"))
    n = data.draw(st.integers(0, 40), label="n")
    offsets = np.sort(rng.uniform(0, 0.1, n)).astype(np.float32)
    msg = PointCloudMsg(10**18, "lidar", rng.normal(size=(n, 3)).astype(np.float32), None, offsets)
    ros = RosEncoder(2).encode(msg, 0)
    for change in data.draw(st.lists(FIELD_CHANGES, min_size=1, max_size=3), label="changes"):
        if change in ("height", "width", "point_step", "row_step"):
            setattr(ros, change, data.draw(HUGE, label=change))
        elif change == "is_bigendian":
            ros.is_bigendian = not ros.is_bigendian
        elif change in ("offset", "datatype") and ros.fields:
            field = ros.fields[data.draw(st.integers(0, len(ros.fields) - 1), label="field")]
            setattr(field, change, data.draw(st.integers(0, 2**32 - 1), label=change))
        elif change == "data":
            cut = data.draw(st.integers(0, len(ros.data)), label="cut")
            ros.data = ros.data[:cut]
        elif change == "time" and n:
            raw = ros.data.view(np.uint8).copy()
            top = data.draw(st.sampled_from([np.inf, np.nan, 3.4e38, -3.4e38, 1e9, -50.0]))
            at = next(f for f in ros.fields if f.name == "t").offset
            if at + 4 <= len(raw):
                raw[at : at + 4] = np.frombuffer(np.float32(top).tobytes(), np.uint8)
            ros.data = raw
    return ros


@FUZZ
@given(data=st.data())
def test_point_cloud_messages(data: st.DataObject) -> None:
    ros = _damaged_cloud(data)
    with bounded_memory(MEMORY_BOUND):
        items = decode("sensor_msgs/msg/PointCloud2", ros, 0, DecodeOptions(), False)
    for item in items:
        if isinstance(item, Bad):
            assert "\n" not in item.detail and len(item.detail) < 300
            event(f"skipped: {item.reason}")
            continue
        assert isinstance(item, PointCloudMsg)
        if item.time_offset_s is not None and len(item.time_offset_s):
            assert 0.0 <= item.time_offset_s.min() <= item.time_offset_s.max() <= MAX_SWEEP_SPAN_S
            assert item.last_point_ns() >= item.stamp_ns
        event("decoded")


# ----- map_server YAML + PGM ----------------------------------------------------------------------
GRID = OccupancyGrid(
    np.random.default_rng(9).choice([-2.0, 0.0, 3.0], size=(12, 20)).astype(np.float32),
    0.05, (-1.0, 2.0, 0.0, 0.0),
)  # fmt: skip


def _map_files(tmp_path: Path) -> tuple[str, bytes]:
    write_map_server(tmp_path / "good.yaml", GRID)
    text = (tmp_path / "good.yaml").read_text().replace("good.pgm", "map.pgm")
    return text, (tmp_path / "good.pgm").read_bytes()


def _read_grid(path: Path) -> None:
    """Read the pair; an error names the YAML or the image it names (under ``path.parent``)."""
    try:
        with bounded_memory(MEMORY_BOUND):
            grid = read_map_server(path)
    except TaglocError as exc:
        message = str(exc)
        assert "\n" not in message and len(message) < len(str(path)) + 400, message
        assert message.startswith(str(path.parent)), message
        event(f"refused: {type(exc).__name__}")
        return
    assert np.isfinite(grid.log_odds).all() and grid.resolution_m > 0
    assert np.isfinite(grid.origin_xyz_yaw).all()
    grid.occupied(), grid.free()
    event("read")


@FUZZ
@given(edits=st.one_of(EDITS, SIZE_EDITS))
def test_map_server_pgm_bytes(tmp_path: Path, edits: Any) -> None:
    text, pgm = _map_files(tmp_path)
    (tmp_path / "map.yaml").write_text(text)
    (tmp_path / "map.pgm").write_bytes(damaged(pgm, edits))
    _read_grid(tmp_path / "map.yaml")


@FUZZ
@given(edits=EDITS)
def test_map_server_yaml_bytes(tmp_path: Path, edits: Any) -> None:
    text, pgm = _map_files(tmp_path)
    (tmp_path / "map.pgm").write_bytes(pgm)
    (tmp_path / "map.yaml").write_bytes(damaged(text.encode(), edits))
    _read_grid(tmp_path / "map.yaml")


@FUZZ
@given(data=st.data())
def test_map_server_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text, pgm = _map_files(tmp_path)
    (tmp_path / "map.pgm").write_bytes(pgm)
    (tmp_path / "map.yaml").write_text(value_damage(text, data))
    _read_grid(tmp_path / "map.yaml")
