"""How an odometry relates to gravity and to the body it reports: one definition for the map
builder and the localizer.

An odometry publishes ``T_odom_base``: the pose of a body frame (``base``) in its own fixed frame
(``odom``). Two facts about it decide how "up" is found, and every algorithm that needs "up"
(the map builder's noise model and gravity priors, the localizer's gravity prior) reads them
from :class:`OdometryFrameConfig`:

- ``gravity_aligned``: the odometry frame has an axis along gravity (``up_axis``, ``+z`` as
  REP-105 asks). A visual-inertial odometry observes gravity, so its roll and pitch do not
  drift; a robot's wheel or leg odometry on a level floor is also level. Then "up" in the body
  at each sample is ``R_odom_base^T up_odom``, whatever way the body is mounted or held.
- otherwise (camera-only visual odometry, whose frame is wherever the first image looked) the
  odometry says nothing about gravity, and "up" in the body is the fixed axis ``base_up_axis``
  of a robot standing on the floor (``+z`` for a REP-103 ``base_link``).

- neither (``base_up_axis: null``: a handheld camera with camera-only visual odometry): no
  "up" is known, and nothing that needs it is used (no gravity prior in the localizer, no
  vertical split of the map builder's odometry noise).

The defaults (``gravity_aligned: false``, ``base_up_axis: +z``) are right for an upright robot
base. A handheld rig or a camera-frame body (the body's z looks forward) with a VIO is
``gravity_aligned: true``; a rig whose body is an optical frame without gravity is
``base_up_axis: -y``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from tagloc._types import FloatArray
from tagloc.config import StrictModel

Axis = Literal["+x", "-x", "+y", "-y", "+z", "-z"]


def axis_vector(axis: Axis) -> FloatArray:
    """``(3,)`` unit vector of a signed axis name such as ``"-y"``."""
    v = np.zeros(3)
    v["xyz".index(axis[1])] = 1.0 if axis[0] == "+" else -1.0
    return v


class OdometryFrameConfig(StrictModel):
    """The odometry's relation to gravity and to the body (module docstring).

    Attributes
    ----------
    gravity_aligned : bool
        The odometry frame's ``up_axis`` points against gravity (VIO; wheel or leg odometry on
        a level floor).
    up_axis : {"+x", "-x", "+y", "-y", "+z", "-z"}
        The odometry frame's axis that points up, when ``gravity_aligned``.
    base_up_axis : {"+x", "-x", "+y", "-y", "+z", "-z"} or None
        The body's axis that points up when the robot stands level; used when the odometry is
        not gravity-aligned. None: no up is known.
    """

    gravity_aligned: bool = False
    up_axis: Axis = "+z"
    base_up_axis: Axis | None = "+z"

    @property
    def knows_up(self) -> bool:
        """Whether "up" in the body is known at all (gravity-aligned, or a body axis)."""
        return self.gravity_aligned or self.base_up_axis is not None

    def up_in_base(self, R_odom_base: FloatArray) -> FloatArray:
        """``(K, 3)`` unit "up" in the body at each odometry sample.

        Parameters
        ----------
        R_odom_base : (K, 3, 3) float
            Rotations of ``T_odom_base``.

        Returns
        -------
        (K, 3) float
            ``R_odom_base^T up_odom`` when gravity-aligned, else ``base_up_axis`` at every
            sample.

        Raises
        ------
        ValueError
            No up is known (:attr:`knows_up` is false).
        """
        R = np.asarray(R_odom_base, dtype=np.float64).reshape(-1, 3, 3)
        if self.gravity_aligned:
            return np.asarray(np.einsum("kji,j->ki", R, axis_vector(self.up_axis)))
        if self.base_up_axis is None:
            raise ValueError("odometry_frame: no up is known (base_up_axis: null)")
        return np.asarray(np.broadcast_to(axis_vector(self.base_up_axis), (len(R), 3)).copy())


def base_tilt_deg(R_odom_base: FloatArray, up_base: FloatArray) -> float:
    """Median angle (deg) between the odometry frame's z and the body's "up" carried into it.

    A body the configuration calls upright while the odometry holds it 90 deg away (a camera
    frame as the body, z forward) shows here as about 90: :class:`OdometryFrameConfig` is then
    likely wrong for this odometry.

    Parameters
    ----------
    R_odom_base : (K, 3, 3) float
    up_base : (K, 3) float
        From :meth:`OdometryFrameConfig.up_in_base`.
    """
    R = np.asarray(R_odom_base, dtype=np.float64).reshape(-1, 3, 3)
    if len(R) == 0:
        return 0.0
    up_odom = np.einsum("kij,kj->ki", R, np.asarray(up_base, dtype=np.float64))
    return float(np.degrees(np.median(np.arccos(np.clip(up_odom[:, 2], -1.0, 1.0)))))
