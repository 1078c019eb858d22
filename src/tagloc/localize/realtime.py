"""Real-time operation of the node: wall-clock pacing, detection on a worker thread, drops.

:func:`run_wall` is the ``clock="wall"`` of the driver (:func:`tagloc.localize.driver.run`): it
feeds a :class:`~tagloc.localize.node.LocalizerNode` from any message source (an iterable of
``(topic, record)`` in arrival order: a bag, the simulator) as a live robot would see it:

1. **Pacing.** The record stamped ``t`` is fed at wall time ``start + (t - t0) / speed``
   (``t0``: the first record's stamp); ``speed=None`` or ``inf`` feeds as fast as possible.
2. **Detection off the main thread.** An ``ImageMsg`` on the image topic of any camera of
   the node's rig (:attr:`LocalizerNode.cameras`; one camera on the node's image topic if none
   were given) goes to one bounded queue (``queue_size``, shared by the cameras: the detector
   is one resource); when it is full the *oldest* waiting frame, of whichever camera, is
   dropped and counted (a stale frame is worth less than a fresh one). One worker thread, at a
   lower priority (``worker_nice``), runs the detector (the node's configured backend unless
   given) and hands back the frame's tags (:mod:`tagloc.localize.realtime_worker`). It detects
   in the regions where the mapped tags are predicted (``tags.roi``,
   :mod:`tagloc.localize.roi_detector`, with its fallbacks to the full frame: every
   ``full_frame_every`` frames, after a gap, after an alarming decision, ...), predicted from
   the node's estimate and state when the frame was handed to the worker (never a later
   one: :meth:`LocalizerNode.region_detect`); the main
   thread feeds them to the node as a ``TagDetectionsMsg`` (same stamp and ``frame_id``) on
   that camera's detections topic. Once the node can form a camera's fixes (its model and
   extrinsics known), the worker also computes each of its frames' fixes (PnP, covariance,
   gates, with the node's latest estimate as the orientation prior:
   :meth:`LocalizerNode.fixer`), so the main thread only applies them to the filter, as that
   camera's. A detector that raises loses that frame: logged, counted.
   ``TagDetectionsMsg`` records of the source, on any camera's detections topic, go straight
   to the node.
3. **The node stays single-threaded.** Only the main thread calls ``node.feed``; it never waits
   for the worker while the source runs (odometry is never blocked by detection), only at the
   end: the queue is drained (every waiting frame detected and fed), then ``node.finish()``.

Latencies are measured by a sink the node is built with, beside the caller's (definitions in
:class:`~tagloc.localize.realtime_stats.RealtimeStats`); memory stays bounded.
"""

from __future__ import annotations

import heapq
import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Iterable, Sequence

from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import Estimate, NodeOutput, OutputSink
from tagloc.localize.realtime_stats import LatencyReservoir, RealtimeStats
from tagloc.localize.realtime_worker import (
    DetectionJob,
    DetectionResult,
    DropOldestQueue,
    detect_loop,
)
from tagloc.messages import ImageMsg, Message, TagDetectionsMsg
from tagloc.tags import TagDetector, make_detector
from tagloc.units import S_NS

__all__ = ["RealtimeStats", "run_wall"]

logger = logging.getLogger(__name__)
#: Frames awaiting their correction at most (more go unmeasured).
_MAX_WAITING_FRAMES = 4096


class _TimingSink:
    """One of the node's sinks for the run: timestamps the ``Estimate`` outputs."""

    def __init__(self) -> None:
        self.odom = LatencyReservoir(seed=1)
        self.odom_due = LatencyReservoir(seed=2)
        self.odom_frame = LatencyReservoir(seed=3)
        self.odom_only = LatencyReservoir(seed=4)
        self.correction = LatencyReservoir(seed=5)
        self.worker_detect = LatencyReservoir(seed=6)
        self.worker_fixes = LatencyReservoir(seed=7)
        self._expect: tuple[int, float, float] | None = None  # stamp, fed, due (s)
        self._waiting: list[tuple[int, int, float]] = []  # heap: (stamp, seq, due)
        self._seq = 0

    def feeding(self, stamp_ns: int, fed_s: float, due_s: float) -> None:
        """The main thread is about to feed a record stamped ``stamp_ns``."""
        self._expect = (stamp_ns, fed_s, due_s)

    def frame_fed(self, stamp_ns: int, due_s: float) -> None:
        """A frame's detections were fed: its correction is the next estimate at or after it."""
        if len(self._waiting) >= _MAX_WAITING_FRAMES:
            return  # no odometry for a long while: this frame goes unmeasured
        self._seq += 1
        heapq.heappush(self._waiting, (stamp_ns, self._seq, due_s))

    def write(self, output: NodeOutput) -> None:
        if not isinstance(output, Estimate):
            return
        now = time.perf_counter()
        frames = 0  # decided in this feed, before this estimate
        while self._waiting and self._waiting[0][0] <= output.stamp_ns:
            self.correction.add(now - heapq.heappop(self._waiting)[2])
            frames += 1
        if self._expect is not None and self._expect[0] == output.stamp_ns:
            _, fed_s, due_s = self._expect
            self.odom.add(now - fed_s)
            self.odom_due.add(now - due_s)
            (self.odom_frame if frames else self.odom_only).add(now - fed_s)
            self._expect = None


