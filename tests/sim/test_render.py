"""The camera image renderer: corners where AprilTag finds them, occlusion, effects, streaming.

Oracles: the AprilTag 3 detector (pupil-apriltags) for corner positions; the tags layer's
independent homography renderer (``render_tags.render_tag``) for pixel geometry; straight-edge
corner predictions for a fisheye (the detector fits straight lines to curved edges); the closed
forms of the noise model; ray-casting geometry worked by hand for occlusion.
"""

from __future__ import annotations

import gc
import itertools
import math
import weakref
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pydantic
import pytest

from tagloc.camera import CameraModel, PinholeRadtan
from tagloc.geometry import SE3, SO3
from tagloc.io import load_kalibr_cameras
from tagloc.sim import World, load_default_world, render_pipeline, simulate_drive
from tagloc.sim.render import (
    RenderConfig,
    render_frames,
    render_tags_scene,
    render_view,
)
from tagloc.sim.world import Tag, Wall, WallMount
from tagloc.tags import make_detector, tag_object_points
from tagloc.tags.bitmaps import render_tag

FloatArray = npt.NDArray[np.float64]
DUPONT = Path("/work/shared/data/dupont/cameras.yaml")
#: Camera body (x forward, y left, z up) -> optical frame (x right, y down, z forward).
R_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
#: Tag frame -> optical frame for a tag facing the camera upright (x right, y up, z to camera).
R_CAM_FACING = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])


@pytest.fixture(scope="module")
def world() -> World:
    return load_default_world()


@pytest.fixture(scope="module")
def pinhole(world: World) -> CameraModel:
    return world.robot.camera.camera_model()  # 1280 x 720, 90 deg horizontal field of view


@pytest.fixture(scope="module")
def fisheye() -> CameraModel:
    if not DUPONT.exists():
        pytest.skip(f"{DUPONT} not available")
    return load_kalibr_cameras(DUPONT)["cam0"]


@pytest.fixture(scope="module")
def vga() -> CameraModel:
    return PinholeRadtan(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5)


def facing_pose(
    dist: float, yaw_deg: float = 0.0, pitch_deg: float = 0.0, roll_deg: float = 0.0,
    ax: float = 0.0, ay: float = 0.0,
) -> SE3:  # fmt: skip
    """``T_cam_tag``: tag ``dist`` m away along direction ``(tan ax, tan ay, 1)``, turned."""
    R = SO3.from_euler("xyz", [pitch_deg, yaw_deg, roll_deg], degrees=True).as_matrix()
    direction = np.array([math.tan(ax), math.tan(ay), 1.0])
    return SE3(
        rotation=SO3.from_matrix(R_CAM_FACING @ R),
        translation=dist * direction / np.linalg.norm(direction),
    )


