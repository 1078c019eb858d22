"""The lidar half of the streaming node (:class:`~tagloc.localize.node.LocalizerNode`).

A ``PointCloudMsg`` on the lidar topic (``config.lidar``, :mod:`tagloc.localize.config_lidar`)
waits until the odometry covers its sweep, then: non-finite points dropped; each point moved to
the scanner's pose at the sweep start with the odometry (:func:`tagloc.lidar.cloud.deskew`;
``T_base_lidar`` from ``/tf_static``) and expressed in the base frame at ``stamp_ns``; the
estimate's ``T_map_base`` at that stamp predicted; the scan registered against the premap
(:func:`tagloc.lidar.fix.lidar_fix`); the fix applied by
:meth:`MapOdomFilter.update_partial <tagloc.localize.filter.MapOdomFilter.update_partial>` with
source ``lidar``. Every sweep feeds the supervisor's liveness of input ``lidar``; every fix
decided on (accepted, gated, or rejected by the registration's own checks) its quality books.

A sweep that cannot be used is a counted skip with one log line per reason (``lidar_empty``,
``lidar_wrong_frame``, ``lidar_no_tf``, ``lidar_no_odometry``, ``lidar_stale``,
``lidar_no_estimate``, ``in_cab``, ``lidar_rejected: <reason>``); the node goes on with its
other sources. The node's state lives on the node; this mixin holds only methods.
"""

from __future__ import annotations

import logging
import math
import re
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from tagloc.errors import TransformLookupError
from tagloc.geometry import SE3
from tagloc.lidar.cloud import deskew
from tagloc.lidar.fix import lidar_fix
from tagloc.localize.events import APPLIED, FilterEvent
from tagloc.localize.fix import FixQuality, LocalizeError, PartialFix
from tagloc.localize.projected_update import planar_constraint
from tagloc.localize.run import FixAttempt
from tagloc.messages import PointCloudMsg

if TYPE_CHECKING:
    from collections import Counter

    from tagloc.frames import TransformBuffer
    from tagloc.lidar.registration import Target
    from tagloc.localize.config import LocalizerConfig
    from tagloc.localize.config_tags import FramesConfig
    from tagloc.localize.filter import MapOdomFilter
    from tagloc.localize.held import HeldRecords
    from tagloc.supervise import Supervisor
    from tagloc.tags import TagDetection, TagMap

__all__ = ["LIDAR", "LidarScans", "check_premap_overlap"]

logger = logging.getLogger(__name__)
LIDAR = "lidar"
S_NS = 1_000_000_000
#: Sweeps that may wait for odometry to cover them (10 s at 10 Hz); older ones are dropped.
_MAX_WAITING = 100
#: Variance written for the unmeasured directions of a lidar fix in its run record (m^2, rad^2).
UNMEASURED_VAR = 1e6
#: A premap must reach within this of at least one tag of the map frame (m, horizontally).
PREMAP_TAG_MARGIN_M = 1.0


def check_premap_overlap(premap_map: np.ndarray, tag_map: TagMap, map_frame: str) -> None:
    """Refuse a premap that cannot be in the tag map's frame: none of the map frame's tags lies
    within its horizontal bounding box grown by :data:`PREMAP_TAG_MARGIN_M` (tags hang on the
    walls the premap holds; a premap of another building, or in another frame, misses all).
    A map without tags in ``map_frame`` is not checked.

    Raises
    ------
    LocalizeError
        One line with both extents.
    """
    tags = tag_map.in_frame(map_frame)
    if not len(tags):
        return
    xy = np.array([t.T_frame_tag().translation[:2] for t in tags])
    lo = premap_map[:, :2].min(axis=0) - PREMAP_TAG_MARGIN_M
    hi = premap_map[:, :2].max(axis=0) + PREMAP_TAG_MARGIN_M
    if not ((xy >= lo) & (xy <= hi)).all(axis=1).any():
        raise LocalizeError(
            f"premap does not overlap the tag map: its extent x {lo[0]:.1f}..{hi[0]:.1f}, "
            f"y {lo[1]:.1f}..{hi[1]:.1f} m (with {PREMAP_TAG_MARGIN_M:g} m margin) holds none of "
            f"the {len(tags)} tags in {map_frame!r} (x {xy[:, 0].min():.1f}..{xy[:, 0].max():.1f}"
            f", y {xy[:, 1].min():.1f}..{xy[:, 1].max():.1f} m): another site or another frame?"
        )


