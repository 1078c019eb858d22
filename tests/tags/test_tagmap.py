"""The tag map file: validation errors name file, entry and field; saving is stable; diffs."""

from __future__ import annotations

import copy
import difflib
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from tagloc.errors import ConfigError
from tagloc.geometry import SE3, SO3
from tagloc.tags.tagmap import (
    TagEntry,
    TagMap,
    TagMapError,
    TagMapLookupError,
    load_tag_map,
    save_tag_map,
)
from tagloc.tags.tagmap_diff import diff_tag_maps, format_tag_map_diff

#: The README example, exactly as ``to_yaml_text`` writes it.
EXAMPLE = """\
# tagloc tag map. Check: `tagloc map check FILE`; compare two: `tagloc map diff A B`.
# A tag's pose is T_frame_tag: the tag frame (origin at the tag centre, z out of the printed
#   face towards a viewer, x to the viewer's right, y up) expressed in `frame`: `map`
#   (static) or a moving frame listed in `frames` (e.g. elevator_cab).
# size: black-border edge, metres. position: [x, y, z], metres (6 decimals = micrometres).
# quat_xyzw: [x, y, z, w] (ROS/scipy order), unit norm within 1e-6, written with w >= 0.
# covariance (optional): 6x6 rows of the right perturbation T_frame_tag (+) [x, y, z, rx,
#   ry, rz] (metres, radians; translation first, as ROS PoseWithCovariance).
# anchor: true = surveyed pose, a prior of the map builder; anchor_sigma: its standard
#   deviation per axis {position_m, rotation_deg}. observations: builder count.
# Tags are sorted by (family, id). Saving rewrites the file: comments are lost; use note.
version: 1
frames: [map, elevator_cab]
tags:

  - id: 7
    family: aruco_4x4_50
    size: 0.05
    frame: map
    position: [31.200000, 4.800000, 0.300000]
    quat_xyzw: [0.707106781, 0.000000000, 0.000000000, 0.707106781]
    note: "charging dock"

  - id: 0
    family: tag36h11
    size: 0.162
    frame: map
    position: [0.000000, 2.350000, 1.400000]
    quat_xyzw: [0.500000000, 0.500000000, 0.500000000, 0.500000000]
    anchor: true
    anchor_sigma: {position_m: 0.005, rotation_deg: 1}
    note: "lobby, left of the main door (surveyed)"

  - id: 3
    family: tag36h11
    size: 0.1
    frame: elevator_cab
    position: [0.000000, -0.900000, 1.500000]
    quat_xyzw: [0.500000000, -0.500000000, -0.500000000, 0.500000000]
    note: "inside the cab, back wall"

  - id: 17
    family: tag36h11
    size: 0.162
    frame: map
    position: [24.512000, -0.050000, 1.450000]
    quat_xyzw: [0.000000000, 0.707106781, 0.707106781, 0.000000000]
    observations: 41
    note: "by the elevator"
    covariance:
      - [4.00e-06, 1.20e-06, 0.00e+00, 0.00e+00, 0.00e+00, 0.00e+00]
      - [1.20e-06, 4.00e-06, 0.00e+00, 0.00e+00, 0.00e+00, 0.00e+00]
      - [0.00e+00, 0.00e+00, 9.00e-06, 0.00e+00, 0.00e+00, 0.00e+00]
      - [0.00e+00, 0.00e+00, 0.00e+00, 3.00e-05, 0.00e+00, 0.00e+00]
      - [0.00e+00, 0.00e+00, 0.00e+00, 0.00e+00, 3.00e-05, 0.00e+00]
      - [0.00e+00, 0.00e+00, 0.00e+00, 0.00e+00, 0.00e+00, 1.00e-05]
"""

