"""Camera models: project points to pixels, undistort pixels to rays, from ROS or Kalibr records.

Conventions (the same as :mod:`tagloc.geometry` and ``docs/CONVENTIONS.md``):

- Points are in the camera **optical frame**: x right, y down, z forward (``points_cam``).
- Pixels are ``(u, v)`` with the **center** of the top-left pixel at ``(0, 0)`` (OpenCV); the
  image area is ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.
- **Normalized** coordinates are ``(x / z, y / z)`` on the undistorted image plane ``z = 1``.
- **Domain**: a model projects a point only if ``z > 0`` and it lies before the distortion
  polynomial's fold; anything else, and NaN input, gives NaN (never a mirrored pixel).
- Jacobians are named output-wrt-input and come from the same call as the value:
  ``pixels, J_px_point = camera.project_with_jacobian(points_cam)``.

Models: :class:`PinholeRadtan` (OpenCV / ROS ``plumb_bob``, Kalibr ``radtan``) and
:class:`PinholeEquidistant` (``cv2.fisheye``, ROS and Kalibr ``equidistant``), both implementing
the :class:`CameraModel` protocol; frozen value types. The math is vectorized numpy (the Jacobian
comes from the same pass); the tests hold it to ``cv2.projectPoints``, ``cv2.fisheye`` and
``cv2.undistortPoints``.

Example
-------
>>> camera = from_kalibr({"camera_model": "pinhole", "intrinsics": [600, 600, 640, 512],
...                       "distortion_model": "equidistant", "distortion_coeffs": [0, 0, 0, 0],
...                       "resolution": [1280, 1024]})
>>> camera.project([[0.0, 0.0, 2.0]]).tolist()
[[640.0, 512.0]]
"""

from tagloc.camera.calibration import from_camera_info, from_kalibr
from tagloc.camera.equidistant import PinholeEquidistant
from tagloc.camera.model import CameraModel, check_image
from tagloc.camera.radtan import PinholeRadtan

__all__ = [
    "CameraModel",
    "PinholeEquidistant",
    "PinholeRadtan",
    "check_image",
    "from_camera_info",
    "from_kalibr",
]
