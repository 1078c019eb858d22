"""Gravity priors: roll and pitch of every keyframe from a gravity-aligned odometry.

A visual-inertial odometry observes gravity: its frame's z axis is "up", and its roll and pitch
do not drift while its position and yaw do. With
:attr:`tagloc.frames.OdometryFrameConfig.gravity_aligned`, the map frame's z is declared
the same "up": keyframe ``k`` gets the prior

.. math:: e_k = \\left(R_k^\\top \\hat z - u_k\\right) / \\sigma, \\qquad
          u_k = R^{odom\\top}_k \\hat z

with ``R_k`` the rotation of ``T_map_base`` and ``u_k`` "up" in ``base`` as the odometry
(``T_odom_base``) sees it. ``|e_k| sigma`` is the angle between the two (``2 sin(a/2)``); the
rotation about "up" (yaw) is free. Right perturbation ``R Exp(w)``: ``d e / d w = [u]_x /
sigma`` (rotation columns of ``[x, y, z, rx, ry, rz]``; none on the translation).

The pose-factor stage uses GTSAM's ``AttitudeFactorPose3`` (the same direction error, on the
``Unit3`` tangent); the corner refinement linearizes :func:`gravity_residuals` here.

:func:`map_tilt_deg` measures how far a map's z is from the odometry's gravity: the angle between
``z`` and the mean over keyframes of ``R_k u_k`` (each keyframe's "up" as the odometry sees it,
carried into ``map``).
"""

from __future__ import annotations

import gtsam
import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import hat

_Z = np.array([0.0, 0.0, 1.0])


def add_gravity_factors(
    graph: gtsam.NonlinearFactorGraph,
    keys: list[int],
    up_base: FloatArray,
    sigma_rad: float,
) -> None:
    """One ``AttitudeFactorPose3`` per keyframe key: ``R_map_base u_k`` should be ``z``."""
    model = gtsam.noiseModel.Isotropic.Sigma(2, sigma_rad)
    z = gtsam.Unit3(_Z)
    for key, u in zip(keys, up_base, strict=True):
        graph.add(gtsam.AttitudeFactorPose3(key, z, model, gtsam.Unit3(np.asarray(u))))


def gravity_residuals(M_map_base: FloatArray, up_base: FloatArray, sigma_rad: float) -> FloatArray:
    """``(K, 3)`` whitened gravity errors ``(R_k^T z - u_k) / sigma`` (module docstring)."""
    map_up_base = np.einsum("kji,j->ki", M_map_base[:, :3, :3], _Z)
    return np.asarray((map_up_base - up_base) / sigma_rad)


def gravity_jacobians(M_map_base: FloatArray, sigma_rad: float) -> FloatArray:
    """``(K, 3, 6)`` Jacobians of :func:`gravity_residuals` in each keyframe's right tangent."""
    map_up_base = np.einsum("kji,j->ki", M_map_base[:, :3, :3], _Z)
    J = np.zeros((len(M_map_base), 3, 6))
    J[:, :, 3:] = hat(map_up_base) / sigma_rad
    return J


def map_tilt_deg(M_map_base: FloatArray, up_base: FloatArray) -> float:
    """Angle (deg) between the map's z and the odometry's gravity carried into ``map``."""
    up_map = np.einsum("kij,kj->i", M_map_base[:, :3, :3], up_base)
    up_map = up_map / np.linalg.norm(up_map)
    return float(np.degrees(np.arccos(np.clip(up_map @ _Z, -1.0, 1.0))))


def keyframe_tilts_deg(M_map_base: FloatArray, up_base: FloatArray) -> FloatArray:
    """``(K,)`` angle (deg) between each keyframe's map "up" and the odometry's."""
    map_up_base = np.einsum("kji,j->ki", M_map_base[:, :3, :3], _Z)
    cos = np.clip(np.einsum("ki,ki->k", map_up_base, up_base), -1.0, 1.0)
    return np.asarray(np.degrees(np.arccos(cos)))
