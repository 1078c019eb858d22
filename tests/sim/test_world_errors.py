"""Bad world files fail with ONE line naming the file and the exact field path."""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import pytest
import yaml

from tagloc.errors import ConfigError
from tagloc.sim import World, load_world

Doc = dict[str, Any]
DEFAULT_TEXT = resources.files("tagloc.sim").joinpath("worlds/office.yaml").read_text("utf-8")


def _default_doc() -> Doc:
    doc = yaml.safe_load(DEFAULT_TEXT)
    assert isinstance(doc, dict)
    return doc


def _load_error(tmp_path: Path, text: str) -> str:
    path = tmp_path / "world.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_world(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    return message.removeprefix(f"{path}: ")


def _set(doc: Doc, path: list[Any], value: Any) -> None:
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value


def _delete(doc: Doc, path: list[Any]) -> None:
    node = doc
    for key in path[:-1]:
        node = node[key]
    del node[path[-1]]


CASES: list[tuple[str, Callable[[Doc], None], str]] = [
    (
        "duplicate tag id",
        lambda d: _set(d, ["tags", 7, "id"], 2),
        "tags[7].id: duplicate tag id 2 (also tags[2])",
    ),
    ("tag without size", lambda d: _delete(d, ["tags", 3, "size"]), "tags[3].size: field required"),
    (
        "non-unit quaternion",
        lambda d: (
            _delete(d, ["tags", 5, "wall"]),
            _set(d, ["tags", 5, "pose"], {"position": [1, 2, 1.3], "quat_xyzw": [0, 0, 0.1, 1]}),
        ),
        "tags[5].pose.quat_xyzw: not a unit quaternion: |q| = 1.00498756",
    ),
    (
        "unknown odometry model",
        lambda d: _set(d, ["robot", "odometry", "model"], "tracked"),
        "robot.odometry.model: unknown value 'tracked'; allowed: 'wheel', 'legged'",
    ),
    (
        "missing odometry model",
        lambda d: _delete(d, ["robot", "odometry", "model"]),
        "robot.odometry.model: field required",
    ),
    (
        "odometry parameter out of range",
        lambda d: _set(d, ["robot", "odometry", "slip_rate_per_m"], -1),
        "robot.odometry.slip_rate_per_m: input should be greater than or equal to 0",
    ),
    (
        "wheel model rejects legged-only fields",
        lambda d: _set(d, ["robot", "odometry"], {"model": "wheel", "lateral_drift": 0.1}),
        "robot.odometry.lateral_drift: extra inputs are not permitted",
    ),
    (
        "cab tag without elevator",
        lambda d: _delete(d, ["elevator"]),
        "tags[35].frame: tag is in frame elevator_cab but the world has no elevator",
    ),
    (
        "unknown checkpoint",
        lambda d: _set(d, ["route", "waypoints", 3], "nowhere"),
        "route.waypoints[3]: unknown checkpoint 'nowhere' (known: start, a_door,",
    ),
    (
        "bad waypoint",
        lambda d: _set(d, ["route", "waypoints", 2], [1.0, 2.0, 3.0]),
        "route.waypoints[2].at: expected a checkpoint name or [x, y] in metres",
    ),
    (
        "negative size",
        lambda d: _set(d, ["tags", 0, "size"], -0.16),
        "tags[0].size: input should be greater than 0",
    ),
    (
        "pose and wall",
        lambda d: _set(d, ["tags", 0, "pose"], {"position": [0, 0, 1], "quat_xyzw": [0, 0, 0, 1]}),
        "tags[0]: give exactly one of 'pose' or 'wall'",
    ),
    (
        "unknown key",
        lambda d: _set(d, ["walls", 0, "colour"], "red"),
        "walls[0].colour: extra inputs are not permitted",
    ),
    (
        "bad material",
        lambda d: _set(d, ["walls", 2, "material"], "brick"),
        "walls[2].material: input should be 'wall', 'glass' or 'mirror'",
    ),
    (
        "id beyond family",
        lambda d: _set(d, ["tags", 1, "id"], 587),
        "tags[1].id: id 587 is out of range for tag36h11 (0..586)",
    ),
    (
        "camera quat and rpy",
        lambda d: _set(d, ["robot", "camera", "T_base_cam", "quat_xyzw"], [0, 0, 0, 1]),
        "robot.camera.T_base_cam: give exactly one of 'quat_xyzw' or 'rpy_deg'",
    ),
    (
        "distortion coefficients",
        lambda d: _set(
            d, ["robot", "camera", "distortion"], {"model": "radtan", "coefficients": [0.1]}
        ),
        "robot.camera.distortion.coefficients: model radtan takes 4 or 5 coefficients, got 1",
    ),
    (
        "zero rate",
        lambda d: _set(d, ["robot", "odom_rate_hz"], 0),
        "robot.odom_rate_hz: input should be greater than 0",
    ),
    ("wrong version", lambda d: _set(d, ["version"], 2), "version: input should be 1"),
    (
        "duplicate checkpoint",
        lambda d: _set(d, ["checkpoints", 4, "name"], "start"),
        "checkpoints[4].name: duplicate checkpoint 'start' (also checkpoints[0])",
    ),
    (
        "route of one repeated waypoint",
        lambda d: _set(d, ["route", "waypoints"], ["start", "start", {"at": "start"}]),
        "route.waypoints: the route needs at least two distinct waypoints",
    ),
    (
        "tiny speed",
        lambda d: _set(d, ["route", "speed"], 1e-9),
        "route.speed: input should be greater than or equal to 0.01",
    ),
    (
        "dwells past the sample budget",
        lambda d: (_set(d, ["route", "dwell"], 3600), _set(d, ["route", "repeat"], 10)),
        "route: driving the route (1926 m, repeat 10) takes 1228683 s, 1.23e+08 odometry "
        "samples at robot.odom_rate_hz, more than 500000;",
    ),
    (
        "waypoint far away",
        lambda d: _set(d, ["route", "waypoints", 1], [1e300, 0.0]),
        "route.waypoints[1].at: expected a checkpoint name or [x, y] in metres "
        "(|x|, |y| <= 100000), "
        "got [1e+300, 0.0]",
    ),
    (
        "checkpoint far away",
        lambda d: _set(d, ["checkpoints", 1, "x"], -1e300),
        "checkpoints[1].x: input should be greater than or equal to -100000",
    ),
    (
        "wall far away",
        lambda d: _set(d, ["walls", 1, "end"], [1e300, 0]),
        "walls[1].end[0]: input should be less than or equal to 100000",
    ),
    (
        "tiny focal length",
        lambda d: _set(d, ["robot", "camera", "intrinsics", "fx"], 1e-300),
        "robot.camera.intrinsics.fx: input should be greater than or equal to 1",
    ),
    (
        "huge distortion",
        lambda d: _set(
            d, ["robot", "camera", "distortion"], {"model": "radtan", "coefficients": [1e300] * 4}
        ),
        "robot.camera.distortion.coefficients[0]: input should be less than or equal to 1000 "
        "(and 3 more errors)",
    ),
    (
        "long bad waypoint is quoted by a prefix",
        lambda d: _set(d, ["route", "waypoints", 2], [[1.0] * 10_000] * 3),
        "route.waypoints[2].at: expected a checkpoint name or [x, y] in metres (|x|, |y| <= "
        "100000), got [[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, ...], [1.0, 1.0, 1.0, 1.0...",
    ),
]


