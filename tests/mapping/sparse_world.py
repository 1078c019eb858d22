"""A sparse building for the uncertainty tests: one rectangular corridor loop, a tag every
``spacing_m`` metres on its outer wall, the office world's robot (legged odometry) driving once
around it. With one anchor, the tags far along the loop are only as good as the odometry between
sightings: the builder's sigmas must say so.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tagloc.sim import World, load_default_world

#: Corridor width (m): the route runs down its middle.
WIDTH_M = 3.0


#: The legged odometry's drift terms, scaled by ``odometry_scale``.
_DRIFT_TERMS = (
    "scale_error", "yaw_scale_error", "yaw_bias_deg_per_m", "sigma_xy_per_sqrt_m",
    "sigma_yaw_deg_per_sqrt_m", "sigma_yaw_deg_per_sqrt_rad", "lateral_drift", "slip_rate_per_m",
)  # fmt: skip


def sparse_world(
    length_m: float = 48.0,
    depth_m: float = 12.0,
    spacing_m: float = 12.0,
    odometry_scale: float = 1.0,
) -> World:
    """The loop ``[0, length] x [0, depth]`` with an inner block leaving a 3 m corridor.

    ``odometry_scale`` multiplies every drift term of the office robot's legged odometry (1: as
    is, 0.7 deg/sqrt(m) of yaw; 0.3: a better robot).

    Tags (0.16 m) on the outer wall every ``spacing_m`` of perimeter, starting 3 m from the
    south-west corner, facing into the corridor, 1.3 m high; ids 0, 1, ... in driving order.
    """
    L, D, w = length_m, depth_m, WIDTH_M
    walls = [
        {"start": [0, 0], "end": [L, 0]}, {"start": [L, 0], "end": [L, D]},
        {"start": [L, D], "end": [0, D]}, {"start": [0, D], "end": [0, 0]},
        {"start": [w, w], "end": [L - w, w]}, {"start": [L - w, w], "end": [L - w, D - w]},
        {"start": [L - w, D - w], "end": [w, D - w]}, {"start": [w, D - w], "end": [w, w]},
    ]  # fmt: skip
    # outer perimeter, counter-clockwise from the south-west corner: (start, direction, facing)
    sides = [
        ((0.0, 0.0), (1.0, 0.0), 90.0, L),
        ((L, 0.0), (0.0, 1.0), 180.0, D),
        ((L, D), (-1.0, 0.0), -90.0, L),
        ((0.0, D), (0.0, -1.0), 0.0, D),
    ]
    tags: list[dict[str, Any]] = []
    s = 3.0
    offset = 0.0
    for (x0, y0), (dx, dy), yaw, side in sides:
        while s - offset < side - 1.0:
            if s - offset > 1.0:  # not in a corner
                u = s - offset
                wall = {"x": x0 + dx * u, "y": y0 + dy * u, "yaw_deg": yaw, "height": 1.3}
                tags.append({"id": len(tags), "size": 0.16, "wall": wall})
            s += spacing_m
        offset += side
    h = w / 2
    corners = [(h, h), (L - h, h), (L - h, D - h), (h, D - h)]
    checkpoints = [{"name": f"c{i}", "x": x, "y": y} for i, (x, y) in enumerate(corners)]
    route = {
        "speed": 0.8, "accel_max": 0.4, "yaw_rate_max": 0.8, "yaw_accel_max": 1.5,
        "corner_radius": 0.5, "repeat": 1,
        "waypoints": [{"at": [h + 1.0, h], "dwell": 1.0}, "c1", "c2", "c3", "c0",
                      {"at": [h + 1.0, h], "dwell": 1.0}],
    }  # fmt: skip
    office = load_default_world()
    robot = office.robot.model_dump(mode="json")
    for term in _DRIFT_TERMS:
        robot["odometry"][term] *= odometry_scale
    data = {
        "version": 1, "name": "sparse loop", "walls": walls, "tags": tags,
        "checkpoints": checkpoints, "route": route,
        "robot": robot,
    }  # fmt: skip
    return World.model_validate(data)


def true_positions(world: World) -> dict[int, np.ndarray]:
    """Tag id -> true position in ``map``."""
    return {t.id: world.T_map_tag(t).translation for t in world.tags}
