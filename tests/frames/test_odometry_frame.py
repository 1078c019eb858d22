"""The odometry frame's relation to gravity and to the body: "up" in the body, and the check
that notices a body the configuration takes for upright while the odometry holds it sideways."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tagloc.config import validate
from tagloc.errors import ConfigError
from tagloc.frames import OdometryFrameConfig, axis_vector, base_tilt_deg


@pytest.mark.parametrize(
    ("axis", "expected"), [("+x", [1, 0, 0]), ("-y", [0, -1, 0]), ("+z", [0, 0, 1])]
)
def test_axis_names(axis: str, expected: list[int]) -> None:
    np.testing.assert_array_equal(axis_vector(axis), expected)  # type: ignore[arg-type]


def test_gravity_aligned_up_is_the_odometry_up_seen_from_the_body() -> None:
    R_odom_base = Rotation.random(50, random_state=1).as_matrix()
    for axis in ("+z", "-y"):
        up = OdometryFrameConfig(gravity_aligned=True, up_axis=axis).up_in_base(R_odom_base)  # type: ignore[arg-type]
        # scipy as the oracle: the body's up, rotated into the odometry frame, is the up axis
        back = Rotation.from_matrix(R_odom_base).apply(up)
        np.testing.assert_allclose(back, np.broadcast_to(axis_vector(axis), back.shape), atol=1e-12)  # type: ignore[arg-type]


def test_without_gravity_up_is_the_configured_body_axis() -> None:
    R_odom_base = Rotation.random(5, random_state=2).as_matrix()
    up = OdometryFrameConfig(base_up_axis="-y").up_in_base(R_odom_base)
    np.testing.assert_array_equal(up, np.tile([0.0, -1.0, 0.0], (5, 1)))


def test_base_tilt_sees_a_camera_frame_taken_for_an_upright_base() -> None:
    yaw = Rotation.from_euler("z", np.linspace(0, 6, 40)[:, None])
    upright = yaw.as_matrix()
    # a body whose z looks forward (an optical frame: x right, y down, z forward)
    R_base_cam = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    camera = upright @ R_base_cam
    default = OdometryFrameConfig()
    assert base_tilt_deg(upright, default.up_in_base(upright)) == pytest.approx(0.0, abs=1e-9)
    assert base_tilt_deg(camera, default.up_in_base(camera)) == pytest.approx(90.0, abs=1e-9)
    fixed = OdometryFrameConfig(base_up_axis="-y")
    assert base_tilt_deg(camera, fixed.up_in_base(camera)) == pytest.approx(0.0, abs=1e-9)


def test_a_bad_axis_names_the_field() -> None:
    with pytest.raises(ConfigError, match="up_axis"):
        validate(OdometryFrameConfig, {"gravity_aligned": True, "up_axis": "up"}, "odom.yaml")
