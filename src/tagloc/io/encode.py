"""tagloc records -> ``rosbags`` message objects of ROS 1 or ROS 2, and their bytes.

What each record becomes is tabled in :mod:`tagloc.io.bag_writer`, which writes them; the
reverse is :mod:`tagloc.io.convert`. Covariances go from tagloc's body tangent to ROS'
parent-frame convention (:func:`tagloc.io.convert.cov_ros_from_body`).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from tagloc import messages as m
from tagloc.io.convert import TAGS_ROS1, TAGS_ROS2, cov_ros_from_body, make_typestore
from tagloc.io.errors import BagWriteError
from tagloc.tags.families import family_spec

__all__ = ["RosEncoder"]

_MSGTYPES: dict[type[m.Message], str] = {
    m.OdometryMsg: "nav_msgs/msg/Odometry",
    m.TransformMsg: "tf2_msgs/msg/TFMessage",
    m.PoseWithCovarianceMsg: "geometry_msgs/msg/PoseWithCovarianceStamped",
    m.GroundTruthMsg: "geometry_msgs/msg/PoseStamped",
    m.ImageMsg: "sensor_msgs/msg/Image",
    m.CameraInfoMsg: "sensor_msgs/msg/CameraInfo",
    m.PointCloudMsg: "sensor_msgs/msg/PointCloud2",
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


class RosEncoder:
    """tagloc records -> ``rosbags`` message objects of one ROS version, and their bytes."""

    def __init__(self, ros_version: Literal[1, 2]) -> None:
        self.ros1 = ros_version == 1
        self.store = make_typestore(ros_version)
        self._t = {name.rsplit("/", 1)[-1]: self.store.types[name] for name in _ROS_TYPES}
        self._tag = self.store.types[TAGS_ROS1 if self.ros1 else TAGS_ROS2]
        self._detection = self.store.types[
            "apriltag_msgs/msg/Apriltag" if self.ros1 else "apriltag_msgs/msg/AprilTagDetection"
        ]

    def msgtype(self, record_type: type[m.Message]) -> str:
        if record_type is m.TagDetectionsMsg:
            return TAGS_ROS1 if self.ros1 else TAGS_ROS2
        return _MSGTYPES[record_type]

    def serialize(self, ros_msg: Any, msgtype: str) -> Any:
        if self.ros1:
            return self.store.serialize_ros1(ros_msg, msgtype)
        return self.store.serialize_cdr(ros_msg, msgtype)

    def encode(self, msg: m.Message, seq: int) -> Any:
        """The ROS message object of ``msg``."""
        t = self._t
        if isinstance(msg, m.TransformMsg):
            tr = msg.T_parent_child.translation
            transform = t["Transform"](t["Vector3"](*tr), self._quat(msg.T_parent_child))
            header = self._header(msg.stamp_ns, msg.parent, seq)
            return t["TFMessage"]([t["TransformStamped"](header, msg.child, transform)])
        if isinstance(msg, m.ElevatorStateMsg):
            # a building's elevator state has no standard ROS message: not recorded in bags
            raise BagWriteError("a building's elevator state has no ROS message type: it is not "
                                "written to bags")  # fmt: skip
        header = self._header(msg.stamp_ns, msg.frame_id, seq)
        if isinstance(msg, m.OdometryMsg):
            T = msg.T_parent_child
            twist = np.zeros(6) if msg.twist is None else msg.twist
            return t["Odometry"](
                header, msg.child_frame_id, self._pose_cov(T, msg.cov),
                t["TwistWithCovariance"](
                    t["Twist"](t["Vector3"](*twist[:3]), t["Vector3"](*twist[3:])), np.zeros(36)
                ),
            )  # fmt: skip
        if isinstance(msg, m.PoseWithCovarianceMsg):
            return t["PoseWithCovarianceStamped"](
                header, self._pose_cov(msg.T_frame_child, msg.cov)
            )
        if isinstance(msg, m.GroundTruthMsg):
            return t["PoseStamped"](header, self._pose(msg.T_frame_child))
        if isinstance(msg, m.ImageMsg):
            h, w = msg.image.shape[:2]
            step = w * (1 if msg.encoding == "mono8" else 3)
            data = np.ascontiguousarray(msg.image).reshape(-1)
            return t["Image"](header, h, w, msg.encoding, 0, step, data)
        if isinstance(msg, m.CameraInfoMsg):
            return self._camera_info(header, msg.info)
        if isinstance(msg, m.PointCloudMsg):
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

    def _point_cloud(self, header: Any, msg: m.PointCloudMsg) -> Any:
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
