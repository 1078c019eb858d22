"""The typed, timestamped records of tagloc's message stream, and its source and sink protocols.

A low layer (it needs only geometry and the tag detection type) so that every consumer of the
stream (the localizer, the map builder, the simulator, the bag reader and writer) shares it;
``tagloc.io`` re-exports the records for users who read and write bags.

Everything that happens is a time-ordered stream of these records (``docs/DESIGN.md``, *Data
flow*): a bag (:class:`tagloc.io.BagSource`) and the simulator are two :class:`MessageSource` s of
it, a bag writer (:class:`tagloc.io.BagSink`) is a :class:`MessageSink`. A stream item is a
``(topic, record)`` pair, so copying is ``for topic, msg in source: sink.write(topic, msg)``.

Conventions (``docs/CONVENTIONS.md``): ``stamp_ns`` (first field of every record) is integer
nanoseconds ``>= 0``, the time the data refers to (a header stamp, not the log time). Poses are
single :class:`~tagloc.geometry.SE3` named for their frames (``T_parent_child`` maps ``child``
points into ``parent``). Every 6x6 covariance is ordered ``[x, y, z, rx, ry, rz]`` in the *body*
(right) tangent, ``T (+) xi = T @ Exp(xi)``; ROS uses the same order but the parent frame's axes,
and :mod:`tagloc.io.convert` rotates between the two. Images follow OpenCV: ``mono8`` ``(H, W)``,
``bgr8`` ``(H, W, 3)``, uint8. Records are frozen, slotted dataclasses with read-only arrays;
equality is identity (arrays inside): compare fields with ``allclose``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from types import MappingProxyType, TracebackType
from typing import Any, Protocol, Self, TypeAlias, get_args

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import RecordError
from tagloc.geometry import SE3
from tagloc.tags.detection import TagDetection

__all__ = [
    "IMAGE_ENCODINGS",
    "MESSAGE_TYPES",
    "CameraInfoMsg",
    "ElevatorStateMsg",
    "FrameTruth",
    "GroundTruthMsg",
    "ImageMsg",
    "Message",
    "MessageSink",
    "MessageSource",
    "NodeTopics",
    "OdometryMsg",
    "PointCloudMsg",
    "PoseWithCovarianceMsg",
    "TagDetectionsMsg",
    "TransformMsg",
]

UInt8Array: TypeAlias = npt.NDArray[np.uint8]

_INFO_KEYS = {"d": "D", "k": "K", "r": "R", "p": "P"}
#: Image encodings a record may carry, with the number of channels each has.
IMAGE_ENCODINGS: Mapping[str, int] = MappingProxyType({"mono8": 1, "bgr8": 3})


@dataclass(frozen=True, slots=True, eq=False)
class OdometryMsg:
    """Odometry of ``child_frame_id`` in ``frame_id`` (ROS ``nav_msgs/Odometry``).

    Attributes
    ----------
    frame_id : str
        The odometry origin (REP-105 ``odom``).
    child_frame_id : str
        The moving body (``base_link``).
    T_parent_child : SE3
        Pose of the child in the parent frame (``T_odom_base``).
    cov : (6, 6) float64, read-only
        Covariance of ``T_parent_child`` in its body tangent, ``[x, y, z, rx, ry, rz]``.
    twist : (6,) float64, read-only, or None
        ``[vx, vy, vz, wx, wy, wz]`` in ``child_frame_id`` (as ROS), m/s and rad/s; None when
        the source has none (written as zeros).
    """

    stamp_ns: int
    frame_id: str
    child_frame_id: str
    T_parent_child: SE3
    cov: FloatArray
    twist: FloatArray | None = None

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        _set(self, "child_frame_id", _frame(self, "child_frame_id"))
        _set(self, "T_parent_child", _pose(self, "T_parent_child"))
        _set(self, "cov", _array(self, "cov", (6, 6)))
        if self.twist is not None:
            _set(self, "twist", _array(self, "twist", (6,)))


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
class TransformMsg:
    """One edge of the transform tree (one ``TransformStamped`` of a ``/tf`` message).

    Attributes
    ----------
    parent, child : str
        Non-empty frame names.
    T_parent_child : SE3
    static : bool
        True for ``/tf_static`` edges (valid at every time).
    """

    stamp_ns: int
    parent: str
    child: str
    T_parent_child: SE3
    static: bool = False

    def __post_init__(self) -> None:
        _set(self, "stamp_ns", _stamp(self))
        for name in ("parent", "child"):
            if not _frame(self, name):
                raise RecordError(f"TransformMsg.{name}: must be a non-empty frame name")
        _set(self, "T_parent_child", _pose(self, "T_parent_child"))
        _set(self, "static", bool(self.static))


@dataclass(frozen=True, slots=True, eq=False)
class PoseWithCovarianceMsg:
    """A pose estimate with covariance (ROS ``geometry_msgs/PoseWithCovarianceStamped``).

    Attributes
    ----------
    frame_id : str
        The frame the pose is expressed in (``map``).
    T_frame_child : SE3
        The pose of the estimated body (``T_map_base``).
    cov : (6, 6) float64, read-only
        Body-tangent covariance, ``[x, y, z, rx, ry, rz]``.
    """

    stamp_ns: int
    frame_id: str
    T_frame_child: SE3
    cov: FloatArray

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        _set(self, "T_frame_child", _pose(self, "T_frame_child"))
        _set(self, "cov", _array(self, "cov", (6, 6)))


@dataclass(frozen=True, slots=True, eq=False)
class GroundTruthMsg:
    """The true pose of the robot (simulator truth; ROS ``geometry_msgs/PoseStamped``).

    Attributes
    ----------
    frame_id : str
        The frame the truth is expressed in (``map``).
    T_frame_child : SE3
        True pose of the body (``T_map_base``).
    """

    stamp_ns: int
    frame_id: str
    T_frame_child: SE3

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        _set(self, "T_frame_child", _pose(self, "T_frame_child"))


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


#: Any record of the stream.
Message: TypeAlias = (
    OdometryMsg | ImageMsg | CameraInfoMsg | TagDetectionsMsg | TransformMsg
    | PoseWithCovarianceMsg | GroundTruthMsg | PointCloudMsg | ElevatorStateMsg
)  # fmt: skip
MESSAGE_TYPES: tuple[type[Message], ...] = get_args(Message)


@dataclass(frozen=True, slots=True)
class NodeTopics:
    """Stream topic of each role the localizer reads (the simulator's and
    :class:`~tagloc.io.BagSink`'s defaults)."""

    odom: str = "/odom"
    detections: str = "/tag_detections"
    image: str = "/camera/image"
    camera_info: str = "/camera/camera_info"
    truth: str = "/ground_truth"
    tf: str = "/tf"
    lidar: str = "/lidar/points"
    #: The building's elevator state (:class:`ElevatorStateMsg`), where it provides one.
    elevator: str = "/elevator/state"


@dataclass(frozen=True, slots=True)
class FrameTruth:
    """Simulator truth of one camera frame, for the run record only (never for decisions).

    Attributes
    ----------
    false_detection : tuple of bool
        Per detection of the frame's ``TagDetectionsMsg``: injected (a glint) or real.
    nearest_visible_m : float
        Camera to the nearest tag truly in view, m (``inf``: none).
    """

    false_detection: tuple[bool, ...]
    nearest_visible_m: float


class MessageSource(Protocol):
    """A time-ordered stream of ``(topic, record)`` pairs (a bag, the simulator, a live feed).

    Iterating yields the stream from its start; a source that can be replayed (a file) starts
    over on each ``iter()``. Items come in non-decreasing *arrival* order (a bag's log time);
    ``stamp_ns`` increases strictly per topic (and per child frame on transform topics), but
    stamps of different topics may interleave out of order by the sensors' latencies.
    """

    @property
    def topics(self) -> Mapping[str, type[Message]]:
        """The topics this source yields, each with the record type it carries."""
        ...

    def __iter__(self) -> Iterator[tuple[str, Message]]:
        """Yield ``(topic, record)`` pairs in time order."""
        ...


class MessageSink(Protocol):
    """Where stream records go (a bag or MCAP writer, a live publisher); a context manager.

    ``close`` makes the output final; leaving the ``with`` block on an exception discards it.
    """

    def write(self, topic: str, msg: Message) -> None:
        """Append one record on ``topic``."""
        ...

    def close(self) -> None:
        """Finish the output (idempotent)."""
        ...

    def __enter__(self) -> Self: ...

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...


# ----- validation helpers ------------------------------------------------------------------------
def _set(record: object, name: str, value: object) -> None:
    object.__setattr__(record, name, value)


def _describe(value: object) -> str:
    if isinstance(value, np.ndarray):
        return f"{value.dtype} array of shape {value.shape}"
    return type(value).__name__


def _stamp(record: Any) -> int:
    value = record.stamp_ns
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise RecordError(
            f"{type(record).__name__}.stamp_ns: expected int nanoseconds, got {_describe(value)}"
        )
    if value < 0:
        raise RecordError(f"{type(record).__name__}.stamp_ns: must be >= 0, got {value}")
    return int(value)


def _frame(record: Any, name: str) -> str:
    value = getattr(record, name)
    if not isinstance(value, str):
        raise RecordError(f"{type(record).__name__}.{name}: expected a str, got {_describe(value)}")
    return value


def _check_stamp_frame(record: Any) -> None:
    _set(record, "stamp_ns", _stamp(record))
    _frame(record, "frame_id")  # may be empty: ROS allows it


def _pose(record: Any, name: str) -> SE3:
    value = getattr(record, name)
    if not isinstance(value, SE3) or value.batch_shape != ():
        raise RecordError(
            f"{type(record).__name__}.{name}: expected a single SE3, got "
            f"{'a batch' if isinstance(value, SE3) else _describe(value)}"
        )
    return value


def _array(record: Any, name: str, shape: tuple[int, ...]) -> FloatArray:
    where = f"{type(record).__name__}.{name}"
    try:
        array = np.array(getattr(record, name), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise RecordError(f"{where}: cannot be read as a float array ({exc})") from None
    if array.shape != shape:
        raise RecordError(f"{where}: expected shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        raise RecordError(f"{where}: holds NaN or infinite values")
    array.flags.writeable = False
    return array


def _float32(record: Any, name: str) -> npt.NDArray[np.float32]:
    """A read-only float32 copy of an array field (a read-only float32 array is kept as is)."""
    value = getattr(record, name)
    where = f"{type(record).__name__}.{name}"
    if isinstance(value, np.ndarray) and value.dtype == np.float32 and not value.flags.writeable:
        return value
    try:
        array = np.array(value, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise RecordError(f"{where}: cannot be read as a float32 array ({exc})") from None
    array.flags.writeable = False
    return array


def _frozen(value: Any) -> Any:
    """Lists and arrays to tuples of float/int, mappings to read-only mappings (recursively)."""
    if isinstance(value, Mapping):
        return MappingProxyType({str(k): _frozen(v) for k, v in value.items()})
    if isinstance(value, np.ndarray):
        return tuple(value.reshape(-1).tolist())
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(v) for v in value)
    if isinstance(value, np.generic):
        return value.item()
    return value
