"""``tagloc sim record``: a simulated drive as a bag any reader (and ``tagloc localize``) takes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cli_runner import run_tagloc
from tagloc.io import BagSource, read_tum
from tagloc.tags import load_tag_map


@pytest.mark.parametrize("name", ["drive.bag", "drive.mcap"])
def test_recorded_drive_is_a_bag_with_truth_that_localizes(tmp_path: Path, name: str) -> None:
    bag = tmp_path / name
    result = run_tagloc("sim", "record", "--out", str(bag), "--duration", "12", "--seed", "3")
    assert result.returncode == 0, result.stderr
    assert load_tag_map(tmp_path / "tags.yaml").ids()
    source = BagSource(bag)
    assert {"/odom", "/tag_detections", "/ground_truth", "/camera/camera_info"} <= set(
        source.bag_topics
    )
    out = tmp_path / "loc"
    result = run_tagloc("localize", str(bag), "--tags", str(tmp_path / "tags.yaml"), "--out",
                     str(out), "--no-bag")  # fmt: skip
    assert result.returncode == 0, result.stderr
    _, T_fused = read_tum(out / "fused.tum")
    stamps, T_truth = read_tum(out / "truth.tum")
    assert len(stamps) == 1201  # 12 s of 100 Hz odometry
    err = np.linalg.norm(np.asarray(T_fused.translation) - T_truth.translation, axis=1)
    assert np.sqrt(np.mean(err[len(err) // 2 :] ** 2)) < 0.1  # initialized after a few frames


def test_bad_format_and_scenario_are_one_line(tmp_path: Path) -> None:
    for args, words in ((("--format", "zip"), "--format 'zip'"),
                        (("--scenario", "volcano"), "unknown scenario")):  # fmt: skip
        result = run_tagloc("sim", "record", "--out", str(tmp_path / "x.mcap"), *args)
        assert result.returncode == 1
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and words in lines[0], result.stderr
        assert not (tmp_path / "x.mcap").exists()
