"""Detection backends against rendered tags with exactly known corners, and the corner convention.

Oracle: :func:`tagloc.tags.bitmaps.render_tag` (itself checked against exact areas and centroids in
``test_tag_bitmaps.py``) paints a tag whose black-border corners are exactly ``corners_px``.
"""

from __future__ import annotations

import gc
import math
import subprocess
import sys
from collections.abc import Iterator

import cv2
import numpy as np
import pupil_apriltags
import pytest
from tag_scenes import max_corner_error, perspective_quad, scene, square_quad

from tagloc.tags import (
    TagBackendError,
    TagDetection,
    TagDetector,
    TagInputError,
    available_backends,
    make_detector,
    tag_bitmap,
    tag_object_points,
)
from tagloc.tags.apriltag_backend import release_pupil_detector
from tagloc.tags.bitmaps import bitmap_corners_px
from tagloc.tags.families import opencv_quarter_turns

# AprilTag 3 stays within 0.22 px on these cases. OpenCV's CORNER_REFINE_SUBPIX pulls corners
# ~0.12 px towards the tag center (test_aruco_subpix_corners_are_pulled_inwards) and reaches
# 0.36 px on the most skewed quad here, hence the looser ArUco bound.
TOL_TRUTH_PX = {"apriltag": 0.3, "aruco": 0.4}
TOL_BETWEEN_PX = 0.4
BACKENDS = ("apriltag", "aruco")
CENTER = (320.37, 240.81)  # off the pixel grid


@pytest.fixture(scope="module")
def detectors() -> dict[str, TagDetector]:
    return {name: make_detector(name, "tag36h11") for name in BACKENDS}


@pytest.fixture(scope="module")
def raw_pupil() -> Iterator[pupil_apriltags.Detector]:
    """A bare pupil-apriltags detector, freed in the safe order (its own __del__ is not)."""
    detector = pupil_apriltags.Detector("tag36h11")
    yield detector
    release_pupil_detector(detector)


def _perspective_cases() -> list[tuple[str, np.ndarray]]:
    rng = np.random.default_rng(20240611)
    cases = []
    for i in range(6):
        side = float(rng.uniform(90.0, 160.0))
        center = (float(rng.uniform(220, 420)), float(rng.uniform(170, 310)))
        cases.append((f"random{i}", perspective_quad(rng, center, side, jitter=0.06)))
    oblique = np.array([[262.4, 171.3], [401.9, 199.6], [396.2, 287.7], [257.8, 318.1]])
    for k in range(4):  # a strongly foreshortened tag, turned by quarter turns about CENTER
        a = math.radians(90 * k)
        R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        cases.append((f"oblique{90 * k}", (oblique - CENTER) @ R.T + CENTER))
    return cases


AGREEMENT_CASES = [
    *((f"square{angle}", square_quad(CENTER, 120.0, angle)) for angle in (0, 90, 180, 270, 33)),
    *_perspective_cases(),
]


@pytest.mark.parametrize(("name", "truth"), AGREEMENT_CASES, ids=[c[0] for c in AGREEMENT_CASES])
def test_both_backends_find_the_true_corners_and_agree(
    detectors: dict[str, TagDetector], name: str, truth: np.ndarray
) -> None:
    image = scene([("tag36h11", 42, truth)])
    found = {}
    for backend, detector in detectors.items():
        detections = detector.detect(image)
        assert [(d.tag_id, d.family) for d in detections] == [(42, "tag36h11")], backend
        found[backend] = detections[0].corners_px
        error = max_corner_error(found[backend], truth)
        assert error < TOL_TRUTH_PX[backend], f"{backend} {name}: {error:.3f} px from truth"
    between = max_corner_error(found["apriltag"], found["aruco"])
    assert between < TOL_BETWEEN_PX, f"{name}: backends {between:.3f} px apart"


@pytest.mark.parametrize(
    ("backend", "family"),
    [("apriltag", "tag36h11"), ("aruco", "tag36h11"), ("apriltag", "tag16h5"),
     ("aruco", "aruco_4x4_50"), ("aruco", "aruco_mip_36h12")],
)  # fmt: skip
def test_corner_labelled_top_left_is_the_upright_tags_upper_left(backend: str, family: str) -> None:
    # Upright, axis-aligned: corner 0 has the smallest u and v, then clockwise on screen.
    truth = square_quad(CENTER, 100.0, 0.0)
    detections = make_detector(backend, family).detect(scene([(family, 5, truth)]))
    assert len(detections) == 1
    corners = detections[0].corners_px
    u_mid, v_mid = corners.mean(axis=0)
    upper_left, upper_right, lower_right, lower_left = corners
    assert upper_left[0] < u_mid and upper_left[1] < v_mid
    assert upper_right[0] > u_mid and upper_right[1] < v_mid
    assert lower_right[0] > u_mid and lower_right[1] > v_mid
    assert lower_left[0] < u_mid and lower_left[1] > v_mid
    assert max_corner_error(corners, truth) < TOL_TRUTH_PX[backend]


