"""Fuzzed bags: a small bag written by :class:`BagSink` (MCAP, ROS 1, ROS 2 sqlite3 with its
``metadata.yaml``), its bytes then flipped, inserted, deleted or truncated. Opening and reading it
either yields records (and camera infos that build a camera model or fail with
:class:`CameraModelError`) or raises a :class:`TaglocError` on one line naming the bag."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fuzz_helpers import damaged
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from tagloc.camera import from_camera_info
from tagloc.errors import TaglocError
from tagloc.geometry import SE3
from tagloc.io import (
    BagSink,
    BagSource,
    CameraInfoMsg,
    GroundTruthMsg,
    ImageMsg,
    Message,
    OdometryMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.tags.detection import TagDetection

S = 1_000_000_000
FUZZ = settings(
    max_examples=25,
    database=None,
    derandomize=True,  # the same examples on every run; campaigns raise max_examples instead
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def _records() -> list[tuple[str, Message]]:
    rng = np.random.default_rng(7)
    K = [50.0, 0, 32, 0, 51.0, 24, 0, 0, 1]
    info = {"width": 64, "height": 48, "distortion_model": "plumb_bob", "D": [0.01] * 5, "K": K}
    detection = TagDetection(3, "tag36h11", np.array([[10.0, 10], [30, 10], [30, 30], [10, 30]]))
    out: list[tuple[str, Message]] = []
    for i in range(3):
        stamp = 1_700_000_000 * S + i * 10_000_000
        T = SE3.random(rng, translation_scale=5.0)
        mono = rng.integers(0, 256, (6, 9), np.uint8)
        out += [
            ("/odom", OdometryMsg(stamp, "odom", "base_link", T, np.eye(6) * 1e-3)),
            ("/tf", TransformMsg(stamp, "map", "odom", T.inverse())),
            ("/truth", GroundTruthMsg(stamp, "map", T)),
            ("/cam/image", ImageMsg(stamp, "camera", mono, "mono8")),
            ("/cam/info", CameraInfoMsg(stamp, "camera", info)),
            ("/cam/tags", TagDetectionsMsg(stamp, "camera", (detection,))),
        ]
    return out


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bags")
    out = {}
    for fmt, name in (("mcap", "a.mcap"), ("ros1", "a.bag"), ("ros2", "a_bag")):
        storage = {"storage": "sqlite3"} if fmt == "ros2" else {}
        with BagSink(root / name, fmt, **storage) as sink:  # type: ignore[arg-type]
            for topic, msg in _records():
                sink.write(topic, msg)
        out[fmt] = root / name
    return out


_edit = st.tuples(
    st.integers(0, 2**24), st.integers(0, 16), st.binary(max_size=8)
)  # position, bytes deleted, bytes inserted
EDITS = st.tuples(
    st.lists(_edit, min_size=1, max_size=6), st.one_of(st.none(), st.integers(0, 2**24))
)


def _read_all(path: Path) -> None:
    try:
        for _, msg in BagSource(path):
            if isinstance(msg, CameraInfoMsg):
                try:
                    from_camera_info(msg.info, "/cam/info CameraInfo")
                except TaglocError as exc:
                    assert "\n" not in str(exc)
    except TaglocError as exc:
        message = str(exc)
        assert "\n" not in message and len(message) < 700, message
        assert message.startswith(f"{path}"), message
        event(f"refused: {type(exc).__name__}")
        return
    event("read")


@pytest.mark.parametrize("fmt", ["mcap", "ros1"])
@FUZZ
@given(edits=EDITS)
def test_damaged_bag_file(tmp_path: Path, bags: dict[str, Path], fmt: str, edits: Any) -> None:
    path = tmp_path / bags[fmt].name
    path.write_bytes(damaged(bags[fmt].read_bytes(), edits))
    _read_all(path)


@pytest.mark.parametrize("part", ["a_bag.db3", "metadata.yaml"])
@FUZZ
@given(edits=EDITS)
def test_damaged_ros2_bag(tmp_path: Path, bags: dict[str, Path], part: str, edits: Any) -> None:
    path = tmp_path / "a_bag"
    shutil.rmtree(path, ignore_errors=True)
    shutil.copytree(bags["ros2"], path)
    (path / part).write_bytes(damaged((path / part).read_bytes(), edits))
    _read_all(path)
