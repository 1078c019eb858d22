"""``tagloc eval bags``: many recorded drives at once give each drive's own numbers.

The oracle of each log's numbers is ``tagloc localize`` on that log alone (its files sink counts
the fixes and the ladder independently of the evaluation) and ``tagloc eval bag`` for the
held-out tag; the pooled numbers are the logs' sums. The Ray path runs against a local Ray head
this module starts (skipped without ray).
"""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from cli_runner import one_error_line, run_tagloc

HELD_OUT = "13"
#: The default suite's drives; the slow test takes all eight.
N_DEFAULT, N_SLOW = 2, 8


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Eight 20 s drives of the office route (odometry seeds 0..7), each bag with its
    tags.yaml beside it."""
    root = tmp_path_factory.mktemp("drives")
    out = []
    for seed in range(N_SLOW):
        bag = root / f"drive{seed}" / "drive.mcap"
        bag.parent.mkdir()
        done = run_tagloc("sim", "record", "--out", str(bag), "--seed", str(seed),
                          "--duration", "20")  # fmt: skip
        assert done.returncode == 0, done.stderr
        out.append(bag)
    return out


def _eval_bags(logs: list[Path], out: Path, *extra: str) -> dict:
    done = run_tagloc("eval", "bags", *map(str, logs), "--hold-out", HELD_OUT, "--out", str(out),
                      *extra)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in out.iterdir()) == ["report.html", "summary.json", "summary.txt"]
    return json.loads((out / "summary.json").read_text())


def _numbers(log: dict) -> dict:
    """A log's results without how it ran (wall time) and its label among the others."""
    return {k: v for k, v in log.items() if k not in ("wall_s", "name")}


def _check_against_single_runs(logs: list[Path], summary: dict, tmp_path: Path) -> None:
    for bag, log in zip(logs, summary["logs"], strict=True):
        done = run_tagloc("localize", str(bag), "--tags", str(bag.parent / "tags.yaml"),
                          "--no-bag", "--out", str(tmp_path / bag.parent.name))  # fmt: skip
        assert done.returncode == 0, done.stderr
        single = json.loads((tmp_path / bag.parent.name / "summary.json").read_text())
        assert log["fixes_accepted"] == single["fixes_accepted"]
        assert log["fix_attempts"] == single["fix_attempts"]
        assert log["odometry_samples"] == single["odometry_samples"]
        assert log["suspect_sources"] == single["suspect_sources"]
        assert log["ladder_transitions"] == single["ladder"]["transitions"]
        for level, seconds in single["ladder"]["seconds_at_level"].items():
            assert log["ladder_s"][level] == pytest.approx(seconds, abs=1e-9)
        assert log["ate_fused_m"] == pytest.approx(single["ate_unaligned_m"]["fused"], rel=1e-9)
    pooled = summary["pooled"]
    assert pooled["fixes_accepted"] == sum(log["fixes_accepted"] for log in summary["logs"])
    rel = pooled["reliability"]
    assert rel["opportunities"] == sum(x["reliability"]["opportunities"] for x in summary["logs"])
    assert rel["successes"] == sum(x["reliability"]["successes"] for x in summary["logs"])


def test_eval_bags_gives_each_drive_its_own_numbers(drives: list[Path], tmp_path: Path) -> None:
    logs = drives[:N_DEFAULT]
    summary = _eval_bags(logs, tmp_path / "fleet", "--jobs", "2")
    assert summary["engine"] == {"kind": "processes", "jobs": 2, "address": None,
                                 "passes": 2 * len(logs)}  # fmt: skip
    _check_against_single_runs(logs, summary, tmp_path)
    # the held-out tag of the first drive, as `eval bag` measures it alone
    done = run_tagloc("eval", "bag", str(logs[0]), "--tags", str(logs[0].parent / "tags.yaml"),
                      "--hold-out", HELD_OUT, "--out", str(tmp_path / "alone"))  # fmt: skip
    assert done.returncode == 0, done.stderr
    alone = json.loads((tmp_path / "alone" / "summary.json").read_text())["held_out_tags"]
    fleet = summary["logs"][0]["held_out_tags"]  # (with the truth errors eval bag does not read)
    for part in ("overall", *alone["per_tag"]):
        ours = fleet["overall"] if part == "overall" else fleet["per_tag"][part]
        theirs = alone["overall"] if part == "overall" else alone["per_tag"][part]
        assert {k: ours[k] for k in ("position_m", "yaw_deg")} == theirs
    assert fleet["unseen_tags"] == alone["unseen_tags"]
    assert alone["overall"]["position_m"]["n"] > 0
    # one log alone in series: the same numbers as beside the others in the pool
    one = _eval_bags(logs[1:2], tmp_path / "one", "--jobs", "1")
    assert _numbers(one["logs"][0]) == _numbers(summary["logs"][1])
    names = [x["name"] for x in summary["logs"]]
    assert names == [f"drive{i}/drive.mcap" for i in range(len(logs))]
    assert "verdict" in (tmp_path / "fleet" / "summary.txt").read_text()


@pytest.mark.slow
def test_eight_drives_in_parallel_match_eight_single_runs(
    drives: list[Path], tmp_path: Path
) -> None:
    summary = _eval_bags(drives, tmp_path / "fleet", "--jobs", "2")
    _check_against_single_runs(drives, summary, tmp_path)


def test_eval_bags_unreachable_ray_is_one_line(drives: list[Path], tmp_path: Path) -> None:
    pytest.importorskip("ray")
    out = tmp_path / "fleet"
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    done = run_tagloc("eval", "bags", str(drives[0]), "--ray", f"127.0.0.1:{port}",
                      "--out", str(out))  # fmt: skip
    assert f"--ray 127.0.0.1:{port}: no Ray cluster reachable" in one_error_line(done)
    assert not out.exists()


def test_eval_bags_missing_tag_map_is_one_line(tmp_path: Path, drives: list[Path]) -> None:
    bag = tmp_path / "lone" / "drive.mcap"
    bag.parent.mkdir()
    shutil.copy(drives[0], bag)
    out = tmp_path / "fleet"
    done = run_tagloc("eval", "bags", str(bag), "--out", str(out))
    assert "tags.yaml" in one_error_line(done)
    assert not out.exists()


@pytest.fixture(scope="module")
def ray_head(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A local Ray head of two CPUs for this module (stopped with it)."""
    pytest.importorskip("ray")
    ray_bin = Path(sys.executable).parent / "ray"
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    log = tmp_path_factory.mktemp("ray") / "head.log"
    with log.open("w") as f:
        head = subprocess.Popen(
            [str(ray_bin), "start", "--head", f"--port={port}", "--num-cpus=2",
             "--include-dashboard=false", "--disable-usage-stats", "--block"],
            stdout=f, stderr=subprocess.STDOUT,
        )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert head.poll() is None and time.monotonic() < deadline, log.read_text()
                time.sleep(0.5)
        yield f"127.0.0.1:{port}"
    finally:
        head.terminate()
        head.wait(timeout=60)


def test_eval_bags_on_ray_gives_the_same_numbers(
    drives: list[Path], ray_head: str, tmp_path: Path
) -> None:
    logs = drives[:2]
    local = _eval_bags(logs, tmp_path / "local", "--jobs", "1")
    on_ray = _eval_bags(logs, tmp_path / "ray", "--ray", ray_head)
    assert on_ray["engine"]["kind"] == "ray" and on_ray["engine"]["address"] == ray_head
    assert [_numbers(x) for x in on_ray["logs"]] == [_numbers(x) for x in local["logs"]]
    assert on_ray["pooled"] == local["pooled"]
