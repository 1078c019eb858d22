"""The simulated lidar in a building of floors: each sweep sees the scene of its instant.

:class:`FloorLidarSimulator` is a :class:`~tagloc.sim.lidar.LidarSimulator` whose walls and people
are those of :func:`tagloc.sim.floor_scene.scene_at` at the sweep's start: the robot's floor and
the cabs standing there (a closed door is a wall), or only its cab between floors. Beams are cast
in that floor's frame (its floor at z = 0 under the robot), which is what the scanner sees: the
points are in the scanner frame anyway. In a moving cab with its door closed the lidar sees the
cab's walls (mirrors in the built-in tower) and floor, standing still around it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tagloc.sim.drive import Drive
from tagloc.sim.floor_scene import SceneCache
from tagloc.sim.lidar import LidarSimulator, PoseFunction, Sweep
from tagloc.sim.lidar_cast import Segments
from tagloc.sim.people import Person
from tagloc.sim.ride import RidePlan
from tagloc.sim.robot import LidarConfig
from tagloc.sim.world import World

__all__ = ["FloorLidarSimulator", "lidar_for_drive"]


class FloorLidarSimulator(LidarSimulator):
    """Sweeps of ``config``'s scanner along ``drive`` in a building (module docstring)."""

    def __init__(self, config: LidarConfig, world: World, drive: Drive) -> None:
        assert isinstance(drive.plan, RidePlan)
        super().__init__(config, world.all_floors()[0].walls, (), drive.t0_ns)
        self._drive = drive
        self._scenes = SceneCache(world, drive.plan)
        self._segments: dict[tuple[object, ...], Segments] = {}

    def sweep(self, xy_yaw_at: PoseFunction, start_ns: int, index: int) -> Sweep:
        stamp = np.array([start_ns], dtype=np.int64)
        xy = np.asarray(xy_yaw_at(stamp), dtype=np.float64)[0, :2]
        scene = self._scenes.at(float(self._drive.route_s(stamp)[0]), xy)
        segments = self._segments.get(scene.key) if scene.floor is not None else None
        if segments is None:
            segments = Segments.from_walls(scene.walls)
            if scene.floor is not None:
                self._segments[scene.key] = segments
        self.segments = segments
        self._set_people(scene.people)
        # people walk on route time; the parent reads them at (stamps - t0_ns)
        self.t0_ns = int(start_ns) - round(float(self._drive.route_s(stamp)[0]) * 1e9)
        return super().sweep(xy_yaw_at, start_ns, index)

    def _set_people(self, people: Sequence[Person]) -> None:
        if len(people) == len(self.people) and all(
            a is b for a, b in zip(people, self.people, strict=True)
        ):
            return
        self.people = tuple(people)
        self._people_wp = [p.waypoints() for p in self.people]
        self._radius = np.array([p.radius_m for p in self.people], dtype=np.float64)
        self._height = np.array([p.height_m for p in self.people], dtype=np.float64)


def lidar_for_drive(
    config: LidarConfig, world: World, people: Sequence[Person], drive: Drive
) -> LidarSimulator:
    """The lidar of a drive: a :class:`FloorLidarSimulator` in a building of floors, otherwise
    ``LidarSimulator(config, world.walls_in_map(), people, drive.t0_ns)``."""
    if isinstance(drive.plan, RidePlan):
        return FloorLidarSimulator(config, world, drive)
    return LidarSimulator(config, world.walls_in_map(), people, drive.t0_ns)
