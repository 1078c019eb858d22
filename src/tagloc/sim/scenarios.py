"""Named localization scenarios: a drive, how the camera sees tags, the true world vs the map.

Each scenario is one row of :data:`SCENARIOS` (a :class:`ScenarioSpec`, pure data) applied to the
built-in office world by :func:`build_scenario`:

============  ===================================================================================
default       the route with legged odometry (drifting several % of distance)
kidnap        at ``kidnap_at_s`` the robot is carried ``kidnap_skip_s`` further along the route:
              the ground truth jumps, the odometry continues smoothly (spliced); two tags in view
kidnap_one_tag  the same, to a place where one tag alone is in view
glint         false detections injected at ``glint_rate`` per frame (wrong ids, random quads)
moved_tag     tag ``moved_tags`` physically moved after the map was made: observations come
              from the moved world, the map from the original
corridor      a long featureless corridor: the corridor's middle tags removed from world and map
dropout       camera frames dropped over ``dropout_s``
camera_unplugged, odometry_stall, clock_jump_back, duplicated_messages
              stream-level ``faults`` (:mod:`tagloc.sim.faults`, whose table gives the ladder
              walk each must produce): frames lost, odometry stalled, its clock jumping back,
              messages sent twice
glass_corridor  (world ``glass_corridor``) glass on both sides: the lidar sees floor and end walls
mirrored_lobby  (world ``mirrored_lobby``) a mirror wall: phantom lidar geometry behind it
crowd         people walking with the robot hide ``crowd_fraction`` (45 %) of the lidar's beams
lidar_unplugged  no ``PointCloudMsg`` from 30 s to 50 s (a ``DropMessages`` fault)
long_corridor  (world ``long_corridor``) 120 m without doors, tags only near the ends
============  ===================================================================================

Every scenario streams the lidar when its world's robot has one (all built-in worlds do):
:class:`ScenarioSource` yields the sweeps of :mod:`tagloc.sim.lidar`, occluded by the world's and
the scenario's people.

Pure: the same name, seed and duration give the same scenario. This module is the scenario's
*source* only; running the localizer on a scenario is :mod:`tagloc.eval.scenarios`'. The built
scenario is :mod:`tagloc.sim.scenario`'s, its stream :mod:`tagloc.sim.scenario_source`'s, the
kidnap's splice and the truncation of a drive :mod:`tagloc.sim.drive_edits`'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from tagloc.config import short_repr
from tagloc.errors import SimulationError
from tagloc.messages import OdometryMsg, PointCloudMsg, TagDetectionsMsg
from tagloc.sim.drive import Drive, simulate_drive
from tagloc.sim.drive_edits import SplicedDrive, _splice, truncate_drive
from tagloc.sim.faults import ClockJump, DropMessages, DuplicateMessages, StreamFault
from tagloc.sim.observations import ObservationConfig
from tagloc.sim.odometry_ride import ImuFusionConfig
from tagloc.sim.people import Person, crowd_around
from tagloc.sim.ride_schedule import pacing_passengers, random_ride_route
from tagloc.sim.scenario import Scenario, scenario_premap, tag_map_from_world
from tagloc.sim.scenario_source import ScenarioSource
from tagloc.sim.world import WallMount, World, load_builtin_world, load_default_world
from tagloc.units import S_NS

__all__ = [
    "SCENARIOS",
    "Scenario",
    "ScenarioSource",
    "ScenarioSpec",
    "SplicedDrive",
    "build_scenario",
    "scenario_premap",
    "tag_map_from_world",
    "truncate_drive",
]


@dataclass(frozen=True, slots=True)
class ScenarioSpec:
    """One scenario as data (see the module docstring). Times in seconds after the start."""

    description: str
    observation: dict[str, float] = field(default_factory=dict)
    remove_tags: tuple[int, ...] = ()
    moved_tags: dict[int, tuple[float, float]] = field(default_factory=dict)  # id -> (dx, dy) m
    kidnap_at_s: float | None = None
    kidnap_skip_s: float = 0.0
    dropout_s: tuple[float, float] | None = None
    #: Applied to the message stream (:mod:`tagloc.sim.faults`), as a bag would deliver it.
    faults: tuple[StreamFault, ...] = ()
    #: A built-in world other than the office (:data:`tagloc.sim.world.BUILTIN_WORLDS`).
    world: str | None = None
    #: People walking with the robot, hiding about this fraction of the lidar's beams.
    crowd_fraction: float | None = None
    #: A building's route replaced by this many rides to random floors (seeded by the seed).
    rides: int | None = None
    #: People pacing in the cab (hiding its back-wall tag part of the time).
    passengers: int = 0
    #: The building publishes its elevators' state (``ElevatorStateMsg`` on ``topics.elevator``).
    elevator_topic: bool = False
    #: The robot's odometry fuses an IMU (:mod:`tagloc.sim.odometry_ride`).
    odometry_imu: bool = False


SCENARIOS: dict[str, ScenarioSpec] = {
    "default": ScenarioSpec("the office route, legged odometry"),
    "kidnap": ScenarioSpec(
        "robot carried 122.5 s further along the route at t = 40 s (odometry unaware), to the "
        "room_b door where two tags are in view",
        kidnap_at_s=40.0,
        kidnap_skip_s=122.5,
    ),
    "kidnap_one_tag": ScenarioSpec(
        "robot carried 75.6 s further along the route at t = 40 s (odometry unaware), into "
        "room_c where one tag (17) alone is in view for 6 s",
        kidnap_at_s=40.0,
        kidnap_skip_s=75.6,
    ),
    "glint": ScenarioSpec(
        "false detections, 0.6 per frame (wrong ids on real corners, random quads)",
        observation={"glint_rate": 0.6},
    ),
    "moved_tag": ScenarioSpec(
        "tag 5 moved 0.4 m along its wall after the survey", moved_tags={5: (0.4, 0.0)}
    ),
    "corridor": ScenarioSpec(
        "corridor tags 1-3 and 5-8 removed: 20 m without tags", remove_tags=(1, 2, 3, 5, 6, 7, 8)
    ),
    "dropout": ScenarioSpec("camera frames dropped from 20 s to 50 s", dropout_s=(20.0, 50.0)),
    # stream-level faults; each description names the ladder walk it must produce
    "camera_unplugged": ScenarioSpec(
        "camera unplugged: no tag detections from 30 s to 50 s (tags in view before and after); "
        "ladder 3 -> 4 (camera dead) within 1 s of the camera timeout, back to 3 once fixes are "
        "accepted again",
        faults=(DropMessages(30.0, 50.0, (TagDetectionsMsg,)),),
    ),
    "odometry_stall": ScenarioSpec(
        "odometry stalled from 40 s to 42 s (camera frames continue); ladder 3 -> 4 (odometry "
        "dead) and back to 3, nothing skipped, fused error after the stall as without it",
        faults=(DropMessages(40.0, 42.0, (OdometryMsg,)),),
    ),
    "clock_jump_back": ScenarioSpec(
        "odometry clock jumps 5 s back at 45 s and runs on from there (camera clock unchanged); "
        "the node starts over and the ladder falls 3 -> 4 at once (clock jumped back)",
        faults=(ClockJump(45.0, 5.0, (OdometryMsg,)),),
    ),
    "duplicated_messages": ScenarioSpec(
        "every message from 30 s to 40 s sent twice; counted as duplicates, ladder walk and "
        "fused trajectory those of the drive without duplicates",
        faults=(DuplicateMessages(30.0, 40.0),),
    ),
    # lidar scenarios (the world's robot carries the lidar; tags are unaffected by glass)
    "glass_corridor": ScenarioSpec(
        "a 40 m corridor walled with glass on both sides and nothing behind it: the lidar sees "
        "the floor and the two solid end walls only, which fix the position along the corridor "
        "and not across it; tags on the glass carry the localization",
        world="glass_corridor",
    ),
    "mirrored_lobby": ScenarioSpec(
        "a lobby whose east wall is a mirror: lidar beams reflected by it return phantom "
        "geometry behind the mirror (the reflected lobby), consistent in every sweep and so "
        "in a premap made with the scanner",
        world="mirrored_lobby",
    ),
    "crowd": ScenarioSpec(
        "the office route in a crowd: people walking with the robot at 0.9 m hide about 45 % of "
        "the lidar's beams (between 30 % and 60 % in every sweep), the gaps between them moving",
        crowd_fraction=0.45,
    ),
    "lidar_unplugged": ScenarioSpec(
        "lidar unplugged: no point clouds from 30 s to 50 s (odometry and camera continue)",
        faults=(DropMessages(30.0, 50.0, (PointCloudMsg,)),),
    ),
    "long_corridor": ScenarioSpec(
        "a 120 m straight corridor without doors, tags only near its ends: over its middle 40 m "
        "the lidar sees two parallel walls and the floor (the end walls beyond its 40 m range), "
        "which fix the position across the corridor and the heading, not along it",
        world="long_corridor",
    ),
    # a building of floors (world tower): floors 0, 1, 2 at 0, 3.5, 7 m, one mirrored cab
    "elevator": ScenarioSpec(
        "20 rides of the tower's mirrored lift to random floors (a seeded schedule): the doors "
        "open and close, two passengers pacing in the cab hide its tag part of the time, the "
        "building publishes the lift's door and floor; legged odometry (no motion in a ride)",
        world="tower",
        rides=20,
        passengers=2,
        elevator_topic=True,
    ),
    "elevator_imu": ScenarioSpec(
        "the elevator scenario with IMU-fused odometry: each trip gives the odometry a z drift "
        "and a tilt transient",
        world="tower",
        rides=20,
        passengers=2,
        elevator_topic=True,
        odometry_imu=True,
    ),
    "kidnap_floor": ScenarioSpec(
        "robot carried 133.7 s further along the tower's route at t = 70 s (odometry unaware): "
        "from floor 2 to the same spot of floor 0, which looks the same; only the tags tell",
        world="tower",
        kidnap_at_s=70.0,
        kidnap_skip_s=133.7,
    ),
}


def build_scenario(
    name: str,
    seed: int = 0,
    duration_s: float | None = None,
    world: World | None = None,
) -> Scenario:
    """Build scenario ``name`` (a key of :data:`SCENARIOS`).

    Parameters
    ----------
    name : str
    seed : int
        Odometry, observation-noise and crowd seed.
    duration_s : float, optional
        Keep only the first ``duration_s`` seconds of the drive (default: all of it, ~700 s).
    world : World, optional
        Default: the scenario's built-in world (the office unless it names another).

    Raises
    ------
    SimulationError
        For an unknown name (the message lists the known ones), or a ``duration_s`` that is not
        a positive number.
    """
    spec = SCENARIOS.get(name)
    if spec is None:
        raise SimulationError(
            f"unknown scenario {short_repr(name)} (known: {', '.join(SCENARIOS)})"
        )
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise SimulationError(
            f"the duration must be a positive number of seconds, got {duration_s}"
        )
    base = world or (load_builtin_world(spec.world) if spec.world else load_default_world())
    base = _building(base, spec, seed)
    surveyed = base.model_copy(
        update={"tags": tuple(t for t in base.tags if t.id not in spec.remove_tags)}
    )
    true_world = _move_tags(surveyed, spec.moved_tags)
    drive = simulate_drive(surveyed, seed=seed)
    kidnaps: list[int] = []
    if spec.kidnap_at_s is not None:
        drive = _splice(drive, spec.kidnap_at_s, spec.kidnap_skip_s)
        kidnaps.append(drive.t0_ns + round(spec.kidnap_at_s * S_NS))
    if duration_s is not None:
        drive = truncate_drive(drive, duration_s)
    if true_world is not surveyed:
        drive = replace(drive, world=true_world)
    stamps = drive.camera_stamps_ns
    if spec.dropout_s is not None:
        lo, hi = (drive.t0_ns + round(s * S_NS) for s in spec.dropout_s)
        stamps = stamps[(stamps < lo) | (stamps > hi)]
    obs = ObservationConfig(seed=seed, **spec.observation)
    tag_map = tag_map_from_world(surveyed)
    people = true_world.people
    if spec.crowd_fraction is not None:
        people = (*people, *_crowd(drive, spec.crowd_fraction, seed))
    return Scenario(
        name, drive, obs, true_world, tag_map, stamps, kidnaps, spec.faults, tuple(people),
        spec.elevator_topic,
    )  # fmt: skip


def _building(world: World, spec: ScenarioSpec, seed: int) -> World:
    """The scenario's changes to a building: a seeded schedule of rides, passengers in the
    first cab, an IMU in the odometry."""
    update: dict[str, object] = {}
    if spec.rides is not None and world.elevators:
        update["route"] = random_ride_route(world, spec.rides, seed)
    if spec.odometry_imu:
        odometry = world.robot.odometry.model_copy(update={"imu": ImuFusionConfig()})
        update["robot"] = world.robot.model_copy(update={"odometry": odometry})
    if not update and not spec.passengers:
        return world
    world = world.model_copy(update=update)
    if spec.passengers and world.elevators:
        duration = world.plan_route().total_duration_s
        riders = pacing_passengers(world.elevators[0], duration, spec.passengers)
        world = world.model_copy(update={"people": (*world.people, *riders)})
    return world


def _crowd(drive: Drive, fraction: float, seed: int) -> tuple[Person, ...]:
    """People walking with the robot's true path (sampled every 0.5 s), times after t0."""
    stamps = np.arange(int(drive.stamps_ns[0]), int(drive.stamps_ns[-1]) + S_NS, S_NS // 2)
    truth = drive.ground_truth_at(stamps)
    t_s = ((stamps - drive.t0_ns) * 1e-9).astype(np.float64)
    return crowd_around(truth.xy_yaw_map_base, t_s, fraction, seed=seed)


def _move_tags(world: World, moves: dict[int, tuple[float, float]]) -> World:
    if not moves:
        return world
    tags = []
    for tag in world.tags:
        if tag.id in moves and tag.wall is not None:
            dx, dy = moves[tag.id]
            wall = WallMount(x=tag.wall.x + dx, y=tag.wall.y + dy, yaw_deg=tag.wall.yaw_deg,
                             height=tag.wall.height)  # fmt: skip
            tag = tag.model_copy(update={"wall": wall})
        tags.append(tag)
    return world.model_copy(update={"tags": tuple(tags)})
