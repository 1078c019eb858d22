"""Fuzzed input files other than configurations: Kalibr camera files, TUM trajectories and
tagSLAM rig files (damage: ``fuzz_helpers``). A reader returns usable values (cameras that
project, finite poses within bounds) or raises one short TaglocError line naming the file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from fuzz_helpers import (
    EDITS,
    FUZZ,
    damaged,
    expect_one_line,
    load_or_refuse,
    value_damage,
)
from hypothesis import event, given
from hypothesis import strategies as st

from tagloc.errors import TaglocError
from tagloc.io import load_kalibr_cameras, read_tum

# ----- Kalibr camera files ------------------------------------------------------------------------
CAMERAS_TEXT = """\
cam0:
  camera_model: pinhole
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  distortion_model: radtan
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  camera_model: pinhole
  intrinsics: [280.0, 280.0, 320.0, 240.0]
  distortion_model: equidistant
  distortion_coeffs: [0.01, -0.002, 0.0005, -0.0001]
  resolution: [640, 480]
"""


def _use_cameras(path: Path) -> None:
    for camera in load_kalibr_cameras(path).values():
        points = np.array([[0.0, 0.0, 1.0], [0.3, -0.2, 2.0]])
        camera.project(points)


@FUZZ
@given(edits=EDITS)
def test_camera_yaml_bytes(tmp_path: Path, edits: Any) -> None:
    load_or_refuse(_use_cameras, tmp_path / "cameras.yaml", damaged(CAMERAS_TEXT.encode(), edits))


@FUZZ
@given(data=st.data())
def test_camera_yaml_values(tmp_path: Path, data: st.DataObject) -> None:
    text = value_damage(CAMERAS_TEXT, data)
    load_or_refuse(_use_cameras, tmp_path / "cameras.yaml", text.encode())


# ----- TUM files ----------------------------------------------------------------------------------
TUM_TEXT = (
    "# timestamp tx ty tz qx qy qz qw\n"
    "1.000000000 0.0 0.0 0.0 0.0 0.0 0.0 1.0\n"
    "1.100000000 0.1 0.0 0.0 0.0 0.0 0.0499792 0.9987503\n"
    "1.2 0.2 0.01 0.0 0 0 0.0998334 0.9950042\n"
    "1.30e0 3.0e-1 2e-2 0 0 0 0.1494381 0.9887711\n"
)
TUM_TOKENS = st.sampled_from(
    [b" ", b"\n", b"#", b"nan", b"inf", b"1e308", b"-1e308", b"1e999999999", b"-", b".", b"e",
     b"9" * 25, b"0", b"\xff", b"\t", b"\x00"]
)  # fmt: skip
TUM_EDITS = st.tuples(
    st.lists(
        st.tuples(st.integers(0, 2**20), st.integers(0, 8), TUM_TOKENS), min_size=1, max_size=6
    ),
    st.one_of(st.none(), st.integers(0, 2**20)),
)


def _use_tum(path: Path) -> None:
    stamps, poses = read_tum(path)
    assert np.all(np.diff(stamps) > 0) and stamps.dtype == np.int64
    assert np.all(np.isfinite(poses.as_matrix()))
    assert np.all(np.abs(poses.translation) <= 1e8)
    assert np.isfinite(np.sum(np.square(poses.translation)))  # an ATE over them cannot overflow


@FUZZ
@given(edits=TUM_EDITS)
def test_tum_bytes(tmp_path: Path, edits: Any) -> None:
    load_or_refuse(_use_tum, tmp_path / "t.tum", damaged(TUM_TEXT.encode(), edits))


# ----- tagSLAM rig files (camera_poses.yaml, tagslam.yaml) ---------------------------------------
TAGSLAM_TEXT = """\
bodies:
  - rig:
      odom_topic: /odom
      ignore_tags: [5, 6]
      T_body_odom: {position: {x: 0.1, y: 0, z: 0}, rotation: {x: 0, y: 0, z: 0.1}}
  - lab:
      is_static: true
      default_tag_size: 0.16
      tags:
        - {id: 1, size: 0.2, pose: {position: {x: 1, y: 2, z: 0}, rotation: {x: 0, y: 0, z: 1}}}
        - {id: 2}
tag_id_remap:
  - id: 20
    remaps: [{remap_id: 420, start_time: 10.0, end_time: 20.0}]
"""
CAMERA_POSES_TEXT = """\
cam0:
  pose: {position: {x: 0.1, y: 0, z: 0.2}, rotation: {x: 0, y: 0, z: 0}}
cam1:
  pose: {position: {x: -0.1, y: 0, z: 0.2}, rotation: {x: 0, y: 0, z: 3.14}}
"""


def _use_rig(path: Path) -> None:
    from tagloc.mapping.stream_survey import parse_camera_poses, parse_tagslam

    text = path.read_bytes().decode("utf-8", errors="replace")
    parser = parse_tagslam if path.name == "tagslam.yaml" else parse_camera_poses
    try:
        parser(text, str(path))
    except TaglocError as exc:
        expect_one_line(exc, path)
        event(f"refused: {type(exc).__name__}")


@FUZZ
@given(data=st.data(), which=st.sampled_from(["tagslam.yaml", "camera_poses.yaml"]))
def test_rig_yaml_values(tmp_path: Path, data: st.DataObject, which: str) -> None:
    text = value_damage(TAGSLAM_TEXT if which == "tagslam.yaml" else CAMERA_POSES_TEXT, data)
    (tmp_path / which).write_text(text)
    _use_rig(tmp_path / which)


@FUZZ
@given(edits=EDITS, which=st.sampled_from(["tagslam.yaml", "camera_poses.yaml"]))
def test_rig_yaml_bytes(tmp_path: Path, edits: Any, which: str) -> None:
    text = TAGSLAM_TEXT if which == "tagslam.yaml" else CAMERA_POSES_TEXT
    (tmp_path / which).write_bytes(damaged(text.encode(), edits))
    _use_rig(tmp_path / which)
