"""``tagloc map build``: a simulated or recorded survey in, tags.yaml and a QA report out;
bad input gives one line naming the file or field, exit 1, and no map file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_runner import run_tagloc
from tagloc.sim import load_default_world
from tagloc.tags.tagmap import load_tag_map

DUPONT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "dupont"


def _short_world(tmp_path: Path) -> Path:
    world = load_default_world()
    world = world.model_copy(update={"route": world.route.model_copy(update={"repeat": 1})})
    path = tmp_path / "world.yaml"
    path.write_text(world.to_yaml_text())
    return path


def test_sim_build_writes_map_and_json_report(tmp_path: Path) -> None:
    out, report = tmp_path / "tags.yaml", tmp_path / "qa.json"
    result = run_tagloc(
        "map", "build", "--sim", "--world", str(_short_world(tmp_path)), "--camera-stride", "6",
        "--out", str(out), "--report", str(report), "--no-lidar",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "reprojection RMS" in result.stdout and f"wrote {out}" in result.stdout
    tag_map = load_tag_map(out)
    world = load_default_world()
    assert len(tag_map) == len(world.tags) and len(tag_map.anchors) == 1
    anchor = tag_map.anchors[0]
    assert anchor.T_frame_tag().allclose(world.T_map_tag(world.find_tag(anchor.id)), atol=1e-3)
    qa = json.loads(report.read_text())
    assert qa["observations"] > 500 and len(qa["tags"]) == len(world.tags)
    assert qa["reproj_rms_px"] < 1.0


def test_markdown_report_and_map_check_round_trip(tmp_path: Path) -> None:
    out, report = tmp_path / "tags.yaml", tmp_path / "qa.md"
    result = run_tagloc(
        "map", "build", "--sim", "--world", str(_short_world(tmp_path)), "--camera-stride", "9",
        "--anchor", "3", "--out", str(out), "--report", str(report), "--no-lidar",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert report.read_text().startswith("# Tag map build report")
    assert [e.id for e in load_tag_map(out).anchors] == [3]
    check = run_tagloc("map", "check", str(out))
    assert check.returncode == 0 and "anchors: 1" in check.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((), "give exactly one of --bag PATH or --sim"),
        (("--bag", "missing.bag"), "--bag needs --cameras cameras.yaml"),
        (("--sim", "--size", "x=0.1"), "--size"),
    ],
)
def test_bad_arguments_fail_in_one_line(
    tmp_path: Path, args: tuple[str, ...], message: str
) -> None:
    out = tmp_path / "tags.yaml"
    result = run_tagloc("map", "build", "--out", str(out), *args)
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and message in result.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("tags: [\n", "line 2, column 1: invalid YAML"),
        (
            "version: 1\ntags:\n  - {id: 1, family: tag36h11, size: -0.1, frame: map, "
            "position: [0, 0, 0], quat_xyzw: [0, 0, 0, 1]}\n",
            "tags[0] (id 1): size: must be > 0",
        ),
    ],
)
def test_malformed_anchor_map_fails_before_reading_the_bag(
    tmp_path: Path, text: str, message: str
) -> None:
    bad, out = tmp_path / "anchors.yaml", tmp_path / "tags.yaml"
    bad.write_text(text)
    result = run_tagloc(
        "map", "build", "--bag", str(tmp_path / "missing.bag"), "--cameras",
        str(tmp_path / "cameras.yaml"), "--anchors", str(bad), "--out", str(out),
    )  # fmt: skip
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and f"{bad}: {message}" in result.stderr
    assert not out.exists()


def test_anchor_map_with_sim_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "tags.yaml"
    result = run_tagloc("map", "build", "--sim", "--anchors", "x.yaml", "--out", str(out))
    assert result.returncode == 1 and "--anchors is for --bag" in result.stderr
    assert result.stderr.count("\n") == 1 and not out.exists()


def _dupont_args(tmp_path: Path) -> list[str]:
    if not (DUPONT / "tag_detections.bag.bz2").is_file():
        pytest.skip(f"dupont data set not found at {DUPONT.resolve()} (../shared/data/dupont)")
    return [
        "map", "build", "--bag", str(DUPONT / "tag_detections.bag.bz2"),
        "--cameras", str(DUPONT / "cameras.yaml"),
        "--camera-poses", str(DUPONT / "camera_poses.yaml"),
        "--odom-topic", "/fla/vio/odom", "--corner-order", "bl_br_tr_tl",
    ]  # fmt: skip


def test_bag_without_odometry_or_tag_size_fails_without_writing(tmp_path: Path) -> None:
    args = _dupont_args(tmp_path)
    out = tmp_path / "tags.yaml"
    no_odom = [a if a != "/fla/vio/odom" else "/nope" for a in args]
    result = run_tagloc(*no_odom, "--tag-size", "0.15", "--out", str(out))
    assert result.returncode == 1 and "/nope" in result.stderr and not out.exists()
    result = run_tagloc(*args, "--anchor", "6", "--anchor", "3", "--out", str(out))
    assert result.returncode == 1 and "--anchor 6: no pose known" in result.stderr
    result = run_tagloc(*args, "--out", str(out))
    assert result.returncode == 1 and "has no known size" in result.stderr
    assert result.stderr.count("\n") == 1 and not out.exists()


def test_dupont_bag_build(tmp_path: Path) -> None:
    out = tmp_path / "tags.yaml"
    args = [*_dupont_args(tmp_path), "--tagslam", str(DUPONT / "tagslam.yaml")]
    result = run_tagloc(*args, "--out", str(out))
    assert result.returncode == 0, result.stderr
    tag_map = load_tag_map(out)
    assert len(tag_map) == 20 and tag_map.get(381) is None
    assert np.allclose(tag_map.T_frame_tag(6).translation, [1.92018, 0.5987, 2.2390], atol=1e-3)
    assert "cam0" in result.stdout and "cam1" in result.stdout
