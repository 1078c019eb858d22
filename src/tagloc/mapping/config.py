"""Tunables of the map builder (pydantic; every field has a documented default)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, model_validator

from tagloc.config import StrictModel
from tagloc.frames import OdometryFrameConfig
from tagloc.mapping.lidar_config import LidarSurveyConfig
from tagloc.tags.covariance import NoiseModel


class OdometryNoise(StrictModel):
    """Noise of the odometry between two keyframes: a random walk in distance and rotation.

    Per axis, ``var = per_m * d + per_rad * a + floor^2`` with ``d`` the distance (m) and ``a``
    the rotation angle (rad) travelled between the keyframes: variance grows *linearly* with
    what was travelled, so the sum over a path does not depend on how finely it is keyframed.
    The standard deviations of ``z``, roll and pitch are scaled by ``vertical_factor``: robots
    on a floor (legged, wheeled) and visual-inertial odometry (gravity observable) drift in x, y
    and yaw, hardly in height, roll and pitch. The defaults (0.063 m/sqrt(m) in translation,
    0.02 rad/sqrt(m) in yaw) are loose: they also cover a few percent of uncalibrated drift, and
    they are what the dupont VIO map uses. Where the odometry's random walk is known, give it
    and calibrate the systematic part (``MapBuildConfig.joint_calibration``): the simulator's
    builder does (:func:`tagloc.sim.survey.odometry_noise_of`), and on 12 simulated
    legged drives that beat these defaults, 7.6 cm tag RMS against 9.8 cm.
    """

    translation_var_per_m: float = Field(4e-3, ge=0.0, le=1e3, description="m^2 per metre")
    translation_var_per_rad: float = Field(1e-4, ge=0.0, le=1e3, description="m^2 per radian")
    rotation_var_per_m: float = Field(4e-4, ge=0.0, le=1e3, description="rad^2 per metre")
    rotation_var_per_rad: float = Field(1e-4, ge=0.0, le=1e3, description="rad^2 per radian")
    vertical_factor: float = Field(
        0.1, gt=0.0, le=1.0, description="scales the z, roll and pitch sigmas"
    )
    translation_floor_m: float = Field(1e-4, ge=1e-8, le=10.0)
    rotation_floor_rad: float = Field(1e-4, ge=1e-8, le=3.2)


class GravityConfig(StrictModel):
    """Roll and pitch priors from a gravity-aligned odometry (:mod:`tagloc.mapping.gravity`).

    Whether the odometry is gravity-aligned, and which of its axes is up, is
    :attr:`MapBuildConfig.odometry_frame` (one definition with the localizer's).

    Attributes
    ----------
    priors : bool
        With a gravity-aligned odometry (visual-inertial: gravity is observable to it, so its
        roll and pitch do not drift), every keyframe's roll and pitch enter the graph as
        priors, and the map is level by physics, not by the anchors' orientation.
    sigma_deg : float
        Standard deviation of each keyframe's gravity direction, degrees (per keyframe,
        independent).
    """

    priors: bool = True
    sigma_deg: float = Field(1.0, ge=1e-3, le=45.0)

    @model_validator(mode="before")
    @classmethod
    def _moved(cls, data: Any) -> Any:
        if isinstance(data, dict) and "aligned_odometry" in data:
            raise ValueError(
                "aligned_odometry: moved to odometry_frame.gravity_aligned (one setting for the "
                "map builder and the localizer)"
            )
        return data


class MapBuildConfig(StrictModel):
    """How :func:`tagloc.mapping.build_tag_map` turns a survey into a tag map.

    Attributes
    ----------
    odometry : OdometryNoise
    pnp_noise : NoiseModel
        Pixel noise for the PnP pose factors' covariances (:mod:`tagloc.tags.covariance`).
    factors : {"corners", "pose"}
        The final optimization: corner reprojection factors (default; unbiased,
        :mod:`tagloc.mapping.corner_graph`) or stop at the PnP pose factors (faster; the PnP
        estimator's range bias stays in the map).
    observation_covariance : {"pixel", "pnp"}
        Covariance of each tag factor: ``"pixel"`` the Gauss-Newton bound of the corners' pixel
        noise at the chosen branch (:func:`tagloc.mapping.observations.pixel_covariance`);
        ``"pnp"`` the localizer's inflated one (valley towards the other branch, range terms).
    robust : {"huber", "cauchy"}
        Kernel on every tag factor; ``robust_k`` is its threshold in whitened units (sigmas).
    odometry_robust_k : float, optional
        Huber threshold on odometry factors (None: Gaussian). Huber, not Cauchy: a redescending
        kernel lets the trajectory tear where false detections pull. The dupont VIO has
        one-frame jumps of up to 0.25 m; its maps from the left and from the right camera alone
        disagree by (median, max) 182 mm, 399 mm with Huber(3) (27 outliers of 3,634), 101 mm,
        191 mm with Huber(10) (56 outliers), 101 mm, 182 mm Gaussian (73): Huber(3) bends the
        trajectory at every slightly off step. Default 10; the simulator's builder uses 3 (with
        the exact random-walk model, for the legged odometry's foot slips).
    max_range_m : float
        Observations of tags farther than this are not used (depth error grows ~ range^2).
    max_ambiguity_for_init : float
        Largest IPPE ambiguity ratio (best / other reprojection error) an observation may have to
        initialize a tag or re-seat a keyframe during initialization.
    outlier_sigma : float
        An observation whose whitened error after optimization exceeds this is reported as an
        outlier (the norm of its 8 whitened corner residuals; with ``factors="pose"``, the
        Mahalanobis norm of its 6-dof pose error).
    disagreeing_fraction : float
        A tag with at least 3 outliers making up more than this fraction of its observations is
        flagged in the report as moved or duplicated.
    anchor_sigma_m, anchor_sigma_rad : float
        Prior standard deviations on anchor tags that do not carry their own
        (:class:`tagloc.mapping.anchors.Anchor`: a measured anchor's survey sigma).
    odometry_frame : OdometryFrameConfig
        How the odometry relates to gravity and to the body (:mod:`tagloc.frames.odometry_frame`):
        "up" for the odometry noise (:mod:`tagloc.mapping.odometry_noise`) and, when
        gravity-aligned, the gravity priors. Default: an upright robot base, no gravity.
    gravity : GravityConfig
        Roll and pitch priors when the odometry is gravity-aligned.
    uncertainty_flag_m : float
        A tag whose marginal position sigma (the norm of its x, y, z sigmas) exceeds this is
        flagged in the QA report with advice (:mod:`tagloc.mapping.advice`). Default 5 cm.
    max_iterations : int
        Levenberg-Marquardt iterations per round of pose factors.
    corner_max_iterations : int
        Gauss-Newton rounds (re-linearizations) of the corner refinement
        (:mod:`tagloc.mapping.refine`; it converges in 3-6 on the simulated office).
    rounds : int
        Optimize, re-pick each observation's IPPE branch at the estimate, optimize again.
    calibration_rounds : int
        Then, this many times: fit the odometry's systematic errors (scale, crab drift, turn
        scale, yaw bias: :mod:`tagloc.mapping.calibration`) to the optimized trajectory,
        correct the odometry, optimize again. Default 0.
    joint_calibration : bool
        Estimate the same four numbers jointly with the map in the corner refinement
        (:mod:`tagloc.mapping.odometry_factors`), starting from the alternation's estimate.
        Simulated legged odometry (4 % scale, 1 % crab, 2 % turn scale): it recovers the scale
        to 0.2 % and the crab drift to 0.1 %, where 3 alternation rounds leave 0.4 % and 0.4-0.7 %
        (two drives); over 12 drives tag RMS 7.6 cm against 7.8 cm, and 7.5 cm with no
        systematic error at all.
        Default off: on the dupont VIO it made the left and right maps disagree more (median
        152 mm against 101 mm).
    calibration_sigma : float
        Standard deviation of the zero-mean prior on each calibration number (fractions for
        the scales, rad/m for the yaw bias).
    lidar : LidarSurveyConfig
        Scan-matching factors and map products of a survey with lidar sweeps.
    """

    odometry: OdometryNoise = OdometryNoise()
    pnp_noise: NoiseModel = NoiseModel()
    factors: Literal["corners", "pose"] = "corners"
    observation_covariance: Literal["pixel", "pnp"] = "pixel"
    robust: Literal["huber", "cauchy"] = "cauchy"
    robust_k: float = Field(3.0, gt=0.0, le=100.0)
    odometry_robust_k: float | None = Field(10.0, gt=0.0, le=1e3)
    max_range_m: float = Field(10.0, gt=0.0, le=1e3)
    max_ambiguity_for_init: float = Field(0.5, gt=0.0, le=1.0)
    outlier_sigma: float = Field(6.0, gt=0.0, le=1e3)
    disagreeing_fraction: float = Field(0.2, gt=0.0, le=1.0)
    anchor_sigma_m: float = Field(1e-4, ge=1e-8, le=10.0)
    anchor_sigma_rad: float = Field(1e-5, ge=1e-9, le=3.2)
    max_iterations: int = Field(100, ge=1, le=10_000)
    corner_max_iterations: int = Field(10, ge=1, le=1000)
    rounds: int = Field(2, ge=1, le=100)
    compute_covariance: bool = True
    calibration_rounds: int = Field(0, ge=0, le=100)
    joint_calibration: bool = False
    calibration_sigma: float = Field(0.1, ge=1e-9, le=10.0)
    odometry_frame: OdometryFrameConfig = OdometryFrameConfig()
    gravity: GravityConfig = GravityConfig()
    uncertainty_flag_m: float = Field(0.05, gt=0.0, le=1e3)
    lidar: LidarSurveyConfig = LidarSurveyConfig()
