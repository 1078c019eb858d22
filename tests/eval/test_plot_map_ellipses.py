"""The drive picture draws a built map's tags with 2-sigma ellipses beside the true tags.

Oracle for the ellipse: samples of the Gaussian (a 2-D 2-sigma ellipse holds 1 - exp(-2) of them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tagloc.eval.plots import ellipse_2sigma, plot_world_and_paths
from tagloc.geometry import SE3
from tagloc.sim import load_default_world
from tagloc.sim.scenarios import tag_map_from_world
from tagloc.tags.tagmap import TagMap


def test_ellipse_holds_the_two_sigma_mass() -> None:
    rng = np.random.default_rng(8)
    angle = np.radians(30.0)
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    cov = R @ np.diag([0.04**2, 0.01**2]) @ R.T
    width, height, angle_deg = ellipse_2sigma(cov)
    assert np.isclose(width, 0.16) and np.isclose(height, 0.04)
    assert np.isclose(angle_deg % 180.0, 30.0)
    samples = rng.multivariate_normal([0, 0], cov, size=200_000)
    a = np.radians(angle_deg)
    u = samples @ np.array([np.cos(a), np.sin(a)])
    v = samples @ np.array([-np.sin(a), np.cos(a)])
    inside = (u / (width / 2)) ** 2 + (v / (height / 2)) ** 2 <= 1.0
    assert abs(inside.mean() - (1 - np.exp(-2))) < 0.005


def test_drive_picture_with_a_built_map(tmp_path: Path) -> None:
    world = load_default_world()
    truth = tag_map_from_world(world)
    rng = np.random.default_rng(9)
    built = TagMap.from_entries(
        e.with_pose(
            SE3(e.T_frame_tag().rotation, e.T_frame_tag().translation + rng.normal(0, 0.1, 3)),
            np.diag([0.01, 0.004, 0.001, 1e-4, 1e-4, 1e-4]),
        )
        for e in truth.in_frame("map")
    )
    path = tmp_path / "drive.png"
    T = SE3.from_rotvec(np.zeros((2, 3)), np.array([[2.0, 10.0, 0.0], [30.0, 10.0, 0.0]]))
    plot_world_and_paths(world, {"ground truth": T}, path, tag_map=built)
    assert path.stat().st_size > 10_000
