"""The supervisor's ladder: hard moves at once, quality moves after the dwell, reasons always.

Driven directly with synthetic stream times and health signals (no filter): the oracle is the
ladder's own specification (module docstring of :mod:`tagloc.supervise.ladder`).
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tagloc.supervise import (
    EstimatorState,
    FixSourceSpec,
    LadderTransition,
    Level,
    Supervisor,
    SupervisorConfig,
)

S = 1_000_000_000
GOOD = EstimatorState(True, False, 0.5, 0.2, 0.05, 1.0)


def _supervisor(**ladder: float) -> Supervisor:
    cfg = SupervisorConfig.model_validate({"ladder": ladder} if ladder else {})
    return Supervisor(cfg, [FixSourceSpec("markers", "markers", "camera")], 10.0, 5.0)


def _drive(
    sup: Supervisor, seconds: float, *, camera: bool = True, est: EstimatorState = GOOD,
    start_s: float = 0.0, fix: tuple[bool, float, float] | None = (True, 1.0, 0.3),
) -> list[LadderTransition]:  # fmt: skip
    """100 Hz odometry, 30 Hz camera (when ``camera``), one fix per camera frame."""
    moves = []
    for k in range(round(seconds * 100)):
        t = round((start_s + k / 100) * S)
        sup.on_input("odometry", t)
        if camera and k % 3 == 0:
            sup.on_input("camera", t)
            if fix is not None:
                sup.on_fix("markers", *fix)
        move = sup.step(t, est)
        if move is not None:
            moves.append(move)
    return moves


def test_markers_carry_at_level_3_and_camera_loss_is_level_4_at_the_timeout() -> None:
    sup = _supervisor()
    moves = _drive(sup, 5.0)
    assert [(m.from_level, m.to_level) for m in moves] == [
        (Level.ODOMETRY_ONLY, Level.MARKERS_ALONE)
    ]
    moves = _drive(sup, 5.0, camera=False, start_s=5.0)
    assert [(m.from_level, m.to_level) for m in moves] == [
        (Level.MARKERS_ALONE, Level.ODOMETRY_ONLY)
    ]
    # the last frame was at 4.98 s; the camera timeout is 1 s: dead from 5.98 s on (exclusive)
    assert 5.98 < moves[0].stamp_ns / S <= 6.0
    assert moves[0].hard and "camera dead" in moves[0].reason
    back = _drive(sup, 2.0, start_s=10.0)
    assert [(m.from_level, m.to_level) for m in back] == [
        (Level.ODOMETRY_ONLY, Level.MARKERS_ALONE)
    ]
    assert back[0].stamp_ns == 10 * S  # a hard fall comes back as soon as the source does


def test_stale_estimate_and_reacquisition_are_hard_reasons() -> None:
    sup = _supervisor()
    _drive(sup, 2.0)
    stale = EstimatorState(True, False, 12.0, 3.0)
    moves = _drive(sup, 0.1, est=stale, start_s=2.0)
    assert (
        moves[0].to_level is Level.ODOMETRY_ONLY and "no accepted fix for 12.0 s" in moves[0].reason
    )
    moves = _drive(sup, 0.1, est=GOOD, start_s=2.1)
    assert moves[0].to_level is Level.MARKERS_ALONE
    moves = _drive(sup, 0.1, est=EstimatorState(True, True, 0.0, 0.0), start_s=2.2)
    assert "re-acquiring" in moves[0].reason


def test_a_quality_fall_waits_for_the_dwell_and_has_hysteresis() -> None:
    sup = _supervisor(min_dwell_s=30.0, window=20)
    _drive(sup, 1.0)  # level 3 at t = 0 (the first step)
    moves = _drive(sup, 10.0, start_s=1.0, fix=(False, 50.0, 0.3))  # every fix gated
    assert moves == []  # degraded, but the dwell since the last move (t = 0) is not over
    moves = _drive(sup, 25.0, start_s=11.0, fix=(False, 50.0, 0.3))
    assert [m.to_level for m in moves] == [Level.ODOMETRY_ONLY]
    assert not moves[0].hard and "markers: degraded (mean NIS" in moves[0].reason
    assert abs(moves[0].stamp_ns / S - 30.0) < 0.02
    # acceptance back to 0.3 (above enter 0.2, below exit 0.5): stays degraded
    fixes = [(k % 10 < 3, 1.0, 0.3) for k in range(600)]
    sup2 = sup
    moved = []
    for k, fx in enumerate(fixes):
        t = round((36.0 + k / 30) * S)
        sup2.on_input("odometry", t)
        sup2.on_input("camera", t)
        sup2.on_fix("markers", *fx)
        if (m := sup2.step(t, GOOD)) is not None:
            moved.append(m)
    assert moved == []


def test_time_at_each_level_adds_up() -> None:
    sup = _supervisor()
    _drive(sup, 5.0)
    _drive(sup, 5.0, camera=False, start_s=5.0)
    seconds = sup.ladder.seconds_at_levels()
    assert math.isclose(sum(seconds.values()), 9.99, abs_tol=1e-9)
    assert math.isclose(seconds["odometry_only"], 4.0, abs_tol=0.02)


@settings(max_examples=12, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**31 - 1), p_accept=st.floats(0.05, 0.95), jitter_s=st.floats(0.0, 0.9))
def test_noisy_health_signals_move_the_ladder_at_most_twice_a_minute(
    seed: int, p_accept: float, jitter_s: float
) -> None:
    """Random acceptance, NIS and reprojection around every threshold, camera frames late by up
    to ``jitter_s`` (within the 1 s timeout): never more than 2 transitions in any 60 s, and
    every transition names a reason for each level it leaves or skips."""
    rng = np.random.default_rng(seed)
    sup = _supervisor()
    moves: list[LadderTransition] = []
    next_frame = 0.0
    for k in range(180 * 100):  # 3 minutes at 100 Hz
        t_s = k / 100
        t = round(t_s * S)
        sup.on_input("odometry", t)
        if t_s >= next_frame:
            sup.on_input("camera", t)
            sup.on_fix(
                "markers", bool(rng.random() < p_accept), float(rng.gamma(2.0, 2.0)),
                float(rng.uniform(0.2, 2.0)),
            )  # fmt: skip
            next_frame = t_s + 1 / 30 + float(rng.uniform(0, jitter_s)) * (rng.random() < 0.05)
        est = EstimatorState(True, False, float(rng.uniform(0, 9.9)), float(rng.uniform(0, 4.9)))
        if (m := sup.step(t, est)) is not None:
            moves.append(m)
    stamps = np.array([m.stamp_ns for m in moves]) / S
    for s in stamps:
        assert np.sum((stamps >= s) & (stamps < s + 60.0)) <= 2, stamps
    for m in moves:
        assert m.reason
        if m.to_level > m.from_level:  # every level left or skipped is named with its reason
            for level in range(m.from_level, m.to_level):
                assert f"{Level(level).label}: " in m.reason
