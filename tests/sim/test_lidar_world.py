"""The lidar and people in world files: validation (one line naming the field), the built-in
worlds, the elevator cab's walls seen by the lidar as walls of their material."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest

from tagloc.config import ConfigError
from tagloc.geometry import SE3
from tagloc.sim.lidar import LidarSimulator
from tagloc.sim.lidar_cast import MATERIALS, Segments
from tagloc.sim.world import BUILTIN_WORLDS, World, load_builtin_world, load_default_world

OFFICE = resources.files("tagloc.sim").joinpath("worlds/office.yaml").read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("    rings: 16\n", "    rings: 0\n", "robot.lidar.rings"),
        ("vertical_fov_deg: [-7.0, 52.0]", "vertical_fov_deg: [52.0, -7.0]", "low 52.0 is above"),
        ("    rings: 16\n", "    rings: 1\n", "one ring needs low == high"),
        ("    min_range_m: 0.1\n", "    min_range_m: 50.0\n", "robot.lidar.min_range_m"),
        ("    max_bounces: 1\n", "    max_bounces: 3\n", "robot.lidar.max_bounces"),
        ("people: []", "people: [{radius_m: 0.3}]", "give exactly one of 'path' or 'random_walk'"),
        ("people: []", "people: [{path: [[1, 0, 0], [0, 1, 1]]}]", "waypoint times must increase"),
    ],
)
def test_bad_lidar_or_people_fields_are_one_line(old: str, new: str, message: str) -> None:
    assert old in OFFICE
    with pytest.raises(ConfigError) as info:
        World.from_yaml_text(OFFICE.replace(old, new, 1), source="office.yaml")
    text = str(info.value)
    assert "\n" not in text and text.startswith("office.yaml: ") and message in text


def test_builtin_worlds_load_with_a_lidar() -> None:
    for name in BUILTIN_WORLDS:
        world = load_builtin_world(name)
        assert world.name == name and world.robot.lidar is not None
    lidar = load_default_world().robot.lidar
    assert lidar is not None and (lidar.rings, lidar.columns, lidar.rate_hz) == (16, 360, 10.0)


def test_the_cab_walls_reflect_the_lidar_as_mirrors() -> None:
    world = load_default_world()
    assert world.elevator is not None and world.elevator.wall_material == "mirror"
    walls = world.walls_in_map()
    seg = Segments.from_walls(walls)
    assert (seg.material == MATERIALS["mirror"]).sum() == len(world.elevator.walls_cab())
    lidar = world.robot.lidar
    assert lidar is not None
    # inside the cab (x 37.7 - 39.9, y 14 - 16), facing its back wall (east)
    _, cast = LidarSimulator(lidar, walls).scan_at(SE3.from_quat([0, 0, 0, 1.0], [38.3, 15.0, 0]))
    level = np.abs(LidarSimulator(lidar, walls).directions_lidar.reshape(-1, 3)[:, 2]) < 0.05
    # a level beam reflected by one cab wall meets another one (a second bounce: lost), unless
    # it leaves through the door (one bounce, a phantom point)
    assert np.isinf(cast.range_m[level]).mean() > 0.5 and (cast.bounces[level] == 1).any()
    opaque = [w.model_copy(update={"material": "wall"}) for w in walls]
    _, plain = LidarSimulator(lidar, opaque).scan_at(SE3.from_quat([0, 0, 0, 1.0], [38.3, 15.0, 0]))
    assert (plain.bounces == 0).all() and np.isfinite(plain.range_m[level]).all()