def map_camera(x: float, y: float, yaw_deg: float, z: float = 1.2) -> SE3:
    """``T_map_cam`` of a level camera at ``(x, y, z)`` looking along ``yaw_deg``."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    R_map_body = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return SE3(
        rotation=SO3.from_matrix(R_map_body @ R_BODY_OPTICAL), translation=np.array([x, y, z])
    )


def corner_errors(camera: CameraModel, tags: list[tuple[int, float, SE3]]) -> FloatArray:
    """Distances (px) between detected and true corners, one row per tag, rendered ideally."""
    image, truths = render_tags_scene(camera, tags, RenderConfig.ideal())
    detected = {d.tag_id: d for d in make_detector("apriltag", quad_decimate=1.0).detect(image)}
    assert {t.tag_id for t in truths} == {t[0] for t in tags}
    assert set(detected) == {t[0] for t in tags}, "a tag was not detected"
    return np.array(
        [np.linalg.norm(detected[t.tag_id].corners_px - t.corners_px, axis=1) for t in truths]
    )


VIEWS = [(0.0, 0.0), (40.0, 0.0), (0.0, -40.0), (30.0, 30.0)]


@pytest.mark.parametrize("dist", [1.0, 2.0, 3.0])
def test_pinhole_corners_agree_with_apriltag(pinhole: CameraModel, dist: float) -> None:
    # Three tags across the image per view (view angles up to about 65 deg). Measured: RMS
    # 0.10 px; max 0.38 px at 3 m on the most oblique view, where the detector shows the same
    # spread on images of the independent homography renderer (render_tag).
    errors = np.vstack(
        [
            corner_errors(
                pinhole,
                [
                    (3 * k + v, 0.16, facing_pose(dist, yaw, pitch, 25 * k + 7, ax, ay))
                    for k, (ax, ay) in enumerate([(-0.5, -0.25), (0.0, 0.0), (0.5, 0.25)])
                ],
            )
            for v, (yaw, pitch) in enumerate(VIEWS)
        ]
    )
    assert errors.max() < 0.4  # the detector's own spread on the most oblique views
    assert np.sqrt(np.mean(errors**2)) < 0.15


@pytest.mark.parametrize("dist", [1.0, 2.0, 3.0])
def test_fisheye_corners_agree_with_apriltag_near_the_axis(
    fisheye: CameraModel, dist: float
) -> None:
    # Near the axis the edges are straight enough for the detector's line fits; measured max
    # 0.25 px (see the next test for the rest of the image).
    errors = np.vstack(
        [
            corner_errors(fisheye, [(v, 0.16, facing_pose(dist, yaw, pitch, 10 * v + 7))])
            for v, (yaw, pitch) in enumerate(VIEWS)
        ]
    )
    assert errors.max() < 0.3


def straight_edge_corners(camera: CameraModel, T_cam_tag: SE3, size: float) -> FloatArray:
    """Corners a straight-line edge fit finds: intersections of lines fitted to projected edges."""
    points = tag_object_points(size)
    lines = []
    for i in range(4):
        s = np.linspace(0.0, 1.0, 200)[:, None]
        edge = camera.project(T_cam_tag.act(points[i] * (1 - s) + points[(i + 1) % 4] * s))
        center = edge.mean(axis=0)
        direction = np.linalg.svd(edge - center)[2][0]
        normal = np.array([-direction[1], direction[0]])
        lines.append(np.array([*normal, -normal @ center]))
    corners = [np.cross(lines[i - 1], lines[i]) for i in range(4)]
    return np.array([c[:2] / c[2] for c in corners])


def test_fisheye_off_axis_matches_straight_edge_fits(fisheye: CameraModel) -> None:
    # Off the axis the detector's straight-line model departs from the true corners by up to
    # ~1 px at 1 m (measured); the image is right if detections match straight-edge fits of the
    # truly projected (curved) edges.
    worst_truth, worst_fit = 0.0, 0.0
    for k, (ax, ay) in enumerate([(0.6, 0.0), (-0.5, 0.4), (0.0, -0.6), (0.8, 0.3)]):
        T_cam_tag = facing_pose(1.0, 20.0, -10.0, 30.0 * k, ax, ay)
        image, truths = render_tags_scene(fisheye, [(k, 0.16, T_cam_tag)], RenderConfig.ideal())
        (det,) = make_detector("apriltag", quad_decimate=1.0).detect(image)
        fit = straight_edge_corners(fisheye, T_cam_tag, 0.16)
        worst_truth = max(
            worst_truth, np.linalg.norm(det.corners_px - truths[0].corners_px, axis=1).max()
        )
        worst_fit = max(worst_fit, np.linalg.norm(det.corners_px - fit, axis=1).max())
    assert worst_fit < 0.3
    assert worst_truth > worst_fit  # the departure is real: this test can tell them apart


@pytest.mark.parametrize("yaw", [0.0, 50.0])
def test_pinhole_pixels_match_the_homography_renderer(vga: CameraModel, yaw: float) -> None:
    # tagloc.tags.bitmaps.render_tag warps the bitmap by the homography of the true corners,
    # area-sampled at 8 x 8: an independent renderer. Dark-area centroids agree to 1e-3 px.
    config = RenderConfig.ideal(supersample=4, tag_black=0.0, tag_white=1.0)
    image, (truth,) = render_tags_scene(vga, [(5, 0.16, facing_pose(1.2, yaw, 20.0, 17.0))], config)
    reference = render_tag(
        np.full((480, 640), 128, np.uint8), "tag36h11", 5, truth.corners_px, 1, 8
    )
    dark, dark_ref = 255.0 - image, 255.0 - reference.astype(float)
    v, u = np.mgrid[0:480, 0:640]
    centroid = np.array([(dark * u).sum(), (dark * v).sum()]) / dark.sum()
    centroid_ref = np.array([(dark_ref * u).sum(), (dark_ref * v).sum()]) / dark_ref.sum()
    assert np.abs(centroid - centroid_ref).max() < 0.005
    assert abs(dark.sum() / dark_ref.sum() - 1.0) < 1e-3
    assert np.abs(image.astype(float) - reference).max() < 40  # 4x4 vs 8x8 edge samples


def test_truth_geometry(vga: CameraModel) -> None:
    T_cam_tag = facing_pose(2.0, yaw_deg=30.0)
    _, (truth,) = render_tags_scene(vga, [(7, 0.2, T_cam_tag)], RenderConfig.ideal())
    assert truth.tag_id == 7 and truth.size == 0.2 and truth.family == "tag36h11"
    assert truth.range_m == pytest.approx(2.0)
    assert math.degrees(truth.view_angle_rad) == pytest.approx(30.0)
    assert truth.fraction_visible == pytest.approx(1.0, abs=1e-3)
    np.testing.assert_allclose(truth.corners_px, vga.project(T_cam_tag.act(tag_object_points(0.2))))
    # Centered on the image's right border (u = 639.5), parallel to the image: half visible.
    on_border = SE3(rotation=SO3.from_matrix(R_CAM_FACING), translation=np.array([1.28, 0.0, 2.0]))
    _, (half,) = render_tags_scene(vga, [(7, 0.2, on_border)], RenderConfig.ideal())
    assert half.fraction_visible == pytest.approx(0.5, abs=0.01)


def small_world(world: World, walls: list[Wall], tags: list[Tag]) -> World:
    """The default world's robot and route with other walls and tags and no elevator."""
    return world.model_copy(update={"walls": tuple(walls), "tags": tuple(tags), "elevator": None})


