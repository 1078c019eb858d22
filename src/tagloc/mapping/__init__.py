"""Offline tag-map building: a factor graph in GTSAM from a survey drive, with a QA report.

- :class:`Survey` (odometry + camera frames of detections + cameras + extrinsics + tag sizes)
  from the simulator (:func:`tagloc.sim.survey.survey_from_drive`) or a recorded stream
  (:func:`survey_from_messages`; :func:`survey_from_tagslam` with a tagSLAM rig's settings).
- :func:`build_tag_map` -> ``(TagMap, BuildReport)``; :mod:`tagloc.sim.survey` builds one
  from a simulated drive and measures it against the simulated world.
- :class:`MapBuildConfig`: the tunables (:class:`GravityConfig`: roll and pitch priors from a
  gravity-aligned odometry); :class:`Anchor`: a measured anchor with its sigmas;
  :func:`exclude_observations`: leave detections out before building again.
- With lidar sweeps in the survey (:class:`SurveyScans`): scan-matching factors
  (:mod:`tagloc.mapping.lidar_survey`, :mod:`tagloc.mapping.scan_factors`; tunables
  :class:`LidarSurveyConfig`) and the premap and occupancy grid at the optimized poses
  (:func:`tagloc.mapping.products.build_products`).

Errors are :class:`MappingError`.
"""

from tagloc.mapping.anchors import Anchor
from tagloc.mapping.builder import build_tag_map
from tagloc.mapping.config import GravityConfig, MapBuildConfig, OdometryNoise
from tagloc.mapping.exclude import Exclusion, exclude_observations
from tagloc.mapping.lidar_config import LidarSurveyConfig
from tagloc.mapping.report import BuildReport, TagQA
from tagloc.mapping.stream_survey import (
    RigConfig,
    corner_rotation_by_gravity,
    parse_camera_poses,
    parse_tagslam,
    survey_from_messages,
    survey_from_tagslam,
)
from tagloc.mapping.survey import CameraFrame, MappingError, Survey, only_cameras
from tagloc.mapping.survey_scans import SurveyScans

__all__ = [
    "Anchor",
    "BuildReport",
    "CameraFrame",
    "Exclusion",
    "GravityConfig",
    "LidarSurveyConfig",
    "MapBuildConfig",
    "MappingError",
    "OdometryNoise",
    "RigConfig",
    "Survey",
    "SurveyScans",
    "TagQA",
    "build_tag_map",
    "corner_rotation_by_gravity",
    "exclude_observations",
    "only_cameras",
    "parse_camera_poses",
    "parse_tagslam",
    "survey_from_messages",
    "survey_from_tagslam",
]
