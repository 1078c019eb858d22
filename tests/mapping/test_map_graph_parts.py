"""Pieces of the map builder against independent oracles: GTSAM, known synthetic errors."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from tagloc.geometry import SE3
from tagloc.mapping import CameraFrame, MappingError, Survey, build_tag_map
from tagloc.mapping.calibration import OdometryCalibration, apply_calibration, fit_calibration
from tagloc.mapping.gtsam_bridge import cov_from_gtsam, cov_to_gtsam, from_pose3, to_pose3
from tagloc.mapping.initialize import consensus_rotation
from tagloc.mapping.observations import interpolate_odometry
from tagloc.sim import load_default_world
from tagloc.tags import TagDetection


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


def test_calibration_recovers_known_systematic_odometry_errors() -> None:
    rng = np.random.default_rng(3)
    steps = [SE3.from_rotvec([0, 0, rng.normal(0, 0.1)], [0.1, rng.normal(0, 0.01), 0])]
    for _ in range(400):
        steps.append(SE3.from_rotvec([0, 0, rng.normal(0, 0.1)], [0.1, rng.normal(0, 0.01), 0]))
    M_true = [np.eye(4)]
    for step in steps:
        M_true.append(M_true[-1] @ step.as_matrix())
    truth = np.array(M_true)
    known = OdometryCalibration(np.diag([1.04, 1.04, 1.0]), 0.02, 0.001)
    corrupted = apply_calibration(truth, known)
    fit = fit_calibration(corrupted, truth)  # what maps corrupted steps back to the truth
    assert np.allclose(fit.S[:2, :2], np.diag([1 / 1.04, 1 / 1.04]), atol=1e-3)
    assert np.allclose(apply_calibration(corrupted, fit)[:, :3, 3], truth[:, :3, 3], atol=0.05)


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
