"""The lidar fix source of the node: sweeps registered against the premap
(:class:`LidarSource`).

A ``PointCloudMsg`` on the lidar topic (``config.lidar``, :mod:`tagloc.localize.config_lidar`)
waits in the node's queue until the odometry covers its sweep, then: non-finite points
dropped; each point moved to the scanner's pose at the sweep start with the odometry
(:func:`tagloc.lidar.cloud.deskew`; ``T_base_lidar`` from ``/tf_static``) and expressed in
the base frame at ``stamp_ns``; the estimate's ``T_map_base`` at that stamp predicted; the scan
registered against the premap (:func:`tagloc.lidar.fix.lidar_fix`); the fix offered to
:meth:`MapOdomFilter.update_partial <tagloc.localize.filter.MapOdomFilter.update_partial>` with
source ``lidar``. Every sweep feeds the supervisor's liveness of input ``lidar``; every fix
decided on (accepted, gated, or rejected by the registration's own checks) its quality books.

A sweep that cannot be used is a counted skip with one log line per reason (``lidar_empty``,
``lidar_wrong_frame``, ``lidar_no_tf``, ``lidar_no_odometry``, ``lidar_stale``,
``lidar_no_estimate``, ``in_cab``, ``lidar_rejected: <reason>``); the node goes on with its
other sources. The source owns the premap (a registration target, prepared once), the
thinning to ``lidar.max_rate_hz`` and the cab rule (:class:`CabRule`, fed by the camera
frames the other sources report).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Any

import numpy as np

from tagloc.errors import TransformLookupError
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.lidar.cloud import deskew
from tagloc.lidar.fix import lidar_fix
from tagloc.lidar.registration import Target
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.fix import FixQuality, LocalizeError, PartialFix
from tagloc.localize.projected_update import planar_constraint
from tagloc.localize.run import FixAttempt
from tagloc.localize.sources import (
    Arrival,
    FixContext,
    Offer,
    SkipCounter,
    SourceInputs,
    SourceResult,
    Work,
)
from tagloc.messages import Message, PointCloudMsg
from tagloc.supervise import FixSourceSpec
from tagloc.tags import TagDetection, TagMap
from tagloc.units import S_NS

__all__ = [
    "LIDAR",
    "CabRule",
    "LidarSource",
    "check_premap",
    "check_premap_overlap",
    "prepare_premap",
]

LIDAR = "lidar"
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


def check_premap(premap: np.ndarray, tag_map: TagMap, map_frame: str) -> np.ndarray:
    """The premap as ``(N, 3)`` float64 points, if the node can use it.

    Raises
    ------
    LocalizeError
        If the premap is not a finite ``(N, 3)`` array of at least 10 points, or misses every
        tag of the map frame (:func:`check_premap_overlap`).
    """
    points = np.asarray(premap, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 10:
        raise LocalizeError(f"premap must be (N >= 10, 3) points, got {points.shape}")
    if not np.isfinite(points).all():
        raise LocalizeError("premap holds NaN or inf points")
    check_premap_overlap(points, tag_map, map_frame)
    return points


def prepare_premap(premap: np.ndarray, tag_map: TagMap, config: LocalizerConfig) -> Target:
    """The premap as a registration target, once checked (:func:`check_premap`).

    Raises
    ------
    LocalizeError
        As :func:`check_premap`.
    """
    points = check_premap(premap, tag_map, config.frames.map_frame)
    return Target.from_points(points, config.lidar.fix.registration)


class CabRule:
    """Whether the robot is in the elevator cab: the newest camera frame with a tag the map
    knows decides (its tags in ``lidar.cab_frame``: in; a tag of the map frame: out)."""

    def __init__(self, tag_map: TagMap, config: LocalizerConfig) -> None:
        self._tag_map, self._family = tag_map, config.tags.family
        self._cab, self._map = config.lidar.cab_frame, config.frames.map_frame
        self.in_cab = False

    def note(self, detections: tuple[TagDetection, ...]) -> None:
        """One camera frame's tags."""
        for det in detections:
            entry = self._tag_map.get(det.tag_id, self._family)
            if entry is not None and entry.frame in (self._cab, self._map):
                self.in_cab = entry.frame == self._cab
                return


