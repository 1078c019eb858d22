"""dimos messages <-> tagloc records: what survives LCM, against the records themselves."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from dimos.msgs.geometry_msgs.PoseWithCovarianceStamped import PoseWithCovarianceStamped
from dimos.msgs.sensor_msgs.CompressedImage import CompressedImage
from dimos.msgs.sensor_msgs.Image import Image, ImageFormat
from drive import drive
from harness import decoded

from tagloc.adapters.dimos import convert
from tagloc.adapters.dimos.convert import DimosInputError
from tagloc.geometry import SE3
from tagloc.io.convert import cov_body_from_ros
from tagloc.messages import CameraInfoMsg, ImageMsg, PointCloudMsg, TransformMsg


def test_records_survive_the_round_trip_through_lcm() -> None:
    d = drive("odom")
    seen = set()
    for r in d.records:
        back = decoded(r)
        assert type(back) is type(r) and back.stamp_ns == r.stamp_ns
        seen.add(type(r))
        if isinstance(r, TransformMsg):
            assert (back.parent, back.child, back.static) == (r.parent, r.child, r.static)
            np.testing.assert_allclose(back.T_parent_child.as_matrix(),
                                       r.T_parent_child.as_matrix(), rtol=0, atol=1e-15)
        elif isinstance(r, ImageMsg):
            assert back.frame_id == r.frame_id and np.array_equal(back.image, r.image)
        elif isinstance(r, CameraInfoMsg):
            for key in ("width", "height", "distortion_model", "D", "K", "R", "P"):
                assert back.info[key] == r.info[key]
        elif isinstance(r, PointCloudMsg):
            assert np.array_equal(back.points, r.points, equal_nan=True)
            assert np.array_equal(back.intensity, r.intensity)
            # dimos carries per-point times as uint32 nanoseconds
            np.testing.assert_allclose(back.time_offset_s, r.time_offset_s, rtol=0, atol=1e-9)
    assert seen == {TransformMsg, ImageMsg, CameraInfoMsg, PointCloudMsg}


def test_color_and_jpeg_images_become_gray_or_bgr() -> None:
    rng = np.random.default_rng(0)
    bgr = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    rgb = Image(data=bgr[:, :, ::-1].copy(), format=ImageFormat.RGB, frame_id="cam", ts=12.5)
    gray = convert.image_msg(rgb)
    assert gray.encoding == "mono8" and gray.stamp_ns == 12_500_000_000
    np.testing.assert_array_equal(gray.image, cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
    ok, jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 100])
    assert ok
    msg = convert.image_msg(CompressedImage(data=jpeg.tobytes(), format="jpeg", ts=1.0), "cam")
    assert msg.frame_id == "cam" and msg.image.shape == (48, 64)
    diff = msg.image.astype(int) - cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(int)
    assert np.abs(diff).mean() < 3  # JPEG at quality 100
    with pytest.raises(DimosInputError, match="do not decode as jpeg"):
        convert.image_msg(CompressedImage(data=b"not a jpeg", format="jpeg", ts=1.0))
    depth = Image(data=np.zeros((4, 4), np.float32), format=ImageFormat.DEPTH, ts=1.0)
    with pytest.raises(DimosInputError, match="DEPTH"):
        convert.image_msg(depth)


def test_pose_covariance_is_ros_order_in_parent_axes() -> None:
    T = SE3.from_rotvec([0.1, -0.2, 1.3], [1.0, 2.0, 0.5])
    A = np.random.default_rng(1).normal(size=(6, 6))
    cov_body = A @ A.T
    msg = convert.pose_with_covariance(5_000_000_000, "map", T, cov_body)
    msg = PoseWithCovarianceStamped.lcm_decode(msg.lcm_encode())
    assert msg.frame_id == "map" and convert.stamp_ns(msg.ts) == 5_000_000_000
    back = cov_body_from_ros(np.asarray(msg.covariance).reshape(6, 6), T.rotation.matrix)
    np.testing.assert_allclose(back, cov_body, rtol=0, atol=1e-12)
    q = msg.pose.orientation
    np.testing.assert_allclose(np.abs(np.dot([q.x, q.y, q.z, q.w], T.as_quat())), 1.0, atol=1e-12)
