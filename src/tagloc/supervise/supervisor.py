"""The supervisor: inputs' liveness, fix sources' quality, the ladder and the status message.

Fed by the streaming node (:class:`~tagloc.localize.node.LocalizerNode`): every input message
(:meth:`Supervisor.on_input`), every fix decision (:meth:`Supervisor.on_fix`), and at each
odometry sample the estimator's state (:meth:`Supervisor.step`), which may move the ladder.
Fix sources are generic (:class:`FixSourceSpec`: a name, a role ``markers`` or ``lidar``, the
input whose liveness it needs), so a lidar source joins without changing this module.

In a building with elevators it also owns the map <-> cab handoff (:attr:`Supervisor.handoff`,
:mod:`tagloc.supervise.cab`) and the floor (:attr:`Supervisor.floors`,
:mod:`tagloc.supervise.floors`): in a cab the lidar is ignored (a hard reason: the ladder leaves
``lidar_nominal`` at once), and the status carries the floor and the handoff's state.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

from tagloc.supervise.cab import CabHandoff, CabState, ElevatorConfig
from tagloc.supervise.config import SupervisorConfig
from tagloc.supervise.floors import FloorBook
from tagloc.supervise.health import (
    FixQualityMonitor,
    InputHealth,
    Liveness,
    QualityState,
    QualityVerdict,
)
from tagloc.supervise.ladder import Ladder, LadderTransition, Level
from tagloc.units import S_NS

__all__ = ["EstimatorState", "FixSourceSpec", "StatusReport", "Supervisor"]

ODOMETRY = "odometry"


@dataclass(frozen=True, slots=True)
class FixSourceSpec:
    """A fix source as the supervisor sees it: ``role`` places it on the ladder, ``input`` is
    the stream whose liveness it needs (``camera`` for tags, ``lidar`` for scans)."""

    name: str
    role: Literal["markers", "lidar"]
    input: str


@dataclass(frozen=True, slots=True)
class EstimatorState:
    """What the supervisor needs of the estimator at a stamp.

    Attributes
    ----------
    initialized, reacquiring : bool
        The state exists; it waits for consistent fixes after a gap.
    since_fix_s, since_fix_m : float
        Stream time and travel since the last accepted fix (``inf`` before any).
    sigma_xy_m, sigma_yaw_deg : float
        1-sigma of the base's position (the larger horizontal axis) and yaw (NaN uninitialized).
    """

    initialized: bool
    reacquiring: bool
    since_fix_s: float
    since_fix_m: float
    sigma_xy_m: float = math.nan
    sigma_yaw_deg: float = math.nan


@dataclass(frozen=True, slots=True)
class StatusReport:
    """The node's status at a stamp (published at ``supervisor.status_rate_hz``)."""

    stamp_ns: int
    level: Level
    stale: bool
    estimator: EstimatorState
    inputs: dict[str, InputHealth] = field(default_factory=dict)
    sources: dict[str, QualityVerdict] = field(default_factory=dict)
    #: The floor (None: unknown, riding a cab, or a building without floors).
    floor: str | None = None
    #: The handoff's state (``in_map`` without elevators) and its cab frame ('' in the map).
    cab: CabState = CabState.IN_MAP
    cab_frame: str = ""

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (non-finite numbers as None)."""
        e = self.estimator
        return {
            "floor": self.floor, "cab": str(self.cab), "cab_frame": self.cab_frame,
            "stamp_ns": self.stamp_ns, "level": int(self.level), "level_name": self.level.label,
            "stale": self.stale, "initialized": e.initialized, "reacquiring": e.reacquiring,
            "since_fix_s": _num(e.since_fix_s), "since_fix_m": _num(e.since_fix_m),
            "sigma_xy_m": _num(e.sigma_xy_m), "sigma_yaw_deg": _num(e.sigma_yaw_deg),
            "inputs": {
                k: {"alive": v.alive, "age_s": _num(v.age_s), "rate_hz": _num(v.rate_hz),
                    "expected_rate_hz": v.expected_rate_hz, "gaps": v.gaps, "count": v.count}
                for k, v in self.inputs.items()
            },
            "sources": {
                k: {"state": str(v.state), "offered": v.offered, "accepted": v.accepted,
                    "acceptance": _num(v.acceptance), "mean_nis": _num(v.mean_nis),
                    "mean_reproj_px": _num(v.mean_reproj_px), "reason": v.reason}
                for k, v in self.sources.items()
            },
        }  # fmt: skip


def _num(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


class Supervisor:
    """Health, ladder and status (module docstring).

    Parameters
    ----------
    config : SupervisorConfig
    sources : sequence of FixSourceSpec
    gap_s, gap_m : float
        An estimate with no accepted fix for longer (or farther) is stale: nothing carries it.
    elevators : ElevatorConfig, optional
        With it, :attr:`handoff` is the map <-> cab handoff (None: no cab).
    floor_heights_m : mapping of str to float, optional
        The floors (name -> height in ``map``, m); with them :attr:`floors` books the floor.
    """

    def __init__(
        self, config: SupervisorConfig, sources: Sequence[FixSourceSpec], gap_s: float,
        gap_m: float, elevators: ElevatorConfig | None = None,
        floor_heights_m: dict[str, float] | None = None,
    ) -> None:  # fmt: skip
        self.config = config
        self.handoff = None if elevators is None else CabHandoff(elevators)
        self.floors = (
            FloorBook(floor_heights_m, elevators.floor_confirm_fixes, elevators.floor_change_fixes)
            if elevators is not None and floor_heights_m
            else None
        )
        self.sources = {s.name: s for s in sources}
        lad = config.ladder
        odo = config.odometry
        self._inputs = {ODOMETRY: Liveness(odo.timeout_s, odo.expected_rate_hz)}
        for s in sources:
            if s.input not in self._inputs:
                h = config.camera if s.role == "markers" else config.lidar
                self._inputs[s.input] = Liveness(h.timeout_s, h.expected_rate_hz)
        self._quality = {
            s.name: FixQualityMonitor(
                lad.window, lad.enter_acceptance, lad.exit_acceptance, lad.enter_nis,
                lad.exit_nis, lad.enter_reproj_px, lad.exit_reproj_px,
            )
            for s in sources
        }  # fmt: skip
        self.ladder = Ladder(lad.min_dwell_s)
        self._gap_s, self._gap_m = gap_s, gap_m
        self._status_ns = round(S_NS / config.status_rate_hz)
        self._next_status: int | None = None
        self._was_alive: dict[str, bool] = {}

    @property
    def level(self) -> Level:
        return self.ladder.level

    # ----- inputs ----------------------------------------------------------------------------
    def on_input(self, name: str, stamp_ns: int) -> None:
        """A message of input ``name`` (``odometry``, ``camera``, ...) stamped ``stamp_ns``."""
        live = self._inputs.get(name)
        if live is not None:
            live.arrived(stamp_ns)

    def on_fix(self, source: str, accepted: bool, nis_per_dof: float, reproj_px: float) -> None:
        """A fix of ``source`` decided by the filter (NaN where a number is unknown)."""
        monitor = self._quality.get(source)
        if monitor is not None:
            monitor.add(accepted, nis_per_dof, reproj_px)

    # ----- per odometry sample ---------------------------------------------------------------
    def clock_jumped(self, stamp_ns: int) -> None:
        """The stream's clock jumped back to ``stamp_ns``: forget arrival times and quality (the
        ladder keeps its level and totals; the next :meth:`step` judges afresh)."""
        for live in self._inputs.values():
            live.restart()
        for q in self._quality.values():
            q.clear()
        self._was_alive.clear()
        self._next_status = None
        self.ladder.restart(stamp_ns)

    def step(
        self, stamp_ns: int, estimator: EstimatorState, reason: str = ""
    ) -> LadderTransition | None:
        """Judge every level at ``stamp_ns``; return the ladder's move, if any. ``reason``: an
        event that makes every level unavailable now (a hard reason, e.g. a clock jump)."""
        for name, live in self._inputs.items():  # a dead input's old quality says nothing
            alive = live.alive(stamp_ns)
            if self._was_alive.get(name, False) and not alive:
                for s in self.sources.values():
                    if s.input == name:
                        self._quality[s.name].clear()
            self._was_alive[name] = alive
        unmet, hard = self._unmet(stamp_ns, estimator)
        if reason:
            for table in (unmet, hard):
                for level in table:
                    table[level] = [reason, *table[level]]
        return self.ladder.step(stamp_ns, unmet, hard)

    def status_due(self, stamp_ns: int) -> bool:
        """Whether a status message is due at ``stamp_ns`` (the configured rate)."""
        if self._next_status is None or stamp_ns >= self._next_status:
            self._next_status = stamp_ns + self._status_ns
            return True
        return False

    def status(self, stamp_ns: int, estimator: EstimatorState) -> StatusReport:
        handoff, floors = self.handoff, self.floors
        return StatusReport(
            stamp_ns, self.level, self.level is Level.ODOMETRY_ONLY, estimator,
            {k: v.report(stamp_ns) for k, v in self._inputs.items()},
            {k: v.verdict() for k, v in self._quality.items()},
            floors.floor if floors is not None and floors.known else None,
            CabState.IN_MAP if handoff is None else handoff.state,
            "" if handoff is None else handoff.cab_frame,
        )  # fmt: skip

    def _unmet(
        self, stamp_ns: int, est: EstimatorState
    ) -> tuple[dict[Level, list[str]], dict[Level, list[str]]]:
        """Why each of levels 1-3 is unavailable: all reasons, and the hard ones only."""
        common: list[str] = []
        odom = self._inputs[ODOMETRY]
        if not odom.alive(stamp_ns):
            common.append(f"odometry dead ({_age(odom, stamp_ns)})")
        if not est.initialized:
            common.append("no estimate yet")
        elif est.reacquiring:
            common.append("re-acquiring after a gap")
        elif est.since_fix_s > self._gap_s or est.since_fix_m > self._gap_m:
            common.append(
                f"no accepted fix for {est.since_fix_s:.1f} s / {est.since_fix_m:.1f} m "
                f"(gap {self._gap_s:g} s / {self._gap_m:g} m)"
            )
        hard_by_role: dict[str, list[str]] = {"markers": [], "lidar": []}
        soft_by_role: dict[str, list[str]] = {"markers": [], "lidar": []}
        usable = {"markers": False, "lidar": False}
        alive_any = {"markers": False, "lidar": False}
        for s in self.sources.values():
            live = self._inputs[s.input]
            if not live.alive(stamp_ns):
                hard_by_role[s.role].append(f"{s.name}: {s.input} dead ({_age(live, stamp_ns)})")
                continue
            alive_any[s.role] = True
            q = self._quality[s.name]
            if q.state is QualityState.DEGRADED:
                soft_by_role[s.role].append(f"{s.name}: degraded ({q.reason})")
            else:
                usable[s.role] = True
        for role in ("markers", "lidar"):
            if not any(s.role == role for s in self.sources.values()):
                hard_by_role[role].append(f"no {role} source")
        if self.handoff is not None and self.handoff.state.in_cab:  # the cab's walls move
            usable["lidar"] = alive_any["lidar"] = False
            hard_by_role["lidar"].append(f"lidar ignored in the cab ({self.handoff.state})")

        def reasons(role: str, *, hard_only: bool) -> list[str]:
            if usable[role]:
                return []
            if hard_only:
                return [] if alive_any[role] else hard_by_role[role]
            return hard_by_role[role] + soft_by_role[role]

        # level 2 needs a lidar that is alive (degraded: else level 1 applies first)
        no_lidar = [] if alive_any["lidar"] else ["no lidar alive"]
        all_unmet: dict[Level, list[str]] = {}
        hard_unmet: dict[Level, list[str]] = {}
        for hard_only, out in ((False, all_unmet), (True, hard_unmet)):
            markers = reasons("markers", hard_only=hard_only)
            out[Level.LIDAR_NOMINAL] = common + reasons("lidar", hard_only=hard_only)
            out[Level.MARKERS_CARRY] = common + markers + no_lidar
            out[Level.MARKERS_ALONE] = common + markers
        return all_unmet, hard_unmet


def _age(live: Liveness, stamp_ns: int) -> str:
    if live.last_ns is None:
        return "never seen"
    return f"silent {(stamp_ns - live.last_ns) / S_NS:.1f} s > {live.timeout_ns / S_NS:g} s"
