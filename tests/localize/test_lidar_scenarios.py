"""Lidar and tags fused on the simulator's scenarios (ray-cast sweeps, truth premap), against
ground truth and against the same drive with tags alone.

Short drives by default (the first 45-60 s); whole drives under ``--runslow``.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from tagloc.eval.scenarios import localize_scenario
from tagloc.geometry import SE3
from tagloc.localize.projected_update import planar_constraint
from tagloc.localize.run import FixAttempt, LocalizationRun
from tagloc.localize.source_lidar import UNMEASURED_VAR
from tagloc.sim.scenarios import build_scenario

S = 1_000_000_000


@functools.cache
def _run(name: str, duration_s: float | None, lidar: bool) -> LocalizationRun:
    return localize_scenario(build_scenario(name, 0, duration_s), lidar=lidar)


def _xy_errors_m(run: LocalizationRun) -> np.ndarray:
    assert run.T_map_base_truth is not None
    d = np.asarray(run.T_map_base.translation - run.T_map_base_truth.translation)
    return np.linalg.norm(d[run.initialized][:, :2], axis=1)


def _rmse(run: LocalizationRun) -> float:
    return float(np.sqrt(np.mean(_xy_errors_m(run) ** 2)))


def _lidar(run: LocalizationRun) -> list[FixAttempt]:
    return [a for a in run.fixes if a.source == "lidar"]


def lidar_nees(name: str, duration_s: float | None, run: LocalizationRun) -> np.ndarray:
    """NEES per measured planar direction of each accepted lidar fix against the simulator's
    truth at its stamp, as the planar filter uses the fix: ``y^T C^-1 y / k`` with
    ``y = B^T e[x, y, yaw]``, ``e = Log(T_true^-1 T_fix)`` and ``(B, C)`` the fix's measured
    directions and covariance (the run record's, without its unmeasured part) projected on the
    plane (:func:`planar_constraint`)."""
    fixes = [a for a in _lidar(run) if a.accepted]
    drive = build_scenario(name, 0, duration_s).drive
    truth = drive.ground_truth_at(np.array([a.stamp_ns for a in fixes], dtype=np.int64))
    out = []
    for a, T_true in zip(fixes, truth.T_map_base, strict=True):
        w, V = np.linalg.eigh(a.cov)
        measured = w < 0.01 * UNMEASURED_VAR
        B, C = planar_constraint(V[:, measured], np.diag(w[measured]))
        e = np.asarray((T_true.inverse() @ a.T_map_base).log())
        y = B.T @ e[[0, 1, 5]]
        out.append(float(y @ np.linalg.solve(C, y)) / B.shape[1])
    return np.array(out)


def test_default_drive_lidar_and_tags_beat_tags_alone() -> None:
    fused, tags = _run("default", 45.0, True), _run("default", 45.0, False)
    lidar = _lidar(fused)
    assert sum(a.accepted for a in lidar) >= 0.95 * len(lidar) > 150
    assert _rmse(fused) <= 0.025
    assert _rmse(fused) < 0.5 * _rmse(tags)
    assert tags.metadata["lidar_used"] is False and not _lidar(tags)
    nees = lidar_nees("default", 45.0, fused)
    assert 0.3 < float(np.mean(nees)) < 2.0  # honest covariance: about 1 per direction


def test_lidar_unplugged_leaves_level_1_and_comes_back() -> None:
    run = _run("lidar_unplugged", 60.0, True)
    t0 = run.stamps_ns[0]
    walk = [((t.stamp_ns - t0) / S, int(t.from_level), int(t.to_level)) for t in run.ladder]
    down = [w for w in walk if w[1] == 1 and 30.0 <= w[0] <= 31.0]
    up = [w for w in walk if w[2] == 1 and w[0] >= 50.0]
    assert down and down[0][2] == 3, walk  # lidar dead: no usable lidar, markers alone
    assert up and up[0][0] < 52.0, walk
    assert run.metadata["ladder"]["level"] == 1


@pytest.mark.slow
def test_glass_corridor_never_accepts_a_wrong_lidar_fix() -> None:
    fused, tags = _run("glass_corridor", None, True), _run("glass_corridor", None, False)
    drive = build_scenario("glass_corridor", 0, None).drive
    fixes = [a for a in _lidar(fused) if a.accepted]
    truth = drive.ground_truth_at(np.array([a.stamp_ns for a in fixes], dtype=np.int64))
    wrong = [
        a.stamp_ns for a, T in zip(fixes, truth.T_map_base, strict=True)
        if np.linalg.norm(a.T_map_base.translation[:2] - np.asarray(T.translation)[:2]) > 0.10
        and _measured_error_m(a, T) > 0.10
    ]  # fmt: skip
    assert not wrong
    assert _rmse(fused) <= _rmse(tags) * 1.05
    # glass walls: most fixes measure only some of x, y, yaw (degenerate in the plane)
    planar_k = [_planar_k(a) for a in fixes]
    assert sum(k < 3 for k in planar_k) >= 0.5 * len(planar_k)


def _planar_k(a: FixAttempt) -> int:
    w, V = np.linalg.eigh(a.cov)
    m = w < 0.01 * UNMEASURED_VAR
    return int(planar_constraint(V[:, m], np.diag(w[m]))[1].shape[0])


def _measured_error_m(a: FixAttempt, T_true: SE3) -> float:
    """The fix's translation error along the directions it measures (m)."""
    w, V = np.linalg.eigh(a.cov)
    B = V[:, w < 0.01 * UNMEASURED_VAR]
    e = np.asarray((T_true.inverse() @ a.T_map_base).log())
    return float(np.linalg.norm((B @ (B.T @ e))[:3]))


@pytest.mark.slow
def test_long_corridor_lidar_does_no_harm() -> None:
    """Tags only at the corridor's ends: the estimate starts at the far end (a lidar fix
    cannot start it), so the lidar adds little; it must not make the run worse."""
    fused, tags = _run("long_corridor", None, True), _run("long_corridor", None, False)
    assert _rmse(fused) <= _rmse(tags) * 1.05
