"""Output paths and numeric options are checked before any work: one line naming the option and
the path or value, exit code 1, no traceback, nothing written, and nothing the user had lost."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cli_runner import _MAIN, _SRC, one_error_line, run_tagloc


def _tree(root: Path) -> dict[str, bytes | None]:
    """Every path under ``root`` with its bytes (None for a directory)."""
    return {
        str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes())
        for p in sorted(root.rglob("*"))
    }


@pytest.fixture
def site(tmp_path: Path) -> Path:
    """A directory with things the commands must not lose: a directory of files, a file."""
    (tmp_path / "precious").mkdir()
    (tmp_path / "precious" / "notes.txt").write_text("field notes\n")
    (tmp_path / "precious" / "sub").mkdir()
    (tmp_path / "precious" / "sub" / "data.bin").write_bytes(b"\x00\x01")
    (tmp_path / "afile").write_text("a file\n")
    return tmp_path


def _fails_cleanly(site: Path, args: list[str], words: tuple[str, ...]) -> str:
    """Run ``tagloc ARGS`` in ``site``; assert one error line with ``words``, no file change."""
    before = _tree(site)
    done = run_tagloc(*[a.replace("@", str(site)) for a in args])
    line = one_error_line(done)
    assert "Traceback" not in done.stderr
    for word in words:
        assert word.replace("@", str(site)) in line, (word, line)
    assert _tree(site) == before  # nothing written, nothing removed
    return line


@pytest.mark.parametrize(
    ("args", "words"),
    [
        # an existing directory that is not a bag: refused (it used to be deleted)
        (["--out", "@/precious"], ("--out", "@/precious", "existing directory")),
        (["--out", "@/precious", "--format", "ros2"], ("--out", "@/precious", "may not replace")),
        (["--out", "@/precious.mcap", "--tags-out", "@/precious"], ("--tags-out", "directory")),
        # two outputs on one path: the tag map would overwrite the bag
        (["--out", "@/d.mcap", "--tags-out", "@/d.mcap"], ("--tags-out", "same path as --out")),
        (["--out", "@/d.mcap", "--tags-out", "@/./x/../d.mcap"], ("same path as --out",)),
        (["--out", "@/r2", "--tags-out", "@/r2/tags.yaml"], ("--tags-out", "inside the output")),
        # an unwritable place: checked before minutes of simulation, not after
        (["--out", "@/d.mcap", "--tags-out", "@/afile/tags.yaml"], ("--tags-out", "afile")),
        (["--out", "@/afile/d.mcap"], ("--out", "not a directory")),
        (["--out", "@/d.mcap", "--tags-out", "/proc/none/tags.yaml"], ("/proc/none/tags.yaml",)),
        # the format has to fit the name, so readers open what was written
        (["--out", "@/d.mcap", "--format", "ros1"], ("--format ros1", ".bag")),
        (["--out", "@/d.bag", "--format", "mcap"], ("--format mcap", ".mcap")),
        (["--out", "@/d.bag", "--format", "ros2"], ("--format ros2", "directory")),
        (["--out", "@/d", "--format", "mcap"], ("--format mcap",)),
        # numbers
        (["--out", "@/d.mcap", "--duration", "nan"], ("--duration nan",)),
        (["--out", "@/d.mcap", "--duration", "inf"], ("--duration inf",)),
        (["--out", "@/d.mcap", "--duration", "-1"], ("--duration -1",)),
        (["--out", "@/d.mcap", "--duration", "0"], ("--duration 0",)),
        (["--out", "@/d.mcap", "--duration", "1e300"], ("--duration 1e+300",)),
        (["--out", "@/d.mcap", "--seed", "-1"], ("--seed -1",)),
        (["--out", "@/d.mcap", "--seed", str(2**64)], ("--seed",)),
    ],
)
def test_sim_record_refuses_before_any_work(
    site: Path, args: list[str], words: tuple[str, ...]
) -> None:
    _fails_cleanly(site, ["sim", "record", *args], words)


def test_sim_record_replaces_its_own_ros2_bag_but_no_other_directory(site: Path) -> None:
    bag = site / "drive_bag"
    for seed in ("1", "2"):  # the second run replaces the first bag: it holds nothing else
        done = run_tagloc("sim", "record", "--out", str(bag), "--duration", "1", "--seed", seed)
        assert done.returncode == 0, done.stderr
    assert (bag / "metadata.yaml").is_file()
    (bag / "my_notes.txt").write_text("mine\n")  # now it is more than a bag
    _fails_cleanly(
        site, ["sim", "record", "--out", str(bag), "--duration", "1"], ("--out", "may not replace")
    )
    assert (bag / "my_notes.txt").read_text() == "mine\n"


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["map", "build", "--sim", "--out", "@/t.yaml", "--report", "@/precious"],
         ("--report", "@/precious", "directory")),
        (["map", "build", "--sim", "--out", "@/t.yaml", "--report", "@/t.yaml"],
         ("--report", "same path as --out")),
        (["map", "build", "--sim", "--out", "@/precious"], ("--out", "directory")),
        (["map", "build", "--sim", "--out", "@/afile/t.yaml"], ("--out", "not a directory")),
        (["map", "build", "--sim", "--out", "@/afile", "--world", "@/afile"],
         ("--out", "input --world")),
        (["map", "build", "--sim", "--out", "@/t.yaml", "--camera-stride", "0"],
         ("--camera-stride 0",)),
        (["map", "build", "--sim", "--out", "@/t.yaml", "--seed", "-1"], ("--seed -1",)),
        (["map", "build", "--sim", "--out", "@/t.yaml", "--anchor", "-1"], ("--anchor -1",)),
        (["map", "build", "--sim", "--out", "@/t.yaml", "--tag-size", "nan"], ("--tag-size nan",)),
        (["map", "build", "--sim", "--out", "@/t.yaml", "--size", "3=inf"], ("--size '3=inf'",)),
        (["map", "build", "--sim", "--out", "@/t.yaml", "--calibrate-odometry", "-1"],
         ("--calibrate-odometry -1",)),
        (["map", "diff", "@/afile", "@/afile", "--min-move-cm", "nan"], ("--min-move-cm nan",)),
        (["map", "diff", "@/afile", "@/afile", "--min-rot-deg", "-1"], ("--min-rot-deg -1",)),
        (["eval", "files", "--truth", "@/afile", "--est", "@/afile", "--delta-m", "-1"],
         ("--delta-m -1",)),
        (["eval", "files", "--truth", "@/afile", "--est", "@/afile", "--max-diff-s", "nan"],
         ("--max-diff-s nan",)),
        (["eval", "run", "--scenario", "default", "--out", "@/afile"],
         ("--out", "not a directory")),
        (["eval", "run", "--scenario", "default", "--out", "@/x", "--duration", "nan"],
         ("--duration nan",)),
        (["eval", "run", "--scenario", "default", "--out", "@/x", "--range-m", "0"],
         ("--range-m 0",)),
        (["eval", "run", "--scenario", "default", "--out", "@/x", "--rotation-deg", "inf"],
         ("--rotation-deg inf",)),
        (["eval", "tags", "--out", "@/afile"], ("--out", "not a directory")),
        (["eval", "tags", "--out", "@/x", "--trials", "0"], ("trials", "greater than")),
        (["eval", "tags", "--out", "@/x", "--seed", "-1"], ("seed", "greater than")),
        (["world", "coverage", "--csv", "@/precious"], ("--csv", "directory")),
        (["world", "coverage", "--csv", "@/afile/gaps.csv"], ("--csv", "not a directory")),
        (["world", "coverage", "--stride", "0"], ("--stride 0",)),
        (["world", "coverage", "--laps", "1000000"], ("--laps 1000000",)),
        (["world", "coverage", "--min-distance", "nan"], ("--min-distance nan",)),
        (["demo", "--out", "@/afile"], ("--out", "not a directory")),
        (["demo", "--out", "@/x", "--seed", "-1"], ("--seed -1",)),
        (["demo", "--out", "@/x", "--duration", "-inf"], ("--duration -inf",)),
    ],
)  # fmt: skip
def test_every_command_checks_outputs_and_numbers_first(
    site: Path, args: list[str], words: tuple[str, ...]
) -> None:
    _fails_cleanly(site, args, words)


def test_a_read_only_directory_is_refused_before_the_survey(site: Path) -> None:
    import os

    if os.geteuid() == 0:
        pytest.skip("root writes into read-only directories")
    locked = site / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        _fails_cleanly(
            site, ["map", "build", "--sim", "--out", str(locked / "t.yaml")], ("cannot write in",)
        )
    finally:
        locked.chmod(0o755)


@pytest.mark.parametrize(
    ("signum", "code"),
    [
        (signal.SIGTERM, 128 + signal.SIGTERM),
        pytest.param(signal.SIGINT, 130, marks=pytest.mark.slow),
    ],
)
def test_a_terminated_run_leaves_nothing_it_created(
    site: Path, signum: signal.Signals, code: int
) -> None:
    """A run stopped by a signal (a timeout's SIGTERM, Ctrl-C) removes the output directory it
    created (the nested one and its missing parent) and leaves the rest as it was."""
    before = _tree(site)
    out = site / "new" / "run"
    env = {"MPLBACKEND": "Agg", "PATH": "", "PYTHONPATH": _SRC}
    args = ["localize", "--scenario", "default", "--out", str(out)]
    with subprocess.Popen([sys.executable, "-c", _MAIN, *args], env=env, text=True,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE) as run:  # fmt: skip
        while not any(out.glob(".*.tmp*")) and run.poll() is None:  # the run is writing
            time.sleep(0.2)
        run.send_signal(signum)
        _, stderr = run.communicate(timeout=120)
    assert run.returncode == code, stderr
    assert "Traceback" not in stderr
    assert _tree(site) == before
