"""The node in an elevator cab: the cab's tags give the pose relative to the cab, the lidar and
the floor are set aside, and a tag map with an unknown cab frame is refused.

The office world's cab stands still at the ground floor, so its tags, posed in the cab frame,
give fixes of ``T_cab_base``; the oracle is the simulator's truth ``T_map_cab^-1 T_map_base``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tagloc.eval.scenarios import localize_scenario
from tagloc.eval.summary import evaluate
from tagloc.geometry import SE3
from tagloc.localize import LocalizerConfig
from tagloc.localize.fix import LocalizeError
from tagloc.localize.node import LocalizerNode
from tagloc.localize.run import LocalizationRun
from tagloc.sim.scenarios import Scenario, build_scenario
from tagloc.supervise import CabState
from tagloc.tags.tagmap import TagEntry, TagMap

S = 1_000_000_000


def _cab_map(scenario: Scenario, cab_frame: str = "elevator_cab") -> TagMap:
    """The surveyed map with the cab's tags in the cab frame (as a survey that rode it gives)."""
    world = scenario.world
    entries = [
        TagEntry.from_pose(t.id, t.T_frame_tag(), t.size, frame=cab_frame)
        if t.frame == "elevator_cab"
        else scenario.tag_map.get(t.id)
        for t in world.tags
    ]
    return TagMap.from_entries([e for e in entries if e is not None])


@pytest.fixture(scope="module")
def cab_run() -> tuple[Scenario, LocalizationRun]:
    scenario = build_scenario("default", seed=1, duration_s=200.0)  # in the cab 165-180 s
    scenario = Scenario(**{**{f: getattr(scenario, f) for f in scenario.__dataclass_fields__},
                           "tag_map": _cab_map(scenario)})  # fmt: skip
    return scenario, localize_scenario(scenario, lidar=False)


def test_the_cab_tags_give_the_pose_relative_to_the_cab(
    cab_run: tuple[Scenario, LocalizationRun],
) -> None:
    scenario, run = cab_run
    states = [m.to_state for m in run.cab_moves]
    assert states[:2] == [CabState.BOARDING, CabState.IN_CAB], run.cab_moves
    assert all(m.reason for m in run.cab_moves)
    boarding = run.cab_moves[0].stamp_ns - scenario.drive.t0_ns
    assert 150 * S < boarding < 175 * S  # the route enters the cab at 164.8 s
    inside = [c for c in run.cab if c.state is CabState.IN_CAB]  # the doors closed
    assert len(inside) > 500  # 100 Hz over seconds in the cab
    T_map_cab = scenario.world.elevator.T_map_cab()  # type: ignore[union-attr]
    truth = scenario.drive.ground_truth_at(np.array([c.stamp_ns for c in inside]))
    err = [
        float(np.linalg.norm((T_map_cab.inverse() @ T).translation - c.T_cab_base.translation))
        for c, T in zip(inside, truth.T_map_base, strict=True)
    ]
    rms = float(np.sqrt(np.mean(np.square(err))))
    assert rms <= 0.02, f"in-cab RMS {rms:.4f} m"


def test_the_ladder_and_status_say_where_the_robot_is(
    cab_run: tuple[Scenario, LocalizationRun],
) -> None:
    _, run = cab_run
    board = run.cab_moves[0].stamp_ns
    back = next((m.stamp_ns for m in run.cab_moves if m.to_state is CabState.IN_MAP), None)
    assert back is not None and back > board
    assert run.metadata["elevators"]["cab_fixes"]["accepted"] > 10  # type: ignore[index]
    assert run.floors and all(f is None for f in run.floors)  # no floor table: no floor


def test_a_tag_map_with_an_unknown_cab_frame_is_refused_at_start_up() -> None:
    scenario = build_scenario("default", seed=0, duration_s=1.0)
    with pytest.raises(LocalizeError) as info:
        LocalizerNode(_cab_map(scenario, "cab_west"), LocalizerConfig())
    assert str(info.value) == (
        "the tag map has tags in frame 'cab_west', which the configuration does not know as a "
        "cab (elevators.cab_frames: elevator_cab)"
    )


def test_cab_only_frames_are_judged_against_the_simulators_cab_truth(
    cab_run: tuple[Scenario, LocalizationRun],
) -> None:
    scenario, run = cab_run
    # oracle: the simulator's base in the (still) cab at each cab estimate's odometry stamp
    T_map_cab = scenario.world.elevator.T_map_cab()  # type: ignore[union-attr]
    stamps = np.array([c.stamp_ns for c in run.cab], dtype=np.int64)
    T_true = T_map_cab.inverse() @ scenario.drive.ground_truth_at(stamps).T_map_base
    row_of = {int(s): i for i, s in enumerate(stamps)}
    accepted = {a.stamp_ns for a in run.fixes if a.frame == "elevator_cab" and a.accepted}
    odom = np.asarray(run.stamps_ns)

    def by_hand(T_cab_base: list[SE3]) -> tuple[int, int]:
        """Cab-only opportunities (the cab's tag within 3 m, no map tag) and their successes."""
        n = ok = 0
        for f in run.frames:
            if f.nearest_in({"elevator_cab"}) > 3.0 or f.nearest_in({"elevator_cab"}, False) <= 3:
                continue
            n += 1
            i = row_of.get(int(odom[min(np.searchsorted(odom, f.stamp_ns), len(odom) - 1)]))
            if i is None or f.stamp_ns not in accepted:
                continue
            d = T_true[i].inverse() @ T_cab_base[i]
            ok += bool(np.linalg.norm(d.translation) <= 0.05
                       and np.degrees(np.linalg.norm(d.rotation.as_rotvec())) <= 2.0)  # fmt: skip
        return n, ok

    r = evaluate(run).summary.estimators["fused"].reliability
    assert r is not None
    n, ok = by_hand([c.T_cab_base for c in run.cab])
    assert n >= 30 and (r.in_cab.n_opportunities, r.in_cab.n_success) == (n, ok)
    assert ok >= 0.8 * n  # the node's pose relative to the cab: within 5 cm / 2 deg
    # a cab estimate corrupted by 8 cm fails every cab opportunity; the map's are unchanged
    shift = SE3.from_rotvec(np.zeros(3), np.array([0.08, 0.0, 0.0]))
    bad = dataclasses.replace(
        run, cab=[dataclasses.replace(c, T_cab_odom=shift @ c.T_cab_odom) for c in run.cab]
    )
    rb = evaluate(bad).summary.estimators["fused"].reliability
    assert rb is not None and by_hand([c.T_cab_base for c in bad.cab]) == (n, 0)
    assert rb.in_cab.n_success == 0 and rb.in_map == r.in_map
