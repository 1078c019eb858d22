"""Simulation: world files, ground-truth trajectories, odometry drift models, drives and the
lidar.

>>> from tagloc.sim import load_default_world, simulate_drive
>>> drive = simulate_drive(load_default_world(), seed=1)  # doctest: +SKIP
"""

from tagloc.sim.drive import Drive, simulate_drive
from tagloc.sim.lidar import LidarSimulator, Sweep, premap_from_world
from tagloc.sim.observations import (
    ObservationConfig,
    ObservedFrame,
    TagSighting,
    simulate_observations,
)
from tagloc.sim.odometry import (
    ODOMETRY_MODELS,
    DriftParameters,
    LeggedOdometryConfig,
    WheelOdometryConfig,
    simulate_odometry,
)
from tagloc.sim.people import Person, RandomWalk
from tagloc.sim.render import RenderedFrame, TagTruth, render_frames, render_tags_scene, render_view
from tagloc.sim.render_config import RenderConfig
from tagloc.sim.robot import LidarConfig, LidarMount
from tagloc.sim.route import RouteConfig
from tagloc.sim.trajectory import (
    RoutePlan,
    Trajectory,
    generate_trajectory,
    plan_from_config,
    plan_route,
)
from tagloc.sim.world import (
    BUILTIN_WORLDS,
    Tag,
    World,
    load_builtin_world,
    load_default_world,
    load_world,
)

__all__ = [
    "BUILTIN_WORLDS",
    "ODOMETRY_MODELS",
    "DriftParameters",
    "Drive",
    "LeggedOdometryConfig",
    "LidarConfig",
    "LidarMount",
    "LidarSimulator",
    "ObservationConfig",
    "ObservedFrame",
    "Person",
    "RandomWalk",
    "RenderConfig",
    "RenderedFrame",
    "RouteConfig",
    "RoutePlan",
    "Sweep",
    "Tag",
    "TagSighting",
    "TagTruth",
    "Trajectory",
    "WheelOdometryConfig",
    "World",
    "generate_trajectory",
    "load_builtin_world",
    "load_default_world",
    "load_world",
    "plan_from_config",
    "plan_route",
    "premap_from_world",
    "render_frames",
    "render_tags_scene",
    "render_view",
    "simulate_drive",
    "simulate_observations",
    "simulate_odometry",
]
