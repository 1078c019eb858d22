"""What riding an elevator does to the robot's odometry.

The planar drift models of :mod:`tagloc.sim.odometry` see the feet (or wheels) and nothing else:
standing in a moving cab they see no motion (the planar increments are zero, so they add no
error), and they never observe z. So by default the odometry's z stays where it started
(``T_odom_base`` z = the true z of the first sample above the floor it starts on: a robot's
odometry starts at zero where it boots) through every ride: ``odom`` and ``map`` differ by the
start floor's height, and after a ride by the floor's.

An *IMU-fused* odometry (``robot.odometry.imu``, :class:`ImuFusionConfig`: a filter fusing the
kinematics with an inertial unit) feels the cab accelerate. Its model, with ``a_z`` the cab's
vertical acceleration:

- **z**: during a trip (the cab moving) the filter integrates the measured vertical acceleration
  ``a_z + b`` (a bias ``b ~ N(0, accel_bias_sigma_mps2^2)`` drawn once per drive); the kinematics'
  zero-velocity constraint pulls the fused vertical velocity back to zero with time constant
  ``tau = velocity_time_constant_s``: ``v' = (a_z + b) [in a trip] - v / tau``, ``z' = v``. A trip
  from rest to rest therefore gives a transient (the reported z rises and falls back, by at most
  ``tau`` times the cab's peak speed) and, once settled (a few ``tau`` after the trip), a z drift
  of exactly ``b T tau`` for a trip of ``T`` seconds.
- **tilt**: the attitude filter takes part of the vertical acceleration for a tilt: a pitch error
  ``theta' = (k a_z - theta) / tau_tilt`` (``k = tilt_deg_per_mps2``, ``tau_tilt =
  tilt_time_constant_s``), which fades once the cab stops accelerating.

Integration is exact for piecewise-constant input between odometry samples.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from pydantic import Field

from tagloc._types import FloatArray
from tagloc.config import StrictModel
from tagloc.geometry import SE3, SO3

__all__ = ["ImuFusionConfig", "imu_ride_effects", "ride_odometry"]


class ImuFusionConfig(StrictModel):
    """An IMU fused into the odometry (see the module docstring; units in the names)."""

    accel_bias_sigma_mps2: float = Field(default=0.03, ge=0.0, le=1.0)
    velocity_time_constant_s: float = Field(default=2.0, gt=0.0, le=100.0)
    tilt_deg_per_mps2: float = Field(default=1.5, ge=0.0, le=20.0)
    tilt_time_constant_s: float = Field(default=0.5, gt=0.0, le=100.0)


def imu_ride_effects(
    config: ImuFusionConfig,
    t_s: FloatArray,
    accel_z: FloatArray,
    in_trip: npt.NDArray[np.bool_],
    bias: float,
) -> tuple[FloatArray, FloatArray]:
    """``(z offset, pitch error in rad)`` at each sample (module docstring), both 0 at the start.

    Parameters
    ----------
    t_s : (N,) float
        Sample times, s.
    accel_z : (N,) float
        The true vertical acceleration, m/s^2 (held over each interval from its start sample).
    in_trip : (N,) bool
        Whether the cab moves over the interval starting at each sample.
    bias : float
        The accelerometer's vertical bias, m/s^2.
    """
    tau, tau_tilt = config.velocity_time_constant_s, config.tilt_time_constant_s
    k = math.radians(config.tilt_deg_per_mps2)
    n = len(t_s)
    z, pitch = np.zeros(n), np.zeros(n)
    v, zk, th = 0.0, 0.0, 0.0
    dts = np.diff(t_s)
    for i in range(n - 1):
        dt = float(dts[i])
        u = (float(accel_z[i]) + bias) if in_trip[i] else 0.0
        e = math.exp(-dt / tau)
        # exact for constant u: v(t) = u tau + (v0 - u tau) e^{-t/tau}
        zk += u * tau * dt + (v - u * tau) * tau * (1.0 - e)
        v = u * tau + (v - u * tau) * e
        target = k * float(accel_z[i]) if in_trip[i] else 0.0
        th = target + (th - target) * math.exp(-dt / tau_tilt)
        z[i + 1], pitch[i + 1] = zk, th
    return z, pitch


def ride_odometry(
    imu: ImuFusionConfig | None,
    T_odom_base: SE3,
    t_s: FloatArray,
    z_start: float,
    accel_z: FloatArray,
    in_trip: npt.NDArray[np.bool_],
    seed: int,
) -> SE3:
    """The planar odometry ``T_odom_base`` (N) at height ``z_start``, plus the IMU's ride
    effects when ``imu`` is set (its bias drawn from ``default_rng([seed, 1])``)."""
    translation = np.array(T_odom_base.translation, dtype=np.float64).reshape(-1, 3)
    translation[:, 2] = z_start
    rotation = T_odom_base.rotation
    if imu is not None:
        bias = float(np.random.default_rng([seed, 1]).normal(0.0, imu.accel_bias_sigma_mps2))
        dz, pitch = imu_ride_effects(imu, t_s, accel_z, in_trip, bias)
        translation[:, 2] += dz
        c, s = np.cos(pitch), np.sin(pitch)
        R_pitch = np.zeros((len(pitch), 3, 3))
        R_pitch[:, 0, 0], R_pitch[:, 0, 2], R_pitch[:, 1, 1] = c, s, 1.0
        R_pitch[:, 2, 0], R_pitch[:, 2, 2] = -s, c
        rotation = SO3.from_matrix(rotation.as_matrix() @ R_pitch)
    return SE3(rotation=rotation, translation=translation)
