"""Black-and-white images of real tags, upright, for the simulator to render.

The image is the tag as printed (see :mod:`tagloc.tags.families` for *upright*): a
``border_cells x border_cells`` grid (data bits plus a one-cell black border; 8 cells for
tag36h11), framed by ``quiet_zone_cells`` of white on every side, each cell ``cells_px`` pixels
square. The black-border square is what ``size`` measures: its edge spans
``border_cells * cells_px`` pixels. :func:`bitmap_corners_px` gives its corners in the image's
pixel coordinates, in the corner order of :class:`~tagloc.tags.detection.TagDetection`, so the
homography from these corners to the projected object points renders the tag where a detector
will find it; :func:`render_tag` does exactly that, area-sampled.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.tags.errors import TagInputError
from tagloc.tags.families import family_spec, opencv_dictionary, opencv_quarter_turns


def tag_bitmap(
    family: str, tag_id: int, cells_px: int = 10, quiet_zone_cells: int = 1
) -> npt.NDArray[np.uint8]:
    """The upright image of one tag.

    Parameters
    ----------
    family : str
        A known family name (``"tag36h11"``, ``"aruco_4x4_50"``).
    tag_id : int
        Id in the family, ``0 .. num_ids - 1``.
    cells_px : int
        Pixels per cell side (>= 1).
    quiet_zone_cells : int
        White margin around the black border, in cells (>= 0). AprilTag's reference images use 1;
        detectors need at least 1 in the rendered scene (a white surround).

    Returns
    -------
    (N, N) uint8
        0 for black, 255 for white, ``N = (border_cells + 2 * quiet_zone_cells) * cells_px``.

    Raises
    ------
    TagInputError
        If ``tag_id``, ``cells_px`` or ``quiet_zone_cells`` is out of range.
    TagBackendError
        If ``family`` is unknown.
    """
    spec = family_spec(family)
    _check_count(tag_id, "tag_id", 0)
    if tag_id >= spec.num_ids:
        raise TagInputError(f"tag_id: {family} has ids 0..{spec.num_ids - 1}, got {tag_id}")
    _check_count(cells_px, "cells_px", 1)
    _check_count(quiet_zone_cells, "quiet_zone_cells", 0)
    marker = cv2.aruco.generateImageMarker(
        opencv_dictionary(spec), int(tag_id), spec.border_cells * cells_px, borderBits=1
    )
    upright = np.ascontiguousarray(np.rot90(marker, opencv_quarter_turns(family)))
    margin = quiet_zone_cells * cells_px
    framed = cv2.copyMakeBorder(
        upright, margin, margin, margin, margin, cv2.BORDER_CONSTANT, value=255
    )
    return np.asarray(framed, dtype=np.uint8)


def bitmap_corners_px(family: str, cells_px: int = 10, quiet_zone_cells: int = 1) -> FloatArray:
    """Black-border corners of :func:`tag_bitmap` in its own pixel coordinates.

    Parameters
    ----------
    family, cells_px, quiet_zone_cells
        As for :func:`tag_bitmap`.

    Returns
    -------
    corners_px : (4, 2) float64
        Top-left, top-right, bottom-right, bottom-left ``(u, v)`` in OpenCV pixel coordinates
        (pixel centers at integers, so the outer edge of pixel ``i`` is at ``i - 0.5``):
        ``a = quiet_zone_cells * cells_px - 0.5`` and ``b = a + border_cells * cells_px``
        give ``[[a, a], [b, a], [b, b], [a, b]]``.

    Raises
    ------
    TagInputError, TagBackendError
        As for :func:`tag_bitmap`.
    """
    spec = family_spec(family)
    _check_count(cells_px, "cells_px", 1)
    _check_count(quiet_zone_cells, "quiet_zone_cells", 0)
    a = quiet_zone_cells * cells_px - 0.5
    b = a + spec.border_cells * cells_px
    return np.array([[a, a], [b, a], [b, b], [a, b]], dtype=np.float64)


def render_tag(
    canvas: npt.NDArray[np.uint8],
    family: str,
    tag_id: int,
    corners_px: npt.ArrayLike,
    quiet_zone_cells: int = 1,
    supersample: int = 4,
) -> npt.NDArray[np.uint8]:
    """Paint a tag (with its white quiet zone) into a gray image through a homography.

    Each output pixel gets the *area average* of the tag over its square (sampled on a
    ``supersample x supersample`` grid of bilinear samples), blended with the canvas by the
    covered fraction, so an edge lands where the geometry puts it to within about 0.01 px
    (checked against exact areas and centroids in ``tests/tags/test_tag_bitmaps.py``). The whole
    sheet, quiet zone included, must be in front of the camera: a homography cannot represent
    points behind it, so clip such tags before calling this.

    Parameters
    ----------
    canvas : (H, W) uint8
        Background; not modified.
    family, tag_id, quiet_zone_cells
        As for :func:`tag_bitmap`.
    corners_px : (4, 2) array_like
        Where the black-border corners go: top-left, top-right, bottom-right, bottom-left of the
        upright tag, OpenCV pixel coordinates (the order and convention of ``TagDetection``).
    supersample : int
        Samples per pixel side (>= 1).

    Returns
    -------
    (H, W) uint8
        A new image.

    Raises
    ------
    TagInputError
        If the canvas is not a 2-D uint8 array or the arguments are out of range.
    """
    if not isinstance(canvas, np.ndarray) or canvas.ndim != 2 or canvas.dtype != np.uint8:
        raise TagInputError("canvas: expected a 2-D uint8 array")
    _check_count(supersample, "supersample", 1)
    dst = np.asarray(corners_px, dtype=np.float64)
    if dst.shape != (4, 2) or not np.isfinite(dst).all():
        raise TagInputError(f"corners_px: expected (4, 2) finite values, got shape {dst.shape}")
    spec = family_spec(family)
    edge_px = float(np.linalg.norm(np.roll(dst, -1, axis=0) - dst, axis=1).max())
    cells_px = int(np.clip(np.ceil(edge_px * supersample / spec.border_cells), 1, 64))
    bitmap = tag_bitmap(family, tag_id, cells_px, quiet_zone_cells).astype(np.float32)
    src = bitmap_corners_px(family, cells_px, quiet_zone_cells)
    H_img_bmp = cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32))
    H_img_bmp = np.asarray(H_img_bmp, dtype=np.float64)

    # Window of the canvas the sheet covers (plus a pixel), in canvas pixels.
    n = bitmap.shape[0] - 0.5
    sheet = np.array([[[-0.5, -0.5], [n, -0.5], [n, n], [-0.5, n]]])
    sheet_px = cv2.perspectiveTransform(sheet, H_img_bmp)[0]
    lo = np.maximum(np.floor(sheet_px.min(axis=0)) - 1, 0).astype(int)
    hi = np.minimum(np.ceil(sheet_px.max(axis=0)) + 2, canvas.shape[::-1]).astype(int)
    out = canvas.copy()
    if (hi <= lo).any():
        return out
    width, height = int(hi[0] - lo[0]), int(hi[1] - lo[1])

    # Supersampled pixel (X, Y) has its center at window pixel ((X + 0.5) / k - 0.5, ...).
    k = supersample
    S = np.array([[k, 0.0, k * (0.5 - lo[0]) - 0.5], [0.0, k, k * (0.5 - lo[1]) - 0.5], [0, 0, 1]])
    H_fine_bmp = S @ H_img_bmp
    size = (width * k, height * k)
    tag = cv2.warpPerspective(
        bitmap, H_fine_bmp, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    cover = cv2.warpPerspective(
        np.ones_like(bitmap),
        H_fine_bmp,
        size,
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0.0,
    )
    window = out[lo[1] : hi[1], lo[0] : hi[0]].astype(np.float32)
    tag_mean = cv2.resize(tag * cover, (width, height), interpolation=cv2.INTER_AREA)
    cover_mean = cv2.resize(cover, (width, height), interpolation=cv2.INTER_AREA)
    blended = tag_mean + window * (1.0 - cover_mean)
    out[lo[1] : hi[1], lo[0] : hi[0]] = np.clip(np.rint(blended), 0, 255).astype(np.uint8)
    return out


def _check_count(value: int, name: str, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TagInputError(f"{name}: expected an int, got {type(value).__name__}")
    if value < minimum:
        raise TagInputError(f"{name}: must be >= {minimum}, got {value}")
