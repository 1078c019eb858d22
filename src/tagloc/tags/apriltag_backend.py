"""AprilTag 3 detection through ``pupil_apriltags.Detector`` (the default backend).

Reconciliation with the tagloc convention, measured on synthetic images with exactly known
corners (pupil-apriltags 1.0.4.post11, AprilTag 3.1; ``tests/tags/test_detection.py`` pins each
property):

- **Pixel centers**: AprilTag 3 puts the center of pixel ``(i, j)`` at ``(i + 0.5, j + 0.5)``.
  Over 80 random views (tags 50-200 px, perspective) its raw corners minus the truth average
  ``(+0.499, +0.498)`` px with ``quad_decimate=1`` and ``(+0.500, +0.500)`` with 2. We subtract
  0.5; the corrected corners then have RMS error 0.06 px, worst 0.30 px.
- **Corner order**: ``Detection.corners`` runs bottom-left, bottom-right, top-right, top-left of
  the upright tag (counter-clockwise on screen, starting at tag coordinates ``(-1, +1)`` of its
  y-down tag frame); we reorder to top-left, top-right, bottom-right, bottom-left.
- **Tag frame**: AprilTag's pose frame is x right, y down, z into the tag; tagloc's is x right,
  y up, z out of the face (180 degrees about x). Only corners cross this module, never poses.

Three defects of pupil-apriltags 1.0.4 are worked around:

- it stores ``int(decode_sharpening)`` (0.25 becomes 0): the value is written again into the C
  detector struct after construction;
- its ``Detector.__del__`` frees the tag family before the C detector, whose destructor then
  reads and clears the freed family's ``impl`` field (``quick_decode_uninit``, offset 0x40 in
  the shipped ``libapriltag.so.3.1.0``): a use after free that can corrupt the heap at random
  (pupil-labs/apriltags#65). :func:`release_pupil_detector` frees them in the right order and
  runs when an :class:`AprilTagDetector` is collected;
- the C library crashes (SIGSEGV) on images fewer than 3 decimated rows high: images with a side
  shorter than ``max(MIN_IMAGE_SIDE_PX, ceil(4 * quad_decimate))`` pixels return no detections
  without reaching it.
"""

from __future__ import annotations

import logging
import math
import weakref
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc.config import MAX_THREADS, short_repr
from tagloc.tags.detection import APRILTAG3_ORDER, TagDetection
from tagloc.tags.errors import TagBackendError, TagInputError
from tagloc.tags.families import family_spec
from tagloc.tags.images import MIN_IMAGE_SIDE_PX, as_gray_u8

logger = logging.getLogger(__name__)

#: Coordinate AprilTag 3 gives to the center of the top-left pixel (OpenCV: 0.0).
APRILTAG3_PIXEL_OFFSET = 0.5

#: Options :func:`tagloc.tags.backends.make_detector` passes through to this backend.
APRILTAG_OPTIONS = frozenset(
    {"quad_decimate", "quad_sigma", "refine_edges", "decode_sharpening", "nthreads"}
)


