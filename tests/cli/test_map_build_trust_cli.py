"""``tagloc map build`` options for a map you can trust: --export-graph, --exclude,
--anchor-sigma, --anchors with anchor_sigma, --gravity-aligned-odometry, --config,
--uncertain-cm, and `map diff` against the maps' uncertainty; bad values give one line, exit 1
and no output."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_runner import run_tagloc
from tagloc.sim import load_default_world
from tagloc.tags.tagmap import load_tag_map

REPO = Path(__file__).resolve().parents[2]
DUPONT = REPO / ".." / "shared" / "data" / "dupont"


def _short_world(tmp_path: Path) -> Path:
    world = load_default_world()
    route = world.route.model_copy(update={"waypoints": world.route.waypoints[:7], "repeat": 1})
    path = tmp_path / "world.yaml"
    path.write_text(world.model_copy(update={"route": route}).to_yaml_text())
    return path


def test_export_graph_exclude_and_flags(tmp_path: Path) -> None:
    out, graph, report = tmp_path / "tags.yaml", tmp_path / "graph.jsonl", tmp_path / "qa.json"
    config = tmp_path / "build.yaml"
    config.write_text("gravity: {sigma_deg: 0.5}\n")  # the flag below turns them on
    result = run_tagloc(
        "map", "build", "--sim", "--world", str(_short_world(tmp_path)), "--camera-stride", "6",
        "--out", str(out), "--export-graph", str(graph), "--report", str(report),
        "--exclude", "tag:13", "--exclude", "time:0-1", "--uncertain-cm", "2",
        "--config", str(config), "--gravity-aligned-odometry", "--anchor-sigma", "0.001,0.5",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    records = [json.loads(line) for line in graph.read_text().splitlines()]
    assert records[0]["type"] == "header" and records[0]["factors"] == len(records) - 1
    kinds = {r["type"] for r in records[1:]}
    # the exclusions leave the survey's lidar sweeps: their scan-matching factors stay
    assert kinds == {"observation", "odometry", "anchor", "gravity", "scan_match"}
    obs = [r for r in records if r["type"] == "observation"]
    assert all(r["tag"] != 13 and r["t_s"] > 1.0 for r in obs)
    (anchor,) = [r for r in records if r["type"] == "anchor"]
    # with gravity priors the anchor's tilt is gravity's: its sigmas are along map's axes, the
    # tilt free (0.1 rad), the heading the anchor's own
    expected = [0.001] * 3 + [0.1, 0.1, np.radians(0.5)]
    np.testing.assert_allclose(anchor["sigma"], expected, rtol=1e-6)
    gravity = [r for r in records if r["type"] == "gravity"]
    assert all(
        r["whitened"]
        == pytest.approx(np.radians(r["tilt_deg"]) / np.radians(0.5), rel=1e-2, abs=1e-3)
        for r in gravity
    )
    assert load_tag_map(out).get(13) is None
    qa = json.loads(report.read_text())
    assert qa["gravity_priors"] is True and qa["uncertainty_flag_m"] == 0.02
    flagged = [t for t in qa["tags"] if t["uncertain"]]
    assert flagged and all(t["position_sigma_mm"] > 20 and t["advice"] for t in flagged)
    assert "map tilt against the odometry's gravity" in result.stdout
    assert "uncertain tags (position sigma > 2 cm)" in result.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--exclude", "tag:abc"), "--exclude 'tag:abc': expected tag:ID"),
        (("--exclude", "tag:999"), "tag 999 is never detected"),
        (("--anchor-sigma", "0.01"), "--anchor-sigma '0.01': expected POS_M,ROT_DEG"),
        (("--anchor-sigma", "0,1"), "expected 0 < POS_M <= 10"),
        (("--uncertain-cm", "0"), "--uncertain-cm"),
    ],
)
def test_bad_options_fail_in_one_line(tmp_path: Path, args: tuple[str, ...], message: str) -> None:
    out, graph = tmp_path / "tags.yaml", tmp_path / "graph.jsonl"
    result = run_tagloc(
        "map", "build", "--sim", "--world", str(_short_world(tmp_path)), "--camera-stride", "9",
        "--out", str(out), "--export-graph", str(graph), *args,
    )  # fmt: skip
    assert result.returncode == 1, result.stdout
    assert result.stderr.count("\n") == 1 and message in result.stderr
    assert not out.exists() and not graph.exists()


def test_bad_config_names_the_field(tmp_path: Path) -> None:
    config, out = tmp_path / "build.yaml", tmp_path / "tags.yaml"
    config.write_text("gravity: {priors: true, sigma_deg: -1}\n")
    result = run_tagloc(
        "map", "build", "--sim", "--world", str(_short_world(tmp_path)), "--camera-stride", "9",
        "--out", str(out), "--config", str(config),
    )  # fmt: skip
    assert result.returncode == 1
    assert f"{config}: gravity.sigma_deg" in result.stderr and not out.exists()


def test_dupont_with_measured_anchor_file_and_gravity(tmp_path: Path) -> None:
    if not (DUPONT / "tag_detections.bag.bz2").is_file():
        pytest.skip(f"dupont data set not found at {DUPONT.resolve()} (../shared/data/dupont)")
    anchors, out = tmp_path / "anchors.yaml", tmp_path / "tags.yaml"
    anchors.write_text(
        "version: 1\ntags:\n  - {id: 6, size: 0.15, position: [1.92018, 0.5987, 2.2390], "
        "quat_xyzw: [0, -0.7071067812, 0, 0.7071067812], anchor: true, "
        "anchor_sigma: {position_m: 0.0001, rotation_deg: 0.5}}\n"
    )
    result = run_tagloc(
        "map", "build", "--bag", str(DUPONT / "tag_detections.bag.bz2"),
        "--cameras", str(DUPONT / "cameras.yaml"),
        "--camera-poses", str(DUPONT / "camera_poses.yaml"),
        "--tagslam", str(DUPONT / "tagslam.yaml"), "--anchors", str(anchors),
        "--odom-topic", "/fla/vio/odom", "--corner-order", "bl_br_tr_tl",
        "--config", str(REPO / "docs" / "dupont_map.yaml"), "--out", str(out),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    line = next(x for x in result.stdout.splitlines() if "map tilt" in x)
    assert float(line.split("gravity ")[1].split(" deg")[0]) <= 0.2
    assert len(load_tag_map(out)) == 20


def test_map_diff_tells_moves_beyond_and_within_uncertainty(tmp_path: Path) -> None:
    cov = (
        "covariance: ["
        + ", ".join(
            str(0.0025 if i == j and i < 3 else (1e-4 if i == j else 0.0))
            for i in range(6)
            for j in range(6)
        )
        + "]"
    )
    entry = "  - {{id: {id}, size: 0.16, position: [{x}, 0, 1], quat_xyzw: [0, 0, 0, 1], {cov}}}\n"
    old, new = tmp_path / "old.yaml", tmp_path / "new.yaml"
    old.write_text(
        "version: 1\ntags:\n" + entry.format(id=1, x=0, cov=cov) + entry.format(id=2, x=5, cov=cov)
    )
    new.write_text(
        "version: 1\ntags:\n"
        + entry.format(id=1, x=0.1, cov=cov)
        + entry.format(id=2, x=5.5, cov=cov)
    )
    result = run_tagloc("map", "diff", str(old), str(new))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert (
        "tag36h11:1 moved 10.0 cm" in lines[0] and "1.4 sigma: within their uncertainty" in lines[0]
    )
    assert (
        "tag36h11:2 moved 50.0 cm" in lines[1] and "7.1 sigma: beyond their uncertainty" in lines[1]
    )
