"""``tagloc eval bag`` and the camera checks of ``tagloc localize``, as a user runs them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cli_runner import one_error_line, run_tagloc

REPO = Path(__file__).resolve().parents[2]
DUPONT = REPO / ".." / "shared" / "data" / "dupont"
KALIBR = """cam0:
  camera_model: pinhole
  intrinsics: [{f}, {f}, 639.5, 359.5]
  distortion_model: radtan
  distortion_coeffs: [0.0, 0.0, 0.0, 0.0]
  resolution: [1280, 720]
"""


@pytest.fixture(scope="module")
def sim_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 25 s simulated drive as MCAP, its tags.yaml beside it, and camera files: the right
    one (the simulator's camera) and one with the focal length halved."""
    d = tmp_path_factory.mktemp("bag")
    done = run_tagloc("sim", "record", "--out", str(d / "drive.mcap"), "--duration", "25")
    assert done.returncode == 0, done.stderr
    (d / "right.yaml").write_text(KALIBR.format(f=640.0))
    (d / "half.yaml").write_text(KALIBR.format(f=320.0))
    return d


def test_eval_bag_writes_its_report(sim_bag: Path, tmp_path: Path) -> None:
    out = tmp_path / "eval"
    (tmp_path / "cp.yaml").write_text("checkpoints:\n  - {name: start, x: 2.0, y: 10.25}\n")
    done = run_tagloc(
        "eval", "bag", str(sim_bag / "drive.mcap"), "--tags", str(sim_bag / "tags.yaml"),
        "--cameras", str(sim_bag / "right.yaml"), "--hold-out", "13", "--checkpoints",
        str(tmp_path / "cp.yaml"), "--out", str(out),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in out.iterdir()) == ["report.html", "summary.json", "summary.txt"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["camera_check"]["problems"] == []
    overall = summary["held_out_tags"]["overall"]["position_m"]
    assert overall["n"] > 0 and 0.0 < overall["median"] < 0.5
    assert summary["acceptance"]["note"].startswith("the bag has pre-detected corners only")
    assert summary["checkpoints"]["from"].endswith("cp.yaml")
    assert "held-out tags" in done.stdout and "fix acceptance" in done.stdout
    # the verdict, from the held-out tags' p95 (and the extrinsic check's warning)
    p95 = overall["p95"]
    verdict = summary["verdict"]
    warned = bool(summary["extrinsic_check"] and summary["extrinsic_check"]["warning"])
    assert verdict["passed"] is (p95 <= 0.10 and not warned)
    assert f"p95 {p95 * 100:.1f} cm" in verdict["reason"]
    page = (out / "report.html").read_text()
    for section in ("verdict", "Trajectory (top-down)", "Fix decisions (refusals by reason)",
                    "Held-out tags"):  # fmt: skip
        assert section in page


def test_eval_bag_unknown_held_out_tag_is_one_line(sim_bag: Path, tmp_path: Path) -> None:
    out = tmp_path / "eval"
    done = run_tagloc(
        "eval", "bag", str(sim_bag / "drive.mcap"), "--tags", str(sim_bag / "tags.yaml"),
        "--hold-out", "999", "--out", str(out),
    )  # fmt: skip
    assert "--hold-out 999: no tag tag36h11:999" in one_error_line(done)
    assert not out.exists()


@pytest.mark.parametrize("info_topic", ["/camera/camera_info", "/no_camera_info"])
def test_localize_refuses_another_cameras_file(
    sim_bag: Path, tmp_path: Path, info_topic: str
) -> None:
    """A halved focal length: refused before any fix, from the bag's CameraInfo or, without
    one, from the depth of the tags against the odometry's motion."""
    out = tmp_path / "loc"
    done = run_tagloc(
        "localize", str(sim_bag / "drive.mcap"), "--tags", str(sim_bag / "tags.yaml"),
        "--cameras", str(sim_bag / "half.yaml"), "--camera-info-topic", info_topic,
        "--out", str(out),
    )  # fmt: skip
    line = one_error_line(done)
    assert "the camera model does not fit drive.mcap" in line and "refusing before any fix" in line
    assert ("fx = 640.0 px" in line) == (info_topic == "/camera/camera_info")
    assert not out.exists()


@pytest.mark.slow
def test_dupont_camera_passes_the_check(tmp_path: Path) -> None:
    """The real drive with its own calibration: the camera check must pass."""
    bag = DUPONT / "tag_detections.bag.bz2"
    if not bag.is_file():
        pytest.skip(f"dupont data set not found at {DUPONT.resolve()} (../shared/data/dupont)")
    common = ["--cameras", str(DUPONT / "cameras.yaml"), "--camera-poses",
              str(DUPONT / "camera_poses.yaml"), "--tagslam", str(DUPONT / "tagslam.yaml"),
              "--corner-order", "bl_br_tr_tl", "--odom-topic", "/fla/vio/odom"]  # fmt: skip
    tags = tmp_path / "tags.yaml"
    done = run_tagloc("map", "build", "--bag", str(bag), *common, "--config",
                      str(REPO / "docs" / "dupont_map.yaml"), "--out", str(tags))  # fmt: skip
    assert done.returncode == 0, done.stderr
    out = tmp_path / "loc"
    done = run_tagloc("localize", str(bag), "--tags", str(tags), *common, "--detections-topic",
                      "/fla/ovc_node/left/tags", "--no-bag", "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr
    checks = json.loads((out / "summary.json").read_text())["camera_check"]  # by camera: a rig
    assert sorted(checks) == ["cam0", "cam1"]
    for check in checks.values():
        assert check["problems"] == [] and check["n_pairs"] >= 5
        assert abs(check["pnp_scale"] - 1) < 0.1
    # eval bag takes every camera too: each camera's views of a held-out tag are predicted
    # through its own calibrated mount; the stereo pair's two predictions agree (measured:
    # median 2.5 cm each, tag 51 held out)
    out = tmp_path / "eval"
    done = run_tagloc("eval", "bag", str(bag), "--tags", str(tags), *common, "--config",
                      str(REPO / "docs" / "dupont_localizer.yaml"), "--hold-out", "51",
                      "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(summary["camera_check"]) == ["cam0", "cam1"]
    assert sorted(summary["extrinsic_check_by_camera"]) == ["cam0", "cam1"]
    per_camera = summary["held_out_tags"]["per_camera"]
    medians = {c: per_camera[c]["position_m"]["median"] for c in ("cam0", "cam1")}
    assert all(per_camera[c]["position_m"]["n"] >= 50 for c in medians)
    assert max(medians.values()) < 0.06 and abs(medians["cam0"] - medians["cam1"]) < 0.02
    assert "camera cam1:" in done.stdout and "accepted per camera" in done.stdout


def test_eval_bag_checks_its_output_before_any_work(sim_bag: Path, tmp_path: Path) -> None:
    taken = tmp_path / "a_file"
    taken.write_text("keep me\n")
    done = run_tagloc(
        "eval", "bag", str(sim_bag / "drive.mcap"), "--tags", str(sim_bag / "tags.yaml"),
        "--out", str(taken),
    )  # fmt: skip
    assert "--out" in one_error_line(done)
    assert taken.read_text() == "keep me\n"