Q_WALL = [0.5, 0.5, 0.5, 0.5]  # a tag on a wall facing +x in map
BASE: dict[str, Any] = {
    "version": 1,
    "frames": ["map", "elevator_cab"],
    "tags": [
        {"id": 0, "size": 0.162, "position": [0.0, 2.35, 1.4], "quat_xyzw": Q_WALL},
        {"id": 1, "size": 0.162, "position": [4.0, 2.35, 1.4], "quat_xyzw": Q_WALL},
        {
            "id": 5,
            "family": "aruco_4x4_50",
            "size": 0.05,
            "position": [9.0, 1.0, 0.3],
            "quat_xyzw": Q_WALL,
        },
        {
            "id": 12,
            "size": 0.1,
            "frame": "elevator_cab",
            "position": [0.0, -0.9, 1.5],
            "quat_xyzw": [0.5, -0.5, -0.5, 0.5],
        },
        {
            "id": 17,
            "size": 0.162,
            "position": [24.5, 0.0, 1.45],
            "quat_xyzw": Q_WALL,
            "note": "by the elevator",
            "covariance": np.diag([1e-6] * 3 + [1e-4] * 3).tolist(),
        },
    ],
}


INDEFINITE = np.eye(6) * 1e-6
INDEFINITE[0, 1] = INDEFINITE[1, 0] = 2e-6  # a correlation of 2


def _text(edit: Any = None) -> str:
    data = copy.deepcopy(BASE)
    if edit is not None:
        edit(data)
    return yaml.safe_dump(data, sort_keys=False)


def _load(edit: Any = None) -> TagMap:
    return TagMap.from_yaml_text(_text(edit), source="tags.yaml")


def _set(path: tuple[Any, ...], value: Any) -> Any:
    def edit(data: dict[str, Any]) -> None:
        node = data
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return edit


def _drop(k: int, key: str) -> Any:
    return lambda data: data["tags"][k].pop(key)


