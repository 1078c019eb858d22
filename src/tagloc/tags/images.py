"""Checking and converting the images handed to a detector (one place, one policy).

Policy
------
Accepted, converted to a C-contiguous ``(H, W) uint8`` gray image:

- ``(H, W)`` or ``(H, W, 1)`` ``uint8``: used as is (copied only if not C-contiguous: slices,
  ``[::2]`` views and transposes are fine).
- ``(H, W, 3)``: **BGR**, OpenCV's channel order (what ``cv2.imread`` and most ROS ``bgr8``
  bridges give), converted with ``cv2.cvtColor(COLOR_BGR2GRAY)``. An RGB image is read with the red
  and blue weights swapped (0.114 vs 0.299); tag edges are black on white, so detection does not
  care, but convert it yourself if you need exact luma.
- ``(H, W, 4)``: **BGRA** (``cv2.imread(..., IMREAD_UNCHANGED)`` of a PNG with alpha); the alpha
  channel is dropped, not composited.
- ``float32``/``float64`` with every value finite and in ``[0, 1]``: scaled by 255 and rounded.

Refused with :class:`~tagloc.tags.errors.TagInputError` (the message names what is wrong):
anything that is not a numpy array, an empty image, 1-D or 4-D+ arrays, 2 or 5+ channels, any
other dtype (``uint16`` and friends: the bit depth in use is unknown here, so scale to ``uint8``
yourself), and float images with NaN/inf or values outside ``[0, 1]``.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from tagloc.tags.errors import TagInputError

GrayImage = npt.NDArray[np.uint8]

#: Images with a side shorter than this cannot hold a tag (tag16h5 with its quiet zone needs 8
#: cells at >= 1 px each); backends return no detections for them without calling the library.
MIN_IMAGE_SIDE_PX = 10


def as_gray_u8(image: Any, name: str = "image") -> GrayImage:
    """Check ``image`` and return it as a C-contiguous ``(H, W) uint8`` gray image.

    Parameters
    ----------
    image : (H, W), (H, W, 1), (H, W, 3) BGR or (H, W, 4) BGRA array
        ``uint8``, or float in ``[0, 1]``; see the module docstring for the full policy.
    name : str
        How the message of an error calls the argument.

    Returns
    -------
    (H, W) uint8, C-contiguous
        The input itself when it already is one, else a new array.

    Raises
    ------
    TagInputError
        If the image is not usable (the message says why).
    """
    if not isinstance(image, np.ndarray):
        raise TagInputError(f"{name}: expected a numpy array, got {type(image).__name__}")
    if image.size == 0:
        raise TagInputError(f"{name}: empty image (shape {image.shape})")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 3 and image.shape[2] not in (3, 4):
        raise TagInputError(
            f"{name}: {image.shape[2]} channels (shape {image.shape}); expected gray (H, W), "
            "BGR (H, W, 3) or BGRA (H, W, 4)"
        )
    if image.ndim not in (2, 3):
        raise TagInputError(
            f"{name}: {image.ndim}-D array (shape {image.shape}); expected gray (H, W), "
            "BGR (H, W, 3) or BGRA (H, W, 4)"
        )
    image = _to_uint8(image, name)
    image = np.ascontiguousarray(image)
    if image.ndim == 3:
        code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        image = cv2.cvtColor(image, code)
    return np.asarray(image, dtype=np.uint8)


def _to_uint8(image: npt.NDArray[Any], name: str) -> npt.NDArray[np.uint8]:
    """``image`` as ``uint8`` under the dtype policy of the module docstring."""
    if image.dtype == np.uint8:
        return image
    if image.dtype.kind != "f":
        raise TagInputError(
            f"{name}: dtype {image.dtype} not supported; pass uint8 (or float in [0, 1]); "
            "scale deeper images to uint8 yourself, tagloc cannot know the bit depth in use"
        )
    if not np.isfinite(image).all():
        raise TagInputError(f"{name}: float image holds NaN or infinite values")
    lo, hi = float(image.min()), float(image.max())
    if lo < 0.0 or hi > 1.0:
        raise TagInputError(
            f"{name}: float image must lie in [0, 1], found values in [{lo:g}, {hi:g}]"
        )
    return np.rint(image * 255.0).astype(np.uint8)
