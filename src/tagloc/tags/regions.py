"""Detection in regions of an image: crops aligned to the detector's grid, corners shifted back.

A :class:`PixelRegion` is a box of whole pixels ``[u0, u1) x [v0, v1)`` with the decimation
its quads are searched at. :func:`detect_in_regions` runs an AprilTag 3 detector on each crop
and shifts the corners back by ``(u0, v0)``: in tagloc's convention (pixel centers at integer
coordinates, :mod:`tagloc.tags.detection`) pixel ``(i, j)`` of a crop is pixel
``(u0 + i, v0 + j)`` of the image, so the shift is exact.

Why the corners equal the full frame's: AprilTag 3 decimates by taking every ``d``-th pixel
from the origin and thresholds in tiles of 4 decimated pixels from the origin. A crop whose
origin is a multiple of ``4 d`` pixels (:func:`grid_px`) sees the same decimated pixels and the
same tiles as the full frame; away from the crop's border (the margin the caller leaves: the
blur kernel, the tile statistics' 3x3 neighbourhood) every step gives the same numbers, and edge
refinement and decoding read the full-resolution pixels, which are the same. Checked against
the full-frame detection in ``tests/tags/test_regions.py``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.tags.apriltag_backend import AprilTagDetector
from tagloc.tags.detection import TagDetection
from tagloc.tags.errors import TagInputError
from tagloc.tags.images import as_gray_u8

__all__ = ["PixelRegion", "detect_in_regions", "grid_px", "merge_regions", "region_around"]


@dataclass(frozen=True, slots=True)
class PixelRegion:
    """A box of whole pixels ``[u0, u1) x [v0, v1)`` and its quad decimation.

    Attributes
    ----------
    u0, v0, u1, v1 : int
        Column and row bounds (``0 <= u0 < u1 <= width``, likewise rows).
    quad_decimate : float
        Decimation the detector searches this region's quads at (>= 1).
    """

    u0: int
    v0: int
    u1: int
    v1: int
    quad_decimate: float = 2.0

    def __post_init__(self) -> None:
        if not (0 <= self.u0 < self.u1 and 0 <= self.v0 < self.v1):
            raise TagInputError(f"region: empty or negative box {self.box}")
        if not (math.isfinite(self.quad_decimate) and self.quad_decimate >= 1.0):
            raise TagInputError(f"region: quad_decimate must be >= 1, got {self.quad_decimate}")

    @property
    def box(self) -> tuple[int, int, int, int]:
        """``(u0, v0, u1, v1)``."""
        return self.u0, self.v0, self.u1, self.v1

    @property
    def area_px(self) -> int:
        """Pixels in the region."""
        return (self.u1 - self.u0) * (self.v1 - self.v0)

    def overlaps(self, other: PixelRegion) -> bool:
        """Whether the two boxes share a pixel."""
        return (
            self.u0 < other.u1 and other.u0 < self.u1 and self.v0 < other.v1 and other.v0 < self.v1
        )


def grid_px(quad_decimate: float) -> int:
    """The step (pixels) a crop's origin must be a multiple of for detection at
    ``quad_decimate`` to see the full frame's decimated pixels and threshold tiles: ``4 d`` for
    an integer ``d``, ``8 d`` for a half-integer (1.5: 12), else 48."""
    if float(quad_decimate).is_integer():
        return 4 * int(quad_decimate)
    if float(2.0 * quad_decimate).is_integer():
        return 4 * int(2.0 * quad_decimate)
    return 48


def region_around(
    u_min: float, v_min: float, u_max: float, v_max: float, width: int, height: int,
    quad_decimate: float,
) -> PixelRegion | None:  # fmt: skip
    """The grid-aligned region holding the box ``[u_min, u_max] x [v_min, v_max]`` (pixel
    coordinates, clipped to the image); None if the box misses the image.

    The origin is rounded down to a multiple of :func:`grid_px`; the far bounds are rounded up
    (past the last pixel the box touches) and clipped to ``width`` x ``height``.
    """
    values = (u_min, v_min, u_max, v_max)
    if not all(math.isfinite(x) for x in values) or u_max < u_min or v_max < v_min:
        return None
    if u_max < -0.5 or v_max < -0.5 or u_min > width - 0.5 or v_min > height - 0.5:
        return None
    grid = grid_px(quad_decimate)
    u0 = max(0, math.floor(max(u_min, 0.0) / grid) * grid)
    v0 = max(0, math.floor(max(v_min, 0.0) / grid) * grid)
    u1 = min(width, math.floor(u_max) + 2)
    v1 = min(height, math.floor(v_max) + 2)
    if u1 <= u0 or v1 <= v0:
        return None
    return PixelRegion(u0, v0, u1, v1, float(quad_decimate))


def merge_regions(
    regions: Iterable[PixelRegion], width: int, height: int
) -> list[PixelRegion]:
    """Regions that overlap merged into their bounding box (at the smaller decimation,
    re-aligned to its grid), until none overlap; sorted by ``(v0, u0)``."""
    pending = list(regions)
    merged = True
    while merged:
        merged = False
        out: list[PixelRegion] = []
        for region in pending:
            for i, kept in enumerate(out):
                if kept.overlaps(region):
                    decimate = min(kept.quad_decimate, region.quad_decimate)
                    union = region_around(
                        min(kept.u0, region.u0), min(kept.v0, region.v0),
                        max(kept.u1, region.u1) - 1, max(kept.v1, region.v1) - 1,
                        width, height, decimate,
                    )  # fmt: skip
                    assert union is not None
                    out[i] = union
                    merged = True
                    break
            else:
                out.append(region)
        pending = out
    return sorted(pending, key=lambda r: (r.v0, r.u0))


def shifted(detection: TagDetection, du: float, dv: float) -> TagDetection:
    """The detection with its corners moved by ``(du, dv)`` pixels."""
    corners = detection.corners_px + np.array([du, dv], dtype=np.float64)
    return TagDetection(
        detection.tag_id, detection.family, corners, detection.hamming,
        detection.decision_margin,
    )  # fmt: skip


def detect_in_regions(
    detector: AprilTagDetector, image_gray: npt.NDArray[np.generic],
    regions: Sequence[PixelRegion],
) -> list[TagDetection]:  # fmt: skip
    """Detect tags in each region and return them in full-image pixel coordinates.

    Parameters
    ----------
    detector : AprilTagDetector
        Run on each crop at the region's ``quad_decimate``.
    image_gray : (H, W) image
        As :meth:`~tagloc.tags.detection.TagDetector.detect` takes it.
    regions : sequence of PixelRegion
        Inside the image (typically from :func:`merge_regions`: no two overlap).

    Returns
    -------
    list of TagDetection
        Sorted as a detector sorts them; a tag found in two regions is kept once (the
        detection with the larger decision margin).

    Raises
    ------
    TagInputError
        If the image is not usable or a region lies outside it.
    """
    gray = as_gray_u8(image_gray, "image_gray")
    height, width = gray.shape
    best: dict[tuple[int, int, int], TagDetection] = {}
    found: list[TagDetection] = []
    for region in regions:
        if region.u1 > width or region.v1 > height:
            raise TagInputError(f"region {region.box} outside the {width}x{height} image")
        crop = np.ascontiguousarray(gray[region.v0 : region.v1, region.u0 : region.u1])
        for det in detector.detect(crop, quad_decimate=region.quad_decimate):
            found.append(shifted(det, region.u0, region.v0))
    for det in found:
        key = (det.tag_id, round(float(det.center_px[0])), round(float(det.center_px[1])))
        near = next((k for k in best if k[0] == key[0] and _close(k, key)), None)
        if near is None:
            best[key] = det
        elif det.decision_margin > best[near].decision_margin:
            best[near] = det
    detections = list(best.values())
    detections.sort(key=lambda d: (d.tag_id, d.center_px[1], d.center_px[0]))
    return detections


def _close(a: tuple[int, int, int], b: tuple[int, int, int], tol_px: int = 3) -> bool:
    return abs(a[1] - b[1]) <= tol_px and abs(a[2] - b[2]) <= tol_px
