"""The lidar in the simulator's message stream: topics, the static mount, stamps and arrival
order, faults on point clouds, bags written by ``tagloc sim record``, the node ignoring the lidar,
and what each lidar scenario must show.

Oracles: the world file (mount, rate), the drive's ground truth, the scenarios' geometry (wall
coordinates from their world files), BagSource reading back what was written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cli_runner import run_tagloc
from tagloc.eval.scenarios import localize_scenario
from tagloc.io import BagSource
from tagloc.messages import Message, OdometryMsg, PointCloudMsg, TransformMsg
from tagloc.sim.faults import ClockJump, DropMessages, DuplicateMessages, apply_faults
from tagloc.sim.lidar import LidarSimulator
from tagloc.sim.scenarios import SCENARIOS, ScenarioSource, build_scenario, scenario_premap
from tagloc.sim.world import load_default_world

S = 1_000_000_000


@pytest.fixture(scope="module")
def short() -> tuple[ScenarioSource, list[tuple[str, Message]]]:
    source = ScenarioSource(build_scenario("default", 0, 3.0))
    return source, list(source)


def test_the_stream_carries_sweeps_stamped_at_start_delivered_at_end(short) -> None:  # type: ignore[no-untyped-def]
    source, items = short
    world = load_default_world()
    assert world.robot.lidar is not None
    assert source.topics["/lidar/points"] is PointCloudMsg
    t0 = int(source.scenario.drive.stamps_ns[0])
    statics = [m for t, m in items[:4] if isinstance(m, TransformMsg) and m.static]
    mount = [m for m in statics if (m.parent, m.child) == ("base_link", "lidar")]
    assert len(mount) == 1 and mount[0].stamp_ns == t0
    expected = world.robot.lidar.T_base_lidar.T_base_lidar().as_matrix()
    np.testing.assert_allclose(mount[0].T_parent_child.as_matrix(), expected, atol=1e-12)
    clouds = [(i, m) for i, (t, m) in enumerate(items) if t == "/lidar/points"]
    # sweeps every 100 ms; those complete within the 3 s drive
    assert [m.stamp_ns - t0 for _, m in clouds] == [k * S // 10 for k in range(30)]
    odom = [(i, m.stamp_ns) for i, (t, m) in enumerate(items) if isinstance(m, OdometryMsg)]
    for i, msg in clouds:
        assert isinstance(msg, PointCloudMsg) and msg.frame_id == "lidar"
        end = msg.last_point_ns()
        assert 0.0997 * S < end - msg.stamp_ns < 0.1 * S  # the last column: 359/360 of a turn
        before = [s for j, s in odom if j < i]
        after = [s for j, s in odom if j > i]
        assert before[-1] < end <= after[0]  # delivered once complete, before its end's odometry


def test_faults_treat_point_clouds_like_any_record(short) -> None:  # type: ignore[no-untyped-def]
    _, items = short
    t0 = items[0][1].stamp_ns

    def cloud_stamps(stream: list[tuple[str, Message]]) -> list[float]:
        return [(m.stamp_ns - t0) / S for _, m in stream if isinstance(m, PointCloudMsg)]

    dropped = list(apply_faults(items, [DropMessages(1.0, 2.0, (PointCloudMsg,))], t0))
    assert cloud_stamps(dropped) == [k / 10 for k in range(30) if not 10 <= k < 20]
    assert len(dropped) == len(items) - 10
    twice = list(apply_faults(items, [DuplicateMessages(1.0, 1.5, (PointCloudMsg,))], t0))
    assert len(twice) == len(items) + 5
    jumped = list(apply_faults(items, [ClockJump(2.0, 0.5, (PointCloudMsg,))], t0))
    before = [m for _, m in items if isinstance(m, PointCloudMsg)]
    after = [m for _, m in jumped if isinstance(m, PointCloudMsg)]
    assert [
        round((b.stamp_ns - a.stamp_ns) / S, 3) for a, b in zip(before, after, strict=True)
    ] == [0.0 if a.stamp_ns < t0 + 2 * S else -0.5 for a in before]
    assert all(a.points is b.points for a, b in zip(before, after, strict=True))
    assert [t for t, _ in jumped] == [t for t, _ in items]  # delivery order unchanged


def test_a_robot_without_lidar_streams_none() -> None:
    world = load_default_world()
    bare = world.model_copy(update={"robot": world.robot.model_copy(update={"lidar": None})})
    source = ScenarioSource(build_scenario("default", 0, 1.0, world=bare))
    assert "/lidar/points" not in source.topics
    items = list(source)
    assert not any(isinstance(m, PointCloudMsg) for _, m in items)
    assert not any(isinstance(m, TransformMsg) and m.child == "lidar" for _, m in items)


def test_the_localizer_ignores_the_lidar() -> None:
    world = load_default_world()
    bare = world.model_copy(update={"robot": world.robot.model_copy(update={"lidar": None})})
    with_lidar = localize_scenario(build_scenario("default", 0, 12.0), lidar=False)
    without = localize_scenario(build_scenario("default", 0, 12.0, world=bare))
    np.testing.assert_array_equal(with_lidar.stamps_ns, without.stamps_ns)
    np.testing.assert_array_equal(with_lidar.T_map_base.as_matrix(), without.T_map_base.as_matrix())
    assert sum(f.accepted for f in with_lidar.fixes) == sum(f.accepted for f in without.fixes) > 0
    assert with_lidar.metadata["lidar"] == "16 rings x 360 columns, -7 to 52 deg, 360 deg, 10 Hz"
    assert without.metadata["lidar"] is None and without.metadata["people"] == 0


def test_sim_record_writes_the_sweeps_in_arrival_order(tmp_path: Path, short) -> None:  # type: ignore[no-untyped-def]
    _, items = short
    out = tmp_path / "drive.mcap"
    done = run_tagloc("sim", "record", "--out", str(out), "--duration", "3")
    assert done.returncode == 0, done.stderr
    assert "/lidar/points" in done.stdout
    source = BagSource(out)
    assert source.bag_topics["/lidar/points"].msgtype == "sensor_msgs/msg/PointCloud2"
    back = list(source)
    assert [(t, m.stamp_ns) for t, m in back] == [(t, m.stamp_ns) for t, m in items]
    clouds = [(a, b) for (t, a), (_, b) in zip(items, back, strict=True) if t == "/lidar/points"]
    for a, b in clouds:
        assert isinstance(a, PointCloudMsg) and isinstance(b, PointCloudMsg)
        assert np.array_equal(a.points, b.points) and np.array_equal(a.intensity, b.intensity)  # type: ignore[arg-type]
        assert np.array_equal(a.time_offset_s, b.time_offset_s)  # type: ignore[arg-type]


# ----- the lidar scenarios ------------------------------------------------------------------
def sweep_at(name: str, x: float, **kw: float):  # type: ignore[no-untyped-def]
    """The first sweep of scenario ``name`` whose start finds the robot within 0.5 m of map x,
    with the points in map (each through its column's true pose)."""
    scenario = build_scenario(name, 0)
    drive = scenario.drive
    lidar = scenario.world.robot.lidar
    assert lidar is not None
    sim = LidarSimulator(lidar, scenario.world.walls_in_map(), scenario.people, drive.t0_ns)
    starts = sim.sweep_starts_ns(drive.t0_ns, int(drive.stamps_ns[-1]))
    xy = drive.ground_truth_at(starts).xy_yaw_map_base
    k = int(np.flatnonzero(np.abs(xy[:, 0] - x) < 0.5)[0])
    sweep = sim.sweep(lambda st: drive.ground_truth_at(st).xy_yaw_map_base, int(starts[k]), k)
    col = sweep.beam_index // sim.directions_lidar.shape[1]
    p = np.einsum("nij,nj->ni", sweep.R_map_lidar[col], sweep.msg.points.astype(np.float64))
    return scenario, sweep, p + sweep.t_map_lidar[col]


def test_glass_corridor_returns_only_floor_and_end_walls() -> None:
    scenario, _, p = sweep_at("glass_corridor", 20.0)
    solid = p[np.abs(p[:, 2]) > 0.1]  # not the floor
    assert len(solid) > 0 and (np.minimum(solid[:, 0], 40.0 - solid[:, 0]) < 0.1).all()
    floor = p[np.abs(p[:, 2]) <= 0.1]
    assert (np.abs(floor[:, 1] - 10.0) > 1.2).any()  # the floor beyond the glass is seen
    assert all(t.wall is not None for t in scenario.world.tags)


def test_mirrored_lobby_shows_phantom_geometry_behind_the_mirror() -> None:
    _, sweep, p = sweep_at("mirrored_lobby", 12.0)
    behind = p[:, 0] > 14.05
    assert behind.sum() > 200
    # each phantom is the reflection across x = 14 of the true surface point the beam hit
    true_hit = sweep.cast.hit_map[sweep.beam_index[behind]]
    mirrored = p[behind].copy()
    mirrored[:, 0] = 28.0 - mirrored[:, 0]
    assert np.percentile(np.linalg.norm(mirrored - true_hit, axis=1), 99) < 5 * 0.02


def test_long_corridor_has_no_tags_and_no_end_walls_in_its_middle() -> None:
    scenario, _, p = sweep_at("long_corridor", 60.0)
    xs = [scenario.world.T_map_tag(t).translation[0] for t in scenario.world.tags]
    assert all(x < 5.0 or x > 115.0 for x in xs)
    solid = p[np.abs(p[:, 2]) > 0.1]
    assert len(solid) > 1000
    assert (np.minimum(np.abs(solid[:, 1] - 8.8), np.abs(solid[:, 1] - 11.2)) < 0.1).all()


def test_crowd_and_lidar_unplugged_are_what_they_say() -> None:
    crowd = build_scenario("crowd", 0, 2.0)
    assert len(crowd.people) == 5 and SCENARIOS["crowd"].crowd_fraction == 0.45
    [fault] = SCENARIOS["lidar_unplugged"].faults
    assert isinstance(fault, DropMessages) and fault.kinds == (PointCloudMsg,)
    assert (fault.start_s, fault.end_s) == (30.0, 50.0)


@pytest.mark.slow
def test_lidar_unplugged_stream_has_a_20_s_gap() -> None:
    source = ScenarioSource(build_scenario("lidar_unplugged", 0, 55.0))
    t0 = int(source.scenario.drive.stamps_ns[0])
    stamps = np.array([m.stamp_ns for _, m in source if isinstance(m, PointCloudMsg)])
    assert ((stamps >= t0 + 30 * S) & (stamps < t0 + 50 * S)).sum() == 0
    assert np.diff(stamps).max() == 20 * S + S // 10


def test_a_crowd_scenario_premap_holds_walls_and_floor_but_no_people() -> None:
    scenario = build_scenario("crowd", 0, 10.0)
    premap = scenario_premap(scenario, every_m=1.0)
    walls = scenario.world.walls_in_map()
    a = np.array([w.start for w in walls])
    ab = np.array([w.end for w in walls]) - a
    p = premap[np.abs(premap[:, 2]) > 0.1][:, None, :2]  # off the floor
    s = np.clip(((p - a) * ab).sum(-1) / (ab**2).sum(-1), 0.0, 1.0)
    dist = np.linalg.norm(p - (a + s[..., None] * ab), axis=-1).min(axis=1)
    behind_mirror = p[:, 0, 0] > 37.6  # the cab's mirror walls add phantoms (none in 10 s)
    assert len(p) > 1000 and (dist[~behind_mirror] < 0.1).all()