# ----- validation: one line naming file, entry (index and id) and field ------------------------
CASES = [
    (_set(("tags", 4, "size"), 0), "tags.yaml: tags[4] (id 17): size: must be > 0"),
    (
        _set(("tags", 4, "size"), 162),
        "tags.yaml: tags[4] (id 17): size: 162 is outside [0.001, 5]: sizes are metres, not "
        "millimetres",
    ),
    (_drop(4, "size"), "tags.yaml: tags[4] (id 17): size: field required"),
    (
        _set(("tags", 4, "id"), 1),
        "tags.yaml: tags[4] (id 1): id: duplicate tag36h11 id 1 (also tags[1])",
    ),
    (
        _set(("tags", 1, "quat_xyzw"), [0.0, 0.0, 0.5, 0.5]),
        "tags.yaml: tags[1] (id 1): quat_xyzw: not a unit quaternion: |q| = 0.707106781 "
        "(tolerance 1e-06); write it normalized",
    ),
    (
        _set(("tags", 1, "quat_xyzw"), [0.0, 0.0, 0.0, 1.000002]),
        "tags.yaml: tags[1] (id 1): quat_xyzw: not a unit quaternion: |q| = 1.000002 "
        "(tolerance 1e-06); write it normalized",
    ),
    (
        _set(("tags", 1, "quat_xyzw"), [0.0, 0.0, 1.0]),
        "tags.yaml: tags[1] (id 1): quat_xyzw: must be 4 numbers [x, y, z, w], got 3",
    ),
    (
        _set(("tags", 0, "position"), [1.0, 2.0]),
        "tags.yaml: tags[0] (id 0): position: must be 3 numbers [x, y, z], got 2",
    ),
    (
        _set(("tags", 3, "frame"), "elevator"),
        "tags.yaml: tags[3] (id 12): frame: unknown frame 'elevator'; declared: map, elevator_cab "
        "(list moving frames in the top-level 'frames')",
    ),
    (
        _set(("frames",), ["map"]),
        "tags.yaml: tags[3] (id 12): frame: unknown frame 'elevator_cab'; declared: map "
        "(list moving frames in the top-level 'frames')",
    ),
    (
        _set(("frames",), ["map", "elevator_cab", "elevator_cab"]),
        "tags.yaml: frames[2]: duplicate frame 'elevator_cab'",
    ),
    (
        _set(("frames",), ["map", "elevator cab"]),
        "tags.yaml: frames[1]: bad frame name 'elevator cab' (letters, digits, _ . / -)",
    ),
    (
        _set(("tags", 0, "family"), "tag36h10"),
        "tags.yaml: tags[0] (id 0): family: unknown family "
        "'tag36h10'; known: tag16h5, tag25h9, tag36h11, aruco_4x4_50,",
    ),
    (
        _set(("tags", 2, "id"), 50),
        "tags.yaml: tags[2] (id 50): id: 50 is out of range for aruco_4x4_50 (0..49)",
    ),
    (_set(("tags", 2, "id"), -3), "tags.yaml: tags[2] (id -3): id: must be >= 0"),
    (_set(("tags", 2, "id"), "5"), "tags.yaml: tags[2]: id: input should be a valid integer"),
    (_drop(2, "id"), "tags.yaml: tags[2]: id: field required"),
    (
        lambda d: d["tags"][0].update(positon=d["tags"][0].pop("position")),
        "tags.yaml: tags[0] (id 0): positon: extra inputs are not permitted (and 1 more error)",
    ),
    (
        _set(("tags", 0, "position", 1), float("nan")),
        "tags.yaml: tags[0] (id 0): position[1]: input should be a finite number",
    ),
    (
        _set(("tags", 0, "position", 2), True),
        "tags.yaml: tags[0] (id 0): position[2]: must be a number, not true/false",
    ),
    (
        _set(("tags", 0, "position", 0), 1e6),
        "tags.yaml: tags[0] (id 0): position[0]: 1e+06 m is beyond +-100000 m",
    ),
    (
        _set(("tags", 4, "covariance", 0, 1), 1e-7),
        "tags.yaml: tags[4] (id 17): covariance[0][1]: not symmetric: 1e-07, but covariance[1][0] "
        "= 0",
    ),
    (
        _set(("tags", 4, "covariance"), INDEFINITE.tolist()),
        "tags.yaml: tags[4] (id 17): covariance: not positive semi-definite (correlation matrix "
        "eigenvalue -1)",
    ),
    (
        _set(("tags", 4, "covariance", 3, 3), -1e-3),
        "tags.yaml: tags[4] (id 17): covariance[3][3]: variance of rx must be >= 0, got -0.001",
    ),
    (
        _set(("tags", 4, "covariance", 1, 1), 1e300),
        "tags.yaml: tags[4] (id 17): covariance[1][1]: 1e+300 is beyond 10000 (a 100 m or rad "
        "sigma)",
    ),
    (
        _set(("tags", 4, "covariance"), [1e-6] * 35),
        "tags.yaml: tags[4] (id 17): covariance: must be 6 rows of 6 numbers or 36 numbers, got "
        "35 items",
    ),
    (
        _set(("tags", 4, "covariance", 2), [0.0] * 5),
        "tags.yaml: tags[4] (id 17): covariance[2]: must be a row of 6 numbers, got "
        "[0.0, 0.0, 0.0, 0.0, 0.0]",
    ),
    (
        _set(("tags", 0, "note"), "two\nlines"),
        "tags.yaml: tags[0] (id 0): note: must be printable text on one line (no newlines, tabs)",
    ),
    (
        _set(("tags", 0, "observations"), -1),
        "tags.yaml: tags[0] (id 0): observations: must be >= 0",
    ),
    (
        _set(("tags", 0, "anchor"), "sure"),
        "tags.yaml: tags[0] (id 0): anchor: input should be a valid boolean",
    ),
    (_set(("tags", 1), 5), "tags.yaml: tags[1]: input should be a valid dictionary or instance"),
    (lambda d: d.pop("version"), "tags.yaml: version: field required"),
    (_set(("version",), 2), "tags.yaml: version: unsupported version 2 (this tagloc reads 1)"),
    (_set(("version",), True), "tags.yaml: version: input should be a valid integer"),
    (lambda d: d.update(tag=d.pop("tags")), "tags.yaml: tag: extra inputs are not permitted"),
]


