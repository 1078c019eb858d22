"""Worlds for the lidar-aided survey tests, made from the built-in office.

- :func:`room_loop_world`: the office with a short route (rooms a and b and back, ~60 m): a
  survey that closes loops in a few seconds of simulation.
- :func:`sparse_tag_world`: a loop corridor (48 m x 16 m outside, 2.4 m wide, 118 m around)
  with niches every 4 m in the outer wall (what a scan matcher holds on to along a corridor)
  and a tag every 12 m along it, each on a 0.3 m pillar of the outer wall facing the oncoming
  robot; driven twice by a legged robot whose odometry drifts 0.3 deg of yaw per metre.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import yaml

from tagloc.sim import World, load_default_world


def _office_dict() -> dict[str, Any]:
    data = yaml.safe_load(load_default_world().to_yaml_text())
    assert isinstance(data, dict)
    return data


def room_loop_world() -> World:
    data = _office_dict()
    data["route"]["repeat"] = 1
    data["route"]["waypoints"] = [
        {"at": "start", "dwell": 1.0}, "a_door", "a_room", "a_far", "a_room", "a_door",
        "b_door", "b_room", "b_far", "b_room", "b_door", "a_door", {"at": "start", "dwell": 1.0},
    ]  # fmt: skip
    return World.model_validate(data)


def sparse_tag_world(yaw_bias_deg_per_m: float = 0.3, laps: int = 2) -> World:
    data = _office_dict()
    outer, inner = (0.0, 0.0, 48.0, 16.0), (2.4, 2.4, 45.6, 13.6)
    walls = []
    for x0, y0, x1, y1 in (outer, inner):
        corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        walls += [{"start": list(corners[i]), "end": list(corners[(i + 1) % 4]), "height": 2.7}
                  for i in range(4)]  # fmt: skip
    # niches: 0.3 m stubs into the corridor from the outer wall, every 4 m
    for x in range(4, 48, 4):
        walls += [{"start": [x, 0.0], "end": [x, 0.3]}, {"start": [x, 16.0], "end": [x, 15.7]}]
    for y in range(4, 16, 4):
        walls += [{"start": [0.0, y], "end": [0.3, y]}, {"start": [48.0, y], "end": [47.7, y]}]
    # a tag every 12 m along the corridor's centre line, on a pillar of the outer wall, facing
    # back along the corridor (a tag on a side wall is seen edge-on by a forward camera)
    tags, s, tag_id = [], 6.0, 0
    legs = [((1.2, 1.2), (46.8, 1.2), (0, -1)), ((46.8, 1.2), (46.8, 14.8), (1, 0)),
            ((46.8, 14.8), (1.2, 14.8), (0, 1)), ((1.2, 14.8), (1.2, 1.2), (-1, 0))]  # fmt: skip
    start = 0.0
    for (ax, ay), (bx, by), (nx, ny) in legs:
        length = abs(bx - ax) + abs(by - ay)
        while s < start + length:
            f = (s - start) / length
            x, y = ax + f * (bx - ax), ay + f * (by - ay)
            # the outer wall is 1.2 m from the centre line along the normal; the pillar stands
            # 0.3 m into the corridor, the tag on its face towards the robot coming along
            ox, oy = x + 1.2 * nx, y + 1.2 * ny
            walls.append({"start": [ox, oy], "end": [ox - 0.3 * nx, oy - 0.3 * ny]})
            dx, dy = np.sign(bx - ax), np.sign(by - ay)  # direction of travel
            yaw = float(np.degrees(np.arctan2(-dy, -dx)))
            cx, cy = ox - 0.15 * nx - 0.001 * dx, oy - 0.15 * ny - 0.001 * dy
            tags.append({"id": tag_id, "size": 0.16,
                         "wall": {"x": cx, "y": cy, "yaw_deg": yaw, "height": 1.3}})  # fmt: skip
            tag_id, s = tag_id + 1, s + 12.0
        start += length
    data["walls"], data["tags"] = walls, tags
    data.pop("elevator", None)
    data["checkpoints"] = [{"name": f"c{i}", "x": a[0], "y": a[1]}
                           for i, (a, _, _) in enumerate(legs)]  # fmt: skip
    data["route"]["repeat"] = laps
    data["route"]["waypoints"] = ["c0", "c1", "c2", "c3", "c0"]
    data["robot"]["odometry"]["yaw_bias_deg_per_m"] = yaw_bias_deg_per_m
    data["name"] = "sparse_tags"
    return World.model_validate(data)
