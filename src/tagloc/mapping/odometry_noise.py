"""The odometry factors' noise: a random walk in distance and rotation, level with gravity.

Per step between keyframes ``k`` and ``k+1`` (:class:`~tagloc.mapping.config.OdometryNoise`):
``var_t = per_m d + per_rad a + floor^2`` in translation and likewise ``var_r`` in rotation,
``d`` the distance and ``a`` the angle travelled. Robots on a floor and gravity-aware odometry
drift along the floor and in yaw, hardly in height, roll and pitch, so the noise is split along
"up" ``u`` (in the body at keyframe ``k``: :meth:`~tagloc.frames.OdometryFrameConfig.up_in_base`)
with ``v`` the ``vertical_factor``:

.. math:: \\Sigma_t = \\mathrm{var}_t \\left(I - (1 - v^2)\\, u u^\\top\\right), \\qquad
          \\Sigma_r = \\mathrm{var}_r \\left(v^2 I + (1 - v^2)\\, u u^\\top\\right)

Written as a rotation ``R_level_base`` that takes ``u`` to ``z`` and diagonal sigmas
``[s_t, s_t, v s_t, v s_r, v s_r, s_r]`` in that level frame, the whitened error of a step
error ``e = [e_t, e_r]`` (body right tangent) is ``[R e_t, R e_r] / sigmas``. An upright body
(``u = z``) has ``R = I``: the plain diagonal model, bit for bit. A body mounted any other way
(a camera frame, z forward: its yaw is a rotation about its y axis) gets its yaw noise about the
true vertical, not about its own z; holding the wrong axis tight turned a one-anchor map of a
handheld VIO rig by 2.5 deg.
"""

from __future__ import annotations

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SO3, inverse_h
from tagloc.mapping.config import OdometryNoise
from tagloc.mapping.initialize import rotation_angle
from tagloc.mapping.whitening import AxisWhitening

_Z = np.array([0.0, 0.0, 1.0])


def odometry_whitening(
    M_odom_base: FloatArray, noise: OdometryNoise, up_base: FloatArray | None = None
) -> AxisWhitening:
    """The noise of the consecutive steps of ``M_odom_base (K, 4, 4)`` (module docstring).

    Parameters
    ----------
    M_odom_base : (K, 4, 4) float
    noise : OdometryNoise
    up_base : (K, 3) float, optional
        "Up" in the body at each keyframe; None, or exactly ``+z`` everywhere: an upright body.
    """
    step = inverse_h(M_odom_base[:-1]) @ M_odom_base[1:]
    dist = np.linalg.norm(step[:, :3, 3], axis=1)
    angle = rotation_angle(np.broadcast_to(np.eye(3), step[:, :3, :3].shape), step[:, :3, :3])
    var_t = noise.translation_var_per_m * dist + noise.translation_var_per_rad * angle
    var_r = noise.rotation_var_per_m * dist + noise.rotation_var_per_rad * angle
    var_t += noise.translation_floor_m**2
    var_r += noise.rotation_floor_rad**2
    v = noise.vertical_factor**2
    sigmas = np.sqrt(np.column_stack([var_t, var_t, v * var_t, v * var_r, v * var_r, var_r]))
    sigmas = np.asarray(sigmas, dtype=np.float64)
    if up_base is None or len(step) == 0:
        return AxisWhitening(sigmas)
    u = np.asarray(up_base, dtype=np.float64)[:-1]
    if np.array_equal(u, np.broadcast_to(_Z, u.shape)):
        return AxisWhitening(sigmas)
    return AxisWhitening(sigmas, rotations_to_z(u))


def rotations_to_z(u: FloatArray) -> FloatArray:
    """``(n, 3, 3)`` rotations taking each unit vector ``u (n, 3)`` to ``z`` (the shortest turn;
    ``-z`` turns about ``x``)."""
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    axis = np.cross(u, _Z)
    s = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(s, u[:, 2])
    rotvec = np.zeros_like(u)
    ok = s > 1e-12
    rotvec[ok] = axis[ok] / s[ok, None] * angle[ok, None]
    rotvec[~ok & (u[:, 2] < 0)] = [np.pi, 0.0, 0.0]
    return np.asarray(SO3.from_rotvec(rotvec).as_matrix())
