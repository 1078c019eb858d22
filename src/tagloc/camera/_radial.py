"""Odd radial polynomials ``f(t) = t (1 + c1 t^2 + c2 t^4 + c3 t^6 + c4 t^8)``: evaluate and invert.

Both distortion models reduce to one such polynomial along the radius: plumb_bob's radial part
maps the undistorted normalized radius ``r`` to ``r (1 + k1 r^2 + k2 r^4 + k3 r^6)`` (``c4 = 0``),
and the equidistant model maps the incidence angle ``theta`` to
``theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)`` (Kannala & Brandt 2006, eq. 6).

A polynomial of this kind is increasing from ``t = 0`` up to the first positive root of its
derivative, the *fold*; beyond the fold the model folds back onto the image it already covered and
is neither physical nor invertible. :func:`monotone_limit` finds the fold and :func:`invert` solves
``f(t) = target`` on ``[0, fold)`` with a bracketed (safeguarded) Newton iteration that cannot
diverge: a Newton step that leaves the current bracket is replaced by bisection.
"""

from __future__ import annotations

import math
from typing import TypeAlias

import numpy as np

from tagloc._types import FloatArray

Coeffs: TypeAlias = tuple[float, float, float, float]

#: Relative step below which the Newton iteration has converged (a few ulp).
_STEP_TOL = 8.0 * np.finfo(np.float64).eps
#: Enough iterations for bisection alone to reach double precision on any bracket.
_MAX_ITER = 100


def evaluate(t: FloatArray, coeffs: Coeffs) -> tuple[FloatArray, FloatArray]:
    """``f(t)`` and ``f'(t)`` (Horner form in ``t^2``).

    Parameters
    ----------
    t : (N,) float
        Arguments (radius or angle), ``t >= 0``.
    coeffs : (c1, c2, c3, c4)
        Polynomial coefficients.

    Returns
    -------
    f, df : (N,) float
        ``t (1 + c1 t^2 + ... + c4 t^8)`` and ``1 + 3 c1 t^2 + ... + 9 c4 t^8``.
    """
    c1, c2, c3, c4 = coeffs
    t2 = t * t
    gain = 1.0 + t2 * (c1 + t2 * (c2 + t2 * (c3 + t2 * c4)))
    slope = 1.0 + t2 * (3.0 * c1 + t2 * (5.0 * c2 + t2 * (7.0 * c3 + t2 * 9.0 * c4)))
    return t * gain, slope


def monotone_limit(coeffs: Coeffs) -> float:
    """The fold: the smallest ``t > 0`` with ``f'(t) = 0``, or ``inf`` if ``f`` never turns back.

    ``f'`` is a polynomial of degree at most 4 in ``s = t^2``; its real positive roots come from
    :func:`numpy.roots`.
    """
    c1, c2, c3, c4 = coeffs
    roots = np.roots([9.0 * c4, 7.0 * c3, 5.0 * c2, 3.0 * c1, 1.0])
    real = roots.real[np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots))]
    positive = real[real > 0.0]
    return math.sqrt(float(positive.min())) if positive.size else math.inf


def _upper_bracket(target: FloatArray, coeffs: Coeffs) -> FloatArray:
    """For an ``f`` increasing without bound: ``hi`` with ``f(hi) >= target`` (doubling)."""
    hi = np.fmax(target, 1.0)
    for _ in range(64):
        short = evaluate(hi, coeffs)[0] < target
        if not short.any():
            break
        hi = np.where(short, 2.0 * hi, hi)
    return hi


def invert(target: FloatArray, coeffs: Coeffs, t_max: float) -> FloatArray:
    """Solve ``f(t) = target`` for ``t`` in ``[0, t_max)``, where ``f`` increases.

    Parameters
    ----------
    target : (N,) float
        Values of ``f`` (distorted radius or angle); NaN allowed.
    coeffs : (c1, c2, c3, c4)
        Polynomial coefficients.
    t_max : float
        Upper end of the domain (the fold or a physical limit, ``f' > 0`` below it); may be ``inf``.

    Returns
    -------
    (N,) float
        The solution, to a few ulp; NaN where ``target`` is NaN, negative, or not below
        ``f(t_max)`` (no solution in the domain).
    """
    with np.errstate(all="ignore"):
        if math.isfinite(t_max):
            hi = np.full_like(target, t_max)
            solvable = (target >= 0.0) & (target < evaluate(np.array([t_max]), coeffs)[0][0])
        else:
            hi = _upper_bracket(target, coeffs)
            solvable = (target >= 0.0) & np.isfinite(hi)
        lo = np.zeros_like(target)
        t = np.clip(target, lo, hi)  # f is close to the identity: a good first guess
        for _ in range(_MAX_ITER):
            value, slope = evaluate(t, coeffs)
            error = value - target
            lo = np.where(error < 0.0, t, lo)
            hi = np.where(error > 0.0, t, hi)
            newton = t - error / slope
            inside = (newton >= lo) & (newton <= hi)
            t_next = np.where(inside, newton, 0.5 * (lo + hi))
            moving = np.abs(t_next - t) > _STEP_TOL * t_next
            t = t_next
            if not moving.any():
                break
    return np.where(solvable, t, np.nan)
