"""The map <-> cab handoff and the floor book, driven with synthetic sightings and door news.

The oracle is the specification in :mod:`tagloc.supervise.cab` and :mod:`tagloc.supervise.floors`
(which move each input must cause, and which it must not).
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from tagloc.supervise import (
    CabHandoff,
    CabState,
    CabTransition,
    ElevatorConfig,
    FixSourceSpec,
    FloorBook,
    Level,
    Supervisor,
    SupervisorConfig,
)
from tagloc.supervise.supervisor import EstimatorState

S = 1_000_000_000
CAB = "elevator_cab"
FRAME_NS = S // 30


def _frames(
    h: CabHandoff, t0_s: float, t1_s: float, *, cab: bool, map_: bool, odometer_m: float = 0.0
) -> list[CabTransition]:
    moves = []
    for k in range(round((t1_s - t0_s) * 30)):
        t = round(t0_s * S) + k * FRAME_NS
        for move in (
            h.odometry(t, odometer_m),
            h.frame(t, frozenset({CAB}) if cab else frozenset(), map_),
        ):
            if move is not None:
                moves.append(move)
    return moves


def test_a_ride_without_door_news_walks_every_state_once() -> None:
    h = CabHandoff(ElevatorConfig())
    moves = _frames(h, 0, 5, cab=False, map_=True)  # the lobby
    moves += _frames(h, 5, 8, cab=True, map_=True)  # walking in: the cab's tags and the lobby's
    moves += _frames(h, 8, 20, cab=True, map_=False)  # doors closed, riding
    moves += _frames(h, 20, 21, cab=True, map_=True)  # doors open on the landing
    moves += _frames(h, 21, 23, cab=False, map_=True, odometer_m=1.2)  # walking out
    assert [m.to_state for m in moves] == [
        CabState.BOARDING, CabState.IN_CAB, CabState.ALIGHTING, CabState.IN_MAP
    ]  # fmt: skip
    boarding, closed, opened, out = (m.stamp_ns / S for m in moves)
    assert 5.5 <= boarding < 5.6  # board_dwell_s after the first cab tag
    assert 9.9 <= closed < 10.1  # closed_after_s after the last lobby tag
    assert 20.2 <= opened < 20.3  # open_dwell_s of landing tags
    assert out == 21.0  # exit_m travelled
    assert all(m.cab_frame == CAB for m in moves) and all(m.reason for m in moves)


def test_the_door_topic_decides_when_it_speaks() -> None:
    h = CabHandoff(ElevatorConfig())
    _frames(h, 0, 1, cab=True, map_=True)
    assert h.state is CabState.BOARDING
    move = h.door(round(1.05 * S), CAB, False)  # lobby tags still in view: the topic wins
    assert move is not None and move.to_state is CabState.IN_CAB and "door topic" in move.reason
    assert not _frames(h, 1.1, 3, cab=True, map_=True)  # landing tags through glass: still in
    move = h.door(3 * S, CAB, True)
    assert move is not None and move.to_state is CabState.ALIGHTING
    move = h.door(4 * S, CAB, False)  # closed again before the robot left: the next stop
    assert move is not None and move.to_state is CabState.IN_CAB


def test_walking_past_the_cab_returns_to_the_map() -> None:
    h = CabHandoff(ElevatorConfig())
    moves = _frames(h, 0, 1, cab=True, map_=True) + _frames(h, 1, 5, cab=False, map_=True)
    assert [m.to_state for m in moves] == [CabState.BOARDING, CabState.IN_MAP]
    assert "walked past" in moves[-1].reason


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0.0, 30.0), st.integers(1, 14)),  # start s, frames (< 0.5 s at 30 Hz)
        min_size=1, max_size=12,
    )
)  # fmt: skip
def test_glimpses_shorter_than_the_dwell_never_board(bursts: list[tuple[float, int]]) -> None:
    """Cab tags in bursts of under ``board_dwell_s``, each at least ``lost_s`` apart."""
    h = CabHandoff(ElevatorConfig())
    t = 0
    for start_s, n in sorted(bursts):
        t = max(t + round(3.1 * S), round(start_s * S))
        for k in range(n):
            assert h.frame(t + k * FRAME_NS, frozenset({CAB}), False) is None
        t += n * FRAME_NS
    assert h.state is CabState.IN_MAP


def test_the_ladder_ignores_the_lidar_in_the_cab_at_once() -> None:
    specs = [FixSourceSpec("markers", "markers", "camera"),
             FixSourceSpec("lidar", "lidar", "lidar")]  # fmt: skip
    sup = Supervisor(SupervisorConfig(), specs, 10.0, 5.0, ElevatorConfig())
    good = EstimatorState(True, False, 0.1, 0.1)
    moves = []
    for k in range(300):  # 3 s at 100 Hz; the camera and the lidar alive throughout
        t = k * S // 100
        for name in ("odometry", "camera", "lidar"):
            sup.on_input(name, t)
        if k == 100:
            assert sup.handoff is not None
            sup.handoff.door(t, CAB, False)  # not boarding: the topic alone moves nothing
            sup.handoff.frame(t, frozenset({CAB}), False)
        if k > 100 and k % 3 == 0:
            sup.handoff.frame(t, frozenset({CAB}), False)  # type: ignore[union-attr]
        move = sup.step(t, good)
        if move is not None:
            moves.append(move)
    assert [(m.from_level, m.to_level) for m in moves] == [
        (Level.ODOMETRY_ONLY, Level.LIDAR_NOMINAL), (Level.LIDAR_NOMINAL, Level.MARKERS_ALONE)
    ]  # fmt: skip
    assert moves[-1].hard and "lidar ignored in the cab" in moves[-1].reason
    assert sup.status(3 * S, good).cab is CabState.IN_CAB  # doors closed at boarding (topic)


def test_a_floor_is_known_only_from_its_own_tags() -> None:
    book = FloorBook({"1": 0.0, "2": 4.0, "3": 8.0}, confirm_fixes=3, change_fixes=10)
    changes = [book.accepted(k, "1", 10 + k) for k in range(3)]
    assert changes[:2] == [None, None] and changes[2] is not None and not changes[2].changed
    assert book.known and book.floor == "1" and book.height_m == 0.0
    assert all(book.accepted(10 + k, "3", 30) is None for k in range(9))  # not enough
    assert book.accepted(19, "1", 10) is None and book.floor == "1"  # its own floor: reset
    book.lose()  # the doors closed on a ride
    assert not book.known and book.floor == "1"
    assert book.accepted(20, "2", 21) is None and book.accepted(21, "3", 31) is None
    assert book.accepted(22, "3", 32) is None
    change = book.accepted(23, "3", 33)
    assert change is not None and change.changed and (change.from_floor, change.to_floor) == (
        "1", "3"
    )  # fmt: skip
    assert change.dz_m == 8.0 and change.tag_ids == (31, 32, 33) and "ride" in change.reason
    assert book.accepted(24, "unknown floor", 99) is None and book.floor == "3"


def test_the_configuration_refuses_a_cab_frame_listed_twice() -> None:
    import pytest

    from tagloc.errors import ConfigError
    from tagloc.localize import LocalizerConfig

    with pytest.raises(ConfigError, match=r"elevators.cab_frames: lists a frame twice"):
        LocalizerConfig.from_yaml_text("elevators:\n  cab_frames: [a, a]\n", "localizer.yaml")
