"""OpenCV ArUco detection through ``cv2.aruco.ArucoDetector`` (OpenCV 5).

Reconciliation with the tagloc convention, measured on synthetic images with exactly known
corners (opencv-python-headless 5.0.0.93; ``tests/tags/test_detection.py`` pins each property):

- **Pixel centers**: OpenCV's own, as tagloc's: no offset (subpixel corners minus the truth
  average ``(+0.001, +0.003)`` px over 80 random views of 50-200 px tags).
- **Corner order**: clockwise from the top-left of the marker as OpenCV draws it, which is
  tagloc's order for ArUco dictionaries. For ``DICT_APRILTAG_*`` OpenCV's marker is the printed
  AprilTag turned by :func:`~tagloc.tags.families.opencv_quarter_turns` (180 degrees in 5.0.0.93,
  so its corner 0 is the tag's bottom-right); the corners are rolled back accordingly.
- **Accuracy**: ``CORNER_REFINE_SUBPIX`` (``cornerSubPix`` on the convex outer corner) pulls
  every corner about 0.12 px towards the tag center; over the same 80 views its RMS error is
  0.15 px, 95th percentile 0.32 px, worst 0.44 px (AprilTag 3: 0.06 / 0.16 / 0.30 px).
  ``CORNER_REFINE_APRILTAG`` is not offered: it reports corners +0.43 px off in both axes
  (AprilTag's pixel-center convention leaking through); ``"contour"`` and ``"none"`` have RMS
  errors near 0.5 px.
- **Missed tags**: OpenCV 5 groups candidate quads whose corners are closer than
  ``minMarkerDistanceRate`` (default 0.125) times the smaller perimeter and keeps the largest of
  the group (opencv/opencv_contrib#2913). With a one-cell white quiet zone (AprilTag's printed
  margin) on a darker background, the quiet zone's outline wins and the tag is lost: in
  benchmark-style frames 15 of 120 tags were missed with 0.125 or 0.05, none with 0.02 (0.01
  starts reporting tags twice). tagloc's default is 0.02 (option ``min_marker_distance_rate``).
- **hamming**: OpenCV does not report it; tagloc re-reads the bits on a rectified patch (6 px
  per cell, Otsu threshold, the inner 4x4 px of each cell) and counts the differences from the
  code word of the reported id. ``decision_margin`` is NaN.
"""

from __future__ import annotations

import logging
import math

import cv2
import numpy as np
import numpy.typing as npt

from tagloc.tags.detection import TagDetection
from tagloc.tags.errors import TagBackendError, TagInputError
from tagloc.tags.families import family_spec, opencv_dictionary, opencv_quarter_turns
from tagloc.tags.images import MIN_IMAGE_SIDE_PX, GrayImage, as_gray_u8

logger = logging.getLogger(__name__)

_REFINEMENT = {
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
    "none": cv2.aruco.CORNER_REFINE_NONE,
}
_PX_PER_CELL = 6

#: Options :func:`tagloc.tags.backends.make_detector` passes through to this backend.
ARUCO_OPTIONS = frozenset(
    {
        "corner_refinement",
        "corner_refinement_win_size",
        "relative_corner_refinement_win_size",
        "error_correction_rate",
        "min_marker_distance_rate",
    }
)


