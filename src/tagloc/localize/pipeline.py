"""The localization pipeline: one code path from a message stream to a :class:`LocalizationRun`.

A stream of ``(topic, record)`` pairs (:mod:`tagloc.messages`; from the simulator, a bag, a live
adapter) goes in; the roles of topics are named by :class:`PipelineTopics`:

- ``OdometryMsg`` (``odom``): the ``odom -> base`` edge of a :class:`~tagloc.frames.TransformBuffer`
  and the filter's prediction; one row of the run per sample (published ``T_map_odom``, the
  covariance of ``T_map_base``, initialized or not).
- ``TagDetectionsMsg`` (``detections``) or ``ImageMsg`` (``image``, run through a detector):
  camera frames, held until the odometry covers their stamp, then turned into fixes
  (:class:`~tagloc.localize.fiducial.FiducialFixSource`) applied at their own stamp (a late
  frame is a late fix, which the filter handles).
- ``CameraInfoMsg`` (``camera_info``) and static ``TransformMsg`` (``base -> camera``) when the
  camera model or extrinsics are not given.
- ``GroundTruthMsg`` (``truth``): stored beside the estimate for evaluation.

Bad input is a counted, logged skip (:attr:`LocalizationPipeline.skipped`: an odometry stamp that
does not increase, non-finite odometry, a repeated frame stamp, a frame before the camera is
known) or a one-line :class:`PipelineInputError` (no odometry at all, a required topic missing
from the source). A damaged bag raises its own ``BagFormatError`` from the source.
"""

from __future__ import annotations

