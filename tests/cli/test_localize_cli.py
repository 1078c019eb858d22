"""``tagloc localize``: scenario and bag in, TUM / events / bag out; bad input is one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_runner import run_tagloc
from tagloc.cli.localize_cmd import write_stream_bag
from tagloc.io import BagSource, read_tum
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.tags import save_tag_map


@pytest.fixture(scope="module")
def drive_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A 15 s simulated drive recorded to MCAP, and its tag map."""
    root = tmp_path_factory.mktemp("bag")
    scenario = build_scenario("default", seed=2, duration_s=15.0)
    write_stream_bag(ScenarioSource(scenario), root / "drive.mcap")
    save_tag_map(scenario.tag_map, root / "tags.yaml")
    return root / "drive.mcap", root / "tags.yaml"


def test_scenario_writes_tum_events_and_a_bag(tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = run_tagloc("localize", "--scenario", "default", "--duration", "15", "--out", str(out))
    assert result.returncode == 0, result.stderr
    names = {p.name for p in out.iterdir()}
    assert {"fused.tum", "odometry.tum", "truth.tum", "events.jsonl", "fixes.jsonl"} <= names
    assert {"localization.mcap", "localizer.yaml", "summary.txt"} <= names
    assert not [n for n in names if n.startswith(".")]  # no temporary files left
    stamps, T_fused = read_tum(out / "fused.tum")
    _, T_truth = read_tum(out / "truth.tum")
    err = np.linalg.norm(np.asarray(T_fused.translation) - T_truth.translation, axis=1)
    assert len(stamps) == 1501 and np.sqrt(np.mean(err**2)) < 0.1
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    assert any(e["kind"] == "initialized" for e in events)
    # a fix's decision is written once, final, in fixes.jsonl (not also as an event)
    assert not {e["kind"] for e in events} & {"pending_consistency", "accepted", "gated_chi2"}
    fixes = [json.loads(line) for line in (out / "fixes.jsonl").read_text().splitlines()]
    assert fixes[0]["decision"] == "initialized"  # held as pending, written once decided
    bag = BagSource(out / "localization.mcap")
    assert set(bag.topics) == {"/tf", "/localization/pose"}
    assert "ATE RMSE" in result.stdout


def test_bag_input_localizes_like_the_scenario(
    drive_bag: tuple[Path, Path], tmp_path: Path
) -> None:
    path, tags = drive_bag
    out = tmp_path / "out"
    result = run_tagloc("localize", str(path), "--tags", str(tags), "--out", str(out), "--no-bag")
    assert result.returncode == 0, result.stderr
    _, T_fused = read_tum(out / "fused.tum")
    _, T_truth = read_tum(out / "truth.tum")
    err = np.linalg.norm(np.asarray(T_fused.translation) - T_truth.translation, axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.1
    assert not (out / "localization.mcap").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((), "give exactly one input"),
        (("--scenario", "default", "BAG"), "give exactly one input"),
        (("BAG",), "--tags"),
        (("BAG", "--tags", "TAGS", "--odom-topic", "/robot/odom"), "'/robot/odom'"),
        (("--scenario", "volcano"), "unknown scenario 'volcano'"),
        (("missing.mcap", "--tags", "TAGS"), "missing.mcap"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(
    drive_bag: tuple[Path, Path], tmp_path: Path, args: tuple[str, ...], message: str
) -> None:
    path, tags = drive_bag
    real = [str(path) if a == "BAG" else str(tags) if a == "TAGS" else a for a in args]
    out = tmp_path / "out"
    result = run_tagloc("localize", *real, "--out", str(out))
    assert result.returncode == 1, result.stdout
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr
    assert not out.exists()


def test_bag_output_uses_the_configured_frame_names(
    drive_bag: tuple[Path, Path], tmp_path: Path
) -> None:
    """dimos naming: the odometry origin is ``world`` and the published edge ``world -> map``.
    The bag's odometry is ``odom -> base_link``, so the node is told its frame (``odom_frame``)
    and publishes the inverse edge under the dimos names."""
    from tagloc.geometry import SE3
    from tagloc.io import TransformMsg

    path, tags = drive_bag
    config = tmp_path / "localizer.yaml"
    config.write_text("frames: {convention: dimos, odom_frame: odom}\n")
    out = tmp_path / "out"
    done = run_tagloc(
        "localize", str(path), "--tags", str(tags), "--config", str(config), "--out", str(out)
    )
    assert done.returncode == 0, done.stderr
    tf = [m for t, m in BagSource(out / "localization.mcap") if t == "/tf"]
    assert tf and all(isinstance(m, TransformMsg) for m in tf)
    assert {(m.parent, m.child) for m in tf} == {("odom", "map")}  # type: ignore[union-attr]
    poses = {m.stamp_ns: m for t, m in BagSource(out / "localization.mcap") if t != "/tf"}
    for m in tf[:: max(len(tf) // 20, 1)]:
        pose = poses[m.stamp_ns]
        assert pose.frame_id == "map"  # type: ignore[union-attr]
        # T_map_base = T_map_odom @ T_odom_base and the bag carries T_odom_map
        T_odom_map: SE3 = m.T_parent_child  # type: ignore[union-attr]
        T_odom_base = T_odom_map @ pose.T_frame_child  # type: ignore[union-attr]
        assert np.all(np.isfinite(np.asarray(T_odom_base.translation)))
    saved = (out / "localizer.yaml").read_text()
    assert "convention: dimos" in saved and "publish: odom_to_map" in saved
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ladder"]["transitions"] >= 1
    assert sum(summary["ladder"]["seconds_at_level"].values()) > 14.0


def test_a_wrong_detections_topic_is_one_line(drive_bag: tuple[Path, Path], tmp_path: Path) -> None:
    path, tags = drive_bag
    out = tmp_path / "out"
    done = run_tagloc(
        "localize", str(path), "--tags", str(tags), "--out", str(out),
        "--detections-topic", "/nope", "--image-topic", "/nope2",
    )  # fmt: skip
    assert done.returncode == 1 and "no camera frames" in done.stderr, done.stderr
    assert not out.exists() or not list(out.iterdir())


def test_realtime_runs_the_live_order_and_reports_its_latency(tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = run_tagloc(
        "localize", "--scenario", "default", "--duration", "12", "--realtime", "--speed", "6",
        "--out", str(out), "--no-bag",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "publish_first: true" in (out / "localizer.yaml").read_text()
    summary = json.loads((out / "summary.json").read_text())
    rt = summary["realtime"]
    assert rt["speed"] == 6.0 and rt["frames_dropped"] == 0  # detections need no worker
    assert rt["odom_to_estimate"]["n"] == summary["odometry_samples"] == 1201
    # the frames come as detections (no worker, no drops): the fixes are those of the replay
    # (69 on this stretch), applied one odometry sample later
    assert summary["fixes_accepted"] > 60


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--scenario", "default", "--duration", "nan"), "--duration nan: expected a finite"),
        (("--scenario", "default", "--seed", "-1"), "--seed -1: expected an integer >= 0"),
        (("--scenario", "default", "--realtime", "--speed", "0"), "--speed 0: expected"),
    ],
)
def test_bad_options_are_one_line_before_any_work(
    tmp_path: Path, args: tuple[str, ...], message: str
) -> None:
    out = tmp_path / "out"
    done = run_tagloc("localize", *args, "--out", str(out))
    assert done.returncode == 1 and message in done.stderr, done.stderr
    assert not out.exists()


def test_an_existing_directory_in_place_of_an_output_file_is_kept(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "fused.tum").mkdir(parents=True)
    (out / "fused.tum" / "keep.txt").write_text("mine")
    done = run_tagloc("localize", "--scenario", "default", "--duration", "5", "--out", str(out))
    assert done.returncode == 1 and "fused.tum" in done.stderr, done.stderr
    assert (out / "fused.tum" / "keep.txt").read_text() == "mine"
    assert sorted(p.name for p in out.iterdir()) == ["fused.tum"]