def test_ippe_square_with_tag_object_points_recovers_the_tag_pose() -> None:
    # A camera facing an upright tag: tag x = camera x, tag y = -camera y (up), tag z = -camera z
    # (towards the camera); tilted 25 deg about the tag's y axis and rolled 10 deg.
    K = np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]])
    R_facing = np.diag([1.0, -1.0, -1.0])
    R_cam_tag = R_facing @ cv2.Rodrigues(np.deg2rad([0.0, 25.0, 10.0]))[0]
    t_cam_tag = np.array([0.05, -0.03, 0.9])
    points_tag = tag_object_points(0.16)
    points_cam = points_tag @ R_cam_tag.T + t_cam_tag
    corners = points_cam[:, :2] / points_cam[:, 2:] @ K[:2, :2].T + K[:2, 2]
    for detector in (make_detector("apriltag"), make_detector("aruco")):
        (det,) = detector.detect(scene([("tag36h11", 1, corners)]))
        ok, rvec, tvec = cv2.solvePnP(
            points_tag, det.corners_px, K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        assert ok
        R_est = cv2.Rodrigues(rvec)[0]
        angle = np.degrees(np.arccos(np.clip((np.trace(R_est.T @ R_cam_tag) - 1) / 2, -1, 1)))
        assert angle < 0.5, detector.backend
        np.testing.assert_allclose(tvec.ravel(), t_cam_tag, atol=2e-3)
        assert R_est[2, 2] < 0  # tag z points towards the camera
        assert R_est[1, 1] < 0  # tag y (up) is image-up: camera -y


def test_pupil_apriltags_raw_corners_are_half_a_pixel_off_and_bottom_left_first(
    raw_pupil: pupil_apriltags.Detector,
) -> None:
    # The finding the apriltag backend corrects: pixel centers at +0.5, order bl, br, tr, tl.
    rng = np.random.default_rng(7)
    offsets = []
    for _ in range(8):
        truth = perspective_quad(rng, (320.0, 240.0), float(rng.uniform(80, 160)), 0.05)
        (raw,) = raw_pupil.detect(scene([("tag36h11", 9, truth)]))
        offsets.append(raw.corners - truth[[3, 2, 1, 0]])
    mean_offset = np.concatenate(offsets).mean(axis=0)
    np.testing.assert_allclose(mean_offset, [0.5, 0.5], atol=0.03)


def test_aruco_subpix_corners_are_pulled_inwards(detectors: dict[str, TagDetector]) -> None:
    # The finding behind TOL_TRUTH_PX["aruco"]: a systematic bias along the corner diagonals,
    # which AprilTag (edge-line fits) does not have.
    rng = np.random.default_rng(11)
    radial: dict[str, list[float]] = {backend: [] for backend in BACKENDS}
    for _ in range(10):
        truth = perspective_quad(rng, (320.0, 240.0), float(rng.uniform(80, 160)), 0.04)
        image = scene([("tag36h11", 21, truth)])
        outwards = truth - truth.mean(axis=0)
        outwards /= np.linalg.norm(outwards, axis=1, keepdims=True)
        for backend, detector in detectors.items():
            (det,) = detector.detect(image)
            radial[backend].extend(((det.corners_px - truth) * outwards).sum(axis=1))
    assert -0.2 < np.mean(radial["aruco"]) < -0.07
    assert abs(np.mean(radial["apriltag"])) < 0.05


def test_opencv_raw_corners_of_an_apriltag_start_at_the_rotated_top_left() -> None:
    truth = square_quad(CENTER, 120.0, 20.0)
    detector = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    )
    corners, _ids, _rejected = detector.detectMarkers(scene([("tag36h11", 3, truth)]))
    raw = corners[0].reshape(4, 2)
    k = opencv_quarter_turns("tag36h11")
    assert max_corner_error(np.roll(raw, -k, axis=0), truth) < 1.0  # unrefined corners
    assert max_corner_error(raw, truth) > (20.0 if k else -1.0)


