"""A survey's sweeps, de-skewed with its odometry: the points the scan matching and the map
products use."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from tagloc.geometry import SE3
from tagloc.lidar import deskew, finite_points, voxel_downsample
from tagloc.mapping.initialize import inverse_h
from tagloc.mapping.lidar_config import LidarSurveyConfig
from tagloc.mapping.observations import interpolate_odometry
from tagloc.mapping.survey import Survey

FloatArray = npt.NDArray[np.float64]
S_NS = 1_000_000_000


def keyframe_points(
    survey: Survey, sweep: int, config: LidarSurveyConfig, velocity: FloatArray | None = None
) -> FloatArray:
    """Sweep ``sweep`` of ``survey.lidar`` de-skewed to its stamp with the odometry (or
    ``velocity``, see :func:`sweep_motion`), cut to ``max_range_m`` and downsampled to
    ``voxel_m / 2``; ``(N, 3)`` in the scanner frame."""
    points = deskewed_points(survey, sweep, config.deskew_window_s, velocity)
    dist = np.linalg.norm(points, axis=1)
    keep = dist <= config.max_range_m
    if config.min_height_m is not None:  # the floor left out (see LidarSurveyConfig)
        assert survey.lidar is not None
        z_base = survey.lidar.T_base_lidar.act(points)[:, 2]
        keep &= z_base >= config.min_height_m
    return voxel_downsample(points[keep], 0.5 * config.voxel_m)


def deskewed_points(
    survey: Survey, sweep: int, window_s: float, velocity: FloatArray | None = None
) -> FloatArray:
    """Sweep ``sweep`` de-skewed to its stamp with the survey's odometry (scanner frame), at the
    odometry's mean velocity over ``window_s`` around the sweep (:func:`sweep_motion`)."""
    scans = survey.lidar
    assert scans is not None
    offsets = scans.time_offset_s[sweep]
    if offsets is None:
        return finite_points(scans.points_lidar[sweep])
    period_s = float(np.nanmax(offsets)) if len(offsets) else 0.0
    motion = sweep_motion(survey, int(scans.stamps_ns[sweep]), period_s, window_s, velocity)
    return deskew(scans.points_lidar[sweep], offsets, motion)


def sweep_motion(
    survey: Survey,
    stamp_ns: int,
    period_s: float,
    window_s: float,
    velocity: FloatArray | None = None,
) -> Callable[[np.ndarray], SE3]:
    """``offsets (K,) -> T_lidar0_lidart``: constant body velocity, the odometry's mean over
    ``window_s`` centred on the sweep (clamped to the odometry's span); or, given, ``velocity``
    (``(6,)`` the scanner's own body velocity, tagloc order, per second: from the scan-matched
    poses, :func:`scan_velocity`).

    Why a mean: odometry's own noise is white at the sample rate (legged odometry's yaw random
    walk is 2.7 mrad over one 0.1 s sweep), and following it sample by sample de-skews the
    sweep with that error (simulated office: 3.7 mrad RMS yaw error per registration, against
    0.25 mrad with the true motion); the mean over 1 s leaves about a tenth of it.
    """
    scans = survey.lidar
    assert scans is not None
    E = scans.T_base_lidar
    t0, t1 = int(survey.odom_stamps_ns[0]), int(survey.odom_stamps_ns[-1])
    centre = stamp_ns + round(0.5 * period_s * S_NS)
    half = round(0.5 * window_s * S_NS)
    begin, end = max(t0, centre - half), min(t1, centre + half)
    T = interpolate_odometry(survey, np.array([begin, end], dtype=np.int64))
    twist = (T[0].inverse() @ T[1]).log() / max((end - begin) / S_NS, 1e-9)  # body, per s

    def motion(offsets_s: np.ndarray) -> SE3:
        t = np.asarray(offsets_s, dtype=np.float64)[:, None]
        if velocity is not None:
            return SE3.exp(t * velocity[None])
        return E.inverse() @ SE3.exp(t * twist[None]) @ E

    return motion


def scan_velocity(M_scan: FloatArray, stamps_s: FloatArray) -> FloatArray:
    """``(L, 6)`` the scanner's body velocity at each of ``L`` poses ``M_scan`` (``(L, 4, 4)``,
    scan-matched, at ``stamps_s``), from the poses either side (one-sided at the ends)."""
    n = len(M_scan)
    before, after = np.maximum(np.arange(n) - 1, 0), np.minimum(np.arange(n) + 1, n - 1)
    dt = np.maximum(stamps_s[after] - stamps_s[before], 1e-3)[:, None]
    step = SE3.from_matrix(inverse_h(M_scan[before]) @ M_scan[after], normalize=True).log()
    return np.asarray(step / dt, dtype=np.float64)


#: Yaw (rad) between consecutive keyframes below which the robot goes straight (3 deg).
STEADY_TURN_RAD = 0.05


def steady_keyframes(M: FloatArray) -> npt.NDArray[np.bool_]:
    """``(L,)`` keyframes whose four steps around them (two either side) turn less than
    :data:`STEADY_TURN_RAD` each."""
    R = np.einsum("nji,njk->nik", M[:-1, :3, :3], M[1:, :3, :3])
    turn = np.abs(np.arctan2(R[:, 1, 0], R[:, 0, 0]))
    padded = np.concatenate([[np.inf, np.inf], turn, [np.inf, np.inf]])
    windows = np.lib.stride_tricks.sliding_window_view(padded, 4)[: len(M)]
    return np.asarray(windows.max(axis=1) < STEADY_TURN_RAD)