@pytest.mark.parametrize(("mutate", "expected"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_world_names_file_and_field(
    tmp_path: Path, mutate: Callable[[Doc], None], expected: str
) -> None:
    doc = _default_doc()
    mutate(doc)
    message = _load_error(tmp_path, yaml.safe_dump(doc, sort_keys=False))
    assert message.startswith(expected), message
    assert len(message) < 400


def test_several_errors_still_one_line(tmp_path: Path) -> None:
    doc = _default_doc()
    _delete(doc, ["tags", 3, "size"])
    _delete(doc, ["tags", 4, "size"])
    message = _load_error(tmp_path, yaml.safe_dump(doc))
    assert message == "tags[3].size: field required (and 1 more error)"


def test_malformed_yaml_names_the_line(tmp_path: Path) -> None:
    lines = DEFAULT_TEXT.splitlines()
    row = lines.index("route:") + 2  # 0-based index of the `accel_max` line
    lines[row] = "  accel_max: [0.4"
    message = _load_error(tmp_path, "\n".join(lines))
    assert message.startswith(f"line {row + 2}, column ")
    assert "invalid YAML" in message


def test_tab_indentation_names_the_line(tmp_path: Path) -> None:
    message = _load_error(tmp_path, "version: 1\nwalls:\n\t- {start: [0, 0], end: [1, 0]}\n")
    assert message.startswith("line 3, column 1: invalid YAML")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("", "the top level must be a mapping, got NoneType"),
        ("- 1\n- 2\n", "the top level must be a mapping, got list"),
        ("version: 1\n", "route: field required (and 1 more error)"),
    ],
)
def test_not_a_world(tmp_path: Path, text: str, expected: str) -> None:
    assert _load_error(tmp_path, text) == expected


def test_missing_file_and_text_source(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.yaml: cannot read world file"):
        load_world(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match=r"^<string>: version: input should be 1$"):
        World.from_yaml_text(DEFAULT_TEXT.replace("version: 1", "version: 3", 1))
