"""Pinhole camera with radial-tangential distortion (OpenCV's model, ROS ``plumb_bob``).

For normalized coordinates ``(x, y) = (X/Z, Y/Z)`` and ``r^2 = x^2 + y^2`` (Brown 1966; OpenCV
``calib3d`` "Detailed description", with ``k4..k6``, thin-prism and tilt terms zero)::

    xd = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    yd = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y
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

#: Largest accepted residual |d(x) - xd| of an undistorted point (normalized units; 1e-7 px at
#: f = 1000 px). Newton reaches ~1e-16; a larger residual means no solution.
_RESIDUAL_TOL = 1e-10
_NEWTON_ITER = 20


@dataclass(frozen=True, slots=True, kw_only=True)
class PinholeRadtan(_Pinhole):
    """Pinhole camera with radial (k1, k2, k3) and tangential (p1, p2) distortion.

    ``width``, ``height``, ``fx``, ``fy``, ``cx`` and ``cy`` (pixels) are the intrinsics every
    model shares; below, what this one adds.

    Attributes
    ----------
    k1, k2, p1, p2, k3 : float
        Distortion coefficients in OpenCV's order (``k3 = 0`` for a 4-coefficient calibration,
        as Kalibr's ``radtan``).

    Notes
    -----
    The radial factor ``r (1 + k1 r^2 + k2 r^4 + k3 r^6)`` turns back at the *fold* radius (the
    first positive root of its derivative) for many calibrations, e.g. ``k1 < 0`` with
    ``k2 = k3 = 0``: beyond it a point far outside the field of view would project *into* the
    image. :meth:`project` returns NaN for normalized radii at or beyond the fold, and
    :meth:`undistort` only returns radii below it, so ``project(undistort(px)) == px`` wherever
    the result is finite. Without a fold (``inf``) every ``z > 0`` point projects. The fold is
    found from the radial part; with tangential terms the map is not quite one-to-one within
    about 0.1 degree of it, and :meth:`undistort` returns one of the two preimages there (both
    reproject to the pixel).

    Keyword-only construction (``PinholeRadtan(width=..., fx=..., ...)``): a call with eleven
    positional floats is too easy to get wrong.
    """

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    distortion_model: ClassVar[str] = "radtan"
    _ROS_MODEL: ClassVar[str] = "plumb_bob"
    _COEFFS: ClassVar[tuple[str, ...]] = ("k1", "k2", "p1", "p2", "k3")
    _OPENCV_D: ClassVar[tuple[str, tuple[int, ...]]] = ("dist_coeffs", (4, 5))

    def _radial_coeffs(self) -> _radial.Coeffs:
        return (self.k1, self.k2, self.k3, 0.0)

    def _limits(self) -> tuple[float, float]:
        fold = _radial.monotone_limit(self._radial_coeffs())
        return fold, fold

    def _distort(self, x: FloatArray, y: FloatArray, jacobian: bool) -> Distorted:
        # Terms of zero coefficients are left out: for finite x, y they would add exactly +-0.
        k1, k2, k3, p1, p2 = self.k1, self.k2, self.k3, self.p1, self.p2
        tangential = p1 != 0.0 or p2 != 0.0
        if k1 == k2 == k3 == 0.0 and not tangential:
            return x, y, None  # no distortion: the identity, J_d_n = I
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3) if k3 != 0.0 else k1 + r2 * k2)
        xy2 = 2.0 * x * y
        if tangential:
            xd = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
            yd = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2
        else:
            xd, yd = x * radial, y * radial
        if not jacobian:
            return xd, yd, None
        # d(radial)/d(r^2)
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2) if k3 != 0.0 else k1 + r2 * (2.0 * k2)
        if not tangential:
            J_d_n = np.empty((len(x), 2, 2))
            J_d_n[:, 0, 0] = radial + 2.0 * x * x * dradial
            J_d_n[:, 0, 1] = J_d_n[:, 1, 0] = xy2 * dradial
            J_d_n[:, 1, 1] = radial + 2.0 * y * y * dradial
            return xd, yd, J_d_n
        cross = xy2 * dradial + 2.0 * (p1 * x + p2 * y)
        J_d_n = np.empty((len(x), 2, 2))
        J_d_n[:, 0, 0] = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        J_d_n[:, 0, 1] = cross
        J_d_n[:, 1, 0] = cross
        J_d_n[:, 1, 1] = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        return xd, yd, J_d_n

    def _undistort_normalized(self, xd: FloatArray, yd: FloatArray) -> tuple[FloatArray, ...]:
        # 1. Radial part: exact 1-D inversion along the ray through the distorted point.
        coeffs = self._radial_coeffs()
        tangential = self.p1 != 0.0 or self.p2 != 0.0
        identity = not tangential and coeffs == (0.0, 0.0, 0.0, 0.0)
        if identity and np.isfinite(xd).all() and np.isfinite(yd).all():
            return xd, yd  # no distortion: what the inversion below returns, exactly
        rd = target = np.hypot(xd, yd)
        if tangential and math.isfinite(self._t_max):
            # Tangential terms can push a point just inside the fold beyond the radial part's
            # range: start those at the edge of the range and let the Newton steps decide.
            rd_max = _radial.evaluate(np.array([self._t_max]), coeffs)[0][0]
            target = np.minimum(rd, (1.0 - 1e-6) * rd_max)
        r = _radial.invert(target, coeffs, self._t_max)
        gain = np.where(rd > 0.0, r / rd, 1.0)
        x, y = xd * gain, yd * gain
        if not tangential:
            return x, y
        # 2. Tangential part: 2-D Newton steps from the radial solution (tangential terms are
        #    small, so it starts in the basin of the solution).
        for _ in range(_NEWTON_ITER):
            xh, yh, J = self._distort(x, y, jacobian=True)
            assert J is not None
            ex, ey = xh - xd, yh - yd
            det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
            dx = (J[:, 1, 1] * ex - J[:, 0, 1] * ey) / det
            dy = (J[:, 0, 0] * ey - J[:, 1, 0] * ex) / det
            x, y = x - dx, y - dy
            if not np.any(np.abs(dx) + np.abs(dy) > 1e-15 * (1.0 + np.abs(x) + np.abs(y))):
                break
        # 3. Keep only converged solutions inside the monotone region.
        xh, yh, _ = self._distort(x, y, jacobian=False)
        ok = (np.hypot(xh - xd, yh - yd) <= _RESIDUAL_TOL) & (x * x + y * y < self._t_max**2)
        return np.where(ok, x, np.nan), np.where(ok, y, np.nan)