def test_aruco_keeps_a_tag_whose_quiet_zone_outline_is_grouped_with_it() -> None:
    # With OpenCV's default minMarkerDistanceRate (0.125) this tag is lost: its one-cell white
    # quiet zone's outline is grouped with the black border and kept instead.
    truth = np.array([[188.45, 23.8], [240.24, 139.55], [111.49, 204.98], [59.63, 80.55]])
    image = scene([("tag36h11", 54, truth)])
    assert make_detector("aruco", min_marker_distance_rate=0.125).detect(image) == []
    (det,) = make_detector("aruco").detect(image)
    assert det.tag_id == 54 and max_corner_error(det.corners_px, truth) < TOL_TRUTH_PX["aruco"]


def test_flipped_bit_is_reported_as_hamming_one_by_both_backends(
    detectors: dict[str, TagDetector],
) -> None:
    truth = square_quad(CENTER, 128.0, 0.0)
    clean = scene([("tag36h11", 11, truth)])
    damaged = clean.copy()
    # Invert data cell (row 3, col 4) of the 8x8 black-border grid: 16 px per cell here.
    v0, u0 = (truth[0] + 0.5 + np.array([4, 3]) * 16).astype(int)[::-1]
    damaged[v0 + 2 : v0 + 14, u0 + 2 : u0 + 14] = 255 - damaged[v0 + 8, u0 + 8]
    for backend, detector in detectors.items():
        (before,) = detector.detect(clean)
        (after,) = detector.detect(damaged)
        assert (before.tag_id, before.hamming) == (11, 0), backend
        assert (after.tag_id, after.hamming) == (11, 1), backend


def test_decision_margin_is_apriltags_and_nan_for_aruco(detectors: dict[str, TagDetector]) -> None:
    truth = square_quad(CENTER, 120.0, 0.0)
    strong = detectors["apriltag"].detect(scene([("tag36h11", 2, truth)]))[0]
    faint_image = (scene([("tag36h11", 2, truth)]).astype(float) * 0.3 + 90).astype(np.uint8)
    faint = detectors["apriltag"].detect(faint_image)[0]
    assert 0.0 < faint.decision_margin < strong.decision_margin
    assert math.isnan(detectors["aruco"].detect(scene([("tag36h11", 2, truth)]))[0].decision_margin)


def test_decode_sharpening_reaches_the_c_detector() -> None:
    # pupil-apriltags 1.0.4 stores int(decode_sharpening); the backend writes the real value.
    assert make_detector("apriltag").decode_sharpening == pytest.approx(0.25)  # type: ignore[attr-defined]
    assert make_detector("apriltag", decode_sharpening=0.6).decode_sharpening == pytest.approx(0.6)  # type: ignore[attr-defined]


def test_collected_detector_frees_the_c_detector_before_its_family() -> None:
    detector = make_detector("apriltag")
    raw = detector._detector  # type: ignore[attr-defined]  # the pupil object, to watch it
    del detector
    gc.collect()
    assert raw.tag_detector_ptr is None and raw.tag_families == {}
    release_pupil_detector(raw)  # idempotent
    del raw  # pupil's own __del__ now frees nothing


def test_several_tags_are_all_found_and_sorted_by_id(detectors: dict[str, TagDetector]) -> None:
    truths = {
        7: square_quad((150, 120), 90, 10),
        3: square_quad((470, 130), 100, 200),
        30: square_quad((160, 360), 80, 95),
        12: square_quad((480, 350), 110, 300),
    }
    image = scene([("tag36h11", tag_id, quad) for tag_id, quad in truths.items()])
    for backend, detector in detectors.items():
        detections = detector.detect(image)
        assert [d.tag_id for d in detections] == [3, 7, 12, 30], backend
        for det in detections:
            assert max_corner_error(det.corners_px, truths[det.tag_id]) < TOL_TRUTH_PX[backend]


# --- input validation -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tag_image() -> np.ndarray:
    return scene([("tag36h11", 4, square_quad(CENTER, 110.0, 15.0))])


def _as_bgr(gray: np.ndarray) -> np.ndarray:
    return np.repeat(gray[:, :, None], 3, axis=2)


ACCEPTED = {
    "uint8": lambda g: g,
    "HxWx1": lambda g: g[:, :, None],
    "BGR": _as_bgr,
    "BGRA": lambda g: np.concatenate([_as_bgr(g), np.full_like(g, 7)[:, :, None]], axis=2),
    "float64_0_1": lambda g: g / 255.0,
    "float32_0_1": lambda g: (g / 255.0).astype(np.float32),
    "non_contiguous": lambda g: np.asfortranarray(g),
    "channel_slice": lambda g: _as_bgr(g)[:, :, 1],
}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("variant", list(ACCEPTED))
def test_accepted_image_variants_give_the_gray_result(
    detectors: dict[str, TagDetector], tag_image: np.ndarray, backend: str, variant: str
) -> None:
    (reference,) = detectors[backend].detect(tag_image)
    (det,) = detectors[backend].detect(ACCEPTED[variant](tag_image))
    assert det.tag_id == reference.tag_id
    np.testing.assert_allclose(det.corners_px, reference.corners_px, atol=1e-9)


