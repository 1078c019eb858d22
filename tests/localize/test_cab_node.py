"""The node in an elevator cab: the cab's tags give the pose relative to the cab, the lidar and
the floor are set aside, and a tag map with an unknown cab frame is refused.

The office world's cab stands still at the ground floor, so its tags, posed in the cab frame,
give fixes of ``T_cab_base``; the oracle is the simulator's truth ``T_map_cab^-1 T_map_base``.
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.eval.scenarios import localize_scenario
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
