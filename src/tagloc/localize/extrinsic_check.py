"""Check the camera's mounting (``T_base_cam``) against a drive: hand-eye from tag fixes.

Each accepted tag fix gives the camera's pose in the map, ``T_map_cam_i = T_map_base_fix_i @
T_base_cam`` (the fix was formed with the configured extrinsics, so this is PnP on the surveyed
map, independent of them). Between two fixes a short time apart the odometry gives the base's
motion ``A = T_odom_base_i^-1 @ T_odom_base_j`` and the fixes give the camera's motion
``B = T_map_cam_i^-1 @ T_map_cam_j``; with the true extrinsics ``X``, ``A @ X = X @ B``. The
check solves for ``X = T_base_cam @ Exp(xi)`` (``xi`` in the camera's right tangent,
``[x, y, z, rx, ry, rz]``) by robust least squares over all such pairs, with the odometry's
distance scale, turn scale and sideways drift as nuisances (:mod:`tagloc.localize.extrinsic_fit`).

What planar driving cannot see: with all rotations about the floor's normal, the camera's
height above the base does not enter ``A X = X B`` (any height fits); such components are
reported as unobservable and do not count. The camera's yaw is seen only against the
odometry's direction of travel, which a crabbing base (a legged robot's sideways drift) turns
alike, so its uncertainty includes the drift's prior (``sigma_lateral_drift``).

The warning is a statistical test, not a threshold on the estimate alone: it is raised when
the observable correction is *significant* (its squared Mahalanobis distance from zero under
its cluster-robust covariance exceeds Hotelling's ``T^2`` quantile at level ``alpha``, default
0.001, for the number of ``block_s``-second blocks of the drive; at least ``min_pairs`` pairs
and ``min_blocks`` blocks) *and* large enough to matter (above 0.5 deg or 2 cm). A correct
mounting on a drive too short or too noisy to tell gives no warning; so does a small but
certain correction.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.localize.extrinsic_fit import fit_extrinsics, significance
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.run import FixAttempt, LocalizationRun

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
        Sizes below which no warning is given, however certain.
    T_base_cam_estimate : SE3
    d2, d2_threshold : float
        The correction's squared Mahalanobis distance from zero and the test's threshold.
    n_blocks : int
        Blocks of the drive the covariance was measured over.
    lateral_drift : float
        The nuisance sideways drift of the odometry (m per m forward).
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
    d2: float = 0.0
    d2_threshold: float = math.inf
    n_blocks: int = 0
    lateral_drift: float = 0.0

    @property
    def significant(self) -> bool:
        """The correction is beyond its uncertainty (module docstring)."""
        return self.d2 > self.d2_threshold

    @property
    def warning(self) -> str | None:
        """One line when the correction is significant and above a size, else None."""
        large = (self.rotation_deg > self.warn_rotation_deg
                 or self.translation_m > self.warn_translation_m)  # fmt: skip
        if not (large and self.significant):
            return None
        parts = ", ".join(
            f"{a} {v * 100:+.1f} +- {s * 100:.1f} cm" if k < 3
            else f"{a} {math.degrees(v):+.2f} +- {math.degrees(s):.2f} deg"
            for k, (a, v, s) in enumerate(zip(_AXES, self.xi, self.sigma, strict=True))
            if math.isfinite(s)
        )  # fmt: skip
        return (
            f"camera extrinsics look off by {self.rotation_deg:.2f} deg / "
            f"{self.translation_m * 100:.1f} cm (from {self.n_pairs} fix pairs, "
            f"{math.sqrt(self.d2):.1f} sigma; correction in the camera frame: {parts}): "
            "check T_base_cam"
        )

    def to_dict(self) -> dict[str, Any]:
        observable = np.isfinite(self.sigma)
        return {
            "n_pairs": self.n_pairs, "n_blocks": self.n_blocks,
            "rotation_deg": self.rotation_deg, "translation_m": self.translation_m,
            "odometry_scale": self.odometry_scale, "lateral_drift": self.lateral_drift,
            "correction_cam": {a: float(v) for a, v, o in zip(_AXES, self.xi, observable,
                                                                strict=True) if o},
            "sigma_cam": {a: float(s) for a, s, o in zip(_AXES, self.sigma, observable,
                                                          strict=True) if o},
            "unobservable": [a for a, o in zip(_AXES, observable, strict=True) if not o],
            "d2": self.d2, "d2_threshold": self.d2_threshold, "significant": self.significant,
            "T_base_cam_estimate": {
                "translation": self.T_base_cam_estimate.translation.tolist(),
                "quat_xyzw": self.T_base_cam_estimate.as_quat().tolist(),
            },
            "warning": self.warning,
        }  # fmt: skip


#: One accepted fix as the recorder keeps it (its stamp aside): range, ``T_map_base``
#: (rotation matrix, translation), its covariance, and the odometry ``T_odom_base`` at its stamp.
_ROW, _CHUNK = 1 + 12 + 36 + 12, 1024


class ExtrinsicRecorder:
    """A node sink keeping what :func:`check_extrinsics` needs, in bounded memory.

    Fix records reach the sinks a few seconds after their stamps (once no batch decision can
    revise them), so the recorder keeps the odometry of the last ``odometry_window`` to twice
    that many samples (100-200 s at 200 Hz) in arrays and, for each accepted fix, one row of 62
    numbers (the fix's pose and covariance, the odometry interpolated at its stamp). It keeps
    the first ``max_fixes`` accepted fixes (about 20 minutes of 30 Hz fixes, 18 MB at most): a
    commissioning check needs minutes of driving, and a node that runs for days must not grow.
    :attr:`held` counts what it holds.
    """

    def __init__(self, max_fixes: int = 36_000, odometry_window: int = 20_000) -> None:
        self.max_fixes, self._window = max_fixes, odometry_window
        self._rows: list[FloatArray] = []  # chunks of _CHUNK fix rows
        self._fix_stamps: list[npt.NDArray[np.int64]] = []
        self._n = 0
        self._stamps = np.empty(0, dtype=np.int64)
        self._odom = np.empty((0, 12))
        self._m = 0  # odometry samples held

    @property
    def held(self) -> dict[str, int]:
        """What the recorder holds: accepted fixes, odometry samples, numbers allocated."""
        numbers = len(self._rows) * _CHUNK * (_ROW + 1) + 13 * len(self._stamps)
        return {"fixes": self._n, "odometry": self._m, "numbers": numbers}

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            self._odometry(output)
        elif (
            isinstance(output, FixAttempt) and output.accepted and output.in_map
            and self._n < self.max_fixes and self._m
        ):  # fmt: skip
            if self._n % _CHUNK == 0:
                self._rows.append(np.empty((_CHUNK, _ROW)))
                self._fix_stamps.append(np.empty(_CHUNK, dtype=np.int64))
            row = self._rows[-1][self._n % _CHUNK]
            row[0] = output.range_m
            row[1:13] = _pose_row(output.T_map_base)
            row[13:49] = np.asarray(output.cov, dtype=np.float64).ravel()
            self._fix_stamps[-1][self._n % _CHUNK] = output.stamp_ns
            # the odometry at the fix: between the two samples around its stamp
            i = int(np.searchsorted(self._stamps[: self._m], output.stamp_ns, side="right"))
            near = [max(i - 1, 0), min(i, self._m - 1)]
            row[49:61] = _pose_row(_odometry_at(
                self._stamps[near], _pose_of(self._odom[near]),
                np.array([output.stamp_ns], dtype=np.int64),
            )[0])  # fmt: skip
            self._n += 1

    def _odometry(self, e: Estimate) -> None:
        if self._m and e.stamp_ns <= self._stamps[self._m - 1]:
            self._m = 0  # the clock jumped back: the node started over
        if self._m == len(self._stamps):
            if self._m >= 2 * self._window:  # full: keep the newest window
                keep = slice(self._m - self._window, self._m)
                self._stamps[: self._window] = self._stamps[keep]
                self._odom[: self._window] = self._odom[keep]
                self._m = self._window
            else:
                size = min(max(2 * self._m, 1024), 2 * self._window)
                self._stamps = np.resize(self._stamps, size)
                self._odom = np.resize(self._odom, (size, 12))
        self._stamps[self._m] = e.stamp_ns
        self._odom[self._m] = _pose_row(e.T_odom_base)
        self._m += 1

    def check(self, T_base_cam: SE3 | None, **options: Any) -> ExtrinsicCheck | None:
        """:func:`check_extrinsics` over what was recorded (None without extrinsics)."""
        if T_base_cam is None or self._n < 2:
            return None
        stamps = np.concatenate(self._fix_stamps)[: self._n]
        order = np.argsort(stamps, kind="stable")
        rows = np.concatenate(self._rows)[: self._n][order]
        return _check(
            stamps[order], rows[:, 0], _pose_of(rows[:, 1:13]),
            rows[:, 13:49].reshape(-1, 6, 6), _pose_of(rows[:, 49:61]), T_base_cam, **options,
        )  # fmt: skip


def _pose_row(T: SE3) -> FloatArray:
    return np.concatenate([np.asarray(T.rotation.matrix).ravel(), T.translation], axis=-1)


def _pose_of(rows: FloatArray) -> SE3:
    rows = np.asarray(rows, dtype=np.float64)
    return SE3.from_trusted(rows[..., :9].reshape(*rows.shape[:-1], 3, 3), rows[..., 9:12])


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
    **options: Any,
) -> ExtrinsicCheck | None:
    """Estimate and test the mounting correction from the accepted fixes (module docstring).

    Parameters
    ----------
    fix_attempts : sequence of FixAttempt
        The run's fix attempts (the accepted fixes of the map are used: a cab's fixes are
        against odometry that rides with the cab).
    stamps_ns, T_odom_base : (N,) int64, SE3 batch of N
        The odometry, increasing stamps.
    T_base_cam : SE3
        The extrinsics the run used.
    **options
        Of :func:`_check`.

    Returns
    -------
    ExtrinsicCheck or None
        None with fewer than ``min_pairs`` pairs or ``min_blocks`` blocks.
    """
    fixes = sorted((f for f in fix_attempts if f.accepted and f.in_map), key=lambda f: f.stamp_ns)
    if len(fixes) < 2 or len(stamps_ns) < 2:
        return None
    stamps = np.array([f.stamp_ns for f in fixes], dtype=np.int64)
    return _check(
        stamps, np.array([f.range_m for f in fixes]), SE3.stack([f.T_map_base for f in fixes]),
        np.stack([f.cov for f in fixes]), _odometry_at(stamps_ns, T_odom_base, stamps),
        T_base_cam, **options,
    )  # fmt: skip


def _check(
    stamps: npt.NDArray[np.int64], range_m: FloatArray, T_map_base: SE3, cov: FloatArray,
    T_odom_base: SE3, T_base_cam: SE3, *, min_dt_s: float = 0.5, max_dt_s: float = 4.0,
    sigma_translation_m: float = 0.01, sigma_rotation_rad: float = math.radians(0.3),
    sigma_lateral_drift: float = 0.02, warn_rotation_deg: float = 0.5,
    warn_translation_m: float = 0.02, min_pairs: int = 20, min_blocks: int = 12,
    block_s: float = 5.0, alpha: float = 1e-3, gravity: bool = True,
    max_range_m: float = math.inf, sigma_gravity_rad: float = math.radians(0.1),
) -> ExtrinsicCheck | None:  # fmt: skip
    """The check on fixes sorted by stamp with the odometry at their stamps.

    ``min_dt_s``, ``max_dt_s``: each fix is paired with the first accepted fix at least
    ``min_dt_s`` later, if within ``max_dt_s``; ``sigma_translation_m``,
    ``sigma_rotation_rad``: a pair's odometry noise (nominal: the covariance is measured);
    ``sigma_lateral_drift``: prior 1-sigma of the odometry's sideways drift (m per m; 0 for
    odometry known not to crab); ``gravity``: also use "up", the map's z seen in the camera by
    each fix against the odometry's z in the base (both level: a robot on a floor, or
    visual-inertial odometry), with ``sigma_gravity_rad`` per fix; ``block_s``, ``alpha``,
    ``min_pairs``, ``min_blocks``: the test (module docstring); fixes beyond ``max_range_m``
    are left out."""
    near = range_m <= max_range_m
    if near.sum() < 2:
        return None
    fit = fit_extrinsics(
        stamps[near], T_map_base[near], cov[near], T_odom_base[near], T_base_cam,
        min_dt_s=min_dt_s, max_dt_s=max_dt_s, sigma_translation_m=sigma_translation_m,
        sigma_rotation_rad=sigma_rotation_rad, sigma_lateral_drift=sigma_lateral_drift,
        gravity=gravity, sigma_gravity_rad=sigma_gravity_rad, block_s=block_s,
    )  # fmt: skip
    if fit is None or fit.n_pairs < min_pairs or fit.n_blocks < min_blocks:
        return None
    d2, threshold = significance(fit, alpha)
    xi = np.where(fit.observable, fit.xi, 0.0)
    sigma = np.where(fit.observable, np.sqrt(np.clip(np.diag(fit.cov), 0.0, None)), math.inf)
    return ExtrinsicCheck(
        xi, sigma, fit.odometry_scale, fit.n_pairs, math.degrees(float(np.linalg.norm(xi[3:]))),
        float(np.linalg.norm(xi[:3])), warn_rotation_deg, warn_translation_m,
        T_base_cam @ SE3.exp(xi), d2, threshold, fit.n_blocks, fit.lateral_drift,
    )  # fmt: skip
