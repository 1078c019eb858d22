"""The stream's types: any record (:data:`Message`), the topics the localizer reads, a camera
frame's simulator truth, and the :class:`MessageSource` / :class:`MessageSink` protocols."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from types import TracebackType
from typing import Protocol, Self, TypeAlias, get_args

from tagloc.messages.pose_records import (
    GroundTruthMsg,
    OdometryMsg,
    PoseWithCovarianceMsg,
    TransformMsg,
)
from tagloc.messages.sensor_records import (
    CameraInfoMsg,
    ElevatorStateMsg,
    ImageMsg,
    PointCloudMsg,
    TagDetectionsMsg,
)

__all__ = ["MESSAGE_TYPES", "FrameTruth", "Message", "MessageSink", "MessageSource", "NodeTopics"]


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
    nearest_by_frame : tuple of (str, float)
        Per tag frame with a tag truly in view (``"map"``, an elevator cab's frame), camera
        to its nearest tag, m, in frame order (empty: not known).
    """

    false_detection: tuple[bool, ...]
    nearest_visible_m: float
    nearest_by_frame: tuple[tuple[str, float], ...] = ()

    def nearest_in(self, frame: str) -> float:
        """Camera to the nearest tag truly in view posed in ``frame``, m (``inf``: none)."""
        return min((m for f, m in self.nearest_by_frame if f == frame), default=math.inf)


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
