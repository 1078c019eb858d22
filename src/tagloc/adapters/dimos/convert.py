"""dimos messages <-> tagloc's stream records (:mod:`tagloc.messages`), both ways.

dimos stamps are float seconds (``ts``) and its quaternions ``xyzw``, as tagloc's ``quat_xyzw``.
A stamp becomes integer nanoseconds taken to the microsecond (:func:`stamp_ns`): LCM carries
``sec`` and a truncated ``nsec``, and a float of seconds near the epoch holds no finer than
0.24 us, so sub-microsecond digits are noise that would reorder a frame and the odometry sample
of the same instant.

Images: ``Image`` (BGR, RGB, BGRA, RGBA or GRAY, uint8) and ``CompressedImage`` (JPEG or PNG,
decoded to gray by OpenCV) become ``mono8`` or ``bgr8`` :class:`~tagloc.messages.ImageMsg`;
``PointCloud2`` keeps its points, intensities and per-point time offsets. The pose output is a
``PoseWithCovarianceStamped`` whose covariance is in ROS order and axes (parent frame), converted
from tagloc's body tangent by :func:`tagloc.io.convert.cov_ros_from_body`.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from dimos.msgs.geometry_msgs.Pose import Pose
from dimos.msgs.geometry_msgs.PoseWithCovarianceStamped import PoseWithCovarianceStamped
from dimos.msgs.geometry_msgs.Quaternion import Quaternion
from dimos.msgs.geometry_msgs.Transform import Transform
from dimos.msgs.geometry_msgs.Vector3 import Vector3
from dimos.msgs.sensor_msgs.CameraInfo import CameraInfo
from dimos.msgs.sensor_msgs.CompressedImage import CompressedImage
from dimos.msgs.sensor_msgs.Image import Image, ImageFormat
from dimos.msgs.sensor_msgs.PointCloud2 import PointCloud2

from tagloc.errors import TaglocError
from tagloc.geometry import SE3
from tagloc.io.convert import cov_ros_from_body
from tagloc.messages import CameraInfoMsg, ImageMsg, PointCloudMsg, TransformMsg

__all__ = [
    "DimosInputError",
    "camera_info",
    "camera_info_msg",
    "dimos_image",
    "image_msg",
    "point_cloud",
    "point_cloud_msg",
    "pose_with_covariance",
    "se3",
    "stamp_ns",
    "stamp_s",
    "transform",
    "transform_msg",
]

_TO_GRAY = {
    ImageFormat.BGR: cv2.COLOR_BGR2GRAY, ImageFormat.RGB: cv2.COLOR_RGB2GRAY,
    ImageFormat.BGRA: cv2.COLOR_BGRA2GRAY, ImageFormat.RGBA: cv2.COLOR_RGBA2GRAY,
}  # fmt: skip


class DimosInputError(TaglocError, ValueError):
    """A dimos message tagloc cannot use (the message names it and why)."""


def stamp_ns(ts: float | None) -> int:
    """dimos float seconds to tagloc's integer nanoseconds, to the microsecond (module
    docstring); None or negative: 0."""
    return max(0, round(float(ts or 0.0) * 1e6) * 1000)


def stamp_s(stamp: int) -> float:
    """tagloc nanoseconds to dimos float seconds."""
    return stamp / 1e9


def se3(tf: Transform) -> SE3:
    """``T_parent_child`` of a dimos ``Transform`` (``frame_id -> child_frame_id``)."""
    q, t = tf.rotation, tf.translation
    return SE3.from_quat([q.x, q.y, q.z, q.w], [t.x, t.y, t.z])


def transform(T_parent_child: SE3, parent: str, child: str, ts: float) -> Transform:
    """A dimos ``Transform`` of ``T_parent_child``."""
    x, y, z = (float(v) for v in T_parent_child.translation)
    qx, qy, qz, qw = (float(v) for v in T_parent_child.as_quat())
    return Transform(translation=Vector3(x, y, z), rotation=Quaternion(qx, qy, qz, qw),
                     frame_id=parent, child_frame_id=child, ts=ts)  # fmt: skip


def transform_msg(tf: Transform, static: bool = False) -> TransformMsg:
    """tagloc's record of one dimos transform."""
    return TransformMsg(stamp_ns(tf.ts), tf.frame_id, tf.child_frame_id, se3(tf), static)


