"""Check the camera's mounting (``T_base_cam``) against a drive: hand-eye from tag fixes.

Each accepted tag fix gives the camera's pose in the map, ``T_map_cam_i = T_map_base_fix_i @
T_base_cam`` (the fix was formed with the configured extrinsics, so this is PnP on the surveyed
map, independent of them). Between two fixes a short time apart the odometry gives the base's
motion ``A = T_odom_base_i^-1 @ T_odom_base_j`` and the fixes give the camera's motion
``B = T_map_cam_i^-1 @ T_map_cam_j``; with the true extrinsics ``X``, ``A @ X = X @ B``. The
check solves for ``X = T_base_cam @ Exp(xi)`` (``xi`` in the camera's right tangent,
``[x, y, z, rx, ry, rz]``) and an odometry scale factor (a nuisance) by robust least squares
over all such pairs. Odometry drift within a pair (a few seconds) is the noise, not the signal.

What planar driving cannot see: with all rotations about the floor's normal, the camera's
height above the base does not enter ``A X = X B`` (any height fits). Components whose standard
deviation stays above :attr:`ExtrinsicCheck.observable_sigma` are reported as unobservable and
do not count towards the warning. The correction's rotation angle and its translation over the
observable components are compared with the thresholds (default 0.5 deg, 2 cm).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.run import FixAttempt, LocalizationRun
from tagloc.units import S_NS

__all__ = ["ExtrinsicCheck", "ExtrinsicRecorder", "check_extrinsics", "check_run_extrinsics"]

_AXES = ("x", "y", "z", "rx", "ry", "rz")


@dataclass(frozen=True, slots=True)
class ExtrinsicCheck:
    """The estimated mounting correction ``T_base_cam_true = T_base_cam @ Exp(xi)``.

    Attributes
    ----------
    xi : (6,) float
        ``[x, y, z, rx, ry, rz]`` in the configured camera frame (m, rad); unobservable
        components are 0.
    sigma : (6,) float
        Their standard deviations (inf where unobservable).
    odometry_scale : float
        The nuisance scale of odometry translation the fit found (1 = exact).
    n_pairs : int
        Fix pairs used.
    rotation_deg, translation_m : float
        Size of the correction (translation over the observable components).
    warn_rotation_deg, warn_translation_m : float
        Thresholds of :attr:`warning`.
    T_base_cam_estimate : SE3
    """

    xi: FloatArray
    sigma: FloatArray
    odometry_scale: float
    n_pairs: int
    rotation_deg: float
    translation_m: float
    warn_rotation_deg: float
    warn_translation_m: float
    T_base_cam_estimate: SE3
    observable_sigma: tuple[float, float] = (0.01, math.radians(0.2))

    @property
    def warning(self) -> str | None:
        """One line when the correction is above a threshold, else None."""
        if self.rotation_deg <= self.warn_rotation_deg and (
            self.translation_m <= self.warn_translation_m
        ):
            return None
        parts = ", ".join(
            f"{a} {v * 100:+.1f} cm" if k < 3 else f"{a} {math.degrees(v):+.2f} deg"
            for k, (a, v) in enumerate(zip(_AXES, self.xi, strict=True))
            if math.isfinite(self.sigma[k])
        )
        return (
            f"camera extrinsics look off by {self.rotation_deg:.2f} deg / "
            f"{self.translation_m * 100:.1f} cm (from {self.n_pairs} fix pairs; "
            f"correction in the camera frame: {parts}): check T_base_cam"
        )

    def to_dict(self) -> dict[str, Any]:
        observable = np.isfinite(self.sigma)
        return {
            "n_pairs": self.n_pairs, "rotation_deg": self.rotation_deg,
            "translation_m": self.translation_m, "odometry_scale": self.odometry_scale,
            "correction_cam": {a: float(v) for a, v, o in zip(_AXES, self.xi, observable,
                                                                strict=True) if o},
            "sigma_cam": {a: float(s) for a, s, o in zip(_AXES, self.sigma, observable,
                                                          strict=True) if o},
            "unobservable": [a for a, o in zip(_AXES, observable, strict=True) if not o],
            "T_base_cam_estimate": {
                "translation": self.T_base_cam_estimate.translation.tolist(),
                "quat_xyzw": self.T_base_cam_estimate.as_quat().tolist(),
            },
            "warning": self.warning,
        }  # fmt: skip


class ExtrinsicRecorder:
    """A node sink keeping what :func:`check_extrinsics` needs, in bounded memory.

    Fix records reach the sinks a few seconds after their stamps (once no batch decision can
    revise them), so the recorder keeps the odometry of the last ``odometry_window`` samples
    (100 s at 200 Hz) and, for each accepted fix, the odometry interpolated at its stamp. It
    keeps the first ``max_fixes`` accepted fixes (about 20 minutes of 30 Hz fixes): a
    commissioning check needs minutes of driving, and a node that runs for days must not grow.
    """

    def __init__(self, max_fixes: int = 36_000, odometry_window: int = 20_000) -> None:
        self.fixes: list[FixAttempt] = []
        self.max_fixes = max_fixes
        self._T_odom_at_fix: list[SE3] = []
        self._stamps: deque[int] = deque(maxlen=odometry_window)
        self._odom: deque[SE3] = deque(maxlen=odometry_window)

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            if self._stamps and output.stamp_ns <= self._stamps[-1]:
                self._stamps.clear()  # the clock jumped back: the node started over
                self._odom.clear()
            self._stamps.append(output.stamp_ns)
            self._odom.append(output.T_odom_base)
        elif (
            isinstance(output, FixAttempt) and output.accepted
            and len(self.fixes) < self.max_fixes and self._stamps
        ):  # fmt: skip
            self.fixes.append(output)
            self._T_odom_at_fix.append(self._odometry_at(output.stamp_ns))

    def _odometry_at(self, stamp_ns: int) -> SE3:
        """The odometry at ``stamp_ns``, interpolated between the two samples around it."""
        i = bisect_right(self._stamps, stamp_ns)
        lo, hi = max(i - 1, 0), min(i, len(self._stamps) - 1)
        stamps = np.array([self._stamps[lo], self._stamps[hi]], dtype=np.int64)
        poses = SE3.stack([self._odom[lo], self._odom[hi]])
        return _odometry_at(stamps, poses, np.array([stamp_ns], dtype=np.int64))[0]

    def check(self, T_base_cam: SE3 | None, **options: Any) -> ExtrinsicCheck | None:
        """:func:`check_extrinsics` over what was recorded (None without extrinsics)."""
        if T_base_cam is None or len(self.fixes) < 2:
            return None
        stamps = np.array([f.stamp_ns for f in self.fixes], dtype=np.int64)
        order = np.argsort(stamps, kind="stable")
        T_odom = SE3.stack([self._T_odom_at_fix[k] for k in order])
        return check_extrinsics(self.fixes, stamps[order], T_odom, T_base_cam, **options)


def check_run_extrinsics(
    run: LocalizationRun, T_base_cam: SE3, **options: Any
) -> ExtrinsicCheck | None:
    """:func:`check_extrinsics` on a recorded run."""
    return check_extrinsics(run.fixes, run.stamps_ns, run.T_odom_base, T_base_cam, **options)


def _odometry_at(
    stamps_ns: npt.NDArray[np.int64], T_odom_base: SE3, stamps: npt.NDArray[np.int64]
) -> SE3:
    s = stamps_ns
    i = np.clip(np.searchsorted(s, stamps, side="right") - 1, 0, len(s) - 1)
    j = np.minimum(i + 1, len(s) - 1)
    alpha = np.clip((stamps - s[i]) / np.maximum(s[j] - s[i], 1), 0.0, 1.0)
    return T_odom_base[i].interpolate_rt(T_odom_base[j], alpha)


def check_extrinsics(
    fix_attempts: Sequence[FixAttempt],
    stamps_ns: npt.NDArray[np.int64],
    T_odom_base: SE3,
    T_base_cam: SE3,
    *,
    min_dt_s: float = 0.5,
    max_dt_s: float = 4.0,
    sigma_translation_m: float = 0.01,
    sigma_rotation_rad: float = math.radians(0.3),
    warn_rotation_deg: float = 0.5,
    warn_translation_m: float = 0.02,
    min_pairs: int = 20,
    gravity: bool = True,
    max_range_m: float = math.inf,
    sigma_gravity_rad: float = math.radians(0.1),
) -> ExtrinsicCheck | None:
    """Estimate the mounting correction from ``run``'s accepted fixes (module docstring).

    Parameters
    ----------
    fix_attempts : sequence of FixAttempt
        The run's fix attempts (accepted ones are used).
    stamps_ns, T_odom_base : (N,) int64, SE3 batch of N
        The odometry, increasing stamps.
    T_base_cam : SE3
        The extrinsics the run used.
    min_dt_s, max_dt_s : float
        Each fix is paired with the first accepted fix at least ``min_dt_s`` later, if it is
        within ``max_dt_s``.
    sigma_translation_m, sigma_rotation_rad : float
        Residual scales (a pair's odometry drift plus the fixes' noise).
    warn_rotation_deg, warn_translation_m : float
    min_pairs : int
    gravity : bool
        Also use "up": the map's z seen in the camera by each fix against the odometry's z in
        the base (both frames level: a robot on a floor, or visual-inertial odometry). This
        fixes the camera's tilt (roll, pitch) directly.
    sigma_gravity_rad : float
        The noise of one fix's "up" (PnP tilt), rad.

    Returns
    -------
    ExtrinsicCheck or None
        None with fewer than ``min_pairs`` pairs.
    """
    from scipy.optimize import least_squares

    fixes = sorted(
        (f for f in fix_attempts if f.accepted and f.range_m <= max_range_m),
        key=lambda f: f.stamp_ns,
    )
    if len(fixes) < 2 or len(stamps_ns) < 2:
        return None
    stamps = np.array([f.stamp_ns for f in fixes], dtype=np.int64)
    T_map_cam = SE3.stack([f.T_map_base for f in fixes]) @ T_base_cam
    T_odom_base = _odometry_at(stamps_ns, T_odom_base, stamps)
    j = np.searchsorted(stamps, stamps + round(min_dt_s * S_NS))
    i = np.flatnonzero(j < len(stamps))
    j = j[i]
    keep = (stamps[j] - stamps[i]) <= max_dt_s * S_NS
    i, j = i[keep], j[keep]
    if len(i) < min_pairs:
        return None
    A = T_odom_base[i].inverse() @ T_odom_base[j]
    B = T_map_cam[i].inverse() @ T_map_cam[j]
    rotvec_A, t_A = A.rotation.log(), A.translation
    # each pair's noise: both fixes' covariances moved to B's right tangent, plus the odometry's
    Ad_cam_base = T_base_cam.inverse().adjoint()
    cov_cam = np.stack([Ad_cam_base @ f.cov @ Ad_cam_base.T for f in fixes])
    Ad_B_inv = B.inverse().adjoint()
    odom = np.diag(np.square([sigma_translation_m] * 3 + [sigma_rotation_rad] * 3))
    cov_B = Ad_B_inv @ cov_cam[i] @ np.swapaxes(Ad_B_inv, -1, -2) + cov_cam[j] + odom
    W = np.linalg.inv(np.linalg.cholesky(cov_B))  # whitening: r_w = W r
    prior = 1e-3  # a weak pull to 0 (1 km / 1000 rad): keeps unobservable directions finite
    # gravity: "up" seen by each fix in the camera frame, and by the odometry in the base
    up_cam = T_map_cam.rotation.matrix[..., 2, :]  # R_map_cam^T e_z, per fix
    up_base = T_odom_base.rotation.matrix[..., 2, :]
    tilt_var = np.trace(cov_cam[:, 3:, 3:], axis1=1, axis2=2) / 3.0
    g_weight = 1.0 / np.sqrt(tilt_var + sigma_gravity_rad**2)

    def residuals(p: FloatArray) -> FloatArray:
        X = T_base_cam @ SE3.exp(p[:6])
        A_scaled = SE3.from_rotvec(rotvec_A * p[7], t_A * p[6])
        B_pred = X.inverse() @ A_scaled @ X
        r = np.einsum("nij,nj->ni", W, (B_pred.inverse() @ B).log())
        parts = [r.ravel(), prior * p[:6]]
        if gravity:
            tilt = (up_cam @ X.rotation.matrix.T) - up_base
            parts.append((tilt * g_weight[:, None]).ravel())
        return np.concatenate(parts)

    p0 = np.zeros(8)
    p0[6:] = 1.0
    sol = least_squares(residuals, p0, loss="soft_l1", f_scale=3.0, x_scale="jac")
    J = sol.jac  # the robust loss's (Gauss-Newton of the robust cost)
    sigma2 = max(float(2.0 * sol.cost / max(len(sol.fun) - 8, 1)), 1e-12)
    H = J.T @ J
    # the 6 extrinsic parameters with the odometry's scales marginalized out
    H6 = H[:6, :6] - H[:6, 6:] @ np.linalg.pinv(H[6:, 6:]) @ H[6:, :6]
    w, V = np.linalg.eigh(0.5 * (H6 + H6.T))
    seen = w > (100.0 * prior) ** 2  # directions the data constrain far beyond the weak prior
    cov = (V[:, seen] / w[seen]) @ V[:, seen].T * sigma2
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    # a component is observable when its axis lies in the constrained subspace
    observable = np.linalg.norm(V[:, seen], axis=1) > 0.95
    xi_seen = V[:, seen] @ (V[:, seen].T @ sol.x[:6])
    xi = np.where(observable, xi_seen, 0.0)
    sigma = np.where(observable, sig, math.inf)
    return ExtrinsicCheck(
        xi, sigma, float(sol.x[6]), len(i), math.degrees(float(np.linalg.norm(xi[3:]))),
        float(np.linalg.norm(xi[:3])), warn_rotation_deg, warn_translation_m,
        T_base_cam @ SE3.exp(xi),
    )  # fmt: skip
