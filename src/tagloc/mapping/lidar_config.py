"""Tunables of the lidar-aided survey (scan-matching factors and the survey's map products)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from tagloc.config import StrictModel


class LidarSurveyConfig(StrictModel):
    """How :mod:`tagloc.mapping.lidar_survey` turns a survey's sweeps into factors and maps.

    Attributes
    ----------
    enabled : bool
        Use the survey's lidar sweeps (False: tags and odometry only, as without a scanner).
    keyframe_distance_m, keyframe_turn_deg : float
        A sweep becomes a lidar keyframe (a pose variable of the graph) after this much travel
        or turn of the odometry since the last one.
    deskew_passes : int
        1: sweeps de-skewed with the odometry; 2: registered, then de-skewed again with the
        odometry's velocity corrected by the scan matching, and registered again
        (:func:`tagloc.mapping.lidar_survey.sequential_factors` says why).
    deskew_window_s : float
        Sweeps are de-skewed at the odometry's mean velocity over this window around them
        (:func:`tagloc.mapping.lidar_survey.sweep_motion` says why).
    voxel_m : float
        Voxel size the keyframe scans are downsampled to before registration.
    max_range_m : float
        Points farther from the scanner are dropped (sparse, and the farther the less precise).
    min_height_m : float or None
        Points lower than this above ``base`` (the floor) are left out of the registrations
        (default None: kept). Measured on the simulated loop corridor, the consecutive
        registrations overestimate each 0.75 m step by 2.4 mm and pitch by -2.5 mrad with the
        floor, by 3.1 mm and -3.0 mrad without it: the floor is not what biases them.
    local_map_m : float
        Each keyframe is registered onto a local map of the keyframes over this much travel
        before it (:mod:`tagloc.lidar.local_map`); a loop closure onto the keyframes within half
        of it around the earlier visit. Static check on noise-free 16-ring sweeps 0.75 m apart
        in a corridor (``tests/lidar/test_local_map.py``): the previous scan alone overestimates
        each step by 0.15-0.2 % with -2.7 mrad of pitch; a map of 15 m leaves < 0.1 % and 0.1
        mrad. 0 (with ``local_map_every`` 1): each scan onto the previous one alone.
    local_map_every : int
        The local map is rebuilt every this many keyframes (each rebuild costs a KD-tree and
        the covariances of some 20 000 points); the keyframes in between register onto it.
    max_correspondence_m : float
        Registration: largest point-to-point distance of a correspondence.
    min_inlier_fraction, max_rmse_m : float
        A registration is used only if at least this fraction of its source points found a
        correspondence and their RMS distance is below ``max_rmse_m``.
    loop_radius_m : float
        Loop-closure candidates: keyframes this close (horizontally) in the current estimate...
    loop_min_travel_m : float
        ... that the robot reached this far apart along its path (a loop, not a neighbour).
    loop_max_correction_m, loop_max_correction_deg : float
        A loop registration that moves this far from the estimate's relative pose is not used
        (it may have slid onto the next look-alike place: a corridor's doors and niches repeat).
    loops_per_keyframe : int
        At most this many loop closures from each keyframe (the nearest candidates).
    loop_stride : int
        Look for loops from every n-th keyframe (loops are redundant; each costs a registration).
    information_scale : float
        The registration's Hessian (sum over correspondences of ``J^T Omega J``, GICP's
        unit-free plane-to-plane weights) is scaled by this to be an information matrix
        (1/m^2, 1/rad^2); chosen so that the normalized errors of simulated registrations
        against the truth have unit RMS (see :mod:`tagloc.mapping.lidar_survey`).
    min_sigma_m, min_sigma_rad : float
        Floors on the standard deviations of a registration (what a flat Hessian claims is not
        believed: unmodelled scanner bias, de-skew error from odometry, moving people).
        Rotation 3 mrad: the de-skew's share (legged odometry's yaw noise over one sweep).
        Translation 2 cm, four times the residual-based sigma: the simulated registrations
        overestimate each 0.75 m step by 2.4 mm (0.3 %, a bias, so it does not average out);
        held loosely, the tags set the map's scale instead (office survey, one anchor, seeds
        1 and 2: 3.9 and 1.5 cm tag RMS at 5 mm, 2.4 and 2.4 cm at 2 cm, 2.6 cm (seed 1) at
        4 cm).
    min_sigma_tilt_rad : float
        The floor on roll and pitch (default: that of yaw). A level sweep's roll and pitch lean
        on the floor and on the rings' sampling of the walls: with 2 cm of range noise,
        registrations onto local maps still pitch each 0.75 m step of the simulated loop
        corridor by -0.5 mrad (-1.3 with the odometry's de-skew alone; 0.05 without noise). Raise
        it to leave the tilt to gravity priors. (10 mrad, without gravity priors, let one
        survey of the loop corridor settle 0.4 rad off level about its one anchor.)
    kernel : {"huber", "cauchy"}
    robust_k : float
        Robust kernel on every scan-matching factor, width in sigmas.
    """

    enabled: bool = True
    keyframe_distance_m: float = Field(0.75, ge=0.01, le=1e3)
    keyframe_turn_deg: float = Field(20.0, gt=0.0, le=360.0)
    deskew_window_s: float = Field(0.2, gt=0.0, le=10.0)
    deskew_passes: int = Field(2, ge=1, le=2)
    voxel_m: float = Field(0.15, ge=0.01, le=10.0)
    max_range_m: float = Field(20.0, gt=0.0, le=1e4)
    min_height_m: float | None = Field(None, ge=-1e3, le=1e3)
    local_map_m: float = Field(15.0, ge=0.0, le=1e3)
    local_map_every: int = Field(3, ge=1, le=1000)
    max_correspondence_m: float = Field(0.5, gt=0.0, le=100.0)
    min_inlier_fraction: float = Field(0.5, ge=0.0, le=1.0)
    max_rmse_m: float = Field(0.1, gt=0.0, le=10.0)
    loop_radius_m: float = Field(3.0, gt=0.0, le=1e3)
    loop_min_travel_m: float = Field(10.0, gt=0.0, le=1e6)
    loop_max_correction_m: float = Field(1.0, gt=0.0, le=1e3)
    loop_max_correction_deg: float = Field(10.0, gt=0.0, le=180.0)
    loops_per_keyframe: int = Field(1, ge=0, le=100)
    loop_stride: int = Field(2, ge=1, le=1_000_000)
    information_scale: float = Field(0.5, ge=1e-12, le=1e12)
    min_sigma_m: float = Field(0.02, ge=1e-6, le=10.0)
    min_sigma_rad: float = Field(0.003, ge=1e-6, le=3.2)
    min_sigma_tilt_rad: float = Field(0.003, ge=1e-6, le=3.2)
    kernel: Literal["huber", "cauchy"] = "cauchy"
    robust_k: float = Field(3.0, gt=0.0, le=100.0)