def wall_tag(tag_id: int, x: float, y: float) -> Tag:
    return Tag(id=tag_id, size=0.16, wall=WallMount(x=x, y=y, yaw_deg=180.0, height=1.2))


def test_a_wall_hides_a_tag(world: World, pinhole: CameraModel) -> None:
    # Camera at the origin looking +x; tags on the wall x = 2.5 at y = +-0.3 (0 = left in view);
    # a wall at x = 1.5 over y in [-1, 0] hides tag 2, a wall from y = 0.6 hides half of tag 3.
    back = Wall(start=(2.5, -3.0), end=(2.5, 3.0))
    blocker = Wall(start=(1.5, -1.0), end=(1.5, 0.0))
    half = Wall(start=(1.5, 0.6 * 1.5 / 2.5 + 0.0), end=(1.5, 3.0))
    tags = [wall_tag(1, 2.5, 0.3), wall_tag(2, 2.5, -0.3), wall_tag(3, 2.5, 0.6)]
    scene = small_world(world, [back, blocker, half], tags)
    image, truths = render_view(scene, pinhole, map_camera(0.0, 0.0, 0.0), RenderConfig.ideal())
    fraction = {t.tag_id: t.fraction_visible for t in truths}
    assert fraction[1] == pytest.approx(1.0, abs=1e-3)
    assert fraction[2] == 0.0
    assert fraction[3] == pytest.approx(0.5, abs=0.03)
    detected = {d.tag_id for d in make_detector("apriltag").detect(image)}
    assert detected == {1}


