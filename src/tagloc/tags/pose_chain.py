"""The covariance of poses derived from a tag's: ``T_map_cam``, ``T_map_base``, and the NEES.

A tag observation gives ``T_cam_tag`` with a right-tangent covariance
(:mod:`tagloc.tags.covariance`); the surveyed ``T_map_tag`` and the extrinsics ``T_base_cam``
turn it into the pose a fix needs.
Each step is ``T_a_c = T_a_b @ T_c_b^-1`` with its covariance carried by
:mod:`tagloc.geometry.covariance` (first order, inputs independent, right tangents ordered
``[x, y, z, rx, ry, rz]``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3, cov_compose, cov_inverse

__all__ = ["map_base_from_cam", "map_cam_from_tag", "nees"]

Cov = npt.ArrayLike  # a (6, 6) right-tangent covariance


def map_cam_from_tag(
    T_cam_tag: SE3, cov_cam_tag: npt.ArrayLike, T_map_tag: SE3, cov_map_tag: Cov | None = None
) -> tuple[SE3, FloatArray]:
    """``T_map_cam = T_map_tag @ T_cam_tag^-1`` with its right-tangent covariance.

    ``cov_cam_tag`` is the right tangent of ``T_cam_tag``; ``cov_map_tag`` the survey
    uncertainty of the tag's ``T_map_tag`` (zero by default). Returns ``T_map_cam`` and its
    ``(6, 6)`` right-tangent covariance.
    """
    return _times_inverse(T_map_tag, cov_map_tag, T_cam_tag, cov_cam_tag)


def map_base_from_cam(
    T_map_cam: SE3, cov_map_cam: Cov, T_base_cam: SE3, cov_base_cam: Cov | None = None
) -> tuple[SE3, FloatArray]:
    """``T_map_base = T_map_cam @ T_base_cam^-1`` with its right-tangent covariance.

    ``T_base_cam`` are the static extrinsics (camera optical frame in the robot base frame),
    ``cov_base_cam`` their calibration uncertainty (zero by default).
    """
    return _times_inverse(T_map_cam, cov_map_cam, T_base_cam, cov_base_cam)


def _times_inverse(
    T_a_b: SE3, cov_a_b: Cov | None, T_c_b: SE3, cov_c_b: Cov | None
) -> tuple[SE3, FloatArray]:
    """``T_a_c = T_a_b @ T_c_b^-1`` and its covariance (``None``: a factor known exactly)."""
    T_b_c = T_c_b.inverse()
    cov_b_c = np.zeros((6, 6)) if cov_c_b is None else cov_inverse(T_c_b, cov_c_b)
    if cov_a_b is None:  # cov_compose(T_a_b, 0, T_b_c, C) is C (symmetric) exactly
        return T_a_b @ T_b_c, cov_b_c
    return T_a_b @ T_b_c, cov_compose(T_a_b, cov_a_b, T_b_c, cov_b_c)


def nees(T_true: SE3, T_est: SE3, cov_est: npt.ArrayLike) -> FloatArray:
    """Normalized estimation error squared ``e^T C^-1 e``, ``e = Log(T_true^-1 @ T_est)``.

    Parameters
    ----------
    T_true, T_est : SE3, single or batches of N
    cov_est : (6, 6) or (N, 6, 6) float, right tangent of ``T_est``

    Returns
    -------
    () or (N,) float
        Chi-square with 6 dof (mean 6) when ``cov_est`` is honest.
    """
    e = np.asarray(T_est.minus(T_true))
    C = np.asarray(cov_est, dtype=np.float64)
    x = np.linalg.solve(C, e[..., None])[..., 0]
    return np.asarray(np.einsum("...i,...i->...", e, x))
