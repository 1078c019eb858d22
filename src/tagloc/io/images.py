"""Image files and camera files for single-image tools (``tagloc detect``).

- :func:`read_image`: a PNG/JPEG/... file as a uint8 array (gray or BGR); a file OpenCV cannot
  decode is one line naming it, never a traceback.
- :func:`image_files`: the images of a directory, sorted by name.
- :func:`write_image`: an image written atomically (the format from the suffix).
- :func:`load_camera_file`: a camera model from a Kalibr camchain (its first camera), a ROS
  ``camera_calibration`` file (``image_width``, ``camera_matrix``, ``distortion_model``,
  ``distortion_coefficients``, as ``cameracalibrator`` saves it) or a ``CameraInfo``-shaped
  mapping (``width``, ``height``, ``K``, ``D``, ``distortion_model``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel, from_camera_info
from tagloc.errors import CameraModelError
from tagloc.fileutil import atomic_path
from tagloc.io.errors import InputNotFoundError, TaglocIOError
from tagloc.io.kalibr import load_kalibr_cameras, read_camera_yaml

__all__ = [
    "IMAGE_SUFFIXES",
    "ImageFileError",
    "image_files",
    "load_camera_file",
    "read_image",
    "write_image",
]

#: Suffixes :func:`image_files` picks from a directory.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
#: Larger files are refused before decoding (a 12-bit 50 MP raw is ~100 MB).
MAX_IMAGE_BYTES = 512 << 20


class ImageFileError(TaglocIOError, ValueError):
    """A file that is not an image OpenCV can read, or an image that cannot be written."""


def read_image(path: str | os.PathLike[str]) -> npt.NDArray[np.uint8]:
    """The image at ``path``: ``(H, W)`` gray or ``(H, W, 3)`` BGR, uint8 (16-bit scaled down).

    Raises
    ------
    InputNotFoundError
        If there is no file.
    ImageFileError
        If it is too large or not an image OpenCV decodes (one line naming the file).
    """
    path = Path(path)
    if not path.is_file():
        raise InputNotFoundError(f"{path}: no such image file")
    if path.stat().st_size > MAX_IMAGE_BYTES:
        raise ImageFileError(f"{path}: larger than {MAX_IMAGE_BYTES >> 20} MiB; not read")
    data = np.fromfile(path, dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR) if data.size else None
    if image is None:
        raise ImageFileError(f"{path}: not an image (OpenCV cannot decode it: png, jpg, ...)")
    if image.dtype == np.uint16:
        image = (np.asarray(image, np.uint16) >> 8).astype(np.uint8)
    if image.dtype != np.uint8:
        raise ImageFileError(f"{path}: {image.dtype} pixels; expected 8 or 16 bits")
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return np.ascontiguousarray(image)


def image_files(directory: str | os.PathLike[str]) -> list[Path]:
    """The files of ``directory`` with an image suffix (:data:`IMAGE_SUFFIXES`), by name."""
    root = Path(directory)
    return sorted(p for p in root.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def write_image(path: str | os.PathLike[str], image: npt.NDArray[np.uint8]) -> None:
    """Write ``image`` (gray or BGR uint8) to ``path`` atomically; the suffix picks the format."""
    path = Path(path)
    ok, encoded = cv2.imencode(path.suffix or ".png", image)
    if not ok:
        raise ImageFileError(f"{path}: OpenCV cannot encode an image as {path.suffix!r}")
    with atomic_path(path) as tmp:
        tmp.write_bytes(encoded.tobytes())


def load_camera_file(path: str | os.PathLike[str]) -> CameraModel:
    """The camera model in ``path`` (module docstring for the three forms).

    Raises
    ------
    CameraModelError
        One line naming the file and the field that is wrong or missing.
    """
    path = Path(path)
    data = read_camera_yaml(path)
    if not isinstance(data, Mapping):
        raise CameraModelError(f"{path}: expected a camera calibration mapping")
    try:
        if "camera_matrix" in data:
            return from_camera_info(_ros_calibration(data, path), name=str(path))
        if "K" in data or "k" in data:
            return from_camera_info(data, name=str(path))
    except CameraModelError as exc:
        raise CameraModelError(str(exc)) from None
    return next(iter(load_kalibr_cameras(path).values()))


def _ros_calibration(data: Mapping[str, Any], path: Path) -> dict[str, Any]:
    """A ``camera_calibration`` file's fields as a ``CameraInfo`` mapping."""

    def matrix(key: str) -> Any:
        value = data.get(key)
        return value.get("data") if isinstance(value, Mapping) else value

    return {
        "width": data.get("image_width"),
        "height": data.get("image_height"),
        "distortion_model": data.get("distortion_model"),
        "D": matrix("distortion_coefficients"),
        "K": matrix("camera_matrix"),
    }
