"""Checks of a run through elevator rides, against the simulator's truth.

:func:`elevator_checks` scores a :class:`~tagloc.localize.run.LocalizationRun` whose stream rode
elevator cabs (its ``cab``, ``cab_moves``, ``floors`` and ``floor_changed`` events), given the
truth as plain functions of time (:class:`RideTruth`):

- in the cab with the doors closed: the published pose relative to the cab, RMS (<= 2 cm);
- on each exit: the pose in ``map`` 1 s after the first fix of a landing tag (<= 5 cm), and the
  floor published once the robot is back in the map (right on every exit);
- no floor change declared without accepted fixes of the new floor's tags;
- the fused ATE off the rides (while the floor is known; the floor, and so z, is unknown in a
  riding cab by design, so the whole run's ATE is not judged).

The checks are :class:`~tagloc.eval.summary.Check` s; :func:`apply_ride_checks` puts them in
a summary's list (the evaluation calls it when the run holds rides).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from tagloc.eval.cab_protocol import CabErrors
from tagloc.geometry import SE3
from tagloc.localize.events import EventKind
from tagloc.localize.floors import tag_ids_of
from tagloc.localize.run import LocalizationRun
from tagloc.supervise import CabState
from tagloc.units import S_NS

__all__ = [
    "Exit", "RideTruth", "apply_ride_checks", "cab_errors", "cab_truth", "elevator_checks",
    "exit_error", "exits",
]  # fmt: skip

#: Targets (issue-free names: what the elevator story promises).
CAB_RMS_M, EXIT_M, EXIT_AFTER_S = 0.02, 0.05, 1.0


@dataclass(frozen=True, slots=True)
class RideTruth:
    """The truth the checks need.

    Attributes
    ----------
    T_cab_base : callable
        ``(cab_frame, stamps_ns (N,)) -> SE3 batch``: the base in the cab's frame.
    floor_at : callable
        ``stamps_ns (N,) -> list of str or None``: the floor the robot is on (None in a cab).
    tag_floor : mapping of int to str
        The floor of each landing tag (map-frame tags with a floor).
    """

    T_cab_base: Callable[[str, np.ndarray], SE3]
    floor_at: Callable[[np.ndarray], list[str | None]]
    tag_floor: Mapping[int, str]


@dataclass(frozen=True, slots=True)
class Exit:
    """One exit from a riding cab: when the doors opened and the robot was back in the map."""

    opened_ns: int
    in_map_ns: int


def exits(run: LocalizationRun) -> list[Exit]:
    """The run's exits: an ``alighting`` after ``in_cab``, completed by ``in_map``."""
    out, opened, rode = [], None, False
    for move in run.cab_moves:
        if move.to_state is CabState.IN_CAB:
            rode = True
        elif move.to_state is CabState.ALIGHTING and rode:
            opened = move.stamp_ns
        elif move.to_state is CabState.IN_MAP and opened is not None:
            out.append(Exit(opened, move.stamp_ns))
            opened, rode = None, False
    return out


def elevator_checks(run: LocalizationRun, truth: RideTruth) -> list[tuple[str, float, str, bool]]:
    """``(name, value, target, passed)`` of each check (module docstring)."""
    checks: list[tuple[str, float, str, bool]] = []
    riding = [c for c in run.cab if c.state is CabState.IN_CAB]
    err = []
    for cab_frame in sorted({c.cab_frame for c in riding}):
        mine = [c for c in riding if c.cab_frame == cab_frame]
        stamps = np.array([c.stamp_ns for c in mine], dtype=np.int64)
        T_true = truth.T_cab_base(cab_frame, stamps)
        T_est = SE3.stack([c.T_cab_base for c in mine])
        err += list(np.linalg.norm(T_true.translation - T_est.translation, axis=1))
    rms = float(np.sqrt(np.mean(np.square(err)))) if err else math.nan
    checks.append(("in the cab: pose relative to the cab, RMS (m)", rms, f"<= {CAB_RMS_M:g}",
                   rms <= CAB_RMS_M))  # fmt: skip
    rides = exits(run)
    worst, right = _exit_errors(run, truth, rides)
    checks.append((f"exits: pose in map {EXIT_AFTER_S:g} s after the first landing fix, worst "
                   "(m)", worst, f"<= {EXIT_M:g}", worst <= EXIT_M))  # fmt: skip
    n = len(rides)
    checks.append((f"exits: floor right ({right}/{n})", float(right), f"== {n} (>= 1)",
                   n >= 1 and right == n))  # fmt: skip
    undeclared = _changes_without_landing_fixes(run, truth.tag_floor)
    checks.append(("floor changes without an accepted fix of the new floor's tags",
                   float(undeclared), "== 0", undeclared == 0))  # fmt: skip
    ate = _ate_floor_known(run)
    checks.append(("fused ATE RMSE while the floor is known (m)", ate, "<= 0.1", ate <= 0.1))
    return checks


