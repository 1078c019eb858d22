"""The :class:`CameraModel` protocol, the array conventions it uses, and :func:`check_image`.

Frames and units (see :mod:`tagloc.camera`): points are in the camera optical frame (x right,
y down, z forward, metres); pixels are ``(u, v)`` with the center of the top-left pixel at
``(0, 0)``; normalized coordinates are ``(x / z, y / z)`` on the undistorted image plane ``z = 1``.
"""

from __future__ import annotations

from typing import Any, Protocol, TypeAlias

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import CameraModelError

BoolArray: TypeAlias = npt.NDArray[np.bool_]


class CameraModel(Protocol):
    """A calibrated camera: maps points in its optical frame to pixels of its raw image and back.

    Implemented by :class:`~tagloc.camera.PinholeRadtan` (OpenCV / ROS ``plumb_bob``) and
    :class:`~tagloc.camera.PinholeEquidistant` (``cv2.fisheye``, Kannala-Brandt). Every method
    accepts one point (``(3,)`` or ``(2,)``) or a batch (``(N, 3)`` or ``(N, 2)``) and returns the
    matching shape.

    **Domain.** A point is projected only if it is in front of the camera (``z > 0``) and inside the
    model's monotone region (before the radius at which the distortion polynomial folds back);
    any other point -- and any NaN input -- gives NaN, never a mirrored or folded pixel. Likewise a
    pixel that no point in the domain projects to gives NaN from :meth:`undistort` and
    :meth:`rays`.
    """

    @property
    def width(self) -> int:
        """Image width in pixels."""
        ...

    @property
    def height(self) -> int:
        """Image height in pixels."""
        ...

    @property
    def distortion_model(self) -> str:
        """``"radtan"`` or ``"equidistant"`` (Kalibr's names)."""
        ...

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels (OpenCV's ``imageSize`` order)."""
        ...

    @property
    def K(self) -> FloatArray:
        """(3, 3) float: the camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        ...

    @property
    def dist_coeffs(self) -> FloatArray:
        """(n,) float: distortion coefficients in OpenCV's order for this model."""
        ...

    def project(self, points_cam: npt.ArrayLike) -> FloatArray:
        """Pixels ``(N, 2)`` of points ``(N, 3)`` in the optical frame; NaN outside the domain."""
        ...

    def project_with_jacobian(self, points_cam: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Pixels ``(N, 2)`` and ``J_px_point = d(pixel)/d(point)`` ``(N, 2, 3)``."""
        ...

    def undistort(self, pixels: npt.ArrayLike) -> FloatArray:
        """Normalized coordinates ``(x/z, y/z)`` ``(N, 2)`` of raw-image pixels ``(N, 2)``."""
        ...

    def rays(self, pixels: npt.ArrayLike) -> FloatArray:
        """Unit bearing vectors ``(N, 3)`` in the optical frame of pixels ``(N, 2)``."""
        ...

    def in_image(self, pixels: npt.ArrayLike, margin: float = 0.0) -> BoolArray:
        """``(N,)`` mask of finite pixels at least ``margin`` inside the image area."""
        ...

    def scaled(self, factor: float) -> CameraModel:
        """The same camera for the image resized by ``factor`` (``cv2.resize`` geometry)."""
        ...

    def to_camera_info(self) -> dict[str, Any]:
        """A ROS ``sensor_msgs/CameraInfo``-shaped dict, read back by ``from_camera_info``."""
        ...


def as_vectors(value: npt.ArrayLike, dim: int, name: str) -> tuple[FloatArray, bool]:
    """``value`` as an ``(N, dim)`` float64 array, and whether it was a single ``(dim,)`` vector.

    NaN is allowed (it propagates to NaN outputs); no copy is made when ``value`` already is one.

    Raises
    ------
    CameraModelError
        If ``value`` is not numeric or its shape is neither ``(dim,)`` nor ``(N, dim)``.
    """
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CameraModelError(f"{name}: cannot be read as a float array ({exc})") from exc
    if array.ndim == 1 and array.shape[0] == dim:
        return array[None, :], True
    if array.ndim == 2 and array.shape[1] == dim:
        return array, False
    raise CameraModelError(f"{name}: expected shape ({dim},) or (N, {dim}), got {array.shape}")


def check_image(image: npt.ArrayLike, camera: CameraModel, name: str = "image") -> npt.ArrayLike:
    """Return ``image`` unchanged if its size matches ``camera``; raise otherwise.

    Parameters
    ----------
    image : (height, width) or (height, width, channels) array
        A raw (distorted) image, as OpenCV and the detectors take it.
    camera : CameraModel
        The model the image is meant to be used with.
    name : str
        What to call the image in the message (a topic, a file name).

    Returns
    -------
    The same ``image`` object.

    Raises
    ------
    CameraModelError
        If ``image`` is not 2-D or 3-D, or its ``(width, height)`` differs from
        ``camera.image_size`` (the message names both sizes).
    """
    shape = np.shape(image)
    if len(shape) not in (2, 3):
        raise CameraModelError(
            f"{name}: expected an array of shape (height, width) or (height, width, channels), "
            f"got shape {shape}"
        )
    height, width = int(shape[0]), int(shape[1])
    if (width, height) != camera.image_size:
        model_w, model_h = camera.image_size
        raise CameraModelError(
            f"{name}: image is {width}x{height} (width x height) but the camera model is "
            f"{model_w}x{model_h}; resize the model with camera.scaled(factor) or use the "
            f"calibration for this resolution"
        )
    return image
