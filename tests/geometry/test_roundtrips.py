"""Round trips (hypothesis, derandomized): Exp/Log, quat, matrix, rotvec, inverse, SE2<->SE3."""

from __future__ import annotations

import numpy as np
from geometry_helpers import (
    PROPERTY_SETTINGS,
    poses,
    poses_2d,
    rotations,
    rotvecs,
    se3_tangents,
    to_gtsam,
)
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from tagloc.geometry import SE2, SE3, SO3


@PROPERTY_SETTINGS
@given(se3_tangents())
def test_se3_log_inverts_exp(xi: np.ndarray) -> None:
    T = SE3.exp(xi)
    np.testing.assert_allclose(T.log(), xi, rtol=0, atol=1e-7)
    np.testing.assert_allclose(SE3.exp(T.log()).as_matrix(), T.as_matrix(), rtol=0, atol=1e-12)


@PROPERTY_SETTINGS
@given(rotvecs())
def test_so3_rotvec_matches_scipy(phi: np.ndarray) -> None:
    R = SO3.from_rotvec(phi)
    np.testing.assert_allclose(R.as_matrix(), Rotation.from_rotvec(phi).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(R.as_rotvec(), phi, rtol=0, atol=1e-9)


@PROPERTY_SETTINGS
@given(rotations())
def test_quaternion_round_trip_and_sign(R: SO3) -> None:
    q = R.as_quat()
    assert q[3] >= 0.0
    assert abs(np.linalg.norm(q) - 1.0) < 1e-14
    np.testing.assert_allclose(SO3.from_quat(q).as_matrix(), R.as_matrix(), atol=1e-14)
    np.testing.assert_allclose(SO3.from_quat(-q).as_matrix(), R.as_matrix(), atol=1e-14)
    scipy_q = Rotation.from_matrix(R.as_matrix()).as_quat()  # xyzw
    np.testing.assert_allclose(np.abs(q @ scipy_q), 1.0, atol=1e-12)


@PROPERTY_SETTINGS
@given(poses())
def test_matrix_round_trip_and_inverse(T: SE3) -> None:
    M = T.as_matrix()
    np.testing.assert_array_equal(SE3.from_matrix(M).as_matrix(), M)
    np.testing.assert_allclose((T @ T.inverse()).as_matrix(), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(T.inverse().as_matrix(), np.linalg.inv(M), atol=1e-12)
    np.testing.assert_allclose(T.inverse().as_matrix(), to_gtsam(T).inverse().matrix(), atol=1e-12)
    np.testing.assert_allclose(T.inverse().inverse().as_matrix(), M, atol=1e-14)


@PROPERTY_SETTINGS
@given(poses(), st.lists(st.floats(-5, 5), min_size=3, max_size=3))
def test_from_quat_with_translation(T: SE3, t: list[float]) -> None:
    T2 = SE3.from_quat(T.as_quat(), t)
    np.testing.assert_allclose(T2.rotation.as_matrix(), T.rotation.as_matrix(), atol=1e-14)
    np.testing.assert_array_equal(T2.translation, t)


@PROPERTY_SETTINGS
@given(poses_2d())
def test_se2_round_trips(T: SE2) -> None:
    np.testing.assert_allclose(SE2.exp(T.log()).as_matrix(), T.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(SE2.from_matrix(T.as_matrix()).as_vector(), T.as_vector())
    back = SE2.from_se3(T.to_se3())
    np.testing.assert_allclose(back.as_vector(), T.as_vector(), atol=1e-14)
    M3 = T.to_se3().as_matrix()
    np.testing.assert_allclose(M3[:2, :2], T.as_matrix()[:2, :2], atol=1e-15)
    np.testing.assert_allclose(M3[:2, 3], [T.x, T.y])
    assert M3[2, 3] == 0.0
    assert -np.pi <= T.theta < np.pi


@PROPERTY_SETTINGS
@given(poses())
def test_se3_to_se2_keeps_yaw(T: SE3) -> None:
    planar = SE2.from_se3(T)
    yaw = Rotation.from_matrix(T.rotation.as_matrix()).as_euler("ZYX")[0]
    assert abs(np.angle(np.exp(1j * (planar.theta - yaw)))) < 1e-9
    np.testing.assert_array_equal([planar.x, planar.y], T.translation[:2])


@PROPERTY_SETTINGS
@given(rotations(), st.sampled_from(["xyz", "ZYX", "zyx"]))
def test_euler_round_trip(R: SO3, seq: str) -> None:
    angles = R.as_euler(seq, degrees=True)
    np.testing.assert_allclose(
        SO3.from_euler(seq, angles, degrees=True).as_matrix(), R.as_matrix(), atol=1e-9
    )


def test_se2_angle_wraps_and_composes_like_matrices() -> None:
    T = SE2(1.0, 2.0, 3.0 * np.pi)
    assert np.isclose(T.theta, -np.pi)
    U = SE2(-0.5, 0.25, 2.0)
    np.testing.assert_allclose((T @ U).as_matrix(), T.as_matrix() @ U.as_matrix(), atol=1e-12)


def test_rows_are_the_homogeneous_matrix_and_round_trip_exactly() -> None:
    """``as_rows``: the 4x4 matrix's rotation block row-major and its translation (checked
    against ``as_matrix``); ``from_rows`` gives back the same poses bit for bit, one or a batch."""
    T = SE3.random(np.random.default_rng(3), 5, translation_scale=10.0)
    rows = T.as_rows()
    M = T.as_matrix()
    assert rows.shape == (5, 12)
    assert np.array_equal(rows[:, :9], M[:, :3, :3].reshape(5, 9))
    assert np.array_equal(rows[:, 9:], M[:, :3, 3])
    back = SE3.from_rows(rows)
    assert np.array_equal(back.as_matrix(), M)
    one = SE3.from_rows(T[2].as_rows())
    assert one.as_rows().shape == (12,) and np.array_equal(one.as_matrix(), M[2])
