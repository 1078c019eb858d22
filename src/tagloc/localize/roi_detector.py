"""The tag source's detector in predicted regions, its fallback to the full frame and its counts.

:class:`RegionDetector` decides per camera frame: detect in the regions where the mapped tags
are predicted (:mod:`tagloc.localize.roi`), or in the full frame. The full frame is used (the
reason counted in :class:`RegionStats`) when

- ``backend``: the detector is not AprilTag 3 (regions need its per-call decimation);
- ``no_estimate``: no estimate yet (no camera model, extrinsics, or initialized filter; the
  filter re-acquiring after a gap; the odometry does not reach the frame's time);
- ``odometry_only``: the ladder is at its lowest level (nothing absolute carries);
- ``periodic``: every ``full_frame_every`` frames;
- ``gap``: the previous frame is more than ``gap_s`` older;
- ``no_tag_predicted``: no mapped tag should be in view;
- ``regions_cover_frame``: the merged regions cover more than ``max_area_fraction``;
- ``covariance_too_large``: a predicted corner's sigma exceeds ``max_sigma_px``;
- ``inconsistent_fix``: for ``full_frames_after_alarm`` frames after the filter gated a fix on
  the chi-square test, held one for a consistent set or re-initialized (the estimate may be
  wrong, as after a kidnap: the regions would be searched in the wrong places);
- ``predicted_tags_missing``: the region frame before found none of the tags found in the
  frame before it.

:attr:`RegionDetector.last_reason` says why the last frame used the full frame (None: regions).

``tags_missed`` counts the tags a full frame found that the region frame just before it did
not (a tag entering view between the two frames counts too: an upper bound on the misses).

The node's state arrives through :meth:`RegionDetector.observe` (each fix computation's
:class:`~tagloc.localize.sources.FixContext`: the node's live transform buffer and filter);
the prediction for a frame uses them as they are when the frame arrives. A detector on another
thread (the wall clock's worker) takes the node's state as a :class:`NodeView` made on the
node's thread when the frame is handed over (:meth:`RegionDetector.view`) and passes it to
:meth:`RegionDetector.detect`, so it never reads the live buffer or filter.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel
from tagloc.errors import TaglocError
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.config_roi import RegionConfig
from tagloc.localize.events import EventKind
from tagloc.localize.roi import MappedTag, mapped_tags, plan_regions, predict_tags
from tagloc.localize.sources import FixContext
from tagloc.supervise import Level
from tagloc.tags import AprilTagDetector, TagDetection, TagDetector, TagMap
from tagloc.tags.regions import PixelRegion, detect_in_regions
from tagloc.units import S_NS

__all__ = ["NodeView", "RegionDetector", "RegionStats"]

logger = logging.getLogger(__name__)

#: Filter decisions that say the estimate may be wrong (the ``inconsistent_fix`` reason).
ALARMS = (
    EventKind.GATED_CHI2, EventKind.PENDING_CONSISTENCY, EventKind.DISCARDED_CANDIDATE,
    EventKind.REINITIALIZED_KIDNAP,
)  # fmt: skip


@dataclass(slots=True)
class RegionStats:
    """What the region detector did over a run (:meth:`to_dict` goes in the run metadata)."""

    frames_regions: int = 0
    frames_full: Counter[str] = field(default_factory=Counter)
    regions: int = 0
    region_area_fraction_sum: float = 0.0
    tags_regions: int = 0
    tags_full: int = 0
    tags_missed: int = 0

    @classmethod
    def total(cls, parts: Iterable[RegionStats]) -> RegionStats:
        """The counts of several cameras summed."""
        out = cls()
        for p in parts:  # every field is a count (the reasons' Counter adds too)
            for f in fields(cls):
                setattr(out, f.name, getattr(out, f.name) + getattr(p, f.name))
        return out

    def to_dict(self) -> dict[str, Any]:
        n = self.frames_regions
        return {
            "frames_regions": n, "frames_full": sum(self.frames_full.values()),
            "full_frame_reasons": dict(self.frames_full), "regions": self.regions,
            "mean_region_area_fraction": self.region_area_fraction_sum / n if n else None,
            "tags_detected_regions": self.tags_regions, "tags_detected_full": self.tags_full,
            "tags_missed": self.tags_missed,
        }  # fmt: skip


@dataclass(frozen=True, slots=True, eq=False)
class NodeView:
    """What a frame's region decision reads of the node, taken at one instant (the frame's
    arrival): filter initialized and not re-acquiring (``estimate``), the ladder level (None
    unknown), the filter's alarm count (:data:`ALARMS`), and the estimate of the base in the
    map at the frame's stamp with its ``(6, 6)`` covariance (None: none; grown by the motion
    possible since the newest odometry when that ends before the frame)."""

    estimate: bool
    level: int | None
    alarms: int
    pose: tuple[SE3, np.ndarray] | None


class RegionDetector:
    """Predicted-region detection for one camera (module docstring).

    Parameters
    ----------
    config : RegionConfig
    tags : sequence of MappedTag
        The mapped tags to predict (:func:`tagloc.localize.roi.mapped_tags`).
    odom_frame, base_frame : str
        The odometry edge in the node's transform buffer.
    """

    def __init__(
        self, config: RegionConfig, tags: tuple[MappedTag, ...], odom_frame: str,
        base_frame: str,
    ) -> None:  # fmt: skip
        self._config, self._tags = config, tags
        self._odom_frame, self._base_frame = odom_frame, base_frame
        self._context: FixContext | None = None
        self.stats = RegionStats()
        #: Why the last frame used the full frame (a reason of the module docstring; None:
        #: the regions).
        self.last_reason: str | None = None
        self.reset()

    def observe(self, context: FixContext) -> None:
        """The node's state as of the latest fix computation (for the next frames)."""
        self._context = context

    def view(self, stamp_ns: int, context: FixContext | None = None) -> NodeView | None:
        """The node's state for the frame at ``stamp_ns``, as it is now (``context``, or the
        one observed last; None: none yet). Reads the node only, never this detector's frame
        history: call it on the node's thread, :meth:`detect` may run on another."""
        context = self._context if context is None else context
        if context is None:
            return None
        flt = context.filter
        estimate = flt.initialized and not flt.reacquiring
        alarms = sum(flt.events.count(kind) for kind in ALARMS)
        pose = self._pose(stamp_ns, context) if estimate else None
        return NodeView(estimate, context.level, alarms, pose)

    def reset(self) -> None:
        """Forget the node's state and the frame history (a clock jump back)."""
        self._context = None
        self._last_stamp: int | None = None
        self._since_full = 0
        self._last_region_ids: frozenset[int] | None = None
        self._alarms_seen = -1  # the filter's alarm count at the last frame (-1: none yet)
        self._alarm_frames = 0  # full frames still due after an alarm
        self._all_missing = False  # the last region frame found none of the tags before it
        self._last_found: frozenset[int] = frozenset()  # the tags the last frame found

    def detect(
        self, stamp_ns: int, image: npt.NDArray[np.generic], detector: TagDetector,
        camera: CameraModel | None, T_base_cam: SE3 | None, view: NodeView | None = None,
    ) -> list[TagDetection]:  # fmt: skip
        """One frame's detections, in the regions or the full frame (module docstring), from
        ``view`` of the node (default: :meth:`view` now)."""
        regions: list[PixelRegion] = []
        if view is None and isinstance(detector, AprilTagDetector):
            view = self.view(stamp_ns)
        reason = self._full_reason(stamp_ns, detector, view)
        if reason is None and (camera is None or T_base_cam is None):
            reason = "no_estimate"
        if reason is None:
            assert camera is not None and T_base_cam is not None and view is not None
            assert isinstance(detector, AprilTagDetector)
            regions, reason = self._plan(view, camera, T_base_cam, detector.quad_decimate)
        self._last_stamp = stamp_ns
        self.last_reason = reason
        if reason is not None:
            return self._full(image, detector, reason)
        assert isinstance(detector, AprilTagDetector)
        detections = detect_in_regions(detector, image, regions)
        ids = frozenset(d.tag_id for d in detections)
        # the tags of the frame before, none found now: the estimate may have gone wrong
        self._all_missing = bool(self._last_found) and not ids & self._last_found
        self._last_found = ids
        height, width = np.shape(image)[:2]
        st = self.stats
        st.frames_regions += 1
        st.regions += len(regions)
        st.region_area_fraction_sum += sum(r.area_px for r in regions) / float(width * height)
        st.tags_regions += len(detections)
        self._since_full += 1
        self._last_region_ids = ids
        return detections

    # ----- internals -------------------------------------------------------------------------
    def _full_reason(
        self, stamp_ns: int, detector: TagDetector, view: NodeView | None
    ) -> str | None:
        if not isinstance(detector, AprilTagDetector):
            return "backend"
        if view is None or not view.estimate:
            return "no_estimate"
        if view.level is not None and view.level >= Level.ODOMETRY_ONLY:
            return "odometry_only"
        alarms = view.alarms
        if alarms != self._alarms_seen:
            if self._alarms_seen >= 0:
                self._alarm_frames = self._config.full_frames_after_alarm
            self._alarms_seen = alarms
        if self._alarm_frames > 0:
            self._alarm_frames -= 1
            return "inconsistent_fix"
        if self._all_missing and self._config.full_frames_after_alarm > 0:
            return "predicted_tags_missing"
        if self._last_stamp is None or stamp_ns - self._last_stamp > self._config.gap_s * S_NS:
            return "gap"
        if self._since_full + 1 >= self._config.full_frame_every:
            return "periodic"
        return None

    def _plan(
        self, view: NodeView, camera: CameraModel, T_base_cam: SE3, min_decimate: float
    ) -> tuple[list[PixelRegion], str | None]:
        pose = view.pose
        if pose is None:
            return [], "no_estimate"
        T_map_base, cov = pose
        predicted = predict_tags(camera, T_map_base, cov, T_base_cam, self._tags, self._config,
                                 min_decimate)  # fmt: skip
        if not predicted:
            return [], "no_tag_predicted"
        if max(float(p.sigma_px.max()) for p in predicted) > self._config.max_sigma_px:
            return [], "covariance_too_large"
        regions = plan_regions(predicted, camera.width, camera.height)
        area = sum(r.area_px for r in regions) / float(camera.width * camera.height)
        if area > self._config.max_area_fraction:
            return [], "regions_cover_frame"
        return regions, None

    def _pose(self, stamp_ns: int, context: FixContext) -> tuple[SE3, np.ndarray] | None:
        """The estimate at ``stamp_ns`` (or at the newest odometry before it, its uncertainty
        grown by the motion possible since) with its covariance; None if there is none."""
        cfg = self._config
        try:
            latest = context.buffer.latest_stamp(self._odom_frame, self._base_frame)
            at = min(stamp_ns, latest)
            pose = context.filter.pose_at(at)
        except TaglocError:
            return None
        cov = np.array(pose.cov, dtype=np.float64)
        dt = max(0, stamp_ns - at) / S_NS
        if dt > 0.0:
            grow = [(cfg.max_speed_m_s * dt) ** 2] * 3 + [(cfg.max_turn_rate_rad_s * dt) ** 2] * 3
            cov += np.diag(grow)
        return pose.T_map_base, cov

    def _full(
        self, image: npt.NDArray[np.generic], detector: TagDetector, reason: str
    ) -> list[TagDetection]:
        detections = detector.detect(image)
        ids = frozenset(d.tag_id for d in detections)
        st = self.stats
        st.frames_full[reason] += 1
        st.tags_full += len(detections)
        if self._last_region_ids is not None:
            st.tags_missed += len(ids - self._last_region_ids)
        self._last_region_ids = None
        self._since_full = 0
        self._all_missing = False
        self._last_found = ids
        return detections


def region_detector(config: LocalizerConfig, tag_map: TagMap) -> RegionDetector | None:
    """The tag source's region detector (None when ``tags.roi.enabled`` is false)."""
    roi = config.tags.roi
    if not roi.enabled:
        return None
    frames = config.frames
    tags = mapped_tags(tag_map, config.tags.family, frames.map_frame)
    return RegionDetector(roi, tags, frames.odom_frame, frames.base_frame)
