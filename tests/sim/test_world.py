"""The built-in office world meets its spec; tag, cab and camera frames follow the conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from tagloc.geometry import SE3
from tagloc.sim import World, load_default_world, simulate_drive
from tagloc.sim.world import Tag, Wall

FloatArray = NDArray[np.float64]


@pytest.fixture(scope="module")
def world() -> World:
    return load_default_world()


def _segments(walls: tuple[Wall, ...], opaque_only: bool = False) -> FloatArray:
    """(W, 4) ``[x0, y0, x1, y1]`` of the walls (optionally without glass)."""
    keep = [w for w in walls if not (opaque_only and w.material == "glass")]
    return np.array([[*w.start, *w.end] for w in keep])


def _crosses(p: FloatArray, q: FloatArray, seg: FloatArray) -> FloatArray:
    """(N, W) bool: does the open segment p[n] -> q[n] properly cross wall w (2-D)?"""

    def orient(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
        return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
            c[..., 0] - a[..., 0]
        )

    p, q = p[:, None, :], q[:, None, :]
    a, b = seg[None, :, :2], seg[None, :, 2:]
    return (orient(p, q, a) * orient(p, q, b) < 0) & (orient(a, b, p) * orient(a, b, q) < 0)


def _distance_to_segments(points: FloatArray, seg: FloatArray) -> FloatArray:
    """(N, W) distance from each point to each wall segment."""
    a, b = seg[None, :, :2], seg[None, :, 2:]
    ab = b - a
    t = np.clip(np.sum((points[:, None, :] - a) * ab, -1) / np.sum(ab * ab, -1), 0.0, 1.0)
    return np.linalg.norm(points[:, None, :] - (a + t[..., None] * ab), axis=-1)


def test_default_world_meets_the_spec(world: World) -> None:
    assert world.version == 1
    walls = _segments(world.walls)
    extent = (
        walls[:, [0, 2]].max() - walls[:, [0, 2]].min(),
        walls[:, [1, 3]].max() - walls[:, [1, 3]].min(),
    )
    assert extent == pytest.approx((40.0, 20.0))
    assert any(w.material == "glass" for w in world.walls)
    # 30 along corridor, rooms and lobby, plus 7 placed where the route had 6-9 m without a
    # tag in view (room exits, lobby west wall): 37
    assert len(world.tags) == 37
    ids = [(t.family, t.id) for t in world.tags]
    assert len(set(ids)) == len(ids)
    assert all(t.family == "tag36h11" and t.size == 0.16 for t in world.tags)
    cab_tags = [t for t in world.tags if t.frame == "elevator_cab"]
    assert world.elevator is not None and 1 <= len(cab_tags) <= 2
    heights = [world.T_map_tag(t).translation[2] for t in world.tags if t.frame == "map"]
    assert min(heights) >= 1.2 and max(heights) <= 1.5
    assert len(world.checkpoints) >= 10
    assert world.robot.odometry.model == "legged"
    cam = world.robot.camera
    hfov = 2 * math.degrees(math.atan(cam.intrinsics.width / 2 / cam.intrinsics.fx))
    assert (cam.intrinsics.width, cam.intrinsics.height, cam.rate_hz) == (1280, 720, 30.0)
    assert hfov == pytest.approx(90.0, abs=0.1)


def test_route_is_long_closes_and_keeps_clear_of_walls(world: World) -> None:
    drive = simulate_drive(world)
    xy = drive.trajectory.xy_yaw_map_base[:, :2]
    assert drive.plan.length_m >= 300.0
    assert np.linalg.norm(xy[-1] - xy[0]) < 0.5  # back near the start: loop closure possible
    clearance = _distance_to_segments(xy[::10], _segments(world.walls_in_map())).min()
    assert clearance >= 0.3
    assert not _crosses(xy[:-1], xy[1:], _segments(world.walls_in_map())).any()


def test_tags_hang_on_walls_facing_open_space(world: World) -> None:
    walls = _segments(world.walls_in_map())
    points = walls.reshape(-1, 2)
    low, high = points.min(0), points.max(0)  # the outer shell
    for tag in world.tags:
        T_map_tag = world.T_map_tag(tag)
        R = T_map_tag.rotation.as_matrix()
        centre = T_map_tag.translation
        normal = R[:, 2]
        assert normal[2] == pytest.approx(0.0, abs=1e-12)  # face normal horizontal
        np.testing.assert_allclose(R[:, 1], [0.0, 0.0, 1.0], atol=1e-12)  # upright
        # on a wall: centre on a segment, the whole tag edge within it
        d = _distance_to_segments(centre[None, :2], walls)[0]
        host = walls[int(np.argmin(d))]
        assert d.min() < 1e-6, f"tag {tag.id} is not on a wall"
        along = host[2:] - host[:2]
        half = tag.size / 2 / np.linalg.norm(along)
        s = np.dot(centre[:2] - host[:2], along) / np.dot(along, along)
        assert half <= s <= 1 - half, f"tag {tag.id} overhangs its wall"
        host_wall = world.walls_in_map()[int(np.argmin(d))]
        assert tag.size / 2 < centre[2] < host_wall.height - tag.size / 2
        # the 0.5 m ray along the normal crosses no wall
        start = centre[:2] + 0.01 * normal[:2]
        end = centre[:2] + 0.5 * normal[:2]
        assert not _crosses(start[None], end[None], walls).any(), f"tag {tag.id} faces a wall"
        assert np.all((end >= low) & (end <= high)), f"tag {tag.id} faces out of the building"


def test_every_tag_is_seen_from_the_route(world: World) -> None:
    """Each tag fully projects into some camera frame: in front, < 8 m, < 70 deg, unoccluded."""
    drive = simulate_drive(world)
    cam = world.robot.camera
    truth = drive.ground_truth_at(drive.camera_stamps_ns[::3])
    T_map_cam = truth.T_map_base @ cam.T_base_cam.T_base_cam()
    T_cam_map = T_map_cam.inverse()
    cam_xy = T_map_cam.translation[:, :2]
    opaque = _segments(world.walls_in_map(), opaque_only=True)
    K = cam.camera_model().K
    for tag in world.tags:
        T_map_tag = world.T_map_tag(tag)
        h = tag.size / 2
        corners_map = T_map_tag.act(np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]]))
        corners_cam = np.stack([T_cam_map.act(c) for c in corners_map], axis=1)  # (N, 4, 3)
        z = corners_cam[..., 2]
        uv = (corners_cam @ K.T)[..., :2] / np.maximum(z, 1e-9)[..., None]
        inside = (z > 0.1).all(1) & (uv[..., 0] >= 0).all(1) & (uv[..., 0] <= 1279).all(1)
        inside &= (uv[..., 1] >= 0).all(1) & (uv[..., 1] <= 719).all(1)
        to_cam = T_map_cam.translation - T_map_tag.translation
        dist = np.linalg.norm(to_cam, axis=1)
        facing = to_cam @ T_map_tag.rotation.as_matrix()[:, 2] / dist > math.cos(math.radians(70))
        tag_xy = T_map_tag.translation[:2] + 0.01 * T_map_tag.rotation.as_matrix()[:2, 2]
        visible = inside & facing & (dist < 8.0)
        candidates = np.flatnonzero(visible)
        clear = ~_crosses(
            cam_xy[candidates], np.repeat(tag_xy[None], len(candidates), 0), opaque
        ).any(1)
        assert clear.any(), f"tag {tag.id} ({tag.note}) is never in view"


def test_wall_mount_frame_is_documented_convention() -> None:
    tag = Tag.model_validate(
        {"id": 1, "size": 0.2, "wall": {"x": 1.0, "y": 2.0, "yaw_deg": 90, "height": 1.3}}
    )
    T = tag.T_frame_tag()
    # yaw 90: the face looks north (+y); a viewer facing south has +x... on their right = -x map
    np.testing.assert_allclose(
        T.rotation.as_matrix(), [[-1, 0, 0], [0, 0, 1], [0, 1, 0]], atol=1e-12
    )
    np.testing.assert_allclose(T.translation, [1.0, 2.0, 1.3])
    same = Tag.model_validate(
        {
            "id": 1,
            "size": 0.2,
            "pose": {"position": [1.0, 2.0, 1.3], "quat_xyzw": T.as_quat().tolist()},
        }
    )
    assert same.T_frame_tag().allclose(T)


def test_cab_tags_compose_through_the_cab_pose(world: World) -> None:
    assert world.elevator is not None
    tag = world.find_tag(40)
    T_map_tag = world.T_map_tag(tag)
    assert T_map_tag.allclose(world.elevator.T_map_cab() @ tag.T_frame_tag())
    np.testing.assert_allclose(T_map_tag.translation, [39.9, 14.6, 1.2], atol=1e-12)
    np.testing.assert_allclose(T_map_tag.rotation.as_matrix()[:, 2], [-1, 0, 0], atol=1e-12)


def test_camera_mount_rpy_is_body_frame_then_optical(world: World) -> None:
    T_base_cam: SE3 = world.robot.camera.T_base_cam.T_base_cam()
    R = T_base_cam.rotation.as_matrix()
    up5 = math.radians(5.0)
    np.testing.assert_allclose(R[:, 2], [math.cos(up5), 0, math.sin(up5)], atol=1e-12)  # z fwd
    np.testing.assert_allclose(R[:, 0], [0, -1, 0], atol=1e-12)  # x right
    np.testing.assert_allclose(T_base_cam.translation, [0.25, 0.0, 0.5])


def test_yaml_round_trip(world: World) -> None:
    again = World.from_yaml_text(world.to_yaml_text(), source="round-trip")
    assert again == world
