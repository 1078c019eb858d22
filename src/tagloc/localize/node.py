"""The streaming localizer node: messages in, in stamp order; outputs to sinks as they happen.

One code path for simulated and real data, live or replayed (DESIGN.md's data flow). Feed it
``(topic, record)`` pairs (:mod:`tagloc.messages`) with :meth:`LocalizerNode.feed`; the roles of
topics are named by :class:`NodeTopics`:

- odometry: an ``OdometryMsg`` on ``odom``, or a ``TransformMsg`` on ``tf`` whose edge is the
  configured ``odom_frame -> base_frame`` (ROS ``/tf``, dimos's ``world -> base_link``). Each
  sample is the ``odom -> base`` edge of a bounded :class:`~tagloc.frames.TransformBuffer`, a
  prediction of the filter, a step of the supervisor, and one :class:`~tagloc.localize.outputs.
  Estimate` (and a status message when one is due).
- a clock that jumps back (odometry stamped more than ``supervisor.clock_jump_s`` before the
  last sample): the node starts over, as ROS tf does (buffer, estimate, waiting frames dropped;
  the ladder falls to odometry only with the reason); smaller steps back are counted skips.
- camera frames: ``TagDetectionsMsg`` (``detections``) or ``ImageMsg`` (``image``, run through
  the configured detector): held until the odometry covers their stamp, then turned into fixes
  (:class:`~tagloc.localize.fiducial.FiducialFixSource`) applied at their own stamp.
- lidar sweeps: ``PointCloudMsg`` (``lidar``), when the node has a premap and ``lidar.enabled``:
  held until the odometry covers the sweep, then registered against the premap into a fix that
  measures the directions the scan constrains (:class:`~tagloc.localize.node_lidar.LidarScans`).
- ``CameraInfoMsg`` (``camera_info``) and static ``TransformMsg`` (``base -> camera``) when the
  camera model or extrinsics are not given; ``GroundTruthMsg`` (``truth``) is passed through.

Bad input is a counted, logged skip (:attr:`LocalizerNode.skipped`: odometry whose stamp does
not increase, non-finite odometry, a repeated frame stamp, a frame before the camera is known, a
detector that raised). Memory is bounded: the transform buffer's window, frames waiting for
odometry, and fixes within the consistency window; everything else leaves through the sinks.
"""

from __future__ import annotations

