"""Reading and writing files and messages; the only layer that touches the file system.

- :mod:`tagloc.io.kalibr`: Kalibr camchain yaml -> camera models (:func:`load_kalibr_cameras`).
- :mod:`tagloc.messages`: the typed stream records (:class:`OdometryMsg`, :class:`ImageMsg`,
  :class:`CameraInfoMsg`, :class:`TagDetectionsMsg`, :class:`TransformMsg`,
  :class:`PoseWithCovarianceMsg`, :class:`GroundTruthMsg`,
  :class:`PointCloudMsg`; the :data:`Message` union) and the
  :class:`MessageSource` / :class:`MessageSink` protocols.
- :mod:`tagloc.io.bag_reader`: ROS 1 / ROS 2 bags and MCAP files as a source (:class:`BagSource`).
- :mod:`tagloc.io.bag_writer`: records to MCAP / ROS 2 / ROS 1 bags (:class:`BagSink`).
- :mod:`tagloc.io.bag_output`: the format a bag path names (:func:`bag_output_format`), the one
  directory a writer may replace (:func:`is_ros2_bag_directory`).
- :mod:`tagloc.io.convert`: ROS message fields <-> records (stamps, quaternions, covariance frames).
- :mod:`tagloc.io.tum`: TUM trajectory files (:func:`read_tum`, :func:`write_tum`).
- :mod:`tagloc.io.errors`: :class:`TaglocIOError` and its subclasses.

``rosbags`` is imported only when a bag is opened.
"""

from tagloc.io.bag_output import bag_output_format, check_bag_target, is_ros2_bag_directory
from tagloc.io.bag_reader import BagSource, BagTopic, open_bag
from tagloc.io.bag_writer import BagSink
from tagloc.io.errors import (
    BagFormatError,
    BagTopicError,
    BagWriteError,
    InputNotFoundError,
    RecordError,
    TaglocIOError,
    TrajectoryFileError,
)
from tagloc.io.kalibr import load_kalibr_cameras
from tagloc.io.tum import read_tum, write_tum
from tagloc.messages import (
    CameraInfoMsg,
    GroundTruthMsg,
    ImageMsg,
    Message,
    MessageSink,
    MessageSource,
    OdometryMsg,
    PointCloudMsg,
    PoseWithCovarianceMsg,
    TagDetectionsMsg,
    TransformMsg,
)

__all__ = [
    "BagFormatError",
    "BagSink",
    "BagSource",
    "BagTopic",
    "BagTopicError",
    "BagWriteError",
    "CameraInfoMsg",
    "GroundTruthMsg",
    "ImageMsg",
    "InputNotFoundError",
    "Message",
    "MessageSink",
    "MessageSource",
    "OdometryMsg",
    "PointCloudMsg",
    "PoseWithCovarianceMsg",
    "RecordError",
    "TagDetectionsMsg",
    "TaglocIOError",
    "TrajectoryFileError",
    "TransformMsg",
    "bag_output_format",
    "check_bag_target",
    "is_ros2_bag_directory",
    "load_kalibr_cameras",
    "open_bag",
    "read_tum",
    "write_tum",
]
