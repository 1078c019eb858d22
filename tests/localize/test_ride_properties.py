"""Properties of the published ``map -> odom`` over random ride schedules of the tower.

Each example is a seeded schedule (:func:`_schedule`): a random start floor, random rides to
other floors, the shaft's dwell and door times drawn at random, a random wait in each lobby,
the doors published by the building or inferred. The node runs on the simulated drive and, the
oracle being the simulator's world (its floors' heights, its tags' floors) and truth:

- between consecutive published estimates the ``map -> base`` at the robot's pose moves by at
  most the configured cap (``cap.max_translation_m``, ``cap.max_rotation_deg``), except at a
  declared floor change (a ``floor_changed`` event, stamped with the first estimate on the new
  floor), where z moves by the difference of the two floors' heights and x, y by at most the cap;
- no floor change without an accepted fix of a tag of the new floor, after the doors opened;
- the declared floor is the floor the robot is on, and every ride declares its floor.

The rows before the filter's first initialization are not estimates and are skipped. The default
run holds three one-ride schedules without lidar (about 13 s each); the slow variant rides twice
per schedule with the lidar on.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

import numpy as np
import pytest

from tagloc.eval.scenarios import localize_scenario, scenario_config
from tagloc.localize.events import EventKind
from tagloc.localize.run import LocalizationRun
from tagloc.sim.route import Waypoint
from tagloc.sim.scenarios import Scenario, build_scenario
from tagloc.sim.world import load_builtin_world
from tagloc.supervise import CabState

S = 1_000_000_000
Z_TOL_M = 1e-6  # the floor's lift is exact; the planar filter never moves z
_CHANGE = re.compile(r"^floor (\S+) -> (\S+):")


@dataclass(frozen=True, slots=True)
class Schedule:
    """One random schedule: floors visited in order, the shaft's times, the doors' source."""

    seed: int
    floors: tuple[str, ...]
    dwell_s: float
    door_open_s: float
    door_close_s: float
    lobby_wait_s: tuple[float, ...]
    door_topic: bool


def _schedule(seed: int, rides: int) -> Schedule:
    rng = np.random.default_rng([seed, 7])
    served = load_builtin_world("tower").elevators[0].floors
    floors = [str(rng.choice(served))]
    for _ in range(rides):
        floors.append(str(rng.choice([f for f in served if f != floors[-1]])))
    return Schedule(
        seed, tuple(floors), dwell_s=float(rng.uniform(0.5, 4.0)),
        door_open_s=float(rng.uniform(1.0, 3.0)), door_close_s=float(rng.uniform(1.5, 3.5)),
        lobby_wait_s=tuple(float(w) for w in rng.uniform(1.0, 4.0, rides + 1)),
        door_topic=bool(rng.integers(2)),
    )  # fmt: skip


def _scenario(s: Schedule) -> Scenario:
    """The tower with the schedule's shaft times and route: from the start floor's lobby, each
    ride followed by a wait in the new floor's lobby."""
    world = load_builtin_world("tower")
    shaft = world.elevators[0].model_copy(
        update={"dwell_s": s.dwell_s, "door_open_s": s.door_open_s,
                "door_close_s": s.door_close_s}
    )  # fmt: skip
    waypoints = [Waypoint(at=f"f{s.floors[0]}_lobby", dwell=s.lobby_wait_s[0])]
    for to, wait in zip(s.floors[1:], s.lobby_wait_s[1:], strict=True):
        waypoints.append(Waypoint.model_validate({"ride": {"elevator": shaft.name, "to": to}}))
        waypoints.append(Waypoint(at=f"f{to}_lobby", dwell=wait))
    route = world.route.model_copy(update={"waypoints": tuple(waypoints), "repeat": 1})
    world = world.model_copy(update={"elevators": (shaft,), "route": route})
    scenario = build_scenario("default", seed=s.seed, world=world)
    return dataclasses.replace(scenario, elevator_topic=s.door_topic)


