"""What a real-time run of the node measured: frames, drops, detector errors, latencies.

Latencies are wall-clock durations in seconds while they are collected and milliseconds in the
summaries. Memory is bounded: a :class:`LatencyReservoir` keeps at most ``capacity`` samples
(a uniform random sample of all of them, Vitter's algorithm R, seeded) plus the exact count
and maximum.
"""

from __future__ import annotations

import math
import random
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

__all__ = ["LatencyReservoir", "LatencySummary", "RealtimeStats"]

#: Samples a reservoir keeps by default (800 kB of floats).
DEFAULT_CAPACITY = 100_000


@dataclass(frozen=True, slots=True)
class LatencySummary:
    """Percentiles of one latency.

    Attributes
    ----------
    n : int
        Samples seen (all of them, not only those kept).
    p50_ms, p99_ms : float
        Median and 99th percentile, ms, of the kept samples (NaN without samples).
    max_ms : float
        Largest sample seen, ms (NaN without samples).
    """

    n: int
    p50_ms: float
    p99_ms: float
    max_ms: float

    def text(self) -> str:
        """``p50 / p99 / max`` in ms, one line."""
        return (f"p50 {self.p50_ms:.2f} ms, p99 {self.p99_ms:.2f} ms, max {self.max_ms:.2f} ms "
                f"(n={self.n})")  # fmt: skip


class LatencyReservoir:
    """A bounded uniform sample of latencies (seconds), for percentiles over a long run.

    Parameters
    ----------
    capacity : int
        Samples kept; past it, sample ``i`` replaces a random kept one with probability
        ``capacity / i`` (algorithm R), so the kept ones stay a uniform sample of all.
    seed : int
        Seed of the replacement choice.
    """

    def __init__(self, capacity: int = DEFAULT_CAPACITY, seed: int = 0) -> None:
        if capacity < 1:
            raise ValueError(f"capacity: must be >= 1, got {capacity}")
        self.capacity = capacity
        self.n = 0
        self.max_s = -math.inf
        self._kept: list[float] = []
        self._rng = random.Random(seed)

    def add(self, latency_s: float) -> None:
        """One sample, seconds."""
        self.n += 1
        self.max_s = max(self.max_s, latency_s)
        if len(self._kept) < self.capacity:
            self._kept.append(latency_s)
            return
        j = self._rng.randrange(self.n)
        if j < self.capacity:
            self._kept[j] = latency_s

    def __len__(self) -> int:
        """Samples kept (at most ``capacity``)."""
        return len(self._kept)

    def summary(self) -> LatencySummary:
        """p50, p99 and max, ms."""
        if not self._kept:
            return LatencySummary(self.n, math.nan, math.nan, math.nan)
        p50, p99 = np.percentile(np.asarray(self._kept), [50.0, 99.0]) * 1e3
        return LatencySummary(self.n, float(p50), float(p99), self.max_s * 1e3)