class ArucoTagDetector:
    """Detect one family (ArUco or AprilTag dictionary) with OpenCV's ``ArucoDetector``.

    Parameters
    ----------
    family : str
        Any known family: ``"aruco_4x4_50"`` ... ``"aruco_7x7_1000"``, ``"aruco_original"``,
        ``"aruco_mip_36h12"``, or ``"tag36h11"``/``"tag25h9"``/``"tag16h5"`` (OpenCV's AprilTag
        dictionaries, for comparison with the AprilTag backend).
    corner_refinement : {"subpix", "contour", "none"}
        OpenCV corner refinement; ``"subpix"`` (default) is the accurate one (module docstring).
    corner_refinement_win_size : int
        Largest ``cornerSubPix`` half-window, pixels (>= 1; OpenCV default 5).
    relative_corner_refinement_win_size : float
        Half-window as a fraction of the marker's cell size (> 0; OpenCV default 0.3); the
        smaller of the two windows is used.
    error_correction_rate : float
        Fraction of the dictionary's correctable bits OpenCV may correct, in ``[0, 1]`` (0.6).
    min_marker_distance_rate : float
        OpenCV's ``minMarkerDistanceRate``, in ``[0, 1]``; tagloc default 0.02 instead of
        OpenCV's 0.125, which loses tags with a one-cell quiet zone (module docstring).

    Raises
    ------
    TagBackendError
        If the family is unknown or an option is out of range.

    Notes
    -----
    Not thread-safe: one instance per thread.
    """

    def __init__(
        self,
        family: str = "tag36h11",
        *,
        corner_refinement: str = "subpix",
        corner_refinement_win_size: int = 5,
        relative_corner_refinement_win_size: float = 0.3,
        error_correction_rate: float = 0.6,
        min_marker_distance_rate: float = 0.02,
    ) -> None:
        self._spec = family_spec(family)
        if corner_refinement not in _REFINEMENT:
            raise TagBackendError(
                f"option corner_refinement: {corner_refinement!r} not one of {sorted(_REFINEMENT)}"
            )
        win = corner_refinement_win_size
        if isinstance(win, bool) or not isinstance(win, int) or not 1 <= win <= 100:
            raise TagBackendError(
                f"option corner_refinement_win_size: expected an int from 1 to 100, got {win!r}"
            )
        rel = relative_corner_refinement_win_size
        if not _is_real(rel) or not (math.isfinite(rel) and 0.0 < rel <= 1.0):
            raise TagBackendError(
                f"option relative_corner_refinement_win_size: expected (0, 1], got {rel!r}"
            )
        rate = error_correction_rate
        if not _is_real(rate) or not 0.0 <= rate <= 1.0:
            raise TagBackendError(f"option error_correction_rate: expected [0, 1], got {rate!r}")
        distance = min_marker_distance_rate
        if not _is_real(distance) or not 0.0 <= distance <= 1.0:
            raise TagBackendError(
                f"option min_marker_distance_rate: expected [0, 1], got {distance!r}"
            )

        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = _REFINEMENT[corner_refinement]
        params.cornerRefinementWinSize = win
        params.relativeCornerRefinmentWinSize = float(rel)
        params.errorCorrectionRate = float(rate)
        params.minMarkerDistanceRate = float(distance)
        self._dictionary = opencv_dictionary(self._spec)
        self._detector = cv2.aruco.ArucoDetector(self._dictionary, params)
        self._quarter_turns = opencv_quarter_turns(family)

    @property
    def backend(self) -> str:
        """``"aruco"``."""
        return "aruco"

    @property
    def families(self) -> tuple[str, ...]:
        """The one family this detector reports."""
        return (self._spec.name,)

    def detect(self, image_gray: npt.NDArray[np.generic]) -> list[TagDetection]:
        """Detect tags; see :meth:`tagloc.tags.detection.TagDetector.detect`.

        Raises
        ------
        TagInputError
            If the image is not usable (the message says why).
        """
        gray = as_gray_u8(image_gray, "image_gray")
        if min(gray.shape) < MIN_IMAGE_SIDE_PX:
            logger.debug("image %s below %d px a side: no detection", gray.shape, MIN_IMAGE_SIDE_PX)
            return []
        try:
            corners_list, ids, _rejected = self._detector.detectMarkers(gray)
        except cv2.error as exc:
            raise TagInputError(f"image_gray: OpenCV ArUco detection failed ({exc})") from None
        if ids is None:
            return []
        detections = []
        for corners_cv, tag_id in zip(corners_list, ids.ravel(), strict=True):
            corners_opencv = np.asarray(corners_cv, dtype=np.float64).reshape(4, 2)
            hamming = _sampled_hamming(
                gray, corners_opencv, self._dictionary, int(tag_id), self._spec.border_cells
            )
            upright = np.roll(corners_opencv, -self._quarter_turns, axis=0)
            try:
                detections.append(TagDetection(int(tag_id), self._spec.name, upright, hamming))
            except TagInputError as exc:
                logger.warning("dropping a malformed ArUco detection: %s", exc)
        detections.sort(key=lambda d: (d.tag_id, d.center_px[1], d.center_px[0]))
        return detections


def _sampled_hamming(
    gray: GrayImage,
    corners_opencv: npt.NDArray[np.float64],
    dictionary: cv2.aruco.Dictionary,
    tag_id: int,
    border_cells: int,
) -> int:
    """Bits of the marker under ``corners_opencv`` that differ from the code word of ``tag_id``.

    The quad (OpenCV's order, OpenCV pixel centers) is rectified to ``_PX_PER_CELL`` px per cell,
    thresholded with Otsu, and each cell decided by the mean of its inner pixels.
    """
    side = border_cells * _PX_PER_CELL
    edge = side - 0.5
    target = np.array([[-0.5, -0.5], [edge, -0.5], [edge, edge], [-0.5, edge]], np.float32)
    H_patch_img = cv2.getPerspectiveTransform(corners_opencv.astype(np.float32), target)
    patch = cv2.warpPerspective(gray, H_patch_img, (side, side), flags=cv2.INTER_LINEAR)
    _, binary = cv2.threshold(patch, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    cells = binary.reshape(border_cells, _PX_PER_CELL, border_cells, _PX_PER_CELL)
    inner = cells[:, 1:-1, :, 1:-1].mean(axis=(1, 3))
    bits = (inner[1:-1, 1:-1] > 127.5).astype(np.uint8)
    return int(dictionary.getDistanceToId(bits, tag_id, False))


def _is_real(value: object) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
