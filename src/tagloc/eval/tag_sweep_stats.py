"""Per-cell statistics of a tag-sensor sweep (pure functions).

:class:`ViewOutcome` is one scored view (:mod:`tagloc.eval.tag_sweep`); :func:`cell_row` turns a
cell's views into a :class:`TagSweepRow`; the checks of the rows against
:class:`~tagloc.eval.tag_sweep_config.TagSweepTargets` are :mod:`tagloc.eval.tag_sweep_verdicts`'.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Degrees of freedom of a pose's NEES.
POSE_DOF = 6


@dataclass(frozen=True, slots=True)
class ViewOutcome:
    """One view of a sweep, scored against the renderer's truth.

    Attributes
    ----------
    detected : bool
        The true tag's id was detected.
    accepted : bool
        ``observe_tags`` accepted it.
    corner_sq_px2 : float
        Mean over the four corners of the squared distance detected - true (px^2); NaN if not
        detected.
    detect_s, rest_s : float
        Wall time of detection, and of ``observe_tags``, seconds.
    rejection : str or None
        Why the true tag was not accepted: a ``RejectReason`` value, ``"missed"`` (not
        detected), None if accepted.
    false_detections : int
        Detections of other ids.
    position_error_m, rotation_error_deg, nees : float
        Of the accepted ``T_cam_tag`` against the truth (NaN if not accepted).
    camera_position_error_m : float
        Error of the camera's position in the tag's frame (``T_cam_tag^-1``), which is what a
        fix's position error is for an exactly surveyed tag: it adds rotation error times range.
    flip : bool
        The accepted estimate took the wrong IPPE branch.
    """

    detected: bool
    accepted: bool
    corner_sq_px2: float
    detect_s: float
    rest_s: float
    rejection: str | None
    false_detections: int = 0
    position_error_m: float = math.nan
    rotation_error_deg: float = math.nan
    nees: float = math.nan
    flip: bool = False
    camera_position_error_m: float = math.nan

    def scored(
        self,
        position_error_m: float,
        rotation_error_deg: float,
        flip: bool,
        nees: float,
        camera_position_error_m: float = math.nan,
    ) -> ViewOutcome:
        """The same view with the accepted estimate's errors."""
        return dataclasses.replace(
            self,
            position_error_m=position_error_m,
            rotation_error_deg=rotation_error_deg,
            flip=flip,
            nees=nees,
            camera_position_error_m=camera_position_error_m,
        )


@dataclass(frozen=True, slots=True)
class TagSweepRow:
    """One cell of a sweep: rates, errors of the accepted estimates, timing.

    Attributes
    ----------
    distance_m, angle_deg, blur_px, noise_dn : float
        The cell.
    n_views, n_detected, n_accepted : int
    detection_rate, acceptance_rate : float
        ``n_detected / n_views``, ``n_accepted / n_views``.
    position_error_median_m, position_error_p95_m : float
        Of ``T_cam_tag``'s translation, accepted views (NaN if none).
    rotation_error_median_deg, rotation_error_p95_deg : float
    camera_position_error_median_m, camera_position_error_p95_m : float
        Of the camera's position in the tag frame (a fix's position error; see
        :class:`ViewOutcome`).
    flips : int
        Accepted ambiguity flips.
    nees_per_dof : float
        Mean NEES of the accepted estimates over 6 (1 for an honest covariance).
    corner_rms_px : float
        RMS distance of detected corners from the truth, px (NaN if none detected).
    detect_ms, rest_ms : float
        Median per-frame time of detection, and of PnP + covariance + gates, ms.
    false_detections : int
        Detections of ids that were not in the image.
    rejections : tuple of (str, int)
        Why views were not accepted (``"missed"``: not detected), most frequent first.
    position_errors_m, rotation_errors_deg, nees_values : tuple of float
        The accepted views' values the medians and the mean are of (for the checks' intervals,
        :mod:`tagloc.eval.tag_sweep_verdicts`).
    """

    distance_m: float
    angle_deg: float
    blur_px: float
    noise_dn: float
    n_views: int
    n_detected: int
    n_accepted: int
    detection_rate: float
    acceptance_rate: float
    position_error_median_m: float
    position_error_p95_m: float
    rotation_error_median_deg: float
    rotation_error_p95_deg: float
    camera_position_error_median_m: float
    camera_position_error_p95_m: float
    flips: int
    nees_per_dof: float
    corner_rms_px: float
    detect_ms: float
    rest_ms: float
    false_detections: int
    rejections: tuple[tuple[str, int], ...]
    position_errors_m: tuple[float, ...] = ()
    rotation_errors_deg: tuple[float, ...] = ()
    nees_values: tuple[float, ...] = ()


