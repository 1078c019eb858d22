"""The small-angle switch points of the scalar coefficients, against 50-digit arithmetic.

The Taylor branches and the closed forms meet at fixed thresholds; both sides of each threshold are
compared with the exact value computed by ``decimal`` series, so a wrong series term or a
cancellation-prone closed form fails here.
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext

import numpy as np
import pytest

from tagloc.geometry import _so3math as so3m
from tagloc.geometry.jacobians import _q_coefficients


def _sin_cos(t: Decimal) -> tuple[Decimal, Decimal]:
    s = sum((-1) ** k * t ** (2 * k + 1) / math.factorial(2 * k + 1) for k in range(30))
    c = sum((-1) ** k * t ** (2 * k) / math.factorial(2 * k) for k in range(30))
    return Decimal(s), Decimal(c)


def _exact(theta: float) -> dict[str, float]:
    with localcontext() as ctx:
        ctx.prec = 60
        t = Decimal(theta)
        s, c = _sin_cos(t)
        sh, ch = _sin_cos(t / 2)
        return {
            "sin3": float((t - s) / t**3),
            "cot": float((1 - (t / 2) * ch / sh) / t**2),
            "a2": float((t * t + 2 * c - 2) / (2 * t**4)),
            "a3": float((2 * t - 3 * s + t * c) / (2 * t**5)),
            "cos": float((1 - c) / t**2),
        }


#: Each coefficient multiplies a matrix of size ~theta^p (e.g. ``[phi]x^2`` for ``sin3``); what
#: matters is the error of that product beside the O(1) identity term (a few ulps at most).
POWERS = {"sin3": 2, "cot": 2, "cos": 1, "a1": 1, "a2": 2, "a3": 3}


@pytest.mark.parametrize("theta", [1e-7, 1e-3, 0.05, 0.3, 0.999, 1.001, 2.0, 3.1])
def test_coefficients_match_high_precision(theta: float) -> None:
    exact = _exact(theta)
    t = np.array(theta)
    a1, a2, a3 = _q_coefficients(t)
    got = {
        "sin3": so3m.coeff_sin3(t),
        "cot": so3m.coeff_cot(t),
        "cos": so3m.coeff_cos(t),
        "a1": a1,
        "a2": a2,
        "a3": a3,
    }
    exact["a1"] = exact["sin3"]
    for name, value in got.items():
        error = abs(float(value) - exact[name]) * theta ** POWERS[name]
        assert error <= 1e-15, f"{name} at theta={theta}: term error {error:.3g}"
