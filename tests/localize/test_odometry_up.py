"""The localizer's gravity prior takes "up" from the odometry frame as it is.

A body that is the camera's optical frame (a handheld rig's VIO reports it: z forward, y down)
is not an upright base. Taking its z for "up" makes every clear view of a tag conflict with the
gravity prior (the real drive refused 1,801 of 1,911 fix attempts as ``prior_conflict``); with
"up" from a gravity-aligned odometry the same view is a fix, and the fix is the true pose.
"""

from __future__ import annotations

import numpy as np

from tagloc.camera import PinholeRadtan
from tagloc.frames import OdometryFrameConfig
from tagloc.geometry import SE3, SO3
from tagloc.localize.fiducial import FiducialFixSource
from tagloc.tags import TagDetection
from tagloc.tags.detection import tag_object_points
from tagloc.tags.tagmap import TagEntry, TagMap

CAMERA = PinholeRadtan(width=1280, height=720, fx=640, fy=640, cx=640, cy=360)
#: A wall tag at x = 3 m facing -x (x to the viewer's right = -y of map, y up).
T_MAP_TAG = SE3(
    SO3.from_matrix(np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])),
    np.array([3.0, 0.0, 1.2]),
)
#: The body is the camera, looking along +x turned 25 deg left, 1.6 m from the tag.
R_MAP_OPTICAL = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
T_MAP_BODY = SE3(
    SO3.from_rotvec([0.0, 0.0, np.radians(25.0)]) @ SO3.from_matrix(R_MAP_OPTICAL),
    np.array([1.5, 0.5, 1.0]),
)


def _source() -> FiducialFixSource:
    entry = TagEntry(
        id=1, family="tag36h11", size=0.16, position=tuple(T_MAP_TAG.translation),
        quat_xyzw=tuple(T_MAP_TAG.rotation.as_quat()),
    )  # fmt: skip
    return FiducialFixSource(CAMERA, SE3.identity(), TagMap.from_entries([entry]))


def _detection() -> TagDetection:
    T_cam_tag = T_MAP_BODY.inverse() @ T_MAP_TAG
    corners = CAMERA.project(T_cam_tag.act(tag_object_points(0.16)))
    return TagDetection(1, "tag36h11", corners, 0, 50.0)


def test_an_optical_body_taken_for_upright_conflicts_with_gravity() -> None:
    result = _source().frame_fixes(0, [_detection()])
    assert not result.fixes
    assert [r.reason for r in result.rejects] == ["prior_conflict"]


def test_up_from_the_gravity_aligned_odometry_gives_the_true_fix() -> None:
    # the VIO frame is level: its z is up; "up" in the body from the odometry's orientation
    T_odom_body = SE3.from_rotvec([0.0, 0.0, 0.7], [0.0, 0.0, 0.0]) @ T_MAP_BODY
    frame = OdometryFrameConfig(gravity_aligned=True)
    up_body = frame.up_in_base(T_odom_body.rotation.as_matrix()[None])[0]
    result = _source().frame_fixes(0, [_detection()], up_base=up_body)
    (fix,) = result.fixes
    error = T_MAP_BODY.inverse() @ fix.fix.T_map_base
    assert np.linalg.norm(error.translation) < 1e-6
    # and the body declared by its up axis (an optical frame: -y) gives the same fix
    declared = OdometryFrameConfig(base_up_axis="-y").up_in_base(np.eye(3)[None])[0]
    (again,) = _source().frame_fixes(0, [_detection()], up_base=declared).fixes
    assert np.linalg.norm((again.fix.T_map_base.inverse() @ fix.fix.T_map_base).translation) < 1e-9


def test_no_known_up_runs_without_the_gravity_prior() -> None:
    entry = TagEntry(
        id=1, family="tag36h11", size=0.16, position=tuple(T_MAP_TAG.translation),
        quat_xyzw=tuple(T_MAP_TAG.rotation.as_quat()),
    )  # fmt: skip
    source = FiducialFixSource(CAMERA, SE3.identity(), TagMap.from_entries([entry]), up_base=None)
    result = source.frame_fixes(0, [_detection()])
    assert "prior_conflict" not in [r.reason for r in result.rejects]
