"""``tagloc map check`` and ``tagloc map diff``: output, one-line errors and exit codes."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli_runner import run_tagloc
from tagloc.cli.map_cmd import map_app
from tagloc.tags.tagmap import TagMapError

GOOD = """\
version: 1
frames: [map, elevator_cab]
tags:
  - {id: 0, size: 0.162, position: [0.0, 2.35, 1.4], quat_xyzw: [0.5, 0.5, 0.5, 0.5],
     anchor: true}
  - {id: 17, size: 0.162, position: [24.5, 0.0, 1.45], quat_xyzw: [0.5, 0.5, 0.5, 0.5]}
  - {id: 3, size: 0.1, frame: elevator_cab, position: [0.0, -0.9, 1.5],
     quat_xyzw: [0.5, -0.5, -0.5, 0.5]}
  - {id: 7, family: aruco_4x4_50, size: 0.05, position: [31.2, 4.8, 0.3],
     quat_xyzw: [0.5, 0.5, 0.5, 0.5]}
"""
SUMMARY = "4 tags (aruco_4x4_50: 1, tag36h11: 3); frames: map (3), elevator_cab (1); anchors: 1"
# tag 17 moved 3 cm along map x; tag 7 removed; tag 3's note changed
NEW = (
    GOOD.replace("[24.5, 0.0, 1.45]", "[24.53, 0.0, 1.45]")
    .replace("[0.0, -0.9, 1.5],", "[0.0, -0.9, 1.5], note: back wall,")
    .split("  - {id: 7")[0]
)
DIFF_LINES = [  # sorted by (family, id)
    "- aruco_4x4_50:7 removed: in map at [31.200, 4.800, 0.300] m, size 0.05 m",
    '~ tag36h11:3 note "" -> "back wall"',
    "~ tag36h11:17 moved 3.0 cm [+3.0, +0.0, +0.0] cm in map, rotated 0.0 deg",
]


def _summary(old: Path, new: Path, removed: int, moved: int, changed: int) -> str:
    """The last line of ``map diff``: the counts of the lines above it."""
    total = removed + moved + changed
    return (
        f"{total} change{'s' if total != 1 else ''}: 0 added, {removed} removed, {moved} moved, "
        f"{changed} changed field{'s' if changed != 1 else ''}, 0 frame(s) added or removed "
        f"({old} -> {new})"
    )


@pytest.fixture
def maps(tmp_path: Path) -> tuple[Path, Path, Path]:
    good, new, bad = tmp_path / "tags.yaml", tmp_path / "new.yaml", tmp_path / "bad.yaml"
    good.write_text(GOOD)
    new.write_text(NEW)
    bad.write_text(GOOD.replace("size: 0.1,", "size: 0,"))
    return good, new, bad


def test_check_prints_a_one_line_summary(maps: tuple[Path, Path, Path]) -> None:
    good, _, _ = maps
    result = run_tagloc("map", "check", str(good))
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"{good}: ok: {SUMMARY}\n"


def test_check_of_a_bad_map_is_one_line_naming_file_entry_and_field(
    maps: tuple[Path, Path, Path],
) -> None:
    _, _, bad = maps
    result = run_tagloc("map", "check", str(bad))
    assert result.returncode == 1
    assert result.stdout == ""
    assert result.stderr == f"tagloc: error: {bad}: tags[2] (id 3): size: must be > 0\n"
    missing = run_tagloc("map", "check", str(bad.parent / "missing.yaml"))
    assert missing.returncode == 1 and "cannot read tag map" in missing.stderr
    assert len(missing.stderr.splitlines()) == 1


def test_diff_prints_changes_and_exits_0_or_1_with_exit_code(
    maps: tuple[Path, Path, Path],
) -> None:
    good, new, bad = maps
    result = run_tagloc("map", "diff", str(good), str(new))
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [*DIFF_LINES, _summary(good, new, 1, 1, 1)]
    assert run_tagloc("map", "diff", "--exit-code", str(good), str(new)).returncode == 1
    same = run_tagloc("map", "diff", "--exit-code", str(good), str(good))
    assert same.returncode == 0 and same.stdout == f"no differences: {good} {good}\n"
    # a larger threshold hides the 3 cm move
    result = run_tagloc("map", "diff", "--min-move-cm", "5", str(good), str(new))
    assert result.stdout.splitlines() == [
        DIFF_LINES[0],
        DIFF_LINES[1],
        _summary(good, new, 1, 0, 1),
    ]
    broken = run_tagloc("map", "diff", str(good), str(bad))
    assert broken.returncode == 1 and broken.stderr.startswith(f"tagloc: error: {bad}: tags[2]")


def test_map_is_wired_into_the_tagloc_command(maps: tuple[Path, Path, Path]) -> None:
    from tagloc.cli.app import app

    assert any(g.typer_instance is map_app for g in app.registered_groups)
    good, _, _ = maps
    result = run_tagloc("map", "check", str(good))
    assert result.returncode == 0 and SUMMARY in result.stdout


def test_the_typer_app_directly(maps: tuple[Path, Path, Path]) -> None:
    good, new, bad = maps
    runner = CliRunner()
    result = runner.invoke(map_app, ["check", str(good)])
    assert result.exit_code == 0 and result.output == f"{good}: ok: {SUMMARY}\n"
    result = runner.invoke(map_app, ["diff", str(good), str(new)])
    assert result.exit_code == 0 and result.output.splitlines()[:-1] == DIFF_LINES
    assert runner.invoke(map_app, ["diff", "--exit-code", str(good), str(new)]).exit_code == 1
    result = runner.invoke(map_app, ["check", str(bad)])
    assert isinstance(result.exception, TagMapError)  # main() turns it into one line, exit 1


def test_check_warns_about_floors_on_stderr_and_exits_0(tmp_path: Path) -> None:
    path = tmp_path / "building.yaml"
    path.write_text(
        'version: 1\nfloors: {"0": 0.0, "1": 3.5}\ntags:\n'
        '  - {id: 1, size: 0.16, floor: "1", position: [0.0, 3.0, 1.2],'
        " quat_xyzw: [0.5, 0.5, 0.5, 0.5]}\n"
    )
    result = run_tagloc("map", "check", str(path))
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"{path}: ok: 1 tags")
    assert result.stderr.splitlines() == [
        f"{path}: warning: tags[0] (id 1): floor: z 1.20 m is not on floor 1 (3.5 m; expected "
        "3.2 m <= z < 8.5 m)",
        f"{path}: warning: floors.0: no tag is on this floor (it cannot be told by its tags)",
    ]