import dataclasses
import heapq
import logging
import math
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from tagloc.camera import CameraModel, from_camera_info
from tagloc.errors import TransformLookupError
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.fiducial import FiducialConfig, FiducialFixSource, FrameFixes
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import LocalizeError
from tagloc.localize.motion import CALIBRATION_PARAMETERS
from tagloc.localize.run import CameraFrameRecord, FixAttempt, LocalizationRun
from tagloc.messages import (
    CameraInfoMsg,
    GroundTruthMsg,
    ImageMsg,
    Message,
    OdometryMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.tags import GateConfig, NoiseModel, TagDetection, TagDetector, TagMap

__all__ = ["FrameTruth", "LocalizationPipeline", "PipelineInputError", "PipelineTopics", "localize"]

logger = logging.getLogger(__name__)
S_NS = 1_000_000_000
_NAN6 = np.full((6, 6), np.nan)
_NAN6.flags.writeable = False


class PipelineInputError(LocalizeError):
    """A stream the pipeline cannot localize from (the message names topic and problem)."""


@dataclass(frozen=True, slots=True)
class PipelineTopics:
    """Stream topic of each role (the simulator's and :class:`BagSink`'s defaults)."""

    odom: str = "/odom"
    detections: str = "/tag_detections"
    image: str = "/camera/image"
    camera_info: str = "/camera/camera_info"
    truth: str = "/ground_truth"


@dataclass(frozen=True, slots=True)
class FrameTruth:
    """Simulator truth of one camera frame, for the run record only (never for decisions).

    Attributes
    ----------
    false_detection : tuple of bool
        Per detection of the frame's ``TagDetectionsMsg``: injected (a glint) or real.
    nearest_visible_m : float
        Camera to the nearest tag truly in view, m (``inf``: none).
    """

    false_detection: tuple[bool, ...]
    nearest_visible_m: float


@dataclass(slots=True)
class _Frame:
    stamp_ns: int
    frame_id: str
    detections: tuple[TagDetection, ...]


class LocalizationPipeline:
    """Feed it ``(topic, record)`` pairs in arrival order; :meth:`finish` returns the run.

    Parameters
    ----------
    tag_map : TagMap
    config : LocalizerConfig, optional
    camera : CameraModel, optional
        Default: from the first ``CameraInfoMsg``.
    T_base_cam : SE3, optional
        Default: the static ``base -> <frame's frame_id>`` transform of the stream.
    topics : PipelineTopics, optional
    detector : TagDetector, optional
        For ``ImageMsg`` frames (default: ``make_detector("apriltag", family)`` on first use).
    family : str
    gates, noise, fiducial : optional
        Per-observation gates, the tag sensor's noise model, the fix source's tunables.
    frame_truth : Mapping[int, FrameTruth], optional
        Simulator truth by frame stamp (fills ``false_detection`` / ``nearest_visible_tag_m``).
    name : str
    """

    def __init__(
        self, tag_map: TagMap, config: LocalizerConfig | None = None, *,
        camera: CameraModel | None = None, T_base_cam: SE3 | None = None,
        topics: PipelineTopics | None = None, detector: TagDetector | None = None,
        family: str = "tag36h11", gates: GateConfig | None = None,
        noise: NoiseModel | None = None, fiducial: FiducialConfig | None = None,
        frame_truth: Mapping[int, FrameTruth] | None = None, name: str = "run",
    ) -> None:  # fmt: skip
        self.config = config or LocalizerConfig()
        # the run keeps every event: the log must not drop any
        flt_cfg = self.config.filter.model_copy(update={"max_events": 10**9})
        cfg = self.config.model_copy(update={"filter": flt_cfg})
        self.topics = topics or PipelineTopics()
        self.frames_cfg = cfg.frames
        self.buffer = TransformBuffer(window_ns=30 * S_NS)
        self.filter = MapOdomFilter.from_config(cfg, self.buffer)
        self._tag_map, self._family = tag_map, family
        self._gates, self._noise, self._fid_cfg = gates, noise, fiducial
        self._camera, self._T_base_cam = camera, T_base_cam
        self._detector = detector
        self._source: FiducialFixSource | None = None
        self._truth_info = frame_truth or {}
        self.name = name
        self.skipped: dict[str, int] = {}
        self._pending: list[tuple[int, int, _Frame]] = []  # heap by stamp
        self._seq = 0
        self._frame_stamps: set[int] = set()
        self._last_odom: int | None = None
        self._stamps: list[int] = []
        self._odom: list[SE3] = []
        self._published: list[SE3] = []
        self._covs: list[np.ndarray] = []
        self._cov_last, self._cov_revision, self._cov_stamp = _NAN6, -1, 0
        self._cov_step_ns = round(self.config.process_noise.motion_step_s * S_NS)
        self._init: list[bool] = []
        self._truth: dict[int, SE3] = {}
        self._attempts: list[FixAttempt] = []
        # fixes a batch decision may still use: id -> (fix, index in _attempts)
        self._held: dict[int, tuple[Any, int]] = {}
        windows = (self.config.gates.consistency_window_s, self.config.kidnap.window_s)
        self._held_ns = round((max(windows) + 1.0) * S_NS)
        self._frames: list[tuple[int, float, int]] = []
        self._wall_s = 0.0

    # ----- input -----------------------------------------------------------------------------
    def feed(self, topic: str, msg: Message) -> None:
        """Consume one stream item (other topics and record types are ignored)."""
        t0 = time.perf_counter()
        if isinstance(msg, OdometryMsg) and topic == self.topics.odom:
            self._on_odometry(msg)
        elif isinstance(msg, TagDetectionsMsg) and topic == self.topics.detections:
            self._queue(_Frame(msg.stamp_ns, msg.frame_id, msg.detections))
        elif isinstance(msg, ImageMsg) and topic == self.topics.image:
            self._queue(_Frame(msg.stamp_ns, msg.frame_id, tuple(self._detect(msg))))
        elif isinstance(msg, CameraInfoMsg) and topic == self.topics.camera_info:
            if self._camera is None:
                self._camera = from_camera_info(msg.info, f"{topic} CameraInfo")
        elif isinstance(msg, TransformMsg) and msg.static:
            self.buffer.set_static(msg.parent, msg.child, msg.T_parent_child)
        elif isinstance(msg, GroundTruthMsg) and topic == self.topics.truth:
            self._truth[msg.stamp_ns] = msg.T_frame_child
        self._wall_s += time.perf_counter() - t0

    def run(self, stream: Iterable[tuple[str, Message]]) -> LocalizationRun:
        """Feed a whole stream and :meth:`finish`. Checks ``stream.topics`` when it has them."""
        topics = getattr(stream, "topics", None)  # a MessageSource names its topics up front
        if isinstance(topics, Mapping) and self.topics.odom not in topics:
            raise PipelineInputError(
                f"odometry topic {self.topics.odom!r} is not in the input (topics: "
                f"{', '.join(sorted(topics)) or 'none'})"
            )
        for topic, msg in stream:
            self.feed(topic, msg)
        return self.finish()

    # ----- odometry and frames ---------------------------------------------------------------
    def _skip(self, reason: str, detail: str) -> None:
        n = self.skipped.get(reason, 0)
        self.skipped[reason] = n + 1
        if n == 0:
            logger.warning("skipped (%s): %s; further ones are counted", reason, detail)

    def _on_odometry(self, msg: OdometryMsg) -> None:
        stamp, T = msg.stamp_ns, msg.T_parent_child
        if not (np.isfinite(T.translation).all() and np.isfinite(T.as_quat()).all()):
            return self._skip("odom_non_finite", f"{self.topics.odom} at {stamp} ns")
        if self._last_odom is not None and stamp <= self._last_odom:
            reason = "odom_duplicate_stamp" if stamp == self._last_odom else "odom_stamp_backwards"
            return self._skip(reason, f"{self.topics.odom}: {stamp} ns after {self._last_odom} ns")
        self._last_odom = stamp
        f = self.frames_cfg
        self.buffer.set_transform(f.odom_frame, f.base_frame, stamp, T)
        while self._pending and self._pending[0][0] <= stamp:
            self._process(heapq.heappop(self._pending)[2])
        self.filter.predict(stamp)
        self._record(stamp, T)
        return None

    def _record(self, stamp: int, T_odom_base: SE3) -> None:
        """One row of the run. The covariance of ``T_map_base`` is recomputed when the filter's
        state changed (:attr:`MapOdomFilter.revision`) or a motion step (0.1 s) passed, else the
        row repeats the last one (it grows by the odometry random walk of < 0.1 s meanwhile)."""
        flt = self.filter
        self._stamps.append(stamp)
        self._odom.append(T_odom_base)
        if flt.initialized:
            self._published.append(flt.correction_at(stamp))
            if flt.revision != self._cov_revision or stamp - self._cov_stamp >= self._cov_step_ns:
                self._cov_last = flt.pose_at(stamp).cov
                self._cov_revision, self._cov_stamp = flt.revision, stamp
            self._covs.append(self._cov_last)
        else:
            self._published.append(SE3.identity())
            self._covs.append(_NAN6)
        self._init.append(flt.initialized)

    def _queue(self, frame: _Frame) -> None:
        if frame.stamp_ns in self._frame_stamps:
            return self._skip("frame_duplicate_stamp", f"camera frame at {frame.stamp_ns} ns")
        self._frame_stamps.add(frame.stamp_ns)
        self._seq += 1
        heapq.heappush(self._pending, (frame.stamp_ns, self._seq, frame))
        return None

    def _detect(self, msg: ImageMsg) -> list[TagDetection]:
        if self._detector is None:
            from tagloc.tags import make_detector

            self._detector = make_detector("apriltag", self._family)
        return self._detector.detect(msg.image)

    def _fix_source(self, frame: _Frame) -> FiducialFixSource | None:
        if self._source is not None:
            return self._source
        if self._camera is None:
            self._skip("no_camera_info", f"frame at {frame.stamp_ns} ns before any CameraInfo")
            return None
        T_base_cam = self._T_base_cam
        if T_base_cam is None:
            try:
                T_base_cam = self.buffer.lookup(
                    self.frames_cfg.base_frame, frame.frame_id, frame.stamp_ns
                )
            except TransformLookupError as exc:
                self._skip("no_extrinsics", str(exc))
                return None
        self._source = FiducialFixSource(
            self._camera, T_base_cam, self._tag_map, family=self._family, gates=self._gates,
            noise=self._noise, config=self._fid_cfg, map_frame=self.frames_cfg.map_frame,
        )  # fmt: skip
        return self._source

    def _process(self, frame: _Frame) -> None:
        """One camera frame: fixes, the filter's decisions, the frame's record."""
        source = self._fix_source(frame)
        if source is None:
            return
        truth = self._truth_info.get(frame.stamp_ns)
        flags = truth.false_detection if truth is not None else None
        if flags is not None and len(flags) != len(frame.detections):
            flags = None
        prior = None
        if self.filter.initialized:
            try:
                prior = self.filter.T_map_base_at(frame.stamp_ns)
            except TransformLookupError:
                prior = None
        result = source.frame_fixes(frame.stamp_ns, frame.detections, prior, flags)
        self._apply(frame.stamp_ns, result)
        nearest = truth.nearest_visible_m if truth is not None else self._nearest(result)
        self._frames.append((frame.stamp_ns, nearest, len(frame.detections)))

    def _apply(self, stamp_ns: int, result: FrameFixes) -> None:
        for r in result.rejects:
            self._attempts.append(
                FixAttempt(
                    stamp_ns, "" if r.tag_id is None else f"tag:{r.tag_id}",
                    () if r.tag_id is None else (r.tag_id,), SE3.identity(), _NAN6,
                    f"rejected:{r.reason}", r.range_m, math.nan, r.false_detection,
                )
            )  # fmt: skip
        for sourced in result.fixes:
            fix = sourced.fix
            serial = self.filter.batch_serial
            event = self.filter.update(fix)
            self._held[id(fix)] = (fix, len(self._attempts))
            self._attempts.append(
                FixAttempt(
                    fix.stamp_ns, fix.source, sourced.tag_ids, fix.T_map_base, fix.cov,
                    event.kind.value, fix.quality.range_m, fix.quality.view_angle_rad,
                    sourced.false_detection,
                )
            )  # fmt: skip
            if self.filter.batch_serial != serial:
                self._relabel()
        horizon = stamp_ns - self._held_ns
        for key in [k for k, (f, _) in self._held.items() if f.stamp_ns < horizon]:
            del self._held[key]

    def _relabel(self) -> None:
        """Fixes held earlier (pending, or gated toward the kidnap test) and used by a batch
        decision (start-up, kidnap, re-acquisition) get their final decision."""
        for fix, kind in self.filter.last_batch:
            held = self._held.get(id(fix))
            if held is not None and held[0] is fix:
                a = self._attempts[held[1]]
                self._attempts[held[1]] = dataclasses.replace(a, decision=kind.value)

    @staticmethod
    def _nearest(result: FrameFixes) -> float:
        ranges = [s.fix.quality.range_m for s in result.fixes]
        ranges += [r.range_m for r in result.rejects if math.isfinite(r.range_m)]
        return min(ranges, default=math.inf)

    # ----- output ----------------------------------------------------------------------------
    def finish(self) -> LocalizationRun:
        """Process frames still held, and assemble the :class:`LocalizationRun`.

        Raises
        ------
        PipelineInputError
            If the stream held no usable odometry.
        """
        while self._pending:
            self._process(heapq.heappop(self._pending)[2])
        if not self._stamps:
            raise PipelineInputError(
                f"no usable odometry on topic {self.topics.odom!r} (skipped: {self.skipped})"
            )
        stamps = np.array(self._stamps, dtype=np.int64)
        accepted: dict[int, int] = {}
        for a in self._attempts:
            if a.accepted:
                accepted[a.stamp_ns] = accepted.get(a.stamp_ns, 0) + 1
        frames = [CameraFrameRecord(s, d, n, accepted.get(s, 0)) for s, d, n in self._frames]
        return LocalizationRun(
            name=self.name, stamps_ns=stamps, T_odom_base=SE3.stack(self._odom),
            T_map_odom=SE3.stack(self._published), cov_map_base=np.array(self._covs),
            initialized=np.array(self._init, dtype=bool), T_map_base_truth=self._truth_at(stamps),
            fixes=list(self._attempts), frames=frames, events=list(self.filter.events.events),
            metadata=self._metadata(),
        )  # fmt: skip

    def _truth_at(self, stamps: np.ndarray) -> SE3 | None:
        if not self._truth:
            return None
        if all(int(s) in self._truth for s in stamps):
            return SE3.stack([self._truth[int(s)] for s in stamps])
        buf = TransformBuffer(window_ns=2**62)
        keys = sorted(self._truth)
        buf.set_transforms(
            "truth", "base", np.array(keys), SE3.stack([self._truth[k] for k in keys])
        )
        inside = (stamps >= keys[0]) & (stamps <= keys[-1])
        if not inside.all():
            logger.warning("ground truth does not cover every odometry stamp: not recorded")
            return None
        return buf.lookup_many("truth", "base", stamps)

    def _metadata(self) -> dict[str, Any]:
        counts = {str(k): v for k, v in self.filter.events.counts_by_kind().items()}
        calibration = self.filter.odometry_calibration
        if calibration is not None:
            value, sigma = calibration
            calib: dict[str, Any] | None = {
                name: {"value": float(v), "sigma": float(s)}
                for name, v, s in zip(CALIBRATION_PARAMETERS, value, sigma, strict=True)
            }
        else:
            calib = None
        return {
            "odometry_calibration": calib,
            "skipped": dict(self.skipped), "event_counts": counts,
            "suspect_sources": list(self.filter.suspect_sources),
            "pipeline_wall_s": self._wall_s, "config": self.config.model_dump(mode="json"),
            "cap_translation_m": self.config.cap.max_translation_m,
            "cap_rotation_deg": self.config.cap.max_rotation_deg,
        }  # fmt: skip


def localize(
    stream: Iterable[tuple[str, Message]], tag_map: TagMap, config: LocalizerConfig | None = None,
    **options: Any,
) -> LocalizationRun:  # fmt: skip
    """Localize a whole stream: ``LocalizationPipeline(tag_map, config, **options).run(stream)``."""
    return LocalizationPipeline(tag_map, config, **options).run(stream)
