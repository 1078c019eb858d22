"""Where mapped tags should appear: the predicted corners against OpenCV's projection of the
simulator's true pose, their sigma against Monte-Carlo samples of the pose covariance."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tagloc.geometry import SE3
from tagloc.localize.config_roi import RegionConfig
from tagloc.localize.roi import mapped_tags, predict_tags
from tagloc.sim.scenarios import ScenarioSource, build_scenario

#: No floors on the pose's sigma: the test's covariance is the whole uncertainty.
NO_FLOOR = RegionConfig(min_translation_sigma_m=0.0, min_rotation_sigma_rad=0.0)


@pytest.fixture(scope="module")
def view():  # type: ignore[no-untyped-def]
    """The drive's first frame with a tag in view: camera, extrinsics, true pose, tags."""
    scenario = build_scenario("default", 0, 10.0)
    source = ScenarioSource(scenario)
    frame = next(f for f in source.frames if f.truth)
    T_map_base = scenario.drive.ground_truth_at(np.array([frame.stamp_ns])).T_map_base[0]
    tags = mapped_tags(scenario.tag_map, "tag36h11", "map")
    return source.camera, source.T_base_cam, T_map_base, tags, {s.tag_id for s in frame.truth}


def _opencv(camera, T_cam_map: SE3, corners_map: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    rvec = T_cam_map.rotation.as_rotvec().reshape(3, 1)
    tvec = T_cam_map.translation.reshape(3, 1)
    px, _ = cv2.projectPoints(corners_map, rvec, tvec, camera.K, camera.dist_coeffs)
    return px.reshape(-1, 2)


def test_corners_at_the_true_pose_are_opencvs(view) -> None:  # type: ignore[no-untyped-def]
    camera, T_base_cam, T_map_base, tags, in_view = view
    tiny = np.eye(6) * 1e-12
    predicted = predict_tags(camera, T_map_base, tiny, T_base_cam, tags, NO_FLOOR)
    assert in_view <= {p.tag_id for p in predicted}  # every tag truly in view is predicted
    T_cam_map = (T_map_base @ T_base_cam).inverse()
    by_id = {t.tag_id: t for t in tags}
    for p in predicted:
        expected = _opencv(camera, T_cam_map, by_id[p.tag_id].corners_map)
        np.testing.assert_allclose(p.corners_px, expected, atol=1e-6)
        assert np.all(p.sigma_px < 1e-2)  # a 1e-6 m / rad pose sigma: ~1e-3 px


def test_corner_sigma_matches_monte_carlo_samples_of_the_pose(view) -> None:  # type: ignore[no-untyped-def]
    camera, T_base_cam, T_map_base, tags, _ = view
    sig = np.array([0.02, 0.02, 0.01, 0.004, 0.004, 0.01])  # m, rad: small enough to stay linear
    cov = np.diag(sig**2)
    predicted = predict_tags(camera, T_map_base, cov, T_base_cam, tags, NO_FLOOR)
    assert predicted
    rng = np.random.default_rng(3)
    deltas = rng.normal(size=(4000, 6)) * sig
    by_id = {t.tag_id: t for t in tags}
    for p in predicted[:3]:
        corners = by_id[p.tag_id].corners_map
        samples = np.stack(
            [_opencv(camera, (T_map_base.plus(d) @ T_base_cam).inverse(), corners) for d in deltas]
        )
        spread = samples.std(axis=0)  # (4, 2) px
        # 4000 samples: the standard deviation is known to about 1.1 %; 10 % for the linearization
        np.testing.assert_allclose(p.sigma_px, spread, rtol=0.10)
