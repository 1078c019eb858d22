"""What alignment, GTSAM and the simulator cannot do reaches the user as one line; nothing is
written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cli_runner import one_error_line, run_tagloc
from tagloc.geometry import SE3
from tagloc.io import write_tum

DUPONT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "dupont"


def test_eval_files_align_on_a_static_track_is_one_line(tmp_path: Path) -> None:
    stamps_ns = np.arange(30, dtype=np.int64) * 100_000_000
    write_tum(
        tmp_path / "still.tum", stamps_ns, SE3.from_rotvec(np.zeros((30, 3)), np.zeros((30, 3)))
    )
    done = run_tagloc("eval", "files", "--truth", str(tmp_path / "still.tum"), "--est",
                      str(tmp_path / "still.tum"), "--align")  # fmt: skip
    line = one_error_line(done)
    assert "cannot align the estimate onto the reference" in line and "without alignment" in line
    assert "Traceback" not in done.stderr


def test_map_build_that_sees_no_tag_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "tags.yaml"
    done = run_tagloc("map", "build", "--sim", "--camera-stride", "1000000", "--out", str(out))
    assert "detects no tag" in one_error_line(done)
    assert not out.exists() and "Traceback" not in done.stderr


def test_single_camera_bag_without_extrinsics_is_one_line(tmp_path: Path) -> None:
    if not (DUPONT / "tag_detections.bag.bz2").is_file():
        pytest.skip(f"dupont data set not found at {DUPONT.resolve()} (../shared/data/dupont)")
    one_camera = tmp_path / "cameras.yaml"  # cam0 of the rig, alone
    one_camera.write_text("".join((DUPONT / "cameras.yaml").read_text().splitlines(True)[:9]))
    out, report = tmp_path / "tags.yaml", tmp_path / "qa.md"
    done = run_tagloc(
        "map", "build", "--bag", str(DUPONT / "tag_detections.bag.bz2"), "--cameras",
        str(one_camera), "--odom-topic", "/fla/vio/odom", "--corner-order", "bl_br_tr_tl",
        "--tag-size", "0.15", "--out", str(out), "--report", str(report),
    )  # fmt: skip
    line = one_error_line(done)
    assert "cannot solve" in line and "near tag tag36h11:" in line and "--camera-poses" in line
    assert "Traceback" not in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cameras.yaml"]