class _Runner:
    """State of one :func:`run_wall` call (main thread only)."""

    def __init__(
        self, node: LocalizerNode, timing: _TimingSink,
        outbox: queue.SimpleQueue[DetectionResult],
    ) -> None:  # fmt: skip
        self.node, self.outbox = node, outbox
        self.timing = timing
        self.frames_in = self.dropped = self.errors = self.detections_in = 0
        cameras = node.cameras
        #: image topic -> camera, camera -> its detections topic, detections topics
        self.image_camera = {c.image_topic: c.name for c in cameras if c.image_topic}
        self.detections_topic = {c.name: c.detections_topic for c in cameras}
        self.detections_topics = frozenset(self.detections_topic.values())

    def feed(self, topic: str, msg: Message, due_s: float) -> None:
        self.timing.feeding(msg.stamp_ns, time.perf_counter(), due_s)
        self.node.feed(topic, msg)

    def deliver(self, result: DetectionResult) -> None:
        """A detected frame to the node (or an error counted)."""
        self.timing.worker_detect.add(result.detect_s)
        if result.fixes is not None:
            self.timing.worker_fixes.add(result.fixes_s)
        if result.detections is None:
            self.errors += 1
            return
        job = result.job
        image = job.msg
        if result.fixes is not None:  # computed on the worker: the node applies them
            self.timing.feeding(image.stamp_ns, time.perf_counter(), job.due_s)
            self.node.feed_frame(image.stamp_ns, image.frame_id, result.detections, result.fixes,
                                 job.camera)  # fmt: skip
        else:
            msg = TagDetectionsMsg(image.stamp_ns, image.frame_id, result.detections)
            self.feed(self.detections_topic[job.camera], msg, job.due_s)
        self.timing.frame_fed(image.stamp_ns, result.job.due_s)

    def deliver_ready(self) -> None:
        while True:
            try:
                result = self.outbox.get_nowait()
            except queue.Empty:
                return
            self.deliver(result)

    def wait_until(self, due_s: float) -> None:
        """Sleep until ``due_s`` (perf_counter s), feeding detected frames as they come."""
        while (remaining := due_s - time.perf_counter()) > 0:
            try:
                result = self.outbox.get(timeout=remaining)
            except queue.Empty:
                return
            self.deliver(result)


