"""The report's timeline of elevator rides (:mod:`tagloc.eval.rides`): one table row per ride."""

from __future__ import annotations

import math
from collections.abc import Sequence

from tagloc.eval.elevator import CAB_RMS_M, EXIT_AFTER_S, EXIT_M
from tagloc.eval.report_style import table
from tagloc.eval.rides import RideRow

__all__ = ["rides_section"]

HEADER = [
    "ride", "boarding (s)", "doors closed (s)", "doors open (s)", "out (s)", "floor",
    "declared", "declared at (s)", f"pose in map {EXIT_AFTER_S:g} s after the first landing fix "
    "(m)", "in the cab, RMS (m)",
]  # fmt: skip


def rides_section(rows: Sequence[RideRow]) -> str:
    """The section's HTML (empty for a run without rides)."""
    if not rows:
        return ""
    body, classes = [], []
    for i, r in enumerate(rows, 1):
        floor = f"{r.from_floor or '?'} -> {r.to_floor or '?'}"
        body.append([i, r.boarding_s, r.doors_closed_s, r.doors_open_s, r.exit_s, floor,
                     r.declared_floor, r.declared_s, r.exit_error_m, r.cab_rms_m])  # fmt: skip
        classes.append(_row_class(r))
    note = (
        "<p>Times after the run's start, from the handoff's moves (boarding, doors closed: "
        "<code>in_cab</code>, doors open: <code>alighting</code>, out: <code>in_map</code>); the "
        "floor from -> to is the simulator's; declared: the first floor the node published after "
        f"the doors opened. Targets: the pose in map <= {EXIT_M:g} m, in the cab <= "
        f"{CAB_RMS_M:g} m RMS, the declared floor the true one.</p>"
    )
    return "<h2>Rides</h2>" + table(HEADER, body, classes) + note


def _row_class(r: RideRow) -> str:
    """``pass`` when the floor is right and both errors within their targets, ``fail`` when
    one is not, ``unknown`` without truth or past the run's end."""
    if r.floor_right is None or math.isnan(r.exit_error_m):
        return "unknown"
    ok = r.floor_right and r.exit_error_m <= EXIT_M and not r.cab_rms_m > CAB_RMS_M
    return "pass" if ok else "fail"
