"""ROS messages to tagloc stream records, the ROS/tagloc conventions, and tagloc's typestores.

:func:`decode` returns records, or :class:`Bad` markers for content the reader counts and skips
(or raises on, per its ``on_bad``). It reads fields by name only, so it takes ``rosbags`` and
``rclpy`` message objects alike; the reverse direction (records to ``rosbags`` objects) lives with
the writer, :mod:`tagloc.io.bag_writer`. Conventions, both ways:

- Stamps: ``header.stamp`` -> ``sec * 10**9 + nanosec`` (int ns).
- Quaternions: ROS ``(x, y, z, w)`` = tagloc ``quat_xyzw``. On reading, a norm within
  ``quat_tol`` of 1 is renormalized; further off is ``Bad("bad_quaternion")``.
- Covariance: ROS and tagloc both order ``[x, y, z, rx, ry, rz]``, but ROS expresses the
  translation and the fixed-axis rotation errors in the *parent* frame, tagloc in the body
  (right) tangent, ``T (+) xi = T @ Exp(xi)``. To first order ``delta_ros = B xi`` with
  ``B = blockdiag(R, R)``, so ``cov_ros = B cov_body B^T`` (:func:`cov_body_from_ros`).
- Twist: ROS ``nav_msgs/Odometry`` twist is in ``child_frame_id``; kept as is.
- Images: ``mono8``/``8UC1`` -> ``(H, W)``; ``bgr8`` -> ``(H, W, 3)``; ``rgb8`` -> reversed to
  ``bgr8``; row padding (``step``) dropped. ``CompressedImage`` is decoded with
  ``cv2.imdecode(..., IMREAD_UNCHANGED)`` (BGR; alpha dropped; 16-bit images unsupported).
- Point clouds (``sensor_msgs/PointCloud2``): fields ``x, y, z`` (float32 or float64) are
  required, ``intensity`` is kept when present; the per-point time is read from the first of
  ``t`` (float: seconds after the stamp; integer: nanoseconds, as Ouster), ``time`` (seconds
  after the stamp, as Velodyne), ``offset_time`` (integer nanoseconds after the stamp, as
  Livox), ``timestamp`` (absolute: nanoseconds if its values exceed 1e12, else seconds, as
  Livox ROS Driver 2 and Hesai). Drivers that stamp the sweep's end give negative offsets: the
  record's stamp is then moved to the earliest point and the offsets re-based on it, so they
  are ``>= 0``. Any byte order, padding and row step; a cloud whose data is shorter than its
  ``height * row_step``, a field outside the point or of an unknown type, more points than
  a sweep may hold or point times spanning more than a sweep may last is
  ``Bad("bad_point_cloud")``; a large sweep is thinned on reading (:mod:`tagloc.io.convert_cloud`
  has the limits).
- Tag corners enter through :meth:`TagDetection.from_corners` with the reader's ``corner_order``
  and ``pixel_offset``; the writer stores tagloc's own order (``tl_tr_br_bl``, offset 0).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from typing import Any, Literal

import cv2
import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.io.convert_cloud import point_cloud
from tagloc.io.decoded import Bad, Decoded, DecodeOptions, stamp_of
from tagloc.io.errors import BagFormatError
from tagloc.messages import (
    CameraInfoMsg,
    GroundTruthMsg,
    ImageMsg,
    Message,
    OdometryMsg,
    PointCloudMsg,
    PoseWithCovarianceMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.tags.detection import TagDetection, corner_permutation
from tagloc.tags.errors import TagInputError
from tagloc.tags.families import known_families

TAGS_ROS1 = "apriltag_msgs/msg/ApriltagArrayStamped"
TAGS_ROS2 = "apriltag_msgs/msg/AprilTagDetectionArray"
#: Added to the Noetic store: ``tf2_msgs`` (absent there) and ``apriltag_msgs`` as the dupont bag
#: embeds it (md5 179c9ccf1becf89d2541dd94fbd5accd).
_EXTRA_ROS1 = {
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    TAGS_ROS1: "std_msgs/Header header\nApriltag[] apriltags\n",
    "apriltag_msgs/msg/Apriltag": "int32 id\nstring family\nint32 hamming\nint32 border\n"
    "int32 bits\ngeometry_msgs/Point center\ngeometry_msgs/Point[4] corners\n",
}
#: ``apriltag_msgs`` of ROS 2 (christianrauch/apriltag_msgs).
_EXTRA_ROS2 = {
    TAGS_ROS2: "std_msgs/Header header\nAprilTagDetection[] detections\n",
    "apriltag_msgs/msg/AprilTagDetection": "string family\nint32 id\nint32 hamming\n"
    "float32 goodness\nfloat32 decision_margin\nPoint centre\nPoint[4] corners\n"
    "float64[9] homography\n",
    "apriltag_msgs/msg/Point": "float64 x\nfloat64 y\n",
}


@functools.cache
def _typestore(ros_version: int) -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros_version == 1 else Stores.ROS2_HUMBLE)
    for name, text in (_EXTRA_ROS1 if ros_version == 1 else _EXTRA_ROS2).items():
        store.register(get_types_from_msg(text, name))
    return store


def make_typestore(ros_version: Literal[1, 2]) -> Any:
    """The ``rosbags`` typestore tagloc writes with: Noetic (plus ``tf2_msgs``) or Humble, with
    ``apriltag_msgs``.

    Shared and cached; do not register further types in it.
    """
    return _typestore(ros_version)


def cov_body_from_ros(cov_ros: FloatArray, R: FloatArray) -> FloatArray:
    """ROS pose covariance (parent-frame axes) to tagloc's body tangent: ``B^T cov_ros B``.

    Parameters
    ----------
    cov_ros : (6, 6) float
        ``[x, y, z, rx, ry, rz]`` errors along and about the parent frame's axes.
    R : (3, 3) float
        ``R_parent_child`` of the pose; ``B = blockdiag(R, R)`` (first order in the error).
    """
    B = np.zeros((6, 6))
    B[:3, :3] = B[3:, 3:] = R
    return np.asarray(B.T @ cov_ros @ B)


def cov_ros_from_body(cov_body: FloatArray, R: FloatArray) -> FloatArray:
    """``B cov_body B^T``: the inverse of :func:`cov_body_from_ros`."""
    B = np.zeros((6, 6))
    B[:3, :3] = B[3:, 3:] = R
    return np.asarray(B @ cov_body @ B.T)


# ----- decoding ----------------------------------------------------------------------------------
def _pose(position: Any, orientation: Any, opts: DecodeOptions) -> SE3 | Bad:
    t = (position.x, position.y, position.z)
    q = (orientation.x, orientation.y, orientation.z, orientation.w)
    if not all(map(math.isfinite, t + q)):
        return Bad("non_finite", f"pose holds NaN or inf: t={t}, quat_xyzw={q}")
    norm = math.sqrt(sum(v * v for v in q))
    if abs(norm - 1.0) > opts.quat_tol:
        return Bad("bad_quaternion", f"|quat_xyzw| = {norm:.6g} (tolerance {opts.quat_tol:g})")
    return SE3.from_quat(np.array(q) / norm, t)


def _cov(values: Any, pose: SE3) -> FloatArray | Bad:
    cov = np.asarray(values, dtype=np.float64).reshape(6, 6)
    if not np.isfinite(cov).all():
        return Bad("non_finite", "covariance holds NaN or inf")
    return cov_body_from_ros(cov, pose.rotation.matrix)


def _odometry(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    pose = _pose(msg.pose.pose.position, msg.pose.pose.orientation, opts)
    if isinstance(pose, Bad):
        return [pose]
    cov = _cov(msg.pose.covariance, pose)
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    twist = (lin.x, lin.y, lin.z, ang.x, ang.y, ang.z)
    if isinstance(cov, Bad) or not all(map(math.isfinite, twist)):
        return [cov if isinstance(cov, Bad) else Bad("non_finite", f"twist {twist}")]
    stamp = stamp_of(msg.header, log_ns, opts)
    return [OdometryMsg(stamp, msg.header.frame_id, msg.child_frame_id, pose, cov, np.array(twist))]


def _pose_cov(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    pose = _pose(msg.pose.pose.position, msg.pose.pose.orientation, opts)
    cov = pose if isinstance(pose, Bad) else _cov(msg.pose.covariance, pose)
    if isinstance(cov, Bad) or isinstance(pose, Bad):
        return [cov if isinstance(cov, Bad) else pose]  # type: ignore[list-item]
    return [
        PoseWithCovarianceMsg(stamp_of(msg.header, log_ns, opts), msg.header.frame_id, pose, cov)
    ]


def _pose_stamped(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    pose = _pose(msg.pose.position, msg.pose.orientation, opts)
    if isinstance(pose, Bad):
        return [pose]
    return [GroundTruthMsg(stamp_of(msg.header, log_ns, opts), msg.header.frame_id, pose)]


def _tf(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    out: Decoded = []
    for tf in msg.transforms:
        pose = _pose(tf.transform.translation, tf.transform.rotation, opts)
        if isinstance(pose, Bad):
            out.append(pose)
            continue
        stamp = stamp_of(tf.header, log_ns, opts)
        out.append(TransformMsg(stamp, tf.header.frame_id, tf.child_frame_id, pose, static))
    return out


_RAW_ENCODINGS = {
    "mono8": ("mono8", 1),
    "8uc1": ("mono8", 1),
    "bgr8": ("bgr8", 3),
    "rgb8": ("rgb8", 3),
}


def _image(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    known = _RAW_ENCODINGS.get(msg.encoding.lower())
    if known is None:
        return [Bad("unsupported_encoding", f"image encoding {msg.encoding!r}")]
    encoding, channels = known
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if h == 0 or w == 0 or step < w * channels or data.size < h * step:
        return [Bad("bad_image", f"{h}x{w} {encoding}, step {step}, {data.size} bytes")]
    rows = data[: h * step].reshape(h, step)[:, : w * channels]
    image = rows.reshape((h, w) if channels == 1 else (h, w, 3))
    if encoding == "rgb8":
        image, encoding = np.ascontiguousarray(image[..., ::-1]), "bgr8"
    return [ImageMsg(stamp_of(msg.header, log_ns, opts), msg.header.frame_id, image, encoding)]


def _compressed(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    try:
        image: Any = cv2.imdecode(np.asarray(msg.data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:  # an empty buffer, an image too large for OpenCV's limits
        image = None
    if image is None:
        return [Bad("undecodable", f"cv2.imdecode failed on {msg.format!r} data")]
    if image.dtype != np.uint8 or not (image.ndim == 2 or image.shape[2] in (1, 3, 4)):
        return [Bad("unsupported_encoding", f"decoded {image.dtype} image {image.shape}")]
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    encoding = "mono8" if image.ndim == 2 else "bgr8"
    return [ImageMsg(stamp_of(msg.header, log_ns, opts), msg.header.frame_id, image, encoding)]


def _camera_info(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    roi = msg.roi
    info = {
        "width": int(msg.width),
        "height": int(msg.height),
        "distortion_model": msg.distortion_model,
        **{k: getattr(msg, k) if hasattr(msg, k) else getattr(msg, k.lower()) for k in "DKRP"},
        "binning_x": int(msg.binning_x),
        "binning_y": int(msg.binning_y),
        "roi": {f: getattr(roi, f) for f in ("x_offset", "y_offset", "height", "width")}
        | {"do_rectify": bool(roi.do_rectify)},
    }
    return [CameraInfoMsg(stamp_of(msg.header, log_ns, opts), msg.header.frame_id, info)]


def resolve_family(name: str, opts: DecodeOptions) -> str | Bad:
    """The tagloc family of a message's ``family`` string (``"36h11"``, ``"tf36h11"``, ...).

    Raises
    ------
    BagFormatError
        If ``name`` is empty and no ``default_family`` was given.
    """
    if not name:
        if opts.default_family is None:
            raise BagFormatError(
                "tag family is empty in the message; pass default_family= (e.g. 'tag36h11')"
            )
        return opts.default_family
    known = known_families()
    for candidate in (name, name.lower(), "tag" + name.lower().removeprefix("tf")):
        if candidate in known:
            return candidate
    return Bad("unknown_family", f"tag family {name!r} is not one of {list(known)}")


def _detection(
    tag_id: int, family: str, hamming: int, margin: float, corners: Any, opts: DecodeOptions
) -> TagDetection | Bad:
    fam = resolve_family(family, opts)
    if isinstance(fam, Bad):
        return fam
    points = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    ordered = points[list(corner_permutation(opts.corner_order))]
    edges = np.roll(ordered, -1, axis=0) - ordered
    nxt = np.roll(edges, -1, axis=0)
    if ((edges[:, 0] * nxt[:, 1] - edges[:, 1] * nxt[:, 0]) < 0.0).all():
        labels = opts.corner_order.split("_")[::-1]
        other = ["_".join(labels[i:] + labels[:i]) for i in range(4)]
        raise BagFormatError(
            f"tag {fam}:{tag_id}: its corners taken in corner_order={opts.corner_order!r} run "
            "counter-clockwise on screen (the tag would be seen mirrored), so the data lists its "
            f"corners the other way round: pass one of {other} as corner_order"
        )
    try:
        return TagDetection.from_corners(
            tag_id, fam, points, opts.corner_order, opts.pixel_offset, hamming, margin
        )
    except TagInputError as exc:
        return Bad("bad_detection", str(exc))


def _points(corners: Any) -> Any:
    return corners if isinstance(corners, np.ndarray) else [(p.x, p.y) for p in corners]


def _tags(msg: Any, tags: Any, log_ns: int, opts: DecodeOptions, ros1: bool) -> Decoded:
    bad: Decoded = []
    detections: list[TagDetection] = []
    for tag in tags:
        margin = math.nan if ros1 else float(tag.decision_margin)  # ROS 1 messages have none
        item = _detection(tag.id, tag.family, tag.hamming, margin, _points(tag.corners), opts)
        if isinstance(item, Bad):
            bad.append(item)
        else:
            detections.append(item)
    stamp = stamp_of(msg.header, log_ns, opts)
    return [*bad, TagDetectionsMsg(stamp, msg.header.frame_id, tuple(detections))]


def _tags_ros1(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    return _tags(msg, msg.apriltags, log_ns, opts, ros1=True)


def _tags_ros2(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    return _tags(msg, msg.detections, log_ns, opts, ros1=False)


Decoder = Callable[[Any, int, DecodeOptions, bool], Decoded]
#: ROS type (as rosbags names it) -> (decoder, record type).
DECODERS: Mapping[str, tuple[Decoder, type[Message]]] = {
    "nav_msgs/msg/Odometry": (_odometry, OdometryMsg),
    "sensor_msgs/msg/Image": (_image, ImageMsg),
    "sensor_msgs/msg/CompressedImage": (_compressed, ImageMsg),
    "sensor_msgs/msg/CameraInfo": (_camera_info, CameraInfoMsg),
    "sensor_msgs/msg/PointCloud2": (point_cloud, PointCloudMsg),
    "tf2_msgs/msg/TFMessage": (_tf, TransformMsg),
    "tf/msg/tfMessage": (_tf, TransformMsg),
    "geometry_msgs/msg/PoseWithCovarianceStamped": (_pose_cov, PoseWithCovarianceMsg),
    "geometry_msgs/msg/PoseStamped": (_pose_stamped, GroundTruthMsg),
    TAGS_ROS1: (_tags_ros1, TagDetectionsMsg),
    TAGS_ROS2: (_tags_ros2, TagDetectionsMsg),
}


def decode(msgtype: str, msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    """Records (and :class:`Bad` markers) of one deserialized message of a type in DECODERS.

    Raises
    ------
    BagFormatError
        When the options cannot fit the data (see :func:`resolve_family`, corner winding).
    RecordError
        When a field breaks a record's rules (an empty frame name on a transform).
    """
    return DECODERS[msgtype][0](msg, log_ns, opts, static)