def cab_truth(run: LocalizationRun, truth: RideTruth) -> SE3 | None:
    """The true base in the cab of each of ``run.cab``'s estimates, at its stamp (None
    without one): what :attr:`LocalizationRun.T_cab_base_truth` holds."""
    if not run.cab:
        return None
    stamps = np.array([c.stamp_ns for c in run.cab], dtype=np.int64)
    frames = np.array([c.cab_frame for c in run.cab])
    xyz, R = np.empty((len(stamps), 3)), np.empty((len(stamps), 3, 3))
    for cab_frame in sorted(set(frames.tolist())):
        mine = frames == cab_frame
        T = truth.T_cab_base(cab_frame, stamps[mine])
        xyz[mine], R[mine] = T.translation, T.rotation.matrix
    return SE3.from_trusted(R, xyz)


def cab_errors(run: LocalizationRun) -> CabErrors | None:
    """The run's estimates relative to its cabs judged against their truth, for the
    reliability protocol's cab opportunities (None for a run without cab frames; with cab
    frames but without the truth, None too: the cab's opportunities cannot be judged)."""
    if run.T_cab_base_truth is None and run.cab:
        return None
    cabs = cab_frames_of(run)
    if not cabs:
        return None
    truth = run.T_cab_base_truth if run.T_cab_base_truth is not None else SE3.identity()
    return CabErrors.of(cabs, run.cab, truth, run.fixes)


def cab_frames_of(run: LocalizationRun) -> tuple[str, ...]:
    """The cab frames of the run's tag map (its ``elevators`` metadata), and those of its
    cab estimates and fixes."""
    meta = run.metadata.get("elevators")
    listed = meta.get("cab_frames", []) if isinstance(meta, dict) else []
    found = {c.cab_frame for c in run.cab} | {a.frame for a in run.fixes if not a.in_map}
    return tuple(sorted({str(f) for f in listed} | found))


def apply_ride_checks(
    run: LocalizationRun, checks: Sequence[Any], make: Callable[..., Any]
) -> list[Any]:
    """``checks`` with the run's ride checks (``run.metadata["ride_checks"]``) appended and the
    whole run's ATE check marked not judged (``make(name, value, target, passed)`` builds a
    check)."""
    rows = run.metadata.get("ride_checks")
    if not isinstance(rows, list):
        return list(checks)
    out = []
    for c in checks:
        if c.name.startswith("fused ATE RMSE"):
            c = make(c.name, c.value, f"{c.target} (not judged: rides, floor unknown)", None)
        out.append(c)
    return out + [make(name, value, target, passed) for name, value, target, passed in rows]


def exit_error(run: LocalizationRun, truth: RideTruth, ride: Exit) -> float | None:
    """The pose error in map ``EXIT_AFTER_S`` after the exit's first landing fix the filter did
    not reject, m (inf without one; None past the run's end or without the run's truth)."""
    first = min(
        (a.stamp_ns for a in run.fixes if a.stamp_ns >= ride.opened_ns and a.tag_ids
         and a.tag_ids[0] in truth.tag_floor and not a.decision.startswith("rejected")),
        default=None,
    )  # fmt: skip
    if first is None:
        return math.inf
    stamps = np.asarray(run.stamps_ns)
    k = int(np.searchsorted(stamps, first + round(EXIT_AFTER_S * S_NS)))
    if k >= len(stamps) or run.T_map_base_truth is None:
        return None
    return float(np.linalg.norm(run.T_map_base[k].translation
                                - run.T_map_base_truth[k].translation))  # fmt: skip


def _exit_errors(
    run: LocalizationRun, truth: RideTruth, rides: list[Exit]
) -> tuple[float, int]:
    """The worst pose error in map 1 s after each exit's first landing fix; exits whose
    published floor is right once back in the map."""
    stamps = np.asarray(run.stamps_ns)
    worst, right = -math.inf, 0
    for ride in rides:
        e = exit_error(run, truth, ride)
        if e is None:
            continue
        worst = max(worst, e)
        if e == math.inf:
            continue
        j = int(np.searchsorted(stamps, ride.in_map_ns))
        if j < len(stamps) and run.floors:
            published = next((f for f in run.floors[j:] if f is not None), None)
            right += published is not None and published == truth.floor_at(stamps[j : j + 1])[0]
    return (worst if math.isfinite(worst) or worst == math.inf else math.nan), right


def _changes_without_landing_fixes(run: LocalizationRun, tag_floor: Mapping[int, str]) -> int:
    """Declared floor changes whose tags are not the new floor's, or were never accepted."""
    accepted: dict[int, int] = {}
    for a in run.fixes:
        if a.accepted:
            for i in a.tag_ids:
                accepted[i] = min(accepted.get(i, a.stamp_ns), a.stamp_ns)
    bad = 0
    for e in run.events:
        if e.kind is not EventKind.FLOOR_CHANGED:
            continue
        to = e.detail.split(" -> ", 1)[1].split(":", 1)[0] if " -> " in e.detail else ""
        ids = tag_ids_of(e.source)
        bad += not ids or any(tag_floor.get(i) != to or i not in accepted for i in ids)
    return bad


def _ate_floor_known(run: LocalizationRun) -> float:
    if run.T_map_base_truth is None or not run.floors:
        return math.nan
    keep = np.array([f is not None for f in run.floors]) & np.asarray(run.initialized)
    if not keep.any():
        return math.nan
    d = run.T_map_base.translation[keep] - run.T_map_base_truth.translation[keep]
    return float(np.sqrt(np.mean(np.sum(np.square(d), axis=1))))
