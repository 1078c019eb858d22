"""One detection type with one corner convention, and the detector protocol.

The corner convention
---------------------
``TagDetection.corners_px`` is a ``(4, 2) float64`` array of ``(u, v)`` pixel coordinates:

- **Pixels**: OpenCV's convention (``docs/CONVENTIONS.md``): the *center* of the top-left pixel is
  ``(0, 0)``, so that pixel covers ``[-0.5, 0.5] x [-0.5, 0.5]``; ``u`` right, ``v`` down.
- **Corners**: the four outer corners of the black border (the square whose edge is ``size``), in
  the order of the tag's object points in the tag frame (origin at the tag center, z out of the
  printed face towards the viewer, x to the tag's right, y up), as seen by a viewer facing the
  printed face with the tag upright (see :mod:`tagloc.tags.families` for what *upright* means)::

      0 = top-left     (-s/2, +s/2, 0)        0 ---- 1
      1 = top-right    (+s/2, +s/2, 0)        |  up  |
      2 = bottom-right (+s/2, -s/2, 0)        |      |
      3 = bottom-left  (-s/2, -s/2, 0)        3 ---- 2

  In the image the corners therefore run clockwise on screen (``u`` right, ``v`` down) whatever
  the tag's in-plane rotation; :class:`TagDetection` refuses any other winding.

Relation to OpenCV PnP: :func:`tag_object_points` is *exactly* the object-point order that
``cv2.solvePnP(..., flags=cv2.SOLVEPNP_IPPE_SQUARE)`` requires (point 0 ``[-s/2, s/2, 0]``, 1
``[s/2, s/2, 0]``, 2 ``[s/2, -s/2, 0]``, 3 ``[-s/2, -s/2, 0]``), with no sign change: pass
``tag_object_points(size)`` and ``corners_px`` as they are, and ``rvec, tvec`` is ``T_cam_tag``
in this tag frame (checked in ``tests/tags/test_detection.py``). It is also the object-point order
of OpenCV's ArUco ``estimatePoseSingleMarkers``. The AprilTag 3 library's own pose frame differs:
x right, y *down*, z *into* the tag; its points are ours rotated 180 degrees about x,
``(x, y, z)_apriltag = (x, -y, -z)_tagloc``.

Recorded corners from other sources enter through :meth:`TagDetection.from_corners`, which takes
their order and pixel-center offset (table in its docstring).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.tags.errors import TagInputError
from tagloc.tags.families import family_spec

#: Corner labels in tagloc order; ``"_".join(CORNER_LABELS)`` is the native ``order``.
CORNER_LABELS: tuple[str, str, str, str] = ("tl", "tr", "br", "bl")
TAGLOC_ORDER = "tl_tr_br_bl"
#: ``apriltag_detection_t.p`` of the AprilTag 3 C library (pupil-apriltags, dt-apriltags).
APRILTAG3_ORDER = "bl_br_tr_tl"


def tag_object_points(size: float) -> FloatArray:
    """Corners of a tag in its own frame, in the corner order of :class:`TagDetection`.

    Parameters
    ----------
    size : float
        Black-border edge length, metres (> 0).

    Returns
    -------
    points_tag : (4, 3) float64
        ``[[-s/2, s/2, 0], [s/2, s/2, 0], [s/2, -s/2, 0], [-s/2, -s/2, 0]]`` (top-left,
        top-right, bottom-right, bottom-left); the ``SOLVEPNP_IPPE_SQUARE`` order.

    Raises
    ------
    TagInputError
        If ``size`` is not a finite positive number.
    """
    if isinstance(size, bool) or not isinstance(size, (int, float, np.floating, np.integer)):
        raise TagInputError(f"size: expected a number of metres, got {type(size).__name__}")
    if not (math.isfinite(size) and size > 0.0):
        raise TagInputError(f"size: expected a finite positive edge length, got {size!r}")
    half = 0.5 * float(size)
    return np.array(
        [[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0], [-half, -half, 0.0]]
    )


def corner_permutation(order: str) -> tuple[int, int, int, int]:
    """Indices that take corners given in ``order`` to the tagloc order.

    Parameters
    ----------
    order : str
        The four labels ``tl``, ``tr``, ``br``, ``bl`` joined by ``_``, in the order the source
        lists its corners (``"bl_br_tr_tl"`` for AprilTag 3).

    Returns
    -------
    tuple of 4 int
        ``perm`` with ``corners_tagloc = corners_given[list(perm)]``.

    Raises
    ------
    TagInputError
        If ``order`` is not a permutation of the four labels.
    """
    labels = order.split("_") if isinstance(order, str) else []
    if sorted(labels) != sorted(CORNER_LABELS):
        raise TagInputError(
            f"order: {order!r} is not a permutation of 'tl', 'tr', 'br', 'bl' joined by '_' "
            f"(e.g. {TAGLOC_ORDER!r} or {APRILTAG3_ORDER!r})"
        )
    perm = tuple(labels.index(label) for label in CORNER_LABELS)
    return perm[0], perm[1], perm[2], perm[3]


@dataclass(frozen=True, slots=True, eq=False)
class TagDetection:
    """One tag seen in one image, in tagloc's corner convention (module docstring).

    Attributes
    ----------
    tag_id : int
        Id within the family (``0 .. num_ids - 1``).
    family : str
        A known family name (``"tag36h11"``, ``"aruco_4x4_50"``; see
        :func:`tagloc.tags.families.known_families`).
    corners_px : (4, 2) float64, read-only
        Black-border corners ``(u, v)``: top-left, top-right, bottom-right, bottom-left of the
        upright tag, OpenCV pixel centers (top-left pixel center at ``(0, 0)``).
    hamming : int
        Bits the decoder corrected (0 = exact code word).
    decision_margin : float
        AprilTag 3's mean distance of the data bits from the decision threshold (intensity
        units, higher is surer). NaN where the source has no such number: the ArUco backend
        (OpenCV reports none) and :meth:`from_corners` by default.
    center_px : (2,) float64, read-only
        Projective center: the intersection of the diagonals, where the tag frame's origin
        projects (not the mean of the corners under perspective). Derived from ``corners_px``.

    Raises
    ------
    TagInputError
        From the constructor, if a field is malformed or the corners are not a convex quad wound
        clockwise on screen (the signature of a wrong corner order).
    TagBackendError
        If ``family`` is not a known family.

    Notes
    -----
    Equality is identity (arrays inside); compare detections field by field with ``allclose``.
    """

    tag_id: int
    family: str
    corners_px: FloatArray
    hamming: int = 0
    decision_margin: float = math.nan
    center_px: FloatArray = field(init=False)

    def __post_init__(self) -> None:
        if isinstance(self.tag_id, bool) or not isinstance(self.tag_id, (int, np.integer)):
            raise TagInputError(f"tag_id: expected an int, got {type(self.tag_id).__name__}")
        num_ids = family_spec(self.family).num_ids
        if not 0 <= self.tag_id < num_ids:
            raise TagInputError(
                f"tag_id: {self.family} has ids 0..{num_ids - 1}, got {self.tag_id}"
            )
        if isinstance(self.hamming, bool) or not isinstance(self.hamming, (int, np.integer)):
            raise TagInputError(f"hamming: expected an int, got {type(self.hamming).__name__}")
        if self.hamming < 0:
            raise TagInputError(f"hamming: must be >= 0, got {self.hamming}")
        corners = _checked_corners(self.corners_px, "corners_px")
        _check_winding(corners, f"tag {self.family}:{self.tag_id} corners_px")
        center = _diagonal_intersection(corners)
        corners.flags.writeable = False
        center.flags.writeable = False
        object.__setattr__(self, "tag_id", int(self.tag_id))
        object.__setattr__(self, "hamming", int(self.hamming))
        try:
            decision_margin = float(self.decision_margin)
        except (TypeError, ValueError):
            raise TagInputError(
                f"decision_margin: expected a number, got {self.decision_margin!r}"
            ) from None
        object.__setattr__(self, "decision_margin", decision_margin)
        object.__setattr__(self, "corners_px", corners)
        object.__setattr__(self, "center_px", center)

    @classmethod
    def from_corners(
        cls,
        tag_id: int,
        family: str,
        corners_px: npt.ArrayLike,
        order: str = TAGLOC_ORDER,
        pixel_offset: float = 0.0,
        hamming: int = 0,
        decision_margin: float = math.nan,
    ) -> TagDetection:
        """Build a detection from corners recorded in another order or pixel convention.

        Parameters
        ----------
        tag_id, family, hamming, decision_margin
            As the attributes.
        corners_px : (4, 2) array_like
            The four black-border corners as the source lists them.
        order : str
            Which corner of the upright tag each row is: the labels ``tl``, ``tr``, ``br``, ``bl``
            joined by ``_``. Known sources:

            ========================================  =================  ============
            source                                    order              pixel_offset
            ========================================  =================  ============
            tagloc, OpenCV ArUco (ArUco dicts)        ``tl_tr_br_bl``    0.0
            AprilTag 3 C / pupil-apriltags corners    ``bl_br_tr_tl``    0.5
            OpenCV 5.0.0 ArUco with DICT_APRILTAG_*   ``br_bl_tl_tr``    0.0
            ========================================  =================  ============

            (The last row: OpenCV builds without opencv/opencv#28823 number the corners of a
            180-degree-rotated AprilTag; measured on opencv-python-headless 5.0.0.93.)
        pixel_offset : float
            The coordinate the source gives to the *center* of the top-left pixel: 0.0 for
            OpenCV, 0.5 for AprilTag 3 (pixel ``i`` spans ``[i, i + 1]``), 1.0 for MATLAB.
            Subtracted from both coordinates.

        Returns
        -------
        TagDetection

        Raises
        ------
        TagInputError
            If ``order`` is not a permutation of the labels, the corners are not ``(4, 2)``
            finite numbers, or after reordering they are not clockwise on screen (the order
            given is wrong).
        TagBackendError
            If ``family`` is not a known family.
        """
        perm = corner_permutation(order)
        corners = _checked_corners(corners_px, "corners_px")
        try:
            offset = float(pixel_offset)
        except (TypeError, ValueError):
            offset = math.nan
        if not math.isfinite(offset):
            raise TagInputError(f"pixel_offset: must be a finite number, got {pixel_offset!r}")
        reordered = corners[list(perm)] - offset
        try:
            return cls(tag_id, family, reordered, hamming, decision_margin)
        except TagInputError as exc:
            raise TagInputError(f"{exc} (corners given in order {order!r})") from None


class TagDetector(Protocol):
    """What every detection backend provides (see :func:`tagloc.tags.backends.make_detector`).

    Implementations are not required to be thread-safe: use one detector per thread.
    """

    @property
    def backend(self) -> str:
        """Registry name of the backend (``"apriltag"``, ``"aruco"``)."""
        ...

    @property
    def families(self) -> tuple[str, ...]:
        """Families this detector reports."""
        ...

    def detect(self, image_gray: npt.NDArray[np.generic]) -> list[TagDetection]:
        """Detect tags in one image.

        Parameters
        ----------
        image_gray : (H, W) uint8 (or BGR, BGRA, float in [0, 1]; see :mod:`tagloc.tags.images`)
            The image, undistorted or not (corners are where the tag appears in *this* image).

        Returns
        -------
        list of TagDetection
            Sorted by ``(tag_id, v, u)`` of the center; empty when nothing is found.

        Raises
        ------
        TagInputError
            If the image is not usable (the message says why).
        """
        ...


def _checked_corners(corners_px: npt.ArrayLike, name: str) -> FloatArray:
    """``corners_px`` as a new ``(4, 2) float64`` array of finite numbers."""
    try:
        corners = np.array(corners_px, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TagInputError(f"{name}: cannot be read as a float array ({exc})") from None
    if corners.shape != (4, 2):
        raise TagInputError(f"{name}: expected shape (4, 2), got {corners.shape}")
    if not np.isfinite(corners).all():
        raise TagInputError(f"{name}: holds NaN or infinite values")
    return corners


def is_convex_clockwise(corners: FloatArray) -> bool:
    """Whether a quad (4, 2) is strictly convex and wound clockwise on screen (u right, v down),
    as :class:`TagDetection` requires (and a detector reports)."""
    edges = np.roll(corners, -1, axis=0) - corners
    following = np.roll(edges, -1, axis=0)
    turns = edges[:, 0] * following[:, 1] - edges[:, 1] * following[:, 0]
    return bool((turns > 0.0).all())


def _check_winding(corners: FloatArray, name: str) -> None:
    """Require a strictly convex quad wound clockwise on screen (:func:`is_convex_clockwise`)."""
    if not is_convex_clockwise(corners):
        raise TagInputError(
            f"{name}: not a convex quadrilateral running top-left, top-right, bottom-right, "
            f"bottom-left clockwise on screen: {corners.round(2).tolist()}"
        )


def _diagonal_intersection(corners: FloatArray) -> FloatArray:
    """Intersection of the diagonals 0-2 and 1-3 (homogeneous line intersection)."""
    h = np.hstack([corners, np.ones((4, 1))])
    point = np.cross(np.cross(h[0], h[2]), np.cross(h[1], h[3]))
    return np.asarray(point[:2] / point[2], dtype=np.float64)
