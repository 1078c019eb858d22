"""TUM trajectory files: exact round trip, evo's reader as the oracle, clear errors with lines."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from evo.core.trajectory import PoseTrajectory3D
from evo.tools import file_interface

from tagloc.geometry import SE3
from tagloc.io import InputNotFoundError, TrajectoryFileError, read_tum, write_tum

S = 1_000_000_000


@pytest.fixture
def trajectory() -> tuple[np.ndarray, SE3]:
    rng = np.random.default_rng(11)
    stamps = 1_700_000_000 * S + np.cumsum(rng.integers(1, 50_000_000, size=200))
    stamps[0] = 1_700_000_000 * S + 1  # odd nanoseconds survive
    return stamps.astype(np.int64), SE3.random(rng, 200, translation_scale=30.0)


def test_round_trip_is_exact(tmp_path: Path, trajectory: tuple[np.ndarray, SE3]) -> None:
    stamps, poses = trajectory
    write_tum(tmp_path / "t.txt", stamps, poses)
    lines = (tmp_path / "t.txt").read_text().splitlines()
    assert lines[0].startswith("# timestamp[s] tx ty tz qx qy qz qw")
    assert lines[1].startswith("1700000000.000000001 ")
    stamps_back, poses_back = read_tum(tmp_path / "t.txt")
    assert stamps_back.dtype == np.int64 and np.array_equal(stamps_back, stamps)
    assert np.abs(poses_back.as_matrix() - poses.as_matrix()).max() < 1e-14
    assert np.array_equal(poses_back.translation, poses.translation)


def test_evo_reads_the_same_poses(tmp_path: Path, trajectory: tuple[np.ndarray, SE3]) -> None:
    stamps, poses = trajectory
    write_tum(tmp_path / "t.tum", stamps, poses)
    traj = file_interface.read_tum_trajectory_file(str(tmp_path / "t.tum"))
    assert np.array_equal(traj.positions_xyz, poses.translation)
    assert np.array_equal(traj.orientations_quat_wxyz, np.roll(poses.as_quat(), 1, axis=1))
    assert np.allclose(traj.timestamps, stamps * 1e-9, rtol=0.0, atol=1e-6)
    assert np.abs(np.array(traj.poses_se3) - poses.as_matrix()).max() < 1e-14


def test_reads_what_evo_writes(tmp_path: Path, trajectory: tuple[np.ndarray, SE3]) -> None:
    stamps, poses = trajectory
    quat_wxyz = np.roll(poses.as_quat(), 1, axis=1)
    traj = PoseTrajectory3D(poses.translation.copy(), quat_wxyz, stamps * 1e-9)
    file_interface.write_tum_trajectory_file(str(tmp_path / "evo.txt"), traj)
    stamps_back, poses_back = read_tum(tmp_path / "evo.txt")
    assert np.abs(stamps_back - stamps).max() < 1_000  # evo stores seconds as float64
    assert poses_back.allclose(poses, atol=1e-12)


def test_reads_tum_benchmark_style_lines(tmp_path: Path) -> None:
    text = "# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n" \
           "1305031098.6659 1.3563 0.6305 1.6380 0.6132 0.5962 -0.3311 -0.3986\n" \
           "1305031098.6758\t1.3543 0.6306 1.6360  0.6129 0.5966 -0.3316 -0.3980\n\n"  # fmt: skip
    (tmp_path / "gt.txt").write_text(text)
    stamps, poses = read_tum(tmp_path / "gt.txt")
    assert stamps.tolist() == [1_305_031_098_665_900_000, 1_305_031_098_675_800_000]
    assert np.allclose(poses.translation[0], [1.3563, 0.6305, 1.6380])


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("1.0 1 2 3 0 0 0", "line 3: expected 8 values 'timestamp tx ty tz qx qy qz qw', got 7"),
        ("1.0 1 2 3 0 0 0 1 9", "line 3: expected 8 values"),
        ("1.0 1 2 x 0 0 0 1", "line 3: not a number"),
        ("1.0 1 2 nan 0 0 0 1", "line 3: NaN or infinite value"),
        ("-1.0 1 2 3 0 0 0 1", "line 3: negative timestamp -1.0"),
        ("0.5 1 2 3 0 0 0 1", "line 3: timestamp 0.5 is not after the one on line 2"),
        ("0.9999999999 1 2 3 0 0 0 1", "line 3: timestamp 0.9999999999 is not after"),  # 1.0 s
        (
            "2.0 1 2 3 0 0 0.1 1",
            r"line 3: quaternion \(qx qy qz qw\) = \['0', '0', '0.1', '1'\] is not unit",
        ),
    ],
)
def test_malformed_lines_name_the_line(tmp_path: Path, line: str, match: str) -> None:
    (tmp_path / "t.txt").write_text(f"# header\n1.0 0 0 0 0 0 0 1\n{line}\n")
    with pytest.raises(TrajectoryFileError, match=f"t.txt: {match}"):
        read_tum(tmp_path / "t.txt")


def test_empty_and_missing_files(tmp_path: Path) -> None:
    (tmp_path / "empty.txt").write_text("# only a comment\n\n")
    with pytest.raises(TrajectoryFileError, match=r"empty\.txt: no pose in the file"):
        read_tum(tmp_path / "empty.txt")
    with pytest.raises(InputNotFoundError, match=r"nope\.txt: no such trajectory file"):
        read_tum(tmp_path / "nope.txt")


def test_write_validates_and_is_atomic(tmp_path: Path, trajectory: tuple[np.ndarray, SE3]) -> None:
    stamps, poses = trajectory
    target = tmp_path / "t.txt"
    target.write_text("old")
    for bad_stamps, bad_poses, match in [
        (stamps * 1.0, poses, "stamps_ns must be a 1-D array of integer nanoseconds"),
        (stamps[:-1], poses, "199 stamps but 200 poses"),
        (stamps[::-1].copy(), poses, r"stamps must increase strictly: stamps_ns\[1\]"),
        (stamps - stamps[5], poses, "negative stamp"),
    ]:
        with pytest.raises(TrajectoryFileError, match=f"t.txt: {match}"):
            write_tum(target, bad_stamps, bad_poses)
    assert target.read_text() == "old"
    write_tum(target, 5, SE3.identity())  # a single pose
    assert read_tum(target)[0].tolist() == [5]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.txt"]


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("2.0 1e308 0 0 0 0 0 1", r"line 3: position coordinate 1e\+308 m is beyond 1e\+08 m"),
        ("2.0 0 0 -2e8 0 0 0 1", r"line 3: position coordinate 2e\+08 m is beyond"),
        ("1e20 0 0 0 0 0 0 1", r"line 3: timestamp 1e20 is past the int64 nanosecond range"),
        ("1e999999999 0 0 0 0 0 0 1", r"line 3: timestamp 1e999999999 is past the int64"),
        ("2.0 1 2 inf 0 0 0 1", r"line 3: NaN or infinite value"),
        ("2.0 1 2 3 1e-300 0 0 1e-300", r"line 3: quaternion .* is not unit: \|q\| = 0 "),
        ("2.0 1 2 3 0 0 1e200 1e200", r"line 3: quaternion .* is not unit: \|q\| = inf"),
        ("9" * 5000 + " 0 0 0 0 0 0 1", r"line 3: timestamp 9{57}\.\.\. is past"),
    ],
)
def test_values_that_would_overflow_later_are_refused(
    tmp_path: Path, line: str, match: str
) -> None:
    (tmp_path / "t.txt").write_text(f"# header\n1.0 0 0 0 0 0 0 1\n{line}\n")
    with pytest.raises(TrajectoryFileError, match=f"t.txt: {match}") as info:
        read_tum(tmp_path / "t.txt")
    assert len(str(info.value)) < 200 + len(str(tmp_path))


def test_unreadable_files_are_one_line(tmp_path: Path) -> None:
    (tmp_path / "latin1.txt").write_bytes(b"# caf\xe9\n1.0 0 0 0 0 0 0 1\n")
    with pytest.raises(TrajectoryFileError, match=r"latin1\.txt: .* not UTF-8 text: byte 0xe9"):
        read_tum(tmp_path / "latin1.txt")
    with pytest.raises(TrajectoryFileError, match=r": cannot read the trajectory file: Is a dir"):
        read_tum(tmp_path)
