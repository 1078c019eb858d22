"""The camera-frame half of the streaming node (:class:`~tagloc.localize.node.LocalizerNode`).

A frame (pre-detected corners, an image through the configured detector, or fixes formed on a
worker thread) is queued until the odometry covers its stamp, then turned into fixes
(:class:`~tagloc.localize.fiducial.FiducialFixSource`) and decided on by the filter; each
decision feeds the supervisor's quality books, and the frame's records are held until final
(:class:`~tagloc.localize.held.HeldRecords`). The node's state lives on the node; this mixin
holds only methods.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tagloc.errors import TransformLookupError
from tagloc.geometry import SE3
from tagloc.localize.events import APPLIED, EventKind, FilterEvent
from tagloc.localize.fiducial import FiducialConfig, FiducialFixSource, FrameFixes
from tagloc.localize.run import CameraFrameRecord, FixAttempt
from tagloc.messages import ImageMsg
from tagloc.tags import TagDetection

if TYPE_CHECKING:
    from collections import Counter, OrderedDict

    from tagloc.camera import CameraModel
    from tagloc.frames import TransformBuffer
    from tagloc.localize.config import LocalizerConfig
    from tagloc.localize.config_tags import FramesConfig
    from tagloc.localize.filter import MapOdomFilter
    from tagloc.localize.held import HeldRecords
    from tagloc.messages import FrameTruth
    from tagloc.supervise import Supervisor
    from tagloc.tags import TagDetector, TagMap

__all__ = ["MARKERS", "CameraFrames"]

logger = logging.getLogger(__name__)
MARKERS = "markers"
#: Camera frames that may wait for odometry to cover their stamp (30 s at 30 Hz).
_MAX_PENDING = 900
#: Frame stamps remembered to refuse duplicates (a bounded set of the newest).
_RECENT_FRAMES = 1024
_NAN6 = np.full((6, 6), np.nan)
_NAN6.flags.writeable = False


@dataclass(slots=True)
class _Frame:
    stamp_ns: int
    frame_id: str
    detections: tuple[TagDetection, ...]
    fixes: FrameFixes | None = None  # computed elsewhere (the real-time worker)


class CameraFrames:
    """Camera frames to fixes to filter decisions (module docstring). The node's state it
    uses is declared here; the node sets it."""

    config: LocalizerConfig
    frames_cfg: FramesConfig
    buffer: TransformBuffer
    filter: MapOdomFilter
    supervisor: Supervisor
    skipped: Counter[str]
    latest_T_map_odom: SE3 | None
    _tag_map: TagMap
    _camera: CameraModel | None
    _T_base_cam: SE3 | None
    _detector: TagDetector | None
    _source: FiducialFixSource | None
    _truth_info: Mapping[int, FrameTruth]
    _pending: list[tuple[int, int, _Frame]]
    _seq: int
    _recent_frames: OrderedDict[int, None]
    _held: HeldRecords
    _held_ns: int
    _fix_ns: int | None
    _odometer_m: float
    _fix_odometer_m: float
    _last_T: SE3 | None

    def _tick(self, stamp: int, reason: str = "") -> None:
        raise NotImplementedError  # the node's: steps the supervisor

    if TYPE_CHECKING:

        def _note_tags(self, detections: tuple[TagDetection, ...]) -> None: ...  # LidarScans'

    def _skip(self, reason: str, detail: str) -> None:
        """Count a skipped input; log the first of each reason."""
        self.skipped[reason] += 1
        if self.skipped[reason] == 1:
            logger.warning("skipped (%s): %s; further ones are counted", reason, detail)

    def feed_frame(
        self, stamp_ns: int, frame_id: str, detections: tuple[TagDetection, ...],
        fixes: FrameFixes,
    ) -> None:  # fmt: skip
        """A camera frame whose fixes were computed elsewhere (by :meth:`fixer`, on another
        thread): queued like any frame, applied when the odometry covers its stamp."""
        self._queue(_Frame(stamp_ns, frame_id, detections, fixes))

    def fixer(
        self, stamp_ns: int, frame_id: str
    ) -> Callable[[int, tuple[TagDetection, ...]], FrameFixes] | None:
        """A function that forms a frame's fixes without touching the node's state, for a worker
        thread (None until the camera model and extrinsics are known). Its orientation prior is
        the newest published correction when it runs (the frame may wait behind others: the
        filter has moved on by then) composed with the odometry when the frame arrived."""
        source = self._fix_source(_Frame(stamp_ns, frame_id, ()), quiet=True)
        if source is None:
            return None
        T_odom_base = self._last_T  # the odometry now, about the frame's stamp

        def fixes(stamp: int, detections: tuple[TagDetection, ...]) -> FrameFixes:
            T_map_odom = self.latest_T_map_odom  # the newest correction when the worker runs
            prior = None if T_map_odom is None or T_odom_base is None else T_map_odom @ T_odom_base
            return source.frame_fixes(stamp, detections, prior, None)

        return fixes

    def _queue(self, frame: _Frame) -> None:
        self.supervisor.on_input("camera", frame.stamp_ns)
        self._tick(frame.stamp_ns)
        if len(self._pending) >= _MAX_PENDING:  # no odometry reaches them: drop the oldest
            heapq.heappop(self._pending)
            self._skip("frame_without_odometry", f"over {_MAX_PENDING} frames wait for odometry")
        if frame.stamp_ns in self._recent_frames:
            return self._skip("frame_duplicate_stamp", f"camera frame at {frame.stamp_ns} ns")
        self._recent_frames[frame.stamp_ns] = None
        if len(self._recent_frames) > _RECENT_FRAMES:
            self._recent_frames.popitem(last=False)
        self._seq += 1
        heapq.heappush(self._pending, (frame.stamp_ns, self._seq, frame))
        return None

    def _detect(self, msg: ImageMsg) -> tuple[TagDetection, ...] | None:
        tags = self.config.tags
        cam = self._camera
        if cam is not None and msg.image.shape[:2] != (cam.height, cam.width):
            h, w = msg.image.shape[:2]
            self._skip(
                "image_size_mismatch",
                f"image at {msg.stamp_ns} ns is {w}x{h}, the camera model {cam.width}x{cam.height}",
            )
            return None
        try:
            if self._detector is None:
                from tagloc.tags import make_detector

                self._detector = make_detector(tags.backend, tags.family)
            return tuple(self._detector.detect(msg.image))
        except Exception as exc:  # a detector's failure on one frame must not stop the node
            self._skip("detector_error", f"frame at {msg.stamp_ns} ns: {exc!r}")
            return None

    def _fix_source(self, frame: _Frame, *, quiet: bool = False) -> FiducialFixSource | None:
        if self._source is not None:
            return self._source
        if self._camera is None:
            if not quiet:
                self._skip("no_camera_info", f"frame at {frame.stamp_ns} ns before CameraInfo")
            return None
        T_base_cam = self._T_base_cam
        if T_base_cam is None:
            try:
                T_base_cam = self.buffer.lookup(
                    self.frames_cfg.base_frame, frame.frame_id, frame.stamp_ns
                )
            except TransformLookupError as exc:
                if not quiet:
                    self._skip("no_extrinsics", str(exc))
                return None
        tags = self.config.tags
        fid = FiducialConfig(
            cov_scale=tags.cov_scale, min_cov_translation_m=tags.min_cov_translation_m,
            min_cov_rotation_rad=tags.min_cov_rotation_rad, mode=tags.mode,
            prior_rotation_sigma_rad=tags.prior_rotation_sigma_rad,
            ambiguity_log_odds_with_prior=tags.ambiguity_log_odds_with_prior,
            shared_quad_px=tags.shared_quad_px,
        )  # fmt: skip
        self._source = FiducialFixSource(
            self._camera, T_base_cam, self._tag_map, family=tags.family,
            gates=self.config.gates.observation_gates(), noise=tags.noise, config=fid,
            map_frame=self.frames_cfg.map_frame,
        )  # fmt: skip
        return self._source

    def _process(self, frame: _Frame) -> None:
        """One camera frame: fixes, the filter's decisions, the frame's record."""
        source = self._fix_source(frame)
        if source is None:
            return
        self._note_tags(frame.detections)  # the lidar's cab rule
        truth = self._truth_info.get(frame.stamp_ns)
        flags = truth.false_detection if truth is not None else None
        if flags is not None and len(flags) != len(frame.detections):
            flags = None
        prior = None
        if self.filter.initialized and frame.fixes is None:
            try:
                prior = self.filter.T_map_base_at(frame.stamp_ns)
            except TransformLookupError:
                prior = None
        result = (
            frame.fixes
            if frame.fixes is not None
            else source.frame_fixes(frame.stamp_ns, frame.detections, prior, flags)
        )
        self._apply(frame.stamp_ns, result)
        nearest = truth.nearest_visible_m if truth is not None else _nearest(result)
        self._held.hold(CameraFrameRecord(frame.stamp_ns, nearest, len(frame.detections), 0))
        self._held.release(frame.stamp_ns - self._held_ns)

    def _apply(self, stamp_ns: int, result: FrameFixes) -> None:
        for r in result.rejects:
            self._held.hold(
                FixAttempt(
                    stamp_ns, "" if r.tag_id is None else f"tag:{r.tag_id}",
                    () if r.tag_id is None else (r.tag_id,), SE3.identity(), _NAN6,
                    f"rejected:{r.reason}", r.range_m, math.nan, r.false_detection,
                )
            )  # fmt: skip
        flt = self.filter
        for sourced in result.fixes:
            fix = sourced.fix
            serial = flt.batch_serial
            event = flt.update(fix)
            self._held.hold(
                FixAttempt(
                    fix.stamp_ns, fix.source, sourced.tag_ids, fix.T_map_base, fix.cov,
                    event.kind.value, fix.quality.range_m, fix.quality.view_angle_rad,
                    sourced.false_detection,
                ),
                fix,
            )  # fmt: skip
            if event.kind is not EventKind.PENDING_CONSISTENCY:
                self._judged(event, fix.quality.reproj_err_px)
            if flt.batch_serial != serial:  # a batch decision revised fixes held earlier
                for old, kind in self._held.relabel(flt.last_batch):
                    self._judged(FilterEvent(old.stamp_ns, kind), old.quality.reproj_err_px)

    def _judged(self, event: FilterEvent, reproj_px: float) -> None:
        """A final decision on a fix: the supervisor's quality books, the last accepted fix."""
        accepted = event.kind.value in APPLIED
        if accepted:
            self._fix_ns = max(self._fix_ns or event.stamp_ns, event.stamp_ns)
            self._fix_odometer_m = self._odometer_m
        nis = math.nan if event.d2 is None else event.d2 / self.filter.dof
        self.supervisor.on_fix(MARKERS, accepted, nis, reproj_px)


def _nearest(result: FrameFixes) -> float:
    ranges = [s.fix.quality.range_m for s in result.fixes]
    ranges += [r.range_m for r in result.rejects if math.isfinite(r.range_m)]
    return min(ranges, default=math.inf)
