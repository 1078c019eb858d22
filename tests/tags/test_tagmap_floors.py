"""Tag maps of buildings: the floors table and a tag's floor round-trip, bad floors are one line
naming the entry and field, floor warnings; a tower's map from its world."""

from __future__ import annotations

import pytest

from tagloc.geometry import SE3
from tagloc.sim import load_builtin_world
from tagloc.sim.scenarios import tag_map_from_world
from tagloc.tags.tagmap import TagEntry, TagMap, TagMapError
from tagloc.tags.tagmap_floors import Z_TOLERANCE_M, floor_warnings

BUILDING = """\
version: 1
frames: [map, elevator_cab]
floors: {"0": 0.0, "1": 3.5, "2": 7.0}
tags:
  - {id: 1, size: 0.16, floor: "0", position: [0.0, 3.0, 1.2], quat_xyzw: [0.5, 0.5, 0.5, 0.5]}
  - {id: 11, size: 0.16, floor: "1", position: [0.0, 3.0, 4.7], quat_xyzw: [0.5, 0.5, 0.5, 0.5]}
  - {id: 21, size: 0.16, floor: "2", position: [0.0, 3.0, 8.2], quat_xyzw: [0.5, 0.5, 0.5, 0.5]}
  - {id: 100, size: 0.16, frame: elevator_cab, position: [-1.0, 0.0, 0.7],
     quat_xyzw: [0.5, 0.5, 0.5, 0.5]}
"""


def test_floors_round_trip_and_saving_is_stable() -> None:
    tag_map = TagMap.from_yaml_text(BUILDING)
    assert tag_map.floors == {"0": 0.0, "1": 3.5, "2": 7.0}
    entry = tag_map.get(11)
    assert entry is not None and entry.floor == "1"
    text = tag_map.to_yaml_text()
    again = TagMap.from_yaml_text(text)
    assert again == tag_map and again.to_yaml_text() == text
    assert 'floors: {"0": 0.0, "1": 3.5, "2": 7.0}' in text and '    floor: "1"' in text
    assert floor_warnings(tag_map) == []


def test_a_map_without_floors_writes_none() -> None:
    tag_map = TagMap.from_yaml_text(BUILDING.replace('floors: {"0": 0.0, "1": 3.5, "2": 7.0}\n', "")
                                    .replace('floor: "0", ', "").replace('floor: "1", ', "")
                                    .replace('floor: "2", ', ""))  # fmt: skip
    assert tag_map.floors is None
    assert "floor" not in tag_map.to_yaml_text().split("version: 1")[1]


@pytest.mark.parametrize(
    "old, new, message",
    [
        ('floor: "1"', 'floor: "5"', "tags[1] (id 11): floor: unknown floor '5' (floors: 0, 1, 2)"),
        ('floors: {"0": 0.0, "1": 3.5, "2": 7.0}\n', "",
         "tags[0] (id 1): floor: unknown floor '0' (floors: none: add a top-level 'floors' table)"),
        ("frame: elevator_cab,", 'frame: elevator_cab, floor: "1",',
         "tags[3] (id 100): floor: only a map tag is on a floor (this one is in elevator_cab)"),
        ("frames: [map, elevator_cab]", "frames: [map]", "tags[3] (id 100): frame: unknown frame"),
        ('"2": 7.0}', '"2 b": 7.0}', "floors.2 b: bad floor name"),
    ],
)  # fmt: skip
def test_bad_floors_are_one_line_naming_the_entry_and_field(
    old: str, new: str, message: str
) -> None:
    assert old in BUILDING
    with pytest.raises(TagMapError) as info:
        TagMap.from_yaml_text(BUILDING.replace(old, new, 1), "tags.yaml")
    text = str(info.value)
    assert "\n" not in text and text.startswith("tags.yaml: ") and message in text, text


def test_warnings_name_a_tag_off_its_floor_and_a_floor_without_tags() -> None:
    # tag 11 (floor 1 at 3.5 m) placed at 2.0 m: below its floor; floor 2 left without tags
    lines = BUILDING.replace("[0.0, 3.0, 4.7]", "[0.0, 3.0, 2.0]").splitlines(keepends=True)
    text = "".join(line for line in lines if "id: 21," not in line)
    tag_map = TagMap.from_yaml_text(text)
    warnings = floor_warnings(tag_map)
    assert warnings == [
        "tags[1] (id 11): floor: z 2.00 m is not on floor 1 (3.5 m; expected 3.2 m <= z < 6.7 m)",
        "floors.2: no tag is on this floor (it cannot be told by its tags)",
    ]
    # within the tolerance below the floor, and just under the next floor: no warning
    for z in (3.5 - Z_TOLERANCE_M + 1e-6, 7.0 - Z_TOLERANCE_M - 1e-6):
        entry = TagEntry.from_pose(11, SE3.from_quat([0, 0, 0, 1], [0, 0, z]), 0.16, floor="1")
        assert floor_warnings(TagMap.from_entries([entry], floors={"1": 3.5, "2": 7.0}))[:1] == [
            "floors.2: no tag is on this floor (it cannot be told by its tags)"
        ]


def test_a_towers_map_has_its_floors_and_its_cab_tag_in_the_cab_frame() -> None:
    world = load_builtin_world("tower")
    tag_map = tag_map_from_world(world)
    assert tag_map.frames == ("map", "elevator_cab")
    assert tag_map.floors == world.floor_heights()
    (cab,) = tag_map.in_frame("elevator_cab")
    assert cab.id == 100 and cab.floor is None
    assert cab.position == pytest.approx(tuple(world.find_tag(100).T_frame_tag().translation))
    for tag, floor in world.all_tags():
        entry = tag_map.get(tag.id)
        assert entry is not None and entry.floor == floor
        if floor is not None:
            assert entry.position == pytest.approx(tuple(world.T_map_tag(tag).translation))
    assert floor_warnings(tag_map) == []
    text = tag_map.to_yaml_text()
    assert TagMap.from_yaml_text(text).to_yaml_text() == text


def test_a_single_floor_worlds_map_is_unchanged() -> None:
    world = load_builtin_world("office")
    tag_map = tag_map_from_world(world)
    assert tag_map.floors is None and tag_map.frames == ("map",)
    assert all(entry.floor is None for entry in tag_map)
