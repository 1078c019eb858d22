"""The lidar-aided survey on simulated drives: scan matching against the simulator's truth.

Short: the office with a 60 m route through two rooms and back (:func:`room_loop_world`).
Slow (``--runslow``): the built-in office survey (the demo's) and a loop corridor with a tag
every 12 m and 0.3 deg/m of odometry yaw drift.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from survey_worlds import room_loop_world, sparse_tag_world
from tagloc.eval.occupancy import occupancy_iou
from tagloc.geometry import SE3
from tagloc.mapping import MappingError, Survey, build_tag_map
from tagloc.mapping.config import MapBuildConfig
from tagloc.mapping.lidar_survey import prepare_lidar
from tagloc.mapping.observations import collect_observations
from tagloc.mapping.products import build_products
from tagloc.mapping.report import BuildReport
from tagloc.mapping.scan_factors import relative_errors
from tagloc.mapping.stream_survey import survey_from_messages
from tagloc.messages import OdometryMsg, PointCloudMsg, TagDetectionsMsg, TransformMsg
from tagloc.sim import Drive, ObservationConfig, World, load_default_world, simulate_drive
from tagloc.sim.survey import MapErrors, map_errors, sim_build_config, survey_and_anchors
from tagloc.sim.trajectory import se3_from_xy_yaw
from tagloc.tags.tagmap import TagMap


@cache
def _drive(world_name: str, seed: int) -> Drive:
    world = {"rooms": room_loop_world, "office": load_default_world,
             "sparse": sparse_tag_world}[world_name]()  # fmt: skip
    return simulate_drive(world, seed=seed)


@cache
def _survey(world_name: str, seed: int, lidar: bool, stride: int = 3) -> tuple[Survey, dict]:
    return survey_and_anchors(_drive(world_name, seed), ObservationConfig(seed=seed), None,
                              stride, lidar)  # fmt: skip


@cache
def _built(world_name: str, seed: int, lidar: bool) -> tuple[TagMap, BuildReport, MapErrors]:
    drive = _drive(world_name, seed)
    survey, anchors = _survey(world_name, seed, lidar)
    config = sim_build_config(drive, ObservationConfig(seed=seed))
    tag_map, report = build_tag_map(survey, anchors, config)
    return tag_map, report, map_errors(tag_map, drive.world)


def _truth(drive: Drive, stamps_ns: np.ndarray) -> np.ndarray:
    xy_yaw = np.asarray(drive.ground_truth_at(stamps_ns).xy_yaw_map_base)
    return np.asarray(se3_from_xy_yaw(xy_yaw).as_matrix())
