"""Odometry drift models: corrupt the true relative motion step by step and integrate it.

Each step ``k`` of the ground truth gives a relative motion ``[dx, dy, dyaw]`` of ``base`` expressed
in the previous ``base`` frame (an SE(2) increment). A model corrupts it with errors that scale with
the distance travelled ``d = |(dx, dy)|`` (metres) and the angle turned ``|dyaw|`` (radians), never
with time, so the simulated drift does not depend on the odometry rate:

- systematic: distance scale ``dx, dy *= 1 + scale_error``; turn scale
  ``dyaw *= 1 + yaw_scale_error``; yaw bias ``dyaw += yaw_bias * d``; lateral (crab) drift
  ``dy += lateral_drift * d``;
- random walk (white noise per step with variance proportional to ``d`` or ``|dyaw|``): ``dx, dy``
  get ``N(0, sigma_xy^2 d)``; ``dyaw`` gets ``N(0, sigma_yaw^2 d + sigma_yaw_turn^2 |dyaw|)``;
- foot slips (legged): a Poisson number of events per metre, each adding ``N(0, slip_xy^2)`` to
  ``dx`` and ``dy`` and ``N(0, slip_yaw^2)`` to ``dyaw``.

The corrupted increments are composed, ``T_odom_base[k] = T_odom_base[k-1] @ Delta'_k``, from
``T_odom_base[0] = T_map_base[0]`` (``odom`` coincides with ``map`` at the start), so the errors
accumulate as in real dead reckoning. Reference magnitudes (indoor, decent tuning): wheels drift
1-5 % of distance with heading error dominating; legged kinematic odometry several % plus yaw drift,
with foot slip (see the reference notes, section 3, "Odometry sources").
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from tagloc._types import FloatArray
from tagloc.config import StrictModel
from tagloc.geometry import SE3
from tagloc.sim.odometry_ride import ImuFusionConfig
from tagloc.sim.trajectory import se3_from_xy_yaw


class _DriftConfig(StrictModel):
    """Fields shared by every model. Units in the field names: fractions, deg, m."""

    seed: int = Field(default=0, ge=0)
    scale_error: float = Field(default=0.01, gt=-0.5, lt=0.5)
    yaw_scale_error: float = Field(default=0.005, gt=-0.5, lt=0.5)
    yaw_bias_deg_per_m: float = Field(default=0.02, ge=-10.0, le=10.0)
    sigma_xy_per_sqrt_m: float = Field(default=0.005, ge=0.0, le=1.0)
    sigma_yaw_deg_per_sqrt_m: float = Field(default=0.1, ge=0.0, le=20.0)
    sigma_yaw_deg_per_sqrt_rad: float = Field(default=0.3, ge=0.0, le=20.0)
    #: An IMU fused into the odometry: what it makes of an elevator ride
    #: (:mod:`tagloc.sim.odometry_ride`); None: the kinematics alone (no motion in a ride).
    imu: ImuFusionConfig | None = None


class WheelOdometryConfig(_DriftConfig):
    """Wheel-encoder odometry: 1 % scale, 0.05 deg/m yaw bias, small random walk (defaults)."""

    model: Literal["wheel"]


class LeggedOdometryConfig(_DriftConfig):
    """Legged kinematic odometry: larger errors, lateral drift and foot slips (defaults)."""

    model: Literal["legged"]
    scale_error: float = Field(default=0.04, gt=-0.5, lt=0.5)
    yaw_scale_error: float = Field(default=0.02, gt=-0.5, lt=0.5)
    yaw_bias_deg_per_m: float = Field(default=0.05, ge=-10.0, le=10.0)
    sigma_xy_per_sqrt_m: float = Field(default=0.02, ge=0.0, le=1.0)
    sigma_yaw_deg_per_sqrt_m: float = Field(default=0.7, ge=0.0, le=20.0)
    sigma_yaw_deg_per_sqrt_rad: float = Field(default=1.0, ge=0.0, le=20.0)
    lateral_drift: float = Field(default=0.01, gt=-0.5, lt=0.5)
    slip_rate_per_m: float = Field(default=0.05, ge=0.0, le=10.0)
    slip_sigma_xy_m: float = Field(default=0.03, ge=0.0, le=1.0)
    slip_sigma_yaw_deg: float = Field(default=2.0, ge=0.0, le=45.0)


#: The odometry models a world file may name (``robot.odometry.model``).
OdometryConfig = Annotated[WheelOdometryConfig | LeggedOdometryConfig, Field(discriminator="model")]
ODOMETRY_MODELS: dict[str, type[_DriftConfig]] = {
    "wheel": WheelOdometryConfig,
    "legged": LeggedOdometryConfig,
}


class DriftParameters(StrictModel):
    """Drift model parameters in SI units (radians); see the module docstring for the model.

    A wheel model is the special case ``lateral_drift = slip_rate_per_m = 0``. Built from a
    world file's section by :meth:`from_config`; every value is finite.
    """

    scale_error: float = 0.0
    yaw_scale_error: float = 0.0
    yaw_bias_per_m: float = 0.0
    sigma_xy_per_sqrt_m: float = 0.0
    sigma_yaw_per_sqrt_m: float = 0.0
    sigma_yaw_per_sqrt_rad: float = 0.0
    lateral_drift: float = 0.0
    slip_rate_per_m: float = 0.0
    slip_sigma_xy_m: float = 0.0
    slip_sigma_yaw: float = 0.0

    @classmethod
    def from_config(cls, config: WheelOdometryConfig | LeggedOdometryConfig) -> DriftParameters:
        """Unpack a world-file odometry section (degrees to radians)."""
        extra: dict[str, float] = {}
        if isinstance(config, LeggedOdometryConfig):
            extra = {
                "lateral_drift": config.lateral_drift,
                "slip_rate_per_m": config.slip_rate_per_m,
                "slip_sigma_xy_m": config.slip_sigma_xy_m,
                "slip_sigma_yaw": math.radians(config.slip_sigma_yaw_deg),
            }
        return cls(
            **extra,
            scale_error=config.scale_error,
            yaw_scale_error=config.yaw_scale_error,
            yaw_bias_per_m=math.radians(config.yaw_bias_deg_per_m),
            sigma_xy_per_sqrt_m=config.sigma_xy_per_sqrt_m,
            sigma_yaw_per_sqrt_m=math.radians(config.sigma_yaw_deg_per_sqrt_m),
            sigma_yaw_per_sqrt_rad=math.radians(config.sigma_yaw_deg_per_sqrt_rad),
        )


def relative_motion(xy_yaw: FloatArray) -> FloatArray:
    """Increments between consecutive planar poses, each in the earlier ``base`` frame.

    Parameters
    ----------
    xy_yaw : (N, 3) float
        ``[x, y, yaw]`` of ``base`` in a fixed frame.

    Returns
    -------
    (N - 1, 3) float
        ``[dx, dy, dyaw]`` with ``dyaw`` wrapped to ``[-pi, pi)``: the SE(2) ``T_{k-1}^-1 T_k``.
    """
    d_xy = np.diff(xy_yaw[:, :2], axis=0)
    c, s = np.cos(xy_yaw[:-1, 2]), np.sin(xy_yaw[:-1, 2])
    d_yaw = (np.diff(xy_yaw[:, 2]) + np.pi) % (2 * np.pi) - np.pi
    return np.column_stack(
        [c * d_xy[:, 0] + s * d_xy[:, 1], -s * d_xy[:, 0] + c * d_xy[:, 1], d_yaw]
    )


def integrate_motion(start_xy_yaw: FloatArray, delta: FloatArray) -> FloatArray:
    """Compose increments from a start pose: the inverse of :func:`relative_motion`.

    Parameters
    ----------
    start_xy_yaw : (3,) float
    delta : (N - 1, 3) float
        ``[dx, dy, dyaw]`` in the previous ``base`` frame.

    Returns
    -------
    (N, 3) float
        ``[x, y, yaw]`` (yaw unwrapped).
    """
    yaw = start_xy_yaw[2] + np.concatenate([[0.0], np.cumsum(delta[:, 2])])
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    step_x = c * delta[:, 0] - s * delta[:, 1]
    step_y = s * delta[:, 0] + c * delta[:, 1]
    x = start_xy_yaw[0] + np.concatenate([[0.0], np.cumsum(step_x)])
    y = start_xy_yaw[1] + np.concatenate([[0.0], np.cumsum(step_y)])
    return np.column_stack([x, y, yaw])


def corrupt_motion(
    delta: FloatArray, params: DriftParameters, rng: np.random.Generator
) -> FloatArray:
    """Apply the drift model to true increments (see the module docstring).

    Parameters
    ----------
    delta : (M, 3) float
        True ``[dx, dy, dyaw]`` per step, in the previous ``base`` frame.
    params : DriftParameters
    rng : numpy.random.Generator
        Consumed in a fixed order (one ``(M, 4)`` normal block, then Poisson counts and one
        ``(M, 3)`` block when slips are enabled), so a seed fixes the result.

    Returns
    -------
    (M, 3) float
        Measured increments. All-zero parameters return ``delta`` unchanged.
    """
    p = params
    dist = np.hypot(delta[:, 0], delta[:, 1])
    turn = np.abs(delta[:, 2])
    noise = rng.standard_normal((len(delta), 4))
    sqrt_d = np.sqrt(dist)
    out = np.empty_like(delta)
    out[:, :2] = (
        delta[:, :2] * (1.0 + p.scale_error)
        + p.sigma_xy_per_sqrt_m * sqrt_d[:, None] * noise[:, :2]
    )
    out[:, 1] += p.lateral_drift * dist
    out[:, 2] = (
        delta[:, 2] * (1.0 + p.yaw_scale_error)
        + p.yaw_bias_per_m * dist
        + p.sigma_yaw_per_sqrt_m * sqrt_d * noise[:, 2]
        + p.sigma_yaw_per_sqrt_rad * np.sqrt(turn) * noise[:, 3]
    )
    if p.slip_rate_per_m > 0:
        slips = np.sqrt(rng.poisson(p.slip_rate_per_m * dist).astype(np.float64))
        jumps = rng.standard_normal((len(delta), 3)) * slips[:, None]
        out[:, :2] += p.slip_sigma_xy_m * jumps[:, :2]
        out[:, 2] += p.slip_sigma_yaw * jumps[:, 2]
    return out


def simulate_odometry_xy_yaw(
    xy_yaw_map_base: FloatArray, params: DriftParameters, rng: np.random.Generator
) -> FloatArray:
    """Drifting odometry ``[x, y, yaw]`` of ``base`` in ``odom`` at the ground-truth samples.

    Parameters
    ----------
    xy_yaw_map_base : (N, 3) float
        Ground truth in ``map``.

    Returns
    -------
    (N, 3) float
        ``xy_yaw_odom_base``; row 0 equals the ground truth (``odom`` = ``map`` at the start).
    """
    delta = corrupt_motion(relative_motion(xy_yaw_map_base), params, rng)
    return integrate_motion(xy_yaw_map_base[0], delta)


def simulate_odometry(
    config: WheelOdometryConfig | LeggedOdometryConfig,
    xy_yaw_map_base: FloatArray,
    seed: int | None = None,
) -> SE3:
    """``T_odom_base`` (SE3 batch of N) for a ground-truth drive, from a world-file odometry config.

    Parameters
    ----------
    config : WheelOdometryConfig or LeggedOdometryConfig
    xy_yaw_map_base : (N, 3) float
        Ground truth ``[x, y, yaw]`` of ``base`` in ``map``.
    seed : int, optional
        Overrides ``config.seed`` for ``numpy.random.default_rng``.
    """
    rng = np.random.default_rng(config.seed if seed is None else seed)
    params = DriftParameters.from_config(config)
    return se3_from_xy_yaw(simulate_odometry_xy_yaw(xy_yaw_map_base, params, rng))
