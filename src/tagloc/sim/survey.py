"""Surveys from the simulator, and the map-from-a-drive entry point the demo calls.

>>> from tagloc.sim import load_default_world, simulate_drive
>>> drive = simulate_drive(load_default_world(), seed=1)              # doctest: +SKIP
>>> tag_map, report = build_map_from_drive(drive)                       # doctest: +SKIP
>>> map_errors(tag_map, drive.world)                                    # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.frames import OdometryFrameConfig
from tagloc.geometry import SE3
from tagloc.mapping.builder import ProgressFn, build_tag_map
from tagloc.mapping.config import MapBuildConfig, OdometryNoise
from tagloc.mapping.exclude import Exclusion, exclude_observations
from tagloc.mapping.report import BuildReport
from tagloc.mapping.survey import CameraFrame, MappingError, Survey
from tagloc.sim.drive import Drive
from tagloc.sim.observations import ObservationConfig, ObservedFrame, simulate_observations
from tagloc.sim.odometry import DriftParameters, LeggedOdometryConfig, WheelOdometryConfig
from tagloc.sim.world import World
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.tagmap import TagMap

CAMERA = "cam0"


def odometry_noise_of(odometry: WheelOdometryConfig | LeggedOdometryConfig) -> OdometryNoise:
    """The builder's odometry noise matching a simulated drift model's random part.

    The simulator's random walk (:mod:`tagloc.sim.odometry`) has, per metre ``d`` and radian
    ``a`` travelled, variances ``sigma_xy^2 d`` on x and y and ``sigma_yaw^2 d +
    sigma_yaw_turn^2 a`` on yaw; foot slips (a Poisson rate per metre) add their variance per
    metre. Its systematic part (scales, biases, crab drift) is left to the calibration.
    """
    p = DriftParameters.from_config(odometry)
    return OdometryNoise(
        translation_var_per_m=p.sigma_xy_per_sqrt_m**2 + p.slip_rate_per_m * p.slip_sigma_xy_m**2,
        translation_var_per_rad=0.0,
        rotation_var_per_m=p.sigma_yaw_per_sqrt_m**2 + p.slip_rate_per_m * p.slip_sigma_yaw**2,
        rotation_var_per_rad=p.sigma_yaw_per_sqrt_rad**2,
    )


def sim_build_config(
    drive: Drive, observation_config: ObservationConfig | None, gravity_aligned: bool = False
) -> MapBuildConfig:
    """The map-build configuration that matches a simulated drive's noise.

    Odometry noise from :func:`odometry_noise_of`, corner noise from the observation config;
    the odometry's systematic errors calibrated jointly with the map (one alternation round to
    start); Huber(3) odometry factors, for the legged model's foot slips (12 simulated drives:
    7.59 cm tag RMS, Gaussian 7.66 cm).

    ``gravity_aligned``: the simulated odometry is level, so roll and pitch priors from it
    (``MapBuildConfig.odometry_frame``) are truthful.
    The simulated odometry is planar, its z axis up, as a real robot's IMU-aided odometry is
    gravity-aligned. With one anchor, nothing else fixes the map's tilt: the anchor tag's own
    tilt is poorly observed (a small tag seen face-on), and a lidar-aided survey of the loop
    corridor (seed 2) settled 0.4 rad off level about its one anchor without them (13 m tag
    RMS, 2.9 cm after a rigid alignment), 4.6 cm with them.
    """
    sigma_px = (observation_config or ObservationConfig()).pixel_sigma_px
    return MapBuildConfig(
        odometry=odometry_noise_of(drive.world.robot.odometry),
        pnp_noise=NoiseModel(sigma_px=max(sigma_px, 0.05)),
        calibration_rounds=1,
        joint_calibration=True,
        odometry_robust_k=3.0,
        odometry_frame=OdometryFrameConfig(gravity_aligned=gravity_aligned),
    )


def survey_from_drive(
    drive: Drive,
    observation_config: ObservationConfig | None = None,
    camera_stride: int = 1,
    lidar: bool = False,
) -> Survey:
    """The survey of a simulated drive: its drifting odometry and simulated detections.

    Parameters
    ----------
    drive : Drive
    observation_config : ObservationConfig, optional
        How the simulated detector sees tags (noise, glints).
    camera_stride : int
        Use every ``camera_stride``-th camera frame (1: all, at the robot's camera rate).
    lidar : bool
        Also simulate the lidar sweeps a survey keeps (:mod:`tagloc.sim.survey_lidar`).
    """
    return _survey(drive, _observed(drive, observation_config, camera_stride), lidar)


def _observed(
    drive: Drive, observation_config: ObservationConfig | None, camera_stride: int
) -> list[ObservedFrame]:
    stamps = drive.camera_stamps_ns[:: max(1, camera_stride)]
    frames = simulate_observations(drive, observation_config, stamps_ns=stamps)
    return [f for f in frames if f.detections]


def _survey(drive: Drive, observed: list[ObservedFrame], lidar: bool = False) -> Survey:
    from tagloc.sim.survey_lidar import survey_scans_of

    world = drive.world
    frames = tuple(CameraFrame(f.stamp_ns, CAMERA, f.detections) for f in observed)
    return Survey(
        odom_stamps_ns=drive.stamps_ns,
        T_odom_base=drive.T_odom_base,
        frames=frames,
        cameras={CAMERA: world.robot.camera.camera_model()},
        T_base_cam={CAMERA: world.robot.camera.T_base_cam.T_base_cam()},
        tag_sizes={(tag.family, tag.id): tag.size for tag in world.tags},
        source=f"simulated drive of {world.name or 'world'} (seed {drive.seed})",
        lidar=survey_scans_of(drive) if lidar else None,
    )


def build_map_from_drive(
    drive: Drive,
    observation_config: ObservationConfig | None = None,
    anchors: Sequence[int] | None = None,
    config: MapBuildConfig | None = None,
    camera_stride: int = 1,
    progress: ProgressFn | None = None,
    exclusions: Sequence[Exclusion] = (),
    lidar: bool = False,
) -> tuple[TagMap, BuildReport]:
    """Map the tags of a simulated drive (the demo's entry point).

    Parameters
    ----------
    drive : Drive
        From :func:`tagloc.sim.simulate_drive`.
    observation_config : ObservationConfig, optional
    anchors : sequence of int, optional
        Tag ids (tag36h11) whose true pose is given as surveyed; default: the first tag truly
        detected.
    config : MapBuildConfig, optional
        Default: :func:`sim_build_config` (noise models matching the simulation).
    camera_stride : int
        Use every n-th camera frame.
    progress : callable, optional
        See :func:`tagloc.mapping.build_tag_map`.
    exclusions : sequence of Exclusion
        Observations left out (:func:`tagloc.mapping.exclude.exclude_observations`).
    lidar : bool
        Survey with the lidar too: scan-matching factors (:mod:`tagloc.mapping.lidar_survey`).
        To keep the survey (its sweeps make the premap and the occupancy grid), call
        :func:`survey_and_anchors` and :func:`tagloc.mapping.build_tag_map` instead.

    Raises
    ------
    MappingError
        No anchors are given and the drive detects no tag (a world without tags, or none along
        the route).
    """
    survey, T_map_anchor = survey_and_anchors(
        drive, observation_config, anchors, camera_stride, lidar, exclusions
    )
    config = config or sim_build_config(drive, observation_config)
    return build_tag_map(survey, T_map_anchor, config, progress)


def survey_and_anchors(
    drive: Drive,
    observation_config: ObservationConfig | None = None,
    anchors: Sequence[int] | None = None,
    camera_stride: int = 1,
    lidar: bool = False,
    exclusions: Sequence[Exclusion] = (),
) -> tuple[Survey, dict[int, SE3]]:
    """The survey of a simulated drive and its anchors' true poses (arguments and errors as
    :func:`build_map_from_drive`)."""
    observed = _observed(drive, observation_config, camera_stride)
    survey = exclude_observations(_survey(drive, observed, lidar), exclusions)
    world = drive.world
    if anchors is None:  # the first tag truly detected (not an injected glint)
        first = next((s.tag_id for f in observed for s in f.truth if s.detected), None)
        if first is None:
            raise MappingError(
                f"the simulated drive of world {world.name or '(unnamed)'} detects no tag "
                f"({len(world.tags)} tags in the world): nothing to map; add tags along the route "
                "(tagloc world coverage shows where the camera sees one)"
            )
        anchors = [first]
    return survey, {i: world.T_map_tag(world.find_tag(i)) for i in anchors}


@dataclass(frozen=True, slots=True)
class MapErrors:
    """A built map against the world's true tag poses."""

    tag_ids: tuple[int, ...]
    position_error_m: npt.NDArray[np.float64]
    rotation_error_deg: npt.NDArray[np.float64]
    aligned_position_error_m: npt.NDArray[np.float64]

    @property
    def position_rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.position_error_m**2)))

    @property
    def rotation_rms_deg(self) -> float:
        return float(np.sqrt(np.mean(self.rotation_error_deg**2)))

    @property
    def aligned_position_rms_m(self) -> float:
        """Position RMS after the best rigid alignment of the map to the truth: the map's shape
        error, without the error of the frame that one anchor tag's observations fix."""
        return float(np.sqrt(np.mean(self.aligned_position_error_m**2)))


