"""Sweeps of the simulated lidar along a drive: raw (skewed) points consistent with the true
motion, time offsets, seeding, people's occlusion fraction, the truth premap.

Oracles: the world's wall segments and the floor (point-to-segment distances computed here), the
drive's ground truth, the requested crowd fraction. Tolerances: noise sigma 2 cm -> 5 sigma.
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.sim import load_default_world, simulate_drive
from tagloc.sim.lidar import LidarSimulator, premap_from_world
from tagloc.sim.lidar_cast import HIT_FLOOR, HIT_PERSON, HIT_WALL
from tagloc.sim.people import Person, crowd_around, people_xy
from tagloc.sim.scenarios import truncate_drive
from tagloc.sim.world import load_builtin_world

S = 1_000_000_000


def surface_distance(points_map: np.ndarray, walls: list) -> np.ndarray:  # type: ignore[type-arg]
    """Distance of each point to the nearest wall face (within the wall's height) or the floor."""
    a = np.array([w.start for w in walls])
    b = np.array([w.end for w in walls])
    h = np.array([w.height for w in walls])
    ab = b - a
    p = points_map[:, None, :2]
    s = np.clip(((p - a) * ab).sum(-1) / (ab**2).sum(-1), 0.0, 1.0)
    d = np.linalg.norm(p - (a + s[..., None] * ab), axis=-1)
    z = points_map[:, 2:3]
    d = np.where((z >= -0.1) & (z <= h + 0.1), d, np.inf)
    return np.minimum(d.min(axis=1), np.abs(points_map[:, 2]))


@pytest.fixture(scope="module")
def office_drive():  # type: ignore[no-untyped-def]
    world = load_default_world()
    return truncate_drive(simulate_drive(world, seed=0), 40.0)


def truth(drive):  # type: ignore[no-untyped-def]
    return lambda stamps: drive.ground_truth_at(stamps).xy_yaw_map_base


def test_raw_points_deskewed_with_the_true_motion_land_on_the_walls(office_drive) -> None:  # type: ignore[no-untyped-def]
    world = office_drive.world
    assert world.robot.lidar is not None
    # no mirrors here: the cab's mirror walls would put phantoms behind them
    walls = [w for w in world.walls_in_map() if w.material == "wall"]
    sim = LidarSimulator(world.robot.lidar, walls)
    starts = sim.sweep_starts_ns(office_drive.t0_ns, int(office_drive.stamps_ns[-1]))
    yaw = truth(office_drive)(starts)[:, 2]
    k = int(np.argmax(np.abs(np.diff(np.unwrap(yaw)))))  # the sweep that turns the most
    sweep = sim.sweep(truth(office_drive), int(starts[k]), k)
    msg = sweep.msg
    ends = truth(office_drive)(np.array([starts[k], sweep.end_ns]))[:, 2]
    turned = abs(np.diff(np.unwrap(ends))[0])
    assert turned > 0.04  # rad: the sweep is skewed
    assert msg.time_offset_s is not None and len(msg.points) > 1000
    # test-only de-skew with ground truth: each point through its column's true scanner pose
    col = sweep.beam_index // sim.directions_lidar.shape[1]
    p = msg.points.astype(np.float64)
    deskewed = np.einsum("nij,nj->ni", sweep.R_map_lidar[col], p) + sweep.t_map_lidar[col]
    assert np.percentile(surface_distance(deskewed, walls), 99) < 5 * 0.02 + 1e-3
    # the raw points taken at the sweep-start pose miss the walls: the data is skewed
    raw = p @ sweep.R_map_lidar[0].T + sweep.t_map_lidar[0]
    assert np.percentile(surface_distance(raw, walls), 90) > 0.1
    # every point's time offset is its column's firing time, within the sweep, non-decreasing
    expected = sim.column_offsets_s[col]
    np.testing.assert_allclose(msg.time_offset_s, expected, atol=1e-7)
    assert np.all(np.diff(msg.time_offset_s) >= 0) and msg.time_offset_s.max() < 0.1
    assert msg.stamp_ns == starts[k] and sweep.end_ns == msg.last_point_ns()
    assert sweep.end_ns - starts[k] == round(float(np.float32(0.1 * 359 / 360)) * S)
    kinds = sweep.cast.kind[sweep.beam_index]
    assert set(np.unique(kinds)) <= {HIT_WALL, HIT_FLOOR}


def test_sweeps_are_seeded_per_index(office_drive) -> None:  # type: ignore[no-untyped-def]
    world = office_drive.world
    sim = LidarSimulator(world.robot.lidar, world.walls_in_map())
    start = office_drive.t0_ns + 5 * S
    a, b = sim.sweep(truth(office_drive), start, 3), sim.sweep(truth(office_drive), start, 3)
    c = sim.sweep(truth(office_drive), start, 4)
    assert np.array_equal(a.msg.points, b.msg.points)
    same = np.intersect1d(a.beam_index, c.beam_index)
    ia, ic = np.searchsorted(a.beam_index, same), np.searchsorted(c.beam_index, same)
    diff = np.linalg.norm(a.msg.points[ia] - c.msg.points[ic], axis=1)
    assert 0.01 < np.median(diff) < 0.05  # independent noise: sigma * sqrt(2) * 0.67
    # the lazy stream of sweeps gives the same sweeps (poses sampled in blocks)
    streamed = next(sim.sweeps(truth(office_drive), np.array([start]), first_index=3))
    np.testing.assert_allclose(streamed.msg.points, a.msg.points, atol=1e-6)


def test_a_crowd_blocks_the_requested_fraction_of_beams(office_drive) -> None:  # type: ignore[no-untyped-def]
    world = office_drive.world
    stamps = np.arange(office_drive.t0_ns, int(office_drive.stamps_ns[-1]) + S, S // 2)
    t_s = (stamps - office_drive.t0_ns) * 1e-9
    people = crowd_around(office_drive.ground_truth_at(stamps).xy_yaw_map_base, t_s, 0.45, seed=2)
    sim = LidarSimulator(world.robot.lidar, world.walls_in_map(), people, office_drive.t0_ns)
    starts = sim.sweep_starts_ns(office_drive.t0_ns, int(office_drive.stamps_ns[-1]))[::2]
    fractions = np.array(
        [(s.cast.kind == HIT_PERSON).mean() for s in sim.sweeps(truth(office_drive), starts)]
    )
    assert abs(fractions.mean() - 0.45) < 0.05, fractions.mean()
    assert fractions.min() > 0.30 and fractions.max() < 0.60, (fractions.min(), fractions.max())


def test_people_walk_their_path_and_random_walks_are_seeded() -> None:
    person = Person(path=((0.0, 0.0, 0.0), (10.0, 5.0, 0.0)))
    np.testing.assert_allclose(
        people_xy([person.waypoints()], np.array([-1.0, 2.0, 20.0]))[:, 0],
        [[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]],
    )
    walk = {"start": [1.0, 1.0], "bounds": [0, 0, 4, 3], "seed": 5, "duration_s": 60}
    a, b = Person(random_walk=walk).waypoints(), Person(random_walk=walk).waypoints()
    assert np.array_equal(a, b) and len(a) == 121
    assert (a[:, 1] >= 0).all() and (a[:, 1] <= 4).all() and (a[:, 2] <= 3).all()
    steps = np.linalg.norm(np.diff(a[:, 1:], axis=0), axis=1)
    assert steps.max() <= 0.5 + 1e-9  # 1 m/s for 0.5 s (a bounce shortens a step)


def test_truth_premap_lies_on_the_walls_and_floor_one_point_per_voxel() -> None:
    world = load_builtin_world("long_corridor")
    drive = truncate_drive(simulate_drive(world, seed=0), 20.0)
    premap = premap_from_world(world, drive.T_map_base, every_m=1.0, voxel_m=0.1)
    walls = list(world.walls_in_map())
    assert len(premap) > 2000
    assert surface_distance(premap, walls).max() < 0.1 * np.sqrt(3)
    keys = np.floor(premap / 0.1 + 0.5).astype(np.int64)  # cubes centred on multiples of 0.1
    assert len(np.unique(keys, axis=0)) == len(premap)
    # a wall on a round coordinate is one layer of cubes thick
    near = premap[(np.abs(premap[:, 1] - 8.8) < 0.2) & (premap[:, 2] > 0.2) & (premap[:, 0] > 0.5)]
    assert np.abs(near[:, 1] - 8.8).max() < 0.05
    # both corridor walls are mapped along the stretch driven and 40 m beyond
    for y in (8.8, 11.2):
        on = premap[np.abs(premap[:, 1] - y) < 0.1]
        assert on[:, 0].min() < 2.0 and on[:, 0].max() > 20.0
