"""Chain lookups through the frame tree, checked against 4x4 matrices composed by hand."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pytest
from scipy.spatial.transform import Rotation

from tagloc.errors import DisconnectedFramesError
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3

Mat = npt.NDArray[np.float64]
MS = 1_000_000


def _random_poses(rng: np.random.Generator, n: int | None = None, scale: float = 1.0) -> SE3:
    """Uniform rotations and Gaussian translations (scipy draws the rotations)."""
    quat_xyzw = Rotation.random(n, random_state=rng).as_quat()
    return SE3.from_quat(quat_xyzw, scale * rng.normal(size=(3,) if n is None else (n, 3)))


@dataclass
class Robot:
    """A buffer with map -> odom -> base_link (dynamic) -> camera_mount -> camera_optical (static)
    and the matrices it was filled with."""

    buffer: TransformBuffer
    stamps: npt.NDArray[np.int64]
    M_map_odom: Mat  # (N, 4, 4)
    M_odom_base: Mat  # (N, 4, 4)
    M_base_mount: Mat
    M_mount_optical: Mat


def _robot(seed: int = 0) -> Robot:
    rng = np.random.default_rng(seed)
    stamps = np.arange(50) * 20 * MS + 1_000_000_000_000
    T_map_odom = _random_poses(rng, len(stamps))
    T_odom_base = _random_poses(rng, len(stamps), scale=3.0)
    T_base_mount, T_mount_optical = _random_poses(rng), _random_poses(rng)
    buffer = TransformBuffer()
    for i, stamp in enumerate(stamps.tolist()):
        buffer.set_transform("map", "odom", stamp, T_map_odom[i])
        buffer.set_transform("odom", "base_link", stamp, T_odom_base[i])
    buffer.set_static("base_link", "camera_mount", T_base_mount)
    buffer.set_static("camera_mount", "camera_optical", T_mount_optical)
    return Robot(
        buffer,
        stamps,
        T_map_odom.as_matrix(),
        T_odom_base.as_matrix(),
        T_base_mount.as_matrix(),
        T_mount_optical.as_matrix(),
    )


@pytest.fixture
def robot() -> Robot:
    return _robot()


def test_chain_matches_hand_composed_matrices(robot: Robot) -> None:
    for i in (0, 17, 49):
        M_map_optical = (
            robot.M_map_odom[i] @ robot.M_odom_base[i] @ robot.M_base_mount @ robot.M_mount_optical
        )
        got = robot.buffer.lookup("map", "camera_optical", int(robot.stamps[i]))
        np.testing.assert_allclose(got.as_matrix(), M_map_optical, atol=1e-12)


def test_inverse_direction_source_above_target(robot: Robot) -> None:
    i = 23
    M_odom_optical = robot.M_odom_base[i] @ robot.M_base_mount @ robot.M_mount_optical
    got = robot.buffer.lookup("camera_optical", "odom", int(robot.stamps[i]))
    np.testing.assert_allclose(got.as_matrix(), np.linalg.inv(M_odom_optical), atol=1e-12)
    back = robot.buffer.lookup("odom", "camera_optical", int(robot.stamps[i]))
    np.testing.assert_allclose((got @ back).as_matrix(), np.eye(4), atol=1e-12)


def test_siblings_meet_at_common_ancestor(robot: Robot) -> None:
    rng = np.random.default_rng(5)
    T_base_imu, T_map_tag = _random_poses(rng), _random_poses(rng)
    robot.buffer.set_static("base_link", "imu", T_base_imu)
    robot.buffer.set_static("map", "tag_7", T_map_tag)
    i = 31
    stamp = int(robot.stamps[i])
    M_base_optical = robot.M_base_mount @ robot.M_mount_optical
    got = robot.buffer.lookup("camera_optical", "imu", stamp)
    expected = np.linalg.inv(M_base_optical) @ T_base_imu.as_matrix()
    np.testing.assert_allclose(got.as_matrix(), expected, atol=1e-12)
    # Through the root, with dynamic edges on the source side only.
    M_map_optical = robot.M_map_odom[i] @ robot.M_odom_base[i] @ M_base_optical
    got = robot.buffer.lookup("tag_7", "camera_optical", stamp)
    expected = np.linalg.inv(T_map_tag.as_matrix()) @ M_map_optical
    np.testing.assert_allclose(got.as_matrix(), expected, atol=1e-12)


def test_dynamic_edges_on_both_sides_of_the_ancestor() -> None:
    rng = np.random.default_rng(9)
    buffer = TransformBuffer()
    T_w_a, T_w_b = _random_poses(rng, 2), _random_poses(rng, 2)
    for k, stamp in enumerate((0, 10 * MS)):
        buffer.set_transform("world", "a", stamp, T_w_a[k])
        buffer.set_transform("world", "b", stamp, T_w_b[k])
    got = buffer.lookup("a", "b", 10 * MS)
    expected = np.linalg.inv(T_w_a[1].as_matrix()) @ T_w_b[1].as_matrix()
    np.testing.assert_allclose(got.as_matrix(), expected, atol=1e-12)


def test_frame_with_itself_is_identity(robot: Robot) -> None:
    got = robot.buffer.lookup("odom", "odom", 0)
    np.testing.assert_allclose(got.as_matrix(), np.eye(4), atol=0)


def test_static_only_chain_valid_at_any_stamp(robot: Robot) -> None:
    M_base_optical = robot.M_base_mount @ robot.M_mount_optical
    for stamp in (-(2**62), 0, 2**62):
        got = robot.buffer.lookup("base_link", "camera_optical", stamp)
        np.testing.assert_allclose(got.as_matrix(), M_base_optical, atol=1e-12)
        assert robot.buffer.can_transform("base_link", "camera_optical", stamp)


def test_static_update_invalidates_cached_path(robot: Robot) -> None:
    stamp = int(robot.stamps[3])
    robot.buffer.lookup("map", "camera_optical", stamp)  # cache the path
    T_mount_optical = SE3.from_rotvec([0.1, -0.2, 0.3], [0.05, 0.0, 0.02])
    robot.buffer.set_static("camera_mount", "camera_optical", T_mount_optical)
    expected = (
        robot.M_map_odom[3] @ robot.M_odom_base[3] @ robot.M_base_mount
        @ T_mount_optical.as_matrix()
    )  # fmt: skip
    got = robot.buffer.lookup("map", "camera_optical", stamp)
    np.testing.assert_allclose(got.as_matrix(), expected, atol=1e-12)


def test_new_edge_invalidates_cached_path(robot: Robot) -> None:
    robot.buffer.set_static("elevator", "cab_tag", SE3.identity())
    with pytest.raises(DisconnectedFramesError):
        robot.buffer.lookup("map", "cab_tag", 0)
    T_map_elevator = SE3.from_rotvec([0.0, 0.0, 1.0], [10.0, 2.0, 0.0])
    robot.buffer.set_static("map", "elevator", T_map_elevator)
    got = robot.buffer.lookup("map", "cab_tag", 0)
    np.testing.assert_allclose(got.as_matrix(), T_map_elevator.as_matrix(), atol=1e-12)


def test_lookup_many_matches_hand_composition_and_lookup(robot: Robot) -> None:
    M_base_optical = robot.M_base_mount @ robot.M_mount_optical
    expected = robot.M_map_odom @ robot.M_odom_base @ M_base_optical
    got = robot.buffer.lookup_many("map", "camera_optical", robot.stamps)
    assert len(got) == len(robot.stamps)
    np.testing.assert_allclose(got.as_matrix(), expected, atol=1e-12)
    rng = np.random.default_rng(2)
    stamps = rng.integers(robot.stamps[0], robot.stamps[-1], size=40, endpoint=True)
    many = robot.buffer.lookup_many("camera_optical", "map", stamps)
    for k, stamp in enumerate(stamps.tolist()):
        one = robot.buffer.lookup("camera_optical", "map", stamp)
        np.testing.assert_allclose(many[k].as_matrix(), one.as_matrix(), atol=1e-12)


def test_lookup_many_static_and_identity_plans(robot: Robot) -> None:
    stamps = np.array([0, 5, -7], dtype=np.int64)
    got = robot.buffer.lookup_many("base_link", "camera_optical", stamps)
    M_base_optical = robot.M_base_mount @ robot.M_mount_optical
    np.testing.assert_allclose(
        got.as_matrix(), np.broadcast_to(M_base_optical, (3, 4, 4)), atol=1e-12
    )
    same = robot.buffer.lookup_many("odom", "odom", stamps)
    np.testing.assert_allclose(same.as_matrix(), np.broadcast_to(np.eye(4), (3, 4, 4)))


def test_frames_and_inspection(robot: Robot) -> None:
    assert robot.buffer.frames == ("base_link", "camera_mount", "camera_optical", "map", "odom")
    assert robot.buffer.stamp_range("map", "odom") == (int(robot.stamps[0]), int(robot.stamps[-1]))
    assert robot.buffer.latest_stamp("odom", "base_link") == int(robot.stamps[-1])
    assert robot.buffer.num_samples("odom", "base_link") == len(robot.stamps)
    assert robot.buffer.window_ns == 10_000_000_000
    assert robot.buffer.extrapolation_tolerance_ns == 0
