"""Corrections through dimos's transports equal the offline node's on the same messages.

A simulated drive (rendered camera images, TF odometry, camera info, lidar sweeps against a
``.pc2.lcm`` premap) goes through LCM transports into :class:`TaglocRelocalization`; the oracle
is :class:`~tagloc.localize.node.LocalizerNode` fed the same messages directly, in the same
order, as dimos delivers them (:func:`harness.decoded`: a pose crosses the wire as a quaternion,
and the 1e-16 of that round trip is enough to move a lidar point across a voxel boundary and the
estimate by 0.5 mm, so the oracle gets what the wire carries; the conversions themselves are
checked in ``test_convert.py``). Both frame conventions: dimos's default ``world -> map`` and
the Go2 navigation stacks' ``odom -> map``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from drive import drive
from harness import decoded, offline, publish_all, wire

from tagloc.adapters.dimos import convert
from tagloc.adapters.dimos.module import TaglocRelocalization
from tagloc.io.dimos_premap import write_pc2_lcm
from tagloc.tags import save_tag_map

TOL_M = 1e-6
TOL_RAD = 1e-6


def _files(tmp_path: Path, odom_frame: str) -> tuple[Path, Path, Path]:
    d = drive(odom_frame)
    tags, config = tmp_path / "tags.yaml", tmp_path / "localizer.yaml"
    premap = tmp_path / "premap.pc2.lcm"
    save_tag_map(d.tag_map, tags)
    config.write_text(d.config_yaml, encoding="utf-8")
    write_pc2_lcm(premap, d.premap)
    return tags, config, premap


@pytest.mark.parametrize("odom_frame", ["world", "odom"])
def test_corrections_through_dimos_equal_the_offline_node(tmp_path: Path, odom_frame: str) -> None:
    d = drive(odom_frame)
    tags, config, premap = _files(tmp_path, odom_frame)
    expected = offline(tags, [decoded(r) for r in d.records], config, premap, odom_frame)
    assert len(expected) > 50  # localized for the second half of the drive at least

    module = TaglocRelocalization(tag_map=str(tags), localizer_config=str(config),
                                  map_file=str(premap), world_frame=odom_frame, tf_interval=0.0)
    transports = wire(module, ["tf", "color_image", "camera_info", "lidar", "tagloc_pose"])
    corrections, poses = [], []
    transports["tf"].subscribe(lambda m: corrections.extend(
        t for t in m.transforms if (t.frame_id, t.child_frame_id) == (odom_frame, "map")))
    transports["tagloc_pose"].subscribe(poses.append)
    module.start()
    try:
        publish_all(module, transports, d.records)
        deadline = time.monotonic() + 10
        while (len(corrections) < len(expected) or len(poses) < len(expected)) and (
                time.monotonic() < deadline):
            time.sleep(0.01)
        status = module.status()
    finally:
        module.stop()

    assert status["problems"] == [] and status["localizing"]
    assert len(corrections) == len(poses) == len(expected)
    for got, want in zip(corrections, expected, strict=True):
        T_world_map = want.T_map_odom.inverse()
        np.testing.assert_allclose(convert.se3(got).translation, T_world_map.translation,
                                   rtol=0, atol=TOL_M)
        angle = (convert.se3(got).inverse() @ T_world_map).rotation.log()
        assert np.linalg.norm(angle) < TOL_RAD
    for got, want in zip(poses, expected, strict=True):
        assert convert.stamp_ns(got.ts) == want.stamp_ns  # the odometry's stamp
        p = got.pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], want.T_map_base.translation, rtol=0, atol=TOL_M)
    # dimos re-stamps the transform on tf with the wall clock, not the drive's (2023) clock
    assert all(abs(t.ts - time.time()) < 600 for t in corrections)
    assert expected[-1].stamp_ns / 1e9 < time.time() - 86400
    # the drive was corrected: the correction moved well beyond the tolerance
    assert np.linalg.norm(expected[-1].T_map_odom.translation) > 1e-3
