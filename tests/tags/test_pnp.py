"""Single-tag and joint PnP against simulator ground truth and OpenCV.

Oracles: exact corners projected by the camera model (the pose must come back exactly), OpenCV's
own IPPE_SQUARE and ITERATIVE solvers, numeric differentiation for the Jacobian, and seeded
corner-noise simulation for the accuracy targets. The helpers at the top (camera, wall views,
noisy corners) are shared with ``test_covariance.py`` and ``test_gates.py``.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from tagloc.camera import PinholeRadtan
from tagloc.eval.tag_views import sample_wall_view
from tagloc.geometry import SE3, SO3
from tagloc.tags._refine import _residuals
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.detection import TagDetection, tag_object_points
from tagloc.tags.observation import ObservationResult, PosePrior, observe_tags
from tagloc.tags.pnp import (
    TagPoseError,
    TagPoseEstimate,
    estimate_joint_pose,
    estimate_tag_pose,
    estimate_tag_poses,
)

FloatArray = npt.NDArray[np.float64]

#: The reference setup: 1280x720, 90 deg horizontal FOV (fx = 640), 0.16 m tags.
CAMERA = PinholeRadtan(width=1280, height=720, fx=640.0, fy=640.0, cx=639.5, cy=359.5)
#: The same with a real lens' distortion, for the OpenCV cross-checks.
CAMERA_DISTORTED = PinholeRadtan(
    width=1280,
    height=720,
    fx=640.0,
    fy=641.0,
    cx=641.2,
    cy=357.9,
    k1=-0.12,
    k2=0.02,
    p1=0.0008,
    p2=-0.0005,
    k3=0.0,
)
SIZE = 0.16


def wall_view(
    distance: float, angle_rad: float, rng: np.random.Generator, tilt_deg: float = 1.0
) -> tuple[SE3, SE3]:
    """An upright tag on a vertical wall seen by a nearly level camera at the map origin
    (:func:`tagloc.eval.tag_views.sample_wall_view`, which the rendered sweep uses too)."""
    return sample_wall_view(distance, angle_rad, rng, tilt_deg)


def simulate_corners(
    T_cam_tag: SE3,
    sigma: float,
    rng: np.random.Generator,
    bias_px: float = 0.0,
    size_error_rel: float = 0.0,
) -> FloatArray:
    """Corners with Gaussian noise ``sigma``, an inward bias and a printed-size error."""
    corners = corners_of(T_cam_tag, size=SIZE * (1.0 + size_error_rel))
    inward = corners.mean(axis=0) - corners
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    noisy: FloatArray = corners + bias_px * inward + rng.normal(0.0, sigma, (4, 2))
    return noisy


def observe_cell(
    distance: float,
    angle_deg: float,
    sigma: float,
    n: int,
    prior: str,
    seed: int,
    bias_px: float = 0.0,
    size_error_rel: float = 0.0,
    noise: NoiseModel | None = None,
) -> list[tuple[SE3, ObservationResult]]:
    """``n`` seeded views of one (distance, angle) cell through :func:`observe_tags`.

    ``prior`` is ``"none"``, ``"gravity"`` (the camera's up with 1 deg error, sigma 3 deg) or
    ``"rotation"`` (also a predicted ``T_map_cam`` with 2 deg error per axis, sigma 3 deg).
    Returns the true ``T_cam_tag`` and the result of each view.
    """
    rng = np.random.default_rng(seed)
    noise = noise or NoiseModel(sigma_px=sigma)
    out = []
    for _ in range(n):
        T_cam_tag, T_map_cam = wall_view(distance, np.deg2rad(angle_deg), rng)
        corners = simulate_corners(T_cam_tag, sigma, rng, bias_px, size_error_rel * rng.normal())
        pose_prior = None
        if prior != "none":
            measured = T_map_cam.rotation @ SO3.from_rotvec(np.deg2rad(1.0) * rng.normal(size=3))
            up_cam = measured.inverse().act(np.array([0.0, 0.0, 1.0]))
            predicted = None
            if prior == "rotation":
                predicted = T_map_cam.plus(np.r_[0, 0, 0, np.deg2rad(2.0) * rng.normal(size=3)])
            pose_prior = PosePrior(predicted, np.deg2rad(3.0), up_cam, np.deg2rad(3.0))
        detection = TagDetection(0, "tag36h11", corners, 0, 60.0)
        result = observe_tags(
            [detection],
            CAMERA,
            SIZE,
            tag_poses={0: T_map_cam @ T_cam_tag},
            prior=pose_prior,
            noise=noise,
        )
        out.append((T_cam_tag, result))
    return out


def corners_of(T_cam_tag: SE3, camera: PinholeRadtan = CAMERA, size: float = SIZE) -> FloatArray:
    """Exact corners ``(4, 2)`` of a tag at ``T_cam_tag``."""
    return camera.project(T_cam_tag.act(tag_object_points(size)))


def rotation_error_deg(T_true: SE3, T_est: SE3) -> float:
    return float(np.rad2deg(np.linalg.norm((T_true.inverse() @ T_est).rotation.log())))


def _oracle_branch(T_true: SE3, estimate: TagPoseEstimate | None) -> SE3:
    """The branch closest in rotation to the truth (a perfect prior)."""
    assert estimate is not None
    cands = [estimate.T_cam_tag, estimate.T_cam_tag_alt]
    return min(cands, key=lambda T: rotation_error_deg(T_true, T))


def _random_views(n: int, seed: int, camera: PinholeRadtan = CAMERA) -> list[SE3]:
    rng = np.random.default_rng(seed)
    return [
        wall_view(rng.uniform(0.5, 3.0), np.deg2rad(rng.uniform(20, 65)), rng)[0] for _ in range(n)
    ]


# ----- conventions and exactness ---------------------------------------------------------------


def test_tag_object_points_are_the_ippe_square_frame() -> None:
    # OpenCV's IPPE_SQUARE on exact corners (real K, no distortion) returns our T_cam_tag.
    T, _ = wall_view(1.2, np.deg2rad(35.0), np.random.default_rng(1))
    _, rvecs, tvecs, _ = cv2.solvePnPGeneric(
        tag_object_points(SIZE), corners_of(T), CAMERA.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE
    )
    errors = [
        rotation_error_deg(T, SE3.from_rotvec(np.ravel(r), np.ravel(t)))
        for r, t in zip(rvecs, tvecs, strict=True)
    ]
    assert min(errors) < 1e-6


@pytest.mark.parametrize("camera", [CAMERA, CAMERA_DISTORTED], ids=["pinhole", "radtan"])
def test_exact_corners_give_the_exact_pose_and_both_branches(camera: PinholeRadtan) -> None:
    views = _random_views(12, seed=2, camera=camera)
    corners = np.stack([corners_of(T, camera) for T in views])
    estimates = estimate_tag_poses(range(12), corners, [SIZE] * 12, camera, NoiseModel())
    for T, est in zip(views, estimates, strict=True):
        assert est is not None
        assert est.T_cam_tag.allclose(T, atol=1e-8)
        assert est.reproj_err_px < 1e-6
        assert est.reproj_err_alt_px > 0.05  # the mirrored branch does not fit exact corners
        assert est.ambiguity_ratio < 1e-4
        assert est.range_m == pytest.approx(np.linalg.norm(T.translation))
        normal, to_cam = T.rotation.matrix[:, 2], -T.translation / np.linalg.norm(T.translation)
        assert est.view_angle_rad == pytest.approx(np.arccos(normal @ to_cam), abs=1e-9)


def test_reprojection_jacobian_matches_numeric_right_perturbation() -> None:
    T, _ = wall_view(1.5, np.deg2rad(40.0), np.random.default_rng(3))
    points = tag_object_points(SIZE)[None]
    pixels = corners_of(T, CAMERA_DISTORTED)[None] + 0.3
    r0, J, _ = _residuals(
        CAMERA_DISTORTED, T.rotation.matrix[None], T.translation[None], points, pixels
    )
    eps = 1e-6
    for i in range(6):
        step = np.zeros(6)
        step[i] = eps
        Tp = T.plus(step)
        rp, _, _ = _residuals(
            CAMERA_DISTORTED, Tp.rotation.matrix[None], Tp.translation[None], points, pixels
        )
        np.testing.assert_allclose((rp - r0)[0] / eps, J[0, :, i], rtol=1e-4, atol=1e-3)


# ----- OpenCV cross-checks ---------------------------------------------------------------------


def test_refined_pose_reprojects_no_worse_than_opencv_ippe() -> None:
    rng = np.random.default_rng(4)
    views = _random_views(40, seed=5, camera=CAMERA_DISTORTED)
    corners = np.stack([corners_of(T, CAMERA_DISTORTED) for T in views])
    corners += rng.normal(0.0, 0.5, corners.shape)
    estimates = estimate_tag_poses(range(40), corners, [SIZE] * 40, CAMERA_DISTORTED)
    points = tag_object_points(SIZE)
    K, dist = CAMERA_DISTORTED.K, CAMERA_DISTORTED.dist_coeffs
    for c, est in zip(corners, estimates, strict=True):
        assert est is not None
        _, rvecs, tvecs, _ = cv2.solvePnPGeneric(points, c, K, dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        ippe_rms = min(
            np.sqrt(
                np.mean(
                    np.sum((cv2.projectPoints(points, r, t, K, dist)[0][:, 0] - c) ** 2, axis=1)
                )
            )
            for r, t in zip(rvecs, tvecs, strict=True)
        )
        assert est.reproj_err_px <= ippe_rms + 1e-9


def test_agrees_with_opencv_iterative_on_easy_views() -> None:
    rng = np.random.default_rng(6)
    K, dist = CAMERA_DISTORTED.K, CAMERA_DISTORTED.dist_coeffs
    points = tag_object_points(SIZE)
    for _ in range(10):
        T, _ = wall_view(rng.uniform(0.6, 1.5), np.deg2rad(rng.uniform(30, 60)), rng)
        c = corners_of(T, CAMERA_DISTORTED) + rng.normal(0.0, 0.3, (4, 2))
        est = estimate_tag_pose(TagDetection(7, "tag36h11", c), CAMERA_DISTORTED, SIZE)
        rvec0, tvec0 = cv2.Rodrigues(est.T_cam_tag.rotation.matrix)[0], est.T_cam_tag.translation
        ok, rvec, tvec = cv2.solvePnP(
            points,
            c,
            K,
            dist,
            rvec0.copy(),
            tvec0.copy().reshape(3, 1),
            useExtrinsicGuess=True,
            flags=cv2.SOLVEPNP_ITERATIVE,
        )
        assert ok
        T_cv = SE3.from_rotvec(np.ravel(rvec), np.ravel(tvec))
        assert rotation_error_deg(T_cv, est.T_cam_tag) < 1e-3
        assert np.linalg.norm(T_cv.translation - est.T_cam_tag.translation) < 1e-5
        # and from OpenCV's own initialization (homography) on these easy views
        ok, rvec, tvec = cv2.solvePnP(points, c, K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        T_cv = SE3.from_rotvec(np.ravel(rvec), np.ravel(tvec))
        assert rotation_error_deg(T_cv, est.T_cam_tag) < 0.05


# ----- accuracy --------------------------------------------------------------------------------


def _accuracy(distance: float, angle_deg: float, sigma: float, n: int = 150) -> tuple[float, float]:
    """Median position (m) and rotation (deg) error of the branch nearest the truth."""
    rng = np.random.default_rng(int(100 * distance + angle_deg))
    views = [wall_view(distance, np.deg2rad(angle_deg), rng)[0] for _ in range(n)]
    corners = np.stack([corners_of(T) for T in views]) + rng.normal(0.0, sigma, (n, 4, 2))
    estimates = estimate_tag_poses(
        range(n), corners, [SIZE] * n, CAMERA, NoiseModel(sigma_px=sigma)
    )
    pos, rot = [], []
    for T, est in zip(views, estimates, strict=True):
        T_est = _oracle_branch(T, est)
        pos.append(np.linalg.norm(T_est.translation - T.translation))
        rot.append(rotation_error_deg(T, T_est))
    return float(np.median(pos)), float(np.median(rot))


@pytest.mark.parametrize("angle_deg", [15.0, 30.0, 60.0])
def test_accuracy_targets_for_a_016_m_tag_at_1280x720(angle_deg: float) -> None:
    # AprilTag 3 corners on sharp images: ~0.1 px (measured numbers for 0.2-0.5 px in the
    # position scales with sigma, so 0.3 px still meets the 2 m target).
    pos2, rot2 = _accuracy(2.0, angle_deg, 0.1)
    pos4, _ = _accuracy(4.0, angle_deg, 0.1)
    assert pos2 <= 0.01
    assert pos4 <= 0.03
    assert rot2 <= 1.0
    assert _accuracy(2.0, angle_deg, 0.3)[0] <= 0.01


def test_refinement_fixes_the_face_on_tilt_of_ippe() -> None:
    # Face-on at 1 m, 0.1 px: raw IPPE ~3 deg median rotation error, refined < 1 deg.
    rng = np.random.default_rng(8)
    points = tag_object_points(SIZE)
    raw, refined = [], []
    for _ in range(100):
        T, _ = wall_view(1.0, 0.0, rng)
        c = corners_of(T) + rng.normal(0.0, 0.1, (4, 2))
        _, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            points, c, CAMERA.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        raw.append(
            min(
                rotation_error_deg(T, SE3.from_rotvec(np.ravel(r), np.ravel(t)))
                for r, t in zip(rvecs, tvecs, strict=True)
            )
        )
        refined.append(
            rotation_error_deg(
                T,
                _oracle_branch(T, estimate_tag_pose(TagDetection(1, "tag36h11", c), CAMERA, SIZE)),
            )
        )
    assert np.median(refined) < 1.0
    assert np.median(refined) < 0.5 * np.median(raw)


# ----- joint PnP -------------------------------------------------------------------------------


def wall_tags(xs: list[float], heights: list[float]) -> dict[int, SE3]:
    """Upright tags on the wall ``y = 5`` of the map, facing ``-y`` (z up)."""
    z_tag, y_tag = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    R = SO3.from_matrix(np.stack([np.cross(y_tag, z_tag), y_tag, z_tag], axis=1))
    return {
        i: SE3(rotation=R, translation=np.array([x, 5.0, h]))
        for i, (x, h) in enumerate(zip(xs, heights, strict=True))
    }


def level_camera(x: float, y: float, z: float, yaw: float) -> SE3:
    """``T_map_cam`` of a level camera looking along map ``+y`` turned by ``yaw`` about ``+z``."""
    forward = np.array([np.sin(yaw), np.cos(yaw), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    return SE3(
        rotation=SO3.from_matrix(np.stack([np.cross(down, forward), down, forward], axis=1)),
        translation=np.array([x, y, z]),
    )


def test_joint_pose_is_exact_on_exact_corners_and_carries_base() -> None:
    tags = wall_tags([-0.4, 0.0, 0.5], [1.0, 1.3, 1.1])
    T_map_cam = level_camera(0.3, 2.5, 1.2, 0.3)
    estimates, corners = [], []
    for tag_id, T_map_tag in tags.items():
        c = corners_of(T_map_cam.inverse() @ T_map_tag, CAMERA_DISTORTED)
        estimates.append(
            estimate_tag_pose(TagDetection(tag_id, "tag36h11", c), CAMERA_DISTORTED, SIZE)
        )
        corners.append(c)
    T_base_cam = SE3.from_rotvec([0.0, 0.0, 0.1], [0.2, 0.0, 0.5])
    joint = estimate_joint_pose(
        estimates, np.array(corners), list(tags.values()), CAMERA_DISTORTED, T_base_cam=T_base_cam
    )
    assert joint is not None
    assert joint.T_map_cam.allclose(T_map_cam, atol=1e-8)
    assert joint.reproj_err_px < 1e-6
    assert joint.T_map_base is not None
    assert joint.T_map_base.allclose(T_map_cam @ T_base_cam.inverse(), atol=1e-8)
    assert joint.tag_ids == (0, 1, 2)


@pytest.mark.parametrize("n_tags", [2, 4])
def test_joint_pnp_is_no_worse_than_the_best_single_tag_and_within_1_deg_face_on(
    n_tags: int,
) -> None:
    tags = wall_tags(list(np.linspace(-0.5, 0.5, n_tags)), [1.0, 1.25] * (n_tags // 2))
    T_map_cam = level_camera(0.0, 3.0, 1.1, 0.0)  # 2 m from the wall, face-on
    rng = np.random.default_rng(9 + n_tags)
    joint_rot, best_single_rot = [], []
    for _ in range(60):
        estimates, corners = [], []
        for tag_id, T_map_tag in tags.items():
            c = corners_of(T_map_cam.inverse() @ T_map_tag) + rng.normal(0.0, 0.3, (4, 2))
            estimates.append(
                estimate_tag_pose(
                    TagDetection(tag_id, "tag36h11", c), CAMERA, SIZE, NoiseModel(sigma_px=0.3)
                )
            )
            corners.append(c)
        joint = estimate_joint_pose(
            estimates, np.array(corners), list(tags.values()), CAMERA, NoiseModel(sigma_px=0.3)
        )
        assert joint is not None
        joint_rot.append(rotation_error_deg(T_map_cam, joint.T_map_cam))
        singles = [
            rotation_error_deg(T_map_cam, tags[e.tag_id] @ e.T_cam_tag.inverse()) for e in estimates
        ]
        best_single_rot.append(min(singles))
    assert np.median(joint_rot) <= 1.0
    assert np.median(joint_rot) <= np.median(best_single_rot)


def test_coplanar_tags_seen_obliquely_agree_on_the_sheet_normal() -> None:
    # A flat sheet with 6 tags (0.25 m apart) seen at 55 deg from 1.2 m; each tag's own normal
    # must agree with the sheet's within 3 deg.
    rng = np.random.default_rng(10)
    sheet = SE3.from_rotvec([0.0, np.deg2rad(55.0), 0.0], [0.1, -0.05, 1.2]) @ SE3.from_rotvec(
        [np.pi, 0.0, 0.0], [0.0, 0.0, 0.0]
    )
    offsets = [(x, y) for x in (-0.25, 0.0, 0.25) for y in (-0.12, 0.12)]
    normal_cam = sheet.rotation.matrix[:, 2]
    for _ in range(20):
        corners = []
        for x, y in offsets:
            T_cam_tag = sheet @ SE3.from_rotvec([0.0, 0.0, 0.0], [x, y, 0.0])
            corners.append(corners_of(T_cam_tag) + rng.normal(0.0, 0.3, (4, 2)))
        estimates = estimate_tag_poses(
            range(6), np.array(corners), [SIZE] * 6, CAMERA, NoiseModel(sigma_px=0.3)
        )
        for est in estimates:
            assert est is not None
            n_est = est.T_cam_tag.rotation.matrix[:, 2]
            assert np.rad2deg(np.arccos(np.clip(n_est @ normal_cam, -1, 1))) < 3.0


# ----- degenerate input ------------------------------------------------------------------------


def test_degenerate_corners_give_none_and_the_single_api_raises() -> None:
    fisheye_like = PinholeRadtan(
        width=640, height=480, fx=300.0, fy=300.0, cx=319.5, cy=239.5, k1=-0.4
    )  # fold at a normalized radius of ~0.9
    far_outside = np.array(
        [[-5000.0, -5000.0], [5000.0, -5000.0], [5000.0, 5000.0], [-5000.0, 5000.0]]
    )
    good = np.array([[300.0, 200.0], [340.0, 200.0], [340.0, 240.0], [300.0, 240.0]])
    estimates = estimate_tag_poses(
        [1, 2], np.stack([far_outside, good]), [SIZE, SIZE], fisheye_like
    )
    assert estimates[0] is None
    assert estimates[1] is not None
    with pytest.raises(TagPoseError, match="tag tag36h11:1"):
        estimate_tag_pose(TagDetection(1, "tag36h11", far_outside), fisheye_like, SIZE)


def test_swapped_exchanges_the_branches() -> None:
    T, _ = wall_view(2.0, np.deg2rad(20.0), np.random.default_rng(11))
    c = corners_of(T) + np.random.default_rng(12).normal(0.0, 0.3, (4, 2))
    est = estimate_tag_pose(TagDetection(3, "tag36h11", c), CAMERA, SIZE)
    alt = est.swapped()
    assert alt.T_cam_tag is est.T_cam_tag_alt and alt.T_cam_tag_alt is est.T_cam_tag
    assert alt.ambiguity_ratio == pytest.approx(1.0 / est.ambiguity_ratio)
    assert alt.swapped().view_angle_rad == pytest.approx(est.view_angle_rad)