REJECTED = {
    "list": ([[0, 1], [2, 3]], "expected a numpy array, got list"),
    "empty": (np.zeros((0, 640), np.uint8), r"empty image \(shape \(0, 640\)\)"),
    "1d": (np.zeros(100, np.uint8), "1-D array"),
    "4d": (np.zeros((4, 4, 3, 2), np.uint8), "4-D array"),
    "2ch": (np.zeros((48, 64, 2), np.uint8), "2 channels"),
    "5ch": (np.zeros((48, 64, 5), np.uint8), "5 channels"),
    "uint16": (np.zeros((48, 64), np.uint16), "dtype uint16 not supported"),
    "int64": (np.zeros((48, 64), np.int64), "dtype int64 not supported"),
    "bool": (np.zeros((48, 64), bool), "dtype bool not supported"),
    "float_255": (np.full((48, 64), 200.0), r"must lie in \[0, 1\], found values in \[200, 200\]"),
    "float_nan": (np.full((48, 64), np.nan), "NaN or infinite"),
}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("variant", list(REJECTED))
def test_bad_images_raise_tag_input_error_naming_the_problem(
    detectors: dict[str, TagDetector], backend: str, variant: str
) -> None:
    image, message = REJECTED[variant]
    with pytest.raises(TagInputError, match=message):
        detectors[backend].detect(image)


def test_tiny_images_return_nothing_instead_of_crashing_the_c_library() -> None:
    # AprilTag 3 segfaults on images under 3 decimated rows: run in a child process so that a
    # crash fails this test instead of killing the session.
    code = (
        "import numpy as np\n"
        "from tagloc.tags import make_detector\n"
        "for backend, options in [('apriltag', {'quad_decimate': 1.0}),\n"
        "        ('apriltag', {'quad_decimate': 2.0}), ('apriltag', {'quad_decimate': 8.0}),\n"
        "        ('aruco', {})]:\n"
        "    detector = make_detector(backend, 'tag36h11', **options)\n"
        "    for shape in [(1, 1), (1, 640), (2, 640), (4, 640), (16, 640), (31, 31), (640, 2)]:\n"
        "        assert detector.detect(np.zeros(shape, np.uint8)) == [], (backend, shape)\n"
        "print('ok')\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip() == "ok"


# --- from_corners, TagDetection, object points ---------------------------------------------------

TRUTH = square_quad(CENTER, 100.0, 25.0)


@pytest.mark.parametrize("perm", [(0, 1, 2, 3), (3, 2, 1, 0), (2, 3, 0, 1), (1, 3, 0, 2)])
def test_from_corners_reorders_any_labelled_order(perm: tuple[int, ...]) -> None:
    labels = ("tl", "tr", "br", "bl")
    order = "_".join(labels[i] for i in perm)
    given = TRUTH[list(perm)] + 0.5
    det = TagDetection.from_corners(8, "tag36h11", given, order=order, pixel_offset=0.5)
    np.testing.assert_allclose(det.corners_px, TRUTH, atol=1e-12)


def test_from_corners_takes_pupil_apriltags_output_as_is(
    raw_pupil: pupil_apriltags.Detector,
) -> None:
    image = scene([("tag36h11", 6, TRUTH)])
    (raw,) = raw_pupil.detect(image)
    det = TagDetection.from_corners(
        raw.tag_id, "tag36h11", raw.corners, order="bl_br_tr_tl", pixel_offset=0.5,
        hamming=raw.hamming, decision_margin=raw.decision_margin,
    )  # fmt: skip
    assert max_corner_error(det.corners_px, TRUTH) < TOL_TRUTH_PX["apriltag"]
    assert det.decision_margin == pytest.approx(raw.decision_margin)


def test_detection_fields_center_and_immutability() -> None:
    det = TagDetection.from_corners(8, "aruco_4x4_50", TRUTH)
    assert det.hamming == 0 and math.isnan(det.decision_margin)
    np.testing.assert_allclose(det.center_px, CENTER, atol=1e-9)  # diagonals of a square
    assert det.corners_px.dtype == np.float64 and det.corners_px.shape == (4, 2)
    with pytest.raises(ValueError, match="read-only"):
        det.corners_px[0, 0] = 1.0
    with pytest.raises(AttributeError):
        det.tag_id = 3  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"order": "tl_tr_br"}, "not a permutation"),
        ({"order": "tl_tl_br_bl"}, "not a permutation"),
        ({"order": "tl_bl_br_tr"}, "not a convex quadrilateral .* in order 'tl_bl_br_tr'"),
        ({"order": "tl_tr_bl_br"}, "not a convex quadrilateral"),
        ({"corners_px": np.zeros((3, 2))}, r"expected shape \(4, 2\), got \(3, 2\)"),
        ({"corners_px": np.full((4, 2), np.nan)}, "NaN or infinite"),
        ({"corners_px": "abcd"}, "cannot be read as a float array"),
        ({"family": "tag36H11"}, "unknown tag family 'tag36H11'"),
        ({"tag_id": -1}, r"tag_id: tag36h11 has ids 0\.\.586, got -1"),
        ({"tag_id": 587}, r"tag_id: tag36h11 has ids 0\.\.586, got 587"),
        ({"decision_margin": "high"}, "decision_margin: expected a number"),
        ({"tag_id": 1.0}, "tag_id: expected an int"),
        ({"hamming": -2}, "hamming: must be >= 0"),
        ({"pixel_offset": math.inf}, "pixel_offset: must be a finite number"),
        ({"pixel_offset": "half"}, "pixel_offset: must be a finite number"),
    ],
)
def test_from_corners_rejects_malformed_input(kwargs: dict[str, object], message: str) -> None:
    arguments: dict[str, object] = {"tag_id": 1, "family": "tag36h11", "corners_px": TRUTH}
    with pytest.raises((TagInputError, TagBackendError), match=message):
        TagDetection.from_corners(**{**arguments, **kwargs})  # type: ignore[arg-type]


