"""Ray casting of the simulated lidar against hand-computed geometry (no simulator code in the
oracles): distances in a box room, hits on walls, glass, mirrors (phantoms), people, the 2D case.

Tolerances: noise-free distances 1e-9 m (float64 arithmetic on metre-scale numbers).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from tagloc.geometry import SE3
from tagloc.sim.lidar import LidarSimulator
from tagloc.sim.lidar_cast import (
    HIT_FLOOR,
    HIT_GLASS,
    HIT_NONE,
    HIT_PERSON,
    HIT_WALL,
    Cylinders,
    Segments,
    cast_rays,
)
from tagloc.sim.robot import LidarConfig
from tagloc.sim.world import Wall

TOL = 1e-9


def box(w: float = 10.0, h: float = 6.0, height: float = 2.5, **materials: str) -> list[Wall]:
    """Walls of the room [0, w] x [0, h]; ``materials`` by side: south, east, north, west."""
    corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)]
    sides = ["south", "east", "north", "west"]
    return [
        Wall(start=corners[i], end=corners[(i + 1) % 4], height=height,
             material=materials.get(sides[i], "wall"))  # type: ignore[arg-type]
        for i in range(4)
    ]  # fmt: skip


def unit(v: list[float]) -> np.ndarray:
    a = np.array(v, dtype=np.float64)
    return a / np.linalg.norm(a)


def test_distances_in_a_box_room_are_the_hand_computed_ones() -> None:
    seg = Segments.from_walls(box())
    o = np.array([3.0, 2.0, 0.5])
    e = math.radians(10.0)
    rays = [
        ([1, 0, 0], 7.0, HIT_WALL),
        ([-1, 0, 0], 3.0, HIT_WALL),
        ([0, 1, 0], 4.0, HIT_WALL),
        ([0, -1, 0], 2.0, HIT_WALL),
        ([1, 1, 0], 4.0 * math.sqrt(2), HIT_WALL),  # reaches y = 6 at x = 7 first
        ([math.cos(e), 0, math.sin(e)], 7.0 / math.cos(e), HIT_WALL),  # z = 1.73 < 2.5
        ([0, math.cos(1.2), math.sin(1.2)], math.inf, HIT_NONE),  # over the 2.5 m wall (no ceiling)
        ([1, 0, -0.2], 0.5 / math.sin(math.atan(0.2)), HIT_FLOOR),  # floor at 2.55 m < 7 m
    ]
    d = np.array([unit(r) for r, _, _ in rays])
    for group in (0, 1):  # the general and the level path agree with the oracle
        res = cast_rays(np.tile(o, (len(d), 1)), d, seg, 40.0, level_group=group)
        expected = np.array([r for _, r, _ in rays])
        finite = np.isfinite(expected)
        np.testing.assert_allclose(res.range_m[finite], expected[finite], atol=TOL, rtol=0)
        assert np.isinf(res.range_m[~finite]).all()
        assert res.kind.tolist() == [k for _, _, k in rays]
        np.testing.assert_allclose(
            res.hit_map[finite], o + expected[finite, None] * d[finite], atol=TOL
        )


def test_a_wall_return_lies_on_its_wall_and_range_is_respected() -> None:
    rng = np.random.default_rng(0)
    walls = [
        Wall(start=tuple(a), end=tuple(a + rng.normal(size=2) * 4), height=float(rng.uniform(1, 3)))  # type: ignore[arg-type]
        for a in rng.uniform(-10, 10, (12, 2))
    ]
    seg = Segments.from_walls(walls)
    n = 4000
    o = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(0.2, 1.5, n)])
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    res = cast_rays(o, d, seg, 12.0)
    on_wall = res.kind == HIT_WALL
    assert on_wall.sum() > 300 and (res.range_m[np.isfinite(res.range_m)] <= 12.0).all()
    p = res.hit_map[on_wall]
    # oracle: distance of each hit to the nearest wall segment (2D), and within its height
    a, b = seg.start, seg.end
    ab = b - a
    s = np.clip(np.einsum("pwk,wk->pw", p[:, None, :2] - a, ab) / (ab**2).sum(1), 0, 1)
    dist = np.linalg.norm(p[:, None, :2] - (a + s[..., None] * ab), axis=2)
    nearest = dist.argmin(axis=1)
    assert dist.min(axis=1).max() < 1e-9
    assert (p[:, 2] >= -TOL).all() and (p[:, 2] <= seg.height[nearest] + TOL).all()
    # and no wall lies between the origin and the hit: a brute-force check with a finer ray march
    for i in np.flatnonzero(on_wall)[:50]:
        ts = np.linspace(0.0, res.range_m[i] - 1e-3, 400)
        pts = o[i] + ts[:, None] * d[i]
        rel = pts[:, None, :2] - a[None]
        sign = np.sign(ab[None, :, 0] * rel[..., 1] - ab[None, :, 1] * rel[..., 0])  # wall side
        crossed = (np.diff(sign, axis=0) != 0).any(axis=0)
        for w in np.flatnonzero(crossed):
            k = np.flatnonzero(np.diff(sign[:, w]) != 0)[0]
            q = pts[k]
            u = np.dot(q[:2] - a[w], ab[w]) / np.dot(ab[w], ab[w])
            assert not (0 <= u <= 1 and 0 <= q[2] <= seg.height[w]), "a nearer wall was skipped"


def test_glass_lets_the_beam_through_or_gives_a_weak_return() -> None:
    # the east side is glass; a wall 5 m behind it; and a second room with nothing behind
    walls = [*box(east="glass"), Wall(start=(15.0, -5.0), end=(15.0, 10.0))]
    seg = Segments.from_walls(walls)
    o = np.array([[3.0, 2.0, 0.5]] * 2)
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    res = cast_rays(o, d, seg, 40.0)
    np.testing.assert_allclose(res.range_m, [12.0, 12.0], atol=TOL)  # the wall behind the glass
    weak = cast_rays(o, d, seg, 40.0, glass_returns=np.array([True, False]))
    np.testing.assert_allclose(weak.range_m, [7.0, 12.0], atol=TOL)
    assert weak.kind.tolist() == [HIT_GLASS, HIT_WALL]
    alone = cast_rays(o, d, Segments.from_walls(box(east="glass")), 40.0)
    assert np.isinf(alone.range_m).all() and (alone.kind == HIT_NONE).all()  # nothing behind


def test_mirror_return_is_the_reflection_of_the_true_hit_across_the_mirror() -> None:
    seg = Segments.from_walls(box(east="mirror"))  # mirror on x = 10
    rng = np.random.default_rng(1)
    n = 2000
    o = np.tile([3.0, 2.0, 0.5], (n, 1))
    az, el = rng.uniform(-1.2, 1.2, n), rng.uniform(-0.05, 0.3, n)
    d = np.column_stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
    res = cast_rays(o, d, seg, 40.0, max_bounces=1)
    bounced = res.bounces == 1
    assert bounced.sum() > 300
    phantom = o[bounced] + res.range_m[bounced, None] * d[bounced]
    assert (phantom[:, 0] > 10.0).all()  # behind the mirror
    mirrored = phantom.copy()
    mirrored[:, 0] = 20.0 - phantom[:, 0]  # reflection across the plane x = 10
    np.testing.assert_allclose(mirrored, res.hit_map[bounced], atol=1e-9)
    # the straight-back case by hand: from x = 3 to the mirror (7 m) and back to x = 0 (10 m)
    back = cast_rays(o[:1], np.array([[1.0, 0.0, 0.0]]), seg, 40.0)
    assert back.range_m[0] == pytest.approx(17.0, abs=TOL) and back.bounces[0] == 1
    # without bounces the mirror swallows the beam; between two mirrors a beam is lost
    assert np.isinf(
        cast_rays(o[:1], np.array([[1.0, 0, 0]]), seg, 40.0, max_bounces=0).range_m
    ).all()
    two = Segments.from_walls(box(east="mirror", west="mirror"))
    assert np.isinf(
        cast_rays(o[:1], np.array([[1.0, 0, 0]]), two, 40.0, max_bounces=2).range_m
    ).all()


def test_people_occlude_from_their_side_up_to_their_height() -> None:
    seg = Segments.from_walls(box(height=5.0))
    cyl = Cylinders(np.array([[6.0, 2.0]]), np.array([0.5]), np.array([1.8]))
    o = np.tile([3.0, 2.0, 0.5], (3, 1))
    # the person's front is 2.5 m ahead; z there: 0.5, 1.33 (hit) and 1.875 m (over its head)
    d = np.array([[1.0, 0, 0], unit([3.0, 0, 1.0]), unit([1.0, 0, 0.55])])
    res = cast_rays(o, d, seg, 40.0, cylinders=cyl)
    assert res.kind.tolist() == [HIT_PERSON, HIT_PERSON, HIT_WALL]
    np.testing.assert_allclose(res.range_m[:2], [2.5, 2.5 / d[1, 0]], atol=TOL)
    np.testing.assert_allclose(res.range_m[2], 7.0 / d[2, 0], atol=TOL)  # the wall behind


def test_a_single_level_ring_is_a_2d_scanner() -> None:
    cfg = LidarConfig.model_validate(
        {"T_base_lidar": {"position": [0, 0, 0.4], "rpy_deg": [0, 0, 0]}, "rings": 1,
         "vertical_fov_deg": [0, 0], "columns": 8, "range_sigma_m": 0.0}
    )  # fmt: skip
    sim = LidarSimulator(cfg, box())
    points, cast = sim.scan_at(SE3.from_quat([0.0, 0.0, 0.0, 1.0], [3.0, 2.0, 0.0]))
    # oracle: azimuths -180, -135, ..., 135 deg from (3, 2) in the 10 x 6 room
    expected = [
        3.0,
        2 * math.sqrt(2),
        2.0,
        2 * math.sqrt(2),
        7.0,
        4 * math.sqrt(2),
        4.0,
        3 * math.sqrt(2),
    ]
    np.testing.assert_allclose(cast.range_m, expected, atol=TOL)
    assert np.allclose(points[:, 2], 0.4)
    with pytest.raises(ValidationError, match=r"one ring needs low == high"):
        LidarConfig.model_validate(
            {"T_base_lidar": {"position": [0, 0, 0], "rpy_deg": [0, 0, 0]}, "rings": 1,
             "vertical_fov_deg": [-1, 1]}
        )  # fmt: skip
