"""PLY / PCD point-cloud files: round trips, small_gicp's PLY reader as oracle, bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import small_gicp

from tagloc.io.errors import InputNotFoundError
from tagloc.io.pointcloud_files import (
    MAX_COORDINATE_M,
    PointCloudFileError,
    read_pcd,
    read_ply,
    read_premap,
    write_pcd,
    write_ply,
)

SEED = 17


@pytest.fixture
def points() -> np.ndarray:
    return np.random.default_rng(SEED).uniform(-50, 50, (1000, 3))


@pytest.mark.parametrize(("write", "read"), [(write_ply, read_ply), (write_pcd, read_pcd)])
def test_round_trip_is_float32_exact(tmp_path: Path, points: np.ndarray, write, read) -> None:
    path = tmp_path / "premap.bin"
    write(path, points)
    back = read(path)
    assert back.dtype == np.float64 and back.shape == (1000, 3)
    np.testing.assert_array_equal(back, points.astype(np.float32).astype(np.float64))
    assert b"frame map" in path.read_bytes()[:200]
    assert [p.name for p in tmp_path.iterdir()] == ["premap.bin"]  # no temporary left


def test_small_gicp_reads_our_ply(tmp_path: Path, points: np.ndarray) -> None:
    write_ply(tmp_path / "premap.ply", points)
    cloud = small_gicp.read_ply(str(tmp_path / "premap.ply"))
    oracle = np.asarray(cloud.points())[:, :3]
    np.testing.assert_allclose(oracle, points.astype(np.float32), rtol=0, atol=0)


def test_other_writers_fields_are_skipped(tmp_path: Path) -> None:
    xyz = np.arange(12, dtype=np.float64).reshape(4, 3)
    records = np.zeros(4, dtype=[("x", "<f8"), ("intensity", "u1"), ("y", "<f8"), ("z", "<f8")])
    records["x"], records["y"], records["z"], records["intensity"] = xyz.T[0], xyz.T[1], xyz.T[2], 7
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment by another tool\nelement vertex 4\n"
        "property double x\nproperty uchar intensity\nproperty double y\nproperty double z\n"
        "element face 0\nproperty list uchar int vertex_indices\nend_header\n"
    )
    (tmp_path / "a.ply").write_bytes(header.encode() + records.tobytes())
    np.testing.assert_array_equal(read_ply(tmp_path / "a.ply"), xyz)
    pcd = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x intensity y z\nSIZE 8 1 8 8\nTYPE F U F F\n"
        "COUNT 1 1 1 1\nWIDTH 4\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA binary\n"
    )
    (tmp_path / "a.pcd").write_bytes(pcd.encode() + records.tobytes())
    np.testing.assert_array_equal(read_pcd(tmp_path / "a.pcd"), xyz)


def _ply(tmp_path: Path, header: str, body: bytes = b"") -> Path:
    path = tmp_path / "bad.ply"
    path.write_bytes(header.encode() + body)
    return path


PLY_HEAD = "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
XYZ = "property float x\nproperty float y\nproperty float z\nend_header\n"


@pytest.mark.parametrize(
    ("header", "body", "message"),
    [
        (PLY_HEAD + XYZ, b"\0" * 35, "truncated: 3 points need 36 bytes, the file has 35"),
        ("plx\n" + PLY_HEAD[4:] + XYZ, b"\0" * 36, "not a PLY file"),
        (PLY_HEAD.replace("binary_little_endian", "ascii") + XYZ, b"", "only binary_little"),
        (PLY_HEAD + "property float x\nproperty float y\nend_header\n", b"\0" * 24, "no field z"),
        (PLY_HEAD, b"", "no end of header"),
        (PLY_HEAD.replace("3", "three") + XYZ, b"", "element count 'three' is not an integer"),
        ("ply\nformat binary_little_endian 1.0\nelement face 2\n" + XYZ, b"", "not 'vertex'"),
    ],
)
def test_bad_ply_fails_in_one_line_naming_the_file(
    tmp_path: Path, header: str, body: bytes, message: str
) -> None:
    path = _ply(tmp_path, header, body)
    with pytest.raises(PointCloudFileError) as info:
        read_ply(path)
    text = str(info.value)
    assert text.startswith(f"{path}: ") and message in text and "\n" not in text


@pytest.mark.parametrize(
    ("replace", "message"),
    [
        (("DATA binary", "DATA ascii"), "only 'binary' is read"),
        (("SIZE 4 4 4\n", ""), "no SIZE line"),
        (("TYPE F F F", "TYPE F F"), "differ in length"),
        (("POINTS 3", "POINTS 4"), "truncated"),
        (("DATA binary", "DATA_ binary"), "no DATA line"),
    ],
)
def test_bad_pcd_fails_in_one_line_naming_the_file(
    tmp_path: Path, replace: tuple[str, str], message: str
) -> None:
    good = tmp_path / "good.pcd"
    write_pcd(good, np.zeros((3, 3)))
    raw = good.read_bytes()
    split = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = raw[:split].decode().replace(*replace)
    path = tmp_path / "bad.pcd"
    path.write_bytes(header.encode() + raw[split:])
    with pytest.raises(PointCloudFileError) as info:
        read_pcd(path)
    text = str(info.value)
    assert text.startswith(f"{path}: ") and message in text and "\n" not in text


def test_missing_file_and_bad_points(tmp_path: Path) -> None:
    with pytest.raises(InputNotFoundError, match="no such point-cloud file"):
        read_ply(tmp_path / "none.ply")
    with pytest.raises(PointCloudFileError, match=r"shape \(N, 3\)"):
        write_pcd(tmp_path / "x.pcd", np.zeros((3, 2)))
    assert not (tmp_path / "x.pcd").exists()


def test_a_failed_write_keeps_the_previous_file(tmp_path: Path, points: np.ndarray) -> None:
    path = tmp_path / "premap.ply"
    write_ply(path, points)
    before = path.read_bytes()
    with pytest.raises(PointCloudFileError):
        write_ply(path, np.zeros((2, 4)))
    assert path.read_bytes() == before


# ----- bounds: sizes checked against the file before anything is allocated -----------------------
@pytest.mark.parametrize(
    ("replace", "message"),
    [
        (("POINTS 3", "POINTS 1000000000"), "truncated: 1000000000 points need 12000000000"),
        (("COUNT 1 1 1", "COUNT 1 1 1000000000"), "more than 256 fields"),
        (("SIZE 4 4 4", "SIZE 4 4 " + "9" * 400), "SIZE 99999"),
        (("POINTS 3", "POINTS " + "9" * 400), "POINTS 99999"),
    ],
)
def test_size_claims_are_checked_against_the_file(
    tmp_path: Path, replace: tuple[str, str], message: str
) -> None:
    good = tmp_path / "good.pcd"
    write_pcd(good, np.zeros((3, 3)))
    path = tmp_path / "bad.pcd"
    path.write_bytes(good.read_bytes().replace(*(r.encode() for r in replace), 1))
    with pytest.raises(PointCloudFileError) as info:
        read_pcd(path)
    text = str(info.value)
    assert text.startswith(f"{path}: ") and message in text and len(text) < 300


def test_point_cap_and_non_finite_points(tmp_path: Path, points: np.ndarray) -> None:
    write_ply(tmp_path / "a.ply", points)
    with pytest.raises(PointCloudFileError, match="1000 points, more than the 999 read at most"):
        read_ply(tmp_path / "a.ply", max_points=999)
    for bad in (np.nan, np.inf, 2 * MAX_COORDINATE_M):
        points[500, 1] = bad
        write_pcd(tmp_path / "b.pcd", points)
        with pytest.raises(PointCloudFileError, match=r"point 500 .*finite and within"):
            read_pcd(tmp_path / "b.pcd")


def test_a_premap_above_the_cap_is_voxel_downsampled(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Oracle: the premap's points on a 5 cm grid (a plane of 200 x 200 cells), 4 points per
    cell; above the cap each cell becomes its centroid, read in blocks smaller than the file."""
    import tagloc.io.pointcloud_files as files

    cells = (np.stack(np.meshgrid(np.arange(200), np.arange(200)), -1).reshape(-1, 2) + 0.5) * 0.05
    jitter = np.array([[-0.01, -0.01], [0.01, 0.01], [-0.01, 0.01], [0.01, -0.01]])
    xy = (cells[:, None, :] + jitter[None]).reshape(-1, 2)
    write_pcd(tmp_path / "big.pcd", np.column_stack([xy, np.full(len(xy), 1.0)]))
    assert len(read_premap(tmp_path / "big.pcd")) == len(xy)  # below the cap: as read
    monkeypatch.setattr(files, "PREMAP_KEEP_POINTS", 50_000)
    monkeypatch.setattr(files, "BLOCK_POINTS", 30_000)
    kept = read_premap(tmp_path / "big.pcd")
    assert len(kept) == 40_000
    np.testing.assert_allclose(np.sort(kept[:, 0]), np.sort(np.repeat(cells[:, 0], 1)), atol=1e-6)
    monkeypatch.setattr(files, "PREMAP_KEEP_POINTS", 10_000)  # 10 cm voxels: 4 cells each
    assert len(read_premap(tmp_path / "big.pcd")) == 10_000
    monkeypatch.setattr(files, "MAX_PREMAP_POINTS", 100_000)
    with pytest.raises(PointCloudFileError, match="160000 points, more than the 100000"):
        read_premap(tmp_path / "big.pcd")
    with pytest.raises(PointCloudFileError, match=r"expected a \.ply or \.pcd"):
        read_premap(tmp_path / "big.xyz")
