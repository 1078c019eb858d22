"""The part both camera models share: pinhole intrinsics and the project / undistort pipeline.

A model is ``pixel = A(d(n(point)))`` with the perspective division ``n(x, y, z) = (x/z, y/z)``, a
model-specific distortion ``d`` of normalized coordinates, and the affine map
``A(xd, yd) = (fx xd + cx, fy yd + cy)`` (no skew, as in OpenCV). Subclasses supply ``d``, its
2x2 Jacobian and its inverse; this base class does the rest once.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Self

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import _fields
from tagloc.camera.model import BoolArray, as_vectors
from tagloc.errors import CameraModelError

#: Largest image side, focal length and principal point offset (px), distortion coefficient:
#: far beyond any real camera, and far from overflow in projection.
MAX_IMAGE_SIDE_PX = 100_000
MAX_FOCAL_PX = 1e7
MAX_COEFFICIENT = 1e4
_BOUNDS = {
    "width": (1.0, MAX_IMAGE_SIDE_PX, "px"),
    "height": (1.0, MAX_IMAGE_SIDE_PX, "px"),
    "fx": (1.0, MAX_FOCAL_PX, "px"),
    "fy": (1.0, MAX_FOCAL_PX, "px"),
    "cx": (-MAX_FOCAL_PX, MAX_FOCAL_PX, "px"),
    "cy": (-MAX_FOCAL_PX, MAX_FOCAL_PX, "px"),
}

#: (xd, yd, J_d_n) where J_d_n is (N, 2, 2), or None: not asked for, or the identity.
Distorted = tuple[FloatArray, FloatArray, FloatArray | None]


@dataclass(frozen=True, slots=True, kw_only=True)
class _Pinhole:
    """Image size and pinhole intrinsics (pixels); see the public subclasses.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    fx, fy : float
        Focal lengths in pixels (> 0).
    cx, cy : float
        Principal point in pixels (top-left pixel center at ``(0, 0)``).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    # Domain limits derived from the coefficients in __post_init__ (see _limits).
    _t_max: float = field(init=False, repr=False, compare=False)
    _max_radius: float = field(init=False, repr=False, compare=False)

    distortion_model: ClassVar[str]
    _ROS_MODEL: ClassVar[str]
    _COEFFS: ClassVar[tuple[str, ...]]
    #: The name OpenCV gives the distortion vector, and the lengths it may have.
    _OPENCV_D: ClassVar[tuple[str, tuple[int, ...]]]

    @classmethod
    def from_opencv(cls, K: npt.ArrayLike, D: npt.ArrayLike, image_size: tuple[int, int]) -> Self:
        """Build from OpenCV's camera matrix ``K``, distortion vector ``D`` (``cv2.fisheye``'s 4
        values for the equidistant model; ``distCoeffs``' 4 or 5 for radtan, a missing ``k3``
        is 0) and ``(width, height)``.

        Raises
        ------
        CameraModelError
            If ``K`` is not a zero-skew 3x3 camera matrix or ``D`` has another length.
        """
        fx, fy, cx, cy = _fields.camera_matrix_values(K, "K")
        D_name, counts = cls._OPENCV_D
        k = _fields.float_list(np.ravel(D), D_name, counts, cls.distortion_model)
        width, height = image_size
        coeffs = dict(zip(cls._COEFFS, k, strict=False))
        return cls(width=width, height=height, fx=fx, fy=fy, cx=cx, cy=cy, **coeffs)

    def __post_init__(self) -> None:
        kind = type(self).__name__
        values: dict[str, object] = {
            "width": _fields.positive_int(self.width, f"{kind}.width"),
            "height": _fields.positive_int(self.height, f"{kind}.height"),
            "fx": _fields.positive_float(self.fx, f"{kind}.fx"),
            "fy": _fields.positive_float(self.fy, f"{kind}.fy"),
        }
        for name in ("cx", "cy", *self._COEFFS):
            values[name] = _fields.finite_float(getattr(self, name), f"{kind}.{name}")
        for name, value in values.items():
            low, high, unit = _BOUNDS.get(name, (-MAX_COEFFICIENT, MAX_COEFFICIENT, ""))
            _fields.bounded(float(value), f"{kind}.{name}", low, high, unit)  # type: ignore[arg-type]
        for name, value in values.items():
            object.__setattr__(self, name, value)
        t_max, max_radius = self._limits()
        object.__setattr__(self, "_t_max", t_max)
        object.__setattr__(self, "_max_radius", max_radius)

    # -- hooks for the models ------------------------------------------------------------------

    def _limits(self) -> tuple[float, float]:
        """(domain limit of the radial polynomial's argument, limit of the normalized radius)."""
        raise NotImplementedError

    def _distort(self, x: FloatArray, y: FloatArray, jacobian: bool) -> Distorted:
        """Distorted normalized coordinates (and ``d(xd, yd)/d(x, y)``, None if the identity) of
        normalized ``x, y`` (NaN at the same points)."""
        raise NotImplementedError

    def _undistort_normalized(self, xd: FloatArray, yd: FloatArray) -> tuple[FloatArray, ...]:
        """Inverse of :meth:`_distort`; NaN where no point in the domain maps to ``(xd, yd)``."""
        raise NotImplementedError

    @property
    def dist_coeffs(self) -> FloatArray:
        """(n,) float: distortion coefficients in OpenCV's order."""
        return np.array([getattr(self, name) for name in self._COEFFS], dtype=np.float64)

    # -- shared API ----------------------------------------------------------------------------

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return (self.width, self.height)

    @property
    def max_angle(self) -> float:
        """Largest angle (radians) between the optical axis and a point the model projects.

        ``atan`` of the fold radius (see the model's notes); ``pi / 2`` when there is no fold.
        """
        return math.atan(self._max_radius)

    @property
    def K(self) -> FloatArray:
        """(3, 3) float: ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (a fresh array)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points_cam: npt.ArrayLike) -> FloatArray:
        """Project points in the optical frame to pixels of the raw image.

        Parameters
        ----------
        points_cam : (3,) or (N, 3) float
            Points in the camera optical frame (x right, y down, z forward), any unit.

        Returns
        -------
        (2,) or (N, 2) float
            Pixels ``(u, v)``. NaN for points with ``z <= 0`` (behind or in the plane of the
            camera center), beyond the distortion fold (see the class notes), or holding NaN.

        Raises
        ------
        CameraModelError
            If ``points_cam`` has another shape or is not numeric.
        """
        return self._project(points_cam, jacobian=False)[0]

    def project_with_jacobian(self, points_cam: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Project points and return ``J_px_point = d(pixel)/d(point)`` from the same pass.

        ``J = diag(fx, fy) @ J_d_n @ J_n_point`` with the distortion Jacobian ``J_d_n`` (2x2) and
        ``J_n_point = [[1/z, 0, -x/z^2], [0, 1/z, -y/z^2]]`` of the perspective division.

        Parameters
        ----------
        points_cam : (3,) or (N, 3) float
            Points in the camera optical frame.

        Returns
        -------
        pixels : (2,) or (N, 2) float
            As :meth:`project`.
        J_px_point : (2, 3) or (N, 2, 3) float
            Pixels per unit of point coordinate; NaN wherever the pixel is NaN.

        Raises
        ------
        CameraModelError
            If ``points_cam`` has another shape or is not numeric.
        """
        pixels, J_px_point = self._project(points_cam, jacobian=True)
        assert J_px_point is not None
        return pixels, J_px_point

    def _project(
        self, points_cam: npt.ArrayLike, jacobian: bool
    ) -> tuple[FloatArray, FloatArray | None]:
        points, single = as_vectors(points_cam, 3, "points_cam")
        x, y, z = points[:, 0], points[:, 1], points[:, 2]
        with np.errstate(all="ignore"):
            inv_z = 1.0 / z
            a, b = x * inv_z, y * inv_z
            valid = (z > 0.0) & (a * a + b * b < self._max_radius**2)
            all_valid = bool(valid.all())
            if not all_valid:
                a, b, inv_z = (np.where(valid, c, np.nan) for c in (a, b, inv_z))
            xd, yd, J_d_n = self._distort(a, b, jacobian)
        pixels = np.empty((len(a), 2))
        pixels[:, 0] = self.fx * xd + self.cx
        pixels[:, 1] = self.fy * yd + self.cy
        if not jacobian:
            return (pixels[0] if single else pixels), None
        J_n_point = np.zeros((len(a), 2, 3))
        J_n_point[:, 0, 0] = inv_z
        J_n_point[:, 1, 1] = inv_z
        J_n_point[:, 0, 2] = -a * inv_z
        J_n_point[:, 1, 2] = -b * inv_z
        J_px_point = J_n_point if J_d_n is None else J_d_n @ J_n_point
        J_px_point *= np.array([[self.fx], [self.fy]])
        if not all_valid:
            J_px_point[~valid] = np.nan
        return (pixels[0], J_px_point[0]) if single else (pixels, J_px_point)

    def undistort(self, pixels: npt.ArrayLike) -> FloatArray:
        """Normalized coordinates of raw-image pixels: the inverse of :meth:`project` up to depth.

        Parameters
        ----------
        pixels : (2,) or (N, 2) float
            Pixels ``(u, v)`` of the raw (distorted) image.

        Returns
        -------
        (2,) or (N, 2) float
            ``(x / z, y / z)`` of the points that project there, on the undistorted image plane
            ``z = 1`` of the optical frame. NaN where no point in the model's domain projects to
            the pixel (far outside the image, beyond the fold) or the pixel holds NaN.

        Raises
        ------
        CameraModelError
            If ``pixels`` has another shape or is not numeric.

        Notes
        -----
        Solved in numpy to ~1e-15 (normalized units), not with ``cv2.undistortPoints``: the
        radial part is inverted exactly with a bracketed Newton iteration (``_radial.invert``)
        and tangential terms are removed with 2-D Newton steps.
        """
        px, single = as_vectors(pixels, 2, "pixels")
        with np.errstate(all="ignore"):
            xd = (px[:, 0] - self.cx) / self.fx
            yd = (px[:, 1] - self.cy) / self.fy
            x, y = self._undistort_normalized(xd, yd)
        normalized = np.stack([x, y], axis=-1)
        return normalized[0] if single else normalized

    def rays(self, pixels: npt.ArrayLike) -> FloatArray:
        """Unit bearing vectors in the optical frame of raw-image pixels.

        Parameters
        ----------
        pixels : (2,) or (N, 2) float
            Pixels ``(u, v)`` of the raw image.

        Returns
        -------
        (3,) or (N, 3) float
            ``(x, y, 1) / |(x, y, 1)|`` for the normalized coordinates of :meth:`undistort`
            (so ``z > 0``); NaN where :meth:`undistort` is NaN.

        Raises
        ------
        CameraModelError
            If ``pixels`` has another shape or is not numeric.
        """
        normalized = self.undistort(pixels)
        xyz = np.concatenate([normalized, np.ones((*normalized.shape[:-1], 1))], axis=-1)
        rays: FloatArray = xyz / np.linalg.norm(xyz, axis=-1, keepdims=True)
        return rays

    def in_image(self, pixels: npt.ArrayLike, margin: float = 0.0) -> BoolArray:
        """Which pixels lie on the image, at least ``margin`` pixels inside its border.

        The image area is ``[-0.5, width - 0.5] x [-0.5, height - 0.5]`` (pixel centers at
        integers, so the outer edge of the border pixels is half a pixel out).

        Parameters
        ----------
        pixels : (2,) or (N, 2) float
            Pixels ``(u, v)``.
        margin : float
            Distance in pixels to keep from the border (negative widens the area).

        Returns
        -------
        () or (N,) bool
            False for NaN pixels.
        """
        px, single = as_vectors(pixels, 2, "pixels")
        m = _fields.finite_float(margin, "in_image.margin")
        u, v = px[:, 0], px[:, 1]
        inside = (u >= m - 0.5) & (v >= m - 0.5)
        inside &= (u <= self.width - 0.5 - m) & (v <= self.height - 0.5 - m)
        return inside[0] if single else inside

    def scaled(self, factor: float) -> Self:
        """The model of the same camera for its image resized by ``factor``.

        Follows ``cv2.resize`` geometry (pixel areas scale about the image corner):
        ``f' = f s``, ``c' = (c + 0.5) s - 0.5``; distortion coefficients are unchanged.

        Parameters
        ----------
        factor : float
            Scale ``s > 0`` such that ``width * s`` and ``height * s`` are whole pixels.

        Raises
        ------
        CameraModelError
            If ``factor`` is not positive or gives a fractional image size.
        """
        s = _fields.positive_float(factor, "scaled.factor")
        width, height = self.width * s, self.height * s
        if abs(width - round(width)) > 1e-6 or abs(height - round(height)) > 1e-6:
            raise CameraModelError(
                f"scaled.factor: {s:g} turns the {self.width}x{self.height} image into "
                f"{width:g}x{height:g} pixels; choose a factor that gives whole pixels"
            )
        return dataclasses.replace(
            self,
            width=round(width),
            height=round(height),
            fx=self.fx * s,
            fy=self.fy * s,
            cx=(self.cx + 0.5) * s - 0.5,
            cy=(self.cy + 0.5) * s - 0.5,
        )

    def to_camera_info(self) -> dict[str, Any]:
        """A ROS ``sensor_msgs/CameraInfo``-shaped dict (no header) describing this model.

        ``R`` is the identity and ``P = [K | 0]``: the model describes the raw image, not a
        rectified one. :func:`~tagloc.camera.from_camera_info` reads it back to an equal model.
        """
        K = self.K
        return {
            "width": self.width,
            "height": self.height,
            "distortion_model": self._ROS_MODEL,
            "D": self.dist_coeffs.tolist(),
            "K": K.reshape(-1).tolist(),
            "R": np.eye(3).reshape(-1).tolist(),
            "P": np.hstack([K, np.zeros((3, 1))]).reshape(-1).tolist(),
            "binning_x": 0,
            "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
        }