def _violations(scenario: Scenario, run: LocalizationRun) -> list[str]:
    """Every breach of the module docstring's properties, one line each (empty: all hold)."""
    cap = scenario_config().cap
    cap_m, cap_deg = cap.max_translation_m, cap.max_rotation_deg
    heights = {f.name: f.height_m for f in scenario.world.all_floors()}
    tag_floor = {t.id: f for t, f in scenario.world.all_tags() if f is not None}
    stamps = np.asarray(run.stamps_ns)
    t0 = scenario.drive.t0_ns
    changes = {}
    for e in run.events:
        m = _CHANGE.match(e.detail) if e.kind is EventKind.FLOOR_CHANGED else None
        if m is not None:
            changes[int(np.searchsorted(stamps, e.stamp_ns))] = (e.stamp_ns, m[1], m[2])
    bad: list[str] = []
    # 1. the jumps of the published map -> base between consecutive estimates
    T_prev = run.T_map_odom[:-1] @ run.T_odom_base[1:]
    T_next = run.T_map_odom[1:] @ run.T_odom_base[1:]
    d_map = np.asarray(T_next.translation) - np.asarray(T_prev.translation)
    step = T_prev.inverse() @ T_next
    deg = np.degrees(np.linalg.norm(np.asarray(step.rotation.as_rotvec()), axis=1))
    init = np.asarray(run.initialized)
    for i in np.flatnonzero(init[:-1] & init[1:]):
        k, t = int(i) + 1, (stamps[int(i) + 1] - t0) / S
        xy, dz = float(np.hypot(*d_map[i, :2])), float(d_map[i, 2])
        if k in changes and changes[k][1] in heights:
            want = heights[changes[k][2]] - heights[changes[k][1]]
            if abs(dz - want) > Z_TOL_M or xy > cap_m + 1e-9 or deg[i] > cap_deg + 1e-9:
                old, new = changes[k][1:]
                bad.append(f"t={t:.2f} s floor change {old} -> {new}: dz {dz:+.4f} m (want "
                           f"{want:+.4f}), xy {xy:.4f} m, {deg[i]:.3f} deg")  # fmt: skip
        elif math.hypot(xy, dz) > cap_m + 1e-9 or deg[i] > cap_deg + 1e-9:
            bad.append(f"t={t:.2f} s jump {math.hypot(xy, dz):.4f} m, {deg[i]:.3f} deg "
                       f"(cap {cap_m:g} m, {cap_deg:g} deg)")  # fmt: skip
    # 2. each floor change: an accepted fix of the new floor's tags since the doors opened, and
    #    the floor the robot is on
    opened = [m.stamp_ns for m in run.cab_moves if m.to_state is CabState.ALIGHTING]
    for stamp, old, new in changes.values():
        since = max((o for o in opened if o <= stamp), default=run.stamps_ns[0])
        landing = [a for a in run.fixes if a.accepted and a.in_map and since <= a.stamp_ns <= stamp
                   and any(tag_floor.get(i) == new for i in a.tag_ids)]  # fmt: skip
        if not landing:
            bad.append(f"t={(stamp - t0) / S:.2f} s {old} -> {new} without an accepted fix of "
                       f"floor {new}'s tags")  # fmt: skip
        truth = scenario.drive.floor_at(int(stamp))
        if truth != new:
            bad.append(f"t={(stamp - t0) / S:.2f} s declared floor {new}, the robot is on {truth}")
    rode = sum(old != "None" for _, old, _ in changes.values())
    rides = len(scenario.drive.plan.rides)  # type: ignore[attr-defined]
    if rode != rides:
        bad.append(f"{rode} floor changes after rides, {rides} rides")
    return bad


def _check(seed: int, rides: int, lidar: bool) -> None:
    schedule = _schedule(seed, rides)
    scenario = _scenario(schedule)
    run = localize_scenario(scenario, lidar=lidar)
    bad = _violations(scenario, run)
    assert not bad, f"{schedule}:\n" + "\n".join(bad)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_published_correction_jumps_only_at_declared_floor_changes(seed: int) -> None:
    _check(seed, rides=1, lidar=False)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [10, 11, 12, 13])
def test_the_property_holds_over_two_rides_with_the_lidar(seed: int) -> None:
    _check(seed, rides=2, lidar=True)


@pytest.mark.parametrize("start", ["1", "2"])
def test_a_drive_starting_on_an_upper_floor_is_localized_at_its_height(start: str) -> None:
    """The odometry starts at zero on the floor the robot boots on (as a robot's does): the
    fused pose's z is the floor's height from the first known floor on, before and after a
    ride down, within 5 cm of the simulator's truth."""
    schedule = Schedule(5, (start, "0"), 2.0, 2.0, 2.0, (3.0, 3.0), True)
    scenario = _scenario(schedule)
    run = localize_scenario(scenario, lidar=False)
    known = np.asarray(run.initialized) & np.array([f is not None for f in run.floors])
    assert known.sum() > 100
    floors_seen = {f for f, k in zip(run.floors, known, strict=True) if k}
    assert floors_seen == {start, "0"}
    dz = np.asarray(run.T_map_base.translation)[:, 2] - np.asarray(
        run.T_map_base_truth.translation
    )[:, 2]
    worst = float(np.max(np.abs(dz[known])))
    assert worst < 0.05, f"z off by up to {worst:.3f} m while the floor is known"
