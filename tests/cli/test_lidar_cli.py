"""``tagloc localize --premap``: the lidar fix source from the command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_runner import run_tagloc
from tagloc.io.pointcloud_files import write_ply
from tagloc.sim.scenarios import build_scenario, scenario_premap


@pytest.fixture(scope="module")
def premap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("premap") / "premap.ply"
    write_ply(path, scenario_premap(build_scenario("default", seed=0, duration_s=12.0)))
    return path


def test_premap_file_gives_lidar_fixes(premap: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = run_tagloc(
        "localize", "--scenario", "default", "--duration", "12", "--premap", str(premap),
        "--out", str(out), "--no-bag",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    fixes = [json.loads(line) for line in (out / "fixes.jsonl").read_text().splitlines()]
    lidar = [f for f in fixes if f.get("source") == "lidar"]
    assert sum(f["decision"] == "accepted" for f in lidar) > 20
    assert "lidar:" in (out / "localizer.yaml").read_text()


@pytest.mark.parametrize(
    ("shift", "suffix", "message"),
    [
        (500.0, ".ply", "premap does not overlap the tag map"),
        (0.0, ".xyz", "expected a .ply, .pcd or .pc2.lcm file"),
    ],
)
def test_bad_premap_is_one_line_and_writes_nothing(
    premap: Path, tmp_path: Path, shift: float, suffix: str, message: str
) -> None:
    from tagloc.io.pointcloud_files import read_ply

    path = tmp_path / f"bad{suffix}"
    if suffix == ".ply":
        write_ply(path, read_ply(premap) + np.array([shift, 0.0, 0.0]))
    else:
        path.write_text("0 0 0\n")
    out = tmp_path / "out"
    done = run_tagloc(
        "localize", "--scenario", "default", "--duration", "5", "--premap", str(path),
        "--out", str(out),
    )  # fmt: skip
    assert done.returncode == 1, done.stdout
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], done.stderr
    assert not out.exists()
