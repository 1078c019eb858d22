"""Fix acceptance by viewing conditions: distance, viewing angle, and (from images) blur and
brightness.

Every fix attempt of a run (:class:`~tagloc.localize.run.FixAttempt`, accepted or not, rejected
by a per-observation gate included) falls in one bin per condition; a bin's acceptance rate is
accepted / attempts. Blur and brightness are measured in the tag's bounding box of the raw image
(:func:`image_measures`): the variance of the Laplacian (low = blurred; its scale depends on
the camera, so its bins are the quartiles of the drive) and the mean intensity (0-255). A bag
of pre-detected corners has no images: those two conditions are then absent and say so.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc.localize.run import FixAttempt
from tagloc.tags import TagDetection

__all__ = ["AcceptanceBin", "ImageMeasure", "acceptance_by_conditions", "image_measures"]

DISTANCE_EDGES_M = (0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, math.inf)
ANGLE_EDGES_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0)
BRIGHTNESS_EDGES = (0.0, 32.0, 64.0, 128.0, 192.0, 256.0)
NO_IMAGES = "the bag has pre-detected corners only (no images): blur and brightness not measured"


@dataclass(frozen=True, slots=True)
class ImageMeasure:
    """Blur (variance of the Laplacian) and brightness (mean, 0-255) in a tag's bounding box."""

    laplacian_var: float
    brightness: float


def image_measures(
    image: npt.NDArray[Any], detections: Sequence[TagDetection]
) -> dict[int, ImageMeasure]:
    """:class:`ImageMeasure` of each detection (by tag id) in a raw image (grey or BGR)."""
    import cv2

    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    h, w = grey.shape[:2]
    out = {}
    for d in detections:
        c = np.asarray(d.corners_px)
        x0, y0 = np.clip(np.floor(c.min(axis=0)).astype(int), 0, [w - 1, h - 1])
        x1, y1 = np.clip(np.ceil(c.max(axis=0)).astype(int) + 1, 1, [w, h])
        if x1 - x0 < 3 or y1 - y0 < 3:
            continue
        box = grey[y0:y1, x0:x1].astype(np.float64)
        lap = cv2.Laplacian(box, cv2.CV_64F)
        out[d.tag_id] = ImageMeasure(float(lap.var()), float(box.mean()))
    return out


@dataclass(frozen=True, slots=True)
class AcceptanceBin:
    """One bin of one condition: ``[lo, hi)`` in the condition's unit."""

    lo: float
    hi: float
    attempts: int
    accepted: int

    @property
    def rate(self) -> float:
        return self.accepted / self.attempts if self.attempts else math.nan

    def to_dict(self) -> dict[str, Any]:
        return {"lo": self.lo, "hi": self.hi, "attempts": self.attempts,
                "accepted": self.accepted, "rate": self.rate}  # fmt: skip


def _bins(values: npt.NDArray[np.float64], ok: npt.NDArray[np.bool_],
          edges: Sequence[float]) -> list[AcceptanceBin]:  # fmt: skip
    out = []
    finite = np.isfinite(values)
    for lo, hi in itertools.pairwise(edges):
        m = finite & (values >= lo) & (values < hi)
        out.append(AcceptanceBin(float(lo), float(hi), int(m.sum()), int((m & ok).sum())))
    return out


def acceptance_by_conditions(
    fixes: Iterable[FixAttempt],
    measures: dict[tuple[int, int], ImageMeasure] | None = None,
) -> dict[str, Any]:
    """Acceptance rates binned by ``distance_m``, ``view_angle_deg`` (attempts refused by a
    per-observation gate, before or after PnP, have no angle: counted in
    ``view_angle_unknown``, not binned) and, with ``measures``
    (by ``(stamp_ns, tag_id)``; a joint fix takes its first tag's), ``laplacian_var`` and
    ``brightness``. Returns ``{condition: [AcceptanceBin.to_dict(), ...], "note": ...}``."""
    attempts = [f for f in fixes if f.tag_ids]
    ok = np.array([f.accepted for f in attempts], dtype=bool)
    dist = np.array([f.range_m for f in attempts], dtype=np.float64)
    angle = np.degrees(np.array([f.view_angle_rad for f in attempts], dtype=np.float64))
    out: dict[str, Any] = {
        "attempts": len(attempts), "accepted": int(ok.sum()),
        # a per-observation gate's refusal carries a range but no viewing angle
        "view_angle_unknown": int((~np.isfinite(angle)).sum()),
        "distance_m": [b.to_dict() for b in _bins(dist, ok, DISTANCE_EDGES_M)],
        "view_angle_deg": [b.to_dict() for b in _bins(angle, ok, ANGLE_EDGES_DEG)],
    }  # fmt: skip
    if measures is None:
        out["note"] = NO_IMAGES
        return out
    got = [measures.get((f.stamp_ns, f.tag_ids[0])) for f in attempts]
    blur = np.array([math.nan if g is None else g.laplacian_var for g in got])
    light = np.array([math.nan if g is None else g.brightness for g in got])
    finite = blur[np.isfinite(blur)]
    if finite.size >= 4:
        q = np.unique(np.percentile(finite, [0, 25, 50, 75]))
        out["laplacian_var"] = [b.to_dict() for b in _bins(blur, ok, [*q.tolist(), math.inf])]
    out["brightness"] = [b.to_dict() for b in _bins(light, ok, BRIGHTNESS_EDGES)]
    out["note"] = f"blur and brightness measured for {int(np.isfinite(blur).sum())} attempts"
    return out
