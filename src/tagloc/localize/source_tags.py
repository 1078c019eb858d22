"""The fiducial fix source of the node: camera frames to tag fixes (:class:`TagSource`).

A frame is pre-detected corners (``TagDetectionsMsg`` on ``topics.detections``), an image run
through the configured detector (``ImageMsg`` on ``topics.image``), or fixes formed on a worker
thread (:meth:`TagSource.fixer`, :meth:`TagSource.arrive_fixed`). It waits in the node's queue
until the odometry covers its stamp; then :class:`~tagloc.localize.fiducial.FiducialFixSource`
(built on first use, once the camera model, from ``CameraInfoMsg`` unless given, and the
extrinsics, from the stream's static ``base -> <frame_id>`` unless given, are known) forms its
fixes with the filter's estimate as the orientation prior.

Its own skips: ``frame_duplicate_stamp``, ``image_size_mismatch``, ``detector_error``,
``no_camera_info``, ``no_extrinsics``.
"""

from __future__ import annotations

import logging
import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel, from_camera_info
from tagloc.errors import TransformLookupError
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.fiducial import E_Z, FiducialConfig, FiducialFixSource, FrameFixes
from tagloc.localize.roi_detector import region_detector
from tagloc.localize.run import CameraFrameRecord, FixAttempt
from tagloc.localize.sources import (
    Arrival,
    FixContext,
    Offer,
    SkipCounter,
    SourceInputs,
    SourceResult,
    Work,
)
from tagloc.messages import CameraInfoMsg, ImageMsg, Message, TagDetectionsMsg
from tagloc.supervise import FixSourceSpec
from tagloc.tags import TagDetection

logger = logging.getLogger(__name__)

__all__ = ["MARKERS", "TagSource"]

MARKERS = "markers"
#: Camera frames that may wait for odometry to cover their stamp (30 s at 30 Hz).
_MAX_PENDING = 900
#: Frame stamps remembered to refuse duplicates (a bounded set of the newest).
_RECENT_FRAMES = 1024
_NAN6 = np.full((6, 6), np.nan)
_NAN6.flags.writeable = False

#: ``fixer(stamp_ns, detections)``: a frame's fixes, formed off the node's thread.
Fixer = Callable[[int, tuple[TagDetection, ...]], FrameFixes]


@dataclass(frozen=True, slots=True)
class _Frame:
    stamp_ns: int
    frame_id: str
    detections: tuple[TagDetection, ...]
    fixes: FrameFixes | None = None  # formed elsewhere (the wall clock's worker)


