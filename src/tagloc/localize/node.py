"""The streaming localizer node: messages in, in stamp order; outputs to sinks as they happen.

One code path for simulated and real data, live or replayed (DESIGN.md's data flow). Feed it
``(topic, record)`` pairs (:mod:`tagloc.messages`) with :meth:`LocalizerNode.feed`; the roles of
topics are named by :class:`~tagloc.messages.NodeTopics`:

- odometry: an ``OdometryMsg`` on ``odom``, or a ``TransformMsg`` on ``tf`` whose edge is the
  configured ``odom_frame -> base_frame`` (ROS ``/tf``, dimos's ``world -> base_link``). Each
  sample is the ``odom -> base`` edge of a bounded :class:`~tagloc.frames.TransformBuffer`, a
  prediction of the filter, a step of the supervisor, and one :class:`~tagloc.localize.outputs.
  Estimate` (and a status message when one is due).
- a clock that jumps back (odometry stamped more than ``supervisor.clock_jump_s`` before the
  last sample): the node starts over, as ROS tf does (buffer, estimate, waiting work dropped,
  every component reset; the ladder falls to odometry only with the reason); smaller steps
  back are counted skips.
- static ``TransformMsg`` (``base -> camera``, ``base -> lidar``) into the buffer;
  ``GroundTruthMsg`` (``truth``) is passed through.
- everything else goes to the fix sources (:mod:`tagloc.localize.sources`, built from
  :mod:`tagloc.localize.registry`): camera frames and ``CameraInfoMsg`` to the tag source
  (:class:`~tagloc.localize.source_tags.TagSource`), lidar sweeps to the lidar source when the
  node has a premap and ``lidar.enabled`` (:class:`~tagloc.localize.source_lidar.LidarSource`).
  Their work waits in one queue until the odometry covers it; each fix is decided by the
  filter at its own stamp.

Outputs leave by one path, to the sinks given at construction: the estimates, the filter's own
events (initialization, gap, cap, suspect source; :data:`~tagloc.localize.events.
FIX_DECISIONS` excepted), the ladder's moves and the status; and each fix's decision once, final,
as its :class:`~tagloc.localize.run.FixAttempt` (held until no batch decision of the filter can
revise it), with each camera frame's :class:`~tagloc.localize.run.CameraFrameRecord`.

Bad input is a counted, logged skip (:attr:`LocalizerNode.skipped`). Memory is bounded: the
transform buffer's window, work waiting for odometry, and records within the consistency
window; everything else leaves through the sinks.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.localize.cab import Elevators, check_cab_frames
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.decisions import FixDecisions
from tagloc.localize.estimate_output import EstimateOutput
from tagloc.localize.events import FIX_DECISIONS, EventKind, FilterEvent
from tagloc.localize.fiducial import FrameFixes
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import LocalizeError
from tagloc.localize.fusion import Fusion
from tagloc.localize.motion import CALIBRATION_PARAMETERS
from tagloc.localize.outputs import NodeOutput, OutputSink
from tagloc.localize.realtime_worker import FrameDetect
from tagloc.localize.registry import build_fix_sources
from tagloc.localize.source_tags import TagSource
from tagloc.localize.sources import Arrival, FixContext, FixSource, SkipCounter, SourceInputs
from tagloc.localize.tag_cameras import NodeCamera
from tagloc.localize.work_queue import WorkQueue
from tagloc.messages import (
    ElevatorStateMsg,
    FrameTruth,
    GroundTruthMsg,
    Message,
    NodeTopics,
    OdometryMsg,
    TransformMsg,
)
from tagloc.supervise import EstimatorState, Supervisor
from tagloc.tags import TagDetection, TagDetector, TagMap
from tagloc.units import S_NS

__all__ = ["FrameTruth", "LocalizerNode", "NodeCamera", "NodeTopics"]

logger = logging.getLogger(__name__)


class LocalizerNode:
    """The node (module docstring). Call :meth:`feed` per message, :meth:`finish` at the end.

    Parameters
    ----------
    tag_map : TagMap
    config : LocalizerConfig, optional
        The one configuration (``localizer.yaml``), fixed for the node's life.
    sinks : sequence of OutputSink
        Every output, as it happens (fixed for the node's life).
    camera : CameraModel, optional
        Default: from the first ``CameraInfoMsg``.
    T_base_cam : SE3, optional
        Default: the static ``base -> <frame's frame_id>`` transform of the stream.
    topics : NodeTopics, optional
    detector : TagDetector, optional
        For ``ImageMsg`` frames (default: the configured backend and family, on first use).
    frame_truth : Mapping[int, FrameTruth], optional
        Simulator truth by frame stamp (fills ``false_detection`` / ``nearest_visible_tag_m``).
    premap : (N, 3) float, optional
        The point cloud map (in the map frame, m) the lidar sweeps are registered against;
        prepared once here. None (or ``lidar.enabled: false``): the lidar topic is ignored.
    cameras : sequence of NodeCamera, optional
        Every camera of the rig, each on its own topics with its model and extrinsics
        (:mod:`tagloc.localize.tag_cameras`); instead of ``camera`` / ``T_base_cam`` and the
        topics' camera roles. Default: one camera on ``topics``.

    Raises
    ------
    LocalizeError
        If two cameras share a name or topic, or are given beside ``camera`` / ``T_base_cam``.
        If the premap is not a finite ``(N, 3)`` array of at least 10 points, or misses every
        tag of the map frame (:func:`~tagloc.localize.source_lidar.check_premap_overlap`).
    """

    def __init__(
        self, tag_map: TagMap, config: LocalizerConfig | None = None,
        sinks: Sequence[OutputSink] = (), *, camera: CameraModel | None = None,
        T_base_cam: SE3 | None = None, topics: NodeTopics | None = None,
        detector: TagDetector | None = None, frame_truth: Mapping[int, FrameTruth] | None = None,
        premap: np.ndarray | None = None, cameras: Sequence[NodeCamera] = (),
    ) -> None:  # fmt: skip
        cfg = config or LocalizerConfig()
        self._config, self._topics, self._sinks = cfg, topics or NodeTopics(), tuple(sinks)
        cabs, floors = check_cab_frames(tag_map, cfg), Elevators.floor_frame(tag_map, cfg)
        self._fusion = Fusion(cfg, self._on_event, floors)
        inputs = SourceInputs(tag_map, self._topics, camera, T_base_cam, detector,
                              frame_truth or {}, premap, tuple(cameras))  # fmt: skip
        self._sources: tuple[FixSource, ...] = build_fix_sources(cfg, inputs)
        self._tags = next((s for s in self._sources if isinstance(s, TagSource)), None)
        self.supervisor = Supervisor(
            cfg.supervisor, [s.spec for s in self._sources], cfg.gates.gap_s, cfg.gates.gap_m,
            cfg.elevators if cabs or floors else None, None if floors is None else floors.heights_m,
        )
        self._elevators = Elevators.build(
            tag_map, cfg, self.supervisor, floors, self._emit, lambda: self._fusion.filter
        )
        self._queue = WorkQueue()
        self._skipped = SkipCounter()
        self._decisions = FixDecisions(cfg, self.supervisor, self._emit)
        if self._elevators is not None:  # the cab's fix attempts leave with the map's
            self._elevators.on_fix = self._decisions.record
        self._estimates = EstimateOutput(cfg)
        self._jump_ns = round(cfg.supervisor.clock_jump_s * S_NS)
        self._odom_cov_growth = cfg.process_noise.odometry_covariance == "growth"
        self._odometer_m = 0.0
        self.clock_jumps = 0
        self._start_over()

    def _start_over(self) -> None:
        """The timeline's own state (at construction and after a clock jump)."""
        self._last_odom: int | None = None
        self._last_T: SE3 | None = None
        self._tick_ns = -(2**62)
        #: The correction published at the latest odometry sample (None uninitialized): read by
        #: worker threads (an attribute assignment is atomic).
        self.latest_T_map_odom: SE3 | None = None

    # ----- what the node is ------------------------------------------------------------------
    @property
    def config(self) -> LocalizerConfig:
        """The configuration (fixed at construction)."""
        return self._config

    @property
    def topics(self) -> NodeTopics:
        return self._topics

    @property
    def filter(self) -> MapOdomFilter:
        """The ``map -> odom`` filter now (a new one after a clock jump)."""
        return self._fusion.filter

    @property
    def fix_sources(self) -> tuple[FixSource, ...]:
        """The fix sources, in the registry's order."""
        return self._sources

    @property
    def camera(self) -> CameraModel | None:
        """The camera model in use (given, or from the first ``CameraInfoMsg``; None yet)."""
        return None if self._tags is None else self._tags.camera

    @property
    def T_base_cam(self) -> SE3 | None:
        """The (first camera's) extrinsics in use (given, or the stream's static transform once
        a frame needed it; None yet)."""
        return None if self._tags is None else self._tags.T_base_cam

    @property
    def camera_names(self) -> tuple[str, ...]:
        """The cameras fixes come from (``("",)``: the one camera on :attr:`topics`)."""
        return () if self._tags is None else self._tags.camera_names

    @property
    def cameras(self) -> tuple[NodeCamera, ...]:
        """The cameras and their topics (one, ``""``, on :attr:`topics` if none were given)."""
        return () if self._tags is None else self._tags.cameras

    @property
    def T_base_cam_by_camera(self) -> dict[str, SE3 | None]:
        """Each camera's extrinsics in use, by name (None: not known yet)."""
        return {} if self._tags is None else self._tags.T_base_cam_by_camera

    @property
    def skipped(self) -> Counter[str]:
        """Skipped inputs by reason: the node's (odometry, work without odometry, a clock
        jump) and its fix sources'."""
        out = Counter(self._skipped)
        for source in self._sources:
            out.update(source.skipped)
        return out

    # ----- input -----------------------------------------------------------------------------
    def feed(self, topic: str, msg: Message) -> None:
        """Consume one stream item (other topics and record types are ignored)."""
        t, f = self._topics, self._config.frames
        if isinstance(msg, OdometryMsg) and topic == t.odom:
            self._on_odometry(msg.stamp_ns, msg.T_parent_child, msg.cov)
        elif isinstance(msg, TransformMsg) and not msg.static:
            if topic == t.tf and (msg.parent, msg.child) == (f.odom_frame, f.base_frame):
                self._on_odometry(msg.stamp_ns, msg.T_parent_child)
        elif isinstance(msg, TransformMsg) and msg.static:
            self._fusion.set_static(msg.parent, msg.child, msg.T_parent_child)
        elif isinstance(msg, GroundTruthMsg) and topic == t.truth:
            self._emit(msg)
        elif isinstance(msg, ElevatorStateMsg):  # the building's door news
            if self._elevators is not None and topic == t.elevator:
                self._elevators.door(msg.stamp_ns, msg.cab_frame, msg.door_open)
        else:
            for index, source in enumerate(self._sources):
                arrival = source.arrive(topic, msg)
                if arrival is not None:
                    self._arrived(index, source, arrival)

    def feed_frame(
        self, stamp_ns: int, frame_id: str, detections: tuple[TagDetection, ...],
        fixes: FrameFixes, camera: str | None = None,
    ) -> None:  # fmt: skip
        """A frame of ``camera`` (None: the first) whose fixes were formed elsewhere (by
        :meth:`fixer`, on another thread): queued like any frame, applied when the odometry
        covers its stamp."""
        if self._tags is not None:
            arrival = self._tags.arrive_fixed(stamp_ns, frame_id, detections, fixes, camera)
            self._arrived(self._sources.index(self._tags), self._tags, arrival)

    def fixer(
        self, stamp_ns: int, frame_id: str, camera: str | None = None
    ) -> Callable[[int, tuple[TagDetection, ...]], FrameFixes] | None:
        """A function that forms a frame's fixes of ``camera`` (None: the first) without
        touching the node's state, for a worker thread (None until the camera's model and
        extrinsics are known). Its orientation prior is
        the newest published correction when it runs (the frame may wait behind others: the
        filter has moved on by then) composed with the odometry when the frame arrived."""
        if self._tags is None:
            return None
        T_odom_base = self._last_T  # the odometry now, about the frame's stamp

        def prior() -> SE3 | None:
            T_map_odom = self.latest_T_map_odom  # the newest correction when the worker runs
            return None if T_map_odom is None or T_odom_base is None else T_map_odom @ T_odom_base

        return self._tags.fixer(stamp_ns, frame_id, self._context(), prior, T_odom_base, camera)

    def region_detect(
        self, stamp_ns: int, camera: str | None = None
    ) -> FrameDetect | None:
        """A function ``detect(image, detector)`` that detects the frame at ``stamp_ns`` of
        ``camera`` (None: the first) in the regions predicted from the node's estimate now,
        with the region detector's fallbacks, for a worker thread (None: no tag source, or
        ``tags.roi.enabled`` false); :meth:`TagSource.region_detect`."""
        if self._tags is None:
            return None
        return self._tags.region_detect(stamp_ns, self._context(), camera)

    def finish(self) -> None:
        """Process the work still waiting for odometry and hand on every held record.

        Raises
        ------
        LocalizeError
            If the stream held no usable odometry.
        """
        self._run_due(None)
        self._decisions.release_all()
        if self._last_odom is None:
            f = self._config.frames
            raise LocalizeError(
                f"no usable odometry on {self._topics.odom!r} or as {f.odom_frame} "
                f"-> {f.base_frame} on {self._topics.tf!r} "
                f"(skipped: {dict(self.skipped) or 'none'})"
            )

    # ----- odometry --------------------------------------------------------------------------
    def _on_odometry(self, stamp: int, T: SE3, cov: np.ndarray | None = None) -> None:
        if not (np.isfinite(T.translation).all() and np.isfinite(T.as_quat()).all()):
            return self._skipped.skip("odom_non_finite", f"odometry at {stamp} ns")
        if self._last_odom is not None and stamp <= self._last_odom:
            if self._last_odom - stamp > self._jump_ns:
                self._clock_jump(stamp)
            else:
                reason = (
                    "odom_duplicate_stamp" if stamp == self._last_odom else "odom_stamp_backwards"
                )
                detail = f"odometry: {stamp} ns after {self._last_odom} ns"
                return self._skipped.skip(reason, detail)
        self._last_odom = stamp
        if self._last_T is not None:
            self._odometer_m += float(np.linalg.norm(T.translation - self._last_T.translation))
        self._last_T = T
        f, fusion = self._config.frames, self._fusion
        fusion.buffer.set_transform(f.odom_frame, f.base_frame, stamp, T)
        self.supervisor.on_input("odometry", stamp)
        if cov is not None and self._odom_cov_growth:
            fusion.odometry_covariance(cov)
        first = self._config.output.publish_first
        if first:
            self._estimate(stamp, T)
        self._run_due(stamp)
        if not first:
            self._estimate(stamp, T)
        return None

    def _estimate(self, stamp: int, T_odom_base: SE3) -> None:
        """Predict to the sample, publish its estimate, step the supervisor."""
        self._fusion.filter.predict(stamp)
        estimate = self._estimates.estimate(self._fusion, stamp, T_odom_base)
        if self._elevators is not None:  # the cab's estimate; the floor of this one
            self._elevators.odometry(stamp, self._odometer_m, self._fusion.buffer)
            estimate = self._elevators.estimate(estimate)
        self.latest_T_map_odom = estimate.T_map_odom if estimate.initialized else None
        self._emit(estimate)
        self._tick(stamp)

    # ----- fixes -----------------------------------------------------------------------------
    def _arrived(self, index: int, source: FixSource, arrival: Arrival) -> None:
        if arrival.input_ns is not None:
            self.supervisor.on_input(source.spec.input, arrival.input_ns)
            if arrival.tick:
                self._tick(arrival.input_ns)
        if arrival.work is not None and self._queue.push(index, source, arrival.work):
            self._skipped.skip(
                source.overflow_reason,
                f"over {source.max_waiting} {source.spec.name} items wait for odometry",
            )

    def _context(self) -> FixContext:
        return FixContext(
            self._fusion.buffer, self._fusion.filter, self._last_odom, int(self.supervisor.level)
        )

    def _run_due(self, odom_ns: int | None) -> None:
        """Form and decide the fixes of the work the odometry up to ``odom_ns`` covers."""
        for index, work in self._queue.due(odom_ns):
            source = self._sources[index]
            result = source.fixes(work.payload, self._context())
            if result is None:
                continue
            self._decisions.apply(
                self._sources, index, result, self._fusion.filter, self._odometer_m
            )
            if self._elevators is not None and result.frame is not None:  # the cab's tags
                self._elevators.frame(
                    result.frame.stamp_ns, result.detections, self._fusion.buffer, self.camera,
                    self.T_base_cam,
                )
            for other in self._sources:
                if other is not source:
                    other.observe(result)

    # ----- supervisor, clock jumps -----------------------------------------------------------
    def _tick(self, stamp: int, reason: str = "") -> None:
        """Step the supervisor (and publish the status when due) at ``stamp``: at every odometry
        sample and every camera frame, so a silent input is noticed while others still arrive.
        Older stamps than the last tick are not stepped."""
        if stamp < self._tick_ns:
            return
        self._tick_ns = stamp
        flt = self._fusion.filter
        since_s, since_m = self._decisions.since_last_fix(stamp, self._odometer_m)
        state = EstimatorState(flt.initialized, flt.reacquiring, since_s, since_m)
        if self._elevators is not None:  # in a riding cab, the cab's estimate
            state = self._elevators.estimator_state(state, stamp)
        move = self.supervisor.step(stamp, state, reason)
        if move is not None:
            self._emit(move)
        if self.supervisor.status_due(stamp):  # the sigmas only for the status (not per tick)
            cov = self._estimates.cov_map_base if flt.initialized else None
            if cov is not None:
                sxy = math.sqrt(max(float(np.linalg.eigvalsh(cov[:2, :2])[-1]), 0.0))
                syaw = math.degrees(math.sqrt(max(float(cov[5, 5]), 0.0)))
                state = dataclasses.replace(state, sigma_xy_m=sxy, sigma_yaw_deg=syaw)
            self._emit(self.supervisor.status(stamp, state))

    def _clock_jump(self, stamp: int) -> None:
        """Odometry stamped far before the last one: the clock jumped back (a restarted driver, a
        bag played in a loop). Like ROS tf, start over: the work waiting is dropped, held
        records handed on, every component reset, and the ladder falls to odometry only."""
        assert self._last_odom is not None
        back_s = (self._last_odom - stamp) / S_NS
        logger.warning("clock jumped back %.3f s (odometry at %d ns): starting over", back_s, stamp)
        self.clock_jumps += 1
        dropped = self._queue.clear()
        for index, source in enumerate(self._sources):
            if dropped[index]:
                self._skipped[source.jump_reason] += dropped[index]
            source.reset()
        self._decisions.reset()
        self._fusion.reset()
        if self._elevators is not None:
            self._elevators.reset()
        self._estimates.reset()
        self._start_over()
        self.supervisor.clock_jumped(stamp)
        self._tick(stamp, f"clock jumped back {back_s:.3f} s: estimate restarted")

    # ----- output ----------------------------------------------------------------------------
    def _on_event(self, event: FilterEvent) -> None:
        if self._elevators is not None:
            self._elevators.filter_event(event)
        if event.kind is EventKind.DISCARDED_CANDIDATE:
            self._decisions.discarded(event.stamp_ns, event.source)
        if event.kind not in FIX_DECISIONS:  # a fix's decision leaves once, in its FixAttempt
            self._emit(event)

    def _emit(self, output: NodeOutput) -> None:
        for sink in self._sinks:
            sink.write(output)

    def metadata(self) -> dict[str, Any]:
        """Facts of the run so far (event counts, skips, suspects, calibration, ladder, the
        resolved configuration, the fix sources' own)."""
        flt, cfg = self._fusion.filter, self._config
        counts = {str(k): v for k, v in flt.events.counts_by_kind().items()}
        calibration = flt.odometry_calibration
        calib: dict[str, Any] | None = None
        if calibration is not None:
            value, sigma = calibration
            calib = {
                name: {"value": float(v), "sigma": float(s)}
                for name, v, s in zip(CALIBRATION_PARAMETERS, value, sigma, strict=True)
            }
        ladder = self.supervisor.ladder
        out: dict[str, Any] = {
            "odometry_calibration": calib, "skipped": dict(self.skipped), "event_counts": counts,
            "suspect_sources": list(flt.suspect_sources), "clock_jumps": self.clock_jumps,
            "config": cfg.model_dump(mode="json"),
            "cap_translation_m": cfg.cap.max_translation_m,
            "cap_rotation_deg": cfg.cap.max_rotation_deg,
            "ladder": {"seconds_at_level": ladder.seconds_at_levels(),
                       "transitions": ladder.transitions, "level": int(ladder.level)},
        }  # fmt: skip
        for source in self._sources:
            out.update(source.metadata())
        if self._elevators is not None:
            out.update(self._elevators.metadata())
        return out