@pytest.mark.parametrize(("edit", "expected"), CASES)
def test_invalid_maps_fail_with_one_line_naming_entry_and_field(edit: Any, expected: str) -> None:
    with pytest.raises(TagMapError) as info:
        _load(edit)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(expected), message
    assert isinstance(info.value, ConfigError)


def test_zero_variance_with_a_covariance_is_rejected() -> None:
    def edit(data: dict[str, Any]) -> None:
        cov = np.diag([1e-6] * 3 + [0.0, 1e-4, 1e-4])
        cov[0, 3] = cov[3, 0] = 1e-9
        data["tags"][4]["covariance"] = cov.tolist()

    with pytest.raises(TagMapError, match=r"tags\[4\] \(id 17\): covariance\[0\]\[3\]: x-rx "):
        _load(edit)


def test_yaml_duplicate_keys_and_non_mappings_are_one_line_errors() -> None:
    text = "version: 1\ntags:\n  - id: 3\n    size: 0.1\n    size: 0.2\n"
    with pytest.raises(TagMapError) as info:
        TagMap.from_yaml_text(text, "tags.yaml")
    assert str(info.value) == (
        "tags.yaml: line 5, column 5: invalid YAML: duplicate key 'size' (first at line 4)"
    )
    with pytest.raises(TagMapError, match=r"^tags\.yaml: the top level must be a mapping"):
        TagMap.from_yaml_text("- 1\n", "tags.yaml")


def test_what_is_valid_loads() -> None:
    tag_map = _load()
    assert [t.key for t in tag_map] == [
        ("aruco_4x4_50", 5),
        ("tag36h11", 0),
        ("tag36h11", 1),
        ("tag36h11", 12),
        ("tag36h11", 17),
    ]
    # the same id in another family is a different tag; a quaternion off by < 1e-6 is kept as is
    same_id = {"id": 5, "size": 0.1, "position": [1, 2, 3], "quat_xyzw": [0, 0, 0, 1.0000005]}
    tag_map = _load(lambda d: d["tags"].append(same_id))
    assert tag_map.get(5).quat_xyzw == (0.0, 0.0, 0.0, 1.0000005)  # type: ignore[union-attr]
    assert tag_map.get(5, "aruco_4x4_50").size == 0.05  # type: ignore[union-attr]
    # 36 numbers are a covariance too; frames may omit map; defaults are filled in
    flat = np.diag([1e-6] * 3 + [1e-4] * 3).ravel().tolist()
    tag_map = _load(
        lambda d: d["tags"][4].update(covariance=flat) or d.update(frames=["elevator_cab"])
    )
    assert tag_map.get(17) == _load().get(17)
    assert tag_map.frames == ("map", "elevator_cab")
    assert tag_map.get(0) is not None and tag_map.get(0).family == "tag36h11"  # type: ignore[union-attr]


def test_in_memory_construction_is_validated_too() -> None:
    entry = TagEntry(id=3, size=0.1, position=(0, 0, 0), quat_xyzw=(0, 0, 0, 1))
    with pytest.raises(TagMapError) as info:
        TagMap(tags=(entry, entry))
    assert str(info.value) == "tag map: tags[1] (id 3): id: duplicate tag36h11 id 3 (also tags[0])"
    cab = TagEntry(id=4, size=0.1, frame="elevator_cab", position=(0, 0, 0), quat_xyzw=(0, 0, 0, 1))
    assert TagMap.from_entries([cab]).frames == ("map", "elevator_cab")
    with pytest.raises(TagMapError, match=r"^tag map: tags\[0\] \(id 4\): frame: unknown frame"):
        TagMap.from_entries([cab], frames=["map"])
    with pytest.raises(TagMapError, match=r"^tag 9: size: must be > 0$"):
        TagEntry.from_pose(9, SE3.identity(), -0.1)
    with pytest.raises(ValueError, match="size"):
        TagEntry(id=3, size=0, position=(0, 0, 0), quat_xyzw=(0, 0, 0, 1))


