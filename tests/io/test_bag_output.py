"""Where a bag may be written: the format must fit the name, and no directory is ever lost
except a lone ROS 2 bag that a ``ros2`` output replaces."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tagloc.geometry import SE3
from tagloc.io import (
    BagSink,
    BagSource,
    BagWriteError,
    GroundTruthMsg,
    bag_output_format,
    is_ros2_bag_directory,
)


def _write(path: Path, fmt: Any, n: int = 1, **kw: Any) -> None:
    with BagSink(path, fmt, **kw) as sink:
        for i in range(n):
            sink.write("/truth", GroundTruthMsg(i + 1, "map", SE3.identity()))


@pytest.mark.parametrize(
    ("name", "fmt", "expected"),
    [("a.mcap", "", "mcap"), ("a.bag", "", "ros1"), ("a", "", "ros2"), ("a.MCAP", "", "mcap"),
     ("a.mcap", "mcap", "mcap"), ("a.bag", "ros1", "ros1"), ("drive_2024", "ros2", "ros2")],
)  # fmt: skip
def test_format_follows_or_fits_the_name(name: str, fmt: str, expected: str) -> None:
    assert bag_output_format(Path(name), fmt) == expected


@pytest.mark.parametrize(
    ("name", "fmt", "message"),
    [("a.mcap", "ros1", "--format ros1 a.mcap: a ROS 1 bag is named *.bag, not *.mcap"),
     ("a.bag", "mcap", "--format mcap a.bag: an MCAP file is named *.mcap, not *.bag"),
     ("a", "mcap", "--format mcap a: an MCAP file is named *.mcap"),
     ("a.db3", "ros2", "--format ros2 a.db3: a ROS 2 bag is a directory"),
     ("a.mcap", "zip", "--format 'zip': expected mcap, ros2 or ros1")],
)  # fmt: skip
def test_a_format_that_does_not_fit_the_name_is_one_line(name: str, fmt: str, message: str) -> None:
    with pytest.raises(BagWriteError) as info:
        bag_output_format(Path(name), fmt)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


@pytest.mark.parametrize("fmt", ["mcap", "ros2", "ros1"])
def test_an_existing_directory_survives_every_format(tmp_path: Path, fmt: Any) -> None:
    target = tmp_path / {"mcap": "d.mcap", "ros2": "d", "ros1": "d.bag"}[fmt]
    (target / "sub").mkdir(parents=True)
    (target / "notes.txt").write_text("keep me")
    (target / "sub" / "more.txt").write_text("and me")
    with pytest.raises(BagWriteError, match="existing directory"):
        _write(target, fmt, overwrite=True)
    assert (target / "notes.txt").read_text() == "keep me"
    assert (target / "sub" / "more.txt").read_text() == "and me"
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]  # no temporary left


def test_a_directory_that_appears_while_writing_is_not_replaced(tmp_path: Path) -> None:
    target = tmp_path / "d.mcap"
    sink = BagSink(target, "mcap", overwrite=True)
    sink.write("/truth", GroundTruthMsg(1, "map", SE3.identity()))
    target.mkdir()
    (target / "notes.txt").write_text("keep me")
    with pytest.raises(BagWriteError, match="existing directory"):
        sink.close()
    assert (target / "notes.txt").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.mcap"]


def test_a_lone_ros2_bag_is_replaced_and_one_with_more_is_not(tmp_path: Path) -> None:
    bag = tmp_path / "drive"
    _write(bag, "ros2", n=1)
    assert is_ros2_bag_directory(bag)
    _write(bag, "ros2", n=3, overwrite=True)
    assert len(list(BagSource(bag))) == 3
    (bag / "notes.txt").write_text("mine")
    assert not is_ros2_bag_directory(bag)
    with pytest.raises(BagWriteError, match="not a ROS 2 bag; refusing to replace it"):
        _write(bag, "ros2", overwrite=True)
    assert (bag / "notes.txt").read_text() == "mine" and len(list(BagSource(bag))) == 3


@pytest.mark.parametrize(
    "metadata",
    ["", "rosbag2_bagfile_information: {relative_file_paths: [x.db3]}\n", "a: [\n", "[1, 2]\n"],
)
def test_a_directory_with_metadata_that_does_not_list_its_files_is_no_bag(
    tmp_path: Path, metadata: str
) -> None:
    (tmp_path / "metadata.yaml").write_text(metadata)
    (tmp_path / "other.db3").write_bytes(b"")
    assert not is_ros2_bag_directory(tmp_path)
    assert not is_ros2_bag_directory(tmp_path / "metadata.yaml")
