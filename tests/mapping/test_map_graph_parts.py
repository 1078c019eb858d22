"""Pieces of the map builder against independent oracles: GTSAM, known synthetic errors."""

from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np
import pytest

from tagloc.geometry import SE3, inverse_h, log_h
from tagloc.mapping import CameraFrame, MappingError, Survey, build_tag_map
from tagloc.mapping.calibration import (
    N_CALIBRATION,
    OdometryCalibration,
    apply_calibration,
    calibration_from_vector,
    calibration_vector,
    corrected_step_jacobians,
    corrected_steps,
    fit_calibration,
)
from tagloc.mapping.corner_graph import corner_jacobians, gross_outliers, linearize_corners
from tagloc.mapping.gtsam_bridge import cov_from_gtsam, cov_to_gtsam, from_pose3, to_pose3
from tagloc.mapping.initialize import consensus_rotation
from tagloc.mapping.observations import collect_observations, interpolate_odometry
from tagloc.mapping.odometry_factors import linearize_odometry, odometry_residuals
from tagloc.mapping.odometry_noise import odometry_whitening, rotations_to_z
from tagloc.mapping.whitening import AxisWhitening
from tagloc.sim import ObservationConfig, World, load_default_world, simulate_drive
from tagloc.sim.odometry import simulate_odometry
from tagloc.sim.survey import odometry_noise_of, survey_from_drive
from tagloc.sim.trajectory import se3_from_xy_yaw
from tagloc.tags import TagDetection
from tagloc.tags.covariance import NoiseModel


def test_pose3_and_covariance_order_match_gtsam() -> None:
    rng = np.random.default_rng(0)
    T = SE3.random(rng)
    pose = to_pose3(T)
    assert np.allclose(pose.matrix(), T.as_matrix())
    assert from_pose3(pose).allclose(T)
    # tagloc tangent [x, y, z, rx, ry, rz] vs GTSAM [rx, ry, rz, x, y, z]: same retraction
    tau = rng.normal(size=6) * 0.1
    gtsam_tau = np.concatenate([tau[3:], tau[:3]])
    assert np.allclose(pose.retract(gtsam_tau).matrix(), (T @ SE3.exp(tau)).as_matrix(), atol=1e-9)
    A = rng.normal(size=(6, 6))
    cov = A @ A.T
    assert np.allclose(cov_from_gtsam(cov_to_gtsam(cov)), cov)
    assert np.allclose(cov_to_gtsam(cov)[:3, :3], cov[3:, 3:])


def test_odometry_is_interpolated_at_frame_stamps() -> None:
    stamps = np.array([0, 1_000_000_000], dtype=np.int64)
    T = SE3.stack([SE3.identity(), SE3.from_rotvec([0.0, 0.0, 0.2], [1.0, 2.0, 0.0])])
    survey = Survey(stamps, T, (), {}, {})
    mid = interpolate_odometry(survey, np.array([250_000_000]))
    assert np.allclose(mid.translation, [[0.25, 0.5, 0.0]])
    assert np.allclose(mid.rotation.as_rotvec(), [[0.0, 0.0, 0.05]])


def _random_walk_truth(rng: np.random.Generator, n: int = 400) -> np.ndarray:
    M_true = [np.eye(4)]
    for _ in range(n):
        step = SE3.from_rotvec([0, 0, rng.normal(0, 0.1)], [0.1, rng.normal(0, 0.01), 0])
        M_true.append(M_true[-1] @ step.as_matrix())
    return np.array(M_true)


def test_calibration_recovers_known_systematic_odometry_errors() -> None:
    truth = _random_walk_truth(np.random.default_rng(3))
    known = OdometryCalibration(
        scale=0.04, lateral_per_m=0.01, turn_scale=0.02, yaw_bias_per_m=1e-3
    )
    corrupted = apply_calibration(truth, known)
    fit = fit_calibration(corrupted, truth)  # what maps corrupted steps back to the truth
    assert fit.scale == pytest.approx(1 / 1.04 - 1, abs=1e-3)
    assert fit.lateral_per_m == pytest.approx(-0.01 / 1.04, abs=1e-3)
    assert fit.turn_scale == pytest.approx(1 / 1.02 - 1, abs=2e-3)
    assert np.allclose(apply_calibration(corrupted, fit)[:, :3, 3], truth[:, :3, 3], atol=0.05)
    c = calibration_vector(known)
    assert calibration_from_vector(c) == known and c.shape == (N_CALIBRATION,)


def _numeric_jacobian(f: Callable[[np.ndarray], np.ndarray], n: int, h: float = 1e-6) -> np.ndarray:
    """Central differences of ``f(delta)`` (``delta`` of length ``n``) at 0."""
    columns = []
    for i in range(n):
        d = np.zeros(n)
        d[i] = h
        columns.append((f(d) - f(-d)) / (2 * h))
    return np.stack(columns, axis=-1)


