"""Bad input to the module: one line in its log, it keeps running, and its status says why.

A camera info of another resolution than the images, a tf tree without the camera's mounting, a
missing tag map. "Keeps running": it goes on handling every message, and once the input is good
again it localizes (the problem leaves the status).
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import pytest
from drive import drive
from harness import publish_all, wire

from tagloc.adapters.dimos.module import TaglocRelocalization
from tagloc.messages import CameraInfoMsg, ImageMsg, Message, TransformMsg
from tagloc.tags import save_tag_map

LOGGER = "tagloc.adapters.dimos.module"
STREAMS = ["tf", "color_image", "camera_info"]


def _records(n_images: int) -> list[Message]:
    """The drive up to its ``n_images``-th image (no lidar)."""
    out: list[Message] = []
    for r in drive("world").records:
        if isinstance(r, ImageMsg) and sum(isinstance(o, ImageMsg) for o in out) >= n_images:
            break
        if isinstance(r, (TransformMsg, ImageMsg, CameraInfoMsg)):
            out.append(r)
    return out


def _module(tmp_path: Path, **config: object) -> TaglocRelocalization:
    tags = tmp_path / "tags.yaml"
    save_tag_map(drive("world").tag_map, tags)
    return TaglocRelocalization(**{"tag_map": str(tags), **config})


def _warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.name == LOGGER and r.levelno >= logging.WARNING]  # fmt: skip


def _run(module: TaglocRelocalization, records: list[Message]) -> dict[str, object]:
    transports = wire(module, STREAMS)
    module.start()
    try:
        publish_all(module, transports, records)
        return module.status()
    finally:
        module.stop()


def test_camera_info_of_other_resolution(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    records = []
    for r in _records(6):
        if isinstance(r, CameraInfoMsg):  # the calibration of a 640x480 mode of the camera
            r = dataclasses.replace(r, info={**r.info, "width": 640, "height": 480})
        records.append(r)
    caplog.set_level(logging.WARNING)
    status = _run(_module(tmp_path), records)
    line = "camera frames skipped: camera info is 640x480 but images are 1280x720"
    assert _warnings(caplog) == [f"tagloc: {line}"]
    assert status["problems"] == [line]
    assert status["received"]["color_image"] == 6  # every frame handled, none used
    assert status["received"]["tf"] == sum(isinstance(r, TransformMsg) for r in records)


def test_tf_tree_without_the_camera(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    records = [r for r in _records(6) if not (isinstance(r, TransformMsg) and r.static)]
    caplog.set_level(logging.WARNING)
    status = _run(_module(tmp_path), records)
    line = "camera frames skipped: no transform base_link -> camera_optical in the tf tree"
    assert _warnings(caplog) == [f"tagloc: {line}"]
    assert status["problems"] == [line] and status["localizing"]
    assert status["received"]["color_image"] == 6


def test_the_camera_mounting_arriving_late_clears_the_problem(tmp_path: Path) -> None:
    records = _records(4)
    mount = [r for r in records if isinstance(r, TransformMsg) and r.static]
    late = [r for r in records if r not in mount]
    first_image = next(i for i, r in enumerate(late) if isinstance(r, ImageMsg))
    late[first_image + 1 : first_image + 1] = mount  # after the first frame
    status = _run(_module(tmp_path), late)
    assert status["problems"] == []


def test_missing_tag_map(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    missing = tmp_path / "no_such_tags.yaml"
    caplog.set_level(logging.WARNING)
    module = TaglocRelocalization(tag_map=str(missing))
    records = _records(3)
    status = _run(module, records)
    (line,) = _warnings(caplog)
    assert line.startswith("tagloc: not localizing:") and str(missing) in line
    assert status["problems"] == [line.removeprefix("tagloc: ")]
    assert status["localizing"] is False and status["floor"] is None
    assert status["received"]["tf"] == sum(isinstance(r, TransformMsg) for r in records)
