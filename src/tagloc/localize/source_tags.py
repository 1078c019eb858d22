"""The fiducial fix source of the node: camera frames to tag fixes (:class:`TagSource`).

Frames come from every camera of the rig (:mod:`tagloc.localize.tag_cameras`: the cameras
given, each on its own topics, or one camera on ``topics``). A frame is pre-detected corners
(``TagDetectionsMsg``), an image run through the configured detector (``ImageMsg``), or fixes
formed on a worker thread (:meth:`TagSource.fixer`, :meth:`TagSource.arrive_fixed`, for the
camera named; the worker detects in the predicted regions through
:meth:`TagSource.region_detect`). It waits in the node's queue until the odometry covers its
stamp; then its camera's
:class:`~tagloc.localize.fiducial.FiducialFixSource` (built on first use, once the camera
model, from ``CameraInfoMsg`` unless given, and the extrinsics, from the stream's static
``base -> <frame_id>`` unless given, are known) forms its fixes with the filter's estimate as
the orientation prior; each fix's record names its camera.

Its own skips: ``frame_duplicate_stamp``, ``image_size_mismatch``, ``detector_error``,
``no_camera_info``, ``no_extrinsics``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel, from_camera_info
from tagloc.errors import TransformLookupError
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.fiducial import E_Z, FiducialFixSource, FrameFixes
from tagloc.localize.fix import LocalizeError
from tagloc.localize.realtime_worker import Fixer, FrameDetect
from tagloc.localize.roi_detector import RegionDetector, RegionStats, region_detector
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
from tagloc.localize.tag_cameras import CameraSlot, NodeCamera, camera_slots
from tagloc.messages import CameraInfoMsg, ImageMsg, Message, TagDetectionsMsg
from tagloc.supervise import FixSourceSpec
from tagloc.tags import TagDetection, TagDetector

logger = logging.getLogger(__name__)

__all__ = ["MARKERS", "TagSource"]

MARKERS = "markers"
#: Camera frames that may wait for odometry to cover their stamp (30 s at 30 Hz).
_MAX_PENDING = 900
_NAN6 = np.full((6, 6), np.nan)
_NAN6.flags.writeable = False

@dataclass(frozen=True, slots=True)
class _Frame:
    stamp_ns: int
    frame_id: str
    detections: tuple[TagDetection, ...]
    fixes: FrameFixes | None = None  # formed elsewhere (the wall clock's worker)
    slot: CameraSlot | None = None  # None: the first camera


class TagSource:
    """Camera frames to gated tag fixes (module docstring; a
    :class:`~tagloc.localize.sources.FixSource`)."""

    spec = FixSourceSpec(MARKERS, "markers", "camera")
    max_waiting = _MAX_PENDING
    overflow_reason = "frame_without_odometry"
    jump_reason = "frame_before_clock_jump"

    def __init__(self, config: LocalizerConfig, inputs: SourceInputs) -> None:
        self._config, self._inputs = config, inputs
        self._detector = inputs.detector
        self._slots = camera_slots(inputs.cameras, inputs.topics, inputs.camera,
                                   inputs.T_base_cam)  # fmt: skip
        self.skipped = SkipCounter()
        # predicted-region detection keeps its state per camera
        self._regions: dict[str, RegionDetector] = {}
        for slot in self._slots:
            regions = region_detector(config, inputs.tag_map)
            if regions is not None:
                self._regions[slot.name] = regions

    @property
    def camera(self) -> CameraModel | None:
        """The first camera's model (given, or from the first ``CameraInfoMsg``; None yet)."""
        return self._slots[0].camera

    @property
    def T_base_cam(self) -> SE3 | None:
        """The first camera's extrinsics (given, or the stream's once a frame needed them)."""
        return self.extrinsics(self._slots[0])

    @property
    def T_base_cam_by_camera(self) -> dict[str, SE3 | None]:
        """Each camera's extrinsics (given, or the stream's once a frame needed them)."""
        return {s.name: self.extrinsics(s) for s in self._slots}

    @property
    def cameras(self) -> tuple[NodeCamera, ...]:
        """The cameras and their topics, in order (one, ``""``, on the node's topics if none
        were given)."""
        return tuple(s.spec for s in self._slots)

    @property
    def camera_names(self) -> tuple[str, ...]:
        """The cameras, in order (``("",)``: the one camera on the node's topics)."""
        return tuple(s.name for s in self._slots)

    @staticmethod
    def extrinsics(slot: CameraSlot) -> SE3 | None:
        if slot.spec.T_base_cam is not None:
            return slot.spec.T_base_cam
        return None if slot.source is None else slot.source.T_base_cam

    # ----- FixSource -------------------------------------------------------------------------
    def arrive(self, topic: str, msg: Message) -> Arrival | None:
        for slot in self._slots:
            spec = slot.spec
            if isinstance(msg, TagDetectionsMsg) and topic == spec.detections_topic:
                return self._frame(_Frame(msg.stamp_ns, msg.frame_id, msg.detections, None, slot))
            if isinstance(msg, ImageMsg) and topic == spec.image_topic:
                detections = self._detect(msg, slot)
                return None if detections is None else self._frame(
                    _Frame(msg.stamp_ns, msg.frame_id, detections, None, slot)
                )  # fmt: skip
            if isinstance(msg, CameraInfoMsg) and topic == spec.camera_info_topic:
                if slot.camera is None:
                    slot.camera = from_camera_info(msg.info, f"{topic} CameraInfo")
                return None
        return None

    def arrive_fixed(
        self, stamp_ns: int, frame_id: str, detections: tuple[TagDetection, ...],
        fixes: FrameFixes, camera: str | None = None,
    ) -> Arrival:  # fmt: skip
        """A frame of ``camera`` (None: the first) whose fixes were formed elsewhere (by
        :meth:`fixer`, on another thread)."""
        return self._frame(_Frame(stamp_ns, frame_id, detections, fixes, self._slot(camera)))

    def _slot(self, camera: str | None) -> CameraSlot:
        """The camera named (None: the first).

        Raises
        ------
        LocalizeError
            If no camera has that name.
        """
        if camera is None:
            return self._slots[0]
        for slot in self._slots:
            if slot.name == camera:
                return slot
        raise LocalizeError(f"no camera {camera!r} (cameras: {', '.join(self.camera_names)})")

    def fixes(self, payload: object, context: FixContext) -> SourceResult | None:
        """One frame: its fixes (with the filter's estimate as the prior), refusals, record."""
        assert isinstance(payload, _Frame)
        frame = payload
        slot = frame.slot or self._slots[0]
        for regions in self._regions.values():
            regions.observe(context)
        source = self._fix_source(slot, frame, context, quiet=False)
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
                camera=slot.name,
            )
            for r in result.rejects
        )  # fmt: skip
        offers = tuple(
            Offer(
                s.fix,
                FixAttempt(
                    s.fix.stamp_ns, s.fix.source, s.tag_ids, s.fix.T_map_base, s.fix.cov, "",
                    s.fix.quality.range_m, s.fix.quality.view_angle_rad, s.false_detection,
                    camera=slot.name,
                ),
                dof, s.fix.quality.reproj_err_px,
            )
            for s in result.fixes
        )  # fmt: skip
        nearest = truth.nearest_visible_m if truth is not None else _nearest(result)
        by_frame = truth.nearest_by_frame if truth is not None else ()
        record = CameraFrameRecord(frame.stamp_ns, nearest, len(frame.detections), 0, by_frame)
        return SourceResult(offers, refused, 0, record, frame.stamp_ns, frame.detections)

    def observe(self, result: SourceResult) -> None:
        return None

    def reset(self) -> None:
        """Forget the frame stamps seen and the extrinsics looked up on the old timeline."""
        for slot in self._slots:
            slot.reset()
        for regions in self._regions.values():
            regions.reset()

    def metadata(self) -> dict[str, Any]:
        if not self._regions:
            return {}
        return {"regions": RegionStats.total(r.stats for r in self._regions.values()).to_dict()}

    # ----- the wall clock's worker -----------------------------------------------------------
    def fixer(
        self, stamp_ns: int, frame_id: str, context: FixContext,
        prior: Callable[[], SE3 | None], T_odom_base: SE3 | None = None,
        camera: str | None = None,
    ) -> Fixer | None:  # fmt: skip
        """A function that forms a frame's fixes of ``camera`` (None: the first) without
        touching any state, for a worker thread (None until the camera's model and extrinsics
        are known); ``prior()`` is called when it runs, for the orientation prior;
        ``T_odom_base`` (the odometry about the frame's stamp) gives "up" for a gravity-aligned
        odometry."""
        slot = self._slot(camera)
        source = self._fix_source(slot, _Frame(stamp_ns, frame_id, ()), context, quiet=True)
        if source is None:
            return None

        up_base = self._up_from(T_odom_base)

        def fixes(stamp: int, detections: tuple[TagDetection, ...]) -> FrameFixes:
            return source.frame_fixes(stamp, detections, prior(), None, up_base)

        return fixes

    def region_detect(
        self, stamp_ns: int, context: FixContext, camera: str | None = None
    ) -> FrameDetect | None:
        """A function that detects the frame at ``stamp_ns`` of ``camera`` (None: the first)
        in the regions predicted from the node's state now (``context``: the prediction never
        sees a later state), with the camera's fallbacks to the full frame and its counts, for
        a worker thread (None: ``tags.roi.enabled`` is false). Call the functions in frame
        order, from one thread."""
        slot = self._slot(camera)
        regions = self._regions.get(slot.name)
        if regions is None:
            return None
        cam, T_base_cam = slot.camera, self.extrinsics(slot)
        view = regions.view(stamp_ns, context)

        def detect(image: npt.NDArray[np.generic], detector: TagDetector) -> list[TagDetection]:
            if cam is not None and image.shape[:2] != (cam.height, cam.width):
                return list(detector.detect(image))  # not this camera's size: no prediction
            return regions.detect(stamp_ns, image, detector, cam, T_base_cam, view)

        return detect

    # ----- internals -------------------------------------------------------------------------
    def _frame(self, frame: _Frame) -> Arrival:
        stamp = frame.stamp_ns
        if (frame.slot or self._slots[0]).seen(stamp):
            self.skipped.skip("frame_duplicate_stamp", f"camera frame at {stamp} ns")
            return Arrival(stamp, tick=True)
        return Arrival(stamp, tick=True, work=Work(stamp, stamp, frame))

    def _detect(self, msg: ImageMsg, slot: CameraSlot) -> tuple[TagDetection, ...] | None:
        cam = slot.camera
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
            regions = self._regions.get(slot.name)
            if regions is not None:
                return tuple(regions.detect(
                    msg.stamp_ns, msg.image, self._detector, cam, self.extrinsics(slot)
                ))  # fmt: skip
            return tuple(self._detector.detect(msg.image))
        except Exception as exc:  # a detector's failure on one frame must not stop the node
            self.skipped.skip("detector_error", f"frame at {msg.stamp_ns} ns: {exc!r}")
            return None

    def _fix_source(
        self, slot: CameraSlot, frame: _Frame, context: FixContext, *, quiet: bool
    ) -> FiducialFixSource | None:
        if slot.source is not None:
            return slot.source
        if slot.camera is None:
            if not quiet:
                detail = f"frame at {frame.stamp_ns} ns before CameraInfo"
                self.skipped.skip("no_camera_info", detail)
            return None
        cfg = self._config
        T_base_cam = slot.spec.T_base_cam
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
        slot.source = FiducialFixSource(
            slot.camera, T_base_cam, self._inputs.tag_map, family=tags.family,
            gates=cfg.gates.observation_gates(), noise=tags.noise, config=tags,
            map_frame=cfg.frames.map_frame,
            up_base=E_Z if cfg.odometry_frame.knows_up else None,
        )  # fmt: skip
        if not cfg.odometry_frame.knows_up and slot is self._slots[0]:
            logger.warning(
                "the odometry frame knows no up (odometry_frame.base_up_axis: null): tag fixes "
                "run without the gravity prior"
            )
        return slot.source

    def _up_base(self, context: FixContext, stamp_ns: int) -> FloatArray | None:
        """ "Up" in the base at ``stamp_ns`` for a gravity-aligned odometry (None: the fix
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
