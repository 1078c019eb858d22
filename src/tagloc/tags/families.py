"""The tag families tagloc knows, and which printed layout counts as *upright* for each.

A family name is the string stored in ``TagDetection.family`` and in the tag map: the AprilTag 3
names (``"tag36h11"``, ``"tag25h9"``, ``"tag16h5"``) and ``"aruco_<n>x<n>_<count>"``,
``"aruco_original"``, ``"aruco_mip_36h12"`` for the OpenCV ArUco dictionaries.

Upright
-------
A tag is *upright* when it looks like its reference image: for AprilTag families the images of
AprilRobotics/apriltag-imgs, which the AprilTag generator renders with data bit ``i`` at column
``bit_x[i]``, row ``bit_y[i]`` of the family table (the same table the AprilTag 3 detector decodes
with); for ArUco families the output of ``cv2.aruco.generateImageMarker``. The tag frame, the corner
order and :func:`tagloc.tags.bitmaps.tag_bitmap` all refer to this upright image.

OpenCV's own AprilTag dictionaries do not follow it in every version: with
opencv-python-headless 5.0.0.93 ``generateImageMarker(DICT_APRILTAG_*)`` returns the reference image
rotated by 180 degrees (all ids of 16h5, 25h9 and 36h11 checked against the AprilTag 3 family
tables), and the ArUco detector numbers the corners of that rotated image (OpenCV fixed this in
opencv/opencv#28823, "[OpenCV 5] Fix apriltag corners order"). :func:`opencv_quarter_turns` measures
the rotation of the installed OpenCV once, against the reference image of id 0 embedded below, so
both the bitmaps and the ArUco backend stay right on either side of that fix.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from tagloc.tags.errors import TagBackendError

FamilyKind = Literal["apriltag", "aruco"]


@dataclass(frozen=True, slots=True)
class TagFamily:
    """One tag family: its grid and the libraries that can detect it.

    Attributes
    ----------
    name : str
        The tagloc name (``"tag36h11"``, ``"aruco_4x4_50"``).
    kind : {"apriltag", "aruco"}
        Which reference defines the upright image (see the module docstring).
    data_cells : int
        Data bits along one side (6 for tag36h11, 4 for aruco_4x4_50).
    opencv_dictionary : int
        The ``cv2.aruco.DICT_*`` constant of this family.
    apriltag_name : str or None
        The family name of the AprilTag 3 library (pupil-apriltags), or None when it cannot
        detect this family.
    """

    name: str
    kind: FamilyKind
    data_cells: int
    opencv_dictionary: int
    apriltag_name: str | None

    @property
    def border_cells(self) -> int:
        """Cells along the black-border edge: the data grid plus a one-cell black border."""
        return self.data_cells + 2

    @property
    def num_ids(self) -> int:
        """Number of valid tag ids (``0 .. num_ids - 1``)."""
        return _dictionary_size(self.opencv_dictionary)


@functools.cache
def _dictionary_size(opencv_dictionary: int) -> int:
    return int(cv2.aruco.getPredefinedDictionary(opencv_dictionary).bytesList.shape[0])


def _aruco(n: int, count: int) -> TagFamily:
    constant = getattr(cv2.aruco, f"DICT_{n}X{n}_{count}")
    return TagFamily(f"aruco_{n}x{n}_{count}", "aruco", n, constant, None)


_FAMILY_LIST: tuple[TagFamily, ...] = (
    TagFamily("tag16h5", "apriltag", 4, cv2.aruco.DICT_APRILTAG_16h5, "tag16h5"),
    TagFamily("tag25h9", "apriltag", 5, cv2.aruco.DICT_APRILTAG_25h9, "tag25h9"),
    TagFamily("tag36h11", "apriltag", 6, cv2.aruco.DICT_APRILTAG_36h11, "tag36h11"),
    *(_aruco(n, count) for n in (4, 5, 6, 7) for count in (50, 100, 250, 1000)),
    TagFamily("aruco_original", "aruco", 5, cv2.aruco.DICT_ARUCO_ORIGINAL, None),
    TagFamily("aruco_mip_36h12", "aruco", 6, cv2.aruco.DICT_ARUCO_MIP_36h12, None),
)
FAMILIES: dict[str, TagFamily] = {family.name: family for family in _FAMILY_LIST}

#: Data bits of id 0 of each AprilTag family as printed (apriltag-imgs), rows top to bottom,
#: ``1`` = white. Read from the AprilTag 3 family tables (``codes[0]``, ``bit_x``, ``bit_y``).
_APRILTAG_ID0_UPRIGHT: dict[str, tuple[str, ...]] = {
    "tag16h5": ("0010", "0011", "0001", "1011"),
    "tag25h9": ("10101", "01011", "10010", "11111", "10001"),
    "tag36h11": ("110101", "011101", "011000", "101000", "010110", "000100"),
}


def known_families() -> tuple[str, ...]:
    """Names of every family tagloc knows, in a stable order."""
    return tuple(FAMILIES)


def family_spec(name: str) -> TagFamily:
    """The :class:`TagFamily` called ``name``.

    Raises
    ------
    TagBackendError
        If ``name`` is not a known family (the message lists the known ones).
    """
    try:
        return FAMILIES[name]
    except (KeyError, TypeError):
        raise TagBackendError(
            f"unknown tag family {name!r}; known families: {', '.join(FAMILIES)}"
        ) from None


def opencv_dictionary(family: TagFamily) -> cv2.aruco.Dictionary:
    """The OpenCV ``cv2.aruco.Dictionary`` of ``family``."""
    return cv2.aruco.getPredefinedDictionary(family.opencv_dictionary)


@functools.cache
def opencv_quarter_turns(name: str) -> int:
    """How OpenCV's marker image of family ``name`` must be turned to be upright.

    Returns
    -------
    int
        ``k`` in ``0..3`` with ``upright = np.rot90(opencv_image, k)`` (counter-clockwise quarter
        turns, numpy's convention). OpenCV's corner ``j`` (clockwise from the top-left of *its*
        image) is then upright corner ``(j - k) % 4``, i.e. ``corners_upright =
        np.roll(corners_opencv, -k, axis=0)``. Always 0 for ArUco families; 2 for AprilTag
        families with opencv-python-headless 5.0.0.93.

    Raises
    ------
    TagBackendError
        If OpenCV's id-0 image matches the reference in no rotation (a changed dictionary).
    """
    family = family_spec(name)
    if family.kind == "aruco":
        return 0
    reference = np.array([[c == "1" for c in row] for row in _APRILTAG_ID0_UPRIGHT[name]])
    image = cv2.aruco.generateImageMarker(
        opencv_dictionary(family), 0, family.border_cells, borderBits=1
    )
    data = image[1:-1, 1:-1] > 127
    for k in range(4):
        if np.array_equal(np.rot90(data, k), reference):
            return k
    raise TagBackendError(
        f"OpenCV {cv2.__version__}: the image of {name} id 0 matches the AprilTag reference in "
        "no rotation; the dictionary changed and tagloc.tags.families needs updating"
    )