class LidarScans:
    """Sweeps to lidar fixes to filter decisions (module docstring). The node's state it uses
    is declared here; the node sets it."""

    config: LocalizerConfig
    frames_cfg: FramesConfig
    buffer: TransformBuffer
    filter: MapOdomFilter
    supervisor: Supervisor
    skipped: Counter[str]
    lidar_counts: Counter[str]
    _tag_map: TagMap
    _premap: Target | None
    _scans: deque[PointCloudMsg]
    _next_scan_ns: int
    _in_cab: bool
    _held: HeldRecords
    _fix_ns: int | None
    _odometer_m: float
    _fix_odometer_m: float
    _last_odom: int | None

    if TYPE_CHECKING:

        def _skip(self, reason: str, detail: str) -> None: ...  # CameraFrames': counts, logs

    @property
    def lidar_active(self) -> bool:
        """Whether sweeps are used (``lidar.enabled`` and a premap)."""
        return self._premap is not None

    def _on_cloud(self, msg: PointCloudMsg) -> None:
        """A sweep arrived: liveness, then wait for the odometry to cover it (thinned to
        ``lidar.max_rate_hz``)."""
        self.supervisor.on_input(LIDAR, msg.stamp_ns)
        cfg = self.config.lidar
        if msg.frame_id != cfg.frame_id:
            return self._skip(
                "lidar_wrong_frame",
                f"cloud at {msg.stamp_ns} ns in frame {msg.frame_id!r}, expected {cfg.frame_id!r}",
            )
        if not np.isfinite(msg.points).all(axis=1).any():
            return self._skip("lidar_empty", f"sweep at {msg.stamp_ns} ns has no finite point")
        if msg.stamp_ns < self._next_scan_ns:
            self.lidar_counts["thinned"] += 1
            return None
        self._next_scan_ns = msg.stamp_ns + round(S_NS / cfg.max_rate_hz)
        if len(self._scans) >= _MAX_WAITING:
            self._scans.popleft()
            self._skip("lidar_no_odometry", f"over {_MAX_WAITING} sweeps wait for odometry")
        self._scans.append(msg)
        return None

    def _lidar_due(self, odom_ns: int | None) -> None:
        """Process the waiting sweeps the odometry (up to ``odom_ns``; None: all) covers."""
        while self._scans:
            msg = self._scans[0]
            end = msg.stamp_ns + _sweep_ns(msg)
            if odom_ns is not None and end > odom_ns:
                return
            self._scans.popleft()
            self._process_cloud(msg)

    def _note_tags(self, detections: tuple[TagDetection, ...]) -> None:
        """The cab rule: the newest camera frame with a tag the map knows decides whether the
        robot is in the cab (its tags in ``lidar.cab_frame``) or out (a tag of the map frame)."""
        if self._premap is None:
            return
        cfg = self.config.lidar
        family = self.config.tags.family
        for det in detections:
            entry = self._tag_map.get(det.tag_id, family)
            if entry is not None and entry.frame in (cfg.cab_frame, self.frames_cfg.map_frame):
                self._in_cab = entry.frame == cfg.cab_frame
                return

    def _process_cloud(self, msg: PointCloudMsg) -> None:
        """One sweep (module docstring): a fix decided on, or a counted skip."""
        premap, cfg, f = self._premap, self.config.lidar, self.frames_cfg
        assert premap is not None
        stamp = msg.stamp_ns
        if self._last_odom is not None and self._last_odom - stamp > cfg.max_scan_age_s * S_NS:
            return self._skip("lidar_stale", f"sweep at {stamp} ns processed too late")
        if cfg.ignore_in_cab and self._in_cab:
            return self._expected_skip("in_cab", f"sweep at {stamp} ns: the robot is in the cab")
        finite = np.isfinite(msg.points).all(axis=1)
        points_lidar = np.asarray(msg.points, dtype=np.float64)[finite]
        try:
            T_base_lidar = self.buffer.lookup(f.base_frame, msg.frame_id, stamp)
        except TransformLookupError as exc:
            return self._skip("lidar_no_tf", f"sweep at {stamp} ns: {exc}")
        offsets = msg.time_offset_s
        if offsets is not None:
            try:
                points_lidar = deskew(
                    points_lidar, np.asarray(offsets, dtype=np.float64)[finite],
                    self._sweep_motion(stamp, T_base_lidar),
                )  # fmt: skip
            except TransformLookupError as exc:
                return self._skip("lidar_no_odometry", f"sweep at {stamp} ns: {exc}")
        if not self.filter.initialized:  # a lidar fix cannot start the estimate (tags do)
            return self._expected_skip("lidar_no_estimate", f"sweep at {stamp} ns, no estimate")
        try:
            T_map_base_prior = self.filter.T_map_base_at(stamp)
        except TransformLookupError as exc:
            return self._skip("lidar_no_odometry", f"sweep at {stamp} ns: {exc}")
        points_base = T_base_lidar.act(points_lidar)
        fix = lidar_fix(points_base, premap, T_map_base_prior, cfg.fix)
        if fix.rejected is not None:
            self._skip(
                f"lidar_rejected: {_reason_key(fix.rejected)}", f"{stamp} ns: {fix.rejected}"
            )
            self._held.hold(_attempt(stamp, fix.T_map_base, None, f"rejected:{fix.rejected}"))
            self.supervisor.on_fix(LIDAR, False, math.nan, math.nan)
            return None
        B = fix.basis
        floor = np.diag([cfg.min_sigma_m**2] * 3 + [cfg.min_sigma_rad**2] * 3)
        partial = PartialFix(
            stamp, fix.T_map_base, B, fix.covariance_k + B.T @ floor @ B, LIDAR,
            FixQuality(math.nan, 0, math.nan),
        )  # fmt: skip
        event = self.filter.update_partial(partial)
        self._held.hold(_attempt(stamp, fix.T_map_base, partial, event.kind.value))
        k = (
            planar_constraint(partial.basis, partial.cov)[1].shape[0]
            if self.filter.planar
            else partial.k
        )
        self._lidar_judged(event, k)
        return None

    def _sweep_motion(self, stamp: int, T_base_lidar: SE3) -> Callable[[np.ndarray], SE3]:
        """``offsets (K,) s -> T_lidar0_lidart`` (an SE3 batch) from the odometry."""
        f = self.frames_cfg
        T_odom_base0 = self.buffer.lookup(f.odom_frame, f.base_frame, stamp)
        T_lidar_base = T_base_lidar.inverse()

        def motion(offsets_s: np.ndarray) -> SE3:
            stamps = stamp + np.round(np.asarray(offsets_s) * S_NS).astype(np.int64)
            T_odom_base = self.buffer.lookup_many(f.odom_frame, f.base_frame, stamps)
            return T_lidar_base @ T_odom_base0.inverse() @ T_odom_base @ T_base_lidar

        return motion

    def _expected_skip(self, reason: str, detail: str) -> None:
        """Count a sweep not used for an expected reason (no estimate yet, in the cab); the
        first of each reason is logged at INFO (not a warning: nothing is wrong)."""
        self.skipped[reason] += 1
        if self.skipped[reason] == 1:
            logger.info("lidar sweep skipped (%s): %s; further ones are counted", reason, detail)

    def _lidar_judged(self, event: FilterEvent, dof: int) -> None:
        """The supervisor's quality books (NIS per measured direction, ``dof`` the directions
        the filter measured: after the planar projection in planar mode); an accepted fix that
        measures every direction of the filter counts as the last fix (as a tag fix does)."""
        accepted = event.kind.value in APPLIED
        if accepted and dof >= self.filter.dof:
            self._fix_ns = max(self._fix_ns or event.stamp_ns, event.stamp_ns)
            self._fix_odometer_m = self._odometer_m
        nis = math.nan if event.d2 is None or dof == 0 else event.d2 / dof
        self.supervisor.on_fix(LIDAR, accepted, nis, math.nan)


def _sweep_ns(msg: PointCloudMsg) -> int:
    offsets = msg.time_offset_s
    if offsets is None or not len(offsets):
        return 0
    top = float(np.nanmax(offsets)) if np.isfinite(offsets).any() else 0.0
    return round(top * S_NS)


def _reason_key(reason: str) -> str:
    """The reason without its numbers (``low inlier fraction 0.31 < 0.5`` -> ``low inlier
    fraction``): one skip count per kind of rejection."""
    return re.split(r"[\d:<>=(]", reason, maxsplit=1)[0].strip() or reason


def _attempt(stamp: int, T_map_base: SE3, fix: PartialFix | None, decision: str) -> FixAttempt:
    """The run record of a lidar fix: its covariance along the measured directions, and
    :data:`UNMEASURED_VAR` along the others (NaN for a rejected one)."""
    if fix is None:
        cov = np.full((6, 6), np.nan)
    else:
        B = fix.basis
        cov = B @ fix.cov @ B.T + UNMEASURED_VAR * (np.eye(6) - B @ B.T)
    return FixAttempt(stamp, LIDAR, (), T_map_base, cov, decision, math.nan, math.nan, None)
