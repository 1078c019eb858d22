"""Pinhole camera with equidistant (fisheye) distortion, as ``cv2.fisheye`` and Kalibr use it.

Kannala & Brandt (2006), "A generic camera model and calibration method for conventional,
wide-angle, and fish-eye lenses", IEEE TPAMI 28(8), eq. 6 with four coefficients; OpenCV
``cv::fisheye`` "Detailed description". For normalized ``(x, y) = (X/Z, Y/Z)``, ``r = |(x, y)|``::

    theta = atan(r)                                     # angle of incidence
    theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
    (xd, yd) = (theta_d / r) (x, y)
    u = fx xd + cx,  v = fy yd + cy
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import _radial
from tagloc.camera._pinhole import Distorted, _Pinhole

#: Below this normalized radius ``theta_d / r`` and its derivative use their Taylor series
#: (the closed forms are 0/0 at r = 0).
_SMALL_R = 1e-8


@dataclass(frozen=True, slots=True, kw_only=True)
class PinholeEquidistant(_Pinhole):
    """Pinhole camera with Kannala-Brandt equidistant distortion (``cv2.fisheye``, k1..k4).

    Image size and intrinsics are the pinhole's (``width``, ``height``, ``fx``, ``fy``, ``cx``,
    ``cy`` in pixels, top-left pixel center at ``(0, 0)``); the fisheye adds its four terms.

    Attributes
    ----------
    k1, k2, k3, k4 : float
        Distortion coefficients of the angle polynomial.

    Notes
    -----
    The domain is ``0 <= theta < theta_max`` where ``theta_max`` is the smaller of 90 degrees
    (``z > 0``: points in or behind the camera's plane give NaN, as for every model here) and
    the fold of ``theta_d(theta)`` (first root of its derivative, if any). :meth:`undistort`
    inverts ``theta_d`` in numpy with a bracketed Newton iteration to a few ulp;
    ``cv2.fisheye.undistortPoints`` stops at ``EPS = 1e-8`` and 10 iterations by default and
    returns ``-1e6`` where it fails.

    Keyword-only construction (``PinholeEquidistant(width=..., fx=..., ...)``).
    """

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0

    distortion_model: ClassVar[str] = "equidistant"
    _ROS_MODEL: ClassVar[str] = "equidistant"
    _COEFFS: ClassVar[tuple[str, ...]] = ("k1", "k2", "k3", "k4")
    _OPENCV_D: ClassVar[tuple[str, tuple[int, ...]]] = ("D", (4,))

    def _radial_coeffs(self) -> _radial.Coeffs:
        return (self.k1, self.k2, self.k3, self.k4)

    def _limits(self) -> tuple[float, float]:
        theta_max = min(math.pi / 2.0, _radial.monotone_limit(self._radial_coeffs()))
        max_radius = math.tan(theta_max) if theta_max < math.pi / 2.0 else math.inf
        return theta_max, max_radius

    def _distort(self, x: FloatArray, y: FloatArray, jacobian: bool) -> Distorted:
        r2 = x * x + y * y
        r = np.sqrt(r2)
        theta = np.arctan(r)
        theta_d, dtheta_d = _radial.evaluate(theta, self._radial_coeffs())
        small = r < _SMALL_R
        c = self.k1 - 1.0 / 3.0  # theta_d / r = 1 + c r^2 + O(r^4)
        gain = np.where(small, 1.0 + c * r2, theta_d / r)
        xd, yd = x * gain, y * gain
        if not jacobian:
            return xd, yd, None
        # q = gain'(r) / r, so d(x gain)/dx = gain + x^2 q and d(x gain)/dy = x y q.
        q = np.where(small, 2.0 * c, (dtheta_d * r / (1.0 + r2) - theta_d) / (r2 * r))
        J_d_n = np.empty((len(x), 2, 2))
        J_d_n[:, 0, 0] = gain + x * x * q
        J_d_n[:, 0, 1] = x * y * q
        J_d_n[:, 1, 0] = x * y * q
        J_d_n[:, 1, 1] = gain + y * y * q
        return xd, yd, J_d_n

    def _undistort_normalized(self, xd: FloatArray, yd: FloatArray) -> tuple[FloatArray, ...]:
        # The distortion is purely radial: invert theta_d(theta) along the ray, then rescale.
        theta_d = np.hypot(xd, yd)
        theta = _radial.invert(theta_d, self._radial_coeffs(), self._t_max)
        gain = np.where(theta_d > 0.0, np.tan(theta) / theta_d, 1.0)
        return xd * gain, yd * gain
