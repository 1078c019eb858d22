"""Atomic writes leave either the old file or the complete new one, never a partial file."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tagloc.fileutil import (
    OutputPathError,
    atomic_path,
    atomic_write_text,
    atomic_write_texts,
    check_outputs,
    removing_created_outputs,
)


def test_atomic_write_replaces_target(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "out.txt"
    atomic_write_text(target, "first")
    atomic_write_text(target, "second")
    assert target.read_text() == "second"
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]


def test_failed_write_keeps_old_content_and_leaves_no_temp(tmp_path: Path) -> None:
    target = tmp_path / "out.png"
    target.write_text("good")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        assert tmp.suffix == ".png"
        tmp.write_text("half")
        raise RuntimeError("writer crashed")
    assert target.read_text() == "good"
    assert [p.name for p in tmp_path.iterdir()] == ["out.png"]


def test_outputs_get_the_permissions_of_a_new_file(tmp_path: Path) -> None:
    mask = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "out.txt", "x")
    finally:
        os.umask(mask)
    assert (tmp_path / "out.txt").stat().st_mode & 0o777 == 0o644


def test_atomic_write_never_replaces_a_directory(tmp_path: Path) -> None:
    (tmp_path / "out.txt").mkdir()
    (tmp_path / "out.txt" / "keep").write_text("kept")
    with pytest.raises(OutputPathError, match=r"out\.txt: is a directory"):
        atomic_write_text(tmp_path / "out.txt", "x")
    assert (tmp_path / "out.txt" / "keep").read_text() == "kept"


def test_atomic_write_texts_writes_all_or_none(tmp_path: Path) -> None:
    (tmp_path / "a.txt").write_text("old a")
    (tmp_path / "blocker").write_text("a file where a directory must go")
    with pytest.raises(OSError):
        atomic_write_texts({tmp_path / "a.txt": "new a", tmp_path / "blocker" / "b.txt": "b"})
    assert (tmp_path / "a.txt").read_text() == "old a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "blocker"]
    atomic_write_texts({tmp_path / "a.txt": "new a", tmp_path / "sub" / "b.txt": "b"})
    assert (tmp_path / "a.txt").read_text() == "new a"
    assert (tmp_path / "sub" / "b.txt").read_text() == "b"


def test_check_outputs_accepts_good_paths_and_creates_nothing(tmp_path: Path) -> None:
    (tmp_path / "old.yaml").write_text("replaced later")
    (tmp_path / "run").mkdir()
    resolved = check_outputs(
        {"--out": tmp_path / "new" / "deeper" / "tags.yaml", "--report": tmp_path / "old.yaml",
         "--dir": tmp_path / "run", "--csv": None},
        directories={"--dir": ("report.html", "plots/a.png")},
        inputs={"--world": tmp_path / "world.yaml"},
    )  # fmt: skip
    assert resolved["--report"] == (tmp_path / "old.yaml").resolve() and "--csv" not in resolved
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.yaml", "run"]
    assert list((tmp_path / "run").iterdir()) == []


@pytest.mark.parametrize(
    ("outputs", "directories", "message"),
    [
        ({"--out": "dir"}, {}, "--out {t}/dir: is an existing directory"),
        ({"--out": "dir"}, {"--out": ["sub"]}, "--out {t}/dir/sub: is an existing directory"),
        ({"--out": "file/x.yaml"}, {}, "--out {t}/file/x.yaml: {t}/file is not a directory"),
        ({"--out": "file"}, {"--out": []}, "--out {t}/file: exists and is not a directory"),
        ({"--a": "x.yaml", "--b": "sub/../x.yaml"}, {}, "--b {t}/sub/../x.yaml: the same path"),
        ({"--a": "x.mcap", "--b": "x.mcap/t.yaml"}, {}, "--b {t}/x.mcap/t.yaml: inside the output"),
        ({"--a": "d", "--b": "d/r.html"}, {"--a": ["r.html"]},
         "--b {t}/d/r.html: the same path as --a {t}/d/r.html"),
        ({"--out": "world.yaml"}, {}, "--out {t}/world.yaml: is also the input --world"),
        ({"--out": ""}, {}, "--out: empty path"),
        ({"--out": "/proc/none/x.yaml"}, {}, "--out /proc/none/x.yaml: cannot write in /proc"),
        ({"--out": "/dev/null"}, {}, "--out /dev/null: exists and is not a regular file"),
    ],
)  # fmt: skip
def test_check_outputs_refuses_in_one_line(
    tmp_path: Path, outputs: dict[str, str], directories: dict[str, list[str]], message: str
) -> None:
    (tmp_path / "dir" / "sub").mkdir(parents=True)
    (tmp_path / "file").write_text("x")
    (tmp_path / "world.yaml").write_text("x")
    paths = {
        k: (f"{tmp_path}/{v}" if v and not v.startswith("/") else v) for k, v in outputs.items()
    }
    with pytest.raises(OutputPathError) as info:
        check_outputs(paths, directories=directories, inputs={"--world": tmp_path / "world.yaml"})
    assert str(info.value).startswith(message.format(t=tmp_path)), str(info.value)
    assert "\n" not in str(info.value)


def test_check_outputs_asks_before_taking_a_directory(tmp_path: Path) -> None:
    (tmp_path / "bag").mkdir()
    asked: list[Path] = []

    def replaceable(path: Path) -> bool:
        asked.append(path)
        return path.name == "bag"

    check_outputs({"--out": tmp_path / "bag"}, replaceable={"--out": replaceable})
    assert asked == [(tmp_path / "bag").resolve()]
    with pytest.raises(OutputPathError, match="may not replace"):
        check_outputs({"--out": tmp_path / "bag"}, replaceable={"--out": lambda _: False})


def test_check_outputs_refuses_names_the_file_system_cannot_hold(tmp_path: Path) -> None:
    long = "a" * 250
    for path in (
        tmp_path / f"{long}.yaml",  # fits, but its temporary name beside it does not
        tmp_path / (long * 2) / "x.yaml",
        tmp_path / (long * 2) / long / "x.yaml",
    ):
        with pytest.raises(OutputPathError, match=r"(?i)name too long"):
            check_outputs({"--out": path})
    (tmp_path / "loop1").symlink_to(tmp_path / "loop2")
    (tmp_path / "loop2").symlink_to(tmp_path / "loop1")
    with pytest.raises(OutputPathError, match=r"--out .*loop1/x\.yaml: cannot resolve the path"):
        check_outputs({"--out": tmp_path / "loop1" / "x.yaml"})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loop1", "loop2"]


@pytest.mark.parametrize("failure", [RuntimeError("boom"), KeyboardInterrupt(), SystemExit(143)])
def test_a_failed_command_removes_the_outputs_it_created(
    tmp_path: Path, failure: BaseException
) -> None:
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "keep.txt").write_text("kept\n")
    with pytest.raises(type(failure)), removing_created_outputs():
        outputs = {"--out": tmp_path / "new" / "run", "--into": tmp_path / "old"}
        outputs["--csv"] = tmp_path / "a" / "b.csv"
        check_outputs(outputs, directories={"--out": ["x.txt"], "--into": ["y.txt"]})
        (tmp_path / "new" / "run").mkdir(parents=True)
        (tmp_path / "new" / "run" / "x.txt").write_text("partial")
        atomic_write_text(tmp_path / "old" / "y.txt", "new file in an existing directory")
        atomic_write_text(tmp_path / "a" / "b.csv", "1,2\n")
        raise failure
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old"]
    assert [p.name for p in (tmp_path / "old").iterdir()] == ["keep.txt"]


def test_a_command_that_succeeds_keeps_its_outputs(tmp_path: Path) -> None:
    with pytest.raises(SystemExit), removing_created_outputs():
        check_outputs({"--out": tmp_path / "new"}, directories={"--out": []})
        (tmp_path / "new").mkdir()
        raise SystemExit(0)  # what click does after a command returns
    assert (tmp_path / "new").is_dir()
    with removing_created_outputs():  # outside a failing block nothing is removed either
        check_outputs({"--out": tmp_path / "other"}, directories={"--out": []})
        (tmp_path / "other").mkdir()
    assert (tmp_path / "other").is_dir()