def test_elevator_tags_show_only_through_the_door(world: World, pinhole: CameraModel) -> None:
    # Tag 40 hangs on the cab's back wall (map x 39.9, y 14.6), facing the door (west). From the
    # lobby on the door's axis it is seen through the landing door; from 3 m further south the
    # line of sight crosses the shaft's front wall (x = 37.5, y 12.5-14.5). Cab walls are mirrors.
    config = RenderConfig.ideal()
    detector = make_detector("apriltag", quad_decimate=1.0)
    T_through = map_camera(36.5, 14.8, 0.0)
    image, truths = render_view(world, pinhole, T_through, config)
    assert {t.tag_id: t.fraction_visible for t in truths}[40] == pytest.approx(1.0, abs=1e-3)
    assert 40 in {d.tag_id for d in detector.detect(image)}
    yaw = math.degrees(math.atan2(14.6 - 12.0, 39.9 - 35.0))
    image, truths = render_view(world, pinhole, map_camera(35.0, 12.0, yaw), config)
    assert {t.tag_id: t.fraction_visible for t in truths}[40] == 0.0
    assert 40 not in {d.tag_id for d in detector.detect(image)}


def test_glass_is_seen_through_with_a_tint(world: World, pinhole: CameraModel) -> None:
    tags = [wall_tag(1, 2.5, 0.0)]
    back = Wall(start=(2.5, -3.0), end=(2.5, 3.0))
    pane = Wall(start=(1.5, -1.0), end=(1.5, 1.0), material="glass")
    config = RenderConfig.ideal()
    clear, _ = render_view(small_world(world, [back], tags), pinhole, map_camera(0, 0, 0), config)
    behind, truths = render_view(
        small_world(world, [back, pane], tags), pinhole, map_camera(0, 0, 0), config
    )
    assert truths[0].fraction_visible == pytest.approx(1.0, abs=1e-3)
    (det,) = make_detector("apriltag").detect(behind)
    assert det.tag_id == 1
    assert np.linalg.norm(det.corners_px - truths[0].corners_px, axis=1).max() < 0.3
    window = (slice(340, 380), slice(620, 660))  # inside the tag
    contrast = clear[window].astype(float).std(), behind[window].astype(float).std()
    assert 0.8 * contrast[0] < contrast[1] < 0.9 * contrast[0]  # transmittance 0.85


@pytest.mark.parametrize("camera_name", ["pinhole", "fisheye"])
def test_image_matches_the_camera(
    world: World, camera_name: str, request: pytest.FixtureRequest
) -> None:
    camera: CameraModel = request.getfixturevalue(camera_name)
    image, truths = render_view(world, camera, map_camera(35.0, 10.25, 90.0, z=0.5))
    assert image.dtype == np.uint8 and image.shape == (camera.height, camera.width)
    assert image.std() > 5  # walls, floor and ceiling, not a blank
    assert all(t.corners_px.shape == (4, 2) for t in truths)


def edge_width(image: npt.NDArray[np.uint8], row: int, columns: slice) -> float:
    """10-90 % width (px) of the one falling edge in ``image[row, columns]``."""
    profile = image[row - 2 : row + 3, columns].astype(float).mean(axis=0)
    high, low = profile[:3].mean(), profile[-3:].mean()
    level = (profile - low) / (high - low)
    return float(np.interp(0.1, level[::-1], np.arange(len(level))[::-1])
                 - np.interp(0.9, level[::-1], np.arange(len(level))[::-1]))  # fmt: skip


