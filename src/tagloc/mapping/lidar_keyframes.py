"""Lidar keyframes: pose variables of the graph at the sweeps the builder registers.

Why pose variables at the sweeps, and not the sweeps bridged to the camera keyframes by
odometry? The camera keyframes are the frames with tag detections; between tags there may be
none for many metres (a building with a tag every 12 m), and bridging a scan to the nearest
camera keyframe would put back exactly the odometry drift the scans are there to remove. So
every lidar keyframe (a sweep every :attr:`~tagloc.mapping.lidar_config.LidarSurveyConfig.
keyframe_distance_m` of travel) becomes a keyframe of the graph at its sweep's stamp; the
odometry factors chain all keyframes, camera and lidar, in time order, and a sweep sits exactly
on its variable (``T_map_lidar = x_k @ T_base_lidar``). A sweep at the same stamp as a camera
frame shares its keyframe.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from tagloc.geometry import SE3
from tagloc.mapping.observations import Observations, interpolate_odometry
from tagloc.mapping.survey import Survey
from tagloc.mapping.survey_scans import select_sweeps

IntArray = npt.NDArray[np.int64]


def choose_lidar_keyframes(
    survey: Survey, keyframe_distance_m: float, keyframe_turn_rad: float
) -> IntArray:
    """Indices into ``survey.lidar`` of the sweeps that become keyframes: those inside the
    odometry's span, one each ``keyframe_distance_m`` or ``keyframe_turn_rad`` of odometry."""
    assert survey.lidar is not None
    stamps = survey.lidar.stamps_ns
    inside = np.flatnonzero(
        (stamps >= survey.odom_stamps_ns[0]) & (stamps <= survey.odom_stamps_ns[-1])
    )
    if len(inside) == 0:
        return inside.astype(np.int64)
    T_odom_base = interpolate_odometry(survey, stamps[inside])
    yaw = _yaw(T_odom_base)
    picked = select_sweeps(
        np.asarray(T_odom_base.translation), yaw, keyframe_distance_m, keyframe_turn_rad
    )
    return np.asarray(inside[picked], dtype=np.int64)


def _yaw(T: SE3) -> npt.NDArray[np.float64]:
    R = T.rotation.as_matrix()
    return np.asarray(np.arctan2(R[..., 1, 0], R[..., 0, 0]), dtype=np.float64)


def with_keyframes(
    obs: Observations, survey: Survey, stamps_ns: IntArray
) -> tuple[Observations, IntArray]:
    """``obs`` with keyframes added at ``stamps_ns`` (inside the odometry's span).

    Returns the observations (keyframes sorted by stamp, observation indices remapped,
    odometry interpolated at every keyframe) and the keyframe index of each of ``stamps_ns``.
    """
    stamps = np.union1d(obs.keyframe_stamps_ns, np.asarray(stamps_ns, dtype=np.int64))
    old_to_new = np.searchsorted(stamps, obs.keyframe_stamps_ns)
    merged = replace(
        obs,
        keyframe_stamps_ns=stamps,
        T_odom_base=interpolate_odometry(survey, stamps),
        keyframe=np.asarray(old_to_new[obs.keyframe], dtype=np.int64),
    )
    return merged, np.asarray(np.searchsorted(stamps, stamps_ns), dtype=np.int64)
