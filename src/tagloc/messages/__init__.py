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

from tagloc.messages.pose_records import (
    GroundTruthMsg,
    OdometryMsg,
    PoseWithCovarianceMsg,
    TransformMsg,
)
from tagloc.messages.sensor_records import (
    IMAGE_ENCODINGS,
    CameraInfoMsg,
    ElevatorStateMsg,
    ImageMsg,
    PointCloudMsg,
    TagDetectionsMsg,
)
from tagloc.messages.stream import (
    MESSAGE_TYPES,
    FrameTruth,
    Message,
    MessageSink,
    MessageSource,
    NodeTopics,
)

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
