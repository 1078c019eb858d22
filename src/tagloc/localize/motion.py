"""Motion of the ``map -> odom`` correction between fixes: process noise and odometry calibration.

Both are integrals over the odometry path ``A_k = T_odom_base(t_k)`` between two stamps. For the
increment ``delta_k = A_{k-1}^-1 A_k`` (base frame of ``k-1``: ``dx, dy, dz``, yaw ``dyaw``,
distance ``d``, rotation angle ``a``):

Process noise (a random walk driven by motion: odometry drift is per metre, not per second)
    An error ``n_k`` of the increment, in the base frame at its end, moves the correction by
    ``X <- X @ Exp(Ad(A_k) n_k)``, so ``Q = sum_k Ad(A_k) diag(var_m d + var_rad a + var_s dt)
    Ad(A_k)^T``.
Odometry calibration (the systematic part of the drift)
    The odometry's true increment is ``delta_k @ Exp(G_k c)`` with calibration parameters
    ``c = [scale, lateral, yaw_per_m, yaw_scale]`` (each the correction to add: an odometry that
    over-reads distance by 4 % has ``scale = -0.04``) and ``G_k`` mapping them to the base
    tangent: ``x += scale dx``, ``y += scale dy + lateral d``, ``z += scale dz``,
    ``yaw += yaw_per_m d + yaw_scale dyaw``. Then ``T_map_base = X @ A`` stays true if
    ``X <- X @ Exp(Ad(A_k) G_k c)``: to first order the correction drifts by ``X (+) M c`` with
    ``M = sum_k Ad(A_k) G_k`` (``(d, 4)``), which the filter adds to its prediction, and ``c``
    joins its state (an augmented error-state EKF; fixes observe ``c`` through how the
    corrections they imply drift as the robot moves).

Tangent order: ``[x, y, z, rx, ry, rz]`` on SE(3), ``[x, y, theta]`` in planar mode (SE(2)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.units import S_NS

if TYPE_CHECKING:
    from tagloc.localize.config import CalibrationConfig, ProcessNoiseConfig

#: Calibration parameters, in order.
CALIBRATION_PARAMETERS = ("scale", "lateral", "yaw_per_m", "yaw_scale")
N_CALIBRATION = len(CALIBRATION_PARAMETERS)


def adjoints(R: FloatArray, t: FloatArray, planar: bool) -> FloatArray:
    """``Ad(A_k)`` of odometry poses ``R (N, 3, 3)``, ``t (N, 3)``: SE(3) ``(N, 6, 6)`` or, planar,
    SE(2) of their projections ``(N, 3, 3)``."""
    n = len(R)
    if planar:
        yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
        c, s = np.cos(yaw), np.sin(yaw)
        out = np.zeros((n, 3, 3))
        out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = c, -s, t[:, 1]
        out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = s, c, -t[:, 0]
        out[:, 2, 2] = 1.0
        return out
    out = np.zeros((n, 6, 6))
    out[:, :3, :3] = out[:, 3:, 3:] = R
    tx = np.zeros((n, 3, 3))
    tx[:, 0, 1], tx[:, 0, 2], tx[:, 1, 2] = -t[:, 2], t[:, 1], -t[:, 0]
    out[:, :3, 3:] = (tx - np.swapaxes(tx, 1, 2)) @ R
    return out


def calibration_jacobians(
    d_base: FloatArray, dist: FloatArray, dyaw: FloatArray, planar: bool
) -> FloatArray:
    """``G_k`` of increments (module docstring): ``(N, 3, 4)`` planar or ``(N, 6, 4)``.

    Parameters
    ----------
    d_base : (N, 3) float
        Translation of each increment in the base frame at its start, m.
    dist : (N,) float
        Its length, m.
    dyaw : (N,) float
        Its signed yaw, rad.
    """
    n = len(dist)
    G = np.zeros((n, 3 if planar else 6, N_CALIBRATION))
    yaw_row = 2 if planar else 5
    G[:, 0, 0], G[:, 1, 0] = d_base[:, 0], d_base[:, 1]
    if not planar:
        G[:, 2, 0] = d_base[:, 2]
    G[:, 1, 1] = dist
    G[:, yaw_row, 2], G[:, yaw_row, 3] = dist, dyaw
    return G


_NO_DRIFT = {False: np.zeros((6, 0)), True: np.zeros((3, 0))}  # empty: safe to share


def _no_drift(planar: bool) -> FloatArray:
    """The ``(d, 0)`` ``M`` of a :class:`PathMotion` computed without the drift."""
    return _NO_DRIFT[planar]


@dataclass(frozen=True, slots=True)
class PathMotion:
    """What the odometry path between two stamps does to the correction.

    Attributes
    ----------
    Q : (d, d) float
        Random-walk covariance (right tangent at the later stamp).
    distance_m : float
    M : (d, 4) float
        Drift per unit calibration: ``X_later = X_earlier (+) M c`` (module docstring);
        ``(d, 0)`` when not computed (``drift=False``: no calibration, or only ``Q`` needed).
    """

    Q: FloatArray
    distance_m: float
    M: FloatArray


@dataclass(frozen=True, slots=True)
class ProcessNoise:
    """Random walk of ``T_map_odom`` driven by the odometry's motion, and the calibration drift.

    Attributes
    ----------
    var_per_m, var_per_rad, var_per_s : (d,) float
        Variance per metre travelled, per radian rotated, per second, of the base-frame axes
        (``[x, y, z, rx, ry, rz]``, or ``[x, y, theta]`` planar).
    step_ns : int
        Sampling step of the odometry path (long intervals are integrated piecewise).
    """

    var_per_m: FloatArray
    var_per_rad: FloatArray
    var_per_s: FloatArray
    step_ns: int

    @classmethod
    def from_config(cls, section: ProcessNoiseConfig, planar: bool) -> ProcessNoise:
        """From ``localizer.yaml``'s ``process_noise`` (standard deviations become variances,
        the step nanoseconds; planar: the ``x, y, rz`` axes)."""
        axes = [0, 1, 5] if planar else list(range(6))

        def var(sigmas: tuple[float, ...]) -> FloatArray:
            return np.square(np.asarray(sigmas, dtype=np.float64))[axes]

        return cls(
            var(section.sigma_per_sqrt_m), var(section.sigma_per_sqrt_rad),
            var(section.sigma_per_sqrt_s), round(section.motion_step_s * S_NS),
        )  # fmt: skip

    def path(
        self, stamps_ns: npt.NDArray[np.int64], R: FloatArray, t: FloatArray, planar: bool,
        drift: bool = True,
    ) -> PathMotion:  # fmt: skip
        """The increments between odometry samples ``A_k = (R[k], t[k])`` at ``stamps_ns (N,)``
        (``R (N, 3, 3)``, ``t (N, 3)``), oldest first. ``drift=False`` skips the calibration
        drift ``M`` (left ``(d, 0)``)."""
        R0T = np.swapaxes(R[:-1], 1, 2)
        dR = R0T @ R[1:]
        dt_map = np.diff(t, axis=0)
        dist = np.linalg.norm(dt_map, axis=1)
        cos = np.clip(0.5 * (np.trace(dR, axis1=1, axis2=2) - 1.0), -1.0, 1.0)
        dt = np.abs(np.diff(stamps_ns)) / S_NS
        var = (
            np.outer(dist, self.var_per_m)
            + np.outer(np.arccos(cos), self.var_per_rad)
            + np.outer(dt, self.var_per_s)
        )
        Ad = adjoints(R[1:], t[1:], planar)
        Q = np.einsum("kij,kj,klj->il", Ad, var, Ad)
        if not drift:
            return PathMotion(Q, float(dist.sum()), _no_drift(planar))
        d_base = np.einsum("kij,kj->ki", R0T, dt_map)
        G = calibration_jacobians(d_base, dist, np.arctan2(dR[:, 1, 0], dR[:, 0, 0]), planar)
        M = np.einsum("kij,kjl->il", Ad, G)
        return PathMotion(Q, float(dist.sum()), M)

    def increment(
        self, dt_ns: int, R0: FloatArray, t0: FloatArray, R1: FloatArray, t1: FloatArray,
        planar: bool, drift: bool = True,
    ) -> PathMotion:  # fmt: skip
        """:meth:`path` for one increment ``(R0, t0) -> (R1, t1)`` (the per-fix path).

        ``G`` is :func:`calibration_jacobians` for this one increment, written out on floats
        (0.5 us against 2-3 us for the batched function on one row; the tests compare the
        two through :meth:`path`)."""
        d = t1 - t0
        dist = math.sqrt(float(d @ d))
        cos = 0.5 * (float(np.vdot(R0, R1)) - 1.0)  # trace(R0^T R1) = sum(R0 * R1)
        angle = math.acos(min(1.0, max(-1.0, cos)))
        var = dist * self.var_per_m + angle * self.var_per_rad + (dt_ns / S_NS) * self.var_per_s
        if planar:
            c, s = R1[0, 0], R1[1, 0]
            n = math.hypot(c, s)
            Ad = np.array([[c / n, -s / n, t1[1]], [s / n, c / n, -t1[0]], [0.0, 0.0, 1.0]])
        else:
            x, y, z = t1.tolist()
            Ad = np.zeros((6, 6))
            Ad[:3, :3] = Ad[3:, 3:] = R1
            Ad[:3, 3:] = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]) @ R1
        Q = (Ad * var) @ Ad.T
        if not drift:
            return PathMotion(Q, dist, _no_drift(planar))
        bx, by, bz = (R0.T @ d).tolist()  # the increment in the base frame at its start
        dyaw = math.atan2(float(R0[:, 1] @ R1[:, 0]), float(R0[:, 0] @ R1[:, 0]))
        if planar:
            G = np.array([[bx, 0.0, 0.0, 0.0], [by, dist, 0.0, 0.0], [0.0, 0.0, dist, dyaw]])
        else:
            G = np.zeros((6, N_CALIBRATION))
            G[0, 0], G[1, 0], G[2, 0], G[1, 1] = bx, by, bz, dist
            G[5, 2], G[5, 3] = dist, dyaw
        return PathMotion(Q, dist, Ad @ G)


@dataclass(frozen=True, slots=True)
class CalibrationModel:
    """The odometry calibration the filter estimates (disabled: ``None`` in the filter).

    Attributes
    ----------
    prior_var : (4,) float
        Variance of each parameter at start-up (mean 0).
    var_per_m : (4,) float
        Random walk of the parameters per metre travelled (the odometry's errors change with
        floor, gait and load).
    max_abs : (4,) float
        Each estimate is clamped to ``[-max_abs, max_abs]`` (a bound on a plausible odometry).
    """

    prior_var: FloatArray
    var_per_m: FloatArray
    max_abs: FloatArray

    @classmethod
    def from_config(cls, section: CalibrationConfig) -> CalibrationModel | None:
        """From ``localizer.yaml``'s ``calibration`` (None when disabled; standard deviations
        become variances, ``yaw_per_m`` degrees radians)."""
        if not section.enabled:
            return None
        deg = np.array([1.0, 1.0, math.pi / 180.0, 1.0])  # yaw_per_m is in degrees
        return cls(
            np.square(np.asarray(section.prior_sigma) * deg),
            np.square(np.asarray(section.sigma_per_sqrt_m) * deg),
            np.asarray(section.max_abs) * deg,
        )
