"""Kalibr camchain files (``camchain.yaml``, ``cameras.yaml``) to camera models.

A camchain maps camera names (``cam0``, ``cam1``, ...) to entries with ``camera_model``,
``intrinsics``, ``distortion_model``, ``distortion_coeffs`` and ``resolution``; see
:func:`tagloc.camera.from_kalibr` for the fields read. Extrinsics (``T_cn_cnm1``, ``T_cam_imu``)
are not read here.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from tagloc.camera import CameraModel, from_kalibr
from tagloc.config import parse_yaml, read_text_file
from tagloc.errors import CameraModelError, ConfigError


def load_kalibr_cameras(path: str | os.PathLike[str]) -> dict[str, CameraModel]:
    """Read every camera of a Kalibr camchain yaml.

    Parameters
    ----------
    path : str or PathLike
        The yaml file.

    Returns
    -------
    dict of str to CameraModel
        Camera name (``cam0``, ...) to model, in file order.

    Raises
    ------
    CameraModelError
        If the file cannot be read (or is larger than :data:`tagloc.config.MAX_YAML_BYTES`, or
        not UTF-8), is not YAML, is not a non-empty mapping of camera entries, or an entry is
        invalid; the message starts with the path, then the field path
        (``"cameras.yaml: cam0.distortion_coeffs: expected 4 values for equidistant, got 5"``).
    """
    path = Path(path)
    data = read_camera_yaml(path)
    if not isinstance(data, Mapping) or not data:
        raise CameraModelError(
            f"{path}: expected a mapping of camera names (cam0, cam1, ...) to Kalibr camera "
            f"entries, got {type(data).__name__ if data is not None else 'an empty file'}"
        )
    cameras: dict[str, CameraModel] = {}
    for name, entry in data.items():
        try:
            cameras[str(name)] = from_kalibr(entry, name=str(name))
        except CameraModelError as exc:
            raise CameraModelError(f"{path}: {exc}") from exc
    return cameras


def read_camera_yaml(path: Path) -> object:
    """The YAML document of a camera file; a :class:`CameraModelError` naming the file where it
    cannot be read or is not YAML."""
    text = read_text_file(path, "the camera file", error=CameraModelError)
    try:
        return parse_yaml(text, str(path))
    except ConfigError as exc:
        raise CameraModelError(str(exc)) from None