def test_tag_object_points_order_and_checks() -> None:
    np.testing.assert_array_equal(
        tag_object_points(0.2),
        [[-0.1, 0.1, 0.0], [0.1, 0.1, 0.0], [0.1, -0.1, 0.0], [-0.1, -0.1, 0.0]],
    )
    for bad in (0.0, -1.0, math.nan, "0.2"):
        with pytest.raises(TagInputError, match="size"):
            tag_object_points(bad)  # type: ignore[arg-type]


# --- registry -----------------------------------------------------------------------------------


def test_registry_builds_and_refuses_clearly() -> None:
    assert available_backends() == ("apriltag", "aruco")
    assert make_detector().families == ("tag36h11",)
    assert make_detector("aruco", "aruco_5x5_100").backend == "aruco"
    with pytest.raises(TagBackendError, match="unknown detector backend 'zbar'"):
        make_detector("zbar")
    with pytest.raises(TagBackendError, match="cannot detect family 'aruco_4x4_50'"):
        make_detector("apriltag", "aruco_4x4_50")
    with pytest.raises(TagBackendError, match=r"unknown option\(s\) quad_decimation"):
        make_detector("apriltag", quad_decimation=2.0)
    with pytest.raises(TagBackendError, match="quad_decimate: expected a number from 1 to 64"):
        make_detector("apriltag", quad_decimate=0.5)
    with pytest.raises(TagBackendError, match="nthreads: expected an int from 1 to 64"):
        make_detector("apriltag", nthreads=2**40)  # would reach the library's thread pool
    with pytest.raises(TagBackendError, match="corner_refinement_win_size: expected an int from"):
        make_detector("aruco", corner_refinement_win_size=2**40)
    with pytest.raises(TagBackendError, match="corner_refinement: 'apriltag' not one of"):
        make_detector("aruco", corner_refinement="apriltag")


def test_pasted_bitmap_is_found_at_bitmap_corners_px() -> None:
    # The simulator path without the renderer: a bitmap pasted at an integer offset has its
    # black-border corners at bitmap_corners_px + offset.
    bitmap = tag_bitmap("tag36h11", 0, cells_px=12, quiet_zone_cells=2)
    image = np.full((200, 220), 90, np.uint8)
    image[20 : 20 + bitmap.shape[0], 30 : 30 + bitmap.shape[1]] = bitmap
    corners = bitmap_corners_px("tag36h11", cells_px=12, quiet_zone_cells=2) + np.array([30, 20])
    for backend in BACKENDS:
        (det,) = make_detector(backend).detect(image)
        assert det.tag_id == 0
        assert max_corner_error(det.corners_px, corners) < TOL_TRUTH_PX[backend]
