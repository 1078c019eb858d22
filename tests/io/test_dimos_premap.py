"""dimos ``.pc2.lcm`` premaps: round trip, the layout dimos's reader expects, bad files.

dimos's own reader and writer are the oracle in ``tests_dimos/test_premap_interop.py`` (run by
``make test-dimos``); here the byte layout is checked against the LCM encoding written out by
hand with ``struct``.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from tagloc.io.dimos_premap import FINGERPRINT, read_pc2_lcm, write_pc2_lcm
from tagloc.io.errors import InputNotFoundError
from tagloc.io.pointcloud_files import PointCloudFileError


def _points(n: int = 50) -> np.ndarray:
    return np.random.default_rng(3).uniform(-20, 20, size=(n, 3))


def test_round_trip_keeps_the_points_to_float32(tmp_path: Path) -> None:
    path = tmp_path / "premap.pc2.lcm"
    points = _points()
    write_pc2_lcm(path, points)
    np.testing.assert_allclose(read_pc2_lcm(path), points.astype(np.float32), rtol=0, atol=0)
    assert [p.name for p in tmp_path.iterdir()] == ["premap.pc2.lcm"]  # no temporary left


def _lcm_string(text: str) -> bytes:
    return struct.pack(">I", len(text) + 1) + text.encode() + b"\0"


def test_a_float64_big_endian_cloud_with_nan_rows_is_read(tmp_path: Path) -> None:
    points = _points(5)
    points[2] = np.nan
    fields = b"".join(_lcm_string(a) + struct.pack(">iBi", 8 * i, 8, 1) for i, a in
                      enumerate("xyz"))  # fmt: skip
    data = points.astype(">f8").tobytes()
    message = (FINGERPRINT + struct.pack(">ii", 3, len(data)) + struct.pack(">iii", 0, 1, 2)
               + _lcm_string("map") + struct.pack(">ii", 1, 5) + fields
               + struct.pack(">bii", 1, 24, 120) + data + b"\1")  # fmt: skip
    path = tmp_path / "be.pc2.lcm"
    path.write_bytes(message)
    np.testing.assert_array_equal(read_pc2_lcm(path), points[[0, 1, 3, 4]])


def test_bad_files_fail_with_one_line_naming_them(tmp_path: Path) -> None:
    good = tmp_path / "good.pc2.lcm"
    write_pc2_lcm(good, _points())
    truncated = tmp_path / "cut.pc2.lcm"
    truncated.write_bytes(good.read_bytes()[:-100])
    with pytest.raises(PointCloudFileError, match=r"cut\.pc2\.lcm: truncated"):
        read_pc2_lcm(truncated)
    other = tmp_path / "other.pc2.lcm"
    other.write_bytes(b"\0" * 64)
    with pytest.raises(PointCloudFileError, match=r"other\.pc2\.lcm: not an LCM"):
        read_pc2_lcm(other)
    with pytest.raises(InputNotFoundError, match="missing"):
        read_pc2_lcm(tmp_path / "missing.pc2.lcm")
    with pytest.raises(PointCloudFileError, match=r"shape \(N, 3\)"):
        write_pc2_lcm(tmp_path / "x.pc2.lcm", np.zeros((4, 2)))
    assert not (tmp_path / "x.pc2.lcm").exists()


def test_the_map_builder_writes_a_dimos_premap(tmp_path: Path) -> None:
    from tagloc.io.survey_files import write_survey_outputs

    points = _points()
    path = tmp_path / "premap.pc2.lcm"
    write_survey_outputs({tmp_path / "tags.yaml": "version: 1\n"}, (path, points, "pc2.lcm"))
    np.testing.assert_array_equal(read_pc2_lcm(path), points.astype(np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["premap.pc2.lcm", "tags.yaml"]
