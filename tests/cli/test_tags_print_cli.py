"""``tagloc tags print``: sheets rasterized at 300 dpi (poppler's pdftoppm) and decoded by the
AprilTag library (OpenCV's ArUco detector for ArUco families): every tag where and how large it
was asked for. Skipped with a message where pdftoppm is missing (``make test`` installs it)."""

from __future__ import annotations

import functools
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from cli_runner import one_error_line, run_tagloc

DPI = 300
#: Largest error of a printed black-border edge, millimetres (the requirement).
EDGE_TOL_MM = 0.2

needs_pdftoppm = pytest.mark.skipif(
    shutil.which("pdftoppm") is None,
    reason="pdftoppm (poppler-utils) is not installed: `make test` installs it; the sheets' "
    "physical sizes are not checked",
)


def _rasterize(pdf: Path, out_dir: Path) -> list[np.ndarray]:
    """Every page of ``pdf`` as a gray image at :data:`DPI`."""
    subprocess.run(["pdftoppm", "-r", str(DPI), "-gray", "-png", str(pdf), str(out_dir / "page")],
                   check=True, timeout=120)  # fmt: skip
    pages = sorted(out_dir.glob("page-*.png"))
    return [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in pages]


@functools.cache
def _apriltag_detector(family: str):  # type: ignore[no-untyped-def]
    """One AprilTag detector per family for the whole module (creating and freeing many in one
    process has crashed pupil-apriltags)."""
    from pupil_apriltags import Detector

    return Detector(families=family)


def _decode(family: str, image: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """``(id, corners (4, 2) px)`` of every tag the reference library finds."""
    if family.startswith("tag"):
        found = _apriltag_detector(family).detect(image)
        return [(int(d.tag_id), np.asarray(d.corners)) for d in found]
    name = "DICT_" + family.removeprefix("aruco_").upper()
    detector = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)),
        cv2.aruco.DetectorParameters(),
    )
    corners, ids, _ = detector.detectMarkers(image)
    if ids is None:
        return []
    return [
        (int(i), np.asarray(c).reshape(4, 2)) for i, c in zip(ids.ravel(), corners, strict=True)
    ]


@needs_pdftoppm
@pytest.mark.parametrize(
    ("family", "ids", "expected", "size", "paper"),
    [
        ("tag36h11", "0-1", [0, 1], 0.16, "a4"),
        ("tag36h11", "3,5-15", [3, *range(5, 16)], 0.05, "letter"),
        ("tag25h9", "0-3", [0, 1, 2, 3], 0.08, "a4"),
        ("aruco_4x4_50", "10-13", [10, 11, 12, 13], 0.06, "letter"),
    ],
)
def test_printed_tags_decode_at_their_size(
    tmp_path: Path, family: str, ids: str, expected: list[int], size: float, paper: str
) -> None:
    pdf = tmp_path / "tags.pdf"
    done = run_tagloc("tags", "print", "--family", family, "--ids", ids, "--size", str(size),
                      "--paper", paper, "-o", str(pdf))  # fmt: skip
    assert done.returncode == 0, done.stderr
    pages = _rasterize(pdf, tmp_path)
    width_in, height_in = {"a4": (210 / 25.4, 297 / 25.4), "letter": (8.5, 11.0)}[paper]
    found: list[int] = []
    for image in pages:
        assert (
            abs(image.shape[1] - width_in * DPI) <= 1 and abs(image.shape[0] - height_in * DPI) <= 1
        )
        for tag_id, corners in _decode(family, image):
            edges_mm = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1) / DPI * 25.4
            assert np.abs(edges_mm - 1000 * size).max() <= EDGE_TOL_MM, (tag_id, edges_mm)
            found.append(tag_id)
    assert sorted(found) == expected


def test_bad_ids_and_sizes_are_one_line_and_write_nothing(tmp_path: Path) -> None:
    pdf = tmp_path / "tags.pdf"
    for args, words in (
        (("--ids", "0-600"), "tag36h11 has ids 0-586"),
        (("--ids", "5-2"), "is empty"),
        (("--ids", "a,b"), "expected ids and ranges"),
        (("--ids", "0", "--family", "tag99"), "unknown tag family"),
        (("--ids", "0-3", "--size", "0.3"), "does not fit on a4 paper"),
        (("--ids", "0", "--paper", "a3"), "--paper"),
        (("--ids", "0", "--size", "-1"), "--size"),
    ):
        line = one_error_line(run_tagloc("tags", "print", "-o", str(pdf), *args))
        assert words in line, line
        assert not pdf.exists() and list(tmp_path.iterdir()) == []
