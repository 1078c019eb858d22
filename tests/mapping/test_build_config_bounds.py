"""The map-build configuration (``map build --config``): every field finite and in range, the
lidar and products sections too; one line naming the file and the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from tagloc.cli.map_inputs import build_config
from tagloc.errors import ConfigError
from tagloc.lidar import OccupancyConfig
from tagloc.mapping import MapBuildConfig
from tagloc.mapping.products import ProductsConfig


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("robust_k: .inf\n", "robust_k: input should be a finite number"),
        ("anchor_sigma_m: 1.0e-300\n", "anchor_sigma_m: input should be greater"),
        ("max_iterations: 1000000000000\n", "max_iterations: input should be less"),
        ("rounds: 1000000000\n", "rounds: input should be less"),
        ("odometry: {translation_floor_m: 1.0e-300}\n", "odometry.translation_floor_m: input"),
        ("odometry: {rotation_var_per_m: .inf}\n", "rotation_var_per_m: input should be a finite"),
        ("pnp_noise: {sigma_px: .nan}\n", "pnp_noise.sigma_px: input should be a finite"),
        ("gravity: {sigma_deg: 1.0e-300}\n", "gravity.sigma_deg: input should be greater"),
        ("lidar: {voxel_m: 1.0e-9}\n", "lidar.voxel_m: input should be greater"),
        ("lidar: {information_scale: .inf}\n", "lidar.information_scale: input should be a finite"),
        ("lidar: {loops_per_keyframe: 1000000000}\n", "loops_per_keyframe: input should be less"),
        ("lidar: {min_sigma_m: 1.0e-300}\n", "lidar.min_sigma_m: input should be greater"),
    ],
)
def test_bad_values_are_one_line(tmp_path: Path, text: str, expected: str) -> None:
    path = tmp_path / "build.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        build_config(path, MapBuildConfig(), {})
    message = str(info.value)
    assert message.startswith(f"{path}: ") and expected in message and "\n" not in message


def test_products_and_grid_bounds_and_order() -> None:
    with pytest.raises(ValueError, match="z_min_m"):
        OccupancyConfig(z_min_m=3.0, z_max_m=2.0)
    with pytest.raises(ValueError, match="free_thresh"):
        OccupancyConfig(free_thresh=0.8, occupied_thresh=0.6)
    with pytest.raises(ValueError, match="resolution_m"):
        OccupancyConfig(resolution_m=1e-9)  # a grid of 10^20 cells
    with pytest.raises(ValueError, match="premap_voxel_m"):
        ProductsConfig(premap_voxel_m=float("inf"))
