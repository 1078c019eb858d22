"""``tagloc.io.kalibr.load_kalibr_cameras``: the real dupont camchain and wrapped errors.

(Kept beside the camera tests because the camera layer's constructors are what it exercises.)
Tolerances: projection vs ``cv2.fisheye.projectPoints`` 1e-8 px; round trip over the whole image
1e-6 px (requirement 1e-3 px).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tagloc.camera import PinholeEquidistant, PinholeRadtan
from tagloc.errors import CameraModelError
from tagloc.io.kalibr import load_kalibr_cameras

pytestmark = pytest.mark.filterwarnings("error")

DUPONT = Path(__file__).parents[2] / ".." / "shared" / "data" / "dupont"

GOOD_ENTRY = """\
  camera_model: pinhole
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  distortion_model: radtan
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  resolution: [752, 480]
"""


@pytest.fixture
def dupont_cameras() -> Path:
    path = DUPONT / "cameras.yaml"
    if not path.is_file():
        pytest.skip(f"dupont data set not found at {DUPONT.resolve()} (../shared/data/dupont)")
    return path


def test_dupont_cameras_load(dupont_cameras: Path) -> None:
    cameras = load_kalibr_cameras(dupont_cameras)
    assert list(cameras) == ["cam0", "cam1"]
    cam0 = cameras["cam0"]
    assert isinstance(cam0, PinholeEquidistant)
    assert cam0.image_size == (1280, 1024)
    np.testing.assert_array_equal(
        cam0.K, [[603.924, 0.0, 665.041], [0.0, 603.166, 554.34], [0.0, 0.0, 1.0]]
    )
    np.testing.assert_array_equal(
        cam0.dist_coeffs, [-0.0122741, -0.0100319, 0.00752173, -0.00247881]
    )
    assert cameras["cam1"].K[1, 2] == 440.254


def test_dupont_projection_and_round_trip(dupont_cameras: Path) -> None:
    for camera in load_kalibr_cameras(dupont_cameras).values():
        rng = np.random.default_rng(8)
        pixels = rng.uniform([-0.5, -0.5], [1279.5, 1023.5], (20000, 2))
        corners = np.array([[-0.5, -0.5], [1279.5, -0.5], [-0.5, 1023.5], [1279.5, 1023.5]])
        pixels = np.concatenate([pixels, corners])
        rays = camera.rays(pixels)
        assert np.isfinite(rays).all()
        points_cam = rays * rng.uniform(0.5, 20.0, (len(rays), 1))
        reference, _ = cv2.fisheye.projectPoints(
            points_cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), camera.K, camera.dist_coeffs
        )
        projected = camera.project(points_cam)
        assert np.abs(projected - reference.reshape(-1, 2)).max() < 1e-8
        assert np.abs(projected - pixels).max() < 1e-6
        # the lens sees up to ~88 degrees off-axis in the image corners
        assert 85.0 < np.degrees(np.arccos(rays[:, 2].min())) < 90.0


def test_error_names_file_and_field(tmp_path: Path) -> None:
    path = tmp_path / "cameras.yaml"
    path.write_text(
        "cam0:\n" + GOOD_ENTRY + "cam1:\n" + GOOD_ENTRY.replace("radtan", "equidistant").replace(
            "1.76187114e-05]", "1.76187114e-05, 0.1]"
        )
    )  # fmt: skip
    with pytest.raises(CameraModelError) as info:
        load_kalibr_cameras(path)
    assert str(info.value) == (
        f"{path}: cam1.distortion_coeffs: expected 4 values for equidistant, got 5"
    )


def test_good_file_in_order(tmp_path: Path) -> None:
    path = tmp_path / "camchain.yaml"
    path.write_text("cam1:\n" + GOOD_ENTRY + "  rostopic: /cam1\ncam0:\n" + GOOD_ENTRY)
    cameras = load_kalibr_cameras(str(path))
    assert list(cameras) == ["cam1", "cam0"]
    assert all(isinstance(c, PinholeRadtan) for c in cameras.values())
    assert cameras["cam0"] == cameras["cam1"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("cam0: [1, 2\n", "line 2, column 1: invalid YAML: did not find expected"),
        ("", "expected a mapping of camera names .* got an empty file"),
        ("- cam0\n", "expected a mapping of camera names .* got list"),
        ("cam0: 3\n", "cam0: expected a mapping"),
        (
            "cam0:\n" + GOOD_ENTRY.replace("  resolution: [752, 480]\n", ""),
            "cam0: missing field 'resolution'$",
        ),
    ],
)
def test_bad_files(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "cams.yaml"
    path.write_text(text)
    with pytest.raises(CameraModelError, match=rf"^{path}: {message}"):
        load_kalibr_cameras(path)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "absent.yaml"
    with pytest.raises(CameraModelError, match=rf"^{path}: cannot read the camera file"):
        load_kalibr_cameras(path)
