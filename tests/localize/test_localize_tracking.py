"""The filter while tracking: consistency (NEES), the chi-square gate, glints, the cap, late
fixes, planar mode, and the iterated update against a least-squares oracle."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import least_squares
from test_localize_sim import (
    FIX_COV,
    MS,
    SE3,
    S,
    fix_stamps,
    make_filter,
    make_fix,
    pose_error,
    run_fixes,
    simulate,
)

from tagloc.frames import TransformBuffer
from tagloc.geometry import SE2
from tagloc.localize import EventKind, FixQuality, TagFix

BIG_WINDOW = 1000 * S


def _tracking(seed: int, planar: bool = False, calibration: bool = False, **sim: float):
    rng = np.random.default_rng(seed)
    drive = simulate(rng, **sim)
    buffer = TransformBuffer(window_ns=BIG_WINDOW)
    drive.fill(buffer)
    flt = make_filter(buffer, filter={"planar": planar}, calibration={"enabled": calibration})
    return rng, drive, buffer, flt


def _nees_ratio(planar: bool, calibration: bool = False) -> float:
    """Mean NEES / dof of the pose over three drives (10 Hz fixes, after 3 s), checking on the
    way that each converges with few false alarms."""
    axes = [0, 1, 5] if planar else list(range(6))
    dof = len(axes)
    nees, final = [], []
    for seed in range(3):
        rng, drive, _, flt = _tracking(seed, planar, calibration)
        for t in fix_stamps(drive, 10.0):
            fix = make_fix(drive, int(t), rng, f"tag:{t // S % 4}")
            if flt.update(fix).kind is EventKind.ACCEPTED and t > 3 * S:
                e = drive.T_map_odom(int(t)).minus(flt.T_map_odom)[axes]
                P = flt.covariance[np.ix_(axes, axes)]
                nees.append(float(e @ np.linalg.solve(P, e)))
        err = drive.T_map_odom(int(t)).minus(flt.T_map_odom)[axes]  # planar: x, y, yaw only
        final.append((float(np.linalg.norm(err[: -1 if planar else 3])), float(np.abs(err[-1]))))
        counts = flt.events.counts_by_kind()
        assert counts[EventKind.INITIALIZED] == 1
        assert counts[EventKind.GATED_CHI2] <= 5  # 0.1 % false alarms of ~600 fixes, and slack
    assert max(t for t, _ in final) < 0.08 and max(r for _, r in final) < math.radians(2)
    return float(np.mean(nees) / dof)


@pytest.mark.parametrize("planar", [False, True], ids=["se3", "planar"])
def test_converges_with_consistent_nees(planar: bool) -> None:
    ratio = _nees_ratio(planar)
    assert 0.5 <= ratio <= 2.0, ratio


@pytest.mark.parametrize("planar", [False, True], ids=["se3", "planar"])
def test_nees_stays_consistent_with_odometry_calibration(planar: bool) -> None:
    # The shipped default: the state carries the 4 calibration parameters. This drive has no
    # systematic odometry error, so estimating one must not make the pose overconfident.
    # Measured 0.96 (se3) and 1.02 (planar); one drive's ratio spans 0.87-1.08 over seeds
    # 0-14, so the mean of three stays well inside this band.
    ratio = _nees_ratio(planar, calibration=True)
    assert 0.8 <= ratio <= 1.25, ratio


@pytest.mark.parametrize(
    "offset",
    [SE3.from_rotvec([0, 0, 0], [1.0, 0, 0]), SE3.from_rotvec([0, 0, math.radians(30)], [0, 0, 0])],
    ids=["1m", "30deg"],
)
def test_chi2_gate_rejects_a_displaced_fix(offset: SE3) -> None:
    rng, drive, _, flt = _tracking(1, laps=1)
    run_fixes(flt, drive, rng, fix_stamps(drive, 10.0, stop_s=10.0))
    before, cov_before = flt.T_map_odom, flt.covariance
    event = flt.update(make_fix(drive, 10 * S, rng, "tag:1", offset=offset))
    assert event.kind is EventKind.GATED_CHI2 and event.d2 > event.threshold > 20
    assert flt.T_map_odom.allclose(before, atol=0.0)
    # The covariance grew by the 0.1 s random walk only; the fix itself changed nothing.
    assert np.all(np.diag(flt.covariance) >= np.diag(cov_before))


def test_isolated_glints_are_gated_and_never_trigger_a_kidnap() -> None:
    rng, drive, _, flt = _tracking(2)
    glint = SE3.from_rotvec([0, 0, math.radians(40)], [1.5, -0.5, 0.2])
    glint_stamps = set(range(5 * S, 50 * S, 3 * S))  # a mis-detection every 3 s, any tag
    glint_events = []
    for i, t in enumerate(fix_stamps(drive, 10.0)):
        offset = glint if int(t) in glint_stamps else None
        event = flt.update(make_fix(drive, int(t), rng, f"tag:{i % 4}", offset=offset))
        if offset is not None:
            glint_events.append(event.kind)
    assert glint_events == [EventKind.GATED_CHI2] * len(glint_stamps)
    counts = flt.events.counts_by_kind()
    assert counts[EventKind.REINITIALIZED_KIDNAP] == 0 and counts[EventKind.SUSPECT_SOURCE] == 0
    assert pose_error(flt.T_map_odom, drive.T_map_odom(int(t)))[0] < 0.08


def test_cap_limits_every_published_jump() -> None:
    rng, drive, buffer, flt = _tracking(3, noise_scale=0.0, laps=1)
    wrong = drive.T_map_odom(0) @ SE3.from_rotvec([0, 0, math.radians(12)], [1.2, -0.6, 0.0])
    flt.initialize(0, wrong, np.diag([1.0, 1.0, 1.0, 0.1, 0.1, 0.1]))
    cap_m, cap_rad = 0.25, math.radians(5.0)
    jumps = []
    for t in fix_stamps(drive, 10.0, start_s=0.1, stop_s=4.0):
        prev = flt.correction_at(int(t))
        assert flt.update(make_fix(drive, int(t), rng)).kind is EventKind.ACCEPTED
        A = buffer.lookup("odom", "base_link", int(t))
        jumps.append(pose_error(prev @ A, flt.correction_at(int(t)) @ A))
    jumps_m, jumps_rad = np.array(jumps).T
    assert jumps_m.max() <= cap_m + 1e-9 and jumps_rad.max() <= cap_rad + 1e-9
    assert jumps_m[0] == pytest.approx(cap_m) or jumps_rad[0] == pytest.approx(cap_rad)
    assert flt.events.count(EventKind.CAPPED) >= 3  # > 1.3 m and 12 deg at 0.25 m / 5 deg
    # The remainder is carried, not dropped: the published correction reaches the estimate.
    assert flt.corrections[-1].T_map_odom.allclose(flt.T_map_odom, atol=1e-9)
    assert pose_error(flt.T_map_odom, drive.T_map_odom(int(t)))[0] < 0.03


def test_a_late_fix_applies_at_its_own_stamp() -> None:
    rng = np.random.default_rng(4)
    drive = simulate(rng, noise_scale=0.0, laps=1)  # exact odometry
    t_fix, t_now = 5 * S, 5 * S + 300 * MS
    prior = drive.T_map_odom(0) @ SE3.from_rotvec([0, 0, 0.05], [0.2, -0.1, 0.0])
    fix = make_fix(drive, t_fix, None, cov=FIX_COV * 1e-4)  # nearly exact fix
    results = []
    for arrival in (t_fix, t_now):  # on time, then 300 ms late (odometry already at t_now)
        buffer = TransformBuffer()  # the default 10 s window, filled as time goes
        drive.fill(buffer, until_ns=arrival)
        flt = make_filter(buffer)
        flt.initialize(0, prior, np.diag([0.5, 0.5, 0.5, 0.1, 0.1, 0.1]))
        assert flt.update(fix).kind is EventKind.ACCEPTED
        results.append((flt.T_map_odom, flt.covariance, flt.correction_at(t_now), buffer))
    (X_on, P_on, _, _), (X_late, P_late, C_late, buffer) = results
    assert X_late.allclose(X_on, atol=1e-9) and np.allclose(P_late, P_on, rtol=0, atol=1e-9)
    # The published correction composed with the odometry of *now* is the true pose of now.
    A_now = buffer.lookup("odom", "base_link", t_now)
    i_now = drive.index(t_now)
    err_m, err_rad = pose_error(C_late @ A_now, drive.T_map_base[i_now])
    assert err_m < 0.005 and err_rad < 0.002
    # Using the odometry of the arrival time instead would be off by the 0.3 m driven since.
    naive = fix.T_map_base @ A_now.inverse() @ A_now
    assert pose_error(naive, drive.T_map_base[i_now])[0] > 0.25


def test_a_late_fix_after_the_state_was_predicted_on_gives_the_same_result() -> None:
    rng = np.random.default_rng(5)
    drive = simulate(rng, laps=1)
    buffer = TransformBuffer(window_ns=BIG_WINDOW)
    drive.fill(buffer)
    fixes = [
        make_fix(drive, int(t), rng, f"tag:{i % 3}")
        for i, t in enumerate(fix_stamps(drive, 10.0, stop_s=8.0))
    ]
    on_time, late = make_filter(buffer), make_filter(buffer)
    for fix in fixes:
        on_time.update(fix)
        late.predict(fix.stamp_ns + 300 * MS)  # the state is already 300 ms ahead
        late.update(fix)
    on_time.predict(late.stamp_ns)
    # A random walk: updating late with P - Q is updating on time, then predicting.
    assert late.T_map_odom.allclose(on_time.T_map_odom, atol=1e-9)
    np.testing.assert_allclose(late.covariance, on_time.covariance, rtol=1e-9, atol=1e-15)


def test_planar_mode_pins_z_roll_pitch_and_ignores_them_in_fixes() -> None:
    rng, drive, buffer, flt = _tracking(6, planar=True, laps=1, z_wobble_m=0.05)
    run_fixes(flt, drive, rng, fix_stamps(drive, 10.0, stop_s=10.0))
    tilted = SE3.from_rotvec([math.radians(20), 0, 0], [0, 0, 1.0])  # z + 1 m, roll 20 deg
    fix = make_fix(drive, 10 * S, None)
    bad = TagFix(fix.stamp_ns, fix.T_map_base @ tilted, FIX_COV, "tag:1", FixQuality(0.4))
    assert flt.update(bad).kind is EventKind.ACCEPTED
    run_fixes(flt, drive, rng, fix_stamps(drive, 10.0, start_s=10.1))
    X = flt.T_map_odom
    assert X.translation[2] == 0.0
    roll, pitch, _ = X.rotation.as_euler("xyz")
    assert abs(roll) < 1e-12 and abs(pitch) < 1e-12
    off_plane = [2, 3, 4]
    assert not flt.covariance[off_plane].any() and not flt.covariance[:, off_plane].any()
    t_end = flt.stamp_ns
    err = SE2.from_se3(drive.T_map_odom(t_end)).minus(SE2.from_se3(X))
    assert np.linalg.norm(err[:2]) < 0.08 and abs(err[2]) < math.radians(2)
    pose = flt.pose_at(t_end)
    assert pose.T_map_base.translation[2] == pytest.approx(
        buffer.lookup("odom", "base_link", t_end).translation[2]
    )


def test_iterated_update_reaches_the_least_squares_optimum() -> None:
    """One large update against an independent Gauss-Newton oracle (scipy least_squares)."""
    rng = np.random.default_rng(7)
    drive = simulate(rng, noise_scale=0.0, laps=1)
    buffer = TransformBuffer(window_ns=BIG_WINDOW)
    drive.fill(buffer)
    flt = make_filter(buffer, filter={"max_iterations": 20, "relinearize_tol": 1e-12})
    X0 = drive.T_map_odom(0) @ SE3.from_rotvec([0.1, -0.2, 0.6], [0.8, -0.5, 0.3])
    P0 = np.diag([0.4, 0.3, 0.2, 0.05, 0.05, 0.3])
    t = 4 * S
    fix = make_fix(drive, t, rng)
    flt.initialize(t, X0, P0)
    flt.update(fix)
    A = buffer.lookup("odom", "base_link", t)
    Lp, Lr = np.linalg.cholesky(np.linalg.inv(P0)), np.linalg.cholesky(np.linalg.inv(fix.cov))

    def residuals(delta: np.ndarray) -> np.ndarray:
        X = X0.plus(delta)
        nu = fix.T_map_base.minus(X @ A)
        return np.concatenate([Lp.T @ delta, Lr.T @ nu])

    best = X0.plus(least_squares(residuals, np.zeros(6), xtol=1e-14, ftol=1e-14).x)
    assert flt.T_map_odom.allclose(best, atol=1e-7)