@pytest.mark.parametrize("method", ["directional", "subframes"])
def test_blur_grows_with_speed(vga: CameraModel, method: str) -> None:
    # A 0.5 m tag 1.5 m ahead, camera moving sideways: the flow is f v e / z = 500 v 0.02 / 1.5
    # px. Its left black edge is at u = 319.5 - 500 * 0.25 / 1.5 = 236.2, with a 20.8 px white
    # quiet zone to its left (backdrop as white as the paper) and 20.8 px of black to its right.
    config = RenderConfig.ideal(exposure_s=0.02, motion_blur=method, subframes=32)
    widths = []
    for speed in (0.0, 0.5, 1.0, 2.0):
        twist = [speed, 0.0, 0.0, 0.0, 0.0, 0.0]
        image, _ = render_tags_scene(
            vga, [(0, 0.5, facing_pose(1.5))], config, background=0.85, twist_cam=twist
        )
        widths.append(edge_width(image, 240, slice(220, 249)))
    flows = [500 * v * 0.02 / 1.5 for v in (0.0, 0.5, 1.0, 2.0)]
    assert widths[0] < 2.0  # a sharp edge, as measured on whole pixels (1.57 px)
    assert np.all(np.diff(widths) > 1.0)
    for width, flow in zip(widths[1:], flows[1:], strict=True):
        assert abs(width - 0.8 * flow) < 0.8  # 10-90 % of a uniform ramp: 0.8 of its length


def test_directional_blur_approximates_subframes(vga: CameraModel) -> None:
    tags = [(0, 0.16, facing_pose(1.5, 20.0, 10.0, 5.0, 0.2, 0.1))]
    twist = [0.6, 0.1, 0.3, 0.0, 0.4, 0.1]
    images = [
        render_tags_scene(vga, tags, RenderConfig.ideal(exposure_s=0.02, motion_blur=m,
                                                        subframes=48),
                          background=0.4, twist_cam=twist)[0]
        for m in ("directional", "subframes")
    ]  # fmt: skip
    difference = np.abs(images[0].astype(float) - images[1])
    assert difference.mean() < 0.5 and np.percentile(difference, 99.9) < 20


def test_defocus_widens_edges(vga: CameraModel) -> None:
    # A Gaussian of sigma s turns a step into a ramp whose 10-90 % width is 2.563 s.
    widths = []
    for sigma in (0.0, 1.5, 3.0):
        config = RenderConfig.ideal(defocus_sigma_px=sigma)
        image, _ = render_tags_scene(vga, [(0, 0.5, facing_pose(1.5))], config, background=0.85)
        widths.append(edge_width(image, 240, slice(220, 249)))
    assert widths[0] < 2.0
    assert widths[1] == pytest.approx(2.563 * 1.5, abs=0.5)
    assert widths[2] == pytest.approx(2.563 * 3.0, abs=0.5)


@pytest.mark.parametrize(("albedo", "read", "e_per_dn"), [(0.4, 2.0, 4.0), (0.02, 1.0, 4.0)])
def test_noise_statistics_match_the_config(
    vga: CameraModel, albedo: float, read: float, e_per_dn: float
) -> None:
    # Signal S = 255 albedo DN; variance S / e_per_dn + read^2, plus 1/12 from rounding. The second
    # case (20 electrons) takes the exact Poisson path.
    config = RenderConfig.ideal(read_noise_dn=read, electrons_per_dn=e_per_dn)
    image, _ = render_tags_scene(vga, [], config, np.random.default_rng(3), background=albedo)
    signal = 255.0 * albedo
    expected_std = math.sqrt(signal / e_per_dn + read**2 + 1.0 / 12.0)
    assert image.mean() == pytest.approx(signal, abs=0.05)
    assert image.std() == pytest.approx(expected_std, rel=0.02)


def test_gain_and_vignetting(vga: CameraModel) -> None:
    config = RenderConfig.ideal(gain=0.8, vignetting=0.3)
    image, _ = render_tags_scene(vga, [], config, background=0.5)
    # shading 1 - 0.3 rho^2, rho = distance to (319.5, 239.5) over that of the corner (-0.5, -0.5)
    rho2 = (319.5**2 + 239.5**2) / (320.0**2 + 240.0**2)
    assert image[240, 320] == pytest.approx(0.8 * 0.5 * 255 * (1 - 0.3 * 0.5**2 / 400**2), abs=0.51)
    assert image[0, 0] == pytest.approx(0.8 * 0.5 * 255 * (1 - 0.3 * rho2), abs=0.51)