import dataclasses
import heapq
import logging
import math
from collections import Counter, OrderedDict, deque
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tagloc.camera import CameraModel, from_camera_info
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.lidar.registration import Target
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.fiducial import FiducialFixSource
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import LocalizeError
from tagloc.localize.held import HeldRecords
from tagloc.localize.motion import CALIBRATION_PARAMETERS
from tagloc.localize.node_frames import MARKERS, CameraFrames, _Frame
from tagloc.localize.node_lidar import LIDAR, LidarScans, check_premap_overlap
from tagloc.localize.outputs import Estimate, NodeOutput, OutputSink
from tagloc.messages import (
    CameraInfoMsg,
    FrameTruth,
    GroundTruthMsg,
    ImageMsg,
    Message,
    NodeTopics,
    OdometryMsg,
    PointCloudMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.supervise import EstimatorState, FixSourceSpec, Supervisor
from tagloc.tags import TagDetector, TagMap

__all__ = ["FrameTruth", "LocalizerNode", "NodeTopics"]

logger = logging.getLogger(__name__)
S_NS = 1_000_000_000
_NAN6 = np.full((6, 6), np.nan)
_NAN6.flags.writeable = False


class LocalizerNode(CameraFrames, LidarScans):
    """The node (module docstring). Call :meth:`feed` per message, :meth:`finish` at the end.

    Parameters
    ----------
    tag_map : TagMap
    config : LocalizerConfig, optional
        The one configuration (``localizer.yaml``).
    sinks : sequence of OutputSink
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

    Raises
    ------
    LocalizeError
        If the premap is not a finite ``(N, 3)`` array of at least 10 points, or misses every
        tag of the map frame (:func:`~tagloc.localize.node_lidar.check_premap_overlap`).
    """

    def __init__(
        self, tag_map: TagMap, config: LocalizerConfig | None = None,
        sinks: Sequence[OutputSink] = (), *, camera: CameraModel | None = None,
        T_base_cam: SE3 | None = None, topics: NodeTopics | None = None,
        detector: TagDetector | None = None, frame_truth: Mapping[int, FrameTruth] | None = None,
        premap: np.ndarray | None = None,
    ) -> None:  # fmt: skip
        self.config = cfg = config or LocalizerConfig()
        self.topics = topics or NodeTopics()
        self.sinks = list(sinks)
        self.frames_cfg = cfg.frames
        self.buffer = TransformBuffer(window_ns=30 * S_NS)
        self.filter = MapOdomFilter.from_config(cfg, self.buffer)
        self.filter.events.listeners.append(self._emit)
        self._tag_map = tag_map
        self._premap = self._prepare_premap(premap) if cfg.lidar.enabled else None
        sources = [FixSourceSpec(MARKERS, "markers", "camera")]
        if self._premap is not None:
            sources.append(FixSourceSpec(LIDAR, "lidar", LIDAR))
        self.supervisor = Supervisor(cfg.supervisor, sources, cfg.gates.gap_s, cfg.gates.gap_m)
        self._scans: deque[PointCloudMsg] = deque()
        self._next_scan_ns = -(2**62)
        self._in_cab = False
        self.lidar_counts: Counter[str] = Counter()
        self._camera, self._T_base_cam, self._detector = camera, T_base_cam, detector
        self._source: FiducialFixSource | None = None
        self._truth_info = frame_truth or {}
        self.skipped: Counter[str] = Counter()
        self._pending: list[tuple[int, int, _Frame]] = []  # heap by stamp
        self._seq = 0
        self._recent_frames: OrderedDict[int, None] = OrderedDict()
        self._statics: dict[tuple[str, str], SE3] = {}
        self._last_odom: int | None = None
        self._cov_last: np.ndarray | None = None
        self._cov_revision, self._cov_stamp = -1, 0
        self._cov_step_ns = round(cfg.process_noise.motion_step_s * S_NS)
        rate = cfg.output.publish_rate_hz
        self._publish_ns = 0 if rate == 0 else round(S_NS / rate)
        self._next_publish = 0
        # fix attempts and frame records wait here until no batch decision can revise them
        self._held = HeldRecords(self._emit)
        windows = (cfg.gates.consistency_window_s, cfg.kidnap.window_s)
        self._held_ns = round((max(windows) + 1.0) * S_NS)
        self._fix_ns: int | None = None  # last accepted fix
        self._odometer_m, self._fix_odometer_m = 0.0, 0.0
        self._last_T: SE3 | None = None
        self._odom_cov_growth = cfg.process_noise.odometry_covariance == "growth"
        self._odom_cov: np.ndarray | None = None
        self._tick_ns = -(2**62)
        self._jump_ns = round(cfg.supervisor.clock_jump_s * S_NS)
        self.clock_jumps = 0
        #: The correction published at the latest odometry sample (None uninitialized): read by
        #: worker threads (an attribute assignment is atomic).
        self.latest_T_map_odom: SE3 | None = None

    @property
    def camera(self) -> CameraModel | None:
        """The camera model in use (given, or from the first ``CameraInfoMsg``; None yet)."""
        return self._camera

    @property
    def T_base_cam(self) -> SE3 | None:
        """The extrinsics in use (given, or the stream's static transform once a frame needed
        it; None yet)."""
        if self._T_base_cam is not None:
            return self._T_base_cam
        return None if self._source is None else self._source.T_base_cam

    # ----- input -----------------------------------------------------------------------------
    def feed(self, topic: str, msg: Message) -> None:
        """Consume one stream item (other topics and record types are ignored)."""
        t, f = self.topics, self.frames_cfg
        if isinstance(msg, OdometryMsg) and topic == t.odom:
            self._on_odometry(msg.stamp_ns, msg.T_parent_child, msg.cov)
        elif isinstance(msg, TransformMsg) and not msg.static:
            if topic == t.tf and (msg.parent, msg.child) == (f.odom_frame, f.base_frame):
                self._on_odometry(msg.stamp_ns, msg.T_parent_child)
        elif isinstance(msg, TagDetectionsMsg) and topic == t.detections:
            self._queue(_Frame(msg.stamp_ns, msg.frame_id, msg.detections))
        elif isinstance(msg, ImageMsg) and topic == t.image:
            detections = self._detect(msg)
            if detections is not None:
                self._queue(_Frame(msg.stamp_ns, msg.frame_id, detections))
        elif isinstance(msg, CameraInfoMsg) and topic == t.camera_info:
            if self._camera is None:
                self._camera = from_camera_info(msg.info, f"{topic} CameraInfo")
        elif isinstance(msg, TransformMsg) and msg.static:
            self.buffer.set_static(msg.parent, msg.child, msg.T_parent_child)
            self._statics[msg.parent, msg.child] = msg.T_parent_child
        elif isinstance(msg, PointCloudMsg) and topic == t.lidar:
            if self._premap is not None:
                self._on_cloud(msg)
        elif isinstance(msg, GroundTruthMsg) and topic == t.truth:
            self._emit(msg)

    def _prepare_premap(self, premap: np.ndarray | None) -> Target | None:
        """The premap as a registration target (None without one)."""
        if premap is None:
            return None
        points = np.asarray(premap, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or len(points) < 10:
            raise LocalizeError(f"premap must be (N >= 10, 3) points, got {points.shape}")
        if not np.isfinite(points).all():
            raise LocalizeError("premap holds NaN or inf points")
        check_premap_overlap(points, self._tag_map, self.frames_cfg.map_frame)
        return Target.from_points(points, self.config.lidar.fix.registration)

    def finish(self) -> None:
        """Process frames still waiting for odometry and hand on every held record.

        Raises
        ------
        LocalizeError
            If the stream held no usable odometry.
        """
        while self._pending:
            self._process(heapq.heappop(self._pending)[2])
        self._lidar_due(None)
        self._held.release(None)
        if self._last_odom is None:
            raise LocalizeError(
                f"no usable odometry on {self.topics.odom!r} or as {self.frames_cfg.odom_frame} "
                f"-> {self.frames_cfg.base_frame} on {self.topics.tf!r} "
                f"(skipped: {dict(self.skipped) or 'none'})"
            )

    # ----- odometry --------------------------------------------------------------------------
    def _on_odometry(self, stamp: int, T: SE3, cov: np.ndarray | None = None) -> None:
        if not (np.isfinite(T.translation).all() and np.isfinite(T.as_quat()).all()):
            return self._skip("odom_non_finite", f"odometry at {stamp} ns")
        if self._last_odom is not None and stamp <= self._last_odom:
            if self._last_odom - stamp > self._jump_ns:
                self._clock_jump(stamp)
            else:
                reason = (
                    "odom_duplicate_stamp" if stamp == self._last_odom else "odom_stamp_backwards"
                )
                return self._skip(reason, f"odometry: {stamp} ns after {self._last_odom} ns")
        self._last_odom = stamp
        if self._last_T is not None:
            self._odometer_m += float(np.linalg.norm(T.translation - self._last_T.translation))
        self._last_T = T
        f = self.frames_cfg
        self.buffer.set_transform(f.odom_frame, f.base_frame, stamp, T)
        self.supervisor.on_input("odometry", stamp)
        if cov is not None and self._odom_cov_growth:
            self._add_odometry_noise(cov)
        if self.config.output.publish_first:
            self.filter.predict(stamp)
            self._estimate(stamp, T)
        while self._pending and self._pending[0][0] <= stamp:
            self._process(heapq.heappop(self._pending)[2])
        if self._scans:
            self._lidar_due(stamp)
        if not self.config.output.publish_first:
            self.filter.predict(stamp)
            self._estimate(stamp, T)
        return None

    def _add_odometry_noise(self, cov: np.ndarray) -> None:
        """``process_noise.odometry_covariance: growth``: the positive part of the odometry
        covariance's change since the previous message enters the filter's covariance."""
        last, self._odom_cov = self._odom_cov, cov
        if last is None or not np.isfinite(cov).all():
            return
        w, V = np.linalg.eigh(0.5 * ((cov - last) + (cov - last).T))
        if w.max() > 0:
            self.filter.add_process_noise((V * np.clip(w, 0.0, None)) @ V.T)

    def _estimate(self, stamp: int, T_odom_base: SE3) -> None:
        """The sample's :class:`Estimate`, the supervisor's step and the status when due. The
        covariance of ``T_map_base`` is recomputed when the filter's state changed
        (:attr:`MapOdomFilter.revision`) or a motion step passed, else the last one is repeated
        (it grows by the odometry random walk of < one step meanwhile)."""
        flt = self.filter
        cov = estimate = None
        if flt.initialized:
            T_map_odom = flt.correction_at(stamp)
            estimate = flt.T_map_odom
            if flt.revision != self._cov_revision or stamp - self._cov_stamp >= self._cov_step_ns:
                self._cov_last = flt.pose_at(stamp).cov
                self._cov_revision, self._cov_stamp = flt.revision, stamp
            cov = self._cov_last
        else:
            T_map_odom = SE3.identity()
        self.latest_T_map_odom = T_map_odom if flt.initialized else None
        publish = stamp >= self._next_publish
        if publish:
            self._next_publish = stamp + self._publish_ns
        parent, child = self.frames_cfg.published_edge
        self._emit(Estimate(stamp, T_odom_base, T_map_odom, cov, flt.initialized, publish,
                            parent, child, estimate))  # fmt: skip
        self._tick(stamp)

    def _tick(self, stamp: int, reason: str = "") -> None:
        """Step the supervisor (and publish the status when due) at ``stamp``: at every odometry
        sample and every camera frame, so a silent input is noticed while others still arrive.
        Older stamps than the last tick are not stepped."""
        if stamp < self._tick_ns:
            return
        self._tick_ns = stamp
        state = self._state(stamp)
        move = self.supervisor.step(stamp, state, reason)
        if move is not None:
            self._emit(move)
        if self.supervisor.status_due(stamp):  # the sigmas only for the status (not per tick)
            cov = self._cov_last if self.filter.initialized else None
            if cov is not None:
                sxy = math.sqrt(max(float(np.linalg.eigvalsh(cov[:2, :2])[-1]), 0.0))
                syaw = math.degrees(math.sqrt(max(float(cov[5, 5]), 0.0)))
                state = dataclasses.replace(state, sigma_xy_m=sxy, sigma_yaw_deg=syaw)
            self._emit(self.supervisor.status(stamp, state))

    def _state(self, stamp: int) -> EstimatorState:
        """What the supervisor needs of the estimate at ``stamp`` (sigmas left NaN)."""
        since_s = math.inf if self._fix_ns is None else (stamp - self._fix_ns) / S_NS
        since_m = math.inf if self._fix_ns is None else self._odometer_m - self._fix_odometer_m
        return EstimatorState(self.filter.initialized, self.filter.reacquiring, since_s, since_m)

    def _clock_jump(self, stamp: int) -> None:
        """Odometry stamped far before the last one: the clock jumped back (a restarted driver, a
        bag played in a loop). Like ROS tf, start over: the buffer, the estimate and the frames
        waiting are dropped, held records handed on, and the ladder falls to odometry only."""
        assert self._last_odom is not None
        back_s = (self._last_odom - stamp) / S_NS
        logger.warning("clock jumped back %.3f s (odometry at %d ns): starting over", back_s, stamp)
        self.clock_jumps += 1
        self.skipped["frame_before_clock_jump"] += len(self._pending)
        if self._scans:
            self.skipped["lidar_before_clock_jump"] += len(self._scans)
        self._pending.clear()
        self._scans.clear()
        self._next_scan_ns = -(2**62)
        self._recent_frames.clear()
        self._held.release(None)
        self.buffer = TransformBuffer(window_ns=30 * S_NS)
        for (parent, child), T in self._statics.items():
            self.buffer.set_static(parent, child, T)
        self.filter = MapOdomFilter.from_config(self.config, self.buffer)
        self.filter.events.listeners.append(self._emit)
        self._source = None
        self._last_odom = self._last_T = self._fix_ns = self._cov_last = self._odom_cov = None
        self._cov_revision, self._next_publish, self._tick_ns = -1, 0, -(2**62)
        self.supervisor.clock_jumped(stamp)
        self._tick(stamp, f"clock jumped back {back_s:.3f} s: estimate restarted")

    # ----- output ----------------------------------------------------------------------------
    def _emit(self, output: NodeOutput) -> None:
        for sink in self.sinks:
            sink.write(output)

    def metadata(self) -> dict[str, Any]:
        """Facts of the run so far (event counts, skips, suspects, calibration, ladder, the
        resolved configuration)."""
        flt = self.filter
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
            "config": self.config.model_dump(mode="json"),
            "cap_translation_m": self.config.cap.max_translation_m,
            "cap_rotation_deg": self.config.cap.max_rotation_deg,
            "ladder": {"seconds_at_level": ladder.seconds_at_levels(),
                       "transitions": ladder.transitions, "level": int(ladder.level)},
        }  # fmt: skip
        if self._premap is not None:
            out["lidar_source"] = {"sweeps_thinned": self.lidar_counts["thinned"]}
        return out
