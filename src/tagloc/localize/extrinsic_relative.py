"""A rig's cameras judged together: their relative mounting, measured without the odometry.

What the odometry, the map or the base frame's placement get wrong, every camera's check finds
alike; a camera's own mis-set only its own. Where two cameras see one tag at the same instant,
their relative mounting is measured without the odometry: ``T_cam0_cam1 = T_map_cam0^-1 @
T_map_cam1`` from the two fixes (the tag's surveyed pose cancels), against the calibration's
``T_base_cam0^-1 @ T_base_cam1`` (:func:`relative_mounting`: the mean of the tags' median
corrections, its covariance from the spread over tags, Hotelling's test over the tags). When it
agrees, a mis-set of one of the two alone is ruled out, and the warnings of both are withdrawn
in favour of one line for the rig (:func:`rig_verdicts`): on the dupont stereo drive the two
cameras' checks find the same correction in the base frame (0.3 deg, 9-10 cm), while their
relative mounting, from 1,270 simultaneous fixes of 19 tags, agrees with the calibration to
0.3 cm and 0.13 deg (d2 29.7 against a threshold of 65.3).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.localize.extrinsic_check import ExtrinsicCheck

__all__ = ["RelativeMounting", "RigVerdict", "relative_mounting", "rig_verdicts"]


@dataclass(frozen=True, slots=True)
class RelativeMounting:
    """A camera's mounting relative to the reference camera, measured from the instants both
    saw one tag, against the calibration: ``T_ref_cam = T_ref_cam_calibrated @ Exp(xi)``.

    Attributes
    ----------
    reference, camera : str
    xi, sigma : (6,) float
        ``[x, y, z, rx, ry, rz]`` (m, rad) in the camera's frame, and standard deviations.
    n_pairs, n_tags : int
        Simultaneous fixes of one tag used, and their tags (the clusters).
    d2, d2_threshold : float
        Mahalanobis distance squared of ``xi`` from 0 and Hotelling's threshold (``inf`` with
        no more tags than 6).
    warn_rotation_deg, warn_translation_m : float
    """

    reference: str
    camera: str
    xi: FloatArray
    sigma: FloatArray
    n_pairs: int
    n_tags: int
    d2: float
    d2_threshold: float
    warn_rotation_deg: float = 0.5
    warn_translation_m: float = 0.02

    @property
    def agrees(self) -> bool:
        """The calibration holds: the measured difference is not both significant and large
        (and there were enough tags to tell)."""
        large = (math.degrees(float(np.linalg.norm(self.xi[3:]))) > self.warn_rotation_deg
                 or float(np.linalg.norm(self.xi[:3])) > self.warn_translation_m)  # fmt: skip
        return math.isfinite(self.d2_threshold) and not (large and self.d2 > self.d2_threshold)

    def to_dict(self) -> dict[str, Any]:
        axes = ("x", "y", "z", "rx", "ry", "rz")
        return {
            "reference": self.reference, "n_pairs": self.n_pairs, "n_tags": self.n_tags,
            "correction_cam": dict(zip(axes, self.xi.tolist(), strict=True)),
            "sigma_cam": dict(zip(axes, self.sigma.tolist(), strict=True)),
            "d2": self.d2, "d2_threshold": self.d2_threshold, "agrees": self.agrees,
        }  # fmt: skip


def relative_mounting(
    reference: str, camera: str,
    stamps_ref: npt.NDArray[np.int64], tags_ref: npt.NDArray[np.int64], T_map_base_ref: SE3,
    stamps: npt.NDArray[np.int64], tags: npt.NDArray[np.int64], T_map_base: SE3,
    T_base_ref: SE3, T_base_cam: SE3, *, alpha: float = 1e-3, min_pairs: int = 20,
) -> RelativeMounting | None:  # fmt: skip
    """The camera's mounting relative to the reference from their fixes of one tag at one
    stamp (module docstring); None with fewer than ``min_pairs`` such instants."""
    from scipy.stats import f as f_dist

    index = {key: k for k, key in enumerate(zip(stamps_ref.tolist(), tags_ref.tolist(),
                                                strict=True))}  # fmt: skip
    pairs = zip(stamps.tolist(), tags.tolist(), strict=True)
    matches = [(index[key], k) for k, key in enumerate(pairs) if key in index and key[1] >= 0]
    if len(matches) < min_pairs:
        return None
    i, j = (np.array(m) for m in zip(*matches, strict=True))
    T_ref_cam = (T_map_base_ref[i] @ T_base_ref).inverse() @ (T_map_base[j] @ T_base_cam)
    calibrated = T_base_ref.inverse() @ T_base_cam
    delta = (calibrated.inverse() @ T_ref_cam).log()  # (K, 6)
    keys = tags[j]
    medians = np.array([np.median(delta[keys == t], axis=0) for t in np.unique(keys)])
    g = len(medians)
    xi = medians.mean(axis=0)
    cov = np.cov(medians.T) / g if g > 1 else np.full((6, 6), np.inf)
    sigma = np.sqrt(np.diag(cov))
    if g <= 6 or not np.isfinite(cov).all():
        return RelativeMounting(reference, camera, xi, sigma, len(i), g, 0.0, math.inf)
    d2 = float(xi @ np.linalg.pinv(cov) @ xi)
    threshold = float(6 * (g - 1) / (g - 6) * f_dist.ppf(1.0 - alpha, 6, g - 6))
    return RelativeMounting(reference, camera, xi, sigma, len(i), g, d2, threshold)


@dataclass(frozen=True, slots=True)
class RigVerdict:
    """One camera's verdict on a rig: its own check, its relative mounting to the reference
    (None: the reference, or not measured), and the warning that stands (None: none, or
    withdrawn as common to the rig: ``shared``)."""

    check: ExtrinsicCheck | None
    relative: RelativeMounting | None
    warning: str | None
    shared: bool

    def to_dict(self) -> dict[str, Any] | None:
        if self.check is None:
            return None
        return {**self.check.to_dict(), "warning": self.warning, "shared_with_rig": self.shared,
                "own_warning": self.check.warning,
                "relative": None if self.relative is None else self.relative.to_dict()}  # fmt: skip


def rig_verdicts(
    checks: Mapping[str, ExtrinsicCheck | None], relative: Mapping[str, RelativeMounting | None]
) -> tuple[dict[str, RigVerdict], str | None]:
    """Each camera's verdict, and one line for the rig when warnings were withdrawn.

    A camera's warning is withdrawn when its mounting relative to another camera was measured
    and agrees with the calibration (the reference's: when any camera's relative mounting
    agrees): a mis-set of it alone is then ruled out, and what its check found is common to
    the rig (the odometry, the map, or the placement of the base frame)."""
    names = list(checks)
    agreeing = {n for n, r in relative.items() if r is not None and r.agrees}
    if agreeing and names:
        agreeing.add(names[0])
    verdicts: dict[str, RigVerdict] = {}
    withdrawn = []
    for name, check in checks.items():
        own = None if check is None else check.warning
        shared = own is not None and name in agreeing
        if shared:
            withdrawn.append(name)
        verdicts[name] = RigVerdict(check, relative.get(name), None if shared else own, shared)
    line = None
    if withdrawn:
        line = (
            f"the mounting check of {', '.join(withdrawn)} finds a correction the rig's "
            "cameras share (their relative mounting agrees with the calibration): the "
            "odometry, the map or the base frame's placement, not one camera's mounting"
        )
    return verdicts, line