@dataclass(frozen=True, slots=True)
class RealtimeStats:
    """The summary of :func:`tagloc.localize.realtime.run_wall` (the driver's wall clock).

    Attributes
    ----------
    frames_in : int
        ``ImageMsg`` frames on the node's image topic handed to the detection worker.
    frames_dropped : int
        Of those, dropped unseen by the detector (the queue was full: the oldest is dropped).
    detector_errors : int
        Frames on which the detector raised (logged; the frame is lost).
    detections_in : int
        ``TagDetectionsMsg`` frames of the source passed straight to the node.
    odom_to_estimate : LatencySummary
        Wall time from feeding an odometry sample to the node to its ``Estimate`` having been
        handed to every sink (the run's timing sink comes after the node's own).
    odom_due_to_estimate : LatencySummary
        The same from when the sample was due by the pacing (adds the wait for the main thread
        when it was busy, e.g. with the previous message).
    odom_frame_to_estimate : LatencySummary
        ``odom_to_estimate`` of the samples whose feed also decided camera frames (the node
        turns a frame into fixes and filter updates at the first odometry sample at or after
        its stamp, before that sample's estimate): the costly ones.
    odom_only_to_estimate : LatencySummary
        ``odom_to_estimate`` of the other samples (prediction, estimate, supervisor only).
    image_to_correction : LatencySummary
        Wall time from when a frame was due to the first ``Estimate`` published after the
        frame's detections were fed to the node whose stamp is at or after the frame's (the
        node decides a frame's fixes before that estimate). Frames whose detections arrive
        after the last odometry sample are not measured.
    wall_s : float
        Wall time of the run, s (source exhausted, queue drained, ``node.finish()`` done).
    stream_s : float
        Stamp span of the source, s.
    speed : float
        Pacing factor (``inf``: as fast as possible).
    worker_detect : LatencySummary
        The worker's time per frame in detection (with the regions' prediction; the AprilTag
        library releases the interpreter lock while it runs).
    worker_fixes : LatencySummary
        The worker's time per frame in the fix computation (PnP, covariance, gates: Python and
        small numpy calls, which hold the interpreter lock against the main thread's odometry
        in slices of ``sys.getswitchinterval()``); the frames whose fixes it formed.
    frames_regions : int
        Frames the worker detected in predicted regions only (``tags.roi``).
    full_frame_reasons : dict of str to int
        The frames it detected in full, by reason (:mod:`tagloc.localize.roi_detector`; empty
        when ``tags.roi.enabled`` is false).
    """

    frames_in: int
    frames_dropped: int
    detector_errors: int
    detections_in: int
    odom_to_estimate: LatencySummary
    odom_due_to_estimate: LatencySummary
    odom_frame_to_estimate: LatencySummary
    odom_only_to_estimate: LatencySummary
    image_to_correction: LatencySummary
    wall_s: float
    stream_s: float
    speed: float
    worker_detect: LatencySummary = LatencySummary(0, math.nan, math.nan, math.nan)
    worker_fixes: LatencySummary = LatencySummary(0, math.nan, math.nan, math.nan)
    frames_regions: int = 0
    full_frame_reasons: dict[str, int] = field(default_factory=dict)

    @property
    def drop_fraction(self) -> float:
        """``frames_dropped / frames_in`` (0 without frames)."""
        return self.frames_dropped / self.frames_in if self.frames_in else 0.0

    def to_dict(self) -> dict[str, Any]:
        """Plain values (latency summaries as nested dicts, ms), with ``drop_fraction``."""
        out = asdict(self)
        out["drop_fraction"] = self.drop_fraction
        return out

    def lines(self) -> list[str]:
        """A human summary, one fact a line."""
        speed = "as fast as possible" if math.isinf(self.speed) else f"speed {self.speed:g}"
        return [
            f"stream {self.stream_s:.1f} s in {self.wall_s:.1f} s wall ({speed})",
            f"frames: {self.frames_in} images in, {self.frames_dropped} dropped "
            f"({100 * self.drop_fraction:.1f} %), {self.detector_errors} detector errors, "
            f"{self.detections_in} pre-detected",
            f"odometry -> estimate: {self.odom_to_estimate.text()}",
            f"odometry due -> estimate: {self.odom_due_to_estimate.text()}",
            f"odometry with a frame -> estimate: {self.odom_frame_to_estimate.text()}",
            f"odometry without a frame -> estimate: {self.odom_only_to_estimate.text()}",
            f"image due -> correction: {self.image_to_correction.text()}",
            f"worker, detection: {self.worker_detect.text()}",
            f"worker, fix computation: {self.worker_fixes.text()}",
            f"detection: {self.frames_regions} frames in predicted regions, "
            f"{sum(self.full_frame_reasons.values())} full "
            f"({', '.join(f'{k} {v}' for k, v in sorted(self.full_frame_reasons.items()))})",
        ]
