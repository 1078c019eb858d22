"""Premaps both ways, with dimos's own ``PointCloud2`` reader and writer as the oracle.

tagloc's ``.pc2.lcm`` (``tagloc map build --premap-format pc2.lcm``) loads in dimos (its
relocalization loads premaps with ``PointCloud2.lcm_decode``), and a premap dimos wrote loads in
tagloc's lidar source, with the same points.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from dimos.mapping.relocalization.module import RelocalizationModule
from dimos.msgs.sensor_msgs.PointCloud2 import PointCloud2

from tagloc.cli.localize_cmd import _read_premap
from tagloc.io.dimos_premap import read_pc2_lcm, write_pc2_lcm


def _points() -> np.ndarray:
    return np.random.default_rng(7).uniform([-30, -20, -0.5], [30, 20, 3.0], size=(5000, 3))


def test_a_tagloc_premap_loads_in_dimos_with_the_same_points(tmp_path: Path) -> None:
    points = _points()
    path = tmp_path / "office.pc2.lcm"
    write_pc2_lcm(path, points)
    cloud = PointCloud2.lcm_decode(path.read_bytes())
    np.testing.assert_array_equal(cloud.points_f32(), points.astype(np.float32))
    module = RelocalizationModule(map_file=str(path))  # dimos's own loader
    module.start()
    try:
        assert module.premap is not None
        np.testing.assert_array_equal(module.premap.points_f32(), points.astype(np.float32))
    finally:
        module.stop()


def test_a_dimos_premap_loads_in_tagloc_with_the_same_points(tmp_path: Path) -> None:
    points = _points().astype(np.float32)
    path = tmp_path / "go2.pc2.lcm"
    cloud = PointCloud2.from_numpy(points, frame_id="map", timestamp=1_700_000_000.25,
                                   intensities=np.linspace(0, 1, len(points)))  # fmt: skip
    path.write_bytes(cloud.lcm_encode())
    np.testing.assert_array_equal(read_pc2_lcm(path), points.astype(np.float64))
    np.testing.assert_array_equal(_read_premap(path), points.astype(np.float64))  # --premap
