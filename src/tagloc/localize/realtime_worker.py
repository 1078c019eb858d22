"""The detection worker of :func:`tagloc.localize.realtime.run_wall` (the driver's wall
clock): a drop-oldest queue of camera frames and the thread that detects them.

The worker runs the detector on each frame it takes from the queue (in the regions predicted
for the frame when the node was handed it, :meth:`LocalizerNode.region_detect`, or the full
frame) and puts the frame's tags, or None when the detector raised, on an output queue for the
main thread; it never touches the node's live state. Its thread can lower its own priority so
that, on a busy core, the main thread's odometry preempts detection.
"""

from __future__ import annotations

import logging
import os
import queue
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np
import numpy.typing as npt

from tagloc.localize.fiducial import FrameFixes
from tagloc.messages import ImageMsg
from tagloc.tags import TagDetection, TagDetector

__all__ = [
    "DetectionJob",
    "DetectionResult",
    "DropOldestQueue",
    "detect_loop",
    "lower_thread_priority",
]

logger = logging.getLogger(__name__)
T = TypeVar("T")


class DropOldestQueue(Generic[T]):
    """A bounded FIFO between threads whose :meth:`put` never blocks: when full, the oldest
    item is dropped and returned.

    Parameters
    ----------
    maxsize : int
        Items waiting at most (>= 1).
    """

    def __init__(self, maxsize: int) -> None:
        if maxsize < 1:
            raise ValueError(f"queue_size: must be >= 1, got {maxsize}")
        self.maxsize = maxsize
        self._items: deque[T] = deque()
        self._cond = threading.Condition()
        self._closed = False

    def put(self, item: T) -> T | None:
        """Append ``item``; return the item dropped to make room (None if there was room).

        Raises
        ------
        RuntimeError
            If the queue is closed.
        """
        with self._cond:
            if self._closed:
                raise RuntimeError("put on a closed DropOldestQueue")
            dropped = self._items.popleft() if len(self._items) >= self.maxsize else None
            self._items.append(item)
            self._cond.notify()
            return dropped

    def get(self) -> T | None:
        """The oldest item, waiting for one; None once the queue is closed and empty."""
        with self._cond:
            while not self._items and not self._closed:
                self._cond.wait()
            return self._items.popleft() if self._items else None

    def close(self, *, discard: bool = False) -> None:
        """No more puts; :meth:`get` returns what is left (nothing with ``discard``), then
        None."""
        with self._cond:
            self._closed = True
            if discard:
                self._items.clear()
            self._cond.notify_all()

    def __len__(self) -> int:
        with self._cond:
            return len(self._items)


#: ``fixer(stamp_ns, detections)``: the frame's fixes, computed on the worker (PnP, gates).
Fixer = Callable[[int, tuple[TagDetection, ...]], FrameFixes]
#: ``detect(image, detector)``: the frame's tags in its predicted regions (or the full frame on
#: the region detector's fallbacks).
FrameDetect = Callable[[npt.NDArray[np.generic], TagDetector], list[TagDetection]]


@dataclass(frozen=True, slots=True)
class DetectionJob:
    """A frame of ``camera`` (a name of the node's rig; ``""``: its one camera) for the worker,
    the wall time (``time.perf_counter``, s) it was due, the node's fix computation when it
    is ready (None: the main thread computes the fixes) and its detection in the predicted
    regions (None: the full frame)."""

    msg: ImageMsg
    due_s: float  # wall time the frame was due, s (perf_counter)
    fixer: Fixer | None = None
    camera: str = ""
    detect: FrameDetect | None = None


@dataclass(frozen=True, slots=True)
class DetectionResult:
    """A detected frame: its tags (None when the detector raised on it), its fixes when the
    worker computed them, and the worker's wall time on each (s): the detection (with the
    regions' prediction) and the fix computation (PnP, covariance, gates: Python and small
    numpy calls, which hold the interpreter lock; 0 when not run)."""

    job: DetectionJob
    detections: tuple[TagDetection, ...] | None  # None: the detector raised
    fixes: FrameFixes | None = None
    detect_s: float = 0.0
    fixes_s: float = 0.0


def lower_thread_priority(nice: int) -> None:
    """Raise the calling thread's nice value by ``nice`` (Linux: per thread), so the main
    thread's odometry preempts detection on a busy core; elsewhere, or if refused, a no-op."""
    if nice <= 0 or not sys.platform.startswith("linux"):
        return
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + nice)
    except OSError as exc:
        logger.debug("detection worker keeps its priority: %s", exc)


def detect_loop(
    detector: TagDetector, inbox: DropOldestQueue[DetectionJob],
    outbox: queue.SimpleQueue[DetectionResult], nice: int = 0,
) -> None:  # fmt: skip
    """The worker thread's body: detect each frame of ``inbox`` until it is closed and empty.

    Parameters
    ----------
    detector : TagDetector
        Used by this thread only.
    inbox : DropOldestQueue of DetectionJob
    outbox : queue.SimpleQueue of DetectionResult
        One result per job taken, in the order taken.
    nice : int
        Added to this thread's nice value first (see :func:`lower_thread_priority`).
    """
    lower_thread_priority(nice)
    errors = 0
    while (job := inbox.get()) is not None:
        start = time.perf_counter()
        try:
            image = job.msg.image
            found = detector.detect(image) if job.detect is None else job.detect(image, detector)
            detections: tuple[TagDetection, ...] | None = tuple(found)
        except Exception:  # one frame's failure must not stop detection
            errors += 1
            if errors == 1:
                logger.warning("detector raised on the frame at %d ns; further errors are "
                               "counted", job.msg.stamp_ns, exc_info=True)  # fmt: skip
            else:
                logger.debug("detector raised on the frame at %d ns", job.msg.stamp_ns,
                             exc_info=True)  # fmt: skip
            detections = None
        detected = time.perf_counter()
        fixes = None
        if detections is not None and job.fixer is not None:
            try:  # PnP and the gates here too: the main thread only applies the fixes
                fixes = job.fixer(job.msg.stamp_ns, detections)
            except Exception:
                logger.warning("fix computation raised on the frame at %d ns; the main thread "
                               "retries it", job.msg.stamp_ns, exc_info=True)  # fmt: skip
        done = time.perf_counter()
        outbox.put(DetectionResult(job, detections, fixes, detected - start, done - detected))
