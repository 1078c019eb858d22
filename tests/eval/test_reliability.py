"""The reliability protocol, fix statistics, kidnap recovery, jumps and RPE on hand-built runs
whose errors are known by construction."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tagloc.eval.fixstats import acceptance_vs_angle, acceptance_vs_range, fix_counts
from tagloc.eval.fixstats import suspect_sources as find_suspects
from tagloc.eval.protocol import EvalConfig, reliability_protocol, relocalization_times
from tagloc.eval.summary import evaluate
from tagloc.eval.trajectories import correction_jumps, pose_errors, relative_pose_error
from tagloc.geometry import SE3
from tagloc.localize.events import EventKind, FilterEvent
from tagloc.localize.run import CabEstimate, CameraFrameRecord, FixAttempt, LocalizationRun
from tagloc.supervise import CabState
from tagloc.units import S_NS

DT_NS = 10_000_000  # 100 Hz odometry
N = 1001  # 10 s
FloatOrArray = float | np.ndarray


def _line(n: int = N, speed_mps: float = 0.5) -> SE3:
    """Base moving along x of map at ``speed_mps``, yaw 0, one pose per 10 ms."""
    xyz = np.zeros((n, 3))
    xyz[:, 0] = speed_mps * np.arange(n) * DT_NS * 1e-9
    return SE3.from_rotvec(np.zeros((n, 3)), xyz)


def _offset(T_map_base: SE3, dy_m: FloatOrArray, yaw_deg: FloatOrArray = 0.0) -> SE3:
    """``T_map_base`` displaced by ``dy_m`` along y of map and rotated by ``yaw_deg``."""
    n = len(T_map_base)
    rotvec = np.zeros((n, 3))
    rotvec[:, 2] = np.radians(np.broadcast_to(yaw_deg, n))
    delta = np.zeros((n, 3))
    delta[:, 1] = np.broadcast_to(dy_m, n)
    return SE3.from_rotvec(rotvec, np.asarray(T_map_base.translation) + delta)


def _fix(
    stamp_ns: int,
    decision: str = "accepted",
    *,
    range_m: float = 2.0,
    angle_deg: float = 10.0,
    false: bool | None = False,
    source: str = "tag:1",
) -> FixAttempt:
    return FixAttempt(stamp_ns, source, (1,), SE3.identity(), np.eye(6) * 1e-4, decision,
                      range_m, math.radians(angle_deg), false)  # fmt: skip


def _run(T_map_base_fused: SE3, frames: list[CameraFrameRecord], **kw: object) -> LocalizationRun:
    truth = _line()
    T_odom_base = truth  # odometry exact: the fused error is all in the correction
    T_map_odom = T_map_base_fused @ T_odom_base.inverse()
    return LocalizationRun(
        name="synthetic",
        stamps_ns=np.arange(N, dtype=np.int64) * DT_NS,
        T_odom_base=T_odom_base,
        T_map_odom=T_map_odom,
        cov_map_base=np.full((N, 6, 6), 1e-4),
        initialized=np.ones(N, dtype=bool),
        T_map_base_truth=truth,
        frames=frames,
        **kw,  # type: ignore[arg-type]
    )


def test_reliability_counts_known_successes() -> None:
    # fused error: 2 cm for t < 5 s, 8 cm after (fails X = 5 cm); 3 deg yaw in [2 s, 3 s)
    t_s = np.arange(N) * DT_NS * 1e-9
    dy = np.where(t_s < 5.0, 0.02, 0.08)
    yaw = np.where((t_s >= 2.0) & (t_s < 3.0), 3.0, 0.0)
    fused = _offset(_line(), dy, yaw)
    # frames at 10 Hz, 5 ms after an odometry stamp (so "right after" is the next row);
    # a tag in view at 2 m on even frames, 4 m on odd ones; a fix accepted except every 5th
    frames = [
        CameraFrameRecord(k * 100_000_000 + 5_000_000, 2.0 if k % 2 == 0 else 4.0, 1,
                          0 if k % 5 == 0 else 1)
        for k in range(100)
    ]  # fmt: skip
    run = _run(fused, frames)
    errors = pose_errors(run.T_map_base_truth, run.T_map_base)  # type: ignore[arg-type]
    result = reliability_protocol(frames, run.stamps_ns, errors, EvalConfig())
    # oracle: count by hand over the frame list
    expected_opps = [k for k in range(100) if k % 2 == 0]
    expected_ok = [
        k for k in expected_opps
        if k % 5 != 0 and (k * 0.1 + 0.01) < 5.0 and not (2.0 <= k * 0.1 + 0.01 < 3.0)
    ]  # fmt: skip
    assert result.n_opportunities == len(expected_opps) == 50
    assert result.n_fix_accepted == sum(k % 5 != 0 for k in expected_opps)
    assert result.n_success == len(expected_ok)
    assert result.fraction == pytest.approx(len(expected_ok) / 50)
    # a looser X admits the 8 cm half; a smaller Z admits no opportunity
    loose = reliability_protocol(frames, run.stamps_ns, errors, EvalConfig(position_tol_m=0.1))
    assert loose.n_success == sum(
        1 for k in expected_opps if k % 5 != 0 and not (2.0 <= k * 0.1 + 0.01 < 3.0)
    )
    none = reliability_protocol(frames, run.stamps_ns, errors, EvalConfig(opportunity_range_m=1))
    assert none.n_opportunities == 0 and math.isnan(none.fraction)


def test_pose_errors_known_offsets() -> None:
    truth = _line(50)
    est = _offset(truth, 0.03, 1.5)
    errors = pose_errors(truth, est)
    np.testing.assert_allclose(errors.translation_m, 0.03, atol=1e-12)
    np.testing.assert_allclose(errors.rotation_deg, 1.5, atol=1e-6)


def test_fix_counts_and_acceptance_bins() -> None:
    fixes = [
        _fix(1, range_m=0.5, angle_deg=5.0),
        _fix(2, "gated_chi2", range_m=1.5, angle_deg=20.0),
        _fix(3, "rejected:range", range_m=9.0, angle_deg=float("nan")),
        _fix(4, "accepted", range_m=2.5, angle_deg=50.0, false=True),
        _fix(5, "gated_chi2", range_m=2.9, angle_deg=80.0, false=True),
        _fix(6, "initialized", range_m=3.5, angle_deg=95.0),
        _fix(7, "rejected:range", range_m=math.inf, angle_deg=float("nan")),
        _fix(8, "rejected:decode", range_m=float("nan"), angle_deg=float("nan")),
    ]
    counts = fix_counts(fixes, range_m=3.0)
    assert (counts.n_attempts, counts.n_offered, counts.n_accepted) == (8, 5, 3)
    assert (counts.n_false_attempts, counts.n_false_offered, counts.n_false_accepted) == (2, 2, 1)
    assert (counts.n_true_in_range, counts.n_true_in_range_accepted) == (2, 1)
    bins, unknown = acceptance_vs_range(fixes, (0.0, 1.0, 2.0, 3.0))
    assert [(b.n_attempts, b.n_offered, b.n_accepted) for b in bins] == [
        (1, 1, 1), (1, 1, 0), (2, 2, 1), (3, 1, 1)
    ]  # fmt: skip
    assert unknown == 1  # NaN range; +inf falls in the last bin
    bins, unknown = acceptance_vs_angle(fixes, (0.0, 30.0, 60.0, 90.0))
    assert [b.n_attempts for b in bins] == [2, 1, 1, 1] and unknown == 3
    assert bins[0].acceptance == 0.5 and math.isnan(
        acceptance_vs_angle([], (0.0,))[0][0].acceptance
    )


def test_suspect_sources_from_events() -> None:
    events = [
        FilterEvent(10, EventKind.SUSPECT_SOURCE, "tag:5"),
        FilterEvent(20, EventKind.REJECTED_SUSPECT, "tag:5"),
    ]
    fixes = [_fix(5, source="tag:5"), _fix(20, "rejected_suspect", source="tag:5"),
             _fix(30, "rejected_suspect", source="tag:5"), _fix(40, source="tag:1")]  # fmt: skip
    [suspect] = find_suspects(events, fixes, listed=["tag:5"])
    assert (suspect.source, suspect.first_flagged_ns) == ("tag:5", 10)
    assert (suspect.n_rejected, suspect.n_accepted, suspect.cleared) == (2, 1, False)


def test_time_to_relocalize_after_kidnap() -> None:
    # fused far off (1 m) until 6.0 s, exact after; kidnap at 5 s; tag first seen at 5.2 s
    t_s = np.arange(N) * DT_NS * 1e-9
    fused = _offset(_line(), np.where(t_s < 6.0, 1.0, 0.0))
    frames = [CameraFrameRecord(int(s * 1e9), 2.0 if s >= 5.2 else math.inf, int(s >= 5.2), 0)
              for s in np.arange(0.0, 10.0, 0.1).round(1)]  # fmt: skip
    # accepted fixes at 5.5 s (pose still off: not a relocalization) and 6.0 s (within tolerance)
    fixes = [_fix(5_500_000_000), _fix(6_000_000_000, "reinitialized_kidnap"), _fix(7_000_000_000)]
    run = _run(fused, frames, fixes=fixes, kidnaps_ns=[5_000_000_000])
    errors = pose_errors(run.T_map_base_truth, run.T_map_base)  # type: ignore[arg-type]
    [recovery] = relocalization_times(
        run.kidnaps_ns, frames, fixes, run.stamps_ns, errors, EvalConfig()
    )
    assert recovery.first_sighting_ns == 5_200_000_000
    assert recovery.relocalized_ns == 6_000_000_000
    assert recovery.time_to_relocalize_s == pytest.approx(0.8)
    summary = evaluate(run).summary
    assert summary.kidnaps == [recovery]
    assert [c.passed for c in summary.checks if c.name.startswith("relocalized")] == [True]


def test_correction_jumps_exclude_snaps() -> None:
    truth = _line(100)
    stamps = np.arange(100, dtype=np.int64) * DT_NS
    dy = np.zeros(100)
    dy[30:] = 0.3  # a 0.3 m step into row 30
    dy[60:] = 0.1  # a 0.2 m step into row 60
    T_map_odom = _offset(SE3.identity(100), dy)
    initialized = np.arange(100) >= 10
    jumps = correction_jumps(stamps, T_map_odom, truth, initialized)
    assert jumps.largest_translation_m == pytest.approx(0.3)
    assert jumps.largest_at_ns == 30 * DT_NS
    snapped = correction_jumps(stamps, T_map_odom, truth, initialized, [30 * DT_NS - 3])
    assert snapped.largest_translation_m == pytest.approx(0.2) and snapped.n_excluded == 1


def test_rpe_of_a_scale_error_is_known() -> None:
    # estimate travels 2 % further than the truth along a straight line: 0.02 m per metre
    truth = _line(2001)
    est = SE3.from_rotvec(np.zeros((2001, 3)), 1.02 * np.asarray(truth.translation))
    stamps = np.arange(2001, dtype=np.int64) * DT_NS
    rpe = relative_pose_error(stamps, truth, est, delta_m=1.0)
    assert rpe is not None and rpe.n_pairs == 10
    assert rpe.translation_rmse_m == pytest.approx(0.02, rel=1e-6)
    assert rpe.rotation_rmse_deg == pytest.approx(0.0, abs=1e-9)
    assert relative_pose_error(stamps[:3], truth[:3], est[:3]) is None


def _cab_run(dx_cab_m: float, yaw_cab_deg: float = 0.0) -> tuple[LocalizationRun, set[int]]:
    """10 s along x; 10 Hz frames, a map tag at 2 m for t < 5 s, after that only the cab's tag
    within Z (a map tag at 5 m); the cab's estimate, at every row from 5 s, is the truth of the
    base in the cab displaced by ``dx_cab_m`` / ``yaw_cab_deg``; a cab fix accepted on the
    cab-only frames but every 5th. Returns the run and the frames whose cab fix was accepted."""
    truth = _line()
    stamps = np.arange(N, dtype=np.int64) * DT_NS
    frames, fixes, accepted = [], [], set()
    for k in range(100):
        stamp = k * 100_000_000 + 5_000_000
        cab_only = k >= 50
        by_frame = (("cab", 1.5), ("map", 5.0)) if cab_only else (("map", 2.0),)
        frames.append(CameraFrameRecord(stamp, 1.5 if cab_only else 2.0, 1, int(not cab_only),
                                        by_frame))  # fmt: skip
        if cab_only and k % 5:
            fixes.append(dataclasses.replace(_fix(stamp), frame="cab"))
            accepted.add(k)
    T_map_cab = SE3.from_rotvec(np.array([0.0, 0.0, 0.7]), np.array([3.0, -1.0, 4.0]))
    rows = np.flatnonzero(stamps >= 5 * S_NS)
    T_cab_base_truth = T_map_cab.inverse() @ truth[rows]
    shift = SE3.from_rotvec(np.zeros(3), np.array([dx_cab_m, 0.0, 0.0]))
    turn = SE3.from_rotvec(np.array([0.0, 0.0, math.radians(yaw_cab_deg)]), np.zeros(3))
    T_cab_base_est = shift @ T_cab_base_truth @ turn
    T_odom_base = truth  # as _run's
    cab = [
        CabEstimate(int(stamps[i]), "cab", T_cab_base_est[j] @ T_odom_base[i].inverse(),
                    T_odom_base[i], np.eye(6) * 1e-6, CabState.IN_CAB)
        for j, i in enumerate(rows)
    ]  # fmt: skip
    run = _run(truth, frames, fixes=fixes, cab=cab, T_cab_base_truth=T_cab_base_truth,
               metadata={"elevators": {"cab_frames": ["cab"]}})  # fmt: skip
    return run, accepted


def test_cab_only_opportunities_are_judged_against_the_cabs_truth() -> None:
    run, accepted = _cab_run(0.0)
    r = evaluate(run).summary.estimators["fused"].reliability
    assert r is not None
    # the map's 50 frames: exact map pose, fix accepted; the cab's 50: judged against the cab
    assert (r.in_map.n_opportunities, r.in_map.n_success) == (50, 50)
    assert len(accepted) == 40
    assert (r.in_cab.n_opportunities, r.in_cab.n_fix_accepted) == (50, 40)
    assert r.in_cab.n_success == 40 and r.n_success == 90 and r.n_opportunities == 100
    # a cab estimate 6 cm off (X = 5 cm) or 3 deg off (Y = 2 deg) fails every cab opportunity
    for dx, yaw in ((0.06, 0.0), (0.0, 3.0)):
        bad = evaluate(_cab_run(dx, yaw)[0]).summary.estimators["fused"].reliability
        assert bad is not None and bad.in_cab.n_success == 0 and bad.in_map.n_success == 50
    # 4 cm off passes; the baseline has no cab estimate: none of its cab frames succeeds
    near = evaluate(_cab_run(0.04)[0]).summary.estimators
    assert near["fused"].reliability.in_cab.n_success == 40  # type: ignore[union-attr]
    assert near["baseline"].reliability.in_cab.n_success == 0  # type: ignore[union-attr]


def test_without_cab_frames_every_opportunity_is_the_maps() -> None:
    run, _ = _cab_run(0.0)
    errors = pose_errors(run.T_map_base_truth, run.T_map_base)  # type: ignore[arg-type]
    r = reliability_protocol(run.frames, run.stamps_ns, errors, EvalConfig())
    # the cab-only frames judged against map, as before: no map fix accepted there
    assert (r.in_cab.n_opportunities, r.in_map.n_opportunities, r.n_success) == (0, 100, 50)
