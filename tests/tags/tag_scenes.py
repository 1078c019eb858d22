"""Synthetic tag scenes with exactly known corners, and the AprilTag family tables as an oracle."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tagloc.tags.bitmaps import render_tag

FloatArray = npt.NDArray[np.float64]

SHAPE_VGA = (480, 640)
BACKGROUND = 128


def square_quad(center: tuple[float, float], side: float, angle_deg: float) -> FloatArray:
    """Corners (tl, tr, br, bl) of an upright square tag, turned ``angle_deg`` clockwise."""
    base = 0.5 * side * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    a = np.deg2rad(angle_deg)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])  # clockwise with v down
    return base @ R.T + np.asarray(center)


def perspective_quad(
    rng: np.random.Generator, center: tuple[float, float], side: float, jitter: float
) -> FloatArray:
    """A square turned by a random angle with each corner moved by ``N(0, jitter * side)``."""
    quad = square_quad(center, side, float(rng.uniform(0.0, 360.0)))
    return quad + rng.normal(0.0, jitter * side, size=(4, 2))


def scene(
    placements: list[tuple[str, int, FloatArray]],
    shape: tuple[int, int] = SHAPE_VGA,
    background: int = BACKGROUND,
) -> npt.NDArray[np.uint8]:
    """A gray image with each ``(family, tag_id, corners_px)`` rendered (area-sampled)."""
    image = np.full(shape, background, dtype=np.uint8)
    for family, tag_id, corners_px in placements:
        image = render_tag(image, family, tag_id, corners_px)
    return image


def max_corner_error(corners_a: FloatArray, corners_b: FloatArray) -> float:
    """Largest Euclidean distance between corresponding corners, pixels."""
    return float(np.linalg.norm(np.asarray(corners_a) - np.asarray(corners_b), axis=1).max())


class _ApriltagFamily(ctypes.Structure):
    """``apriltag_family_t`` of AprilTag 3 (apriltag.h), the fields we read."""

    _fields_ = [
        ("ncodes", ctypes.c_uint32),
        ("codes", ctypes.POINTER(ctypes.c_uint64)),
        ("width_at_border", ctypes.c_int),
        ("total_width", ctypes.c_int),
        ("reversed_border", ctypes.c_bool),
        ("nbits", ctypes.c_uint32),
        ("bit_x", ctypes.POINTER(ctypes.c_uint32)),
        ("bit_y", ctypes.POINTER(ctypes.c_uint32)),
    ]


def apriltag_layouts(family: str) -> npt.NDArray[np.bool_]:
    """Every id's black-border grid, white = True, from the AprilTag 3 library's family table.

    Bit ``i`` of code ``c`` (most significant first) sits at column ``bit_x[i]``, row
    ``bit_y[i]`` of the grid whose corner cell is the black border: the layout the AprilTag
    generator prints (apriltag-generation ``ImageLayout``) and the detector decodes.

    Returns
    -------
    (ncodes, W, W) bool
    """
    import pupil_apriltags

    package = Path(pupil_apriltags.__file__).parent
    library_path = next(
        p for d in ("lib64", "lib") for p in sorted((package / d).glob("libapriltag.so*"))
    )
    library = ctypes.CDLL(str(library_path))
    create = getattr(library, f"{family}_create")
    create.restype = ctypes.POINTER(_ApriltagFamily)
    table = create().contents
    width = table.width_at_border
    grids = np.zeros((table.ncodes, width, width), dtype=bool)
    for tag_id in range(table.ncodes):
        code = table.codes[tag_id]
        for i in range(table.nbits):
            if (code >> (table.nbits - 1 - i)) & 1:
                grids[tag_id, table.bit_y[i], table.bit_x[i]] = True
    return grids