def test_seeded_reproducibility(world: World, pinhole: CameraModel) -> None:
    T = map_camera(3.0, 10.25, 0.0, z=0.5)
    config = RenderConfig()
    a, _ = render_view(world, pinhole, T, config, np.random.default_rng(7))
    b, _ = render_view(world, pinhole, T, config, np.random.default_rng(7))
    c, _ = render_view(world, pinhole, T, config, np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert np.abs(a.astype(int) - c).mean() > 0.5
    ideal = [render_view(world, pinhole, T, RenderConfig.ideal(), np.random.default_rng(s))[0]
             for s in (7, 8)]  # fmt: skip
    np.testing.assert_array_equal(ideal[0], ideal[1])  # only the noise depends on the seed


def test_frames_stream_lazily(world: World, monkeypatch: pytest.MonkeyPatch) -> None:
    drive = simulate_drive(world, seed=1)
    camera = PinholeRadtan(width=320, height=180, fx=160.0, fy=160.0, cx=159.5, cy=89.5)
    calls = []
    original = render_pipeline.render_image

    def counting(*args: object, **kwargs: object) -> object:
        calls.append(1)
        return original(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr("tagloc.sim.render.render_image", counting)
    frames = render_frames(drive, camera, RenderConfig(), seed=5)
    assert isinstance(frames, Iterator) and not calls
    first = next(frames)
    image_ref = weakref.ref(first.image)
    assert first.stamp_ns == drive.camera_stamps_ns[0] and first.image.shape == (180, 320)
    del first
    rest = list(itertools.islice(frames, 3))
    gc.collect()
    assert len(calls) == 4 < len(drive.camera_stamps_ns)  # one render per frame taken
    assert image_ref() is None  # the stream keeps no frame it yielded
    assert [f.stamp_ns for f in rest] == drive.camera_stamps_ns[1:4].tolist()
    # The same seed gives the same frames, another seed other noise.
    again = list(itertools.islice(render_frames(drive, camera, RenderConfig(), seed=5), 4))[1:]
    other = list(itertools.islice(render_frames(drive, camera, RenderConfig(), seed=6), 4))[1:]
    assert all(np.array_equal(a.image, b.image) for a, b in zip(rest, again, strict=True))
    assert not any(np.array_equal(a.image, b.image) for a, b in zip(rest, other, strict=True))


def test_frames_carry_the_true_pose_and_twist(world: World) -> None:
    drive = simulate_drive(world, seed=1)
    camera = PinholeRadtan(width=320, height=180, fx=160.0, fy=160.0, cx=159.5, cy=89.5)
    stamp = drive.camera_stamps_ns[600]
    (frame,) = render_frames(drive, camera, RenderConfig.ideal(), stamps_ns=[stamp])
    truth = drive.ground_truth_at(np.array([stamp]))
    T_base_cam = world.robot.camera.T_base_cam.T_base_cam()
    assert frame.T_map_cam.allclose(truth.T_map_base[0] @ T_base_cam)
    # The camera's velocity in map from the twist equals the finite difference of its position.
    dt = 1_000_000
    ahead = drive.ground_truth_at(np.array([stamp + dt])).T_map_base[0] @ T_base_cam
    velocity_map = (ahead.translation - frame.T_map_cam.translation) / 1e-3
    np.testing.assert_allclose(
        frame.T_map_cam.rotation.as_matrix() @ frame.twist_cam[:3], velocity_map, atol=2e-3
    )


def test_config_rejects_unknown_and_bad_fields() -> None:
    with pytest.raises(pydantic.ValidationError):
        RenderConfig(supersampling=2)  # type: ignore[call-arg]
    with pytest.raises(pydantic.ValidationError):
        RenderConfig(supersample=0)
    assert RenderConfig().supersample == 2 and RenderConfig.ideal().exposure_s == 0.0