class AprilTagDetector:
    """Detect one AprilTag family with the AprilTag 3 C library (pupil-apriltags).

    Parameters
    ----------
    family : str
        ``"tag36h11"`` (default), ``"tag25h9"`` or ``"tag16h5"``.
    quad_decimate : float
        Quad detection runs on the image decimated by this factor (>= 1); decoding and edge
        refinement use the full image. AprilTag's default 2.0: measured corner accuracy equals
        1.0's on tags >= 40 px (RMS 0.05 px) at about half the time; use 1.0 for tiny tags.
    quad_sigma : float
        Gaussian blur (pixels, >= 0) before segmentation; 0.8 helps noisy images.
    refine_edges : bool
        Snap quad edges to strong gradients (recommended with decimation).
    decode_sharpening : float
        Sharpening of the decoded bit samples (>= 0; AprilTag default 0.25).
    nthreads : int
        Worker threads of the C library (>= 1).

    Raises
    ------
    TagBackendError
        If the family is unknown or not an AprilTag 3 family, or an option is out of range.

    Notes
    -----
    Not thread-safe: one instance per thread. ``hamming`` is AprilTag's corrected-bit count (at
    most 2 with pupil-apriltags) and ``decision_margin`` its decision margin.
    """

    def __init__(
        self,
        family: str = "tag36h11",
        *,
        quad_decimate: float = 2.0,
        quad_sigma: float = 0.0,
        refine_edges: bool = True,
        decode_sharpening: float = 0.25,
        nthreads: int = 1,
    ) -> None:
        spec = family_spec(family)
        if spec.apriltag_name is None:
            raise TagBackendError(
                f"backend 'apriltag' cannot detect family {family!r}; it detects tag16h5, "
                "tag25h9 and tag36h11 (use backend 'aruco' for ArUco dictionaries)"
            )
        _check_real(quad_decimate, "quad_decimate", 1.0, 64.0)
        _check_real(quad_sigma, "quad_sigma", 0.0, 100.0)
        _check_real(decode_sharpening, "decode_sharpening", 0.0, 100.0)
        if not isinstance(refine_edges, (bool, np.bool_)):
            raise TagBackendError(f"option refine_edges: expected a bool, got {refine_edges!r}")
        if (
            isinstance(nthreads, bool)
            or not isinstance(nthreads, int)
            or not 1 <= nthreads <= MAX_THREADS
        ):
            wanted = f"an int from 1 to {MAX_THREADS}"
            raise TagBackendError(f"option nthreads: expected {wanted}, got {short_repr(nthreads)}")

        import pupil_apriltags

        self._family = family
        self._quad_decimate = float(quad_decimate)
        self._detector: Any = pupil_apriltags.Detector(
            families=spec.apriltag_name,
            nthreads=nthreads,
            quad_decimate=float(quad_decimate),
            quad_sigma=float(quad_sigma),
            refine_edges=int(bool(refine_edges)),
            decode_sharpening=float(decode_sharpening),
        )
        weakref.finalize(self, release_pupil_detector, self._detector)
        # pupil-apriltags 1.0.4 stores int(decode_sharpening); write the real value.
        self._detector.tag_detector_ptr.contents.decode_sharpening = float(decode_sharpening)

    @property
    def backend(self) -> str:
        """``"apriltag"``."""
        return "apriltag"

    @property
    def families(self) -> tuple[str, ...]:
        """The one family this detector reports."""
        return (self._family,)

    @property
    def decode_sharpening(self) -> float:
        """The sharpening the C detector really uses (read back from its struct)."""
        return float(self._detector.tag_detector_ptr.contents.decode_sharpening)

    @property
    def quad_decimate(self) -> float:
        """The decimation :meth:`detect` uses unless told otherwise."""
        return self._quad_decimate

    def detect(
        self, image_gray: npt.NDArray[np.generic], quad_decimate: float | None = None
    ) -> list[TagDetection]:
        """Detect tags; see :meth:`tagloc.tags.detection.TagDetector.detect`.

        ``quad_decimate`` overrides the detector's decimation for this call (a region of an
        image whose tags are known to be large or small, :mod:`tagloc.tags.regions`).

        Raises
        ------
        TagInputError
            If the image is not usable (the message says why).
        TagBackendError
            If ``quad_decimate`` is out of range.
        """
        gray = as_gray_u8(image_gray, "image_gray")
        decimate = self._quad_decimate
        if quad_decimate is not None:
            _check_real(quad_decimate, "quad_decimate", 1.0, 64.0)
            decimate = float(quad_decimate)
        min_side = max(MIN_IMAGE_SIDE_PX, math.ceil(4.0 * decimate))
        if min(gray.shape) < min_side:
            logger.debug("image %s below %d px a side: no detection", gray.shape, min_side)
            return []
        struct = self._detector.tag_detector_ptr.contents
        struct.quad_decimate = decimate
        try:
            raws = self._detector.detect(gray)
        finally:
            struct.quad_decimate = self._quad_decimate
        detections = []
        for raw in raws:
            try:
                detections.append(
                    TagDetection.from_corners(
                        int(raw.tag_id),
                        self._family,
                        raw.corners,
                        order=APRILTAG3_ORDER,
                        pixel_offset=APRILTAG3_PIXEL_OFFSET,
                        hamming=int(raw.hamming),
                        decision_margin=float(raw.decision_margin),
                    )
                )
            except TagInputError as exc:
                logger.warning("dropping a malformed AprilTag detection: %s", exc)
        detections.sort(key=lambda d: (d.tag_id, d.center_px[1], d.center_px[0]))
        return detections


def release_pupil_detector(detector: Any) -> None:
    """Free a ``pupil_apriltags.Detector``'s C objects in a safe order, once.

    The C detector first (its destructor still reads its families), then the families; then
    ``tag_detector_ptr`` is cleared so pupil's own ``__del__`` (which frees them in the opposite,
    unsafe order) does nothing. Safe to call twice.

    Parameters
    ----------
    detector : pupil_apriltags.Detector
    """
    detector_ptr = detector.tag_detector_ptr
    if detector_ptr is None:
        return
    detector.tag_detector_ptr = None
    libc = detector.libc
    libc.apriltag_detector_destroy.restype = None
    libc.apriltag_detector_destroy(detector_ptr)
    for name, family_ptr in detector.tag_families.items():
        destroy = getattr(libc, f"{name}_destroy")
        destroy.restype = None
        destroy(family_ptr)
    detector.tag_families = {}


def _check_real(value: float, name: str, minimum: float, maximum: float) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TagBackendError(f"option {name}: expected a number, got {short_repr(value)}")
    if not minimum <= value <= maximum:  # NaN fails too
        wanted = f"a number from {minimum:g} to {maximum:g}"
        raise TagBackendError(f"option {name}: expected {wanted}, got {short_repr(value)}")
