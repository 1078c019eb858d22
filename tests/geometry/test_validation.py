"""Input validation (messages name what is wrong) and immutability."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tagloc.errors import GeometryError, TaglocError
from tagloc.geometry import SE2, SE3, SO3, so3_right_jacobian


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: SO3.from_matrix(np.eye(4)), r"shape \(3, 3\)"),
        (lambda: SO3.from_matrix(np.full((3, 3), np.nan)), "NaN"),
        (lambda: SO3.from_matrix(np.eye(3) * 1.01), "not orthonormal"),
        (lambda: SO3.from_matrix(np.diag([1.0, 1.0, -1.0])), "reflection"),
        (lambda: SO3(np.eye(3) + 1e-3), "not orthonormal"),
        (lambda: SO3.from_quat([0.0, 0.0, 0.0, 2.0]), "not a unit quaternion"),
        (lambda: SO3.from_quat([0.0, 0.0, 1.0]), r"shape \(4,\)"),
        (lambda: SO3.from_rotvec([np.inf, 0.0, 0.0]), "inf"),
        (lambda: SO3.from_euler("xyq", [0.0, 0.0, 0.0]), "seq"),
        (lambda: SO3.exp(np.zeros(6)), r"shape \(3,\)"),
        (lambda: SE3.exp([np.nan] * 6), "NaN"),
        (lambda: SE3.from_matrix(np.eye(3)), r"shape \(4, 4\)"),
        (lambda: SE3.from_matrix(np.ones((4, 4))), "last row"),
        (lambda: SE3(rotation=np.eye(3), translation=np.zeros(3)), "must be an SO3"),  # type: ignore[arg-type]
        (lambda: SE3(rotation=SO3.identity(), translation=np.zeros(2)), r"translation"),
        (lambda: SE3(rotation=SO3.identity(2), translation=np.zeros((3, 3))), "does not match"),
        (lambda: SE3.from_quat([0, 0, 0, 1], [0.0, np.nan, 0.0]), "NaN"),
        (lambda: SE2(0.0, np.nan, 0.0), "NaN"),
        (lambda: SE2.from_matrix(np.eye(4)), r"shape \(3, 3\)"),
        (lambda: SE2(np.zeros(2), np.zeros(3), 0.0), "broadcast"),
        (lambda: SE3.identity().act(np.zeros((5, 2))), r"shape \(3,\)"),
        (lambda: SE3.identity().plus(np.zeros(3)), r"shape \(6,\)"),
        (lambda: SE3.identity() @ SO3.identity(), "compose needs two SE3"),  # type: ignore[operator]
        (lambda: so3_right_jacobian(np.zeros(4)), r"shape \(3,\)"),
    ],
)
def test_bad_input_raises_geometry_error_naming_the_problem(build, message) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(GeometryError, match=message) as info:
        build()
    assert isinstance(info.value, TaglocError)


def test_tolerances_accept_slightly_off_inputs_and_normalize() -> None:
    q = np.array([0.1, 0.2, 0.3, 0.9])
    q /= np.linalg.norm(q)
    R = SO3.from_quat(q * (1 + 5e-7))
    assert abs(np.linalg.norm(R.as_quat()) - 1.0) < 1e-15
    drifted = R.as_matrix() + 1e-4
    with pytest.raises(GeometryError):
        SO3.from_matrix(drifted)
    fixed = SO3.from_matrix(drifted, normalize=True)
    np.testing.assert_allclose(fixed.as_matrix().T @ fixed.as_matrix(), np.eye(3), atol=1e-14)
    assert np.abs(fixed.as_matrix() - R.as_matrix()).max() < 1e-3


def test_values_are_immutable() -> None:
    T = SE3.from_rotvec([0.1, 0.2, 0.3], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="read-only"):
        T.translation[0] = 5.0
    with pytest.raises(ValueError, match="read-only"):
        T.rotation.matrix[0, 0] = 5.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        T.translation = np.zeros(3)  # type: ignore[misc]
    S = SE2(1.0, 2.0, 0.3)
    with pytest.raises(ValueError, match="read-only"):
        S.translation[0] = 5.0
    # Inputs are copied: mutating the caller's array does not change the value.
    t = np.array([1.0, 2.0, 3.0])
    U = SE3(rotation=SO3.identity(), translation=t)
    t[0] = 100.0
    assert U.translation[0] == 1.0
    # Outputs of as_matrix are fresh and writable.
    M = T.as_matrix()
    M[0, 3] = 9.0
    assert T.translation[0] == 1.0
    # Results of operations are read-only too.
    with pytest.raises(ValueError, match="read-only"):
        (T @ T).translation[0] = 1.0


def test_broadcasting_constructor() -> None:
    T = SE3(rotation=SO3.identity(), translation=np.zeros((4, 3)))
    assert len(T) == 4
    assert T.rotation.matrix.shape == (4, 3, 3)
