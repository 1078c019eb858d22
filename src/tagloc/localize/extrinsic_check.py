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
0.001, for the number of ``block_s``-second blocks of the drive; the clusters are blocks and,
given each fix's tag, tags; at least ``min_pairs`` pairs and ``min_blocks`` blocks) *and* large
enough to matter (above 0.5 deg or 2 cm). A correct mounting on a drive too short or too noisy
to tell gives no warning; so does a small but certain correction.

On a rig each camera is checked on its own fixes (:func:`check_extrinsics_by_camera`,
:class:`~tagloc.localize.extrinsic_rig.ExtrinsicRecorder`): what is wrong with one camera's
mounting shows in its check only, while what the odometry or the map get wrong shows in every
camera's alike (the same correction in the base frame); where cameras see a tag at the same
instant, their relative mounting is measured without the odometry and compared with the rig's
calibration (:mod:`tagloc.localize.extrinsic_rig`), and a camera's warning stands only if that
comparison does not hold it common to the rig.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.localize.extrinsic_fit import fit_extrinsics, significance
from tagloc.localize.run import FixAttempt, LocalizationRun
from tagloc.units import S_NS

__all__ = [
    "BLOCK_S",
    "MAX_FIXES",
    "ExtrinsicCheck",
    "check_extrinsics",
    "check_extrinsics_by_camera",
    "check_fixes",
    "check_run_extrinsics",
    "odometry_at",
    "tag_key",
    "thinned",
]

_AXES = ("x", "y", "z", "rx", "ry", "rz")
BLOCK_S = 5.0
#: Fixes one check fits at most (per camera): past them whole blocks are left out
#: (:func:`thinned`); the fit's memory grows with them (about 7.5 kB a fix: a 45 MB peak at the
#: bound, 189 MB for the 23,000 fixes of 700 s at 33 Hz unbounded), never with the drive.
MAX_FIXES = 6000


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
    camera : str
        The camera checked (``""``: the node's only camera).
    n_tags : int
        Tags its fixes came from (the second clustering; 0: time blocks only).
    n_fixes : int
        Fixes fitted (after :func:`thinned`).
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
    camera: str = ""
    n_tags: int = 0
    n_fixes: int = 0

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
            (f"{self.camera}: " if self.camera else "") + "camera extrinsics look off by "
            f" {self.rotation_deg:.2f} deg / "
            f"{self.translation_m * 100:.1f} cm (from {self.n_pairs} fix pairs, "
            f"{math.sqrt(self.d2):.1f} sigma; correction in the camera frame: {parts}): "
            "check T_base_cam"
        )

    def to_dict(self) -> dict[str, Any]:
        observable = np.isfinite(self.sigma)
        return {
            "camera": self.camera, "n_fixes": self.n_fixes, "n_pairs": self.n_pairs,
            "n_blocks": self.n_blocks, "n_tags": self.n_tags,
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


def tag_key(fix: FixAttempt) -> int:
    """The fix's tag for the clustering (its smallest tag id; -1 for none)."""
    return min(fix.tag_ids) if fix.tag_ids else -1


def _tag_keys(fixes: Sequence[FixAttempt]) -> npt.NDArray[np.int64]:
    return np.array([tag_key(f) for f in fixes], dtype=np.int64)


def thinned(
    stamps: npt.NDArray[np.int64], max_fixes: int, block_s: float = BLOCK_S
) -> tuple[npt.NDArray[np.bool_], int]:
    """Which fixes a check of at most ``max_fixes`` keeps, and the level ``L``: the fixes of
    every ``2**L``-th ``block_s`` block (whole blocks, so pairs and clusters stay as they were
    within them), for the least ``L`` that keeps at most ``max_fixes``."""
    block = stamps // max(round(block_s * S_NS), 1)
    level = 0
    while True:
        keep = block % (1 << level) == 0
        if keep.sum() <= max_fixes or level >= 62:
            return keep, level
        level += 1


def check_run_extrinsics(
    run: LocalizationRun, T_base_cam: SE3, *, camera: str | None = None, **options: Any
) -> ExtrinsicCheck | None:
    """:func:`check_extrinsics` on a recorded run (the fixes of ``camera`` only, if given)."""
    fixes = run.fixes if camera is None else [f for f in run.fixes if f.camera == camera]
    return check_extrinsics(fixes, run.stamps_ns, run.T_odom_base, T_base_cam, **options)


def check_extrinsics_by_camera(
    fix_attempts: Sequence[FixAttempt], stamps_ns: npt.NDArray[np.int64], T_odom_base: SE3,
    T_base_cam_by_camera: Mapping[str, SE3 | None], **options: Any,
) -> dict[str, ExtrinsicCheck | None]:  # fmt: skip
    """:func:`check_extrinsics` for each camera of a rig on its own fixes (None for a camera
    without extrinsics or without a verdict)."""
    return {
        name: None if X is None else check_extrinsics(
            [f for f in fix_attempts if f.camera == name], stamps_ns, T_odom_base, X,
            camera=name, **options,
        )
        for name, X in T_base_cam_by_camera.items()
    }  # fmt: skip


def odometry_at(
    stamps_ns: npt.NDArray[np.int64], T_odom_base: SE3, stamps: npt.NDArray[np.int64]
) -> SE3:
    """The odometry at ``stamps``, interpolated between its samples (clamped at the ends)."""
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
    by_tag: bool = True,
    **options: Any,
) -> ExtrinsicCheck | None:
    """Estimate and test the mounting correction from the accepted fixes (module docstring).

    Parameters
    ----------
    fix_attempts : sequence of FixAttempt
        The run's fix attempts of one camera (its accepted fixes of the map are used: a cab's
        fixes are against odometry that rides with the cab).
    stamps_ns, T_odom_base : (N,) int64, SE3 batch of N
        The odometry, increasing stamps.
    T_base_cam : SE3
        The extrinsics the run used.
    by_tag : bool
        Cluster by tag too (module docstring); False: by time blocks only.
    **options
        Of :func:`check_fixes`.

    Returns
    -------
    ExtrinsicCheck or None
        None with fewer than ``min_pairs`` pairs or ``min_blocks`` blocks.
    """
    fixes = sorted(
        (f for f in fix_attempts if f.accepted and f.in_map and f.of_tags), key=lambda f: f.stamp_ns
    )
    if len(fixes) < 2 or len(stamps_ns) < 2:
        return None
    stamps = np.array([f.stamp_ns for f in fixes], dtype=np.int64)
    return check_fixes(
        stamps, np.array([f.range_m for f in fixes]), SE3.stack([f.T_map_base for f in fixes]),
        np.stack([f.cov for f in fixes]), odometry_at(stamps_ns, T_odom_base, stamps),
        T_base_cam, tag_keys=_tag_keys(fixes) if by_tag else None, **options,
    )  # fmt: skip