def image_msg(image: Image | CompressedImage, frame_id: str = "") -> ImageMsg:
    """A camera image as tagloc's record (``frame_id``: used when the image has none).

    Raises
    ------
    DimosInputError
        An encoding tagloc cannot read (16-bit, depth, an undecodable or other compression).
    """
    frame = image.frame_id or frame_id
    if isinstance(image, CompressedImage):
        if not image.format.startswith(("jpeg", "png")):
            raise DimosInputError(f"CompressedImage: format {image.format!r} (expected jpeg/png)")
        decoded = cv2.imdecode(np.frombuffer(image.data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
        if decoded is None:
            raise DimosInputError(f"CompressedImage: {len(image.data)} bytes do not decode as "
                                  f"{image.format}")  # fmt: skip
        return ImageMsg(stamp_ns(image.ts), frame, np.asarray(decoded, np.uint8), "mono8")
    data: npt.NDArray[np.uint8] = np.asarray(image.data)
    if data.dtype != np.uint8 or image.format not in (*_TO_GRAY, ImageFormat.GRAY):
        raise DimosInputError(f"Image: format {image.format.value} of {data.dtype} (expected "
                              "8-bit gray or color)")  # fmt: skip
    if image.format == ImageFormat.GRAY:
        return ImageMsg(stamp_ns(image.ts), frame, data.reshape(data.shape[:2]), "mono8")
    if image.format == ImageFormat.BGR:
        return ImageMsg(stamp_ns(image.ts), frame, data, "bgr8")
    gray = np.asarray(cv2.cvtColor(data, _TO_GRAY[image.format]), np.uint8)
    return ImageMsg(stamp_ns(image.ts), frame, gray, "mono8")


def dimos_image(msg: ImageMsg) -> Image:
    """A dimos ``Image`` of tagloc's record (``mono8``: GRAY, ``bgr8``: BGR)."""
    fmt = ImageFormat.GRAY if msg.encoding == "mono8" else ImageFormat.BGR
    return Image(data=np.array(msg.image), format=fmt, frame_id=msg.frame_id,
                 ts=stamp_s(msg.stamp_ns))  # fmt: skip


def camera_info_msg(info: CameraInfo) -> CameraInfoMsg:
    """tagloc's record of a dimos ``CameraInfo``."""
    fields: dict[str, Any] = {
        "width": int(info.width), "height": int(info.height),
        "distortion_model": info.distortion_model, "D": list(info.D), "K": list(info.K),
        "R": list(info.R), "P": list(info.P),
    }  # fmt: skip
    return CameraInfoMsg(stamp_ns(info.ts), info.frame_id, fields)


def camera_info(msg: CameraInfoMsg) -> CameraInfo:
    """A dimos ``CameraInfo`` of tagloc's record."""
    i = msg.info
    return CameraInfo(height=int(i["height"]), width=int(i["width"]),
                      distortion_model=str(i["distortion_model"]), D=list(i["D"]),
                      K=list(i["K"]), R=list(i.get("R", np.eye(3).ravel())),
                      P=list(i.get("P", np.zeros(12))), frame_id=msg.frame_id,
                      ts=stamp_s(msg.stamp_ns))  # fmt: skip


def point_cloud_msg(cloud: PointCloud2) -> PointCloudMsg:
    """tagloc's record of a lidar sweep (per-point ``offset_times`` ns -> ``time_offset_s``)."""
    offsets = cloud.offset_times_u32()
    return PointCloudMsg(stamp_ns(cloud.ts), cloud.frame_id, cloud.points_f32(),
                         cloud.intensities_f32(),
                         None if offsets is None else offsets.astype(np.float64) / 1e9)  # fmt: skip


def point_cloud(msg: PointCloudMsg) -> PointCloud2:
    """A dimos ``PointCloud2`` of tagloc's record (time offsets rounded to nanoseconds)."""
    offsets = None
    if msg.time_offset_s is not None:
        offsets = np.round(msg.time_offset_s.astype(np.float64) * 1e9).astype(np.uint32)
    return PointCloud2.from_numpy(np.array(msg.points), frame_id=msg.frame_id,
                                  timestamp=stamp_s(msg.stamp_ns), intensities=msg.intensity,
                                  offset_times=offsets)  # fmt: skip


def pose_with_covariance(
    stamp: int, frame: str, T_frame_base: SE3, cov_body: np.ndarray | None
) -> PoseWithCovarianceStamped:
    """The pose output: ``T_frame_base`` with its covariance in ROS order and parent axes
    (all -1 when unknown, before the filter is initialized)."""
    x, y, z = (float(v) for v in T_frame_base.translation)
    qx, qy, qz, qw = (float(v) for v in T_frame_base.as_quat())
    if cov_body is None:
        cov = np.full(36, -1.0)
    else:
        cov = cov_ros_from_body(np.asarray(cov_body), T_frame_base.rotation.matrix).ravel()
    pose = Pose(x, y, z, qx, qy, qz, qw)
    return PoseWithCovarianceStamped(ts=stamp_s(stamp), frame_id=frame, pose=pose, covariance=cov)