def test_odometry_jacobians_match_numerical_differences() -> None:
    rng = np.random.default_rng(0)
    M_map_base = SE3.exp(rng.normal(size=(4, 6)) * [1, 1, 0.1, 0.05, 0.05, 1]).as_matrix()
    M_odom = M_map_base @ SE3.exp(rng.normal(size=(4, 6)) * 0.05).as_matrix()
    step = inverse_h(M_odom[:-1]) @ M_odom[1:]
    c = rng.normal(size=N_CALIBRATION) * 0.02
    # per-axis sigmas along rotated axes (a body that is not upright), as the builder whitens
    ups = rng.normal(size=(3, 3))
    sigmas = AxisWhitening(
        np.full((3, 6), 0.1) * [1, 1, 0.5, 0.3, 0.3, 1],
        rotations_to_z(ups / np.linalg.norm(ups, axis=1, keepdims=True)),
    )
    e, A_prev, A_next, A_c = linearize_odometry(M_map_base, step, c, sigmas, calibrate=True)
    assert A_c is not None
    assert np.allclose(e, odometry_residuals(M_map_base, step, c, sigmas))

    def moved(k: int, d: np.ndarray) -> np.ndarray:
        M = M_map_base.copy()
        M[k] = M[k] @ SE3.exp(d).as_matrix()
        return odometry_residuals(M, step, c, sigmas)

    for k in range(1, 3):  # keyframe k closes step k-1 and opens step k
        J = _numeric_jacobian(lambda d, k=k: moved(k, d), 6)
        assert np.allclose(J[k - 1], A_next[k - 1], atol=1e-5)
        assert np.allclose(J[k], A_prev[k], atol=1e-5)
    J_c = _numeric_jacobian(lambda d: odometry_residuals(M_map_base, step, c + d, sigmas), 4)
    assert np.allclose(J_c, A_c, atol=1e-5)


def test_calibration_derivative_matches_central_differences() -> None:
    rng = np.random.default_rng(3)
    n = 500
    rotvec = rng.normal(size=(n, 3)) * [0.05, 0.05, 0.8]
    step = SE3.from_rotvec(rotvec, rng.normal(size=(n, 3)) * [0.5, 0.2, 0.05]).as_matrix()
    c = rng.normal(size=N_CALIBRATION) * 0.05
    Z = corrected_steps(step, calibration_from_vector(c))
    h = 1e-6
    numeric = np.empty((n, 6, N_CALIBRATION))
    for i in range(N_CALIBRATION):
        dc = np.zeros(N_CALIBRATION)
        dc[i] = h
        plus = corrected_steps(step, calibration_from_vector(c + dc))
        minus = corrected_steps(step, calibration_from_vector(c - dc))
        Z_inv = inverse_h(Z)
        numeric[..., i] = (log_h(Z_inv @ plus) - log_h(Z_inv @ minus)) / (2 * h)
    assert np.abs(corrected_step_jacobians(step, Z) - numeric).max() < 1e-8


def test_corner_jacobians_match_numerical_differences() -> None:
    drive = simulate_drive(_short_world(), seed=0)
    survey = survey_from_drive(drive, ObservationConfig(seed=1), camera_stride=10)
    obs = collect_observations(survey, NoiseModel(sigma_px=0.3), 10.0)
    M_map_base = drive.ground_truth_at(obs.keyframe_stamps_ns).T_map_base.as_matrix()
    M_map_tag = {
        j: drive.world.T_map_tag(drive.world.find_tag(key[1])).as_matrix()
        for j, key in enumerate(obs.tag_keys)
    }
    idx = np.arange(min(len(obs), 20))
    args = (survey.cameras, survey.T_base_cam, 0.3)

    def residuals(M_base: np.ndarray, tags: dict[int, np.ndarray]) -> np.ndarray:
        M_tags = np.array([tags[int(j)] for j in obs.tag[idx]])
        return linearize_corners(obs, idx, M_base, M_tags, *args)[0].reshape(len(idx), 8)

    M_tags = np.array([M_map_tag[int(j)] for j in obs.tag[idx]])
    r, J, M_base_tag = linearize_corners(obs, idx, M_map_base, M_tags, *args)
    A_base, A_tag, b = corner_jacobians(r, J, M_base_tag, obs.tag[idx], "cauchy", 1e9)
    assert np.allclose(b, -r.reshape(-1, 8))
    for m in idx[:5]:
        k, j = int(obs.keyframe[m]), int(obs.tag[m])

        def move_base(d: np.ndarray, k: int = k) -> np.ndarray:
            M = M_map_base.copy()
            M[k] = M[k] @ SE3.exp(d).as_matrix()
            return residuals(M, M_map_tag)

        def move_tag(d: np.ndarray, j: int = j) -> np.ndarray:
            return residuals(M_map_base, {**M_map_tag, j: M_map_tag[j] @ SE3.exp(d).as_matrix()})

        assert np.allclose(_numeric_jacobian(move_base, 6)[m], A_base[m], rtol=1e-4, atol=1e-3)
        assert np.allclose(_numeric_jacobian(move_tag, 6)[m], A_tag[m], rtol=1e-4, atol=1e-3)


