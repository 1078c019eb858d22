"""The cab's estimate starts at boarding from the cab's placement, against the simulator's truth.

The elevator scenario boards the tower's cab at 56.7 s and again at 121.4 s (seed 0). The first
ride places the cab in the floor's frame; at the second boarding the cab's only tag is 2.6 m
away, too far for its pose's two IPPE branches to be told apart, so the cab's tags alone start
the cab's estimate 3.5 s after boarding (once near). Started from the map estimate composed with
the cab's placement, the estimate exists at boarding and is within 5 cm of the simulator's base
relative to the cab. A wrong placement (shifted 30 cm) must not outlive the cab's near tags.
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.eval.scenarios import run_scenario
from tagloc.geometry import SE3
from tagloc.localize.ride_anchor import CabPlacement
from tagloc.localize.run import LocalizationRun
from tagloc.supervise import CabState
from tagloc.units import S_NS

DURATION_S = 128.0  # two boardings; the second one's cab tag is near from 125 s
START_S = 0.5  # the cab's estimate exists within this long after boarding
START_TOL_M = 0.05


def _boardings(run: LocalizationRun) -> list[int]:
    return [m.stamp_ns for m in run.cab_moves if m.to_state is CabState.BOARDING]


def _errors(run: LocalizationRun, start_ns: int, end_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (s after ``start_ns``) and errors (m) of the cab estimates between the stamps."""
    assert run.T_cab_base_truth is not None
    rows = [i for i, c in enumerate(run.cab) if start_ns <= c.stamp_ns <= end_ns]
    err = [
        float(np.linalg.norm((run.T_cab_base_truth[i].inverse() @ run.cab[i].T_cab_base)
                             .translation))
        for i in rows
    ]  # fmt: skip
    stamps = np.array([(run.cab[i].stamp_ns - start_ns) / S_NS for i in rows])
    return stamps, np.array(err)


def test_the_cab_estimate_exists_at_boarding_and_is_within_5_cm() -> None:
    run = run_scenario("elevator", 0, DURATION_S, lidar=False)
    boardings = _boardings(run)
    assert len(boardings) == 2
    stamps, err = _errors(run, boardings[1], boardings[1] + S_NS)
    assert len(stamps) > 50 and stamps[0] <= START_S, stamps[:1]
    assert err.max() <= START_TOL_M, f"{100 * err.max():.1f} cm"


def test_a_wrong_cab_placement_gives_way_to_the_cab_tags(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every boarding's measurement of the cab's pose shifted by 30 cm (a fault): the start is
    wrong, but the cab's near tags, not the placement, decide the pose in the cab."""
    add = CabPlacement.add
    shift = SE3.from_rotvec(np.zeros(3), np.array([0.3, 0.0, 0.0]))

    def wrong(self: CabPlacement, T_floor_cab: SE3, cov: np.ndarray) -> None:
        add(self, T_floor_cab @ shift, cov)

    monkeypatch.setattr(CabPlacement, "add", wrong)
    run = run_scenario("elevator", 0, DURATION_S, lidar=False)
    boardings = _boardings(run)
    assert len(boardings) == 2
    stamps, err = _errors(run, boardings[1], boardings[1] + 20 * S_NS)
    assert err[0] >= 0.2  # the start is the wrong placement's (the check can fail)
    near = stamps >= 4.0  # the cab's tag within 1 m from 3.5 s on
    assert near.any() and err[near].max() <= START_TOL_M, f"{100 * err[near].max():.1f} cm"
