"""Detection in regions: crops aligned to the detector's grid give the full frame's corners."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.camera import PinholeRadtan
from tagloc.geometry import SE3, SO3
from tagloc.sim import RenderConfig, render_tags_scene
from tagloc.tags import make_detector
from tagloc.tags.regions import (
    PixelRegion,
    detect_in_regions,
    grid_px,
    merge_regions,
    region_around,
)

W, H = 1280, 720
CAMERA = PinholeRadtan(width=W, height=H, fx=W / 2, fy=W / 2, cx=(W - 1) / 2, cy=(H - 1) / 2)


def _frame(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tags = []
    for i in range(4):
        x = (-0.6 + 0.4 * i) + rng.uniform(-0.05, 0.05)
        T_cam_tag = SE3(
            rotation=SO3.from_rotvec([np.pi, rng.uniform(-0.5, 0.5), 0.0]),
            translation=np.array([x, rng.uniform(-0.2, 0.2), rng.uniform(1.2, 2.5)]),
        )
        tags.append((int(rng.integers(587)), 0.16, T_cam_tag))
    image, _ = render_tags_scene(CAMERA, tags, RenderConfig(), rng)
    return image


@pytest.mark.parametrize("decimate", [1.0, 2.0])
def test_crop_corners_equal_full_frame(decimate: float) -> None:
    # oracle: the same detector on the full frame; AprilTag fits quads in float32, so "equal"
    # is 4 float32 ulps at u < 2048 px (4.9e-4 px); a quad fit whose cluster points are
    # visited in another order may move a corner by a few hundredths of a pixel
    detector = make_detector("apriltag", "tag36h11", quad_decimate=decimate)
    errors = []
    for seed in range(3):
        image = _frame(seed)
        for full in detector.detect(image):
            c = full.corners_px
            m = max(16.0, 0.5 * float(np.linalg.norm(c[0] - c[1])))
            region = region_around(*(c.min(0) - m), *(c.max(0) + m), W, H, decimate)
            assert region is not None and region.u0 % grid_px(decimate) == 0
            found = detect_in_regions(detector, image, [region])
            got = [d for d in found if d.tag_id == full.tag_id]
            assert got, f"tag {full.tag_id} lost in its region"
            errors.append(float(np.abs(got[0].corners_px - c).max()))
    assert len(errors) >= 8
    assert max(errors) < 0.1
    assert np.mean(np.array(errors) < 4.9e-4) >= 0.85


def test_merge_leaves_no_overlap() -> None:
    rng = np.random.default_rng(3)
    regions = []
    for _ in range(20):
        u, v = rng.uniform(0, W - 100), rng.uniform(0, H - 100)
        r = region_around(u, v, u + rng.uniform(20, 200), v + rng.uniform(20, 200), W, H, 2.0)
        assert r is not None
        regions.append(r)
    merged = merge_regions(regions, W, H)
    for i, a in enumerate(merged):
        assert a.u1 <= W and a.v1 <= H
        for b in merged[i + 1 :]:
            assert not a.overlaps(b)
    for r in regions:  # every input pixel box is inside a merged one
        assert any(m.u0 <= r.u0 and m.v0 <= r.v0 and m.u1 >= r.u1 and m.v1 >= r.v1 for m in merged)


def test_region_outside_image_is_none() -> None:
    assert region_around(-50.0, -50.0, -10.0, -10.0, W, H, 2.0) is None
    assert isinstance(region_around(10.0, 10.0, 50.0, 50.0, W, H, 2.0), PixelRegion)
