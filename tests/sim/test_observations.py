"""simulate_observations: corners against OpenCV, occlusion, limits, noise, seeding, glints."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tagloc.sim import (
    Drive,
    ObservationConfig,
    ObservedFrame,
    World,
    load_default_world,
    simulate_drive,
    simulate_observations,
)
from tagloc.sim.world import Wall
from tagloc.tags import tag_object_points

#: The first 60 s of the default route (1800 camera frames at 30 Hz).
SPAN_NS = 60 * 10**9


@pytest.fixture(scope="module")
def world() -> World:
    return load_default_world()


@pytest.fixture(scope="module")
def drive(world: World) -> Drive:
    return simulate_drive(world, seed=0)


def _frames(
    drive: Drive, config: ObservationConfig, world: World | None = None
) -> list[ObservedFrame]:
    stamps = drive.camera_stamps_ns[drive.camera_stamps_ns < SPAN_NS]
    return list(simulate_observations(drive, config, stamps_ns=stamps, world=world))


@pytest.fixture(scope="module")
def clean(drive: Drive) -> list[ObservedFrame]:
    return _frames(drive, ObservationConfig(pixel_sigma_px=0.0))


def test_true_corners_match_opencv_projection_of_the_true_pose(
    clean: list[ObservedFrame], world: World
) -> None:
    K = world.robot.camera.camera_model().K
    sightings = [s for f in clean for s in f.truth]
    assert len(sightings) > 100
    for s in sightings[::7]:
        T_cam_tag = s.T_cam_tag
        rvec = T_cam_tag.rotation.as_rotvec()
        expected, _ = cv2.projectPoints(
            tag_object_points(s.size), rvec, np.asarray(T_cam_tag.translation), K, None
        )
        np.testing.assert_allclose(s.corners_px, expected.reshape(4, 2), atol=1e-6)
    for f in clean:
        for det, truth in zip(f.detections, f.truth, strict=True):
            np.testing.assert_allclose(det.corners_px, truth.corners_px, atol=1e-9)


def test_sightings_respect_range_angle_and_image_limits(clean: list[ObservedFrame]) -> None:
    config = ObservationConfig()
    for f in clean:
        for s in f.truth:
            assert s.range_m <= config.max_range_m
            assert s.view_angle_rad <= math.radians(config.max_view_angle_deg) + 1e-9
            # Image area [-0.5, W - 0.5] x [-0.5, H - 0.5] (OpenCV pixel centers at integers).
            assert np.all(s.corners_px >= config.margin_px - 0.5)
            assert np.all(s.corners_px[:, 0] <= 1280 - 0.5 - config.margin_px)
            assert np.all(s.corners_px[:, 1] <= 720 - 0.5 - config.margin_px)
            assert np.min(np.linalg.norm(s.corners_px - np.roll(s.corners_px, 1, 0), axis=1)) >= 10
            # The true pose agrees with the frame's camera pose and the world's tag pose.
            assert s.T_cam_tag.translation[2] > 0


def test_a_wall_in_front_of_a_tag_hides_it(
    drive: Drive, world: World, clean: list[ObservedFrame]
) -> None:
    frame = next(f for f in clean if f.truth)
    sighting = frame.truth[0]
    tag = world.find_tag(sighting.tag_id, sighting.family)
    T_map_tag = world.T_map_tag(tag)
    cam = np.asarray(frame.T_map_cam.translation[:2])
    mid = 0.5 * (cam + np.asarray(T_map_tag.translation[:2]))
    across = np.array([-(mid - cam)[1], (mid - cam)[0]])
    across = across / np.linalg.norm(across)
    wall = Wall(start=tuple(mid - 2.0 * across), end=tuple(mid + 2.0 * across))
    blocked = world.model_copy(update={"walls": (*world.walls, wall)})
    glass = world.model_copy(
        update={"walls": (*world.walls, wall.model_copy(update={"material": "glass"}))}
    )
    config = ObservationConfig(pixel_sigma_px=0.0)
    stamps = np.array([frame.stamp_ns])
    (hidden,) = simulate_observations(drive, config, stamps_ns=stamps, world=blocked)
    (seen,) = simulate_observations(drive, config, stamps_ns=stamps, world=glass)
    assert sighting.tag_id not in [s.tag_id for s in hidden.truth]
    assert sighting.tag_id in [s.tag_id for s in seen.truth]


def test_corner_noise_has_the_configured_sigma(drive: Drive, clean: list[ObservedFrame]) -> None:
    noisy = _frames(drive, ObservationConfig(pixel_sigma_px=0.5, seed=3))
    residuals = [
        det.corners_px - truth.corners_px
        for f in noisy
        for det, truth in zip(f.detections, f.truth, strict=True)
    ]
    r = np.concatenate(residuals).ravel()
    assert len(r) > 1000
    # Sample std of n normal draws: relative standard error 1/sqrt(2n) (< 2 % here).
    assert abs(np.std(r) - 0.5) < 0.05
    assert abs(np.mean(r)) < 0.05


def test_same_seed_same_frames_and_frames_independent_of_the_subset(drive: Drive) -> None:
    config = ObservationConfig(seed=7, glint_rate=0.2)
    a = _frames(drive, config)
    b = _frames(drive, config)
    with_tags = [f for f in a if f.detections]
    assert with_tags
    for fa, fb in zip(a, b, strict=True):
        assert [d.tag_id for d in fa.detections] == [d.tag_id for d in fb.detections]
        for da, db in zip(fa.detections, fb.detections, strict=True):
            np.testing.assert_array_equal(da.corners_px, db.corners_px)
    pick = with_tags[len(with_tags) // 2]
    (alone,) = simulate_observations(drive, config, stamps_ns=np.array([pick.stamp_ns]))
    np.testing.assert_array_equal(alone.detections[0].corners_px, pick.detections[0].corners_px)
    other = _frames(drive, config.model_copy(update={"seed": 8}))
    assert any(
        not np.array_equal(fa.detections[0].corners_px, fo.detections[0].corners_px)
        for fa, fo in zip(a, other, strict=True)
        if fa.detections and fo.detections
    )


def test_glints_are_flagged_poisson_counted_and_decode_as_world_ids(
    drive: Drive, world: World
) -> None:
    rate = 0.5
    frames = _frames(drive, ObservationConfig(glint_rate=rate, seed=1))
    n_glints = sum(sum(f.false_detection) for f in frames)
    expected = rate * len(frames)
    assert abs(n_glints - expected) < 5 * math.sqrt(expected)
    world_ids = {tag.id for tag in world.tags}
    for f in frames:
        assert len(f.false_detection) == len(f.detections)
        true_ids = {s.tag_id for s in f.truth}
        for det, false in zip(f.detections, f.false_detection, strict=True):
            assert det.tag_id in world_ids
            if not false:
                assert det.tag_id in true_ids


def test_missed_detections_follow_the_detection_probability(drive: Drive) -> None:
    frames = _frames(drive, ObservationConfig(detection_probability=0.7, seed=2))
    sightings = [s for f in frames for s in f.truth]
    detected = np.mean([s.detected for s in sightings])
    n = len(sightings)
    assert abs(detected - 0.7) < 5 * math.sqrt(0.21 / n)
    assert sum(len(f.detections) for f in frames) == sum(s.detected for s in sightings)
