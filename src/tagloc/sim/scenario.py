"""A built scenario (:class:`Scenario`: the drive, the true world, the map the localizer is given),
its true tag map and its true lidar premap. The named scenarios and how one is built are
:mod:`tagloc.sim.scenarios`'."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.sim.drive import Drive
from tagloc.sim.faults import StreamFault
from tagloc.sim.lidar import premap_from_world
from tagloc.sim.observations import ObservationConfig
from tagloc.sim.people import Person
from tagloc.sim.world import World
from tagloc.tags.tag_entry import TagEntry
from tagloc.tags.tagmap import TagMap

__all__ = ["Scenario", "scenario_premap", "tag_map_from_world"]


@dataclass(frozen=True, slots=True)
class Scenario:
    """Everything a run of one scenario needs.

    Attributes
    ----------
    name : str
    drive : Drive
        Odometry and truth (truth spliced for a kidnap).
    observation : ObservationConfig
    world : World
        The world the tags really are in (observations come from it).
    tag_map : TagMap
        The map the localizer is given (from the world as surveyed).
    camera_stamps_ns : (M,) int64
        Frames that exist (dropout removes some).
    kidnaps_ns : list of int
    faults : tuple of StreamFault
        Applied to the stream by :class:`~tagloc.sim.scenario_source.ScenarioSource` (empty:
        the clean stream).
    """

    name: str
    drive: Drive
    observation: ObservationConfig
    world: World
    tag_map: TagMap
    camera_stamps_ns: npt.NDArray[np.int64]
    kidnaps_ns: list[int]
    faults: tuple[StreamFault, ...] = ()
    #: Lidar occluders: the world's people and the scenario's crowd.
    people: tuple[Person, ...] = ()
    #: The building publishes its elevators' state (:func:`~tagloc.sim.elevator_stream.
    #: elevator_messages`, on ``topics.elevator``).
    elevator_topic: bool = False


def tag_map_from_world(world: World) -> TagMap:
    """The surveyed tag map of ``world``. A single-floor world: every tag's pose in ``map`` (cab
    tags included, the cab standing still). A world with floors: each floor's tags in ``map`` (z
    above that floor's height) with their ``floor``, each cab's tags in its cab's frame (listed in
    ``frames``), and the ``floors`` table."""
    if not world.has_floors:
        return TagMap.from_entries(
            TagEntry.from_pose(t.id, world.T_map_tag(t), t.size, family=t.family,
                               note=t.note or "")
            for t in world.tags
        )  # fmt: skip
    entries = [
        TagEntry.from_pose(
            t.id,
            world.T_map_tag(t) if floor is not None else t.T_frame_tag(),
            t.size,
            family=t.family,
            note=t.note or "",
            frame=t.frame,
            floor=floor,
        )
        for t, floor in world.all_tags()
    ]
    frames = ["map", *(s.frame for s in world.shafts())]
    return TagMap.from_entries(entries, frames=frames, floors=world.floor_heights())


def scenario_premap(
    scenario: Scenario, *, every_m: float = 0.5, voxel_m: float = 0.1
) -> npt.NDArray[np.float64]:
    """The true lidar premap of a scenario, as :func:`tag_map_from_world` is its true tag map:
    :func:`~tagloc.sim.lidar.premap_from_world` of the world along the drive's ground truth
    (scans every ``every_m`` of travel, no people, no noise; ``voxel_m`` cubes), ``(N, 3)`` in
    ``map``, metres.

    Raises
    ------
    ValueError
        If the world's robot has no lidar.
    """
    return premap_from_world(
        scenario.world, scenario.drive.T_map_base, every_m=every_m, voxel_m=voxel_m
    )
