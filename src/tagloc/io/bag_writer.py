"""Write tagloc records to an MCAP file, a ROS 2 bag or a ROS 1 bag, with standard message types.

:class:`BagSink` is a :class:`~tagloc.messages.MessageSink`. Records become:

======================  ========================================================================
OdometryMsg             ``nav_msgs/Odometry`` (twist None -> zeros; twist covariance zeros)
TransformMsg            ``tf2_msgs/TFMessage``, one transform each; ``static`` ones only on a
                        ``.../tf_static`` topic (latched in ROS 1, transient local in ROS 2)
PoseWithCovarianceMsg   ``geometry_msgs/PoseWithCovarianceStamped``
GroundTruthMsg          ``geometry_msgs/PoseStamped``
ImageMsg                ``sensor_msgs/Image`` (``mono8`` or ``bgr8``, no row padding)
CameraInfoMsg           ``sensor_msgs/CameraInfo`` (``R`` identity, ``P = [K | 0]`` if absent)
PointCloudMsg           ``sensor_msgs/PointCloud2``, one row (``height`` 1), little-endian float32
                        fields ``x, y, z`` [, ``intensity``] [, ``t`` (time offset, s)] packed
                        without padding; ``is_dense`` False when a row is NaN
TagDetectionsMsg        ROS 1 ``apriltag_msgs/ApriltagArrayStamped`` (the dupont type, no margin);
                        ROS 2 / MCAP ``apriltag_msgs/AprilTagDetectionArray`` (float32 margin,
                        homography zeros). Corners in tagloc's order ``tl_tr_br_bl``, offset 0:
                        :class:`BagSource`'s defaults read them back.
======================  ========================================================================

Covariances are rotated from tagloc's body tangent to ROS' parent-frame convention
(:func:`tagloc.io.convert.cov_ros_from_body`); stamps go to ``header.stamp`` and, unless given,
to the log time. Output is atomic: everything is written inside a temporary directory beside the
target and renamed into place by :meth:`BagSink.close`; on an exception inside the ``with``
block (or :meth:`BagSink.abort`, or garbage collection without ``close``) the temporary output
is removed and the target is left as it was. An existing directory at the target is never
removed, except a lone ROS 2 bag that a ``ros2`` output replaces (:mod:`tagloc.io.bag_output`).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import weakref
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, Self

import numpy as np

from tagloc.io.bag_output import BagFormat, check_bag_target, is_ros2_bag_directory
from tagloc.io.convert import TAGS_ROS1, TAGS_ROS2, cov_ros_from_body, make_typestore
from tagloc.io.errors import BagWriteError
from tagloc.messages import (
    MESSAGE_TYPES,
    CameraInfoMsg,
    ElevatorStateMsg,
    GroundTruthMsg,
    ImageMsg,
    Message,
    OdometryMsg,
    PointCloudMsg,
    PoseWithCovarianceMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.tags.families import family_spec

_MSGTYPES: dict[type[Message], str] = {
    OdometryMsg: "nav_msgs/msg/Odometry",
    TransformMsg: "tf2_msgs/msg/TFMessage",
    PoseWithCovarianceMsg: "geometry_msgs/msg/PoseWithCovarianceStamped",
    GroundTruthMsg: "geometry_msgs/msg/PoseStamped",
    ImageMsg: "sensor_msgs/msg/Image",
    CameraInfoMsg: "sensor_msgs/msg/CameraInfo",
    PointCloudMsg: "sensor_msgs/msg/PointCloud2",
}

_ROS_TYPES = (
    "builtin_interfaces/msg/Time",
    "std_msgs/msg/Header",
    *(f"geometry_msgs/msg/{name}" for name in (
        "Point", "Quaternion", "Pose", "PoseWithCovariance", "PoseWithCovarianceStamped",
        "PoseStamped", "Vector3", "Transform", "TransformStamped", "Twist", "TwistWithCovariance",
    )),
    "nav_msgs/msg/Odometry",
    "tf2_msgs/msg/TFMessage",
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CameraInfo",
    "sensor_msgs/msg/RegionOfInterest",
    "sensor_msgs/msg/PointCloud2",
    "sensor_msgs/msg/PointField",
)  # fmt: skip


class BagSink:
    """Write ``(topic, record)`` pairs to a bag; use as a context manager.

    Parameters
    ----------
    path : str or PathLike
        The output: a single ``.mcap`` file (``format="mcap"``), a ROS 2 bag directory
        (``"ros2"``) or a ROS 1 ``.bag`` file (``"ros1"``).
    format : {"mcap", "ros2", "ros1"}
        ``mcap``: ROS 2 (CDR) messages in one MCAP file with embedded schemas, readable by
        Foxglove, ``ros2 bag`` and :class:`BagSource`. ``ros2``: a rosbag2 directory (version 9
        metadata). ``ros1``: a ROS 1 bag (v2.0, uncompressed chunks).
    storage : {"sqlite3", "mcap"}
        Storage plugin of a ``ros2`` directory (the Humble default is sqlite3).
    overwrite : bool
        Replace an existing output at ``path`` on :meth:`close`; otherwise it is an error. Only
        a file, or for ``ros2`` a directory holding a ROS 2 bag and nothing else, is replaced.

    Raises
    ------
    BagWriteError
        If ``path`` exists and ``overwrite`` is False, or is a directory that may not be
        replaced (:func:`~tagloc.io.bag_output.check_bag_target`), or the bag cannot be created.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        format: BagFormat = "mcap",
        *,
        storage: Literal["sqlite3", "mcap"] = "sqlite3",
        overwrite: bool = False,
    ) -> None:
        if format not in ("mcap", "ros2", "ros1") or storage not in ("sqlite3", "mcap"):
            raise ValueError(f"format={format!r}, storage={storage!r}: unknown")
        self.path, self.format = Path(path), format
        if self.path.exists() and not overwrite:
            raise BagWriteError(f"{self.path}: exists already; pass overwrite=True to replace it")
        check_bag_target(self.path, format)
        self._encoder = _Encoder(1 if format == "ros1" else 2)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmpdir = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", dir=self.path.parent))
        self._cleanup = weakref.finalize(self, shutil.rmtree, self._tmpdir, True)
        self._inner = self._tmpdir / ("bag" if format == "mcap" else self.path.name)
        self._topics: dict[str, tuple[Any, type[Message]]] = {}
        self._seq: dict[str, int] = {}
        self._done = False
        try:
            self._writer = self._open_writer(storage)
        except Exception as exc:
            self._cleanup()
            raise BagWriteError(f"{self.path}: cannot create the bag ({exc})") from exc

    def _open_writer(self, storage: str) -> Any:
        if self.format == "ros1":
            from rosbags.rosbag1 import Writer as Writer1

            writer1 = Writer1(self._inner)
            writer1.open()
            return writer1
        from rosbags.rosbag2 import StoragePlugin, Writer

        mcap = self.format == "mcap" or storage == "mcap"
        plugin = StoragePlugin.MCAP if mcap else StoragePlugin.SQLITE3
        writer = Writer(self._inner, version=Writer.VERSION_LATEST, storage_plugin=plugin)
        writer.open()
        return writer

    def write(self, topic: str, msg: Message, log_time_ns: int | None = None) -> None:
        """Append ``msg`` on ``topic`` (log time ``log_time_ns``, default ``msg.stamp_ns``; for a
        :class:`PointCloudMsg` the time of its last point, when a driver publishes the sweep).

        Raises
        ------
        BagWriteError
            After :meth:`close`, for a record type other than the topic's first one, a static
            transform on a topic not named ``.../tf_static`` (or the reverse), or a record the
            message type cannot hold.
        """
        if self._done:
            raise BagWriteError(f"{self.path}: write after close")
        if not isinstance(msg, MESSAGE_TYPES):
            raise BagWriteError(f"{self.path}: {topic}: not a tagloc record: {type(msg).__name__}")
        if isinstance(msg, TransformMsg) and msg.static != _is_static(topic):
            raise BagWriteError(
                f"{self.path}: {topic}: static={msg.static} transform {msg.parent} -> "
                f"{msg.child} on a topic {'not ' if msg.static else ''}named .../tf_static"
            )
        record_type = self._topics[topic][1] if topic in self._topics else type(msg)
        if type(msg) is not record_type:
            raise BagWriteError(
                f"{self.path}: {topic}: carries {record_type.__name__}, got {type(msg).__name__}"
            )
        seq = self._seq.get(topic, 0)
        try:
            conn = self._topics[topic][0] if topic in self._topics else self._connect(topic, msg)
            data = self._encoder.serialize(self._encoder.encode(msg, seq), conn.msgtype)
            self._writer.write(conn, _log_time(msg) if log_time_ns is None else log_time_ns, data)
        except Exception as exc:
            raise BagWriteError(f"{self.path}: {topic} message {seq}: {exc}") from exc
        self._seq[topic] = seq + 1

    def _connect(self, topic: str, msg: Message) -> Any:
        msgtype = self._encoder.msgtype(type(msg))
        static = _is_static(topic)
        if self.format == "ros1":
            conn = self._writer.add_connection(
                topic, msgtype, typestore=self._encoder.store, latching=1 if static else None
            )
        else:
            qos = [_latched_qos()] if static else []
            conn = self._writer.add_connection(
                topic, msgtype, typestore=self._encoder.store, offered_qos_profiles=qos
            )
        self._topics[topic] = (conn, type(msg))
        return conn

    def close(self) -> None:
        """Finish the bag and move it to ``path`` (idempotent).

        Raises
        ------
        BagWriteError
            If finishing or moving fails (nothing is left at ``path`` then, or the old output).
        """
        if self._done:
            return
        self._done = True
        try:
            self._writer.close()
            if self.format == "mcap":
                self._inner = self._inner / f"{self._inner.name}.mcap"
            _replace(self._inner, self.path, self._tmpdir, self.format)
        except Exception as exc:
            raise BagWriteError(f"{self.path}: cannot finish the bag ({exc})") from exc
        finally:
            self._cleanup()

    def abort(self) -> None:
        """Discard everything written (idempotent); ``path`` keeps what it held before."""
        if not self._done:
            self._done = True
            try:
                self._writer.abort()
            finally:
                self._cleanup()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def _log_time(msg: Message) -> int:
    return msg.last_point_ns() if isinstance(msg, PointCloudMsg) else msg.stamp_ns


