"""The command line's first hour: ``--version``, help that reads whole at any width, the
scenario list in ``--help``, and ``sim record`` keeping an edited tag map and refusing a bag
named like a text file."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import typer

from cli_runner import _SRC, one_error_line, run_tagloc
from tagloc.cli import unwrap_help
from tagloc.cli.app import app
from tagloc.cli.options import SCENARIO_NAMES


def _help(*args: str, columns: str | None) -> str:
    """``tagloc ARGS --help`` with stdout a pipe, at ``COLUMNS`` (None: not set)."""
    env = {"MPLBACKEND": "Agg", "PATH": "", "PYTHONPATH": _SRC}
    if columns is not None:
        env["COLUMNS"] = columns
    done = subprocess.run(
        [sys.executable, "-c", "from tagloc.cli import main; main()", *args, "--help"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_version() -> None:
    done = run_tagloc("--version")
    assert done.returncode == 0 and done.stdout.strip() == f"tagloc {version('tagloc')}"


def _groups() -> list[tuple[tuple[str, ...], typer.core.TyperGroup]]:
    root = typer.main.get_command(app)
    unwrap_help(root)
    out = [((), root)]
    for name, sub in root.commands.items():  # type: ignore[attr-defined]
        if hasattr(sub, "commands"):
            out.append(((name,), sub))
    return out


def test_command_lists_keep_each_summary_on_one_line() -> None:
    """A docstring's line breaks must not break a summary mid-sentence: at 200 columns every
    command's summary (its help's first paragraph) is on the line that names the command."""
    for path, group in _groups():
        text = _help(*path, columns="200")
        for name, sub in group.commands.items():
            summary = (sub.help or "").split("\n\n")[0]
            assert "\n" not in summary
            lines = [line for line in text.splitlines() if f" {name} " in line]
            assert any(summary[:150] in " ".join(line.split()) for line in lines), (path, name)


def test_help_is_not_cut_at_80_columns_when_piped() -> None:
    wide = _help("eval", columns=None)
    assert 80 < max(len(line) for line in wide.splitlines()) <= 120
    narrow = _help("eval", columns="80")  # a real 80-column terminal: wrapped, never cut
    assert max(len(line) for line in narrow.splitlines()) <= 80
    assert "checkpoint repeatability" in " ".join(narrow.replace("│", " ").split())


def test_scenarios_and_no_bag_are_explained_in_help() -> None:
    from tagloc.sim.scenarios import SCENARIOS

    assert tuple(SCENARIOS) == SCENARIO_NAMES
    for args in (("localize",), ("sim", "record"), ("eval", "run")):
        text = " ".join(_help(*args, columns="300").replace("│", " ").split())
        assert all(name in text for name in SCENARIO_NAMES), args
    text = " ".join(_help("localize", columns="300").replace("│", " ").split())
    assert "Do not write localization.mcap" in text


def test_sim_record_refuses_a_bag_named_like_a_text_file(tmp_path: Path) -> None:
    line = one_error_line(run_tagloc("sim", "record", "--out", str(tmp_path / "x.txt")))
    assert "--out" in line and "--format ros2" in line
    assert list(tmp_path.iterdir()) == []


def test_sim_record_keeps_an_edited_tag_map(tmp_path: Path) -> None:
    bag = tmp_path / "drive.mcap"
    args = ("sim", "record", "--out", str(bag), "--duration", "2")
    assert run_tagloc(*args).returncode == 0
    tags = tmp_path / "tags.yaml"
    assert run_tagloc(*args).returncode == 0  # the same map again: rewritten, no question
    edited = tags.read_text() + "# moved tag 3 after the survey\n"
    tags.write_text(edited)
    bag.unlink()
    line = one_error_line(run_tagloc(*args))
    assert "--tags-out" in line and "--force" in line
    assert tags.read_text() == edited and not bag.exists()
    assert run_tagloc(*args, "--force").returncode == 0
    assert tags.read_text() != edited and bag.exists()
    assert os.path.getsize(bag) > 0
