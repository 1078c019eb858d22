"""The sensor records of the stream: camera images and calibration, detected tags, lidar sweeps
and the elevator controller's state (conventions in :mod:`tagloc.messages`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, TypeAlias

import numpy as np
import numpy.typing as npt

from tagloc.errors import RecordError
from tagloc.messages._checks import (
    _check_stamp_frame,
    _describe,
    _float32,
    _frame,
    _frozen,
    _set,
    _stamp,
)
from tagloc.tags.detection import TagDetection

__all__ = [
    "IMAGE_ENCODINGS",
    "CameraInfoMsg",
    "ElevatorStateMsg",
    "ImageMsg",
    "PointCloudMsg",
    "TagDetectionsMsg",
]

UInt8Array: TypeAlias = npt.NDArray[np.uint8]

_INFO_KEYS = {"d": "D", "k": "K", "r": "R", "p": "P"}
#: Image encodings a record may carry, with the number of channels each has.
IMAGE_ENCODINGS: Mapping[str, int] = MappingProxyType({"mono8": 1, "bgr8": 3})


@dataclass(frozen=True, slots=True, eq=False)
class ImageMsg:
    """One camera image (ROS ``sensor_msgs/Image`` or ``CompressedImage``).

    Attributes
    ----------
    frame_id : str
        The camera's optical frame.
    image : (H, W) or (H, W, 3) uint8, read-only
        ``mono8`` or ``bgr8`` (OpenCV channel order); see :data:`IMAGE_ENCODINGS`.
    encoding : {"mono8", "bgr8"}
        Must agree with the shape of ``image``.
    """

    stamp_ns: int
    frame_id: str
    image: UInt8Array
    encoding: str

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        image, channels = self.image, IMAGE_ENCODINGS.get(self.encoding)
        if channels is None:
            raise RecordError(f"ImageMsg.encoding: {self.encoding!r} is not mono8 or bgr8")
        shape = "(H, W)" if channels == 1 else "(H, W, 3)"
        if (
            not isinstance(image, np.ndarray)
            or image.dtype != np.uint8
            or not image.size
            or (image.shape[2:] != ((3,) if channels == 3 else ()) or image.ndim < 2)
        ):
            raise RecordError(
                f"ImageMsg.image: expected a non-empty {shape} uint8 array for {self.encoding}, "
                f"got {_describe(image)}"
            )
        if image.flags.writeable:  # the caller's array: keep a read-only copy
            image = image.copy()
            image.flags.writeable = False
        _set(self, "image", image)


@dataclass(frozen=True, slots=True, eq=False)
class CameraInfoMsg:
    """Calibration of a camera (ROS ``sensor_msgs/CameraInfo``).

    Attributes
    ----------
    frame_id : str
    info : Mapping, read-only
        The ``CameraInfo`` fields in the shape :meth:`tagloc.camera.CameraModel.to_camera_info`
        writes and :func:`tagloc.camera.from_camera_info` reads: ``width``, ``height``,
        ``distortion_model``, ``D``, ``K`` (9, row-major), ``R`` (9), ``P`` (12),
        ``binning_x``, ``binning_y``, ``roi`` (a mapping ``x_offset, y_offset, height, width,
        do_rectify``). ``width``, ``height``, ``distortion_model``, ``D`` and ``K`` are required;
        ROS 2's lower-case ``d``, ``k``, ``r``, ``p`` are renamed to upper case. Sequences are
        stored as tuples.
    """

    stamp_ns: int
    frame_id: str
    info: Mapping[str, Any]

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        if not isinstance(self.info, Mapping):
            raise RecordError(f"CameraInfoMsg.info: expected a mapping, got {_describe(self.info)}")
        info = {_INFO_KEYS.get(str(k), str(k)): v for k, v in self.info.items()}
        missing = [k for k in ("width", "height", "distortion_model", "D", "K") if k not in info]
        if missing:
            raise RecordError(f"CameraInfoMsg.info: missing field(s) {missing}")
        _set(self, "info", _frozen(info))


@dataclass(frozen=True, slots=True, eq=False)
class TagDetectionsMsg:
    """Tags detected in one image, corners in tagloc's convention (:class:`TagDetection`).

    Attributes
    ----------
        Stamp of the image the tags were found in.
    frame_id : str
        That image's optical frame.
    detections : tuple of TagDetection
        Possibly empty (an image in which no tag was seen).
    """

    stamp_ns: int
    frame_id: str
    detections: tuple[TagDetection, ...]

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        detections = tuple(self.detections)
        if not all(isinstance(d, TagDetection) for d in detections):
            raise RecordError("TagDetectionsMsg.detections: expected TagDetection items only")
        _set(self, "detections", detections)


@dataclass(frozen=True, slots=True, eq=False)
class PointCloudMsg:
    """One lidar sweep (ROS ``sensor_msgs/PointCloud2`` with float32 fields x, y, z [, intensity]
    [, t]).

    Attributes
    ----------
    stamp_ns : int
        The sweep's *start*; point ``i`` was measured at ``stamp_ns + time_offset_s[i] * 1e9``.
    frame_id : str
        The scanner frame (``lidar``) at the time of *each* point: the points are raw (skewed by
        the motion during the sweep), as a driver publishes them; see
        ``tagloc.lidar.cloud.deskew``.
    points : (N, 3) float32, read-only
        Metres, x forward, y left, z up. A row may be NaN (a beam without return): consumers
        drop such rows. N may be 0.
    intensity : (N,) float32, read-only, or None
        Return strength (driver units); None when the source has none.
    time_offset_s : (N,) float32, read-only, or None
        Seconds after ``stamp_ns``, finite and ``>= 0``; None: every point at ``stamp_ns``.
    """

    stamp_ns: int
    frame_id: str
    points: npt.NDArray[np.float32]
    intensity: npt.NDArray[np.float32] | None = None
    time_offset_s: npt.NDArray[np.float32] | None = None

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        points = _float32(self, "points")
        if points.ndim != 2 or points.shape[1] != 3:
            raise RecordError(f"PointCloudMsg.points: expected shape (N, 3), got {points.shape}")
        _set(self, "points", points)
        n = len(points)
        for name in ("intensity", "time_offset_s"):
            if getattr(self, name) is None:
                continue
            values = _float32(self, name)
            if values.shape != (n,):
                raise RecordError(
                    f"PointCloudMsg.{name}: expected shape ({n},) like points, got {values.shape}"
                )
            if (
                name == "time_offset_s"
                and n
                and not (np.isfinite(values).all() and values.min() >= 0)
            ):
                raise RecordError("PointCloudMsg.time_offset_s: must be finite and >= 0")
            _set(self, name, values)

    def last_point_ns(self) -> int:
        """When the last point was measured, ns: the earliest a driver can publish the sweep
        (``stamp_ns`` without time offsets or points)."""
        if self.time_offset_s is None or not len(self.points):
            return self.stamp_ns
        return self.stamp_ns + round(float(self.time_offset_s.max()) * 1e9)


@dataclass(frozen=True, slots=True, eq=False)
class ElevatorStateMsg:
    """What a building's elevator controller tells: one cab's door and where it stands.

    Attributes
    ----------
    cab_frame : str
        The cab's frame (``elevator_cab``; one frame per cab), whose state this is.
    door_open : bool
        The cab's door is open (at least half-way).
    floor : str or None
        The floor the cab stands at, None while it moves between floors.
    """

    stamp_ns: int
    cab_frame: str
    door_open: bool
    floor: str | None = None

    def __post_init__(self) -> None:
        _set(self, "stamp_ns", _stamp(self))
        _frame(self, "cab_frame")
        if not isinstance(self.door_open, bool | np.bool_):
            raise RecordError(
                f"ElevatorStateMsg.door_open: expected a bool, got {_describe(self.door_open)}"
            )
        _set(self, "door_open", bool(self.door_open))
        if self.floor is not None and (not isinstance(self.floor, str) or not self.floor):
            raise RecordError(
                "ElevatorStateMsg.floor: expected a floor name or None, got "
                f"{_describe(self.floor)}"
            )
