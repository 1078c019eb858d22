"""Every analytic Jacobian against central finite differences (right perturbations).

For a function ``out = f(in_1, ..., in_k)``, column ``j`` of ``J_out_in_i`` is estimated as
``(g(+eps e_j) - g(-eps e_j)) / (2 eps)`` with ``g(d) = f(..., in_i (+) d, ...) (-) f(...)``,
where ``(+)``/``(-)`` are the group plus/minus for group-valued inputs/outputs and ordinary +/-
for vectors (points, tangents).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pytest
from geometry_helpers import SEED, rotvec_with_angle

from tagloc.geometry import SE2, SE3, SO3
from tagloc.geometry import jacobians as jac
from tagloc.geometry._lie import LieGroup

EPS = 1e-6

Value = Any  # a LieGroup element or a float vector


def _perturb(value: Value, delta: np.ndarray) -> Value:
    return value.plus(delta) if isinstance(value, LieGroup) else value + delta


def _difference(a: Value, b: Value) -> np.ndarray:
    return a.minus(b) if isinstance(a, LieGroup) else np.asarray(a - b)


def _dim(value: Value) -> int:
    return value.DOF if isinstance(value, LieGroup) else int(np.size(value))


def numeric_jacobian(f: Callable[..., Value], inputs: Sequence[Value], i: int) -> np.ndarray:
    base = f(*inputs)
    columns = []
    for j in range(_dim(inputs[i])):
        step = np.zeros(_dim(inputs[i]))
        step[j] = EPS
        plus = list(inputs)
        minus = list(inputs)
        plus[i] = _perturb(inputs[i], step)
        minus[i] = _perturb(inputs[i], -step)
        columns.append((_difference(f(*plus), base) - _difference(f(*minus), base)) / (2 * EPS))
    return np.stack(columns, axis=-1)


def _elements(cls: type[LieGroup], rng: np.random.Generator) -> list[tuple[str, LieGroup]]:
    """A generic element, one near identity and one with a rotation near pi (not across it)."""
    axis = rng.standard_normal(3)
    if cls is SO3:
        return [
            ("generic", SO3.random(rng)),
            ("tiny", SO3.exp(rotvec_with_angle(axis, 1e-9))),
            ("near-pi", SO3.exp(rotvec_with_angle(axis, np.pi - 1e-2))),
        ]
    if cls is SE3:
        t = rng.normal(0.0, 2.0, 3)
        return [
            ("generic", SE3.random(rng, translation_scale=2.0)),
            ("tiny", SE3.exp(np.concatenate([t, rotvec_with_angle(axis, 1e-9)]))),
            ("near-pi", SE3.exp(np.concatenate([t, rotvec_with_angle(axis, np.pi - 1e-2)]))),
        ]
    return [
        ("generic", SE2.random(rng, scale=2.0)),
        ("tiny", SE2(1.5, -0.7, 1e-9)),
        ("near-pi", SE2(-0.3, 2.2, np.pi - 1e-2)),
    ]


RIGHT_JACOBIANS = {
    SO3: (jac.so3_right_jacobian, jac.so3_right_jacobian_inv),
    SE3: (jac.se3_right_jacobian, jac.se3_right_jacobian_inv),
    SE2: (jac.se2_right_jacobian, jac.se2_right_jacobian_inv),
}


def _operations(cls: type[LieGroup]) -> dict[str, tuple[Callable[..., Value], Callable[..., Any]]]:
    """``name -> (f, analytic)`` where ``analytic(*inputs)`` returns one Jacobian per input."""
    jr, jr_inv = RIGHT_JACOBIANS[cls]
    return {
        "compose": (lambda a, b: a @ b, lambda a, b: a.compose(b, jacobians=True)[1:]),
        "inverse": (lambda a: a.inverse(), lambda a: a.inverse(jacobians=True)[1:]),
        "between": (lambda a, b: a.between(b), lambda a, b: a.between(b, jacobians=True)[1:]),
        "act": (lambda a, p: a.act(p), lambda a, p: a.act(p, jacobians=True)[1:]),
        "log": (lambda a: a.log(), lambda a: a.log(jacobians=True)[1:]),
        "exp": (lambda v: cls.exp(v), lambda v: cls.exp(v, jacobians=True)[1:]),
        "right-jacobian": (lambda v: cls.exp(v), lambda v: (jr(v),)),
        "right-jacobian-inv": (lambda a: a.log(), lambda a: (jr_inv(a.log()),)),
        "plus": (lambda a, v: a.plus(v), lambda a, v: a.plus(v, jacobians=True)[1:]),
        "minus": (lambda a, b: a.minus(b), lambda a, b: a.minus(b, jacobians=True)[1:]),
    }


def _cases() -> list[Any]:
    rng = np.random.default_rng(SEED)
    cases = []
    for cls in (SO3, SE3, SE2):
        operations = _operations(cls)
        other = cls.random(rng)
        point = rng.normal(0.0, 2.0, 2 if cls is SE2 else 3)
        for label, X in _elements(cls, rng):
            small = 0.3 * rng.standard_normal(cls.DOF)
            inputs: dict[str, list[Value]] = {
                "compose": [X, other],
                "compose-other": [other, X],
                "inverse": [X],
                "between": [X, other],
                "act": [X, point],
                "log": [X],
                "exp": [X.log()],
                "right-jacobian": [X.log()],
                "right-jacobian-inv": [X],
                "plus": [X, small],
                "minus": [X, other],
                "minus-other": [other.plus(small), X],
            }
            for op, args in inputs.items():
                f, analytic = operations[op.removesuffix("-other")]
                cases.append(pytest.param(f, args, analytic, id=f"{cls.__name__}-{label}-{op}"))
    return cases


@pytest.mark.parametrize(("f", "inputs", "analytic"), _cases())
def test_analytic_jacobian_matches_central_differences(
    f: Callable[..., Value], inputs: list[Value], analytic: Callable[..., tuple[np.ndarray, ...]]
) -> None:
    jacobians = analytic(*inputs)
    assert len(jacobians) == len(inputs)
    for i, J in enumerate(jacobians):
        expected = numeric_jacobian(f, inputs, i)
        assert J.shape == expected.shape
        scale = max(1.0, float(np.abs(expected).max()))
        np.testing.assert_allclose(J, expected, rtol=0, atol=2e-7 * scale, err_msg=f"input {i}")


def test_finite_difference_check_detects_a_wrong_jacobian() -> None:
    """The harness can fail: a transposed compose Jacobian is rejected."""
    rng = np.random.default_rng(SEED)
    X, Y = SE3.random(rng), SE3.random(rng)
    _, J_Z_X, _ = X.compose(Y, jacobians=True)
    expected = numeric_jacobian(lambda a, b: a @ b, [X, Y], 0)
    assert not np.allclose(J_Z_X.T, expected, atol=1e-4)
    assert not np.allclose(X.adjoint(), expected, atol=1e-4)  # left-perturbation answer
