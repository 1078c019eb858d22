"""The timeline of a run's elevator rides: one :class:`RideRow` per ride.

A ride is read from the handoff's moves (``run.cab_moves``): ``boarding``, then the doors closed
(``in_cab``), the doors opened (``alighting``), and out (``in_map``). A ride whose doors closed and
opened more than once before the robot left (a stop at another floor) keeps the last closing and
the last opening, the trip that let the robot out; a boarding that ends ``in_map`` without the
doors closing (walked past the cab) is no ride. Beside the node's times:

- the floor the node declared: the first published floor after the doors opened (stamped, as the
  ``floor_changed`` event is, with the first estimate that carries it);
- with the simulator's truth (:class:`~tagloc.eval.elevator.RideTruth`): the floor the robot was
  on at boarding and once out, the pose error in ``map`` 1 s after the first landing fix (as the
  ride checks compute it, :func:`~tagloc.eval.elevator.exit_error`), and the RMS of the published
  pose relative to the cab while the doors were closed.

Times are seconds after the run's first odometry row; a missing value is NaN (a floor: None).
:func:`ride_timeline` computes the rows; :func:`ride_rows` reads those the evaluation stored in the
run's metadata (``run.metadata["rides"]``), else computes them without truth.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tagloc.eval.elevator import Exit, RideTruth, exit_error
from tagloc.geometry import SE3
from tagloc.localize.run import LocalizationRun
from tagloc.supervise import CabState
from tagloc.units import S_NS

__all__ = ["RideRow", "ride_rows", "ride_timeline", "rows_to_metadata"]


@dataclass(frozen=True, slots=True)
class RideRow:
    """One ride (module docstring); times in seconds after the run's start, errors in metres."""

    cab_frame: str
    boarding_s: float
    doors_closed_s: float
    doors_open_s: float
    exit_s: float
    from_floor: str | None
    to_floor: str | None
    declared_floor: str | None
    declared_s: float
    exit_error_m: float
    cab_rms_m: float

    @property
    def floor_right(self) -> bool | None:
        """Whether the declared floor is the true one (None without truth)."""
        if self.to_floor is None:
            return None
        return self.declared_floor == self.to_floor


@dataclass(slots=True)
class _Open:
    cab_frame: str
    boarding_ns: int
    closed_ns: int | None = None
    opened_ns: int | None = None


def ride_timeline(run: LocalizationRun, truth: RideTruth | None = None) -> list[RideRow]:
    """The rides of ``run`` (module docstring), judged against ``truth`` when given."""
    if len(run.stamps_ns) == 0:
        return []
    t0 = int(run.stamps_ns[0])
    rows: list[RideRow] = []
    ride: _Open | None = None
    for move in run.cab_moves:
        if move.to_state is CabState.BOARDING and move.from_state is CabState.IN_MAP:
            ride = _Open(move.cab_frame, move.stamp_ns)
        elif ride is None:
            continue
        elif move.to_state is CabState.IN_CAB:
            ride.closed_ns = move.stamp_ns
        elif move.to_state is CabState.ALIGHTING and ride.closed_ns is not None:
            ride.opened_ns = move.stamp_ns
        elif move.to_state is CabState.IN_MAP:
            if ride.closed_ns is not None and ride.opened_ns is not None:
                rows.append(_row(run, truth, ride, move.stamp_ns, t0))
            ride = None
    return rows


def ride_rows(run: LocalizationRun) -> list[RideRow]:
    """The rows stored in ``run.metadata["rides"]`` (with truth), else :func:`ride_timeline`
    without truth (empty for a run without rides)."""
    stored = run.metadata.get("rides")
    if isinstance(stored, list):
        return [_from_dict(row) for row in stored]
    return ride_timeline(run) if run.cab_moves else []


def rows_to_metadata(rows: list[RideRow]) -> list[dict[str, object]]:
    """``rows`` as plain dicts, for ``run.metadata["rides"]``."""
    return [dataclasses.asdict(r) for r in rows]


def _from_dict(row: dict[str, Any]) -> RideRow:
    """A stored row; a null time or error (JSON's NaN) reads as NaN."""
    fields: dict[str, Any] = {
        k: math.nan if v is None and k.endswith(("_s", "_m")) else v for k, v in row.items()
    }
    return RideRow(**fields)


def _row(
    run: LocalizationRun, truth: RideTruth | None, ride: _Open, out_ns: int, t0: int
) -> RideRow:
    assert ride.closed_ns is not None and ride.opened_ns is not None
    stamps = np.asarray(run.stamps_ns, dtype=np.int64)
    declared, declared_ns = None, None
    k = int(np.searchsorted(stamps, ride.opened_ns))
    for j in range(k, len(stamps)):
        if run.floors and run.floors[j] is not None:
            declared, declared_ns = run.floors[j], int(stamps[j])
            break
    from_floor = to_floor = None
    exit_m = cab_m = math.nan
    if truth is not None:
        from_floor, to_floor = truth.floor_at(np.array([ride.boarding_ns, out_ns], dtype=np.int64))
        error = exit_error(run, truth, Exit(ride.opened_ns, out_ns))
        exit_m = math.nan if error is None else error
        cab_m = _cab_rms(run, truth, ride.cab_frame, ride.closed_ns, ride.opened_ns)

    def s(ns: int | None) -> float:
        return math.nan if ns is None else float(int(ns) - t0) / S_NS

    return RideRow(
        ride.cab_frame, s(ride.boarding_ns), s(ride.closed_ns), s(ride.opened_ns), s(out_ns),
        from_floor, to_floor, declared, s(declared_ns), exit_m, cab_m,
    )  # fmt: skip


def _cab_rms(run: LocalizationRun, truth: RideTruth, cab_frame: str, lo: int, hi: int) -> float:
    """RMS of the published position relative to the cab while the doors were closed, m."""
    mine = [c for c in run.cab if c.cab_frame == cab_frame and lo <= c.stamp_ns < hi
            and c.state is CabState.IN_CAB]  # fmt: skip
    if not mine:
        return math.nan
    T_true = truth.T_cab_base(cab_frame, np.array([c.stamp_ns for c in mine], dtype=np.int64))
    T_est = SE3.stack([c.T_cab_base for c in mine])
    err = np.linalg.norm(np.asarray(T_true.translation) - np.asarray(T_est.translation), axis=1)
    return float(np.sqrt(np.mean(np.square(err))))
