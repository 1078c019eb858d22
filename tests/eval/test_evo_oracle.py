"""tagloc's ATE, alignment, stamp association and RPE equal evo's on the same trajectories.

evo (GPL-3.0) is the oracle only: it is in the dev extra, never imported by tagloc. Each test
builds one pair of random trajectories, computes a number with tagloc and with evo's own API,
and asserts they agree to 1e-9 (metres, degrees, or the scale).
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.eval import (
    absolute_trajectory_error,
    associate_stamps,
    relative_pose_error,
    relative_pose_error_per_time,
    umeyama_alignment,
)
from tagloc.eval.compare import compare_trajectories
from tagloc.eval.rpe import pair_errors, pairs_by_path, pairs_by_time
from tagloc.geometry import SE3

evo_metrics = pytest.importorskip("evo.core.metrics")
evo_sync = pytest.importorskip("evo.core.sync")
evo_trajectory = pytest.importorskip("evo.core.trajectory")
evo_geometry = pytest.importorskip("evo.core.geometry")
Unit = pytest.importorskip("evo.core.units").Unit

TOL = 1e-9
N = 600
DT_NS = 20_000_000  # 50 Hz


def _walk(rng: np.random.Generator, n: int) -> SE3:
    """A wandering 3D path with a varying heading, about 6 m."""
    yaw = np.cumsum(rng.normal(0.0, 0.03, n))
    step = np.c_[0.01 * np.cos(yaw), 0.01 * np.sin(yaw), rng.normal(0.0, 0.002, n)]
    rotvec = np.c_[rng.normal(0.0, 0.02, (n, 2)), yaw]
    return SE3.from_rotvec(rotvec, np.cumsum(step, axis=0))


def _pair(seed: int) -> tuple[np.ndarray, SE3, SE3]:
    rng = np.random.default_rng(seed)
    truth = _walk(rng, N)
    offset = SE3.from_rotvec([0.05, -0.02, 0.4], [1.0, -2.0, 0.3])
    estimate = offset @ truth @ SE3.exp(rng.normal(0.0, 0.01, (N, 6)))
    stamps = 1_700_000_000_000_000_000 + np.arange(N, dtype=np.int64) * DT_NS
    return stamps, truth, estimate


def _evo(stamps_ns: np.ndarray, T: SE3) -> object:
    return evo_trajectory.PoseTrajectory3D(
        poses_se3=list(np.asarray(T.as_matrix())), timestamps=stamps_ns * 1e-9
    )


def _evo_ape(stamps: np.ndarray, ref: SE3, est: SE3, align: bool, scale: bool) -> object:
    traj_ref, traj_est = _evo(stamps, ref), _evo(stamps, est)
    if align:
        traj_est.align(traj_ref, correct_scale=scale)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((traj_ref, traj_est))
    return ape


@pytest.mark.parametrize(("align", "scale"), [(False, False), (True, False), (True, True)])
def test_ate_equals_evo_ape(align: bool, scale: bool) -> None:
    stamps, truth, estimate = _pair(1)
    if scale:  # a trajectory at the wrong scale, as a monocular estimate
        estimate = SE3(rotation=estimate.rotation, translation=0.7 * estimate.translation)
    ours = absolute_trajectory_error(stamps, truth, estimate, align=align, correct_scale=scale)
    ape = _evo_ape(stamps, truth, estimate, align, scale)
    stats = ape.get_all_statistics()
    np.testing.assert_allclose(ours.errors_m, ape.error, rtol=0.0, atol=TOL)
    for name in ("rmse", "mean", "median", "max"):
        assert getattr(ours, name) == pytest.approx(stats[name], abs=TOL), name


@pytest.mark.parametrize("with_scale", [False, True])
def test_umeyama_equals_evo(with_scale: bool) -> None:
    rng = np.random.default_rng(2)
    x = rng.normal(0.0, 3.0, (200, 3))
    y = 1.3 * x @ SE3.from_rotvec([0.3, -0.1, 2.0], [0, 0, 0]).rotation.matrix.T + [4.0, 1, -2]
    y += rng.normal(0.0, 0.05, y.shape)
    ours = umeyama_alignment(x, y, with_scale=with_scale)
    R, t, c = evo_geometry.umeyama_alignment(x.T, y.T, with_scale)
    np.testing.assert_allclose(ours.R_ref_est, R, rtol=0.0, atol=TOL)
    np.testing.assert_allclose(ours.t_ref_est, t, rtol=0.0, atol=TOL)
    assert ours.scale == pytest.approx(c, abs=TOL)


@pytest.mark.parametrize("delta_m", [0.25, 1.0, 2.5])
def test_rpe_by_distance_equals_evo_rpe_in_metres(delta_m: float) -> None:
    stamps, truth, estimate = _pair(3)
    ours = relative_pose_error(stamps, truth, estimate, delta_m=delta_m)
    assert ours is not None and ours.delta_m == delta_m
    pairs = pairs_by_path(truth.translation, delta_m)
    per_pair = pair_errors(truth, estimate, pairs)
    relations = (evo_metrics.PoseRelation.translation_part,
                 evo_metrics.PoseRelation.rotation_angle_deg)  # fmt: skip
    stats = []
    for relation, values in zip(relations, per_pair, strict=True):
        rpe = evo_metrics.RPE(relation, delta_m, Unit.meters, pairs_from_reference=True)
        rpe.process_data((_evo(stamps, truth), _evo(stamps, estimate)))
        assert pairs[:, 1].tolist() == rpe.delta_ids
        np.testing.assert_allclose(values, rpe.error, rtol=0.0, atol=TOL)
        stats.append(rpe.get_all_statistics())
    assert ours.n_pairs == len(pairs)
    assert ours.translation_rmse_m == pytest.approx(stats[0]["rmse"], abs=TOL)
    assert ours.translation_max_m == pytest.approx(stats[0]["max"], abs=TOL)
    assert ours.rotation_rmse_deg == pytest.approx(stats[1]["rmse"], abs=TOL)
    assert ours.rotation_max_deg == pytest.approx(stats[1]["max"], abs=TOL)


@pytest.mark.parametrize("frames", [1, 7, 50])
def test_rpe_by_time_equals_evo_rpe_in_frames_on_even_stamps(frames: int) -> None:
    stamps, truth, estimate = _pair(4)
    delta_s = frames * DT_NS * 1e-9
    ours = relative_pose_error_per_time(stamps, truth, estimate, delta_s=delta_s)
    assert ours is not None and ours.delta_s == delta_s
    pairs = pairs_by_time(stamps, frames * DT_NS)
    per_pair = pair_errors(truth, estimate, pairs)
    relations = (evo_metrics.PoseRelation.translation_part,
                 evo_metrics.PoseRelation.rotation_angle_deg)  # fmt: skip
    stats = []
    for relation, values in zip(relations, per_pair, strict=True):
        rpe = evo_metrics.RPE(relation, frames, Unit.frames, pairs_from_reference=True)
        rpe.process_data((_evo(stamps, truth), _evo(stamps, estimate)))
        assert pairs[:, 1].tolist() == rpe.delta_ids
        np.testing.assert_allclose(values, rpe.error, rtol=0.0, atol=TOL)
        stats.append(rpe.get_all_statistics())
    assert ours.translation_rmse_m == pytest.approx(stats[0]["rmse"], abs=TOL)
    assert ours.rotation_rmse_deg == pytest.approx(stats[1]["rmse"], abs=TOL)


def test_rpe_by_time_on_uneven_stamps_spans_at_least_delta() -> None:
    stamps, truth, estimate = _pair(5)
    rng = np.random.default_rng(5)
    stamps = np.cumsum(rng.integers(5_000_000, 40_000_000, N)).astype(np.int64)
    ours = relative_pose_error_per_time(stamps, truth, estimate, delta_s=0.5)
    pairs = pairs_by_time(stamps, 500_000_000)
    assert ours is not None and ours.n_pairs == len(pairs) > 10
    i, j = pairs.T
    span = stamps[j] - stamps[i]
    assert np.all(span >= 500_000_000) and np.all(stamps[j - 1] - stamps[i] < 500_000_000)
    assert np.array_equal(i[1:], j[:-1]) and i[0] == 0


@pytest.mark.parametrize("case", ["sparse_late", "dense_est", "jitter", "unsorted"])
def test_association_equals_evo_associate_trajectories(case: str) -> None:
    stamps, truth, estimate = _pair(6)
    rng = np.random.default_rng(6)
    if case == "sparse_late":  # every 3rd pose, 2 ms late
        keep = np.arange(0, N, 3)
        stamps_est = stamps[keep] + 2_000_000
    elif case == "dense_est":  # the reference is the short one
        keep = np.arange(N)
        stamps, truth = stamps[::4].copy(), truth[::4]
        stamps_est = np.asarray(
            1_700_000_000_000_000_000 + np.arange(N, dtype=np.int64) * DT_NS + 3_000_000
        )
    elif case == "jitter":  # up to +-15 ms: some poses beyond the 10 ms tolerance
        keep = np.arange(N)
        stamps_est = stamps + rng.integers(-15_000_000, 15_000_000, N)
        stamps_est = np.sort(stamps_est)
    else:
        keep = rng.permutation(N)[: N // 2]
        stamps_est = stamps[keep] + rng.integers(-8_000_000, 8_000_000, len(keep))
    T_est = estimate[keep]
    i_ref, i_est = associate_stamps(stamps, stamps_est, 10_000_000)
    ref_evo, est_evo = evo_sync.associate_trajectories(
        _evo(stamps, truth), _evo(stamps_est, T_est), max_diff=0.01
    )
    assert len(i_ref) == ref_evo.num_poses
    np.testing.assert_allclose(stamps[i_ref] * 1e-9, ref_evo.timestamps, rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(stamps_est[i_est] * 1e-9, est_evo.timestamps, rtol=0.0, atol=1e-6)
    if case == "unsorted":
        return
    ours = compare_trajectories(stamps, truth, stamps_est, T_est, align=True)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    est_evo.align(ref_evo)
    ape.process_data((ref_evo, est_evo))
    assert ours.n_matched == ref_evo.num_poses
    assert ours.ate.rmse == pytest.approx(
        ape.get_statistic(evo_metrics.StatisticsType.rmse), abs=TOL
    )
