"""Building camera models (direct, OpenCV, ROS CameraInfo, Kalibr), validation, and small helpers.

Error tests match the message text: a message must name the field at fault.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from camera_cases import DUPONT

from tagloc.camera import (
    CameraModel,
    PinholeEquidistant,
    PinholeRadtan,
    check_image,
    from_camera_info,
    from_kalibr,
)
from tagloc.errors import CameraModelError, TaglocError

pytestmark = pytest.mark.filterwarnings("error")

FISHEYE = DUPONT
RADTAN = PinholeRadtan(
    width=640, height=480, fx=520.0, fy=521.5, cx=318.2, cy=242.9,
    k1=-0.3, k2=0.11, p1=0.0012, p2=-0.0008, k3=-0.02,
)  # fmt: skip


def camera_info(**changes: Any) -> dict[str, Any]:
    info: dict[str, Any] = {
        "width": 640,
        "height": 480,
        "distortion_model": "plumb_bob",
        "D": [-0.3, 0.11, 0.0012, -0.0008, -0.02],
        "K": [520.0, 0.0, 318.2, 0.0, 521.5, 242.9, 0.0, 0.0, 1.0],
        "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "P": [520.0, 0.0, 318.2, 0.0, 0.0, 521.5, 242.9, 0.0, 0.0, 0.0, 1.0, 0.0],
    }
    info.update(changes)
    return info


def kalibr_entry(**changes: Any) -> dict[str, Any]:
    entry: dict[str, Any] = {
        "camera_model": "pinhole",
        "intrinsics": [603.924, 603.166, 665.041, 554.34],
        "distortion_model": "equidistant",
        "distortion_coeffs": [-0.0122741, -0.0100319, 0.00752173, -0.00247881],
        "resolution": [1280, 1024],
        "rostopic": "/cam0/image_raw",
    }
    entry.update(changes)
    return entry


# -- direct construction -------------------------------------------------------------------------


def test_value_semantics() -> None:
    same = PinholeEquidistant(**{f.name: getattr(FISHEYE, f.name) for f in _init_fields(FISHEYE)})
    assert same == FISHEYE and hash(same) == hash(FISHEYE)
    assert dataclasses.replace(FISHEYE, k4=0.0) != FISHEYE
    with pytest.raises(dataclasses.FrozenInstanceError):
        FISHEYE.fx = 1.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        PinholeRadtan(640, 480, 500.0, 500.0, 320.0, 240.0)  # type: ignore[misc]
    assert FISHEYE.image_size == (1280, 1024)
    assert FISHEYE.distortion_model == "equidistant" and RADTAN.distortion_model == "radtan"
    np.testing.assert_array_equal(RADTAN.dist_coeffs, [-0.3, 0.11, 0.0012, -0.0008, -0.02])
    np.testing.assert_array_equal(RADTAN.K, [[520.0, 0, 318.2], [0, 521.5, 242.9], [0, 0, 1]])


def _init_fields(camera: object) -> list[dataclasses.Field[Any]]:
    return [f for f in dataclasses.fields(camera) if f.init]  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"width": 0}, r"PinholeRadtan\.width: must be positive, got 0"),
        ({"height": 480.5}, r"PinholeRadtan\.height: expected a positive integer"),
        ({"width": True}, r"PinholeRadtan\.width: expected a positive integer"),
        ({"fx": 0.0}, r"PinholeRadtan\.fx: must be positive, got 0\.0"),
        ({"fy": -500.0}, r"PinholeRadtan\.fy: must be positive"),
        ({"cx": math.inf}, r"PinholeRadtan\.cx: must be finite"),
        ({"k1": math.nan}, r"PinholeRadtan\.k1: must be finite"),
        ({"p2": "0.1"}, r"PinholeRadtan\.p2: expected a number"),
        ({"fx": 1e308}, r"PinholeRadtan\.fx: 1e\+308 is outside \[1, 1e\+07\] px"),
        ({"fy": 1e-300}, r"PinholeRadtan\.fy: 1e-300 is outside \[1, 1e\+07\] px"),
        ({"cy": -1e300}, r"PinholeRadtan\.cy: -1e\+300 is outside \[-1e\+07, 1e\+07\] px"),
        ({"width": 10**9}, r"PinholeRadtan\.width: 1e\+09 is outside \[1, 100000\] px"),
        ({"k3": 1e300}, r"PinholeRadtan\.k3: 1e\+300 is outside \[-10000, 10000\]$"),
    ],
)
def test_direct_construction_is_validated(changes: dict[str, Any], message: str) -> None:
    with pytest.raises(CameraModelError, match=message):
        dataclasses.replace(RADTAN, **changes)


def test_from_opencv_matches_fields() -> None:
    camera = PinholeRadtan.from_opencv(RADTAN.K, RADTAN.dist_coeffs.reshape(-1, 1), (640, 480))
    assert camera == RADTAN
    four = PinholeRadtan.from_opencv(RADTAN.K, [0.1, 0.2, 0.3, 0.4], (640, 480))
    assert four.k3 == 0.0 and four.p2 == 0.4
    assert PinholeEquidistant.from_opencv(FISHEYE.K, FISHEYE.dist_coeffs, (1280, 1024)) == FISHEYE
    with pytest.raises(CameraModelError, match="D: expected 4 values for equidistant, got 5"):
        PinholeEquidistant.from_opencv(FISHEYE.K, np.zeros(5), (1280, 1024))


# -- ROS CameraInfo ------------------------------------------------------------------------------


def test_from_camera_info_plumb_bob_and_equidistant() -> None:
    assert from_camera_info(camera_info()) == RADTAN
    four = from_camera_info(camera_info(D=[-0.3, 0.11, 0.0012, -0.0008]))
    assert isinstance(four, PinholeRadtan) and four.k3 == 0.0
    fisheye = from_camera_info(FISHEYE.to_camera_info())
    assert isinstance(fisheye, PinholeEquidistant) and fisheye == FISHEYE


def test_from_camera_info_accepts_ros2_field_names_and_arrays() -> None:
    info = camera_info()
    ros2 = {k.lower() if k in "DKRP" else k: np.asarray(v) for k, v in info.items()}
    ros2["width"], ros2["height"] = np.uint32(640), np.uint32(480)
    ros2["distortion_model"] = "plumb_bob"
    assert from_camera_info(ros2) == RADTAN


@pytest.mark.parametrize("camera", [FISHEYE, RADTAN], ids=["equidistant", "radtan"])
def test_camera_info_round_trip(camera: CameraModel) -> None:
    info = camera.to_camera_info()
    assert yaml.safe_load(yaml.safe_dump(info)) == info  # plain Python values only
    assert from_camera_info(info) == camera
    assert len(info["R"]) == 9 and len(info["P"]) == 12


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        (
            {"distortion_model": "rational_polynomial", "D": [0.0] * 8},
            r"camera_info\.distortion_model: 'rational_polynomial' .* is not supported",
        ),
        ({"distortion_model": "fisheye"}, r"camera_info\.distortion_model: unknown model 'fish"),
        ({"D": [0.0] * 8}, r"camera_info\.D: expected 4 or 5 values for plumb_bob, got 8"),
        ({"D": []}, r"camera_info\.D: expected 4 or 5 values for plumb_bob, got 0"),
        (
            {"distortion_model": "equidistant", "D": [0.0] * 5},
            r"camera_info\.D: expected 4 values for equidistant, got 5",
        ),
        ({"D": [0.0, 0.0, "x", 0.0]}, r"camera_info\.D\[2\]: expected a number"),
        ({"D": 0.1}, r"camera_info\.D: expected a list of numbers"),
        ({"K": [0.0] * 9}, r"camera_info\.K: all zeros \(the camera is not calibrated\)"),
        ({"K": [0.0, 0, 318, 0, 521, 242, 0, 0, 1]}, r"K\[0\]\[0\] \(fx\): must be positive"),
        ({"K": [520.0, 0, 318, 0, -5, 242, 0, 0, 1]}, r"K\[1\]\[1\] \(fy\): must be positive"),
        ({"K": [520.0, 0.3, 318, 0, 521, 242, 0, 0, 1]}, r"camera_info\.K: skew"),
        ({"K": [520.0, 0, 318, 0, 521, 242, 0, 0, 2]}, r"camera_info\.K: expected \[\[fx"),
        ({"K": [520.0, 0, 318, 0, 521, 242]}, r"camera_info\.K: expected 9 values"),
        ({"width": 0}, r"camera_info\.width: must be positive"),
        ({"binning_x": 2}, r"camera_info\.binning_x: binning 2 is not supported"),
        (
            {"roi": {"x_offset": 10, "y_offset": 0, "width": 100, "height": 100}},
            r"camera_info\.roi: a region of interest",
        ),
    ],
)
def test_bad_camera_info_is_rejected(changes: dict[str, Any], message: str) -> None:
    with pytest.raises(CameraModelError, match=message):
        from_camera_info(camera_info(**changes))


@pytest.mark.parametrize("key", ["width", "height", "distortion_model", "D", "K"])
def test_camera_info_missing_field(key: str) -> None:
    info = camera_info()
    del info[key]
    with pytest.raises(CameraModelError, match=rf"^left/camera_info: missing field '{key}'$"):
        from_camera_info(info, name="left/camera_info")


def test_camera_info_full_frame_roi_and_no_binning_are_fine() -> None:
    roi = {"x_offset": 0, "y_offset": 0, "width": 640, "height": 480, "do_rectify": False}
    assert from_camera_info(camera_info(roi=roi, binning_x=1, binning_y=0)) == RADTAN
    with pytest.raises(CameraModelError, match="expected a mapping"):
        from_camera_info([1, 2, 3])  # type: ignore[arg-type]


# -- Kalibr --------------------------------------------------------------------------------------


def test_from_kalibr_models() -> None:
    assert from_kalibr(kalibr_entry()) == FISHEYE
    radtan = from_kalibr(kalibr_entry(distortion_model="radtan", distortion_coeffs=[1, 2, 3, 4]))
    assert isinstance(radtan, PinholeRadtan)
    np.testing.assert_array_equal(radtan.dist_coeffs, [1, 2, 3, 4, 0])
    plain = from_kalibr(kalibr_entry(distortion_model="none", distortion_coeffs=[]))
    assert isinstance(plain, PinholeRadtan) and not plain.dist_coeffs.any()


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        (
            {"distortion_coeffs": [0.1, 0.2, 0.3, 0.4, 0.5]},
            r"^cam0\.distortion_coeffs: expected 4 values for equidistant, got 5$",
        ),
        (
            {"distortion_model": "radtan", "distortion_coeffs": [0.0] * 5},
            r"^cam0\.distortion_coeffs: expected 4 values for radtan, got 5$",
        ),
        ({"distortion_model": "fov"}, r"^cam0\.distortion_model: 'fov' is not supported"),
        ({"camera_model": "omni"}, r"^cam0\.camera_model: 'omni' is not supported"),
        ({"intrinsics": [600, 600, 640]}, r"^cam0\.intrinsics: expected 4 values"),
        ({"intrinsics": [-600, 600, 640, 512]}, r"^cam0\.intrinsics\[0\] \(fu\): must be positive"),
        ({"intrinsics": [600, 0, 640, 512]}, r"^cam0\.intrinsics\[1\] \(fv\): must be positive"),
        ({"resolution": [1280.5, 1024]}, r"^cam0\.resolution\[0\] \(width\): expected a positive"),
        ({"resolution": [1280, -1]}, r"^cam0\.resolution\[1\] \(height\): must be positive"),
        ({"intrinsics": "600 600 640 512"}, r"^cam0\.intrinsics: expected a list of numbers"),
    ],
)
def test_bad_kalibr_entry_is_rejected(changes: dict[str, Any], message: str) -> None:
    with pytest.raises(CameraModelError, match=message):
        from_kalibr(kalibr_entry(**changes))


@pytest.mark.parametrize(
    "key", ["camera_model", "intrinsics", "distortion_model", "distortion_coeffs", "resolution"]
)
def test_kalibr_missing_field(key: str) -> None:
    entry = kalibr_entry()
    del entry[key]
    with pytest.raises(CameraModelError, match=rf"^cam1: missing field '{key}'$"):
        from_kalibr(entry, name="cam1")


def test_errors_are_tagloc_errors() -> None:
    with pytest.raises(TaglocError):
        from_kalibr("cam0")  # type: ignore[arg-type]
    assert issubclass(CameraModelError, ValueError)


# -- scaled, in_image, check_image ---------------------------------------------------------------


def test_scaled_follows_cv2_resize_geometry() -> None:
    # A Gaussian blob centered on the principal point of a 64x48 image, resized by 0.5 with
    # INTER_AREA: its centroid must land on the scaled principal point ((c + 0.5) s - 0.5,
    # not c s, which would be 0.25 px off).
    camera = PinholeRadtan(width=64, height=48, fx=50.0, fy=50.0, cx=20.3, cy=17.8)
    v, u = np.mgrid[0:48, 0:64].astype(np.float64)
    blob = np.exp(-((u - camera.cx) ** 2 + (v - camera.cy) ** 2) / (2 * 2.5**2))
    small = cv2.resize(blob, (32, 24), interpolation=cv2.INTER_AREA)
    vs, us = np.mgrid[0:24, 0:32].astype(np.float64)
    centroid = np.array([(small * us).sum(), (small * vs).sum()]) / small.sum()
    half = camera.scaled(0.5)
    assert half.image_size == (32, 24)
    np.testing.assert_allclose(centroid, [half.cx, half.cy], atol=0.01)


@pytest.mark.parametrize("factor", [0.5, 0.25, 2.0])
def test_scaled_projection_is_the_resized_pixel(factor: float) -> None:
    points_cam = np.random.default_rng(6).uniform([-1, -1, 1], [1, 1, 5], (100, 3))
    scaled = FISHEYE.scaled(factor)
    assert isinstance(scaled, PinholeEquidistant) and scaled.dist_coeffs.tolist() == [
        -0.0122741, -0.0100319, 0.00752173, -0.00247881,
    ]  # fmt: skip
    expected = (FISHEYE.project(points_cam) + 0.5) * factor - 0.5
    np.testing.assert_allclose(scaled.project(points_cam), expected, atol=1e-9)


def test_scaled_rejects_fractional_sizes() -> None:
    with pytest.raises(CameraModelError, match=r"scaled\.factor: 0\.3 turns the 1280x1024"):
        FISHEYE.scaled(0.3)
    with pytest.raises(CameraModelError, match=r"scaled\.factor: must be positive"):
        FISHEYE.scaled(0.0)


def test_in_image_uses_the_pixel_area() -> None:
    pixels = [
        [-0.5, -0.5],
        [1279.5, 1023.5],
        [-0.51, 0.0],
        [0.0, 1023.6],
        [np.nan, 5.0],
        [640, 512],
    ]
    np.testing.assert_array_equal(FISHEYE.in_image(pixels), [True, True, False, False, False, True])
    np.testing.assert_array_equal(
        FISHEYE.in_image([[1.0, 1.0], [1.5, 1.5], [1277.5, 1021.5]], margin=2.0),
        [False, True, True],
    )
    assert FISHEYE.in_image([640.0, 512.0]).shape == ()


def test_check_image() -> None:
    gray = np.zeros((1024, 1280), np.uint8)
    color = np.zeros((1024, 1280, 3), np.uint8)
    assert check_image(gray, FISHEYE) is gray and check_image(color, FISHEYE) is color
    with pytest.raises(
        CameraModelError, match=r"^left: image is 640x512 .* camera model is 1280x1024"
    ):
        check_image(np.zeros((512, 640)), FISHEYE, name="left")
    with pytest.raises(CameraModelError, match="image is 1024x1280"):
        check_image(np.zeros((1280, 1024)), FISHEYE)
    with pytest.raises(CameraModelError, match=r"expected an array of shape \(height, width\)"):
        check_image(np.zeros(1280), FISHEYE)