def test_gross_outliers_are_single_views_not_a_misplaced_tag() -> None:
    tag = np.array([0, 0, 0, 0, 1, 1, 1])
    chi = np.array([2.0, 3.0, 2.5, 400.0, 80.0, 90.0, 85.0])
    assert gross_outliers(chi, tag).tolist() == [False, False, False, True, False, False, False]


def test_odometry_noise_matches_the_simulated_random_walk() -> None:
    world = load_default_world()
    legged = world.robot.odometry.model_copy(
        update={"scale_error": 0.0, "yaw_scale_error": 0.0, "yaw_bias_deg_per_m": 0.0,
                "lateral_drift": 0.0}
    )  # fmt: skip
    i = np.arange(20_001)
    yaw = np.cumsum(np.where((i // 500) % 2 == 0, 0.0, 0.01))  # straight, turn, straight, ...
    xy = np.cumsum(0.008 * np.column_stack([np.cos(yaw), np.sin(yaw)]), axis=0)
    truth = se3_from_xy_yaw(np.column_stack([xy, yaw])).as_matrix()
    errors, sigmas = [], []
    for seed in range(8):
        odom = simulate_odometry(legged, np.column_stack([xy, yaw]), seed=seed).as_matrix()
        key = np.arange(0, len(odom), 10)  # 10-sample keyframe steps, as the builder sees them
        step_true = inverse_h(truth[key][:-1]) @ truth[key][1:]
        step_odom = inverse_h(odom[key][:-1]) @ odom[key][1:]
        errors.append(SE3.from_matrix(inverse_h(step_true) @ step_odom, normalize=True).log())
        sigmas.append(odometry_whitening(odom[key], odometry_noise_of(legged)).sigmas)
    z = np.concatenate(errors) / np.concatenate(sigmas)
    rms = np.sqrt(np.mean(z**2, axis=0))
    assert np.allclose(rms[[0, 1, 5]], 1.0, atol=0.1)  # x, y, yaw: the model's variance
    assert np.allclose(rms[2:5], 0.0, atol=1e-6)  # planar odometry: no z, roll, pitch error


def test_consensus_rotation_picks_the_branch_that_repeats() -> None:
    rng = np.random.default_rng(5)
    R_true = SE3.from_rotvec([0.3, -0.2, 1.0], [0, 0, 0]).rotation.as_matrix()
    both = []
    for _ in range(40):
        right = R_true @ SE3.exp(np.r_[0, 0, 0, rng.normal(0, 0.01, 3)]).rotation.as_matrix()
        wrong = R_true @ SE3.exp(np.r_[0, 0, 0, rng.normal(0, 0.5, 3)]).rotation.as_matrix()
        both.append([wrong, right] if rng.random() < 0.6 else [right, wrong])  # best is wrong
    R = consensus_rotation(np.array(both))
    angle = np.degrees(np.arccos(np.clip((np.trace(R_true.T @ R) - 1.0) / 2.0, -1.0, 1.0)))
    assert angle < 3.0


def _tiny_survey(**kw: object) -> Survey:
    world = load_default_world()
    camera = world.robot.camera.camera_model()
    det = TagDetection(5, "tag36h11", np.array([[600, 300], [680, 300], [680, 380], [600, 380.0]]))
    args: dict[str, object] = {
        "odom_stamps_ns": np.array([0, 10**9], dtype=np.int64),
        "T_odom_base": SE3.stack([SE3.identity(), SE3.identity()]),
        "frames": (CameraFrame(5 * 10**8, "cam0", (det,)),),
        "cameras": {"cam0": camera},
        "T_base_cam": {"cam0": world.robot.camera.T_base_cam.T_base_cam()},
        "source": "tiny",
    }
    args.update(kw)
    return Survey(**args)  # type: ignore[arg-type]


def test_bad_surveys_fail_with_one_clear_message() -> None:
    with pytest.raises(MappingError, match="tiny: odometry: need at least 2 samples"):
        _tiny_survey(odom_stamps_ns=np.array([0]), T_odom_base=SE3.stack([SE3.identity()]))
    with pytest.raises(MappingError, match="tag tag36h11:5 is observed but has no known size"):
        build_tag_map(_tiny_survey())
    with pytest.raises(MappingError, match="anchor tag tag36h11:9 is never observed"):
        build_tag_map(_tiny_survey(default_tag_size=0.16), {9: SE3.identity()})
    with pytest.raises(MappingError, match="camera 'cam1' has no model"):
        _tiny_survey(frames=(CameraFrame(0, "cam1", ()),))


def test_first_tag_is_the_origin_without_anchors() -> None:
    tag_map, report = build_tag_map(_tiny_survey(default_tag_size=0.16))
    assert tag_map.ids() == (5,) and tag_map.get(5) is not None
    assert tag_map.T_frame_tag(5).allclose(SE3.identity(), atol=1e-6)
    assert report.reproj_rms_px < 0.01
    assert gtsam.__name__ == "gtsam"


def _short_world() -> World:
    """The office with its route cut to the corridor's west end (a few seconds of driving)."""
    world = load_default_world()
    route = world.route.model_copy(update={"waypoints": world.route.waypoints[:3], "repeat": 1})
    return world.model_copy(update={"route": route})