def run_wall(
    build: Callable[[Sequence[OutputSink]], LocalizerNode],
    source: Iterable[tuple[str, Message]], sinks: Sequence[OutputSink] = (), *,
    speed: float | None = 1.0, queue_size: int = 2, detector: TagDetector | None = None,
    worker_nice: int = 10,
    check: Callable[[LocalizerNode, Iterable[tuple[str, Message]]], None] | None = None,
) -> tuple[LocalizerNode, RealtimeStats]:  # fmt: skip
    """Run the node ``build(sinks + timing)`` on ``source`` paced by the wall clock, detecting
    images on a worker thread.

    Parameters
    ----------
    build : callable
        ``build(sinks) -> LocalizerNode``; the node is fed from this (the calling) thread only,
        and ``finish()`` is called at the end.
    source : iterable of (topic, Message)
        In arrival order (a :class:`~tagloc.messages.MessageSource`).
    sinks : sequence of OutputSink
        The node's outputs, as they happen (the timing sink of this run follows them).
    speed : float or None
        Stream seconds per wall second (1.0: real time); None or ``inf``: as fast as possible.
    queue_size : int
        Frames waiting for the detector at most (one more may be in detection).
    detector : TagDetector, optional
        Used by the worker only (default: ``make_detector(config.tags.backend,
        config.tags.family)`` of the node's configuration).
    worker_nice : int
        Added to the worker thread's nice value (Linux; 0: unchanged), so that detection
        yields a shared core to the main thread's odometry (on one loaded core it cut the p99
        of odometry due -> estimate by 3-9x, ``benchmarks/bench_realtime.py``).
    check : callable, optional
        ``check(node, source)`` before any record is read (the driver's topic check).

    Returns
    -------
    node : LocalizerNode
        Finished.
    stats : RealtimeStats
        Frames, drops, detector errors and latency percentiles (module docstring).

    Raises
    ------
    ValueError
        If ``speed`` is not positive or ``queue_size`` < 1.
    LocalizeError
        From ``node.finish()`` (no usable odometry).
    """
    rate = math.inf if speed is None else float(speed)
    if not rate > 0:
        raise ValueError(f"speed: must be > 0 (or None), got {speed}")
    inbox: DropOldestQueue[DetectionJob] = DropOldestQueue(queue_size)
    outbox: queue.SimpleQueue[DetectionResult] = queue.SimpleQueue()
    timing = _TimingSink()
    node = build((*sinks, timing))
    if check is not None:
        check(node, source)
    tags = node.config.tags
    detector = detector if detector is not None else make_detector(tags.backend, tags.family)
    worker = threading.Thread(
        target=detect_loop, args=(detector, inbox, outbox, worker_nice), name="tagloc-detect",
        daemon=True,
    )  # fmt: skip
    run = _Runner(node, timing, outbox)
    t0: int | None = None
    stamp_last, start = 0, time.perf_counter()
    worker.start()
    try:
        for topic, msg in source:
            # 1. pace: wait until the record is due, feeding detected frames meanwhile
            t0 = msg.stamp_ns if t0 is None else t0
            stamp_last = max(stamp_last, msg.stamp_ns)
            due_s = start + (msg.stamp_ns - t0) / S_NS / rate
            if math.isinf(rate):
                due_s = time.perf_counter()
            run.wait_until(due_s)
            run.deliver_ready()
            # 2. images to the worker (never waiting for it), everything else to the node
            camera = run.image_camera.get(topic) if isinstance(msg, ImageMsg) else None
            if isinstance(msg, ImageMsg) and camera is not None:
                run.frames_in += 1
                # the node's state now, for the fixes' and the regions' computation later
                fixer = node.fixer(msg.stamp_ns, msg.frame_id, camera)
                detect = node.region_detect(msg.stamp_ns, camera)
                if inbox.put(DetectionJob(msg, due_s, fixer, camera, detect)) is not None:
                    run.dropped += 1
                    if run.dropped == 1:
                        logger.info("detector behind: dropped the oldest waiting frame "
                                    "(further drops are counted)")  # fmt: skip
                continue
            if isinstance(msg, TagDetectionsMsg) and topic in run.detections_topics:
                run.detections_in += 1
                run.feed(topic, msg, due_s)
                run.timing.frame_fed(msg.stamp_ns, due_s)
                continue
            run.feed(topic, msg, due_s)
        # 3. drain: the worker detects what is waiting; then the node finishes
        inbox.close()
        while worker.is_alive() or not outbox.empty():
            run.wait_until(time.perf_counter() + 0.01)
        node.finish()
    finally:
        inbox.close(discard=True)
        worker.join()
    regions = node.metadata().get("regions") or {}
    stats = RealtimeStats(
        frames_in=run.frames_in, frames_dropped=run.dropped, detector_errors=run.errors,
        detections_in=run.detections_in, odom_to_estimate=timing.odom.summary(),
        odom_due_to_estimate=timing.odom_due.summary(),
        odom_frame_to_estimate=timing.odom_frame.summary(),
        odom_only_to_estimate=timing.odom_only.summary(),
        image_to_correction=timing.correction.summary(), wall_s=time.perf_counter() - start,
        stream_s=0.0 if t0 is None else (stamp_last - t0) / S_NS, speed=rate,
        worker_detect=timing.worker_detect.summary(),
        worker_fixes=timing.worker_fixes.summary(), frames_regions=regions.get("frames_regions", 0),
        full_frame_reasons=dict(regions.get("full_frame_reasons", {})),
    )  # fmt: skip
    return node, stats
