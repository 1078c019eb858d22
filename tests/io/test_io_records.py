"""Stream records (``tagloc.messages``): validation, immutability, the covariance convention."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.camera import from_camera_info
from tagloc.camera.radtan import PinholeRadtan
from tagloc.geometry import SE3, SO3
from tagloc.io import (
    CameraInfoMsg,
    GroundTruthMsg,
    ImageMsg,
    OdometryMsg,
    PoseWithCovarianceMsg,
    RecordError,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.io.convert import cov_body_from_ros, cov_ros_from_body

T = SE3.from_rotvec([0.1, -0.2, 0.3], [1.0, 2.0, 3.0])


def test_odometry_fields_are_validated_and_read_only() -> None:
    msg = OdometryMsg(np.int64(5), "odom", "base_link", T, np.eye(6).tolist(), [1, 0, 0, 0, 0, 0])
    assert type(msg.stamp_ns) is int and msg.stamp_ns == 5
    assert msg.cov.dtype == np.float64 and not msg.cov.flags.writeable
    assert msg.twist is not None and not msg.twist.flags.writeable
    with pytest.raises(AttributeError):
        msg.stamp_ns = 6  # type: ignore[misc]
    assert OdometryMsg(0, "odom", "base", T, np.eye(6)).twist is None


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"stamp_ns": -1}, "stamp_ns: must be >= 0"),
        ({"stamp_ns": 1.5}, "stamp_ns: expected int nanoseconds"),
        ({"stamp_ns": True}, "stamp_ns: expected int nanoseconds"),
        ({"frame_id": None}, "frame_id: expected a str"),
        ({"T_parent_child": np.eye(4)}, "T_parent_child: expected a single SE3"),
        ({"T_parent_child": SE3.identity(2)}, "T_parent_child: expected a single SE3, got a batch"),
        ({"cov": np.eye(3)}, r"cov: expected shape \(6, 6\)"),
        ({"cov": np.full((6, 6), np.nan)}, "cov: holds NaN"),
        ({"twist": [0.0] * 5}, r"twist: expected shape \(6,\)"),
    ],
)
def test_odometry_rejects_malformed_fields(kwargs: dict[str, object], match: str) -> None:
    fields: dict[str, object] = {
        "stamp_ns": 1,
        "frame_id": "odom",
        "child_frame_id": "base",
        "T_parent_child": T,
        "cov": np.eye(6),
    }
    with pytest.raises(RecordError, match=f"OdometryMsg.{match}"):
        OdometryMsg(**(fields | kwargs))  # type: ignore[arg-type]


def test_image_encoding_must_fit_the_array() -> None:
    gray = np.zeros((4, 5), np.uint8)
    msg = ImageMsg(0, "cam", gray, "mono8")
    assert not msg.image.flags.writeable and gray.flags.writeable  # copied, caller keeps its own
    ImageMsg(0, "cam", np.zeros((4, 5, 3), np.uint8), "bgr8")
    for image, encoding, match in [
        (gray, "rgb8", "encoding: 'rgb8' is not mono8 or bgr8"),
        (gray, "bgr8", r"expected a non-empty \(H, W, 3\) uint8 array for bgr8, got uint8 array"),
        (np.zeros((4, 5, 3), np.uint8), "mono8", r"non-empty \(H, W\) uint8 array for mono8"),
        (np.zeros((4, 5, 1), np.uint8), "mono8", r"non-empty \(H, W\) uint8 array for mono8"),
        (np.zeros(5, np.uint8), "mono8", r"non-empty \(H, W\) uint8 array for mono8"),
        (gray.astype(np.float32), "mono8", "got float32 array of shape"),
        (np.zeros((0, 5), np.uint8), "mono8", "non-empty"),
    ]:
        with pytest.raises(RecordError, match=match):
            ImageMsg(0, "cam", image, encoding)


def test_camera_info_is_frozen_and_reads_as_a_camera_model() -> None:
    model = PinholeRadtan(
        width=640, height=480, fx=500.0, fy=501.0, cx=320.5, cy=240.5, k1=0.1, k2=-0.05, p1=1e-3
    )
    info = {k.lower() if k in "DKRP" else k: v for k, v in model.to_camera_info().items()}
    msg = CameraInfoMsg(7, "cam", info)  # ROS 2 lower-case names are renamed
    assert set(msg.info) >= {"D", "K", "R", "P", "roi"}
    assert isinstance(msg.info["K"], tuple)
    with pytest.raises(TypeError):
        msg.info["width"] = 1  # type: ignore[index]
    back = from_camera_info(msg.info)
    assert np.allclose(back.K, model.K) and np.allclose(back.dist_coeffs, model.dist_coeffs)
    with pytest.raises(RecordError, match=r"missing field\(s\) \['K'\]"):
        CameraInfoMsg(0, "cam", {"width": 1, "height": 1, "distortion_model": "x", "D": []})


def test_transform_and_pose_records() -> None:
    tf = TransformMsg(3, "map", "odom", T, static=1)  # type: ignore[arg-type]
    assert tf.static is True
    with pytest.raises(RecordError, match=r"TransformMsg\.child: must be a non-empty frame name"):
        TransformMsg(3, "map", "", T)
    PoseWithCovarianceMsg(1, "map", T, np.eye(6))
    GroundTruthMsg(1, "map", T)
    with pytest.raises(RecordError, match=r"TagDetectionsMsg\.detections: expected TagDetection"):
        TagDetectionsMsg(1, "cam", ("not a detection",))  # type: ignore[arg-type]
    assert TagDetectionsMsg(1, "cam", []).detections == ()  # type: ignore[arg-type]


def test_ros_covariance_is_the_body_covariance_rotated_into_the_parent_frame() -> None:
    """Sample right perturbations, map them to ROS' (parent-frame translation, fixed-axis
    rotation) errors, and compare the sample covariance with ``cov_ros_from_body``."""
    rng = np.random.default_rng(7)
    pose = SE3.from_rotvec([0.4, -1.1, 0.7], [2.0, -1.0, 0.5])
    A = rng.normal(size=(6, 6)) * 1e-3
    cov_body = A @ A.T
    xi = rng.multivariate_normal(np.zeros(6), cov_body, size=20_000)
    perturbed = pose @ SE3.exp(xi)
    d_t = perturbed.translation - pose.translation
    d_r = (perturbed.rotation @ SO3.stack([pose.rotation.inverse()])).log()
    cov_sampled = np.cov(np.hstack([d_t, d_r]).T)
    cov_ros = cov_ros_from_body(cov_body, pose.rotation.matrix)
    assert np.allclose(cov_sampled, cov_ros, atol=0.05 * np.abs(cov_ros).max())
    assert np.allclose(cov_body_from_ros(cov_ros, pose.rotation.matrix), cov_body, atol=1e-18)
