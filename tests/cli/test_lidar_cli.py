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


def test_a_laser_scan_on_the_lidar_topic_is_a_counted_skip_without_a_premap(
    premap: Path, tmp_path: Path
) -> None:
    """A planar scanner's ``LaserScan`` where the sweeps would be: without ``--premap`` the lidar
    is not used, so its messages are skipped and counted; with a premap, one error line."""
    import sys

    sys.path.insert(0, str(Path(__file__).parents[1] / "io"))
    from test_bag_errors import raw_bag

    from tagloc.io.encode import RosEncoder
    from tagloc.sim.scenarios import ScenarioSource
    from tagloc.tags import save_tag_map

    scenario = build_scenario("default", seed=2, duration_s=6.0)
    enc = RosEncoder(2)
    scan_type = enc.store.types["sensor_msgs/msg/LaserScan"]
    ranges, intensities = np.full(300, 5.0, np.float32), np.zeros(300, np.float32)
    items, scans = [], 0
    for seq, (topic, msg) in enumerate(ScenarioSource(scenario)):
        ros = enc.encode(msg, seq)
        if topic == "/lidar/points":
            header = type(ros.header)(ros.header.stamp, "lidar")
            ros = scan_type(header, -1.5, 1.5, 0.01, 0.0, 0.1, 0.1, 30.0, ranges, intensities)
            items.append((topic, "sensor_msgs/msg/LaserScan", ros, msg.stamp_ns))
            scans += 1
        else:
            items.append((topic, enc.msgtype(type(msg)), ros, msg.stamp_ns))
    bag = raw_bag(tmp_path / "scan.mcap", items)
    save_tag_map(scenario.tag_map, tmp_path / "tags.yaml")
    args = ["localize", str(bag), "--tags", str(tmp_path / "tags.yaml"), "--no-bag"]
    done = run_tagloc(*args, "--out", str(tmp_path / "out"))
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert scans > 0 and summary["skipped"]["lidar_not_point_cloud"] == scans
    done = run_tagloc(*args, "--premap", str(premap), "--out", str(tmp_path / "out2"))
    assert done.returncode == 1 and "has type sensor_msgs/msg/LaserScan" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "out2").exists()
