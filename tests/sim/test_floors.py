"""Worlds with floors and elevator shafts: the schema, single-floor files unchanged, and bad input
as one line naming the field."""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from tagloc.errors import ConfigError
from tagloc.sim import World, load_builtin_world, load_default_world, load_world

Doc = dict[str, Any]
TOWER_TEXT = resources.files("tagloc.sim").joinpath("worlds/tower.yaml").read_text("utf-8")


def _tower() -> Doc:
    doc = yaml.safe_load(TOWER_TEXT)
    assert isinstance(doc, dict)
    return doc


def test_the_tower_has_three_floors_one_shaft_and_a_cab_tag() -> None:
    world = load_builtin_world("tower")
    assert world.floor_heights() == {"0": 0.0, "1": 3.5, "2": 7.0}
    (shaft,) = world.shafts()
    assert (shaft.name, shaft.frame, shaft.floors, shaft.wall_material) == (
        "lift", "elevator_cab", ("0", "1", "2"), "mirror"
    )  # fmt: skip
    cab_tags = [t for t, floor in world.all_tags() if floor is None]
    assert [t.frame for t in cab_tags] == ["elevator_cab"]
    # the cab tag is on the wall opposite the door (door +x in the cab frame), facing the door
    T = cab_tags[0].T_frame_tag()
    assert T.translation[0] == pytest.approx(-shaft.footprint[0] / 2)
    np.testing.assert_allclose(T.rotation.as_matrix()[:, 2], [1.0, 0.0, 0.0], atol=1e-12)
    # a floor's tag sits at its floor's height plus its mount height
    tag = next(t for t, f in world.all_tags() if f == "2")
    assert tag.wall is not None
    assert world.T_map_tag(tag).translation[2] == pytest.approx(7.0 + tag.wall.height)


def test_a_single_floor_file_is_one_floor_named_0_and_keeps_its_cab() -> None:
    world = load_default_world()
    assert not world.has_floors and not world.floors
    (floor,) = world.all_floors()
    assert (floor.name, floor.height_m, floor.walls) == ("0", 0.0, world.walls)
    assert [t.id for t in floor.tags] == [t.id for t in world.tags if t.frame == "map"]
    (shaft,) = world.shafts()
    assert world.elevator is not None
    np.testing.assert_array_equal(
        shaft.T_map_cab().as_matrix(), world.elevator.T_map_cab().as_matrix()
    )
    assert len(world.walls_in_map()) == len(world.walls) + len(world.elevator.walls_cab())


def test_a_tower_round_trips_through_yaml() -> None:
    world = load_builtin_world("tower")
    again = World.from_yaml_text(world.to_yaml_text())
    assert again == world


def _error(tmp_path: Path, doc: Doc) -> str:
    path = tmp_path / "tower.yaml"
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_world(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{path}: ")
    return message.removeprefix(f"{path}: ")


def _ride(doc: Doc, to: str) -> None:
    doc["route"]["waypoints"][3] = {"ride": {"elevator": "lift", "to": to}}


CASES: list[tuple[str, Callable[[Doc], None], str]] = [
    (
        "shaft serving an unknown floor",
        lambda d: d["elevators"][0]["floors"].append("3"),
        "elevators[0].floors[3]: unknown floor '3' (floors: 0, 1, 2)",
    ),
    (
        "a shaft misses a floor the route rides to",
        lambda d: d["elevators"][0].update(floors=["0", "1"]),
        "route.waypoints[3].ride: elevator lift does not serve floor 2",
    ),
    (
        "a floor name twice",
        lambda d: d["floors"][2].update(name="1"),
        "floors[2].name: floor '1' is listed twice",
    ),
    (
        "two floors at one height",
        lambda d: d["floors"][2].update(height_m=3.6),
        "floors[2].height_m: 3.6 m is within 0.5 m of floor 1 (floors[1])",
    ),
    (
        "a cab tag outside its cab",
        lambda d: d["tags"][0]["wall"].update(x=-1.5),
        "tags[0]: tag lies outside the elevator cab footprint",
    ),
    (
        "a tag in an unknown cab frame",
        lambda d: d["tags"][0].update(frame="freight_cab"),
        "tags[0].frame: tag is in frame freight_cab but the world has no elevator",
    ),
    (
        "a map tag at the top level of a building",
        lambda d: d["tags"][0].update(frame="map"),
        "tags[0].frame: with floors, map tags go in a floor's tags",
    ),
    (
        "a cab tag on a floor",
        lambda d: d["floors"][0]["tags"][0].update(frame="elevator_cab"),
        "floors[0].tags[0].frame: a floor's tags are in map",
    ),
    (
        "a tag id on two floors",
        lambda d: d["floors"][1]["tags"][0].update(id=1),
        "floors[1].tags[0].id: duplicate tag id 1 (also floors[0].tags[0])",
    ),
    (
        "a checkpoint on another floor than the robot",
        lambda d: d["route"]["waypoints"].__setitem__(4, "f1_lobby"),
        "route.waypoints[4]: checkpoint 'f1_lobby' is on floor 1, the robot on 2",
    ),
    (
        "a ride to the floor the robot is on",
        lambda d: _ride(d, "0"),
        "route.waypoints[3].ride.to: the robot is on floor 0",
    ),
    (
        "an unknown elevator",
        lambda d: d["route"]["waypoints"].__setitem__(
            3, {"ride": {"elevator": "stairs", "to": "2"}}
        ),
        "route.waypoints[3].ride.elevator: no elevator 'stairs' (known: lift)",
    ),
    (
        "a ride with a dwell",
        lambda d: d["route"]["waypoints"][3].update(dwell=3.0),
        "route.waypoints[3].dwell: a ride's dwell is its elevator's dwell_s",
    ),
    (
        "walls at the top level of a building",
        lambda d: d.update(walls=[{"start": [0, 0], "end": [1, 0]}]),
        "walls: with floors, walls and checkpoints go in a floor",
    ),
    (
        "a start floor it does not serve",
        lambda d: d["elevators"][0].update(start_floor="7"),
        "elevators[0].start_floor: '7' is not one of the floors it serves",
    ),
]


@pytest.mark.parametrize("edit, expected", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_bad_building_is_one_line_naming_the_field(
    tmp_path: Path, edit: Callable[[Doc], None], expected: str
) -> None:
    doc = _tower()
    edit(doc)
    assert expected in _error(tmp_path, doc)