class TagSource:
    """Camera frames to gated tag fixes (module docstring; a
    :class:`~tagloc.localize.sources.FixSource`)."""

    spec = FixSourceSpec(MARKERS, "markers", "camera")
    max_waiting = _MAX_PENDING
    overflow_reason = "frame_without_odometry"
    jump_reason = "frame_before_clock_jump"

    def __init__(self, config: LocalizerConfig, inputs: SourceInputs) -> None:
        self._config, self._inputs = config, inputs
        self._camera, self._detector = inputs.camera, inputs.detector
        self._source: FiducialFixSource | None = None
        self._recent: OrderedDict[int, None] = OrderedDict()
        self.skipped = SkipCounter()
        self._regions = region_detector(config, inputs.tag_map)

    @property
    def camera(self) -> CameraModel | None:
        """The camera model in use (given, or from the first ``CameraInfoMsg``; None yet)."""
        return self._camera

    @property
    def T_base_cam(self) -> SE3 | None:
        """The extrinsics in use (given, or the stream's once a frame needed them; None yet)."""
        if self._inputs.T_base_cam is not None:
            return self._inputs.T_base_cam
        return None if self._source is None else self._source.T_base_cam

    # ----- FixSource -------------------------------------------------------------------------
    def arrive(self, topic: str, msg: Message) -> Arrival | None:
        t = self._inputs.topics
        if isinstance(msg, TagDetectionsMsg) and topic == t.detections:
            return self._frame(_Frame(msg.stamp_ns, msg.frame_id, msg.detections))
        if isinstance(msg, ImageMsg) and topic == t.image:
            detections = self._detect(msg)
            return None if detections is None else self._frame(
                _Frame(msg.stamp_ns, msg.frame_id, detections)
            )  # fmt: skip
        if isinstance(msg, CameraInfoMsg) and topic == t.camera_info and self._camera is None:
            self._camera = from_camera_info(msg.info, f"{topic} CameraInfo")
        return None

    def arrive_fixed(
        self, stamp_ns: int, frame_id: str, detections: tuple[TagDetection, ...],
        fixes: FrameFixes,
    ) -> Arrival:  # fmt: skip
        """A frame whose fixes were formed elsewhere (by :meth:`fixer`, on another thread)."""
        return self._frame(_Frame(stamp_ns, frame_id, detections, fixes))

    def fixes(self, payload: object, context: FixContext) -> SourceResult | None:
        """One frame: its fixes (with the filter's estimate as the prior), refusals, record."""
        assert isinstance(payload, _Frame)
        frame = payload
        if self._regions is not None:
            self._regions.observe(context)
        source = self._fix_source(frame, context, quiet=False)
        if source is None:
            return None
        truth = self._inputs.frame_truth.get(frame.stamp_ns)
        flags = truth.false_detection if truth is not None else None
        if flags is not None and len(flags) != len(frame.detections):
            flags = None
        result = frame.fixes
        if result is None:
            prior = None
            if context.filter.initialized:
                try:
                    prior = context.filter.T_map_base_at(frame.stamp_ns)
                except TransformLookupError:
                    prior = None
            up_base = self._up_base(context, frame.stamp_ns)
            result = source.frame_fixes(frame.stamp_ns, frame.detections, prior, flags, up_base)
        dof = context.filter.dof
        refused = tuple(
            FixAttempt(
                frame.stamp_ns, "" if r.tag_id is None else f"tag:{r.tag_id}",
                () if r.tag_id is None else (r.tag_id,), SE3.identity(), _NAN6,
                f"rejected:{r.reason}", r.range_m, math.nan, r.false_detection,
            )
            for r in result.rejects
        )  # fmt: skip
        offers = tuple(
            Offer(
                s.fix,
                FixAttempt(
                    s.fix.stamp_ns, s.fix.source, s.tag_ids, s.fix.T_map_base, s.fix.cov, "",
                    s.fix.quality.range_m, s.fix.quality.view_angle_rad, s.false_detection,
                ),
                dof, s.fix.quality.reproj_err_px,
            )
            for s in result.fixes
        )  # fmt: skip
        nearest = truth.nearest_visible_m if truth is not None else _nearest(result)
        record = CameraFrameRecord(frame.stamp_ns, nearest, len(frame.detections), 0)
        return SourceResult(offers, refused, 0, record, frame.stamp_ns, frame.detections)

    def observe(self, result: SourceResult) -> None:
        return None

    def reset(self) -> None:
        """Forget the frame stamps seen and the extrinsics looked up on the old timeline."""
        self._recent.clear()
        self._source = None
        if self._regions is not None:
            self._regions.reset()

    def metadata(self) -> dict[str, Any]:
        return {} if self._regions is None else {"regions": self._regions.stats.to_dict()}

    # ----- the wall clock's worker -----------------------------------------------------------
    def fixer(
        self, stamp_ns: int, frame_id: str, context: FixContext,
        prior: Callable[[], SE3 | None], T_odom_base: SE3 | None = None,
    ) -> Fixer | None:  # fmt: skip
        """A function that forms a frame's fixes without touching any state, for a worker
        thread (None until the camera model and extrinsics are known); ``prior()`` is called
        when it runs, for the orientation prior; ``T_odom_base`` (the odometry about the frame's
        stamp) gives "up" for a gravity-aligned odometry."""
        source = self._fix_source(_Frame(stamp_ns, frame_id, ()), context, quiet=True)
        if source is None:
            return None

        up_base = self._up_from(T_odom_base)

        def fixes(stamp: int, detections: tuple[TagDetection, ...]) -> FrameFixes:
            return source.frame_fixes(stamp, detections, prior(), None, up_base)

        return fixes

    # ----- internals -------------------------------------------------------------------------
    def _frame(self, frame: _Frame) -> Arrival:
        stamp = frame.stamp_ns
        if stamp in self._recent:
            self.skipped.skip("frame_duplicate_stamp", f"camera frame at {stamp} ns")
            return Arrival(stamp, tick=True)
        self._recent[stamp] = None
        if len(self._recent) > _RECENT_FRAMES:
            self._recent.popitem(last=False)
        return Arrival(stamp, tick=True, work=Work(stamp, stamp, frame))

    def _detect(self, msg: ImageMsg) -> tuple[TagDetection, ...] | None:
        cam = self._camera
        if cam is not None and msg.image.shape[:2] != (cam.height, cam.width):
            h, w = msg.image.shape[:2]
            self.skipped.skip(
                "image_size_mismatch",
                f"image at {msg.stamp_ns} ns is {w}x{h}, the camera model {cam.width}x{cam.height}",
            )
            return None
        try:
            if self._detector is None:
                from tagloc.tags import make_detector

                tags = self._config.tags
                self._detector = make_detector(tags.backend, tags.family)
            if self._regions is not None:
                return tuple(self._regions.detect(
                    msg.stamp_ns, msg.image, self._detector, cam, self.T_base_cam
                ))  # fmt: skip
            return tuple(self._detector.detect(msg.image))
        except Exception as exc:  # a detector's failure on one frame must not stop the node
            self.skipped.skip("detector_error", f"frame at {msg.stamp_ns} ns: {exc!r}")
            return None

    def _fix_source(
        self, frame: _Frame, context: FixContext, *, quiet: bool
    ) -> FiducialFixSource | None:
        if self._source is not None:
            return self._source
        if self._camera is None:
            if not quiet:
                detail = f"frame at {frame.stamp_ns} ns before CameraInfo"
                self.skipped.skip("no_camera_info", detail)
            return None
        cfg = self._config
        T_base_cam = self._inputs.T_base_cam
        if T_base_cam is None:
            try:
                T_base_cam = context.buffer.lookup(
                    cfg.frames.base_frame, frame.frame_id, frame.stamp_ns
                )
            except TransformLookupError as exc:
                if not quiet:
                    self.skipped.skip("no_extrinsics", str(exc))
                return None
        tags = cfg.tags
        fid = FiducialConfig(
            cov_scale=tags.cov_scale, min_cov_translation_m=tags.min_cov_translation_m,
            min_cov_rotation_rad=tags.min_cov_rotation_rad, mode=tags.mode,
            prior_rotation_sigma_rad=tags.prior_rotation_sigma_rad,
            ambiguity_log_odds_with_prior=tags.ambiguity_log_odds_with_prior,
            shared_quad_px=tags.shared_quad_px,
        )  # fmt: skip
        self._source = FiducialFixSource(
            self._camera, T_base_cam, self._inputs.tag_map, family=tags.family,
            gates=cfg.gates.observation_gates(), noise=tags.noise, config=fid,
            map_frame=cfg.frames.map_frame,
            up_base=E_Z if cfg.odometry_frame.knows_up else None,
        )  # fmt: skip
        if not cfg.odometry_frame.knows_up:
            logger.warning(
                "the odometry frame knows no up (odometry_frame.base_up_axis: null): tag fixes "
                "run without the gravity prior"
            )
        return self._source

    def _up_base(self, context: FixContext, stamp_ns: int) -> FloatArray | None:
        """"Up" in the base at ``stamp_ns`` for a gravity-aligned odometry (None: the fix
        source's default, an upright base's ``+z`` or no up)."""
        frames = self._config.frames
        if not self._config.odometry_frame.gravity_aligned:
            return None
        try:
            T = context.buffer.lookup(frames.odom_frame, frames.base_frame, stamp_ns)
        except TransformLookupError:
            return None
        return self._up_from(T)

    def _up_from(self, T_odom_base: SE3 | None) -> FloatArray | None:
        frame = self._config.odometry_frame
        if T_odom_base is None or not frame.gravity_aligned:
            return None
        up: FloatArray = frame.up_in_base(T_odom_base.rotation.as_matrix()[None])[0]
        return up


def _nearest(result: FrameFixes) -> float:
    ranges = [s.fix.quality.range_m for s in result.fixes]
    ranges += [r.range_m for r in result.rejects if math.isfinite(r.range_m)]
    return min(ranges, default=math.inf)