class LidarSource:
    """Sweeps to lidar fixes (module docstring; a :class:`~tagloc.localize.sources.FixSource`).

    Parameters
    ----------
    config : LocalizerConfig
    inputs : SourceInputs
        Its ``premap`` ((N, 3) float in the map frame, m) is required.

    Raises
    ------
    LocalizeError
        As :func:`prepare_premap`.
    """

    spec = FixSourceSpec(LIDAR, "lidar", LIDAR)
    max_waiting = _MAX_WAITING
    overflow_reason = "lidar_no_odometry"
    jump_reason = "lidar_before_clock_jump"

    def __init__(self, config: LocalizerConfig, inputs: SourceInputs) -> None:
        assert inputs.premap is not None
        self._config, self._topic = config, inputs.topics.lidar
        self._premap = prepare_premap(inputs.premap, inputs.tag_map, config)
        self._cab = CabRule(inputs.tag_map, config)
        self._next_ns = -(2**62)
        self._thinned = 0
        self.skipped = SkipCounter()

    # ----- FixSource -------------------------------------------------------------------------
    def arrive(self, topic: str, msg: Message) -> Arrival | None:
        """A sweep: the lidar's liveness, then wait for the odometry to cover it (thinned to
        ``lidar.max_rate_hz``)."""
        if not isinstance(msg, PointCloudMsg) or topic != self._topic:
            return None
        cfg, stamp = self._config.lidar, msg.stamp_ns
        if msg.frame_id != cfg.frame_id:
            self.skipped.skip(
                "lidar_wrong_frame",
                f"cloud at {stamp} ns in frame {msg.frame_id!r}, expected {cfg.frame_id!r}",
            )
            return Arrival(stamp)
        if not np.isfinite(msg.points).all(axis=1).any():
            self.skipped.skip("lidar_empty", f"sweep at {stamp} ns has no finite point")
            return Arrival(stamp)
        if stamp < self._next_ns:
            self._thinned += 1
            return Arrival(stamp)
        self._next_ns = stamp + round(S_NS / cfg.max_rate_hz)
        return Arrival(stamp, work=Work(stamp + _sweep_ns(msg), stamp, msg))

    def fixes(self, payload: object, context: FixContext) -> SourceResult | None:
        """One sweep (module docstring): a fix offered, a refusal, or a counted skip."""
        assert isinstance(payload, PointCloudMsg)
        msg, cfg, f = payload, self._config.lidar, self._config.frames
        stamp, last = msg.stamp_ns, context.last_odom_ns
        if last is not None and last - stamp > cfg.max_scan_age_s * S_NS:
            return self._skip("lidar_stale", f"sweep at {stamp} ns processed too late")
        if cfg.ignore_in_cab and self._cab.in_cab:
            return self._skip(
                "in_cab", f"sweep at {stamp} ns: the robot is in the cab", expected=True
            )
        finite = np.isfinite(msg.points).all(axis=1)
        points_lidar = np.asarray(msg.points, dtype=np.float64)[finite]
        buffer = context.buffer
        try:
            T_base_lidar = buffer.lookup(f.base_frame, msg.frame_id, stamp)
        except TransformLookupError as exc:
            return self._skip("lidar_no_tf", f"sweep at {stamp} ns: {exc}")
        offsets = msg.time_offset_s
        if offsets is not None:
            try:
                points_lidar = deskew(
                    points_lidar, np.asarray(offsets, dtype=np.float64)[finite],
                    self._sweep_motion(buffer, stamp, T_base_lidar),
                )  # fmt: skip
            except TransformLookupError as exc:
                return self._skip("lidar_no_odometry", f"sweep at {stamp} ns: {exc}")
        flt = context.filter
        if not flt.initialized:  # a lidar fix cannot start the estimate (tags do)
            return self._skip(
                "lidar_no_estimate", f"sweep at {stamp} ns, no estimate", expected=True
            )
        try:
            T_map_base_prior = flt.T_map_base_at(stamp)
        except TransformLookupError as exc:
            return self._skip("lidar_no_odometry", f"sweep at {stamp} ns: {exc}")
        fix = lidar_fix(T_base_lidar.act(points_lidar), self._premap, T_map_base_prior, cfg.fix)
        if fix.rejected is not None:
            self.skipped.skip(
                f"lidar_rejected: {_reason_key(fix.rejected)}", f"{stamp} ns: {fix.rejected}"
            )
            attempt = _attempt(stamp, fix.T_map_base, None, f"rejected:{fix.rejected}")
            return SourceResult(refused=(attempt,), failed=1)
        B = fix.basis
        floor = np.diag([cfg.min_sigma_m**2] * 3 + [cfg.min_sigma_rad**2] * 3)
        partial = PartialFix(
            stamp, fix.T_map_base, B, fix.covariance_k + B.T @ floor @ B, LIDAR,
            FixQuality(math.nan, 0, math.nan),
        )  # fmt: skip
        k = planar_constraint(B, partial.cov)[1].shape[0] if flt.planar else partial.k
        attempt = _attempt(stamp, fix.T_map_base, partial, "")
        return SourceResult(offers=(Offer(partial, attempt, k),))

    def observe(self, result: SourceResult) -> None:
        """The cab rule reads the camera frames' tags."""
        if result.detections:
            self._cab.note(result.detections)

    def reset(self) -> None:
        """The thinning starts over (the cab rule holds: the robot did not move)."""
        self._next_ns = -(2**62)

    def metadata(self) -> dict[str, Any]:
        return {"lidar_source": {"sweeps_thinned": self._thinned}}

    # ----- internals -------------------------------------------------------------------------
    def _skip(self, reason: str, detail: str, *, expected: bool = False) -> SourceResult | None:
        """A counted skip: nothing came of the sweep."""
        self.skipped.skip(reason, detail, expected=expected)
        return None

    def _sweep_motion(
        self, buffer: TransformBuffer, stamp: int, T_base_lidar: SE3
    ) -> Callable[[np.ndarray], SE3]:
        """``offsets (K,) s -> T_lidar0_lidart`` (an SE3 batch) from the odometry."""
        f = self._config.frames
        T_odom_base0 = buffer.lookup(f.odom_frame, f.base_frame, stamp)
        T_lidar_base = T_base_lidar.inverse()

        def motion(offsets_s: np.ndarray) -> SE3:
            stamps = stamp + np.round(np.asarray(offsets_s) * S_NS).astype(np.int64)
            T_odom_base = buffer.lookup_many(f.odom_frame, f.base_frame, stamps)
            return T_lidar_base @ T_odom_base0.inverse() @ T_odom_base @ T_base_lidar

        return motion


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
