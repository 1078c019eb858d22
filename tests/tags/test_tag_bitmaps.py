"""Tag bitmaps against the AprilTag 3 family tables; the area-sampled renderer against geometry."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from tag_scenes import apriltag_layouts

from tagloc.tags import TagBackendError, TagInputError, bitmap_corners_px, tag_bitmap
from tagloc.tags.bitmaps import render_tag
from tagloc.tags.families import family_spec, opencv_quarter_turns


@pytest.mark.parametrize("family", ["tag16h5", "tag25h9", "tag36h11"])
def test_apriltag_bitmaps_match_the_family_tables_for_every_id(family: str) -> None:
    grids = apriltag_layouts(family)  # oracle: the detector's own table, printed layout
    for tag_id, grid in enumerate(grids):
        bitmap = tag_bitmap(family, tag_id, cells_px=1, quiet_zone_cells=0)
        assert np.array_equal(bitmap == 255, grid), f"{family} id {tag_id}"


def test_opencv_apriltag_dictionary_is_turned_180_degrees_in_this_opencv() -> None:
    # The finding the ArUco backend and the bitmaps correct for (opencv-python-headless 5.0.0.93).
    grids = apriltag_layouts("tag36h11")
    marker = cv2.aruco.generateImageMarker(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), 7, 8, borderBits=1
    )
    turns = opencv_quarter_turns("tag36h11")
    assert np.array_equal(np.rot90(marker, turns) == 255, grids[7])
    if cv2.__version__ == "5.0.0":
        assert turns == 2


@pytest.mark.parametrize("family", ["aruco_4x4_50", "aruco_6x6_250", "aruco_original"])
def test_aruco_bitmaps_are_opencvs_markers(family: str) -> None:
    spec = family_spec(family)
    marker = cv2.aruco.generateImageMarker(
        cv2.aruco.getPredefinedDictionary(spec.opencv_dictionary), 3, spec.border_cells * 5
    )
    assert opencv_quarter_turns(family) == 0
    assert np.array_equal(tag_bitmap(family, 3, cells_px=5, quiet_zone_cells=0), marker)


def test_bitmap_layout_quiet_zone_and_corner_coordinates() -> None:
    bitmap = tag_bitmap("tag36h11", 0, cells_px=4, quiet_zone_cells=2)
    assert bitmap.shape == (48, 48) and bitmap.dtype == np.uint8
    assert set(np.unique(bitmap)) <= {0, 255}
    assert (bitmap[:8] == 255).all() and (bitmap[:, -8:] == 255).all()  # quiet zone
    assert (bitmap[8:12, 8:40] == 0).all() and (bitmap[8:40, 8:12] == 0).all()  # black border
    corners = bitmap_corners_px("tag36h11", cells_px=4, quiet_zone_cells=2)
    # Pixel 8 is the first black one: its outer edge is at 7.5 in OpenCV pixel coordinates.
    assert np.array_equal(corners, [[7.5, 7.5], [39.5, 7.5], [39.5, 39.5], [7.5, 39.5]])


def test_renderer_puts_black_area_and_centroid_where_the_geometry_says() -> None:
    # Under an affine map areas scale by |det A| and centroids map through the map: an exact
    # oracle for the renderer's pixel-center convention and area sampling.
    A = np.array([[0.9, 0.35], [-0.3, 1.05]])
    offset = np.array([60.3, 40.7])
    cell = 10.0
    square = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 8.0], [0.0, 8.0]]) * cell
    image = render_tag(np.full((200, 200), 255, np.uint8), "tag36h11", 3, square @ A.T + offset)
    dark = (255.0 - image) / 255.0
    black = tag_bitmap("tag36h11", 3, cells_px=1, quiet_zone_cells=0) == 0
    rows, cols = np.nonzero(black)
    assert dark.sum() == pytest.approx(black.sum() * cell**2 * abs(np.linalg.det(A)), abs=0.05)
    v, u = np.mgrid[0:200, 0:200]
    centroid = np.array([(dark * u).sum(), (dark * v).sum()]) / dark.sum()
    expected = A @ (np.array([cols.mean(), rows.mean()]) + 0.5) * cell + offset
    np.testing.assert_allclose(centroid, expected, atol=0.01)


def test_bitmap_arguments_are_checked() -> None:
    with pytest.raises(TagBackendError, match="unknown tag family 'tag36H11'"):
        tag_bitmap("tag36H11", 0)
    with pytest.raises(TagInputError, match=r"tag_id: tag36h11 has ids 0\.\.586, got 587"):
        tag_bitmap("tag36h11", 587)
    with pytest.raises(TagInputError, match="cells_px: must be >= 1"):
        tag_bitmap("tag36h11", 0, cells_px=0)
    with pytest.raises(TagInputError, match="quiet_zone_cells: expected an int"):
        tag_bitmap("tag36h11", 0, quiet_zone_cells=1.5)  # type: ignore[arg-type]
