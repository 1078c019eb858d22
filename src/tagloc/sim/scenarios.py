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
*source* only; running the localizer on a scenario is :mod:`tagloc.eval.scenarios`'.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from tagloc.config import short_repr
from tagloc.errors import SimulationError
from tagloc.geometry import SE3
from tagloc.messages import (
    CameraInfoMsg,
    ElevatorStateMsg,
    GroundTruthMsg,
    Message,
    NodeTopics,
    OdometryMsg,
    PointCloudMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.sim.drive import Drive, simulate_drive
from tagloc.sim.elevator_stream import elevator_messages
from tagloc.sim.faults import ClockJump, DropMessages, DuplicateMessages, StreamFault, apply_faults
from tagloc.sim.frame_truth import FrameTruthMap
from tagloc.sim.lidar import LIDAR_FRAME, LidarSimulator, Sweep, premap_from_world
from tagloc.sim.lidar_floors import lidar_for_drive
from tagloc.sim.observations import ObservationConfig, ObservedFrame, simulate_observations
from tagloc.sim.odometry_ride import ImuFusionConfig
from tagloc.sim.people import Person, crowd_around
from tagloc.sim.ride_schedule import pacing_passengers, random_ride_route
from tagloc.sim.trajectory import Trajectory
from tagloc.sim.world import WallMount, World, load_builtin_world, load_default_world
from tagloc.tags.tagmap import TagEntry, TagMap
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

MAP_FRAME, ODOM_FRAME, BASE_FRAME, CAMERA_FRAME = "map", "odom", "base_link", "camera_optical"
TF_STATIC = "/tf_static"
#: Odometry covariance written with the simulated odometry (informational; the filter's process
#: noise is configured in ``localizer.yaml``).
_ODOM_COV = np.diag(np.square([0.02, 0.02, 0.01, 0.005, 0.005, 0.02]))


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


@dataclass(frozen=True, slots=True)
class SplicedDrive(Drive):
    """A drive whose ground truth skips ``skip_ns`` of the route from ``kidnap_ns`` on."""

    kidnap_ns: int = 0
    skip_ns: int = 0

    def ground_truth_at(self, stamps_ns: npt.NDArray[np.int64]) -> Trajectory:
        """Truth at ``stamps_ns``: the route's, shifted by ``skip_ns`` from the kidnap on."""
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        shifted = np.where(stamps >= self.kidnap_ns, stamps + self.skip_ns, stamps)
        return self.plan.sample(shifted, self.t0_ns)

    def route_s(self, stamps_ns: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Route time at ``stamps_ns``, shifted by ``skip_ns`` from the kidnap on."""
        stamps = np.atleast_1d(np.asarray(stamps_ns, dtype=np.int64))
        shifted = np.where(stamps >= self.kidnap_ns, stamps + self.skip_ns, stamps)
        return (shifted - np.int64(self.t0_ns)).astype(np.float64) * 1e-9


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
        Applied to the stream by :class:`ScenarioSource` (empty: the clean stream).
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


def _splice(drive: Drive, kidnap_at_s: float, skip_s: float) -> SplicedDrive:
    """Truth from ``kidnap_at`` on is the route ``skip_s`` later; odometry keeps its own path
    (the increments of the skipped-to stretch) without a jump."""
    step = int(drive.stamps_ns[1] - drive.stamps_ns[0])
    k = int(np.searchsorted(drive.stamps_ns, drive.t0_ns + round(kidnap_at_s * S_NS)))
    skip = round(skip_s * S_NS / step)
    n = len(drive.stamps_ns) - skip
    if k >= n:
        raise SimulationError(f"kidnap at {kidnap_at_s} s + {skip_s} s is past the drive's end")
    idx = np.concatenate([np.arange(k), np.arange(k, n) + skip])
    T_odom = drive.T_odom_base
    T_odom_after = T_odom[k - 1] @ T_odom[k - 1 + skip].inverse() @ T_odom[idx[k:]]
    T_odom_base = SE3.stack([*T_odom[:k], *T_odom_after])
    stamps = drive.stamps_ns[:n]
    cams = drive.camera_stamps_ns[drive.camera_stamps_ns <= stamps[-1]]
    return SplicedDrive(
        world=drive.world, stamps_ns=stamps, T_map_base=drive.T_map_base[idx],
        T_odom_base=T_odom_base, camera_stamps_ns=cams, distance_m=drive.distance_m[idx],
        trajectory=drive.trajectory, plan=drive.plan, t0_ns=drive.t0_ns, seed=drive.seed,
        kidnap_ns=int(stamps[k]), skip_ns=skip * step,
    )  # fmt: skip


def truncate_drive(drive: Drive, duration_s: float) -> Drive:
    """The first ``duration_s`` seconds of ``drive`` (odometry, truth and camera stamps)."""
    end = drive.t0_ns + round(duration_s * S_NS)
    n = int(np.searchsorted(drive.stamps_ns, end, side="right"))
    return replace(
        drive,
        stamps_ns=drive.stamps_ns[:n],
        T_map_base=drive.T_map_base[:n],
        T_odom_base=drive.T_odom_base[:n],
        camera_stamps_ns=drive.camera_stamps_ns[drive.camera_stamps_ns <= drive.stamps_ns[n - 1]],
        distance_m=drive.distance_m[:n],
    )


class ScenarioSource:
    """A scenario as a :class:`~tagloc.messages.MessageSource` (the simulator's stream).

    Yields, in arrival order: the camera's ``CameraInfoMsg`` and the static ``base -> camera``
    transform at the start (and ``base -> lidar`` when the robot has a lidar), then per odometry
    stamp an ``OdometryMsg`` and a ``GroundTruthMsg``, per camera frame a ``TagDetectionsMsg``
    (before the odometry of the same stamp, as a bag's log-time order has it) and per lidar
    sweep a ``PointCloudMsg`` on ``topics.lidar`` (stamped at the sweep's start, delivered at its
    end: the time of its last point, ``last_point_ns()``, also the log time
    :class:`~tagloc.io.BagSink` gives it; simulated lazily as the stream is read:
    :mod:`tagloc.sim.lidar`); then the scenario's ``faults`` rewrite that stream.
    :attr:`frame_truth` holds what only the simulator knows (glints, tags truly in view).
    Camera frames are simulated as the stream is read, and only the recent frames' truth is
    kept (:class:`~tagloc.sim.frame_truth.FrameTruthMap`): memory does not grow with the drive.
    """

    def __init__(
        self, scenario: Scenario, topics: NodeTopics | None = None, lidar: bool = True
    ) -> None:
        """``lidar``: False leaves the sweeps out even when the robot has a lidar (a run that
        ignores them need not simulate them: 4 ms of CPU per sweep)."""
        self.scenario, self.t = scenario, topics or NodeTopics()
        drive = scenario.drive
        self.frame_truth = FrameTruthMap(scenario.camera_stamps_ns, self._observe)
        self.glints_injected = 0  # false detections streamed so far
        robot = scenario.world.robot
        self.camera = robot.camera.camera_model()
        self.T_base_cam = robot.camera.T_base_cam.T_base_cam()
        self.lidar: LidarSimulator | None = None
        if robot.lidar is not None and lidar:
            self.lidar = lidar_for_drive(robot.lidar, scenario.world, scenario.people, drive)

    def _observe(self, stamps_ns: npt.NDArray[np.int64]) -> Iterator[ObservedFrame]:
        scenario = self.scenario
        return simulate_observations(
            scenario.drive, scenario.observation, stamps_ns=stamps_ns, world=scenario.world
        )

    @property
    def n_frames(self) -> int:
        """Camera frames the stream holds."""
        return len(self.scenario.camera_stamps_ns)

    @property
    def frames(self) -> list[ObservedFrame]:
        """Every camera frame of the drive, simulated again (the whole drive in memory)."""
        return list(self._observe(self.scenario.camera_stamps_ns))

    @property
    def topics(self) -> dict[str, type[Message]]:
        """Stream topic -> record type."""
        t = self.t
        topics: dict[str, type[Message]] = {
            t.odom: OdometryMsg, t.truth: GroundTruthMsg, t.detections: TagDetectionsMsg,
            t.camera_info: CameraInfoMsg, TF_STATIC: TransformMsg,
        }  # fmt: skip
        if self.lidar is not None:
            topics[t.lidar] = PointCloudMsg
        if self.scenario.elevator_topic:
            topics[t.elevator] = ElevatorStateMsg
        return topics

    def __iter__(self) -> Iterator[tuple[str, Message]]:
        t0 = int(self.scenario.drive.stamps_ns[0])
        return apply_faults(self._clean(), self.scenario.faults, t0)

    def _clean(self) -> Iterator[tuple[str, Message]]:
        drive, t = self.scenario.drive, self.t
        t0 = int(drive.stamps_ns[0])
        yield t.camera_info, CameraInfoMsg(t0, CAMERA_FRAME, self.camera.to_camera_info())
        yield TF_STATIC, TransformMsg(t0, BASE_FRAME, CAMERA_FRAME, self.T_base_cam, static=True)
        self.glints_injected = 0
        sweeps: Iterator[Sweep] = iter(())
        if self.lidar is not None:
            T_base_lidar = self.lidar.T_base_lidar
            yield TF_STATIC, TransformMsg(t0, BASE_FRAME, LIDAR_FRAME, T_base_lidar, static=True)
            starts = self.lidar.sweep_starts_ns(t0, int(drive.stamps_ns[-1]))
            sweeps = self.lidar.sweeps(lambda st: drive.ground_truth_at(st).xy_yaw_map_base, starts)
        sweep = next(sweeps, None)
        frames = self._observe(self.scenario.camera_stamps_ns)
        frame = next(frames, None)
        building = iter(elevator_messages(drive) if self.scenario.elevator_topic else ())
        state = next(building, None)
        for i, stamp in enumerate(drive.stamps_ns.tolist()):
            while state is not None and state.stamp_ns <= stamp:  # the building's elevators
                yield t.elevator, state
                state = next(building, None)
            # frames arrive at their stamp, sweeps when complete, before the odometry of a stamp
            while True:
                t_frame = frame.stamp_ns if frame is not None else stamp + 1
                t_sweep = sweep.msg.last_point_ns() if sweep is not None else stamp + 1
                if min(t_frame, t_sweep) > stamp:
                    break
                if t_frame <= t_sweep:
                    assert frame is not None
                    self.frame_truth.record(frame)
                    self.glints_injected += sum(frame.false_detection)
                    yield (
                        t.detections,
                        TagDetectionsMsg(frame.stamp_ns, CAMERA_FRAME, frame.detections),
                    )
                    frame = next(frames, None)
                else:
                    assert sweep is not None
                    yield t.lidar, sweep.msg
                    sweep = next(sweeps, None)
            T = drive.T_odom_base[i]
            yield t.odom, OdometryMsg(stamp, ODOM_FRAME, BASE_FRAME, T, _ODOM_COV)
            yield t.truth, GroundTruthMsg(stamp, MAP_FRAME, drive.T_map_base[i])
