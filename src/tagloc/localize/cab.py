"""Localization through an elevator ride: the cab's estimate, the handoff's inputs, the floor.

:class:`Elevators` is the node's component for buildings with elevator cabs or several floors
(built by :meth:`Elevators.build` when the tag map has tags in a cab frame or a floor table;
otherwise the node runs as before). The decisions are the supervisor's
(:mod:`tagloc.supervise.cab`: the handoff, :mod:`tagloc.supervise.floors`: the floor); this
module feeds them and does what they decide:

- every camera frame's known tags feed the handoff (cab tags, map-frame tags); the building's
  door topic (``ElevatorStateMsg``) too, where there is one;
- the cab's tags (posed in their cab frame) give fixes of ``T_<cab>_base`` (a second fiducial fix
  source) decided by a second :class:`~tagloc.localize.filter.MapOdomFilter` whose map frame is
  the cab: the same gates, start-up, gaps, kidnap test and capped publication. It starts afresh
  at each cab's first sighting and is dropped when the robot is back in the map; while the
  handoff is not ``in_map`` its ``<cab_frame> -> odom`` is published as a
  :class:`~tagloc.localize.run.CabEstimate` at each odometry sample;
- the doors closing on a ride make the floor unknown: the published pose in ``map`` keeps x, y
  and yaw (a shaft is vertical) and its z variance is inflated by
  ``elevators.unknown_floor_sigma_m``; the lidar is ignored (its ``in_cab`` rule, and the
  supervisor's ladder, which walks to ``markers_alone`` with the cab's tags carrying);
- every fix the ``map -> odom`` filter accepts feeds the floor book; the floor it gives (the
  landing's tags after a ride) moves the filter's floor frame (:mod:`tagloc.localize.floors`)
  and is declared as a ``floor_changed`` event stamped at the first estimate that carries it;
- the handoff's moves carry the pose in ``map`` through the ride (:mod:`~.ride_anchor`).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from tagloc.camera import CameraModel
from tagloc.errors import TransformLookupError
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.cab_start import CabStart
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.events import APPLIED, EventKind, FilterEvent
from tagloc.localize.fiducial import E_Z, FiducialConfig, FiducialFixSource, SourcedFix
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import LocalizeError
from tagloc.localize.floors import FloorFrame, floor_table, tag_ids_of
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.ride_anchor import RideAnchor
from tagloc.localize.run import CabEstimate
from tagloc.supervise import CabState, CabTransition, EstimatorState, FloorChange, Supervisor
from tagloc.tags import TagDetection, TagMap
from tagloc.units import S_NS

__all__ = ["Elevators", "check_cab_frames"]

logger = logging.getLogger(__name__)


def check_cab_frames(tag_map: TagMap, config: LocalizerConfig) -> tuple[str, ...]:
    """The cab frames of ``tag_map`` (those holding tags).

    Raises
    ------
    LocalizeError
        One line, if the map has tags in a frame that is neither the map frame nor one of
        ``elevators.cab_frames``.
    """
    known = config.elevators.cab_frames
    used = [f for f in tag_map.frames if f != config.frames.map_frame and tag_map.in_frame(f)]
    unknown = [f for f in used if f not in known]
    if unknown:
        raise LocalizeError(
            f"the tag map has tags in frame {unknown[0]!r}, which the configuration does not "
            f"know as a cab (elevators.cab_frames: {', '.join(known) or 'none'})"
        )
    return tuple(used)


class Elevators:
    """The node's elevator component (module docstring); see :meth:`build`."""

    def __init__(
        self, tag_map: TagMap, config: LocalizerConfig, supervisor: Supervisor,
        floors: FloorFrame, cab_frames: tuple[str, ...], emit: Callable[[NodeOutput], None],
        main: Callable[[], MapOdomFilter] | None = None,
    ) -> None:  # fmt: skip
        self._tag_map, self._config, self._supervisor = tag_map, config, supervisor
        self.floors, self.cab_frames, self._emit = floors, cab_frames, emit
        family, map_frame = config.tags.family, config.frames.map_frame
        self._frame_of = {t.id: t.frame for t in tag_map if t.family == family}
        self._main = main
        on_map = {t.id: np.array(t.position, dtype=np.float64) for t in tag_map
                  if t.family == family and t.frame == map_frame}  # fmt: skip
        self.anchor = RideAnchor(config.elevators, on_map)
        self._map_frame = map_frame
        self._cab: MapOdomFilter | None = None
        self._cab_frame = ""
        self._cab_sources: dict[str, FiducialFixSource] = {}
        self._cab_fix: tuple[int, float] | None = None  # last accepted cab fix: stamp, odometer
        self._start = CabStart(config.elevators)  # the cab's estimate's start (at boarding)
        self._odometer_m = 0.0
        self._pending: FloorChange | None = None  # declared at the next estimate
        self._cov: tuple[int, np.ndarray] | None = None
        self._step_ns = round(config.process_noise.motion_step_s * S_NS)
        self.cab_fixes = {"offered": 0, "accepted": 0}
        self.rides = 0
        #: Hears each cab fix with its decision (the node's ``FixDecisions.record``).
        self.on_fix: Callable[[str, SourcedFix, FilterEvent, MapOdomFilter], None] | None = None

    @classmethod
    def build(
        cls, tag_map: TagMap, config: LocalizerConfig, supervisor: Supervisor,
        floors: FloorFrame | None, emit: Callable[[NodeOutput], None],
        main: Callable[[], MapOdomFilter] | None = None,
    ) -> Elevators | None:  # fmt: skip
        """The component, or None for a building without cab tags and floors; ``main`` gives
        the node's ``map -> odom`` filter (what a ride carries the pose into). Raises
        ``LocalizeError`` as :func:`check_cab_frames`."""
        cabs = check_cab_frames(tag_map, config)
        if not cabs and floors is None:
            return None
        frame = floors or FloorFrame({}, {})
        return cls(tag_map, config, supervisor, frame, cabs, emit, main)

    @staticmethod
    def floor_frame(tag_map: TagMap, config: LocalizerConfig) -> FloorFrame | None:
        """The floor frame of a map with a floor table (None without one)."""
        heights, tags = floor_table(tag_map, config.tags.family)
        return FloorFrame(heights, tags) if heights else None

    # ----- inputs ----------------------------------------------------------------------------
    def door(self, stamp_ns: int, cab_frame: str, door_open: bool) -> None:
        """The building's door state of a cab (its ``ElevatorStateMsg``)."""
        handoff = self._supervisor.handoff
        if handoff is not None:
            self._moved(handoff.door(stamp_ns, cab_frame, door_open))

    def odometry(self, stamp_ns: int, odometer_m: float, buffer: TransformBuffer) -> None:
        """An odometry sample (after the buffer holds it, before its estimate)."""
        self._odometer_m = odometer_m
        handoff = self._supervisor.handoff
        if handoff is not None:
            self._moved(handoff.odometry(stamp_ns, odometer_m))
        cab = self._cab
        if cab is None:
            return
        cab.predict(stamp_ns)
        if cab.initialized and handoff is not None and handoff.state.in_cab:
            self._emit(self._cab_estimate(cab, stamp_ns, buffer))
        book = self._supervisor.floors
        boarding = handoff is not None and handoff.state is CabState.BOARDING
        known = book is None or book.known
        if boarding and self._main is not None and known and not self._start.resting:
            self.anchor.observe(stamp_ns, self._main(), cab, self.floors)  # the cab's pose

    def frame(
        self, stamp_ns: int, detections: tuple[TagDetection, ...], buffer: TransformBuffer,
        camera: CameraModel | None, T_base_cam: SE3 | None,
    ) -> None:  # fmt: skip
        """One camera frame's tags (when the odometry covers it): the handoff's input, and the
        cab's fixes."""
        frames = {self._frame_of.get(d.tag_id) for d in detections if d.family == self._family}
        cabs = frozenset(f for f in frames if f in self.cab_frames)
        handoff = self._supervisor.handoff
        if handoff is not None:
            self._moved(handoff.frame(stamp_ns, cabs, self._map_frame in frames))
        if not cabs or camera is None or T_base_cam is None:
            return
        cab_frame = handoff.cab_frame if handoff is not None and handoff.cab_frame else min(cabs)
        if cab_frame not in cabs:
            return
        self._cab_fixes(stamp_ns, detections, cab_frame, buffer, camera, T_base_cam)

    def filter_event(self, event: FilterEvent) -> None:
        """An event of the ``map -> odom`` filter: accepted fixes feed the floor book."""
        book = self._supervisor.floors
        if book is None or event.kind.value not in APPLIED:
            return
        for tag_id in tag_ids_of(event.source):
            floor = self.floors.tag_floor.get(tag_id)
            if floor is None:
                continue
            change = book.accepted(event.stamp_ns, floor, tag_id)
            if change is not None:
                self.floors.height_m = book.height_m
                self._pending = change

    # ----- outputs ---------------------------------------------------------------------------
    def estimate(self, estimate: Estimate) -> Estimate:
        """The node's estimate with its floor (and z variance while unknown); a floor change
        decided since the last one is declared first, stamped with it."""
        book = self._supervisor.floors
        if book is None:
            return estimate
        if self._pending is not None:
            self._declare(self._pending, estimate.stamp_ns)
            self._pending = None
        if book.known:
            return _replace(estimate, floor=book.floor)
        cov = estimate.cov_map_base
        if cov is not None:
            cov = cov.copy()
            cov[2, 2] += self._config.elevators.unknown_floor_sigma_m**2
        return _replace(estimate, floor=None, cov_map_base=cov)

    def estimator_state(self, state: EstimatorState, stamp_ns: int) -> EstimatorState:
        """What the ladder judges: in a cab (boarding, riding, alighting) the cab's estimate
        once it exists (its tags carry it), else the map's."""
        handoff, cab = self._supervisor.handoff, self._cab
        if handoff is None or not handoff.state.in_cab or cab is None or not cab.initialized:
            return state
        last = self._cab_fix
        since_s = np.inf if last is None else (stamp_ns - last[0]) / S_NS
        since_m = np.inf if last is None else self._odometer_m - last[1]
        return EstimatorState(cab.initialized, cab.reacquiring, float(since_s), float(since_m))

    def reset(self) -> None:
        """The clock jumped back: the cab's estimate (on the old buffer) is dropped."""
        self._cab, self._cab_fix, self._cov, self._pending = None, None, None, None
        self._cab_sources.clear()
        if self._supervisor.handoff is not None:
            self._supervisor.handoff.restart()

    def metadata(self) -> dict[str, Any]:
        book, handoff = self._supervisor.floors, self._supervisor.handoff
        return {"elevators": {
            "cab_frames": list(self.cab_frames), "rides": self.rides,
            "handoff_transitions": 0 if handoff is None else handoff.transitions,
            "floor": None if book is None else book.floor,
            "floor_changes": 0 if book is None else book.changes, "cab_fixes": self.cab_fixes,
            "carried_exits": self.anchor.anchored,
        }}  # fmt: skip

    # ----- internals -------------------------------------------------------------------------
    @property
    def _family(self) -> str:
        return self._config.tags.family

    def _moved(self, move: CabTransition | None) -> None:
        if move is None:
            return
        self._emit(move)
        book = self._supervisor.floors
        if self._main is not None and self._cab is not None:  # the pose carried by the cab
            known = book is None or book.known
            self.anchor.moved(move, self._main(), self._cab, self.floors, known)
        if move.to_state is CabState.IN_CAB:
            self.rides += move.from_state is CabState.BOARDING
            if book is not None:
                book.lose()
        elif move.to_state is CabState.IN_MAP:
            self._cab, self._cab_frame, self._cab_fix = None, "", None

    def _cab_fixes(
        self, stamp_ns: int, detections: tuple[TagDetection, ...], cab_frame: str,
        buffer: TransformBuffer, camera: CameraModel, T_base_cam: SE3,
    ) -> None:  # fmt: skip
        new = self._cab is None or self._cab_frame != cab_frame
        if new:
            cfg = self._config
            frames = cfg.frames.model_copy(update={"map_frame": cab_frame})
            self._cab = MapOdomFilter.from_config(cfg.model_copy(update={"frames": frames}), buffer)
            self._cab.events.listeners.append(self._cab_event)
            self._cab_frame, self._cab_fix = cab_frame, None
            self._start = CabStart(cfg.elevators)
            logger.info("%d estimating the pose in %s", stamp_ns, cab_frame)
        cab = self._cab
        assert cab is not None
        source = self._cab_sources.get(cab_frame)
        if source is None:
            source = self._cab_sources[cab_frame] = _fiducial(
                self._config, camera, T_base_cam, self._tag_map, cab_frame
            )
        book = self._supervisor.floors
        if self._main is not None and (book is None or book.known):
            started = self._start.start(stamp_ns, cab, self._main(), self.anchor, self.floors,
                                        source, self._odometer_m)  # fmt: skip
            if started:
                self._cab_fix = None  # a start, not a fix (the ladder counts fixes)
        prior = None
        if cab.initialized:
            try:
                prior = cab.T_map_base_at(stamp_ns)
            except TransformLookupError:
                prior = None
        for sourced in source.frame_fixes(stamp_ns, detections, prior).fixes:
            self.cab_fixes["offered"] += 1
            sourced = self._start.weigh(sourced, self._odometer_m)
            event = cab.update(sourced.fix)
            if self.on_fix is not None:
                self.on_fix(cab_frame, sourced, event, cab)

    def _cab_event(self, event: FilterEvent) -> None:
        """An event of the cab's filter: the last applied fix, for the ladder."""
        if event.kind.value in APPLIED:
            self.cab_fixes["accepted"] += event.kind is EventKind.ACCEPTED
            last = event.stamp_ns if self._cab_fix is None else self._cab_fix[0]
            self._cab_fix = (max(last, event.stamp_ns), self._odometer_m)

    def _cab_estimate(
        self, cab: MapOdomFilter, stamp_ns: int, buffer: TransformBuffer
    ) -> CabEstimate:
        f = self._config.frames
        T_odom_base = buffer.lookup(f.odom_frame, f.base_frame, stamp_ns)
        if self._cov is None or stamp_ns - self._cov[0] >= self._step_ns:
            self._cov = (stamp_ns, cab.pose_at(stamp_ns).cov)
        handoff = self._supervisor.handoff
        state = CabState.IN_MAP if handoff is None else handoff.state
        return CabEstimate(stamp_ns, self._cab_frame, cab.correction_at(stamp_ns), T_odom_base,
                           self._cov[1], state)  # fmt: skip

    def _declare(self, change: FloorChange, stamp_ns: int) -> None:
        tags = "+".join(f"tag:{i}" for i in change.tag_ids)
        detail = (
            f"floor {change.from_floor} -> {change.to_floor}: map -> odom z {change.dz_m:+.3f} m "
            f"(declared; {change.reason})"
        )
        self._emit(FilterEvent(stamp_ns, EventKind.FLOOR_CHANGED, tags, detail=detail))


def _replace(estimate: Estimate, **changes: Any) -> Estimate:
    return dataclasses.replace(estimate, **changes)


def _fiducial(
    config: LocalizerConfig, camera: CameraModel, T_base_cam: SE3, tag_map: TagMap, frame: str
) -> FiducialFixSource:
    """The fiducial fix source of ``frame``'s tags, configured as the node's tag source is."""
    tags = config.tags
    fid = FiducialConfig(
        cov_scale=tags.cov_scale, min_cov_translation_m=tags.min_cov_translation_m,
        min_cov_rotation_rad=tags.min_cov_rotation_rad, mode=tags.mode,
        prior_rotation_sigma_rad=tags.prior_rotation_sigma_rad,
        ambiguity_log_odds_with_prior=tags.ambiguity_log_odds_with_prior,
        shared_quad_px=tags.shared_quad_px,
    )  # fmt: skip
    return FiducialFixSource(
        camera, T_base_cam, tag_map, family=tags.family, gates=config.gates.observation_gates(),
        noise=tags.noise, config=fid, map_frame=frame,
        up_base=E_Z if config.odometry_frame.knows_up else None,
    )  # fmt: skip
