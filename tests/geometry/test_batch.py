"""Batched values: vectorized results equal the per-pose results; broadcasting; containers."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_helpers import SEED, rotvec_with_angle

from tagloc.errors import GeometryError
from tagloc.geometry import SE2, SE3, SO3, se3_right_jacobian, se3_right_jacobian_inv
from tagloc.geometry._lie import LieGroup

N = 40


def _batch(cls: type[LieGroup], rng: np.random.Generator) -> LieGroup:
    """A batch that includes the identity, a tiny and a near-pi rotation."""
    batch = cls.random(rng, N)
    if cls is SE2:
        special = [SE2(0.0, 0.0, 0.0), SE2(1.0, 2.0, 1e-10), SE2(-1.0, 0.5, np.pi - 1e-7)]
    else:
        axis = rng.standard_normal(3)
        rotvecs = [
            np.zeros(3),
            rotvec_with_angle(axis, 1e-10),
            rotvec_with_angle(axis, np.pi - 1e-7),
        ]
        if cls is SO3:
            special = [SO3.exp(v) for v in rotvecs]
        else:
            special = [SE3.exp(np.concatenate([rng.normal(size=3), v])) for v in rotvecs]
    return cls.stack([*special, batch])


GROUPS = [SO3, SE3, SE2]


@pytest.mark.parametrize("cls", GROUPS, ids=lambda c: c.__name__)
def test_batched_ops_equal_per_pose(cls: type[LieGroup]) -> None:
    rng = np.random.default_rng(SEED)
    X, Y = _batch(cls, rng), _batch(cls, rng)
    n = len(X)
    assert n == N + 3
    single = Y[5]
    dim = 2 if cls is SE2 else 3
    points = rng.normal(size=(n, dim))
    many_points = rng.normal(size=(n, 4, dim))
    log = X.log()
    assert log.shape == (n, cls.DOF)
    XY = X @ Y
    for i in range(n):
        Xi, Yi = X[i], Y[i]
        assert not Xi.is_batch
        np.testing.assert_allclose(XY[i].as_matrix(), (Xi @ Yi).as_matrix(), atol=1e-13)
        np.testing.assert_allclose(
            (X @ single)[i].as_matrix(), (Xi @ single).as_matrix(), atol=1e-13
        )
        np.testing.assert_allclose(
            (single @ X)[i].as_matrix(), (single @ Xi).as_matrix(), atol=1e-13
        )
        np.testing.assert_allclose(X.inverse()[i].as_matrix(), Xi.inverse().as_matrix(), atol=1e-13)
        np.testing.assert_allclose(log[i], Xi.log(), atol=1e-12)
        np.testing.assert_allclose(
            cls.exp(log)[i].as_matrix(), cls.exp(log[i]).as_matrix(), atol=1e-13
        )
        np.testing.assert_allclose(X.adjoint()[i], Xi.adjoint(), atol=1e-13)
        np.testing.assert_allclose(X.as_matrix()[i], Xi.as_matrix(), atol=0)
        np.testing.assert_allclose(X.act(points)[i], Xi.act(points[i]), atol=1e-13)
        np.testing.assert_allclose(X.act(points[0])[i], Xi.act(points[0]), atol=1e-13)
        np.testing.assert_allclose(X.act(many_points)[i], Xi.act(many_points[i]), atol=1e-13)
        np.testing.assert_allclose(X.minus(Y)[i], Xi.minus(Yi), atol=1e-9)


@pytest.mark.parametrize("cls", GROUPS, ids=lambda c: c.__name__)
def test_batched_jacobians_equal_per_pose(cls: type[LieGroup]) -> None:
    rng = np.random.default_rng(SEED + 1)
    X, Y = _batch(cls, rng), _batch(cls, rng)
    dim = 2 if cls is SE2 else 3
    points = rng.normal(size=(len(X), dim))
    _, J1, J2 = X.compose(Y[0], jacobians=True)
    _, K1, K2 = X.minus(Y, jacobians=True)
    _, A1, A2 = X.act(points, jacobians=True)
    for i in range(len(X)):
        _, j1, j2 = X[i].compose(Y[0], jacobians=True)
        np.testing.assert_allclose(J1[i], j1, atol=1e-13)
        np.testing.assert_allclose(J2[i], j2, atol=0)
        _, k1, k2 = X[i].minus(Y[i], jacobians=True)
        np.testing.assert_allclose(K1[i], k1, atol=1e-9)
        np.testing.assert_allclose(K2[i], k2, atol=1e-9)
        _, a1, a2 = X[i].act(points[i], jacobians=True)
        np.testing.assert_allclose(A1[i], a1, atol=1e-13)
        np.testing.assert_allclose(A2[i], a2, atol=0)


def test_se3_batched_right_jacobians_equal_per_vector() -> None:
    rng = np.random.default_rng(SEED + 2)
    xi = rng.normal(size=(20, 6))
    xi[0, 3:] = 1e-9
    jr, jr_inv = se3_right_jacobian(xi), se3_right_jacobian_inv(xi)
    for i in range(20):
        np.testing.assert_allclose(jr[i], se3_right_jacobian(xi[i]), atol=0)
        np.testing.assert_allclose(jr_inv[i], se3_right_jacobian_inv(xi[i]), atol=0)


def test_containers_stack_len_getitem_iter() -> None:
    rng = np.random.default_rng(SEED + 3)
    poses = [SE3.random(rng) for _ in range(5)]
    batch = SE3.stack(poses)
    assert len(batch) == 5
    assert batch.translation.shape == (5, 3)
    assert batch.rotation.matrix.shape == (5, 3, 3)
    for expected, got in zip(poses, batch, strict=True):
        np.testing.assert_array_equal(got.as_matrix(), expected.as_matrix())
    np.testing.assert_array_equal(batch[1:3].translation, batch.translation[1:3])
    np.testing.assert_array_equal(batch[[4, 0]].translation[1], poses[0].translation)
    both = SE3.stack([batch, poses[0]])
    assert len(both) == 6
    assert len(SE3.stack([poses[0]])) == 1
    with pytest.raises(TypeError):
        len(poses[0])
    with pytest.raises(TypeError):
        poses[0][0]
    with pytest.raises(GeometryError, match="at least one"):
        SE3.stack([])
    with pytest.raises(GeometryError, match="item 1"):
        SE3.stack([poses[0], SO3.identity()])  # type: ignore[list-item]


def test_mismatched_batches_raise() -> None:
    rng = np.random.default_rng(SEED + 4)
    for cls in GROUPS:
        with pytest.raises(GeometryError, match="batch"):
            cls.random(rng, 3) @ cls.random(rng, 4)
    with pytest.raises(GeometryError, match=r"\(3, 3\)"):
        SE3.random(rng, 3).act(np.zeros((4, 3)))


def test_interpolate_batch_of_alphas() -> None:
    rng = np.random.default_rng(SEED + 5)
    A, B = SE3.random(rng), SE3.random(rng)
    alphas = np.linspace(0.0, 1.0, 7)
    batch = A.interpolate(B, alphas)
    for i, alpha in enumerate(alphas):
        np.testing.assert_allclose(
            batch[i].as_matrix(), A.interpolate(B, alpha).as_matrix(), atol=1e-13
        )


def test_se2_batch_constructor_and_to_se3() -> None:
    x, y, theta = np.array([1.0, 2.0]), np.array([0.0, -1.0]), np.array([0.5, 7.0])
    batch = SE2(x, y, theta)
    assert len(batch) == 2
    np.testing.assert_allclose(batch[1].theta, 7.0 - 2 * np.pi)
    as3 = batch.to_se3()
    np.testing.assert_allclose(as3[1].as_matrix(), batch[1].to_se3().as_matrix(), atol=0)
    np.testing.assert_allclose(SE2.from_se3(as3).as_vector(), batch.as_vector(), atol=1e-15)
    with pytest.raises(GeometryError, match="single"):
        _ = batch.x