def check_fixes(
    stamps: npt.NDArray[np.int64], range_m: FloatArray, T_map_base: SE3, cov: FloatArray,
    T_odom_base: SE3, T_base_cam: SE3, *, tag_keys: npt.NDArray[np.int64] | None = None,
    camera: str = "", min_dt_s: float = 0.5, max_dt_s: float = 4.0,
    sigma_translation_m: float = 0.01, sigma_rotation_rad: float = math.radians(0.3),
    sigma_lateral_drift: float = 0.02, warn_rotation_deg: float = 0.5,
    warn_translation_m: float = 0.02, min_pairs: int = 20, min_blocks: int = 12,
    block_s: float = BLOCK_S, alpha: float = 1e-3, gravity: bool = True,
    max_range_m: float = math.inf, sigma_gravity_rad: float = math.radians(0.1),
    max_fixes: int = MAX_FIXES,
) -> ExtrinsicCheck | None:  # fmt: skip
    """The check on one camera's fixes sorted by stamp with the odometry at their stamps.

    ``tag_keys``: each fix's tag (:func:`tag_key`; None: time blocks only); ``camera``: named
    in the warning; ``min_dt_s``, ``max_dt_s``: each fix is paired with the first accepted fix
    at least ``min_dt_s`` later, if within ``max_dt_s``; ``sigma_translation_m``,
    ``sigma_rotation_rad``: a pair's odometry noise (nominal: the covariance is measured);
    ``sigma_lateral_drift``: prior 1-sigma of the odometry's sideways drift (m per m; 0 for
    odometry known not to crab); ``gravity``: also use "up", the map's z seen in the camera by
    each fix against the odometry's z in the base (both level: a robot on a floor, or
    visual-inertial odometry), with ``sigma_gravity_rad`` per fix; ``block_s``, ``alpha``,
    ``min_pairs``, ``min_blocks``: the test (module docstring); fixes beyond ``max_range_m``
    are left out; beyond ``max_fixes`` fixes, whole blocks are (:func:`thinned`), so the fit's
    memory is bounded whatever the drive's length."""
    near = range_m <= max_range_m
    keep, _ = thinned(stamps[near], max_fixes, block_s)
    near[near] = keep
    if near.sum() < 2:
        return None
    fit = fit_extrinsics(
        stamps[near], T_map_base[near], cov[near], T_odom_base[near], T_base_cam,
        min_dt_s=min_dt_s, max_dt_s=max_dt_s, sigma_translation_m=sigma_translation_m,
        sigma_rotation_rad=sigma_rotation_rad, sigma_lateral_drift=sigma_lateral_drift,
        gravity=gravity, sigma_gravity_rad=sigma_gravity_rad, block_s=block_s,
        tag_keys=None if tag_keys is None else tag_keys[near],
    )  # fmt: skip
    if fit is None or fit.n_pairs < min_pairs or fit.n_blocks < min_blocks:
        return None
    d2, threshold = significance(fit, alpha)
    xi = np.where(fit.observable, fit.xi, 0.0)
    sigma = np.where(fit.observable, np.sqrt(np.clip(np.diag(fit.cov), 0.0, None)), math.inf)
    return ExtrinsicCheck(
        xi, sigma, fit.odometry_scale, fit.n_pairs, math.degrees(float(np.linalg.norm(xi[3:]))),
        float(np.linalg.norm(xi[:3])), warn_rotation_deg, warn_translation_m,
        T_base_cam @ SE3.exp(xi), d2, threshold, fit.n_blocks, fit.lateral_drift, camera,
        fit.n_tags, int(near.sum()),
    )  # fmt: skip