def map_errors(tag_map: TagMap, world: World) -> MapErrors:
    """Per-tag position (m) and rotation (deg) error of ``tag_map`` against ``world``."""
    ids, pos, rot, p_map, p_true = [], [], [], [], []
    for entry in tag_map:
        T_true = world.T_map_tag(world.find_tag(entry.id, entry.family))
        delta = T_true.inverse() @ entry.T_frame_tag()
        ids.append(entry.id)
        pos.append(float(np.linalg.norm(entry.T_frame_tag().translation - T_true.translation)))
        rot.append(float(np.degrees(np.linalg.norm(delta.rotation.as_rotvec()))))
        p_map.append(entry.T_frame_tag().translation)
        p_true.append(T_true.translation)
    aligned = _rigid_fit_residuals(np.array(p_map), np.array(p_true))
    return MapErrors(tuple(ids), np.array(pos), np.array(rot), aligned)


def _rigid_fit_residuals(
    points_a: npt.NDArray[np.float64], points_b: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """``(N,)`` distances after the least-squares rotation and translation of ``a`` onto ``b``
    (Kabsch; K. S. Arun, T. S. Huang, S. D. Blostein, IEEE PAMI 9(5), 1987)."""
    if len(points_a) < 3:
        return np.zeros(len(points_a))
    ca, cb = points_a.mean(axis=0), points_b.mean(axis=0)
    U, _, Vt = np.linalg.svd((points_a - ca).T @ (points_b - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return np.asarray(np.linalg.norm((points_a - ca) @ R.T + cb - points_b, axis=1))
