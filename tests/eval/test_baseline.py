"""The naive snap-to-every-fix baseline, against hand-built runs with known answers.

Oracle: when the odometry is the truth seen from a constant offset ``T_odom_map`` and every fix
is the truth, the snapped correction must be exactly ``T_odom_map^-1`` from the first fix on
(and the identity before it), whatever the fix stamps (also between odometry samples).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tagloc.eval.summary import evaluate
from tagloc.eval.trajectories import baseline_jumps
from tagloc.geometry import SE3
from tagloc.localize.baseline import naive_snap_baseline, offered_single_tag_fixes
from tagloc.localize.fix import LocalizeError
from tagloc.localize.run import FixAttempt, LocalizationRun

DT_NS = 10_000_000
N = 500


def _truth() -> SE3:
    """A curving path: x forward at 0.5 m/s, yaw turning at 0.2 rad/s."""
    t_s = np.arange(N) * DT_NS * 1e-9
    rotvec = np.zeros((N, 3))
    rotvec[:, 2] = 0.2 * t_s
    xyz = np.c_[0.5 * t_s, 0.1 * t_s**2, np.zeros(N)]
    return SE3.from_rotvec(rotvec, xyz)


def _truth_at(stamp_ns: int) -> SE3:
    """The same path evaluated at any stamp (for fixes between odometry samples)."""
    t_s = stamp_ns * 1e-9
    return SE3.from_rotvec([0.0, 0.0, 0.2 * t_s], [0.5 * t_s, 0.1 * t_s**2, 0.0])


def _fix(
    stamp_ns: int,
    T_map_base: SE3,
    decision: str = "accepted",
    *,
    source: str = "tag:3",
    false: bool | None = False,
) -> FixAttempt:
    return FixAttempt(stamp_ns, source, (3,), T_map_base, np.eye(6) * 1e-4, decision, 2.0,
                      0.1, false)  # fmt: skip


T_odom_map = SE3.from_rotvec([0.0, 0.0, 0.3], [1.0, -2.0, 0.0])
STAMPS = np.arange(N, dtype=np.int64) * DT_NS


def test_snaps_to_truth_give_the_offset_exactly() -> None:
    truth = _truth()
    T_odom_base = T_odom_map @ truth
    # fixes on and between odometry stamps; interpolation of a constant-rate turn is exact only
    # on the rotation, so keep the between-stamp fixes on a straight segment: use on-stamp ones
    # for the curve and check between-stamp ones separately below
    fixes = [_fix(int(s), _truth_at(int(s))) for s in STAMPS[100::50]]
    result = naive_snap_baseline(STAMPS, T_odom_base, fixes)
    assert not result.initialized[:100].any() and result.initialized[100:].all()
    M_expected = np.asarray(T_odom_map.inverse().as_matrix())
    M_published = np.asarray(result.T_map_odom.as_matrix())
    np.testing.assert_allclose(M_published[100:], np.broadcast_to(M_expected, (N - 100, 4, 4)),
                               atol=1e-9)  # fmt: skip
    np.testing.assert_allclose(M_published[:100], np.broadcast_to(np.eye(4), (100, 4, 4)))
    np.testing.assert_allclose(
        np.asarray(result.T_map_base.translation)[100:], np.asarray(truth.translation)[100:],
        atol=1e-9,
    )  # fmt: skip
    assert len(result.snaps) == len(fixes) and result.false_fixes_accepted == 0


def test_fix_between_odometry_samples_uses_interpolated_odometry() -> None:
    # straight line, constant heading: linear interpolation of the odometry is exact
    xyz = np.c_[0.5 * STAMPS * 1e-9, np.zeros(N), np.zeros(N)]
    truth = SE3.from_rotvec(np.zeros((N, 3)), xyz)
    T_odom_base = T_odom_map @ truth
    stamp = int(STAMPS[200]) + 3_000_000  # 3 ms after an odometry sample
    fix = _fix(stamp, SE3.from_rotvec(np.zeros(3), [0.5 * stamp * 1e-9, 0.0, 0.0]))
    result = naive_snap_baseline(STAMPS, T_odom_base, [fix])
    assert (
        int(result.snap_rows[0]) == 201 and result.initialized[201] and not result.initialized[200]
    )
    np.testing.assert_allclose(
        np.asarray(result.T_map_odom[300].as_matrix()),
        np.asarray(T_odom_map.inverse().as_matrix()),
        atol=1e-9,
    )


def test_only_offered_single_tag_fixes_are_used_and_false_ones_counted() -> None:
    truth = _truth()
    wrong = _truth_at(int(STAMPS[300])) @ SE3.from_rotvec([0, 0, 0], [0.0, 0.7, 0.0])
    fixes = [
        _fix(int(STAMPS[100]), _truth_at(int(STAMPS[100]))),
        _fix(int(STAMPS[150]), wrong, "rejected:reprojection"),  # never offered
        _fix(int(STAMPS[200]), wrong, source="tags:3,4"),  # joint PnP: not a single tag
        _fix(int(STAMPS[250]), _truth_at(int(STAMPS[250])), "gated_chi2"),  # offered, gated
        _fix(int(STAMPS[300]), wrong, "gated_chi2", false=True),  # a glint: the filter gated it
    ]
    assert [a.stamp_ns for a in offered_single_tag_fixes(fixes)] == [
        int(STAMPS[i]) for i in (100, 250, 300)
    ]
    result = naive_snap_baseline(STAMPS, truth, fixes)  # odometry = truth
    assert result.false_fixes_accepted == 1
    error_m = np.linalg.norm(
        np.asarray(result.T_map_base.translation) - np.asarray(truth.translation), axis=1
    )
    assert error_m[299] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(error_m[300:], 0.7, atol=1e-9)  # held after the false snap
    run = LocalizationRun("synthetic", STAMPS, truth, SE3.identity(N), np.zeros((N, 6, 6)),
                          np.ones(N, dtype=bool), T_map_base_truth=truth, fixes=fixes)  # fmt: skip
    jumps = baseline_jumps(run, result)
    assert jumps.largest_translation_m == pytest.approx(0.7, abs=1e-9)
    assert jumps.largest_at_ns == int(STAMPS[300])
    summary = evaluate(run).summary
    assert summary.estimators["baseline"].false_fixes_accepted == 1
    assert summary.estimators["fused"].false_fixes_accepted == 0
    assert summary.estimators["baseline"].largest_jump_m == pytest.approx(0.7, abs=1e-9)


def test_last_fix_of_a_row_wins_and_first_snap_after_a_kidnap_is_not_a_jump() -> None:
    truth = _truth()
    shifted = SE3.from_rotvec([0, 0, 0], [0.0, 5.0, 0.0])
    fixes = [
        _fix(int(STAMPS[100]) - 4_000_000, _truth_at(int(STAMPS[100]) - 4_000_000)),
        _fix(int(STAMPS[100]), _truth_at(int(STAMPS[100])) @ shifted),  # same row, later: wins
    ]
    result = naive_snap_baseline(STAMPS, truth, fixes)
    y_m = np.asarray(result.T_map_base.translation)[:, 1] - np.asarray(truth.translation)[:, 1]
    assert math.isclose(float(np.hypot(*(np.asarray(result.T_map_base.translation)[100, :2]
                        - np.asarray(truth.translation)[100, :2]))), 5.0, abs_tol=1e-9)  # fmt: skip
    assert abs(y_m[99]) < 1e-12
    later = [*fixes, _fix(int(STAMPS[400]), _truth_at(int(STAMPS[400])))]
    run = LocalizationRun("k", STAMPS, truth, SE3.identity(N), np.zeros((N, 6, 6)),
                          np.ones(N, dtype=bool), T_map_base_truth=truth, fixes=later,
                          kidnaps_ns=[int(STAMPS[350])])  # fmt: skip
    jumps = baseline_jumps(run, naive_snap_baseline(STAMPS, truth, later))
    assert jumps.largest_translation_m == 0.0 and jumps.n_excluded == 1


def test_bad_input_is_a_localize_error() -> None:
    with pytest.raises(LocalizeError, match="odometry poses"):
        naive_snap_baseline(STAMPS, SE3.identity(3), [])
    with pytest.raises(LocalizeError, match="increase strictly"):
        naive_snap_baseline(STAMPS[::-1].copy(), SE3.identity(N), [])
