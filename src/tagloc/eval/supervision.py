"""What the supervisor and the correction's bounds did over a run: the ladder and the cap.

- :func:`ladder_summary`: time at each level of the degradation ladder and its transitions
  (from the run's ladder record and the node's metadata).
- :func:`correction_bounds`: the filter's *unclipped* estimate jumps beside the published ones,
  and how often the per-update cap or the speed limit bound a publication (the published jump
  is bounded by construction; the unclipped one shows what the bounds held back).
- :func:`ladder_steps`: the level as a step function of time, for the report's plot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tagloc.eval.trajectories import SNAP_EVENT_KINDS, correction_jumps
from tagloc.localize.run import LocalizationRun
from tagloc.supervise import Level

__all__ = [
    "CorrectionBounds",
    "LadderSummary",
    "correction_bounds",
    "ladder_steps",
    "ladder_summary",
]


@dataclass(frozen=True, slots=True)
class LadderSummary:
    """Time at each level (s, by level name) and the transitions ``(t_s, from, to, reason)``."""

    seconds_at_level: dict[str, float] = field(default_factory=dict)
    transitions: list[tuple[float, int, int, str]] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class CorrectionBounds:
    """Largest jumps of the unclipped estimate and of the published correction (m, deg), and
    the publications the cap and the speed limit clipped (``CAPPED`` events by bound)."""

    largest_unclipped_m: float
    largest_unclipped_deg: float
    largest_published_m: float
    largest_published_deg: float
    n_capped: int
    n_speed_limited: int


def ladder_summary(run: LocalizationRun) -> LadderSummary:
    ladder = run.metadata.get("ladder")
    seconds = dict(ladder.get("seconds_at_level", {})) if isinstance(ladder, dict) else {}
    t0 = int(run.stamps_ns[0]) if len(run.stamps_ns) else 0
    moves = [
        ((m.stamp_ns - t0) * 1e-9, int(m.from_level), int(m.to_level), m.reason) for m in run.ladder
    ]
    return LadderSummary(seconds, moves)


def ladder_steps(run: LocalizationRun) -> tuple[np.ndarray, np.ndarray]:
    """``(t_s, level)`` of a step plot: the level from each time on (start: the first
    transition's ``from``, or ODOMETRY_ONLY)."""
    t0 = int(run.stamps_ns[0])
    start = int(run.ladder[0].from_level) if run.ladder else int(Level.ODOMETRY_ONLY)
    t = [0.0] + [(m.stamp_ns - t0) * 1e-9 for m in run.ladder]
    level = [start] + [int(m.to_level) for m in run.ladder]
    t.append((int(run.stamps_ns[-1]) - t0) * 1e-9)
    level.append(level[-1])
    return np.asarray(t), np.asarray(level)


def correction_bounds(run: LocalizationRun) -> CorrectionBounds:
    snaps = [e.stamp_ns for e in run.events if str(e.kind) in SNAP_EVENT_KINDS]
    published = correction_jumps(
        run.stamps_ns, run.T_map_odom, run.T_odom_base, run.initialized, snaps
    )
    unclipped = (
        correction_jumps(
            run.stamps_ns, run.T_map_odom_estimate, run.T_odom_base, run.initialized, snaps
        )
        if run.T_map_odom_estimate is not None
        else None
    )
    capped = [e.detail for e in run.events if str(e.kind) == "capped"]
    n_speed = sum(d.startswith("speed limit") for d in capped)
    return CorrectionBounds(
        unclipped.largest_translation_m if unclipped else math.nan,
        unclipped.largest_rotation_deg if unclipped else math.nan,
        published.largest_translation_m, published.largest_rotation_deg,
        len(capped) - n_speed, n_speed,
    )  # fmt: skip
