"""Simulation: world files, ground-truth trajectories, odometry drift models and drives.

>>> from tagloc.sim import load_default_world, simulate_drive
>>> drive = simulate_drive(load_default_world(), seed=1)  # doctest: +SKIP
"""

from tagloc.sim.drive import Drive, simulate_drive
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
from tagloc.sim.render import RenderedFrame, TagTruth, render_frames, render_tags_scene, render_view
from tagloc.sim.render_config import RenderConfig
from tagloc.sim.route import RouteConfig
from tagloc.sim.trajectory import (
    RoutePlan,
    Trajectory,
    generate_trajectory,
    plan_from_config,
    plan_route,
)
from tagloc.sim.world import Tag, World, load_default_world, load_world

__all__ = [
    "ODOMETRY_MODELS",
    "DriftParameters",
    "Drive",
    "LeggedOdometryConfig",
    "ObservationConfig",
    "ObservedFrame",
    "RenderConfig",
    "RenderedFrame",
    "RouteConfig",
    "RoutePlan",
    "Tag",
    "TagSighting",
    "TagTruth",
    "Trajectory",
    "WheelOdometryConfig",
    "World",
    "generate_trajectory",
    "load_default_world",
    "load_world",
    "plan_from_config",
    "plan_route",
    "render_frames",
    "render_tags_scene",
    "render_view",
    "simulate_drive",
    "simulate_observations",
    "simulate_odometry",
]
