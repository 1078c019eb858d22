"""Fix sources: the one plug-in point through which the streaming node gets absolute fixes.

A :class:`FixSource` turns its messages (camera frames, lidar sweeps; an AMCL pose or visual
odometry later) into fixes of the base in the map. It owns all of its state (camera model,
detector, waiting-frame bookkeeping, premap, thinning, ...) and knows nothing of the node. The
node (:class:`~tagloc.localize.node.LocalizerNode`) owns what is shared: one queue of pending
work (ordered by the odometry stamp that must be buffered before it can run), the
``map -> odom`` filter and the one output path. The life of a message:

1. :meth:`FixSource.arrive`: the source's own checks (a counted skip, or an :class:`Arrival`:
   the input's liveness for the supervisor and the :class:`Work` to queue, if any).
2. The node queues the work (at most :attr:`FixSource.max_waiting` of the source's, the oldest
   dropped) until the odometry covers ``Work.ready_ns``.
3. :meth:`FixSource.fixes` with a :class:`FixContext` (the transform buffer and the filter, as
   they are now) returns a :class:`SourceResult`: fixes offered to the filter (:class:`Offer`)
   and records of what never reached it.
4. The node decides each offer with the filter, books it with the supervisor, and hands the run
   records on once final; every other source :meth:`~FixSource.observe` s the result.
5. On a clock jump back the node calls :meth:`FixSource.reset`.

The sources the node builds are those of :data:`tagloc.localize.registry.FIX_SOURCES`, in order.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from tagloc.camera import CameraModel
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import PartialFix, TagFix
from tagloc.localize.run import CameraFrameRecord, FixAttempt
from tagloc.localize.tag_cameras import NodeCamera
from tagloc.messages import FrameTruth, Message, NodeTopics
from tagloc.supervise import FixSourceSpec
from tagloc.tags import TagDetection, TagDetector, TagMap

__all__ = [
    "Arrival",
    "FixContext",
    "FixSource",
    "Offer",
    "SkipCounter",
    "SourceInputs",
    "SourceResult",
    "Work",
]

logger = logging.getLogger(__name__)


class SkipCounter(Counter[str]):
    """Skipped inputs by reason; the first of each reason is logged (a warning, or INFO for an
    expected one: nothing is wrong), the others counted."""

    def skip(self, reason: str, detail: str, *, expected: bool = False) -> None:
        self[reason] += 1
        if self[reason] == 1:
            level = logging.INFO if expected else logging.WARNING
            logger.log(level, "skipped (%s): %s; further ones are counted", reason, detail)


@dataclass(frozen=True, slots=True)
class Work:
    """A message a source holds until the odometry covers ``ready_ns`` (its own payload)."""

    ready_ns: int
    stamp_ns: int
    payload: object


@dataclass(frozen=True, slots=True)
class Arrival:
    """What a source made of one of its messages.

    Attributes
    ----------
    input_ns : int or None
        Stamp of the input the supervisor's liveness counts (None: not an input, e.g. an image
        the detector failed on).
    tick : bool
        Step the supervisor at ``input_ns`` (a camera frame: a silent odometry is noticed).
    work : Work or None
        To queue (None: refused, counted in the source's skips, or not needed).
    """

    input_ns: int | None
    tick: bool = False
    work: Work | None = None


@dataclass(frozen=True, slots=True)
class FixContext:
    """What a source may read when it forms fixes: the node's state now (``level``: the
    supervisor's ladder level, :class:`~tagloc.supervise.Level`; None unknown)."""

    buffer: TransformBuffer
    filter: MapOdomFilter
    last_odom_ns: int | None
    level: int | None = None


@dataclass(frozen=True, slots=True)
class Offer:
    """A fix for the filter and its run record (whose decision the node fills in).

    Attributes
    ----------
    fix : TagFix or PartialFix
        :meth:`MapOdomFilter.update` or :meth:`~MapOdomFilter.update_partial` decides it.
    attempt : FixAttempt
    dof : int
        Directions the filter measures with it (the filter's ``dof`` for a full fix; a partial
        fix's after the planar projection): the NIS per direction, and only a fix of every
        direction counts as the last fix for the supervisor.
    reproj_px : float
        For the supervisor's quality books (NaN unknown).
    """

    fix: TagFix | PartialFix
    attempt: FixAttempt
    dof: int
    reproj_px: float = float("nan")


@dataclass(frozen=True, slots=True)
class SourceResult:
    """What one work item gave.

    Attributes
    ----------
    offers : tuple of Offer
        In the order the filter is to decide them.
    refused : tuple of FixAttempt
        Observations refused before the filter (held and handed on before the offers).
    failed : int
        Of ``refused``, how many the supervisor books as failed fixes of the source.
    frame : CameraFrameRecord or None
        The camera frame's record (held after the offers).
    release_ns : int or None
        Records stamped before this are final (None: no release now).
    detections : tuple of TagDetection
        The frame's tags (for the other sources: the lidar's cab rule).
    """

    offers: tuple[Offer, ...] = ()
    refused: tuple[FixAttempt, ...] = ()
    failed: int = 0
    frame: CameraFrameRecord | None = None
    release_ns: int | None = None
    detections: tuple[TagDetection, ...] = ()


@dataclass(frozen=True, slots=True)
class SourceInputs:
    """What the node was given that sources may need (:data:`~tagloc.localize.registry.
    FIX_SOURCES` factories read it)."""

    tag_map: TagMap
    topics: NodeTopics
    camera: CameraModel | None = None
    T_base_cam: SE3 | None = None
    detector: TagDetector | None = None
    frame_truth: Mapping[int, FrameTruth] = field(default_factory=dict)
    premap: np.ndarray | None = None
    #: Every camera of the rig on its own topics (empty: one camera on ``topics``).
    cameras: tuple[NodeCamera, ...] = ()


class FixSource(Protocol):
    """A source of absolute fixes (module docstring)."""

    @property
    def spec(self) -> FixSourceSpec:
        """The source as the supervisor sees it (name, ladder role, input stream)."""
        ...

    @property
    def max_waiting(self) -> int:
        """Work items that may wait for odometry at most (beyond: the oldest is dropped)."""
        ...

    @property
    def overflow_reason(self) -> str:
        """The skip reason of a work item dropped for want of odometry."""
        ...

    @property
    def jump_reason(self) -> str:
        """The skip reason of a work item dropped by a clock jump back."""
        ...

    @property
    def skipped(self) -> Counter[str]:
        """The source's skipped inputs by reason."""
        ...

    def arrive(self, topic: str, msg: Message) -> Arrival | None:
        """Take one stream item (None: not this source's)."""
        ...

    def fixes(self, payload: object, context: FixContext) -> SourceResult | None:
        """Form the fixes of one queued work item (None: nothing came of it, a counted skip)."""
        ...

    def observe(self, result: SourceResult) -> None:
        """Another source's result (after the filter decided it)."""
        ...

    def reset(self) -> None:
        """The clock jumped back: forget what is tied to the old timeline."""
        ...

    def metadata(self) -> dict[str, Any]:
        """Facts of the run for the node's metadata (empty: none)."""
        ...