# ----- the model ---------------------------------------------------------------------------------
def test_lookups() -> None:
    tag_map = _load()
    assert tag_map.ids() == (0, 1, 12, 17) and tag_map.ids("aruco_4x4_50") == (5,)
    assert tag_map.sizes() == {0: 0.162, 1: 0.162, 12: 0.1, 17: 0.162}
    assert tag_map.families == ("aruco_4x4_50", "tag36h11")
    assert [t.id for t in tag_map.in_frame("elevator_cab")] == [12]
    assert len(tag_map) == 5 and tag_map.get(99) is None
    T_map_tag = tag_map.T_frame_tag(1)
    np.testing.assert_allclose(T_map_tag.translation, [4.0, 2.35, 1.4])
    # the wall quaternion: tag z (face normal) along map +x, tag y (up) along map +z
    np.testing.assert_allclose(T_map_tag.rotation.as_matrix()[:, 2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(T_map_tag.rotation.as_matrix()[:, 1], [0, 0, 1], atol=1e-12)
    cov = tag_map.get(17).covariance_matrix()  # type: ignore[union-attr]
    assert cov is not None and cov.shape == (6, 6) and cov[3, 3] == 1e-4
    with pytest.raises(TagMapLookupError, match="no tag36h11 tag with id 99"):
        tag_map.T_frame_tag(99)
    with pytest.raises(TagMapLookupError, match="no frame 'dock'"):
        tag_map.in_frame("dock")
    assert tag_map.summary() == (
        "5 tags (aruco_4x4_50: 1, tag36h11: 4); frames: map (4), elevator_cab (1); anchors: 0"
    )


def test_from_pose_and_with_pose() -> None:
    rng = np.random.default_rng(7)
    T_map_tag = SE3.random(rng, translation_scale=5.0)
    entry = TagEntry.from_pose(np.int64(4), T_map_tag, 0.162, note="pillar", anchor=True)
    np.testing.assert_allclose(entry.T_frame_tag().as_matrix(), T_map_tag.as_matrix(), atol=1e-12)
    assert entry.quat_xyzw[3] >= 0
    moved = entry.with_pose(T_map_tag @ SE3.from_rotvec([0, 0, 0], [0.1, 0, 0]), np.eye(6) * 1e-4)
    assert (moved.id, moved.size, moved.note, moved.anchor) == (4, 0.162, "pillar", True)
    assert moved.covariance_matrix() is not None


def test_a_negative_w_quaternion_is_stored_and_written_with_w_positive() -> None:
    tag_map = _load(_set(("tags", 0, "quat_xyzw"), [-0.5, -0.5, -0.5, -0.5]))
    assert tag_map.get(0).quat_xyzw == (0.5, 0.5, 0.5, 0.5)  # type: ignore[union-attr]
    assert "quat_xyzw: [0.500000000, 0.500000000, 0.500000000, 0.500000000]" in (
        tag_map.to_yaml_text()
    )


# ----- saving: stable bytes ----------------------------------------------------------------------
def test_the_readme_example_is_exactly_what_saving_writes() -> None:
    tag_map = TagMap.from_yaml_text(EXAMPLE, "README")
    assert tag_map.to_yaml_text() == EXAMPLE
    assert tag_map.summary() == (
        "4 tags (aruco_4x4_50: 1, tag36h11: 3); frames: map (3), elevator_cab (1); anchors: 1"
    )


def test_save_and_load_files(tmp_path: Path) -> None:
    tag_map = _load()
    path = tmp_path / "maps" / "tags.yaml"
    save_tag_map(tag_map, path)
    assert path.read_text(encoding="utf-8") == tag_map.to_yaml_text()
    assert [p.name for p in path.parent.iterdir()] == ["tags.yaml"]  # no temporary left
    assert load_tag_map(path) == tag_map
    with pytest.raises(TagMapError, match=r"nope\.yaml: cannot read tag map: No such file"):
        load_tag_map(tmp_path / "nope.yaml")


def test_awkward_values_survive_a_round_trip() -> None:
    note = 'she said "left: of # the door" \\ ünïcödé ✓'
    entry = TagEntry(
        id=2,
        size=0.1234564,
        frame="on",
        position=(-1e-9, 0.0, -0.0),
        quat_xyzw=(0.0, -0.6, 0.0, 0.8),
        note=note,
    )
    tag_map = TagMap.from_entries([entry])
    text = tag_map.to_yaml_text()
    assert 'frames: [map, "on"]' in text and 'frame: "on"' in text
    assert "size: 0.123456\n" in text
    assert "position: [0.000000, 0.000000, 0.000000]" in text
    again = TagMap.from_yaml_text(text)
    assert again.get(2).note == note and again.get(2).frame == "on"  # type: ignore[union-attr]
    assert again.to_yaml_text() == text


def test_a_near_singular_covariance_is_inflated_to_stay_positive_semi_definite() -> None:
    rng = np.random.default_rng(3)
    A = rng.standard_normal((6, 2)) * np.array([1e-3] * 3 + [1e-2] * 3)[:, None]
    cov = A @ A.T + 1e-18 * np.eye(6)  # rank 2 (in correlation terms)
    entry = TagEntry(id=1, size=0.1, position=(0, 0, 0), quat_xyzw=(0, 0, 0, 1), covariance=cov)
    text = TagMap.from_entries([entry]).to_yaml_text()
    back = TagMap.from_yaml_text(text).get(1).covariance_matrix()  # type: ignore[union-attr]
    assert back is not None
    scale = np.sqrt(np.diag(back))
    assert np.linalg.eigvalsh(back / np.outer(scale, scale))[0] >= -1e-9
    np.testing.assert_allclose(back, cov, rtol=0.11, atol=1e-12)
    assert TagMap.from_yaml_text(text).to_yaml_text() == text


def test_written_quaternions_are_normalized_and_covariances_symmetrized() -> None:
    # |q| - 1 = 9.996e-7 is accepted as is; written with 9 decimals it would read 1.000001000,
    # off by more than 1e-6: saving normalizes (only output; the loaded entry kept its numbers)
    cov = np.diag([4e-6] * 3 + [1e-4] * 3)
    cov[0, 1], cov[1, 0] = 1.2349999999e-6, 1.2350000001e-6  # symmetric within 1e-9, but
    entry = TagEntry(
        id=1, size=0.1, position=(0, 0, 0), quat_xyzw=(0, 0, 0, 1.0000009996), covariance=cov
    )  # 3 digits of each would be 1.23e-06 and 1.24e-06
    text = TagMap.from_entries([entry]).to_yaml_text()
    assert "quat_xyzw: [0.000000000, 0.000000000, 0.000000000, 1.000000000]" in text
    back = TagMap.from_yaml_text(text).get(1).covariance_matrix()  # type: ignore[union-attr]
    assert back is not None and back[0, 1] == back[1, 0] == pytest.approx(1.235e-6, rel=5e-3)


def test_moving_one_tag_changes_only_its_lines() -> None:
    tag_map = _load()
    before = tag_map.to_yaml_text().splitlines()
    tag = tag_map.get(1)
    assert tag is not None
    moved = tag.with_pose(tag.T_frame_tag() @ SE3.from_rotvec([0, 0.01, 0], [0.02, 0, 0]))
    after_map = TagMap.from_entries(
        [moved if t.key == tag.key else t for t in tag_map], tag_map.frames
    )
    after = after_map.to_yaml_text().splitlines()
    changed = [
        (op, before[i1:i2], after[j1:j2])
        for op, i1, i2, j1, j2 in difflib.SequenceMatcher(a=before, b=after).get_opcodes()
        if op != "equal"
    ]
    assert len(changed) == 1 and changed[0][0] == "replace"
    old_lines, new_lines = changed[0][1], changed[0][2]
    assert [line.split(":")[0].strip() for line in old_lines] == ["position", "quat_xyzw"]
    assert [line.split(":")[0].strip() for line in new_lines] == ["position", "quat_xyzw"]
    block_start = before.index("  - id: 1")
    assert before.index(old_lines[0]) == block_start + 4  # inside tag 1's block


# ----- property: save(load(save(m))) == save(m) --------------------------------------------------
FAMILY_NAMES = ("tag36h11", "tag25h9", "aruco_4x4_50")
coordinates = st.floats(-1e4, 1e4, allow_nan=False)


@st.composite
def tag_entries(draw: st.DrawFn, key: tuple[str, int], frames: list[str]) -> TagEntry:
    quat = np.array(draw(st.tuples(*[st.floats(-1, 1, allow_subnormal=True)] * 4)))
    if np.linalg.norm(quat) < 0.1:
        quat = np.array([0.0, 0.0, 0.0, 1.0])
    quat = quat / np.linalg.norm(quat) * (1 + draw(st.floats(-9e-7, 9e-7)))
    covariance = None
    if draw(st.booleans()):
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        A = rng.standard_normal((6, draw(st.integers(1, 6))))
        A *= 10.0 ** rng.uniform(-4, -1, size=(6, 1))
        covariance = A @ A.T
    return TagEntry(
        id=key[1],
        family=key[0],
        size=draw(st.floats(1e-3, 5.0)),
        frame=draw(st.sampled_from(frames)),
        position=draw(st.tuples(coordinates, coordinates, coordinates)),
        quat_xyzw=tuple(float(c) for c in quat),
        anchor=draw(st.booleans()),
        observations=draw(st.none() | st.integers(0, 10_000)),
        note=draw(st.text(max_size=20).filter(str.isprintable)),
        covariance=covariance,
    )


@st.composite
def tag_maps(draw: st.DrawFn) -> TagMap:
    frames = ["map", *draw(st.sets(st.sampled_from(["elevator_cab", "dock_2", "on"])))]
    keys = draw(st.sets(st.tuples(st.sampled_from(FAMILY_NAMES), st.integers(0, 34)), max_size=6))
    return TagMap.from_entries([draw(tag_entries(key, frames)) for key in keys], frames)


@settings(max_examples=120, deadline=None, derandomize=True, database=None)
@given(tag_maps())
def test_saving_is_stable_and_loading_restores_the_map(tag_map: TagMap) -> None:
    text = tag_map.to_yaml_text()
    loaded = TagMap.from_yaml_text(text, "random.yaml")
    assert loaded.to_yaml_text() == text
    assert TagMap.from_yaml_text(loaded.to_yaml_text()) == loaded
    # to the written precision: micrometres, 1e-9 quaternions, 3 digits (+ <= 10 %) covariances
    assert [t.key for t in loaded] == [t.key for t in tag_map] and loaded.frames == tag_map.frames
    for old, new in zip(tag_map, loaded, strict=True):
        assert (new.frame, new.anchor, new.observations, new.note) == (
            old.frame,
            old.anchor,
            old.observations,
            old.note,
        )
        assert abs(new.size - old.size) <= 5e-7
        np.testing.assert_allclose(new.position, old.position, rtol=0, atol=5.1e-7)
        angle = (old.T_frame_tag().rotation.inverse() @ new.T_frame_tag().rotation).as_rotvec()
        assert np.linalg.norm(angle) < 1e-8
        if old.covariance is not None:
            np.testing.assert_allclose(
                np.array(new.covariance), np.array(old.covariance), rtol=0.11, atol=1e-300
            )


# ----- diff --------------------------------------------------------------------------------------
def _moved(tag_map: TagMap, tag_id: int, delta_m: list[float], rotvec: list[float]) -> TagMap:
    """``tag_map`` with tag ``tag_id`` shifted by ``delta_m`` (in its frame) and rotated by
    ``rotvec`` (about its own axes), written to text and read back like a real file."""
    tag = tag_map.get(tag_id)
    assert tag is not None
    T_old = tag.T_frame_tag()
    T_new = SE3(
        rotation=T_old.rotation @ SO3.from_rotvec(rotvec),
        translation=T_old.translation + np.array(delta_m),
    )
    entries = [tag.with_pose(T_new) if t.key == tag.key else t for t in tag_map]
    return TagMap.from_yaml_text(TagMap.from_entries(entries, tag_map.frames).to_yaml_text())


def test_a_3_cm_2_deg_move_reports_3_0_cm_and_2_0_deg() -> None:
    a = _load()
    axis = np.array([1.0, -2.0, 2.0]) / 3.0
    b = _moved(a, 1, [0.01, 0.02, 0.02], list(axis * math.radians(2.0)))
    diff = diff_tag_maps(a, b)
    assert not diff.added and not diff.removed and not diff.changed
    (move,) = diff.moved
    assert move.key == ("tag36h11", 1) and move.frame == "map"
    assert move.translation_m == pytest.approx(0.03, abs=1e-6)
    # oracle: scipy's angle of the relative rotation
    q_a, q_b = a.get(1).quat_xyzw, b.get(1).quat_xyzw  # type: ignore[union-attr]
    angle = (Rotation.from_quat(q_a).inv() * Rotation.from_quat(q_b)).magnitude()
    assert move.rotation_deg == pytest.approx(math.degrees(angle), abs=1e-9)
    assert move.rotation_deg == pytest.approx(2.0, abs=1e-6)
    assert format_tag_map_diff(diff) == [
        "~ tag36h11:1 moved 3.0 cm [+1.0, +2.0, +2.0] cm in map, rotated 2.0 deg"
    ]


@pytest.mark.parametrize(
    ("delta_m", "rot_deg", "reported"),
    [
        (0.004, 0.0, False),
        (0.006, 0.0, True),
        (0.0, 0.4, False),
        (0.0, 0.6, True),
        (0.004, 0.4, False),
    ],
)
def test_move_thresholds(delta_m: float, rot_deg: float, reported: bool) -> None:
    a = _load()
    b = _moved(a, 17, [0.0, delta_m, 0.0], [0.0, 0.0, math.radians(rot_deg)])
    assert bool(diff_tag_maps(a, b).moved) is reported
    assert diff_tag_maps(a, b, min_move_m=0.001, min_rot_deg=0.1).moved  # lower thresholds


def test_diff_lists_every_kind_of_change_one_line_each_sorted() -> None:
    a = _load()

    def edit(data: dict[str, Any]) -> None:
        tags = data["tags"]
        tags[0].update(size=0.16, note="lobby", anchor=True)  # id 0: size, anchor, note
        tags[3]["frame"] = "map"  # id 12: frame
        tags[2]["family"] = "aruco_4x4_100"  # aruco 5: family
        del tags[1]  # id 1: removed
        tags.append(
            {
                "id": 30,
                "size": 0.162,
                "position": [1.0, 2.0, 3.0],
                "quat_xyzw": Q_WALL,
                "note": "new",
            }
        )
        data["frames"] = ["map", "dock"]

    b = _load(edit)
    diff = diff_tag_maps(a, b)
    assert format_tag_map_diff(diff) == [
        "+ frame dock",
        "- frame elevator_cab",
        "~ aruco_4x4_50:5 family aruco_4x4_50 -> aruco_4x4_100",
        "~ tag36h11:0 size 0.162 -> 0.16 m",
        "~ tag36h11:0 anchor false -> true",
        '~ tag36h11:0 note "" -> "lobby"',
        "- tag36h11:1 removed: in map at [4.000, 2.350, 1.400] m, size 0.162 m",
        "~ tag36h11:12 frame elevator_cab -> map",
        '+ tag36h11:30 added: in map at [1.000, 2.000, 3.000] m, size 0.162 m, note "new"',
    ]
    assert diff_tag_maps(a, a).is_empty and format_tag_map_diff(diff_tag_maps(a, a)) == []
