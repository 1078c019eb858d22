"""The ``tagloc`` command: the demo writes its outputs; bad input gives one line and exit 1."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from cli_runner import run_tagloc
from tagloc.sim import load_default_world, load_world
from tagloc.tags.tagmap import load_tag_map


def test_demo_surveys_localizes_and_writes_the_reports(tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = run_tagloc(
        "demo", "--out", str(out), "--duration", "60", "--anchor", "1", "--anchor", "12",
        timeout_s=900.0,  # the lidar-aided survey: about 4 min on a loaded 2-core machine
    )
    assert result.returncode == 0, result.stderr
    png = (out / "drive.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 50_000
    # the world written beside the result is the one that was driven, and reloads identically
    assert load_world(out / "world.yaml") == load_default_world()
    for words in ("end-point drift", "survey: map error", "fused ATE RMSE, built map",
                  "fused ATE RMSE, true map", "largest correction jump"):  # fmt: skip
        assert words in result.stdout, words
    assert sorted(p.name for p in out.iterdir()) == [
        "drive.png",
        "localize",
        "localize_true_map",
        "map",
        "world.yaml",
    ]
    built = load_tag_map(out / "map" / "tags.yaml")
    assert len(built) == len(load_default_world().tags)
    assert [e.id for e in built.anchors] == [1, 12]
    assert "survey: anchor tags (true poses)" in result.stdout
    for run in ("localize", "localize_true_map"):
        summary = json.loads((out / run / "summary.json").read_text())
        assert (
            summary["estimators"]["fused"]["ate_rmse_m"]
            < summary["estimators"]["odometry"]["ate_rmse_m"]
        )
        assert {"report.html", "fused.tum", "truth.tum"} <= {p.name for p in (out / run).iterdir()}
    # the two reports: distinct titles, each saying which map it used
    runs = ("localize", "localize_true_map")
    html = {run: (out / run / "report.html").read_text() for run in runs}
    titles = {run: text.split("<title>")[1].split("</title>")[0] for run, text in html.items()}
    assert "built tag map" in titles["localize"] and "true tag map" in titles["localize_true_map"]
    assert str(out / "map" / "tags.yaml") in html["localize"]


def test_demo_quick_skips_the_survey(tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = run_tagloc("demo", "--out", str(out), "--duration", "20", "--quick")
    assert result.returncode == 0, result.stderr
    assert "survey:" not in result.stdout
    assert sorted(p.name for p in out.iterdir()) == ["drive.png", "localize_true_map", "world.yaml"]


def _write_world_with(tmp_path: Path, edit: str) -> Path:
    data = yaml.safe_load(load_default_world().to_yaml_text())
    if edit == "duplicate_id":
        data["tags"][3]["id"] = data["tags"][1]["id"]
    elif edit == "no_size":
        del data["tags"][2]["size"]
    elif edit == "bad_quat":
        data["tags"][0].pop("wall", None)
        data["tags"][0]["pose"] = {"position": [1.0, 2.0, 1.2], "quat_xyzw": [0.0, 0.0, 0.5, 0.5]}
    elif edit == "odometry_model":
        data["robot"]["odometry"]["model"] = "hovercraft"
    path = tmp_path / "world.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        ("duplicate_id", "tags[3].id"),
        ("no_size", "tags[2].size"),
        ("bad_quat", "tags[0].pose.quat_xyzw"),
        ("odometry_model", "robot.odometry"),
    ],
)
def test_bad_world_is_one_line_naming_file_and_field(tmp_path: Path, edit: str, field: str) -> None:
    path = _write_world_with(tmp_path, edit)
    out = tmp_path / "out"
    result = run_tagloc("demo", "--world", str(path), "--out", str(out))
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert str(path) in lines[0] and field in lines[0]
    assert not out.exists()  # nothing half-written


def test_demo_unknown_anchor_is_one_line_and_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = run_tagloc("demo", "--out", str(out), "--anchor", "99")
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "tag36h11:99" in lines[0], result.stderr
    assert not out.exists()


def test_world_check_accepts_the_default_world() -> None:
    import tagloc.sim

    path = Path(tagloc.sim.__file__).parent / "worlds" / "office.yaml"
    result = run_tagloc("world", "check", str(path))
    assert result.returncode == 0, result.stderr
    assert "37 tags" in result.stdout


def test_demo_seed_changes_the_odometry(tmp_path: Path) -> None:
    from tagloc.sim import simulate_drive

    world = load_default_world()
    a = simulate_drive(world, seed=1)
    b = simulate_drive(world, seed=2)
    assert not np.allclose(np.asarray(a.T_odom_base.translation), b.T_odom_base.translation)
