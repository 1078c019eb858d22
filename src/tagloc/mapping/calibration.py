"""Odometry self-calibration: systematic errors estimated from the optimized trajectory.

Odometry errors are partly systematic: a random-walk noise model cannot remove them, and around
a closed loop a pure scale error even cancels, so loop closures do not reveal it. Where tags pin
the keyframes, the optimized trajectory shows it. The model, per odometry step between
keyframes (in the earlier keyframe's ``base`` frame, ``t`` its translation, ``d = |t|``, ``yaw``
its rotation about z), is the physical one of wheeled and legged odometry:

- translation: ``t' = (1 + scale) t + lateral_per_m d y_hat`` (distance scale; crab drift to the
  left per metre walked);
- yaw: ``yaw' = (1 + turn_scale) yaw + yaw_bias_per_m d`` (turn scale; heading bias per metre).

Four numbers, the vector :func:`calibration_vector`. (A general 3x3 matrix on ``t``, as before,
has two more numbers, lateral scale and axis coupling, that a robot walking forward hardly
excites: jointly estimated they absorbed the random walk, up to 15 % lateral scale on the
simulated legged odometry, and cost 1.3 cm of tag RMS.)

:func:`fit_calibration` fits them by least squares to an optimized trajectory; the builder
alternates that with the pose-factor rounds (``MapBuildConfig.calibration_rounds``) and can then
estimate them jointly with the map (``MapBuildConfig.joint_calibration``,
:mod:`tagloc.mapping.odometry_factors`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import inverse_h

#: Length of :func:`calibration_vector`.
N_CALIBRATION = 4


@dataclass(frozen=True, slots=True)
class OdometryCalibration:
    """Corrections of an odometry step (module docstring): fractions, and rad/m for the bias."""

    scale: float
    lateral_per_m: float
    turn_scale: float
    yaw_bias_per_m: float

    @staticmethod
    def identity() -> OdometryCalibration:
        return OdometryCalibration(0.0, 0.0, 0.0, 0.0)


def calibration_vector(cal: OdometryCalibration) -> FloatArray:
    """``(4,)`` ``[scale, lateral_per_m, turn_scale, yaw_bias_per_m]``."""
    return np.array([cal.scale, cal.lateral_per_m, cal.turn_scale, cal.yaw_bias_per_m])


def calibration_from_vector(c: npt.ArrayLike) -> OdometryCalibration:
    """Inverse of :func:`calibration_vector`."""
    scale, lateral, turn, bias = (float(x) for x in np.asarray(c, dtype=np.float64))
    return OdometryCalibration(scale, lateral, turn, bias)


def _yaw(R: FloatArray) -> FloatArray:
    return np.asarray(np.arctan2(R[..., 1, 0], R[..., 0, 0]))


def _rot_z(angle: FloatArray) -> FloatArray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((*np.shape(angle), 3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def fit_calibration(M_odom_base: FloatArray, M_map_base: FloatArray) -> OdometryCalibration:
    """Least-squares calibration of raw odometry steps against optimized ones.

    Parameters
    ----------
    M_odom_base, M_map_base : (K, 4, 4) float
        Raw odometry and the optimized keyframes.

    Returns
    -------
    OdometryCalibration
        What maps the raw steps onto the optimized ones (module docstring).
    """
    step_odom = inverse_h(M_odom_base[:-1]) @ M_odom_base[1:]
    step_opt = inverse_h(M_map_base[:-1]) @ M_map_base[1:]
    t_odom, t_opt = step_odom[:, :3, 3], step_opt[:, :3, 3]
    dist = np.linalg.norm(t_odom, axis=1)
    # rows: x, y, z of every step; unknowns: scale, lateral_per_m
    A = np.zeros((len(dist), 3, 2))
    A[:, :, 0] = t_odom
    A[:, 1, 1] = dist
    (scale, lateral), *_ = np.linalg.lstsq(
        A.reshape(-1, 2), (t_opt - t_odom).reshape(-1), rcond=None
    )
    yaw_odom, yaw_opt = _yaw(step_odom[:, :3, :3]), _yaw(step_opt[:, :3, :3])
    B = np.column_stack([yaw_odom, dist])
    (turn, bias), *_ = np.linalg.lstsq(B, yaw_opt - yaw_odom, rcond=None)
    return OdometryCalibration(float(scale), float(lateral), float(turn), float(bias))


def corrected_steps(step: FloatArray, cal: OdometryCalibration) -> FloatArray:
    """``(K-1, 4, 4)`` raw odometry steps with the calibration applied (module docstring)."""
    dist = np.linalg.norm(step[:, :3, 3], axis=1)
    extra_yaw = cal.turn_scale * _yaw(step[:, :3, :3]) + cal.yaw_bias_per_m * dist
    fixed = step.copy()
    fixed[:, :3, 3] = (1.0 + cal.scale) * step[:, :3, 3]
    fixed[:, 1, 3] += cal.lateral_per_m * dist
    fixed[:, :3, :3] = _rot_z(extra_yaw) @ step[:, :3, :3]
    return fixed


def corrected_step_jacobians(step: FloatArray, fixed: FloatArray) -> FloatArray:
    """``(K-1, 6, 4)`` right-tangent derivative ``D`` of :func:`corrected_steps` in the
    calibration vector: ``Log(Z^-1 Z(c + dc)) = D dc`` (exact to first order).

    ``step`` are the raw steps, ``fixed = Z(c)`` the corrected ones (rotation ``R_Z``). ``c``
    moves ``Z``'s translation by ``t dscale + d y_hat dlateral`` and turns it about the earlier
    keyframe's z by ``yaw dturn + d dbias``, so ``D = blockdiag(R_Z^T, R_Z^T) G`` with ``G`` the
    ``[x, y, z, rx, ry, rz]`` change per parameter (``t``, ``d``, ``yaw`` of the raw step).
    """
    t = step[:, :3, 3]
    dist = np.linalg.norm(t, axis=1)
    G = np.zeros((len(step), 6, N_CALIBRATION))
    G[:, :3, 0] = t
    G[:, 1, 1] = dist
    G[:, 5, 2] = _yaw(step[:, :3, :3])
    G[:, 5, 3] = dist
    R_T = np.swapaxes(fixed[:, :3, :3], 1, 2)
    D = np.empty_like(G)
    D[:, :3] = R_T @ G[:, :3]
    D[:, 3:] = R_T @ G[:, 3:]
    return D


def apply_calibration(M_odom_base: FloatArray, cal: OdometryCalibration) -> FloatArray:
    """``(K, 4, 4)`` odometry recomposed from calibrated steps, from the same first pose."""
    fixed = corrected_steps(inverse_h(M_odom_base[:-1]) @ M_odom_base[1:], cal)
    out = np.empty_like(M_odom_base)
    out[0] = M_odom_base[0]
    for k in range(len(fixed)):
        out[k + 1] = out[k] @ fixed[k]
    return out