def percentile_or_nan(values: list[float], q: float) -> float:
    """``np.percentile(values, q)``, NaN for no values."""
    return float(np.percentile(values, q)) if values else math.nan


def cell_row(
    distance_m: float,
    angle_deg: float,
    blur_px: float,
    noise_dn: float,
    views: Sequence[ViewOutcome],
) -> TagSweepRow:
    """Statistics of one cell's views (see :class:`TagSweepRow`)."""
    n = len(views)
    accepted = [v for v in views if v.accepted]
    corner = [v.corner_sq_px2 for v in views if v.detected and math.isfinite(v.corner_sq_px2)]
    position = [v.position_error_m for v in accepted]
    rotation = [v.rotation_error_deg for v in accepted]
    camera = [v.camera_position_error_m for v in accepted]
    n_detected = sum(v.detected for v in views)
    reasons = Counter(v.rejection for v in views if v.rejection is not None)
    return TagSweepRow(
        distance_m=distance_m,
        angle_deg=angle_deg,
        blur_px=blur_px,
        noise_dn=noise_dn,
        n_views=n,
        n_detected=n_detected,
        n_accepted=len(accepted),
        detection_rate=n_detected / n if n else math.nan,
        acceptance_rate=len(accepted) / n if n else math.nan,
        position_error_median_m=percentile_or_nan(position, 50),
        position_error_p95_m=percentile_or_nan(position, 95),
        rotation_error_median_deg=percentile_or_nan(rotation, 50),
        rotation_error_p95_deg=percentile_or_nan(rotation, 95),
        camera_position_error_median_m=percentile_or_nan(camera, 50),
        camera_position_error_p95_m=percentile_or_nan(camera, 95),
        flips=sum(v.flip for v in accepted),
        nees_per_dof=float(np.mean([v.nees for v in accepted])) / POSE_DOF
        if accepted
        else math.nan,
        corner_rms_px=math.sqrt(float(np.mean(corner))) if corner else math.nan,
        detect_ms=1e3 * float(np.median([v.detect_s for v in views])) if n else math.nan,
        rest_ms=1e3 * float(np.median([v.rest_s for v in views])) if n else math.nan,
        false_detections=sum(v.false_detections for v in views),
        rejections=tuple(sorted(reasons.items(), key=lambda kv: (-kv[1], kv[0]))),
        position_errors_m=tuple(position),
        rotation_errors_deg=tuple(rotation),
        nees_values=tuple(v.nees for v in accepted),
    )


def pooled_nees_per_dof(rows: Sequence[TagSweepRow]) -> float:
    """Mean NEES / 6 over every accepted estimate of ``rows`` (NaN if none)."""
    n = sum(r.n_accepted for r in rows)
    if n == 0:
        return math.nan
    return sum(r.n_accepted * r.nees_per_dof for r in rows if r.n_accepted) / n


def conditions(rows: Sequence[TagSweepRow]) -> list[tuple[float, float]]:
    """The sweep's ``(blur_px, noise_dn)`` conditions in row order."""
    return list(dict.fromkeys((r.blur_px, r.noise_dn) for r in rows))
