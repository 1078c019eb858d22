"""Interpolation against an independent oracle: scipy ``Slerp`` + linear translation."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from scipy.spatial.transform import Rotation, Slerp

from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3

Mat = npt.NDArray[np.float64]
MS = 1_000_000


def _random_poses(rng: np.random.Generator, n: int | None = None, scale: float = 1.0) -> SE3:
    """Uniform rotations and Gaussian translations (scipy draws the rotations)."""
    quat_xyzw = Rotation.random(n, random_state=rng).as_quat()
    return SE3.from_quat(quat_xyzw, scale * rng.normal(size=(3,) if n is None else (n, 3)))


def _oracle(stamps: npt.NDArray[np.int64], T: SE3, query: npt.NDArray[np.int64]) -> tuple[Mat, Mat]:
    """Rotation matrices and translations at ``query`` by scipy Slerp and np.interp."""
    times = (stamps - stamps[0]).astype(np.float64)
    at = (query - stamps[0]).astype(np.float64)
    R = Slerp(times, Rotation.from_matrix(T.rotation.as_matrix()))(at).as_matrix()
    t = np.stack([np.interp(at, times, T.translation[:, k]) for k in range(3)], axis=1)
    return R, t


def _irregular_stamps(rng: np.random.Generator, n: int) -> npt.NDArray[np.int64]:
    gaps = rng.integers(1 * MS, 40 * MS, size=n)
    return np.cumsum(gaps) + 1_700_000_000 * 1_000_000_000


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_single_edge_matches_scipy_slerp(seed: int) -> None:
    rng = np.random.default_rng(seed)
    stamps = _irregular_stamps(rng, 60)
    T = _random_poses(rng, len(stamps))  # uniform rotations: large angles between samples
    buffer = TransformBuffer()
    for i, stamp in enumerate(stamps.tolist()):
        buffer.set_transform("odom", "base_link", stamp, T[i])
    query = np.sort(rng.integers(stamps[0], stamps[-1], size=200, endpoint=True))
    R_ref, t_ref = _oracle(stamps, T, query)
    for k, stamp in enumerate(query.tolist()):
        got = buffer.lookup("odom", "base_link", stamp)
        np.testing.assert_allclose(got.rotation.as_matrix(), R_ref[k], atol=1e-9)
        np.testing.assert_allclose(got.translation, t_ref[k], atol=1e-9)
    many = buffer.lookup_many("odom", "base_link", query)
    np.testing.assert_allclose(many.rotation.as_matrix(), R_ref, atol=1e-9)
    np.testing.assert_allclose(many.translation, t_ref, atol=1e-9)


def test_small_rotations_between_samples() -> None:
    """Odometry at a high rate: micro-radian steps, and two identical samples (no NaN)."""
    rng = np.random.default_rng(3)
    stamps = np.arange(20, dtype=np.int64) * MS
    rotvecs = np.cumsum(rng.normal(scale=1e-6, size=(20, 3)), axis=0)
    rotvecs[10] = rotvecs[9]
    T = SE3.from_rotvec(rotvecs, rng.normal(size=(20, 3)))
    buffer = TransformBuffer()
    buffer.set_transforms("odom", "base_link", stamps, T)
    query = rng.integers(0, 19 * MS, size=50)
    R_ref, t_ref = _oracle(stamps, T, query)
    many = buffer.lookup_many("odom", "base_link", query)
    assert np.isfinite(many.as_matrix()).all()
    np.testing.assert_allclose(many.rotation.as_matrix(), R_ref, atol=1e-12)
    np.testing.assert_allclose(many.translation, t_ref, atol=1e-12)
    one = buffer.lookup("odom", "base_link", int(query[0]))
    np.testing.assert_allclose(one.rotation.as_matrix(), R_ref[0], atol=1e-12)


def test_chain_interpolates_each_edge_then_composes() -> None:
    rng = np.random.default_rng(4)
    s_map = _irregular_stamps(rng, 30)
    s_odom = _irregular_stamps(rng, 200) - 100 * MS  # other rate and phase
    T_map_odom, T_odom_base = _random_poses(rng, 30), _random_poses(rng, 200)
    T_base_cam = _random_poses(rng)
    buffer = TransformBuffer()
    buffer.set_transforms("map", "odom", s_map, T_map_odom)
    buffer.set_transforms("odom", "base_link", s_odom, T_odom_base)
    buffer.set_static("base_link", "camera", T_base_cam)
    lo, hi = max(s_map[0], s_odom[0]), min(s_map[-1], s_odom[-1])
    query = rng.integers(lo, hi, size=50, endpoint=True)
    R1, t1 = _oracle(s_map, T_map_odom, query)
    R2, t2 = _oracle(s_odom, T_odom_base, query)
    M1, M2 = np.tile(np.eye(4), (50, 1, 1)), np.tile(np.eye(4), (50, 1, 1))
    M1[:, :3, :3], M1[:, :3, 3], M2[:, :3, :3], M2[:, :3, 3] = R1, t1, R2, t2
    expected = M1 @ M2 @ T_base_cam.as_matrix()
    got = buffer.lookup_many("map", "camera", query)
    np.testing.assert_allclose(got.as_matrix(), expected, atol=1e-9)
    for k in (0, 25, 49):
        one = buffer.lookup("camera", "map", int(query[k]))
        np.testing.assert_allclose(one.as_matrix(), np.linalg.inv(expected[k]), atol=1e-9)


def test_translation_is_linear_not_the_se3_geodesic() -> None:
    T0 = SE3.identity()
    T1 = SE3.from_rotvec([0.0, 0.0, np.pi / 2], [2.0, 0.0, 0.0])
    buffer = TransformBuffer()
    buffer.set_transform("odom", "base_link", 0, T0)
    buffer.set_transform("odom", "base_link", 10, T1)
    mid = buffer.lookup("odom", "base_link", 5)
    np.testing.assert_allclose(mid.translation, [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(mid.rotation.as_rotvec(), [0.0, 0.0, np.pi / 4], atol=1e-12)
    geodesic = T0.interpolate(T1, 0.5)
    assert abs(geodesic.translation[1]) > 0.1  # the screw motion bends the path


def test_shortest_arc_for_quaternions_of_opposite_sign() -> None:
    """Near-180-degree steps and rotations whose quaternions have opposite signs."""
    R0 = SE3.from_rotvec([0.0, 0.0, 3.0], np.zeros(3))
    R1 = SE3.from_rotvec([0.0, 0.0, -3.0], np.zeros(3))  # 0.283 rad from R0 the short way
    buffer = TransformBuffer()
    buffer.set_transform("a", "b", 0, R0)
    buffer.set_transform("a", "b", 100, R1)
    mid = buffer.lookup("a", "b", 50).rotation.as_matrix()
    np.testing.assert_allclose(mid, Rotation.from_rotvec([0, 0, np.pi]).as_matrix(), atol=1e-12)


def test_sample_stamps_return_the_samples() -> None:
    rng = np.random.default_rng(6)
    T = _random_poses(rng, 5)
    buffer = TransformBuffer()
    for i in range(5):
        buffer.set_transform("a", "b", i * 7, T[i])
    for i in range(5):
        np.testing.assert_allclose(
            buffer.lookup("a", "b", i * 7).as_matrix(), T[i].as_matrix(), atol=1e-14
        )


def test_rotations_round_trip_on_every_conversion_branch() -> None:
    """Stored as quaternions, returned as matrices: identity, 180-degree turns about each axis
    and random rotations (each branch of the matrix -> quaternion conversion)."""
    rng = np.random.default_rng(7)
    special = Rotation.from_rotvec(
        [[0, 0, 0], [np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [np.pi / 2, 0, 0],
         [2.0, 2.0, 0.0], [0.0, -2.5, 1.0], [0.3, 0.2, -2.9]]
    )  # fmt: skip
    rotations = Rotation.concatenate([special, Rotation.random(200, random_state=rng)])
    matrices = rotations.as_matrix()
    T = SE3.from_matrix(np.concatenate(
        [np.concatenate([matrices, np.zeros((len(matrices), 3, 1))], axis=2),
         np.tile([[[0.0, 0.0, 0.0, 1.0]]], (len(matrices), 1, 1))], axis=1
    ))  # fmt: skip
    buffer = TransformBuffer(window_ns=10**12)
    for i in range(len(matrices)):
        buffer.set_transform("a", "b", 2 * i, T[i])
        buffer.set_static("c", f"d{i}", T[i])
    for i in range(len(matrices)):
        np.testing.assert_allclose(
            buffer.lookup("a", "b", 2 * i).rotation.as_matrix(), matrices[i], atol=1e-12
        )
        np.testing.assert_allclose(
            buffer.lookup("c", f"d{i}", 0).rotation.as_matrix(), matrices[i], atol=1e-12
        )


def test_batch_and_single_insert_store_the_same_values() -> None:
    rng = np.random.default_rng(8)
    T = _random_poses(rng, 30)
    stamps = np.arange(30, dtype=np.int64) * 3 * MS
    single, batch = TransformBuffer(), TransformBuffer()
    for i, stamp in enumerate(stamps.tolist()):
        single.set_transform("a", "b", stamp, T[i])
    batch.set_transforms("a", "b", stamps, T)
    query = rng.integers(0, stamps[-1], size=100)
    np.testing.assert_allclose(
        single.lookup_many("a", "b", query).as_matrix(),
        batch.lookup_many("a", "b", query).as_matrix(),
        atol=1e-12,
    )
