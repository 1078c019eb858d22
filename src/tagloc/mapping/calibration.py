"""Odometry self-calibration: systematic errors estimated from the optimized trajectory.

Odometry errors are partly systematic (distance scale, turn scale, yaw bias per metre, lateral
crab drift): a random-walk noise model cannot remove them, and around a closed loop a pure
scale error even cancels, so loop closures do not reveal it. Where tags pin the keyframes, the
optimized trajectory shows it. Per odometry step between keyframes (in the earlier keyframe's
``base`` frame), we fit by least squares

- translation: ``t_opt = S t_odom`` (``S`` a 3x3 matrix: scale, crab drift, axis coupling);
- yaw: ``yaw_opt = (1 + a) yaw_odom + b d`` (turn scale ``a``, bias ``b`` per metre ``d``),

and recompose the odometry with the corrected steps. The builder alternates this with
optimization (``MapBuildConfig.calibration_rounds``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.mapping.initialize import inverse_h

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class OdometryCalibration:
    """``t' = S t`` and ``yaw' = (1 + turn_scale) yaw + yaw_bias_per_m d`` per step."""

    S: FloatArray
    turn_scale: float
    yaw_bias_per_m: float

    @staticmethod
    def identity() -> OdometryCalibration:
        return OdometryCalibration(np.eye(3), 0.0, 0.0)


def _yaw(R: FloatArray) -> FloatArray:
    return np.asarray(np.arctan2(R[..., 1, 0], R[..., 0, 0]))


def _rot_z(angle: FloatArray) -> FloatArray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((*np.shape(angle), 3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def fit_calibration(M_odom_base: FloatArray, M_map_base: FloatArray) -> OdometryCalibration:
    """Least-squares calibration of raw odometry steps against optimized ones (module doc)."""
    step_odom = inverse_h(M_odom_base[:-1]) @ M_odom_base[1:]
    step_opt = inverse_h(M_map_base[:-1]) @ M_map_base[1:]
    t_odom, t_opt = step_odom[:, :3, 3], step_opt[:, :3, 3]
    gram = t_odom.T @ t_odom
    moving = np.flatnonzero(np.diag(gram) > 1e-6 * max(np.trace(gram), 1e-12))  # planar: x, y
    S = np.eye(3)
    if len(moving) and np.linalg.cond(gram[np.ix_(moving, moving)]) < 1e8:
        block = (t_opt[:, moving].T @ t_odom[:, moving]) @ np.linalg.inv(
            gram[np.ix_(moving, moving)]
        )
        S[np.ix_(moving, moving)] = block
    yaw_odom, yaw_opt = _yaw(step_odom[:, :3, :3]), _yaw(step_opt[:, :3, :3])
    dist = np.linalg.norm(t_odom, axis=1)
    A = np.column_stack([yaw_odom, dist])
    (a, b), *_ = np.linalg.lstsq(A, yaw_opt - yaw_odom, rcond=None)
    return OdometryCalibration(S, float(a), float(b))


def apply_calibration(M_odom_base: FloatArray, cal: OdometryCalibration) -> FloatArray:
    """Odometry recomposed from calibrated steps, starting at the same first pose."""
    step = inverse_h(M_odom_base[:-1]) @ M_odom_base[1:]
    dist = np.linalg.norm(step[:, :3, 3], axis=1)
    extra_yaw = cal.turn_scale * _yaw(step[:, :3, :3]) + cal.yaw_bias_per_m * dist
    fixed = step.copy()
    fixed[:, :3, 3] = step[:, :3, 3] @ cal.S.T
    fixed[:, :3, :3] = _rot_z(extra_yaw) @ step[:, :3, :3]
    out = np.empty_like(M_odom_base)
    out[0] = M_odom_base[0]
    for k in range(len(fixed)):
        out[k + 1] = out[k] @ fixed[k]
    return out