def _is_static(topic: str) -> bool:
    return topic.rstrip("/").rsplit("/", 1)[-1] == "tf_static"


def _latched_qos() -> Any:
    """QoS of a latched topic (``/tf_static``): keep last 1, reliable, transient local."""
    import rosbags.interfaces as ri

    zero = ri.QosTime(0, 0)
    return ri.Qos(
        ri.QosHistory.KEEP_LAST, 1, ri.QosReliability.RELIABLE, ri.QosDurability.TRANSIENT_LOCAL,
        zero, zero, ri.QosLiveliness.AUTOMATIC, zero, False,
    )  # fmt: skip


def _replace(src: Path, dst: Path, tmpdir: Path, format: BagFormat) -> None:
    """Rename ``src`` to ``dst``. A lone ROS 2 bag directory at ``dst`` (checked again: it may
    have changed while the bag was written) is first moved into ``tmpdir``, which is removed
    after; any other directory makes this fail and stays as it is."""
    check_bag_target(dst, format)
    if dst.is_dir() and not dst.is_symlink() and is_ros2_bag_directory(dst):
        dst.rename(tmpdir / ".replaced")
    os.replace(src, dst)


class _Encoder:
    """tagloc records -> ``rosbags`` message objects of one ROS version, and their bytes."""

    def __init__(self, ros_version: Literal[1, 2]) -> None:
        self.ros1 = ros_version == 1
        self.store = make_typestore(ros_version)
        self._t = {name.rsplit("/", 1)[-1]: self.store.types[name] for name in _ROS_TYPES}
        self._tag = self.store.types[TAGS_ROS1 if self.ros1 else TAGS_ROS2]
        self._detection = self.store.types[
            "apriltag_msgs/msg/Apriltag" if self.ros1 else "apriltag_msgs/msg/AprilTagDetection"
        ]

    def msgtype(self, record_type: type[Message]) -> str:
        if record_type is TagDetectionsMsg:
            return TAGS_ROS1 if self.ros1 else TAGS_ROS2
        return _MSGTYPES[record_type]

    def serialize(self, ros_msg: Any, msgtype: str) -> Any:
        if self.ros1:
            return self.store.serialize_ros1(ros_msg, msgtype)
        return self.store.serialize_cdr(ros_msg, msgtype)

    def encode(self, msg: Message, seq: int) -> Any:
        """The ROS message object of ``msg``."""
        if isinstance(msg, ElevatorStateMsg):  # no ROS message type for it yet
            raise BagWriteError("a building's elevator state has no bag message type yet")
        t = self._t
        if isinstance(msg, TransformMsg):
            tr = msg.T_parent_child.translation
            transform = t["Transform"](t["Vector3"](*tr), self._quat(msg.T_parent_child))
            header = self._header(msg.stamp_ns, msg.parent, seq)
            return t["TFMessage"]([t["TransformStamped"](header, msg.child, transform)])
        header = self._header(msg.stamp_ns, msg.frame_id, seq)
        if isinstance(msg, OdometryMsg):
            T = msg.T_parent_child
            twist = np.zeros(6) if msg.twist is None else msg.twist
            return t["Odometry"](
                header, msg.child_frame_id, self._pose_cov(T, msg.cov),
                t["TwistWithCovariance"](
                    t["Twist"](t["Vector3"](*twist[:3]), t["Vector3"](*twist[3:])), np.zeros(36)
                ),
            )  # fmt: skip
        if isinstance(msg, PoseWithCovarianceMsg):
            return t["PoseWithCovarianceStamped"](
                header, self._pose_cov(msg.T_frame_child, msg.cov)
            )
        if isinstance(msg, GroundTruthMsg):
            return t["PoseStamped"](header, self._pose(msg.T_frame_child))
        if isinstance(msg, ImageMsg):
            h, w = msg.image.shape[:2]
            step = w * (1 if msg.encoding == "mono8" else 3)
            data = np.ascontiguousarray(msg.image).reshape(-1)
            return t["Image"](header, h, w, msg.encoding, 0, step, data)
        if isinstance(msg, CameraInfoMsg):
            return self._camera_info(header, msg.info)
        if isinstance(msg, PointCloudMsg):
            return self._point_cloud(header, msg)
        return self._tag(header, [self._tag_detection(d) for d in msg.detections])

    # ----- pieces --------------------------------------------------------------------------------
    def _header(self, stamp_ns: int, frame_id: str, seq: int) -> Any:
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        stamp = self._t["Time"](sec, nanosec)
        return (
            self._t["Header"](seq, stamp, frame_id)
            if self.ros1
            else self._t["Header"](stamp, frame_id)
        )

    def _quat(self, T: Any) -> Any:
        return self._t["Quaternion"](*T.as_quat())

    def _pose(self, T: Any) -> Any:
        return self._t["Pose"](self._t["Point"](*T.translation), self._quat(T))

    def _pose_cov(self, T: Any, cov: Any) -> Any:
        cov_ros = cov_ros_from_body(cov, T.rotation.matrix)
        return self._t["PoseWithCovariance"](self._pose(T), cov_ros.reshape(-1))

    def _camera_info(self, header: Any, info: Any) -> Any:
        K = np.asarray(info["K"], dtype=np.float64).reshape(9)
        P = np.hstack([K.reshape(3, 3), np.zeros((3, 1))]).reshape(-1)
        roi = dict(info.get("roi") or {})
        fields = [
            np.asarray(info["D"], dtype=np.float64),
            K,
            np.asarray(info.get("R", np.eye(3).reshape(-1)), dtype=np.float64).reshape(9),
            np.asarray(info.get("P", P), dtype=np.float64).reshape(12),
        ]
        roi_msg = self._t["RegionOfInterest"](
            *(int(roi.get(k, 0)) for k in ("x_offset", "y_offset", "height", "width")),
            bool(roi.get("do_rectify", False)),
        )
        return self._t["CameraInfo"](
            header, int(info["height"]), int(info["width"]), str(info["distortion_model"]),
            *fields, int(info.get("binning_x", 0)), int(info.get("binning_y", 0)), roi_msg,
        )  # fmt: skip

    def _tag_detection(self, det: Any) -> Any:
        points = [(float(u), float(v)) for u, v in det.corners_px]
        center = (float(det.center_px[0]), float(det.center_px[1]))
        if self.ros1:
            spec = family_spec(det.family)
            P = self._t["Point"]
            return self._detection(
                det.tag_id, det.family, det.hamming, spec.border_cells, spec.data_cells,
                P(*center, 0.0), [P(u, v, 0.0) for u, v in points],
            )  # fmt: skip
        P2 = self.store.types["apriltag_msgs/msg/Point"]
        return self._detection(
            det.family, det.tag_id, det.hamming, 0.0, det.decision_margin,
            P2(*center), [P2(u, v) for u, v in points], np.zeros(9),
        )  # fmt: skip

    def _point_cloud(self, header: Any, msg: PointCloudMsg) -> Any:
        columns = [("x", msg.points[:, 0]), ("y", msg.points[:, 1]), ("z", msg.points[:, 2])]
        if msg.intensity is not None:
            columns.append(("intensity", msg.intensity))
        if msg.time_offset_s is not None:
            columns.append(("t", msg.time_offset_s))
        n, step = len(msg.points), 4 * len(columns)
        packed = np.empty((n, len(columns)), dtype="<f4")
        for i, (_, values) in enumerate(columns):
            packed[:, i] = values
        field = self._t["PointField"]
        fields = [field(name, 4 * i, field.FLOAT32, 1) for i, (name, _) in enumerate(columns)]
        dense = bool(np.isfinite(msg.points).all())
        data = packed.reshape(-1).view(np.uint8)
        return self._t["PointCloud2"](header, 1, n, fields, False, step, step * n, data, dense)
